/* FMI 3.0 interface of the native PRSM FMU (co-simulation and model exchange).
 *
 * One translation unit with the FMI 2.0 interface: it includes prsm_fmi2_me.c (which includes
 * prsm_fmi2.c) and maps every FMI 3.0 function onto the FMI 2.0 one, so that both FMUs run the
 * same code on the same variables (value references, names, units are the FMI 2.0 FMU's; the
 * Integer variables are Int32, the Enumerations Int64 through the API).  Added for FMI 3.0:
 * the event indicators are variables (value references PRSM_FMI3_EI_VR0 + 0..3, defined by
 * fmu_build.fmi3 at compile time), and so is time, the independent variable (the next one).  Types the FMU has no variable of (Float32, Int8..UInt64 but
 * Int32 and Int64, Binary, Clock), configuration mode, clocks and scheduled execution are
 * refused with fmi3Error and a logged message.
 */
#include "prsm_fmi2_me.c"
#include "fmi3Functions.h"

#ifndef PRSM_FMI3_EI_VR0
#error "PRSM_FMI3_EI_VR0 (first event indicator's value reference) must be defined"
#endif

/* the FMI 3.0 host's logger, reached through the FMI 2.0 component's environment */
typedef struct {
    fmi3InstanceEnvironment env;
    fmi3LogMessageCallback log;
} bridge;

static void bridge_logger(fmi2ComponentEnvironment e, fmi2String instance, fmi2Status status,
                          fmi2String category, fmi2String message, ...) {
    (void)instance;
    bridge *b = (bridge *)e;
    if (!b || !b->log) return;
    /* the FMI 2.0 message is a format with literal % doubled (log_msg): undo that */
    char text[4200];
    size_t j = 0;
    for (size_t i = 0; message[i] && j + 1 < sizeof text; i++) {
        if (message[i] == '%' && message[i + 1] == '%') i++;
        text[j++] = message[i];
    }
    text[j] = 0;
    b->log(b->env, (fmi3Status)status, category, text);
}

static fmi3Instance instantiate(fmi2Type type, fmi3String name, fmi3String token,
                                fmi3Boolean logging, fmi3InstanceEnvironment env,
                                fmi3LogMessageCallback log) {
    bridge *b = (bridge *)calloc(1, sizeof *b);
    if (!b) return NULL;
    b->env = env;
    b->log = log;
    fmi2CallbackFunctions cb = {bridge_logger, calloc, free, NULL, b};
    fmi2Component c = fmi2Instantiate(name, type, token, "", &cb, fmi2False, logging ? fmi2True : fmi2False);
    if (!c) free(b);
    return c;
}

static fmi3Status no_such_type(fmi3Instance i, const char *call) {
    component *c = (component *)i;
    if (c) log_msg(c, fmi2Error, "%s: the FMU has no variable of this type", call);
    return fmi3Error;
}

static fmi3Status not_supported(fmi3Instance i, const char *call) {
    component *c = (component *)i;
    if (c) log_msg(c, fmi2Error, "%s is not supported by this FMU", call);
    return fmi3Error;
}

const char *fmi3GetVersion(void) { return fmi3Version; }

fmi3Status fmi3SetDebugLogging(fmi3Instance i, fmi3Boolean on, size_t n, const fmi3String categories[]) {
    return (fmi3Status)fmi2SetDebugLogging(i, on ? fmi2True : fmi2False, n, categories);
}

fmi3Instance fmi3InstantiateModelExchange(fmi3String name, fmi3String token, fmi3String resources,
                                          fmi3Boolean visible, fmi3Boolean logging,
                                          fmi3InstanceEnvironment env, fmi3LogMessageCallback log) {
    (void)resources; (void)visible;
    return instantiate(fmi2ModelExchange, name, token, logging, env, log);
}

fmi3Instance fmi3InstantiateCoSimulation(fmi3String name, fmi3String token, fmi3String resources,
                                         fmi3Boolean visible, fmi3Boolean logging,
                                         fmi3Boolean eventModeUsed, fmi3Boolean earlyReturnAllowed,
                                         const fmi3ValueReference required[], size_t n_required,
                                         fmi3InstanceEnvironment env, fmi3LogMessageCallback log,
                                         fmi3IntermediateUpdateCallback update) {
    (void)resources; (void)visible; (void)eventModeUsed; (void)earlyReturnAllowed;
    (void)required; (void)n_required; (void)update;
    return instantiate(fmi2CoSimulation, name, token, logging, env, log);
}

fmi3Instance fmi3InstantiateScheduledExecution(fmi3String name, fmi3String token, fmi3String resources,
                                               fmi3Boolean visible, fmi3Boolean logging,
                                               fmi3InstanceEnvironment env, fmi3LogMessageCallback log,
                                               fmi3ClockUpdateCallback clock, fmi3LockPreemptionCallback lock,
                                               fmi3UnlockPreemptionCallback unlock) {
    (void)name; (void)token; (void)resources; (void)visible; (void)logging; (void)clock;
    (void)lock; (void)unlock;
    if (log) log(env, fmi3Error, "logStatusError", "scheduled execution is not supported by this FMU");
    return NULL;
}

void fmi3FreeInstance(fmi3Instance i) {
    component *c = (component *)i;
    if (!c) return;
    void *b = c->cb.componentEnvironment;
    fmi2FreeInstance(i);
    free(b);
}

fmi3Status fmi3EnterInitializationMode(fmi3Instance i, fmi3Boolean tol_defined, fmi3Float64 tol,
                                       fmi3Float64 start, fmi3Boolean stop_defined, fmi3Float64 stop) {
    fmi2Status s = fmi2SetupExperiment(i, tol_defined, tol, start, stop_defined, stop);
    if (s != fmi2OK) return (fmi3Status)s;
    return (fmi3Status)fmi2EnterInitializationMode(i);
}

fmi3Status fmi3ExitInitializationMode(fmi3Instance i) { return (fmi3Status)fmi2ExitInitializationMode(i); }

fmi3Status fmi3EnterEventMode(fmi3Instance i) {
    component *c = (component *)i;
    if (c && !c->model_exchange) return not_supported(i, "fmi3EnterEventMode (co-simulation without event mode)");
    return (fmi3Status)fmi2EnterEventMode(i);
}

fmi3Status fmi3Terminate(fmi3Instance i) { return (fmi3Status)fmi2Terminate(i); }
fmi3Status fmi3Reset(fmi3Instance i) { return (fmi3Status)fmi2Reset(i); }

/* ---- variables ---- */
fmi3Status fmi3GetFloat64(fmi3Instance i, const fmi3ValueReference vr[], size_t nvr, fmi3Float64 v[], size_t nv) {
    if (nv != nvr) return not_supported(i, "fmi3GetFloat64 with arrays");
    for (size_t k = 0; k < nvr; k++) {
        if (vr[k] == PRSM_FMI3_EI_VR0 + PRSM_N_EVENT_INDICATORS) {     /* the independent: time */
            component *c = (component *)i;
            if (!c) return fmi3Error;
            v[k] = c->s.t;
        } else if (vr[k] >= PRSM_FMI3_EI_VR0 && vr[k] < PRSM_FMI3_EI_VR0 + PRSM_N_EVENT_INDICATORS) {
            double z[PRSM_N_EVENT_INDICATORS];
            component *c = (component *)i;
            if (!c) return fmi3Error;
            if (c->s.phase != PH_STEPPING) {   /* before initialization: not yet defined */
                v[k] = 0.0;
                continue;
            }
            int me = c->model_exchange;
            c->model_exchange = 1;                 /* indicators at the current state and inputs */
            fmi2Status s = fmi2GetEventIndicators(i, z, PRSM_N_EVENT_INDICATORS);
            c->model_exchange = me;
            if (s != fmi2OK) return (fmi3Status)s;
            v[k] = z[vr[k] - PRSM_FMI3_EI_VR0];
        } else {
            fmi2Status s = fmi2GetReal(i, &vr[k], 1, &v[k]);
            if (s != fmi2OK) return (fmi3Status)s;
        }
    }
    return fmi3OK;
}

fmi3Status fmi3SetFloat64(fmi3Instance i, const fmi3ValueReference vr[], size_t nvr, const fmi3Float64 v[], size_t nv) {
    if (nv != nvr) return not_supported(i, "fmi3SetFloat64 with arrays");
    return (fmi3Status)fmi2SetReal(i, vr, nvr, v);
}

fmi3Status fmi3GetInt32(fmi3Instance i, const fmi3ValueReference vr[], size_t nvr, fmi3Int32 v[], size_t nv) {
    if (nv != nvr) return not_supported(i, "fmi3GetInt32 with arrays");
    return (fmi3Status)fmi2GetInteger(i, vr, nvr, v);
}

fmi3Status fmi3SetInt32(fmi3Instance i, const fmi3ValueReference vr[], size_t nvr, const fmi3Int32 v[], size_t nv) {
    if (nv != nvr) return not_supported(i, "fmi3SetInt32 with arrays");
    return (fmi3Status)fmi2SetInteger(i, vr, nvr, v);
}

/* Int64: the Enumerations (FMI 3.0 sets and gets them as Int64) */
fmi3Status fmi3GetInt64(fmi3Instance i, const fmi3ValueReference vr[], size_t nvr, fmi3Int64 v[], size_t nv) {
    if (nv != nvr) return not_supported(i, "fmi3GetInt64 with arrays");
    for (size_t k = 0; k < nvr; k++) {
        fmi2Integer x;
        fmi2Status s = fmi2GetInteger(i, &vr[k], 1, &x);
        if (s != fmi2OK) return (fmi3Status)s;
        v[k] = x;
    }
    return fmi3OK;
}

fmi3Status fmi3SetInt64(fmi3Instance i, const fmi3ValueReference vr[], size_t nvr, const fmi3Int64 v[], size_t nv) {
    if (nv != nvr) return not_supported(i, "fmi3SetInt64 with arrays");
    for (size_t k = 0; k < nvr; k++)
        if (v[k] < INT32_MIN || v[k] > INT32_MAX) {
            log_msg((component *)i, fmi2Error, "fmi3SetInt64: value %lld of value reference %u is "
                    "out of range: must be an item of its Enumeration", (long long)v[k], (unsigned)vr[k]);
            return fmi3Error;
        }
    fmi2Integer x[64];
    for (size_t k0 = 0; k0 < nvr; k0 += 64) {
        size_t n = nvr - k0 < 64 ? nvr - k0 : 64;
        for (size_t k = 0; k < n; k++) x[k] = (fmi2Integer)v[k0 + k];
        fmi2Status s = fmi2SetInteger(i, vr + k0, n, x);
        if (s != fmi2OK) return (fmi3Status)s;
    }
    return fmi3OK;
}

fmi3Status fmi3GetBoolean(fmi3Instance i, const fmi3ValueReference vr[], size_t nvr, fmi3Boolean v[], size_t nv) {
    if (nv != nvr) return not_supported(i, "fmi3GetBoolean with arrays");
    for (size_t k = 0; k < nvr; k++) {
        fmi2Boolean x;
        fmi2Status s = fmi2GetBoolean(i, &vr[k], 1, &x);
        if (s != fmi2OK) return (fmi3Status)s;
        v[k] = x != fmi2False;
    }
    return fmi3OK;
}

fmi3Status fmi3SetBoolean(fmi3Instance i, const fmi3ValueReference vr[], size_t nvr, const fmi3Boolean v[], size_t nv) {
    if (nv != nvr) return not_supported(i, "fmi3SetBoolean with arrays");
    fmi2Boolean x[64];
    for (size_t k0 = 0; k0 < nvr; k0 += 64) {
        size_t n = nvr - k0 < 64 ? nvr - k0 : 64;
        for (size_t k = 0; k < n; k++) x[k] = v[k0 + k] ? fmi2True : fmi2False;
        fmi2Status s = fmi2SetBoolean(i, vr + k0, n, x);
        if (s != fmi2OK) return (fmi3Status)s;
    }
    return fmi3OK;
}

fmi3Status fmi3GetString(fmi3Instance i, const fmi3ValueReference vr[], size_t nvr, fmi3String v[], size_t nv) {
    if (nv != nvr) return not_supported(i, "fmi3GetString with arrays");
    return (fmi3Status)fmi2GetString(i, vr, nvr, v);
}

fmi3Status fmi3SetString(fmi3Instance i, const fmi3ValueReference vr[], size_t nvr, const fmi3String v[], size_t nv) {
    if (nv != nvr) return not_supported(i, "fmi3SetString with arrays");
    return (fmi3Status)fmi2SetString(i, vr, nvr, v);
}

fmi3Status fmi3GetFloat32(fmi3Instance i, const fmi3ValueReference vr[], size_t nvr, fmi3Float32 v[], size_t nv) {
    (void)vr; (void)nvr; (void)v; (void)nv;
    return no_such_type(i, "fmi3GetFloat32");
}
fmi3Status fmi3SetFloat32(fmi3Instance i, const fmi3ValueReference vr[], size_t nvr, const fmi3Float32 v[], size_t nv) {
    (void)vr; (void)nvr; (void)v; (void)nv;
    return no_such_type(i, "fmi3SetFloat32");
}
fmi3Status fmi3GetInt8(fmi3Instance i, const fmi3ValueReference vr[], size_t nvr, fmi3Int8 v[], size_t nv) {
    (void)vr; (void)nvr; (void)v; (void)nv;
    return no_such_type(i, "fmi3GetInt8");
}
fmi3Status fmi3SetInt8(fmi3Instance i, const fmi3ValueReference vr[], size_t nvr, const fmi3Int8 v[], size_t nv) {
    (void)vr; (void)nvr; (void)v; (void)nv;
    return no_such_type(i, "fmi3SetInt8");
}
fmi3Status fmi3GetUInt8(fmi3Instance i, const fmi3ValueReference vr[], size_t nvr, fmi3UInt8 v[], size_t nv) {
    (void)vr; (void)nvr; (void)v; (void)nv;
    return no_such_type(i, "fmi3GetUInt8");
}
fmi3Status fmi3SetUInt8(fmi3Instance i, const fmi3ValueReference vr[], size_t nvr, const fmi3UInt8 v[], size_t nv) {
    (void)vr; (void)nvr; (void)v; (void)nv;
    return no_such_type(i, "fmi3SetUInt8");
}
fmi3Status fmi3GetInt16(fmi3Instance i, const fmi3ValueReference vr[], size_t nvr, fmi3Int16 v[], size_t nv) {
    (void)vr; (void)nvr; (void)v; (void)nv;
    return no_such_type(i, "fmi3GetInt16");
}
fmi3Status fmi3SetInt16(fmi3Instance i, const fmi3ValueReference vr[], size_t nvr, const fmi3Int16 v[], size_t nv) {
    (void)vr; (void)nvr; (void)v; (void)nv;
    return no_such_type(i, "fmi3SetInt16");
}
fmi3Status fmi3GetUInt16(fmi3Instance i, const fmi3ValueReference vr[], size_t nvr, fmi3UInt16 v[], size_t nv) {
    (void)vr; (void)nvr; (void)v; (void)nv;
    return no_such_type(i, "fmi3GetUInt16");
}
fmi3Status fmi3SetUInt16(fmi3Instance i, const fmi3ValueReference vr[], size_t nvr, const fmi3UInt16 v[], size_t nv) {
    (void)vr; (void)nvr; (void)v; (void)nv;
    return no_such_type(i, "fmi3SetUInt16");
}
fmi3Status fmi3GetUInt32(fmi3Instance i, const fmi3ValueReference vr[], size_t nvr, fmi3UInt32 v[], size_t nv) {
    (void)vr; (void)nvr; (void)v; (void)nv;
    return no_such_type(i, "fmi3GetUInt32");
}
fmi3Status fmi3SetUInt32(fmi3Instance i, const fmi3ValueReference vr[], size_t nvr, const fmi3UInt32 v[], size_t nv) {
    (void)vr; (void)nvr; (void)v; (void)nv;
    return no_such_type(i, "fmi3SetUInt32");
}
fmi3Status fmi3GetUInt64(fmi3Instance i, const fmi3ValueReference vr[], size_t nvr, fmi3UInt64 v[], size_t nv) {
    (void)vr; (void)nvr; (void)v; (void)nv;
    return no_such_type(i, "fmi3GetUInt64");
}
fmi3Status fmi3SetUInt64(fmi3Instance i, const fmi3ValueReference vr[], size_t nvr, const fmi3UInt64 v[], size_t nv) {
    (void)vr; (void)nvr; (void)v; (void)nv;
    return no_such_type(i, "fmi3SetUInt64");
}

fmi3Status fmi3GetBinary(fmi3Instance i, const fmi3ValueReference vr[], size_t nvr, size_t sizes[], fmi3Binary v[], size_t nv) {
    (void)vr; (void)nvr; (void)sizes; (void)v; (void)nv;
    return no_such_type(i, "fmi3GetBinary");
}
fmi3Status fmi3SetBinary(fmi3Instance i, const fmi3ValueReference vr[], size_t nvr, const size_t sizes[], const fmi3Binary v[], size_t nv) {
    (void)vr; (void)nvr; (void)sizes; (void)v; (void)nv;
    return no_such_type(i, "fmi3SetBinary");
}
fmi3Status fmi3GetClock(fmi3Instance i, const fmi3ValueReference vr[], size_t nvr, fmi3Clock v[]) {
    (void)vr; (void)nvr; (void)v;
    return no_such_type(i, "fmi3GetClock");
}
fmi3Status fmi3SetClock(fmi3Instance i, const fmi3ValueReference vr[], size_t nvr, const fmi3Clock v[]) {
    (void)vr; (void)nvr; (void)v;
    return no_such_type(i, "fmi3SetClock");
}

/* ---- what the FMU does not provide ---- */
fmi3Status fmi3GetNumberOfVariableDependencies(fmi3Instance i, fmi3ValueReference vr, size_t *n) {
    (void)vr; (void)n;
    return not_supported(i, "fmi3GetNumberOfVariableDependencies");
}
fmi3Status fmi3GetVariableDependencies(fmi3Instance i, fmi3ValueReference d, size_t e[], fmi3ValueReference ind[],
                                       size_t ei[], fmi3DependencyKind k[], size_t n) {
    (void)d; (void)e; (void)ind; (void)ei; (void)k; (void)n;
    return not_supported(i, "fmi3GetVariableDependencies");
}
fmi3Status fmi3GetDirectionalDerivative(fmi3Instance i, const fmi3ValueReference u[], size_t nu, const fmi3ValueReference k[],
                                        size_t nk, const fmi3Float64 seed[], size_t ns, fmi3Float64 s[], size_t nsens) {
    (void)u; (void)nu; (void)k; (void)nk; (void)seed; (void)ns; (void)s; (void)nsens;
    return not_supported(i, "fmi3GetDirectionalDerivative");
}
fmi3Status fmi3GetAdjointDerivative(fmi3Instance i, const fmi3ValueReference u[], size_t nu, const fmi3ValueReference k[],
                                    size_t nk, const fmi3Float64 seed[], size_t ns, fmi3Float64 s[], size_t nsens) {
    (void)u; (void)nu; (void)k; (void)nk; (void)seed; (void)ns; (void)s; (void)nsens;
    return not_supported(i, "fmi3GetAdjointDerivative");
}
fmi3Status fmi3EnterConfigurationMode(fmi3Instance i) { return not_supported(i, "fmi3EnterConfigurationMode"); }
fmi3Status fmi3ExitConfigurationMode(fmi3Instance i) { return not_supported(i, "fmi3ExitConfigurationMode"); }
fmi3Status fmi3GetIntervalDecimal(fmi3Instance i, const fmi3ValueReference vr[], size_t n, fmi3Float64 iv[], fmi3IntervalQualifier q[]) {
    (void)vr; (void)n; (void)iv; (void)q;
    return not_supported(i, "fmi3GetIntervalDecimal");
}
fmi3Status fmi3GetIntervalFraction(fmi3Instance i, const fmi3ValueReference vr[], size_t n, fmi3UInt64 c[], fmi3UInt64 r[], fmi3IntervalQualifier q[]) {
    (void)vr; (void)n; (void)c; (void)r; (void)q;
    return not_supported(i, "fmi3GetIntervalFraction");
}
fmi3Status fmi3GetShiftDecimal(fmi3Instance i, const fmi3ValueReference vr[], size_t n, fmi3Float64 s[]) {
    (void)vr; (void)n; (void)s;
    return not_supported(i, "fmi3GetShiftDecimal");
}
fmi3Status fmi3GetShiftFraction(fmi3Instance i, const fmi3ValueReference vr[], size_t n, fmi3UInt64 c[], fmi3UInt64 r[]) {
    (void)vr; (void)n; (void)c; (void)r;
    return not_supported(i, "fmi3GetShiftFraction");
}
fmi3Status fmi3SetIntervalDecimal(fmi3Instance i, const fmi3ValueReference vr[], size_t n, const fmi3Float64 iv[]) {
    (void)vr; (void)n; (void)iv;
    return not_supported(i, "fmi3SetIntervalDecimal");
}
fmi3Status fmi3SetIntervalFraction(fmi3Instance i, const fmi3ValueReference vr[], size_t n, const fmi3UInt64 c[], const fmi3UInt64 r[]) {
    (void)vr; (void)n; (void)c; (void)r;
    return not_supported(i, "fmi3SetIntervalFraction");
}
fmi3Status fmi3SetShiftDecimal(fmi3Instance i, const fmi3ValueReference vr[], size_t n, const fmi3Float64 s[]) {
    (void)vr; (void)n; (void)s;
    return not_supported(i, "fmi3SetShiftDecimal");
}
fmi3Status fmi3SetShiftFraction(fmi3Instance i, const fmi3ValueReference vr[], size_t n, const fmi3UInt64 c[], const fmi3UInt64 r[]) {
    (void)vr; (void)n; (void)c; (void)r;
    return not_supported(i, "fmi3SetShiftFraction");
}
fmi3Status fmi3EvaluateDiscreteStates(fmi3Instance i) { return not_supported(i, "fmi3EvaluateDiscreteStates"); }
fmi3Status fmi3GetOutputDerivatives(fmi3Instance i, const fmi3ValueReference vr[], size_t n, const fmi3Int32 o[], fmi3Float64 v[], size_t nv) {
    (void)vr; (void)n; (void)o; (void)v; (void)nv;
    return not_supported(i, "fmi3GetOutputDerivatives");
}
fmi3Status fmi3ActivateModelPartition(fmi3Instance i, fmi3ValueReference clock, fmi3Float64 t) {
    (void)clock; (void)t;
    return not_supported(i, "fmi3ActivateModelPartition");
}

/* ---- FMU state ---- */
fmi3Status fmi3GetFMUState(fmi3Instance i, fmi3FMUState *s) { return (fmi3Status)fmi2GetFMUstate(i, s); }
fmi3Status fmi3SetFMUState(fmi3Instance i, fmi3FMUState s) { return (fmi3Status)fmi2SetFMUstate(i, s); }
fmi3Status fmi3FreeFMUState(fmi3Instance i, fmi3FMUState *s) { return (fmi3Status)fmi2FreeFMUstate(i, s); }
fmi3Status fmi3SerializedFMUStateSize(fmi3Instance i, fmi3FMUState s, size_t *n) {
    return (fmi3Status)fmi2SerializedFMUstateSize(i, s, n);
}
fmi3Status fmi3SerializeFMUState(fmi3Instance i, fmi3FMUState s, fmi3Byte b[], size_t n) {
    return (fmi3Status)fmi2SerializeFMUstate(i, s, (fmi2Byte *)b, n);
}
fmi3Status fmi3DeserializeFMUState(fmi3Instance i, const fmi3Byte b[], size_t n, fmi3FMUState *s) {
    return (fmi3Status)fmi2DeSerializeFMUstate(i, (const fmi2Byte *)b, n, s);
}

/* ---- model exchange ---- */
fmi3Status fmi3EnterContinuousTimeMode(fmi3Instance i) { return (fmi3Status)fmi2EnterContinuousTimeMode(i); }
fmi3Status fmi3CompletedIntegratorStep(fmi3Instance i, fmi3Boolean no_set, fmi3Boolean *enter, fmi3Boolean *term) {
    fmi2Boolean e = fmi2False, t = fmi2False;
    fmi2Status s = fmi2CompletedIntegratorStep(i, no_set ? fmi2True : fmi2False, &e, &t);
    if (enter) *enter = e != fmi2False;
    if (term) *term = t != fmi2False;
    return (fmi3Status)s;
}
fmi3Status fmi3SetTime(fmi3Instance i, fmi3Float64 t) { return (fmi3Status)fmi2SetTime(i, t); }
fmi3Status fmi3SetContinuousStates(fmi3Instance i, const fmi3Float64 x[], size_t nx) {
    return (fmi3Status)fmi2SetContinuousStates(i, x, nx);
}
fmi3Status fmi3GetContinuousStateDerivatives(fmi3Instance i, fmi3Float64 dx[], size_t nx) {
    return (fmi3Status)fmi2GetDerivatives(i, dx, nx);
}
fmi3Status fmi3GetEventIndicators(fmi3Instance i, fmi3Float64 z[], size_t nz) {
    return (fmi3Status)fmi2GetEventIndicators(i, z, nz);
}
fmi3Status fmi3GetContinuousStates(fmi3Instance i, fmi3Float64 x[], size_t nx) {
    return (fmi3Status)fmi2GetContinuousStates(i, x, nx);
}
fmi3Status fmi3GetNominalsOfContinuousStates(fmi3Instance i, fmi3Float64 x[], size_t nx) {
    return (fmi3Status)fmi2GetNominalsOfContinuousStates(i, x, nx);
}
fmi3Status fmi3GetNumberOfEventIndicators(fmi3Instance i, size_t *n) {
    (void)i;
    if (!n) return fmi3Error;
    *n = PRSM_N_EVENT_INDICATORS;
    return fmi3OK;
}
fmi3Status fmi3GetNumberOfContinuousStates(fmi3Instance i, size_t *n) {
    (void)i;
    if (!n) return fmi3Error;
    *n = ME_NX;
    return fmi3OK;
}
fmi3Status fmi3UpdateDiscreteStates(fmi3Instance i, fmi3Boolean *need_update, fmi3Boolean *term,
                                    fmi3Boolean *nominals_changed, fmi3Boolean *values_changed,
                                    fmi3Boolean *next_defined, fmi3Float64 *next_time) {
    component *c = (component *)i;
    fmi2EventInfo info = {fmi2False, fmi2False, fmi2False, fmi2False, fmi2False, 0.0};
    fmi2Status s = c && c->model_exchange ? fmi2NewDiscreteStates(i, &info) : fmi2OK;
    if (need_update) *need_update = info.newDiscreteStatesNeeded != fmi2False;
    if (term) *term = info.terminateSimulation != fmi2False;
    if (nominals_changed) *nominals_changed = info.nominalsOfContinuousStatesChanged != fmi2False;
    if (values_changed) *values_changed = info.valuesOfContinuousStatesChanged != fmi2False;
    if (next_defined) *next_defined = info.nextEventTimeDefined != fmi2False;
    if (next_time) *next_time = info.nextEventTime;
    return (fmi3Status)s;
}

/* ---- co-simulation ---- */
fmi3Status fmi3EnterStepMode(fmi3Instance i) {
    component *c = (component *)i;
    if (!c || c->model_exchange || c->s.phase != PH_STEPPING) return not_supported(i, "fmi3EnterStepMode here");
    return fmi3OK;
}

fmi3Status fmi3DoStep(fmi3Instance i, fmi3Float64 t, fmi3Float64 h, fmi3Boolean no_set,
                      fmi3Boolean *event_needed, fmi3Boolean *term, fmi3Boolean *early,
                      fmi3Float64 *last_time) {
    fmi2Status s = fmi2DoStep(i, t, h, no_set ? fmi2True : fmi2False);
    component *c = (component *)i;
    if (event_needed) *event_needed = false;
    if (term) *term = false;
    if (early) *early = false;
    if (last_time && c) *last_time = c->s.t;
    return (fmi3Status)s;
}
