/* The pythonfmu FMU's binary: forwards every fmi2* call to pythonfmu's own library and answers
 * fmi2GetBooleanStatus(fmi2Terminated) and fmi2GetStatus itself, as the native FMU does
 * (docs/fmu.md, "Errors").
 *
 * pythonfmu 0.7's C++ layer answers fmi2Terminated true from the first refused doStep on,
 * whatever the state, so hosts that ask after fmi2Discard (fmpy's simulate_fmu, fmusim, the FMU
 * Compliance Checker) end a run at a step a retry could take.  This library is packed as
 * binaries/<platform>/<modelIdentifier>.<suffix>; pythonfmu's library lies beside it as
 * PRSM_INNER_STEM.<suffix> and is loaded from there (never unloaded: it embeds Python).  The
 * answer, per instance:
 *   fmi2Terminated = true  after fmi2Terminate (in the stepping phase), until fmi2Reset, and
 *                          after the same doStep (t, h and the inputs screw_torque, load_force as
 *                          last set) was refused twice in a row: the FMU is deterministic, so
 *                          that call cannot succeed, and a host that retries unchanged stops;
 *                  = false otherwise: a refused step left the state unchanged, and a retry
 *                          with other inputs, another step or a restored state may succeed.
 * A successful doStep, a restored state (fmi2SetFMUstate) and fmi2Reset forget the refusals.
 * A restored state brings its phase back, as the native FMU's and the Python slave's do: a state
 * taken while stepping and restored after fmi2Terminate answers false and may step again.  The
 * phase of a state is recorded when fmi2GetFMUstate makes it, or read from the bytes
 * fmi2DeSerializeFMUstate takes (serialized_phase); where neither says, the phase stays.
 * fmi2GetStatus answers fmi2Discard (doStep never runs asynchronously), as the native FMU.
 *
 * Build-time definitions: PRSM_VR_TORQUE, PRSM_VR_LOAD (value references of the inputs),
 * PRSM_INNER_STEM (file name of pythonfmu's library without its suffix, a string).
 */
#if !defined(_WIN32)
#define _GNU_SOURCE               /* dladdr */
#endif
#include <stddef.h>
#include <stdio.h>
#include <stdlib.h>
#include <string.h>

#include "fmi2Functions.h"

#if defined(_WIN32)
#include <windows.h>
#define INNER_SUFFIX ".dll"
#define PATH_SEPARATORS "\\/"
#else
#include <dlfcn.h>
#if defined(__APPLE__)
#define INNER_SUFFIX ".dylib"
#else
#define INNER_SUFFIX ".so"
#endif
#define PATH_SEPARATORS "/"
#endif

#if !defined(PRSM_VR_TORQUE) || !defined(PRSM_VR_LOAD) || !defined(PRSM_INNER_STEM)
#error "define PRSM_VR_TORQUE, PRSM_VR_LOAD and PRSM_INNER_STEM"
#endif

/* every function of pythonfmu's library, by name: X(name) */
#define PRSM_INNER_FUNCTIONS(X) \
    X(fmi2GetTypesPlatform) X(fmi2GetVersion) X(fmi2SetDebugLogging) X(fmi2Instantiate) \
    X(fmi2FreeInstance) X(fmi2SetupExperiment) X(fmi2EnterInitializationMode) \
    X(fmi2ExitInitializationMode) X(fmi2Terminate) X(fmi2Reset) X(fmi2GetReal) X(fmi2GetInteger) \
    X(fmi2GetBoolean) X(fmi2GetString) X(fmi2SetReal) X(fmi2SetInteger) X(fmi2SetBoolean) \
    X(fmi2SetString) X(fmi2GetFMUstate) X(fmi2SetFMUstate) X(fmi2FreeFMUstate) \
    X(fmi2SerializedFMUstateSize) X(fmi2SerializeFMUstate) X(fmi2DeSerializeFMUstate) \
    X(fmi2GetDirectionalDerivative) X(fmi2SetRealInputDerivatives) \
    X(fmi2GetRealOutputDerivatives) X(fmi2DoStep) X(fmi2CancelStep) X(fmi2GetStatus) \
    X(fmi2GetRealStatus) X(fmi2GetIntegerStatus) X(fmi2GetBooleanStatus) X(fmi2GetStringStatus)

typedef struct {
#define PRSM_MEMBER(f) f##TYPE *f;
    PRSM_INNER_FUNCTIONS(PRSM_MEMBER)
#undef PRSM_MEMBER
} inner_functions;

static inner_functions inner;     /* filled once, by the first fmi2Instantiate */
static int inner_loaded;

enum { PH_INSTANTIATED, PH_INITIALIZATION, PH_STEPPING, PH_TERMINATED };

typedef struct {
    fmi2Component inner;          /* pythonfmu's instance */
    fmi2CallbackFunctions cb;
    int logging_on;
    int phase;
    double u[2];                  /* screw_torque, load_force as last set */
    double refused_call[4];       /* the last refused doStep: t, h, u */
    int has_refused, stuck;
    char name[256];
    struct state_phase *states;   /* the phase of each state handle made by this instance */
} wrapper;

typedef struct state_phase {
    fmi2FMUstate state;
    int phase;
    struct state_phase *next;
} state_phase;

/* the recorded phase of ``state``'s entry (NULL: none) */
static state_phase *phase_entry(const wrapper *w, fmi2FMUstate state) {
    for (state_phase *e = w->states; e; e = e->next)
        if (e->state == state) return e;
    return NULL;
}

/* record that ``state`` holds ``phase`` (-1: unknown, the entry is dropped) */
static void record_phase(wrapper *w, fmi2FMUstate state, int phase) {
    state_phase *e = phase_entry(w, state);
    if (!e && phase >= 0) {
        e = (state_phase *)w->cb.allocateMemory(1, sizeof *e);
        if (!e) return;
        e->state = state;
        e->next = w->states;
        w->states = e;
    }
    if (e) e->phase = phase;
}

static void forget_phase(wrapper *w, fmi2FMUstate state) {
    for (state_phase **p = &w->states; *p; p = &(*p)->next)
        if ((*p)->state == state) {
            state_phase *e = *p;
            *p = e->next;
            w->cb.freeMemory(e);
            return;
        }
}

static unsigned long long little_endian(const unsigned char *b, int n) {
    unsigned long long v = 0;
    for (int k = n - 1; k >= 0; k--) v = v << 8 | b[k];
    return v;
}

/* The phase (PH_*) of a serialized state of the Python slave, or -1 where the bytes do not say.
 * prsm_fmu.fmu_state.to_bytes writes "PRSMFMU2" and a pickle (protocol 4) of the state tuple,
 * whose 6th item (fmu_state.FIELDS) is the phase's name; this walks the pickle's opcodes to the
 * end of that tuple, keeping its items (a string's bytes, else NULL) and the strings memoized
 * (for a phase written as a reference to an earlier equal string).  "failed" (initialization refused) reads as the initialization phase, where this
 * wrapper stays when fmi2ExitInitializationMode fails. */
static int serialized_phase(const unsigned char *b, size_t n) {
    enum { MEMO_MAX = 512 };
    static const char *const names[] = {"instantiated", "initialization", "stepping",
                                        "terminated", "failed"};
    static const int phases[] = {PH_INSTANTIATED, PH_INITIALIZATION, PH_STEPPING, PH_TERMINATED,
                                 PH_INITIALIZATION};
    const unsigned char *memo[MEMO_MAX], *top[MEMO_MAX];  /* top: the outer tuple's items */
    size_t memo_len[MEMO_MAX], top_len[MEMO_MAX];
    int n_memo = 0, depth = 0, items = 0;
    const unsigned char *s = NULL;           /* the last object pushed, if a string */
    size_t s_len = 0, i = 8;
#define NEED(k) do { if ((k) > n - i) return -1; } while (0)
    if (n < 8 || memcmp(b, "PRSMFMU2", 8)) return -1;
    while (i < n) {
        unsigned char op = b[i++];
        int push = 1;
        size_t len;
        switch (op) {
        case 0x80: NEED(1); i += 1; push = 0; break;                 /* PROTO */
        case 0x95: NEED(8); i += 8; push = 0; break;                 /* FRAME */
        case '(': depth++; push = 0; break;                          /* MARK */
        case 't':                                                    /* TUPLE */
            if (depth == 1) {          /* the outer tuple is complete: its 6th item */
                if (items < 6 || !top[5]) return -1;
                for (int k = 0; k < 5; k++)
                    if (strlen(names[k]) == top_len[5] && !memcmp(names[k], top[5], top_len[5]))
                        return phases[k];
                return -1;
            }
            if (--depth < 0) return -1;
            s = NULL;
            break;
        case 0x85: case 0x86: case 0x87:                             /* TUPLE1..3 */
            if (depth == 1 && (items -= op - 0x84) < 0) return -1;
            s = NULL;
            break;
        case 0x94:                                                   /* MEMOIZE */
            if (n_memo == MEMO_MAX) return -1;
            memo[n_memo] = s;
            memo_len[n_memo++] = s_len;
            push = 0;
            break;
        case 'h': case 'j': {                                        /* BINGET, LONG_BINGET */
            int k = op == 'h' ? 1 : 4;
            NEED((size_t)k);
            unsigned long long idx = little_endian(b + i, k);
            i += (size_t)k;
            if (idx >= (unsigned long long)n_memo) return -1;
            s = memo[idx];
            s_len = memo_len[idx];
            break;
        }
        case 0x8c: case 'X': case 0x8d: {                            /* strings */
            int k = op == 0x8c ? 1 : op == 'X' ? 4 : 8;
            NEED((size_t)k);
            len = (size_t)little_endian(b + i, k);
            i += (size_t)k;
            NEED(len);
            s = b + i;
            s_len = len;
            i += len;
            break;
        }
        case 0x8a: case 0x8b: case 'C': case 'B': case 0x8e: {   /* LONG1/4, bytes */
            int k = op == 0x8a || op == 'C' ? 1 : op == 0x8e ? 8 : 4;
            NEED((size_t)k);
            len = (size_t)little_endian(b + i, k);
            i += (size_t)k;
            NEED(len);
            i += len;
            s = NULL;
            break;
        }
        case 'K': NEED(1); i += 1; s = NULL; break;                  /* BININT1 */
        case 'M': NEED(2); i += 2; s = NULL; break;                  /* BININT2 */
        case 'J': NEED(4); i += 4; s = NULL; break;                  /* BININT */
        case 'G': NEED(8); i += 8; s = NULL; break;                  /* BINFLOAT */
        case 0x88: case 0x89: case 'N': case ')': case ']': case '}':
            s = NULL;                                    /* True False None () [] {} */
            break;
        case 'a': case 's':                              /* APPEND, SETITEM: into the list/dict */
            if (depth == 1 && (items -= op == 'a' ? 1 : 2) < 1) return -1;
            push = 0;
            break;
        case 'e': case 'u':                              /* APPENDS, SETITEMS: up to the mark */
            if (--depth < 1) return -1;
            push = 0;
            break;
        default: return -1;                                          /* STOP or not ours */
        }
        if (push && depth == 1) {
            if (items == MEMO_MAX) return -1;
            top[items] = s;
            top_len[items++] = s_len;
        }
    }
#undef NEED
    return -1;
}

/* the directory of this library, with its separator, into dir; 0 on success */
static int own_directory(char *dir, size_t len) {
#if defined(_WIN32)
    HMODULE self = NULL;
    if (!GetModuleHandleExA(GET_MODULE_HANDLE_EX_FLAG_FROM_ADDRESS |
                            GET_MODULE_HANDLE_EX_FLAG_UNCHANGED_REFCOUNT,
                            (LPCSTR)(void *)&own_directory, &self))
        return -1;
    DWORD n = GetModuleFileNameA(self, dir, (DWORD)len);
    if (n == 0 || n >= len) return -1;
#else
    Dl_info info;
    if (!dladdr((void *)&own_directory, &info) || !info.dli_fname) return -1;
    if (strlen(info.dli_fname) >= len) return -1;
    strcpy(dir, info.dli_fname);
#endif
    char *end = NULL;
    for (char *p = dir; *p; p++)
        if (strchr(PATH_SEPARATORS, *p)) end = p;
    if (!end) return -1;
    end[1] = '\0';
    return 0;
}

/* load pythonfmu's library beside this one; NULL on success, else why not (into msg) */
static const char *load_inner(char *msg, size_t len) {
    if (inner_loaded) return NULL;
    char path[4096];
    if (own_directory(path, sizeof path - 64)) {
        snprintf(msg, len, "the folder of the FMU's binary cannot be found");
        return msg;
    }
    strcat(path, PRSM_INNER_STEM INNER_SUFFIX);
    inner_functions f;
#if defined(_WIN32)
    HMODULE lib = LoadLibraryExA(path, NULL, LOAD_WITH_ALTERED_SEARCH_PATH);
    if (!lib) {
        snprintf(msg, len, "cannot load %s (error %lu)", path, (unsigned long)GetLastError());
        return msg;
    }
#define PRSM_LOOKUP(name) f.name = (name##TYPE *)(void *)GetProcAddress(lib, #name); \
    if (!f.name) { snprintf(msg, len, "%s does not define %s", path, #name); return msg; }
#else
    void *lib = dlopen(path, RTLD_NOW | RTLD_LOCAL);
    if (!lib) {
        snprintf(msg, len, "cannot load %s: %s", path, dlerror());
        return msg;
    }
#define PRSM_LOOKUP(name) *(void **)(&f.name) = dlsym(lib, #name); \
    if (!f.name) { snprintf(msg, len, "%s does not define %s", path, #name); return msg; }
#endif
    PRSM_INNER_FUNCTIONS(PRSM_LOOKUP)
#undef PRSM_LOOKUP
    /* two threads instantiating at once both load the same library (reference counted) and
       write the same addresses */
    inner = f;
    inner_loaded = 1;
    return NULL;
}

static void log_msg(const wrapper *w, fmi2Status status, const char *category, const char *msg) {
    if (w->logging_on && w->cb.logger)
        w->cb.logger(w->cb.componentEnvironment, w->name, status, category, msg);
}

#define W(comp) wrapper *w = (wrapper *)(comp); if (!w) return fmi2Error

const char *fmi2GetTypesPlatform(void) { return fmi2TypesPlatform; }
const char *fmi2GetVersion(void) { return fmi2Version; }

fmi2Component fmi2Instantiate(fmi2String instanceName, fmi2Type fmuType, fmi2String fmuGUID,
                              fmi2String fmuResourceLocation,
                              const fmi2CallbackFunctions *functions, fmi2Boolean visible,
                              fmi2Boolean loggingOn) {
    char msg[4300];
    if (!functions || !functions->allocateMemory || !functions->freeMemory) return NULL;
    const char *why = load_inner(msg, sizeof msg);
    if (why) {
        if (functions->logger)
            functions->logger(functions->componentEnvironment, instanceName ? instanceName : "",
                              fmi2Error, "logStatusError", why);
        return NULL;
    }
    wrapper *w = (wrapper *)functions->allocateMemory(1, sizeof *w);
    if (!w) return NULL;
    w->cb = *functions;
    w->logging_on = loggingOn == fmi2True;
    snprintf(w->name, sizeof w->name, "%s", instanceName ? instanceName : "");
    w->inner = inner.fmi2Instantiate(instanceName, fmuType, fmuGUID, fmuResourceLocation,
                                     functions, visible, loggingOn);
    if (!w->inner) {
        functions->freeMemory(w);
        return NULL;
    }
    return w;
}

void fmi2FreeInstance(fmi2Component c) {
    wrapper *w = (wrapper *)c;
    if (!w) return;
    inner.fmi2FreeInstance(w->inner);
    while (w->states) forget_phase(w, w->states->state);
    w->cb.freeMemory(w);
}

fmi2Status fmi2SetDebugLogging(fmi2Component c, fmi2Boolean loggingOn, size_t n,
                               const fmi2String categories[]) {
    W(c);
    fmi2Status s = inner.fmi2SetDebugLogging(w->inner, loggingOn, n, categories);
    if (s == fmi2OK) w->logging_on = loggingOn == fmi2True;
    return s;
}

fmi2Status fmi2SetupExperiment(fmi2Component c, fmi2Boolean toleranceDefined, fmi2Real tolerance,
                               fmi2Real startTime, fmi2Boolean stopTimeDefined, fmi2Real stopTime) {
    W(c);
    return inner.fmi2SetupExperiment(w->inner, toleranceDefined, tolerance, startTime,
                                     stopTimeDefined, stopTime);
}

/* the phase after a call that returned s: ``to`` if it succeeded from ``from`` */
static fmi2Status moved(wrapper *w, fmi2Status s, int from, int to) {
    if (s == fmi2OK && w->phase == from) w->phase = to;
    return s;
}

fmi2Status fmi2EnterInitializationMode(fmi2Component c) {
    W(c);
    return moved(w, inner.fmi2EnterInitializationMode(w->inner), PH_INSTANTIATED, PH_INITIALIZATION);
}

fmi2Status fmi2ExitInitializationMode(fmi2Component c) {
    W(c);
    return moved(w, inner.fmi2ExitInitializationMode(w->inner), PH_INITIALIZATION, PH_STEPPING);
}

fmi2Status fmi2Terminate(fmi2Component c) {
    W(c);
    return moved(w, inner.fmi2Terminate(w->inner), PH_STEPPING, PH_TERMINATED);
}

fmi2Status fmi2Reset(fmi2Component c) {
    W(c);
    fmi2Status s = inner.fmi2Reset(w->inner);
    if (s == fmi2OK) {
        w->phase = PH_INSTANTIATED;
        w->has_refused = w->stuck = 0;
    }
    return s;
}

#define PRSM_FORWARD_ARRAY(call, type)                                                        \
    fmi2Status call(fmi2Component c, const fmi2ValueReference vr[], size_t nvr, type value[]) { \
        W(c);                                                                                 \
        return inner.call(w->inner, vr, nvr, value);                                          \
    }
PRSM_FORWARD_ARRAY(fmi2GetReal, fmi2Real)
PRSM_FORWARD_ARRAY(fmi2GetInteger, fmi2Integer)
PRSM_FORWARD_ARRAY(fmi2GetBoolean, fmi2Boolean)
PRSM_FORWARD_ARRAY(fmi2GetString, fmi2String)
PRSM_FORWARD_ARRAY(fmi2SetInteger, const fmi2Integer)
PRSM_FORWARD_ARRAY(fmi2SetBoolean, const fmi2Boolean)
PRSM_FORWARD_ARRAY(fmi2SetString, const fmi2String)

fmi2Status fmi2SetReal(fmi2Component c, const fmi2ValueReference vr[], size_t nvr,
                       const fmi2Real value[]) {
    W(c);
    for (size_t i = 0; vr && value && i < nvr; i++) {     /* the inputs as the host set them */
        if (vr[i] == PRSM_VR_TORQUE) w->u[0] = value[i];
        if (vr[i] == PRSM_VR_LOAD) w->u[1] = value[i];
    }
    return inner.fmi2SetReal(w->inner, vr, nvr, value);
}

fmi2Status fmi2GetFMUstate(fmi2Component c, fmi2FMUstate *state) {
    W(c);
    fmi2Status s = inner.fmi2GetFMUstate(w->inner, state);
    if (s == fmi2OK && state && *state) record_phase(w, *state, w->phase);
    return s;
}

fmi2Status fmi2SetFMUstate(fmi2Component c, fmi2FMUstate state) {
    W(c);
    fmi2Status s = inner.fmi2SetFMUstate(w->inner, state);
    if (s == fmi2OK) {                 /* refused: nothing changed (the native FMU's rule) */
        const state_phase *e = phase_entry(w, state);
        if (e) w->phase = e->phase;    /* the state's phase, as the slave restores it */
        w->has_refused = w->stuck = 0; /* another state: a refused call may succeed from it */
    }
    return s;
}

fmi2Status fmi2FreeFMUstate(fmi2Component c, fmi2FMUstate *state) {
    W(c);
    fmi2FMUstate was = state ? *state : NULL;
    fmi2Status s = inner.fmi2FreeFMUstate(w->inner, state);
    if (was && s == fmi2OK) forget_phase(w, was);
    return s;
}

fmi2Status fmi2SerializedFMUstateSize(fmi2Component c, fmi2FMUstate state, size_t *size) {
    W(c);
    return inner.fmi2SerializedFMUstateSize(w->inner, state, size);
}

fmi2Status fmi2SerializeFMUstate(fmi2Component c, fmi2FMUstate state, fmi2Byte bytes[],
                                 size_t size) {
    W(c);
    return inner.fmi2SerializeFMUstate(w->inner, state, bytes, size);
}

fmi2Status fmi2DeSerializeFMUstate(fmi2Component c, const fmi2Byte bytes[], size_t size,
                                   fmi2FMUstate *state) {
    W(c);
    fmi2Status s = inner.fmi2DeSerializeFMUstate(w->inner, bytes, size, state);
    if (s == fmi2OK && bytes && state && *state)
        record_phase(w, *state, serialized_phase((const unsigned char *)bytes, size));
    return s;
}

fmi2Status fmi2GetDirectionalDerivative(fmi2Component c, const fmi2ValueReference unknown[],
                                        size_t n_unknown, const fmi2ValueReference known[],
                                        size_t n_known, const fmi2Real dv_known[],
                                        fmi2Real dv_unknown[]) {
    W(c);
    return inner.fmi2GetDirectionalDerivative(w->inner, unknown, n_unknown, known, n_known,
                                              dv_known, dv_unknown);
}

fmi2Status fmi2SetRealInputDerivatives(fmi2Component c, const fmi2ValueReference vr[],
                                       size_t nvr, const fmi2Integer order[],
                                       const fmi2Real value[]) {
    W(c);
    return inner.fmi2SetRealInputDerivatives(w->inner, vr, nvr, order, value);
}

fmi2Status fmi2GetRealOutputDerivatives(fmi2Component c, const fmi2ValueReference vr[],
                                        size_t nvr, const fmi2Integer order[], fmi2Real value[]) {
    W(c);
    return inner.fmi2GetRealOutputDerivatives(w->inner, vr, nvr, order, value);
}

fmi2Status fmi2DoStep(fmi2Component c, fmi2Real t, fmi2Real h,
                      fmi2Boolean noSetFMUStatePriorToCurrentPoint) {
    W(c);
    fmi2Status s = inner.fmi2DoStep(w->inner, t, h, noSetFMUStatePriorToCurrentPoint);
    if (s == fmi2OK) {
        w->has_refused = w->stuck = 0;
    } else if (s == fmi2Discard) {     /* refused, state unchanged: the same call again cannot succeed */
        double call[4] = {t, h, w->u[0], w->u[1]};
        w->stuck = w->has_refused && !memcmp(call, w->refused_call, sizeof call);
        memcpy(w->refused_call, call, sizeof call);
        w->has_refused = 1;
    }
    return s;
}

fmi2Status fmi2CancelStep(fmi2Component c) {
    W(c);
    return inner.fmi2CancelStep(w->inner);
}

fmi2Status fmi2GetStatus(fmi2Component c, const fmi2StatusKind s, fmi2Status *value) {
    W(c);
    (void)s; (void)value;
    return fmi2Discard;                /* doStep never returns fmi2Pending */
}

fmi2Status fmi2GetRealStatus(fmi2Component c, const fmi2StatusKind s, fmi2Real *value) {
    W(c);
    return inner.fmi2GetRealStatus(w->inner, s, value);
}

fmi2Status fmi2GetIntegerStatus(fmi2Component c, const fmi2StatusKind s, fmi2Integer *value) {
    W(c);
    return inner.fmi2GetIntegerStatus(w->inner, s, value);
}

fmi2Status fmi2GetBooleanStatus(fmi2Component c, const fmi2StatusKind s, fmi2Boolean *value) {
    W(c);
    if (s != fmi2Terminated || !value) {
        log_msg(w, fmi2Discard, "logStatusDiscard",
                "fmi2GetBooleanStatus: only fmi2Terminated is answered");
        return fmi2Discard;
    }
    *value = w->phase == PH_TERMINATED || w->stuck ? fmi2True : fmi2False;
    return fmi2OK;
}

fmi2Status fmi2GetStringStatus(fmi2Component c, const fmi2StatusKind s, fmi2String *value) {
    W(c);
    return inner.fmi2GetStringStatus(w->inner, s, value);
}
