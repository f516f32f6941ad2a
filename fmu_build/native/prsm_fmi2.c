/* FMI 2.0 co-simulation interface of the native PRSM FMU (kinematic, quasi-static and dynamic
 * levels, and auto: prsm_auto.c).
 *
 * The variable table (names, value references, types, start values) is the Python FMU's,
 * generated into prsm_variables.h by fmu_build.native; the physics is prsm_model.c.
 *
 * What a host sees (docs/fmu.md, "The native FMU"):
 *  - state machine: instantiated -> (setupExperiment) -> initialization mode -> stepping ->
 *    terminated; a call outside its state is refused with fmi2Error and a logged message;
 *  - parameters (causality parameter) can be set before exitInitializationMode, the geometry
 *    included: exitInitializationMode solves its contact (prsm_geometry.c);
 *  - exitInitializationMode checks every parameter and refuses (fmi2Error, logged, the FMU stays
 *    in initialization mode) a value out of range (the rows of prsm_params_gen.h, generated from
 *    prsm_fmu/param_ranges.py: the Python FMU's rules and messages), a stepper the
 *    level does not run here (kinematic, quasi-static: default = closed_form, closed_form_explicit,
 *    explicit_adaptive;
 *    dynamic and auto: default, rosenbrock), fidelity auto for model exchange, or a value of a
 *    parameter this code does not model (it must stay at its start value, 0);
 *  - doStep refuses with fmi2Discard (logged, state unchanged) a non-finite or non-positive
 *    step or one too small to advance the time, non-finite inputs or inputs out of their
 *    bounds, a failed integration, a step that would end out of the state's bounds; with
 *    fmi2Error a communication point that is not the FMU's time (within PRSM_TIME_MATCH);
 *  - fmi2Terminated reads true after fmi2Terminate or after the same doStep refused twice;
 *  - every fmi2FMUstate handed in is checked (tag, owning instance) before it is read or
 *    written;
 *  - the FMU state holds everything that decides the next step (parameters, inputs, time,
 *    state vector, inputs held, counters, stepper memory) and is checked whole when restored.
 */
#include <math.h>
#include <stdarg.h>
#include <stdio.h>
#include <stdlib.h>
#include <string.h>

#include "fmi2Functions.h"
#include "prsm_auto.h"
#include "prsm_model.h"
#include "prsm_quantity.h"
#include "prsm_bounds.h"

enum { T_REAL, T_INTEGER, T_BOOLEAN, T_STRING, T_ENUM };
enum { K_INPUT, K_OUTPUT, K_COUNTER, K_PARAM };
enum { C_RHS_CALLS, C_SUBSTEPS, C_FIDELITY, C_CONTACT };

typedef struct {
    fmi2ValueReference vr;
    int type, kind, index;
    const char *name;
} prsm_var;

typedef struct {
    int value;
    const char *name;
} prsm_enum_item;

typedef struct {
    int type, index;
    const char *name;
} prsm_par_ref;

#define PRSM_STR_LEN 64

#include "prsm_variables.h"
#include "prsm_params_gen.h"

enum { PH_INSTANTIATED, PH_INITIALIZATION, PH_STEPPING, PH_TERMINATED };
static const char *const PHASE_NAMES[] = {"instantiated", "initialization mode", "stepping",
                                          "terminated"};

#define MAGIC "PRSMNAT2"

/* everything an FMU state holds (also the serialized bytes) */
typedef struct {
    char magic[8];
    char guid[64];
    int n_stages;
    int phase;
    double par_real[N_PAR_REAL > 0 ? N_PAR_REAL : 1];
    int par_int[N_PAR_INT > 0 ? N_PAR_INT : 1];
    int par_bool[N_PAR_BOOL > 0 ? N_PAR_BOOL : 1];
    char par_str[N_PAR_STRING > 0 ? N_PAR_STRING : 1][PRSM_STR_LEN];
    double u[2];
    double t;
    double x[PRSM_NX_MAX];
    double u_held[2];
    int stats[3];
    prsm_memory mem;
    int auto_start;            /* fidelity auto: the level chosen at initialization (0 kinematic,
                                  1 quasi-static, 2 dynamic) */
    prsm_auto_memory amem;     /* fidelity auto (unless it chose kinematic): its stepper's memory */
} snapshot;

/* the preview's model (compute_outputs before exitInitializationMode) and the snapshot it was
 * built from (from: its parameters, and for fidelity auto its inputs, which choose the start
 * level); valid while ok */
struct preview_cache {
    int ok;
    snapshot from;
    prsm_model model;
    int is_auto;
    prsm_auto au;
};

typedef struct {
    snapshot s;
    /* valid in phases stepping and terminated (auto: au.dyn), and then built (with au and
       is_auto) by build_model from the parameters s holds: they are fixed from
       exitInitializationMode on, and fmi2SetFMUstate replaces them only with the model of the
       state it restores (model_built_from) */
    prsm_model model;
    int is_auto;               /* auto switches between the dynamic and quasi-static level (au) */
    prsm_auto au;
    double y[N_OUT_REAL > 0 ? N_OUT_REAL : 1];
    int y_valid;
    /* before exitInitializationMode the outputs are a preview of the start state (compute_outputs)
       on a model built from the parameters: that model, kept by preview_model (allocated on the
       first preview, NULL before it) */
    struct preview_cache *pv;
    fmi2CallbackFunctions cb;
    char name[256];
    int logging_on;
    /* the last refused doStep (t, h, inputs) and whether it was refused twice in a row exactly
       as called: the FMU is deterministic, so that call cannot succeed (fmi2Terminated) */
    double refused_call[4];
    int has_refused, stuck;
    int model_exchange;        /* instantiated as fmi2ModelExchange (prsm_fmi2_me.c) */
} component;

/* ---- logging ----------------------------------------------------------------------------------- */
static void log_msg(component *c, fmi2Status status, const char *fmt, ...) {
    if (!c->cb.logger) return;
    if (status == fmi2OK && !c->logging_on) return;
    char raw[2048], esc[4200];
    va_list ap;
    va_start(ap, fmt);
    vsnprintf(raw, sizeof raw, fmt, ap);
    va_end(ap);
    size_t j = 0;       /* the logger's message is a format: a literal % is %% */
    for (size_t i = 0; raw[i] && j + 2 < sizeof esc; i++) {
        if (raw[i] == '%') esc[j++] = '%';
        esc[j++] = raw[i];
    }
    esc[j] = 0;
    const char *category = status == fmi2Error ? "logStatusError"
                           : status == fmi2Discard ? "logStatusDiscard"
                           : status == fmi2Warning ? "logStatusWarning" : "logAll";
    c->cb.logger(c->cb.componentEnvironment, c->name, status, category, esc);
}

/* ---- parameters ------------------------------------------------------------------------------- */
static const char *choice(const snapshot *s, int type, int index, const prsm_enum_item *items,
                          int n_items) {
    if (type == T_STRING) return s->par_str[index];
    for (int i = 0; i < n_items; i++)
        if (items[i].value == s->par_int[index]) return items[i].name;
    return NULL;
}

/* the message of an Enumeration value that is no item (configure._choice's words) */
static void no_item(char *msg, int len, const char *kind, int value, const prsm_enum_item *items,
                    int n_items) {
    int j = snprintf(msg, (size_t)len, "%s = %d is not allowed: must be one of ", kind, value);
    for (int i = 0; i < n_items && j > 0 && j < len; i++)
        j += snprintf(msg + j, (size_t)(len - j), "%s%d (%s)", i ? ", " : "", items[i].value,
                      items[i].name);
}

/* step_fidelity (configure.LEVEL_CODES): kinematic 0, quasi-static 1, dynamic 2 */
static int model_level(const prsm_model *m) { return m->kinematic ? 0 : m->dynamic ? 2 : 1; }

static int level_code(const char *fidelity) {
    if (!fidelity) return 0;
    if (!strcmp(fidelity, "quasi-static") || !strcmp(fidelity, "auto")) return 1;
    if (!strcmp(fidelity, "dynamic")) return 2;
    return 0;
}

/* ---- parameter ranges: the walker of the generated table (prsm_params_gen.h) --------------- */
static const prsm_var *param_var(const char *name) {
    for (int i = 0; i < PRSM_N_VARS; i++)
        if (PRSM_VARS[i].kind == K_PARAM && !strcmp(PRSM_VARS[i].name, name)) return &PRSM_VARS[i];
    return NULL;
}

/* the value of a Real or Integer parameter as a double; 0: not a settable parameter here */
static int param_value(const snapshot *s, const char *name, double *value, int *is_int) {
    const prsm_var *v = param_var(name);
    if (!v) return 0;
    *is_int = v->type != T_REAL;
    if (v->type == T_REAL) *value = s->par_real[v->index];
    else if (v->type == T_INTEGER || v->type == T_ENUM) *value = (double)s->par_int[v->index];
    else return 0;
    return 1;
}

/* Range.check of every row in order (the bounds that follow from a stage's geometry evaluated
 * from its current values: FmuRule.derived); 0, or -1 and Range.message in msg */
static int check_ranges(const snapshot *s, char *msg, int len) {
    for (int i = 0; i < PRSM_N_RANGES; i++) {
        const prsm_range *r = &PRSM_RANGES[i];
        double v, w, lo = r->lo, hi = r->hi;
        int is_int, w_int, has_hi = r->has_hi;
        if (!param_value(s, r->name, &v, &is_int)) continue;
        if (r->when && !(param_value(s, r->when, &w, &w_int) && w > 0.0)) continue;
        if (r->derived) {       /* the stage's radii were checked by earlier rows */
            double r_s, r_r;
            char name[48];
            snprintf(name, sizeof name, "stage[%d].screw_radius", r->stage);
            if (!param_value(s, name, &r_s, &w_int)) continue;
            if (r->derived == PRSM_DERIVED_MAX_ROLLERS) {
                snprintf(name, sizeof name, "stage[%d].roller_radius", r->stage);
                if (!param_value(s, name, &r_r, &w_int)) continue;
                /* param_ranges.max_rollers: int(pi / asin(r_R / (r_S + r_R)) + 1e-9) */
                hi = floor(PRSM_PI / asin(r_r / (r_s + r_r)) + 1e-9);
            } else {
                lo = PRSM_SPLINE_MIN_FRACTION * r_s;
                hi = r_s;
            }
            has_hi = 1;
        }
        if (r->hi_parameter) {
            if (!param_value(s, r->hi_parameter, &w, &w_int)) continue;
            hi = w;
            has_hi = 1;
        }
        int ok = (r->integer ? is_int : !is_int) && isfinite(v) && v >= lo
                 && !(r->lo_open && v == lo) && (!has_hi || v < hi || (v == hi && !r->hi_open));
        if (ok) continue;
        char val[40], lo_s[40], up[400];
        if (is_int) snprintf(val, sizeof val, "%d", (int)v);
        else prsm_fmt_num(val, sizeof val, v);
        if (r->integer) {       /* integers held as doubles (a derived bound may pass INT_MAX) */
            snprintf(lo_s, sizeof lo_s, "%.0f", lo);
            snprintf(up, sizeof up, "%.0f", hi);
        } else {
            prsm_fmt_num(lo_s, sizeof lo_s, lo);
            prsm_fmt_num(up, sizeof up, hi);
        }
        const char *sp = r->unit[0] ? " " : "";
        snprintf(msg, (size_t)len, "%s = %s%s%s is out of range: must be %s%s%s, %s%s%s%s%s%s%s",
                 r->name, val, sp, r->unit, r->integer ? "an integer in " : "in ",
                 r->lo_open ? "(" : "[", lo_s, has_hi ? up : "inf",
                 !has_hi ? ")" : r->hi_open ? ")" : "]", sp, r->unit,
                 r->note[0] ? " (" : "", r->note, r->note[0] ? ")" : "");
        return -1;
    }
    return 0;
}

/* StageParams.validate's checks besides the table, stage by stage: the flank angle in (0, pi/2),
 * r_N = r_S + 2 r_R and r_N = n_S r_R (relative PRSM_GEOMETRY_RTOL), its messages character for
 * character; 0, or -1 with the message */
static int check_geometry(const snapshot *s, char *msg, int len) {
    for (int k = 0; k < PRSM_N_STAGES; k++) {
        double beta = s->par_real[P_FLANK_ANGLE[k]], r_n = s->par_real[P_NUT_RADIUS[k]];
        double r_s = s->par_real[P_SCREW_RADIUS[k]], r_r = s->par_real[P_ROLLER_RADIUS[k]];
        int n_s = s->par_int[P_SCREW_STARTS[k]];
        char a[40], b[40];
        if (!(isfinite(beta) && 0.0 < beta && beta < PRSM_PI / 2.0)) {
            prsm_fmt_num(a, sizeof a, beta);
            snprintf(msg, (size_t)len, "stage[%d].flank_angle = %s rad is out of range: must be "
                     "in (0, pi/2) rad, i.e. (0\u00b0, 90\u00b0)", k + 1, a);
            return -1;
        }
        double fit = r_s + 2.0 * r_r, engaged = (double)n_s * r_r;
        prsm_fmt_num(a, sizeof a, r_n);
        if (fabs(r_n - fit) > PRSM_GEOMETRY_RTOL * fit) {
            prsm_fmt_num(b, sizeof b, fit);
            snprintf(msg, (size_t)len, "stage[%d].nut_radius = %s m is inconsistent with "
                     "screw_radius + 2*roller_radius = %s m: must equal it (relative tolerance "
                     "%g)", k + 1, a, b, PRSM_GEOMETRY_RTOL);
            return -1;
        }
        if (fabs(r_n - engaged) > PRSM_GEOMETRY_RTOL * engaged) {
            prsm_fmt_num(b, sizeof b, engaged);
            snprintf(msg, (size_t)len, "stage[%d].nut_radius = %s m is inconsistent with the roller "
                     "lead: a single-start roller of lead pitch = screw_lead/screw_starts stays "
                     "engaged with the nut only if nut_radius = screw_starts*roller_radius = %s m "
                     "(relative tolerance %g)", k + 1, a, b, PRSM_GEOMETRY_RTOL);
            return -1;
        }
    }
    return 0;
}

/* the model's configuration from the parameters; 0, or -1 with the reason */
static int configuration(const snapshot *s, prsm_config *cfg, char *msg, int len) {
    memset(cfg, 0, sizeof *cfg);
    if (check_ranges(s, msg, len)) return -1;
    if (check_geometry(s, msg, len)) return -1;
    for (int k = 0; k < PRSM_N_STAGES; k++) {
        prsm_stage_values *v = &cfg->stage[k];
        v->screw_mass = s->par_real[P_SCREW_MASS[k]];
        v->nut_mass = s->par_real[P_NUT_MASS[k]];
        v->roller_mass = s->par_real[P_ROLLER_MASS[k]];
        v->carrier_mass = s->par_real[P_CARRIER_MASS[k]];
        v->screw_inertia = s->par_real[P_SCREW_INERTIA[k]];
        v->roller_inertia = s->par_real[P_ROLLER_INERTIA[k]];
        v->carrier_inertia = s->par_real[P_CARRIER_INERTIA[k]];
        v->spline_radius = s->par_real[P_SPLINE_RADIUS[k]];
        v->bearing_radius = s->par_real[P_BEARING_RADIUS[k]];
        v->n_rollers = s->par_int[P_N_ROLLERS[k]];
        v->carriers = s->par_int[P_CARRIERS[k]];
        cfg->threads_per_roller[k] = s->par_int[P_THREADS_PER_ROLLER[k]];
        v->screw_radius = s->par_real[P_SCREW_RADIUS[k]];
        v->roller_radius = s->par_real[P_ROLLER_RADIUS[k]];
        v->nut_radius = s->par_real[P_NUT_RADIUS[k]];
        v->screw_lead = s->par_real[P_SCREW_LEAD[k]];
        v->flank_angle = s->par_real[P_FLANK_ANGLE[k]];
        v->screw_starts = s->par_int[P_SCREW_STARTS[k]];
    }
    cfg->mu_screw_roller = s->par_real[P_MU_SCREW_ROLLER];
    cfg->mu_spline = s->par_real[P_MU_SPLINE];
    cfg->mu_nut_screw = s->par_real[P_MU_NUT_SCREW];
    cfg->mu_viscous = s->par_real[P_MU_VISCOUS];
    cfg->mu_differential = s->par_real[P_MU_DIFFERENTIAL];
    cfg->slip_velocity_scale = s->par_real[P_SLIP_VELOCITY_SCALE];
    cfg->tolerance = s->par_real[P_TOLERANCE];
    cfg->substeps = s->par_int[P_SUBSTEPS];
    cfg->max_substeps = s->par_int[P_MAX_SUBSTEPS];
    cfg->kinematic_efficiency = s->par_real[P_KINEMATIC_EFFICIENCY];
    /* parameters this code does not model: only their start value (zero: the term is absent) */
    for (int i = 0; i < N_UNMODELLED; i++) {
        const prsm_par_ref *p = &UNMODELLED[i];
        int same = p->type == T_REAL ? s->par_real[p->index] == PAR_REAL_START[p->index]
                   : p->type == T_BOOLEAN ? s->par_bool[p->index] == PAR_BOOL_START[p->index]
                   : p->type == T_STRING ? !strcmp(s->par_str[p->index], PAR_STRING_START[p->index])
                   : s->par_int[p->index] == PAR_INT_START[p->index];
        if (!same) {
            snprintf(msg, (size_t)len, "%s is not modelled by the native FMU: it must stay at its "
                     "start value (the term is absent); use the Python FMU for it", p->name);
            return -1;
        }
    }
    const char *fid = choice(s, P_FIDELITY_TYPE, P_FIDELITY, P_FIDELITY_ITEMS, P_FIDELITY_N_ITEMS);
    if (!fid) {
        no_item(msg, len, "fidelity", s->par_int[P_FIDELITY], P_FIDELITY_ITEMS, P_FIDELITY_N_ITEMS);
        return -1;
    }
    if (!strcmp(fid, "kinematic")) cfg->kinematic = 1;
    else if (!strcmp(fid, "quasi-static")) cfg->kinematic = 0;
    else if (!strcmp(fid, "dynamic") || !strcmp(fid, "auto")) cfg->dynamic = 1;
    else {
        snprintf(msg, (size_t)len, "fidelity = '%s' is not allowed: must be one of kinematic, "
                 "quasi-static, dynamic, auto (native FMU)", fid);
        return -1;
    }
    const char *st = choice(s, P_STEPPER_TYPE, P_STEPPER, P_STEPPER_ITEMS, P_STEPPER_N_ITEMS);
    if (!st) {
        no_item(msg, len, "stepper", s->par_int[P_STEPPER], P_STEPPER_ITEMS, P_STEPPER_N_ITEMS);
        return -1;
    }
    /* the slaved levels run the Python FMU's default, closed_form (the friction band stepped by
     * the exponential step of prsm_band.c), or closed_form_explicit (Dormand-Prince 5(4) in the
     * band) or explicit_adaptive; the dynamic level the Python FMU's default, ROS34PW2, and
     * auto its dynamic steps with ROS34PW2 (the engine's method of the Python FMU). */
    if (cfg->dynamic) {
        if (strcmp(st, "default") && strcmp(st, "rosenbrock")) {
            snprintf(msg, (size_t)len, "stepper = '%s' is not allowed with fidelity = '%s' in "
                     "the native FMU: must be one of default (= rosenbrock), rosenbrock", st, fid);
            return -1;
        }
    } else if (!strcmp(st, "default") || !strcmp(st, "closed_form")) {
        cfg->closed_form = 1;
        cfg->band_exponential = 1;
    } else if (!strcmp(st, "closed_form_explicit")) cfg->closed_form = 1;
    else if (!strcmp(st, "explicit_adaptive")) cfg->closed_form = 0;
    else {
        snprintf(msg, (size_t)len, "stepper = '%s' is not allowed in the native FMU: must be one of "
                 "default (= closed_form), closed_form, closed_form_explicit, explicit_adaptive", st);
        return -1;
    }
    return 0;
}

static int is_auto_fidelity(const snapshot *s) {
    const char *fid = choice(s, P_FIDELITY_TYPE, P_FIDELITY, P_FIDELITY_ITEMS, P_FIDELITY_N_ITEMS);
    return fid && !strcmp(fid, "auto");
}

/* fidelity auto: the level to start with (s->auto_start) from the parameters and the inputs
 * at the start (configure: choose_for_start under the torque drive); the estimated model errors
 * of the kinematic and quasi-static level in errors.  0, or -1 with the reason. */
static int choose_start(snapshot *s, double errors[2], char *msg, int len) {
    prsm_config cfg;
    if (configuration(s, &cfg, msg, len)) return -1;
    double eff = cfg.kinematic_efficiency;
    int level = prsm_auto_choose(&cfg, cfg.tolerance, s->u, s->par_real[P_INITIAL_SCREW_SPEED],
                                 !s->par_bool[P_INITIAL_CARRIER_EQUILIBRIUM],
                                 isfinite(eff) && 0.0 < eff && eff <= 1.0 ? eff : 1.0, errors, msg,
                                 len);
    if (level < 0) return -1;
    s->auto_start = level;
    return 0;
}

/* The model of the parameters into m, and for fidelity auto (unless it starts kinematic, with
 * s->auto_start chosen) its switching stepper into au (*is_auto = 1; m is then its dynamic
 * level).  0, or -1 with the reason. */
static int build_model(const snapshot *s, prsm_model *m, prsm_auto *au, int *is_auto, char *msg,
                       int len) {
    prsm_config cfg;
    *is_auto = 0;
    if (configuration(s, &cfg, msg, len)) return -1;
    if (is_auto_fidelity(s)) {
        if (s->auto_start < 0 || s->auto_start > 2) {
            snprintf(msg, (size_t)len, "bad start level %d of fidelity auto", s->auto_start);
            return -1;
        }
        if (s->auto_start == 0) {      /* the kinematic level, with its default stepper */
            const char *st = choice(s, P_STEPPER_TYPE, P_STEPPER, P_STEPPER_ITEMS,
                                    P_STEPPER_N_ITEMS);
            if (strcmp(st, "default")) {
                snprintf(msg, (size_t)len, "stepper = '%s' is not allowed when fidelity = 'auto' "
                         "starts with the kinematic level in the native FMU: must be default "
                         "(= closed_form)", st);
                return -1;
            }
            cfg.kinematic = 1;
            cfg.dynamic = 0;
            cfg.closed_form = 1;
            cfg.band_exponential = 1;
            return prsm_model_init(m, &cfg, msg, len);
        }
        if (prsm_auto_init(au, &cfg, cfg.tolerance, s->auto_start == 2 ? PRSM_AUTO_DYNAMIC
                                                                      : PRSM_AUTO_QUASI_STATIC,
                           msg, len))
            return -1;
        *m = au->dyn;
        *is_auto = 1;
        return 0;
    }
    return prsm_model_init(m, &cfg, msg, len);
}

/* step_fidelity of an auto stepper's memory (configure.LEVEL_CODES) */
static int auto_level(const prsm_auto_memory *mem) {
    return mem->mode == PRSM_AUTO_QUASI_STATIC ? 1 : 2;
}

static void set_starts(snapshot *s) {
    memset(s, 0, sizeof *s);
    memcpy(s->magic, MAGIC, 8);
    snprintf(s->guid, sizeof s->guid, "%s", PRSM_GUID);
    s->n_stages = PRSM_N_STAGES;
    s->phase = PH_INSTANTIATED;
    for (int i = 0; i < N_PAR_REAL; i++) s->par_real[i] = PAR_REAL_START[i];
    for (int i = 0; i < N_PAR_INT; i++) s->par_int[i] = PAR_INT_START[i];
    for (int i = 0; i < N_PAR_BOOL; i++) s->par_bool[i] = PAR_BOOL_START[i];
    for (int i = 0; i < N_PAR_STRING; i++)
        snprintf(s->par_str[i], PRSM_STR_LEN, "%s", PAR_STRING_START[i]);
    s->u[0] = INPUT_START[0];
    s->u[1] = INPUT_START[1];
    const char *fid = choice(s, P_FIDELITY_TYPE, P_FIDELITY, P_FIDELITY_ITEMS, P_FIDELITY_N_ITEMS);
    s->stats[2] = level_code(fid);
}

/* ---- outputs ------------------------------------------------------------------------------------ */
/* Do snapshots a and b hold the same parameters, byte for byte? */
static int same_parameters(const snapshot *a, const snapshot *b) {
    return !memcmp(a->par_real, b->par_real, sizeof a->par_real)
           && !memcmp(a->par_int, b->par_int, sizeof a->par_int)
           && !memcmp(a->par_bool, b->par_bool, sizeof a->par_bool)
           && !memcmp(a->par_str, b->par_str, sizeof a->par_str);
}

/* The preview's model (c->pv->model, and for fidelity auto c->pv->au where c->pv->is_auto)
 * for the parameters c->s holds now.  build_model reads the parameters and auto_start of its
 * snapshot and nothing else, choose_start (fidelity auto) the parameters and the inputs, and
 * both are deterministic; using the model changes only its lazily computed slaved laws, functions
 * of its built constants alone (model_built_from).  So the model built from pv->from is
 * reused while c->s holds the same parameters byte for byte (and for fidelity auto the same
 * inputs): whatever sets a parameter (fmi2Set*, fmi2Reset, fmi2SetFMUstate) changes what is
 * compared, and no call needs to drop the model itself.  A model that fails to build is not
 * kept.  0, or -1 and the reason. */
static int preview_model(component *c, char *msg, int len) {
    struct preview_cache *pv = c->pv;
    int is_auto = is_auto_fidelity(&c->s);
    if (pv && pv->ok && same_parameters(&pv->from, &c->s)
        && (!is_auto || !memcmp(pv->from.u, c->s.u, sizeof c->s.u)))
        return 0;
    if (!pv) {
        pv = c->pv = (struct preview_cache *)malloc(sizeof *pv);
        if (!pv) {
            snprintf(msg, (size_t)len, "out of memory");
            return -1;
        }
    }
    double errors[2];
    pv->ok = 0;
    pv->from = c->s;
    if ((is_auto && choose_start(&pv->from, errors, msg, len))
        || build_model(&pv->from, &pv->model, &pv->au, &pv->is_auto, msg, len))
        return -1;
    pv->ok = 1;
    return 0;
}

static void compute_outputs(component *c) {
    int previewing = c->s.phase < PH_STEPPING;
    const prsm_model *m = &c->model;
    prsm_auto *au = c->is_auto ? &c->au : NULL;
    int mode = c->s.amem.mode;
    const double *x = c->s.x, *u = c->s.u_held;
    double x0[PRSM_NX_MAX];
    if (previewing) {      /* before exitInitializationMode: the initial state */
        char msg[600];
        if (preview_model(c, msg, sizeof msg)) {
            log_msg(c, fmi2Error, "outputs cannot be computed: %s", msg);
            for (int i = 0; i < N_OUT_REAL; i++) c->y[i] = NAN;
            return;
        }
        m = &c->pv->model;
        au = c->pv->is_auto ? &c->pv->au : NULL;
        if (au) mode = au->start;
        prsm_initial_state(m, x0, c->s.par_real[P_INITIAL_SCREW_ANGLE],
                           c->s.par_real[P_INITIAL_SCREW_SPEED],
                           c->s.par_bool[P_INITIAL_CARRIER_EQUILIBRIUM]);
        x = x0;
        u = c->s.u;
    } else if (c->model_exchange) {      /* model exchange: the inputs act at once */
        u = c->s.u;
    }
    prsm_outputs o;
    double xl[PRSM_NX_MAX];
    if (au) {       /* AdaptiveModel.outputs: the level of the last step (before it: the start) */
        m = prsm_auto_outputs_at(au, mode, x, u, xl, &o);
        x = xl;
    } else {
        prsm_outputs_at((prsm_model *)m, x, u, &o);
    }
    for (int i = 0; i < N_OUT_REAL; i++)
        c->y[i] = prsm_quantity(m, x, u, &o, OUT_QUANTITY[i], OUT_STAGE[i]);
    if (!previewing) c->y_valid = 1;
}

/* contact_status: 1 where the rigid contact has no solution at the current state and inputs */
static int contact_status(component *c) {
    if (c->s.phase != PH_STEPPING || !isfinite(c->s.u[0]) || !isfinite(c->s.u[1])) return 0;
    prsm_outputs o;
    prsm_outputs_at(&c->model, c->s.x, c->s.u, &o);
    return o.consistent ? 0 : 1;
}

/* ---- variable access ------------------------------------------------------------------------------ */
static const char *TYPE_NAMES[] = {"Real", "Integer", "Boolean", "String", "Enumeration"};

static const prsm_var *lookup(component *c, fmi2ValueReference vr, int type, const char *action) {
    if (vr > PRSM_MAX_VR || VR_INDEX[vr] < 0) {
        log_msg(c, fmi2Error, "fmi2%s%s: value reference %u is no variable", action,
                TYPE_NAMES[type], (unsigned)vr);
        return NULL;
    }
    const prsm_var *v = &PRSM_VARS[VR_INDEX[vr]];
    int ok = v->type == type || (type == T_INTEGER && v->type == T_ENUM);
    if (!ok) {
        log_msg(c, fmi2Error, "fmi2%s%s: value reference %u is '%s', of type %s, not %s", action,
                TYPE_NAMES[type], (unsigned)vr, v->name, TYPE_NAMES[v->type], TYPE_NAMES[type]);
        return NULL;
    }
    return v;
}

/* may variable v be set now? */
static int settable(component *c, const prsm_var *v, const char *type) {
    if (v->kind == K_INPUT) {
        if (c->s.phase == PH_TERMINATED) {
            log_msg(c, fmi2Error, "fmi2Set%s: input '%s' cannot be set after fmi2Terminate", type, v->name);
            return 0;
        }
        return 1;
    }
    if (v->kind == K_PARAM) {
        if (c->s.phase >= PH_STEPPING) {
            log_msg(c, fmi2Error, "fmi2Set%s: '%s' is a fixed parameter: setting it after "
                    "initialization is not allowed; the value is unchanged", type, v->name);
            return 0;
        }
        return 1;
    }
    log_msg(c, fmi2Error, "fmi2Set%s: '%s' is an output and cannot be set", type, v->name);
    return 0;
}

#define COMPONENT_OR_ERROR(comp) \
    component *c = (component *)(comp); \
    if (!c) return fmi2Error

fmi2Status fmi2GetReal(fmi2Component comp, const fmi2ValueReference vr[], size_t nvr, fmi2Real value[]) {
    COMPONENT_OR_ERROR(comp);
    if (nvr > 0 && (!vr || !value)) return fmi2Error;
    /* the preview's outputs (before exitInitializationMode) are not kept from call to call (an
       input set in between changes them): computed once in this call, for all it asks */
    int computed = 0;
    for (size_t i = 0; i < nvr; i++) {
        const prsm_var *v = lookup(c, vr[i], T_REAL, "Get");
        if (!v) return fmi2Error;
        switch (v->kind) {
        case K_INPUT: value[i] = c->s.u[v->index]; break;
        case K_PARAM: value[i] = c->s.par_real[v->index]; break;
        default:
            if (!c->y_valid && !computed) {
                compute_outputs(c);
                computed = 1;
            }
            value[i] = c->y[v->index];
        }
    }
    return fmi2OK;
}

fmi2Status fmi2GetInteger(fmi2Component comp, const fmi2ValueReference vr[], size_t nvr, fmi2Integer value[]) {
    COMPONENT_OR_ERROR(comp);
    if (nvr > 0 && (!vr || !value)) return fmi2Error;
    for (size_t i = 0; i < nvr; i++) {
        const prsm_var *v = lookup(c, vr[i], T_INTEGER, "Get");
        if (!v) return fmi2Error;
        switch (v->kind) {
        case K_PARAM: value[i] = c->s.par_int[v->index]; break;
        case K_COUNTER:
            if (COUNTER_QUANTITY[v->index] == C_CONTACT) {
                value[i] = contact_status(c);
            } else {
                value[i] = c->s.stats[COUNTER_QUANTITY[v->index]];
            }
            break;
        default: return fmi2Error;
        }
    }
    return fmi2OK;
}

fmi2Status fmi2GetBoolean(fmi2Component comp, const fmi2ValueReference vr[], size_t nvr, fmi2Boolean value[]) {
    COMPONENT_OR_ERROR(comp);
    if (nvr > 0 && (!vr || !value)) return fmi2Error;
    for (size_t i = 0; i < nvr; i++) {
        const prsm_var *v = lookup(c, vr[i], T_BOOLEAN, "Get");
        if (!v) return fmi2Error;
        value[i] = c->s.par_bool[v->index] ? fmi2True : fmi2False;
    }
    return fmi2OK;
}

fmi2Status fmi2GetString(fmi2Component comp, const fmi2ValueReference vr[], size_t nvr, fmi2String value[]) {
    COMPONENT_OR_ERROR(comp);
    if (nvr > 0 && (!vr || !value)) return fmi2Error;
    for (size_t i = 0; i < nvr; i++) {
        const prsm_var *v = lookup(c, vr[i], T_STRING, "Get");
        if (!v) return fmi2Error;
        value[i] = c->s.par_str[v->index];
    }
    return fmi2OK;
}

fmi2Status fmi2SetReal(fmi2Component comp, const fmi2ValueReference vr[], size_t nvr, const fmi2Real value[]) {
    COMPONENT_OR_ERROR(comp);
    if (nvr > 0 && (!vr || !value)) return fmi2Error;
    for (size_t i = 0; i < nvr; i++) {      /* all checked before any is set */
        const prsm_var *v = lookup(c, vr[i], T_REAL, "Set");
        if (!v || !settable(c, v, "Real")) return fmi2Error;
    }
    for (size_t i = 0; i < nvr; i++) {
        const prsm_var *v = &PRSM_VARS[VR_INDEX[vr[i]]];
        if (v->kind == K_INPUT) c->s.u[v->index] = value[i];
        else c->s.par_real[v->index] = value[i];
    }
    if (c->model_exchange) c->y_valid = 0;
    return fmi2OK;
}

fmi2Status fmi2SetInteger(fmi2Component comp, const fmi2ValueReference vr[], size_t nvr, const fmi2Integer value[]) {
    COMPONENT_OR_ERROR(comp);
    if (nvr > 0 && (!vr || !value)) return fmi2Error;
    for (size_t i = 0; i < nvr; i++) {
        const prsm_var *v = lookup(c, vr[i], T_INTEGER, "Set");
        if (!v || !settable(c, v, "Integer")) return fmi2Error;
    }
    for (size_t i = 0; i < nvr; i++) c->s.par_int[PRSM_VARS[VR_INDEX[vr[i]]].index] = value[i];
    if (c->s.phase < PH_STEPPING) {
        const char *fid = choice(&c->s, P_FIDELITY_TYPE, P_FIDELITY, P_FIDELITY_ITEMS, P_FIDELITY_N_ITEMS);
        c->s.stats[2] = level_code(fid);
    }
    return fmi2OK;
}

fmi2Status fmi2SetBoolean(fmi2Component comp, const fmi2ValueReference vr[], size_t nvr, const fmi2Boolean value[]) {
    COMPONENT_OR_ERROR(comp);
    if (nvr > 0 && (!vr || !value)) return fmi2Error;
    for (size_t i = 0; i < nvr; i++) {
        const prsm_var *v = lookup(c, vr[i], T_BOOLEAN, "Set");
        if (!v || !settable(c, v, "Boolean")) return fmi2Error;
    }
    for (size_t i = 0; i < nvr; i++) c->s.par_bool[PRSM_VARS[VR_INDEX[vr[i]]].index] = value[i] ? 1 : 0;
    return fmi2OK;
}

fmi2Status fmi2SetString(fmi2Component comp, const fmi2ValueReference vr[], size_t nvr, const fmi2String value[]) {
    COMPONENT_OR_ERROR(comp);
    if (nvr > 0 && (!vr || !value)) return fmi2Error;
    for (size_t i = 0; i < nvr; i++) {
        const prsm_var *v = lookup(c, vr[i], T_STRING, "Set");
        if (!v || !settable(c, v, "String")) return fmi2Error;
        if (!value[i] || strlen(value[i]) >= PRSM_STR_LEN) {
            log_msg(c, fmi2Error, "fmi2SetString: the value of '%s' must be a string of at most %d "
                    "characters", v->name, PRSM_STR_LEN - 1);
            return fmi2Error;
        }
    }
    for (size_t i = 0; i < nvr; i++)
        snprintf(c->s.par_str[PRSM_VARS[VR_INDEX[vr[i]]].index], PRSM_STR_LEN, "%s", value[i]);
    if (c->s.phase < PH_STEPPING) {
        const char *fid = choice(&c->s, P_FIDELITY_TYPE, P_FIDELITY, P_FIDELITY_ITEMS, P_FIDELITY_N_ITEMS);
        c->s.stats[2] = level_code(fid);
    }
    return fmi2OK;
}

/* ---- life cycle ------------------------------------------------------------------------------------ */
const char *fmi2GetTypesPlatform(void) { return fmi2TypesPlatform; }
const char *fmi2GetVersion(void) { return fmi2Version; }

fmi2Status fmi2SetDebugLogging(fmi2Component comp, fmi2Boolean loggingOn, size_t n, const fmi2String categories[]) {
    COMPONENT_OR_ERROR(comp);
    (void)n;
    (void)categories;
    c->logging_on = loggingOn ? 1 : 0;
    return fmi2OK;
}

fmi2Component fmi2Instantiate(fmi2String instanceName, fmi2Type fmuType, fmi2String fmuGUID,
                              fmi2String fmuResourceLocation, const fmi2CallbackFunctions *functions,
                              fmi2Boolean visible, fmi2Boolean loggingOn) {
    (void)fmuResourceLocation;
    (void)visible;
    component tmp;
    memset(&tmp, 0, sizeof tmp);
    if (functions) tmp.cb = *functions;
    snprintf(tmp.name, sizeof tmp.name, "%s", instanceName ? instanceName : "");
    tmp.logging_on = loggingOn ? 1 : 0;
#ifdef PRSM_MODEL_EXCHANGE
    tmp.model_exchange = fmuType == fmi2ModelExchange;
#endif
    if (fmuType != fmi2CoSimulation && !tmp.model_exchange) {
        log_msg(&tmp, fmi2Error, "fmi2Instantiate: fmuType %d is not allowed: must be "
                "fmi2CoSimulation or fmi2ModelExchange", (int)fmuType);
        return NULL;
    }
    if (!fmuGUID || strcmp(fmuGUID, PRSM_GUID)) {
        log_msg(&tmp, fmi2Error, "fmi2Instantiate: GUID '%s' is not this FMU's ('%s')",
                fmuGUID ? fmuGUID : "(null)", PRSM_GUID);
        return NULL;
    }
    component *c = (component *)calloc(1, sizeof *c);
    if (!c) {
        log_msg(&tmp, fmi2Error, "fmi2Instantiate: out of memory");
        return NULL;
    }
    *c = tmp;
    set_starts(&c->s);
    return c;
}

void fmi2FreeInstance(fmi2Component comp) {
    component *c = (component *)comp;
    if (c) free(c->pv);
    free(c);
}

static fmi2Status wrong_phase(component *c, const char *call) {
    log_msg(c, fmi2Error, "%s is not allowed in %s", call, PHASE_NAMES[c->s.phase]);
    return fmi2Error;
}

fmi2Status fmi2SetupExperiment(fmi2Component comp, fmi2Boolean toleranceDefined, fmi2Real tolerance,
                               fmi2Real startTime, fmi2Boolean stopTimeDefined, fmi2Real stopTime) {
    COMPONENT_OR_ERROR(comp);
    (void)toleranceDefined; (void)tolerance; (void)stopTimeDefined; (void)stopTime;
    if (c->s.phase != PH_INSTANTIATED) return wrong_phase(c, "fmi2SetupExperiment");
    if (!isfinite(startTime)) {
        log_msg(c, fmi2Error, "fmi2SetupExperiment: startTime = %.17g s must be finite", startTime);
        return fmi2Error;
    }
    c->s.t = startTime;
    return fmi2OK;
}

fmi2Status fmi2EnterInitializationMode(fmi2Component comp) {
    COMPONENT_OR_ERROR(comp);
    if (c->s.phase != PH_INSTANTIATED) return wrong_phase(c, "fmi2EnterInitializationMode");
    c->s.phase = PH_INITIALIZATION;
    return fmi2OK;
}

fmi2Status fmi2ExitInitializationMode(fmi2Component comp) {
    COMPONENT_OR_ERROR(comp);
    if (c->s.phase != PH_INITIALIZATION) return wrong_phase(c, "fmi2ExitInitializationMode");
    char msg[600];
    double errors[2];
    int is_auto = is_auto_fidelity(&c->s);
    if (is_auto && c->model_exchange) {
        log_msg(c, fmi2Error, "initialization failed: fidelity = 'auto' is not available for "
                "model exchange (it chooses the level per communication step): must be one of "
                "kinematic, quasi-static, dynamic, or use co-simulation");
        return fmi2Error;
    }
    if ((is_auto && choose_start(&c->s, errors, msg, sizeof msg))
        || build_model(&c->s, &c->model, &c->au, &c->is_auto, msg, sizeof msg)) {
        log_msg(c, fmi2Error, "initialization failed: %s", msg);
        return fmi2Error;
    }
    if (is_auto) {
        static const char *const names[3] = {"kinematic", "quasi-static", "dynamic"};
        log_msg(c, fmi2OK, "fidelity = 'auto' starts with '%s' (estimated model errors: kinematic "
                "%.2g, quasi-static %.2g, dynamic 0; tolerance %g)%s", names[c->s.auto_start],
                errors[0], errors[1], c->s.par_real[P_TOLERANCE],
                c->is_auto ? "; it switches between the dynamic and the quasi-static level along "
                             "the run" : "");
    }
    prsm_initial_state(&c->model, c->s.x, c->s.par_real[P_INITIAL_SCREW_ANGLE],
                       c->s.par_real[P_INITIAL_SCREW_SPEED], c->s.par_bool[P_INITIAL_CARRIER_EQUILIBRIUM]);
    c->s.u_held[0] = c->s.u[0];
    c->s.u_held[1] = c->s.u[1];
    c->s.stats[0] = c->s.stats[1] = 0;
    memset(&c->s.mem, 0, sizeof c->s.mem);
    memset(&c->s.amem, 0, sizeof c->s.amem);
    if (c->is_auto) prsm_auto_reset(&c->au, &c->s.amem);
    c->s.stats[2] = c->is_auto ? auto_level(&c->s.amem) : model_level(&c->model);
    c->y_valid = 0;
    c->s.phase = PH_STEPPING;
    return fmi2OK;
}

fmi2Status fmi2Terminate(fmi2Component comp) {
    COMPONENT_OR_ERROR(comp);
    if (c->s.phase != PH_STEPPING) return wrong_phase(c, "fmi2Terminate");
    c->s.phase = PH_TERMINATED;
    return fmi2OK;
}

fmi2Status fmi2Reset(fmi2Component comp) {
    COMPONENT_OR_ERROR(comp);
    set_starts(&c->s);
    c->y_valid = 0;
    c->has_refused = c->stuck = 0;
    c->is_auto = 0;
    return fmi2OK;
}

/* ---- stepping ---------------------------------------------------------------------------------------- */
static fmi2Status refuse(component *c, const char *reason) {
    log_msg(c, fmi2Discard, "doStep refused, state unchanged: %s", reason);
    return fmi2Discard;
}

/* a refused doStep(t, h) with the inputs set: remembered, and a second identical one in a row
 * marks the instance stuck (fmi2Terminated true) until a call differs */
static fmi2Status refuse_call(component *c, double t, double h, const char *reason) {
    double call[4] = {t, h, c->s.u[0], c->s.u[1]};
    c->stuck = c->has_refused && !memcmp(call, c->refused_call, sizeof call);
    memcpy(c->refused_call, call, sizeof call);
    c->has_refused = 1;
    return refuse(c, reason);
}

fmi2Status fmi2DoStep(fmi2Component comp, fmi2Real t, fmi2Real h, fmi2Boolean noSetFMUStatePriorToCurrentPoint) {
    COMPONENT_OR_ERROR(comp);
    (void)noSetFMUStatePriorToCurrentPoint;
    char reason[900];
    if (c->model_exchange) {
        log_msg(c, fmi2Error, "fmi2DoStep: this instance was instantiated for model exchange");
        return fmi2Error;
    }
    if (c->s.phase != PH_STEPPING)
        return wrong_phase(c, c->s.phase == PH_TERMINATED ? "fmi2DoStep after fmi2Terminate"
                                                          : "fmi2DoStep before fmi2ExitInitializationMode");
    double u[2] = {c->s.u[0], c->s.u[1]};
    if (!(0.0 < h && h < INFINITY) || !(t + h > t)) {
        snprintf(reason, sizeof reason, "communication step size = %.17g s is out of range: must be "
                 "a finite number > 0 that advances the time", h);
        return refuse_call(c, t, h, reason);
    }
    if (!(isfinite(u[0]) && isfinite(u[1]))) {
        snprintf(reason, sizeof reason, "inputs screw_torque = %.17g N.m, load_force = %.17g N: every input must be finite", u[0], u[1]);
        return refuse_call(c, t, h, reason);
    }
    if (!isfinite(t)) {
        snprintf(reason, sizeof reason, "currentCommunicationPoint = %.17g s must be finite", t);
        return refuse_call(c, t, h, reason);
    }
    /* hosts compute communication times their own way: a point within PRSM_TIME_MATCH
       (prsm_fmu.slave.TIME_MATCH) of max(1 s, |time|) from the FMU's own time is the same point;
       the step size does not widen it */
    if (!(fabs(t - c->s.t) <= PRSM_TIME_MATCH * fmax(1.0, fabs(c->s.t)))) {
        log_msg(c, fmi2Error, "fmi2DoStep: currentCommunicationPoint = %.17g s is not the FMU's time "
                "%.17g s (the end of the last step); restore an FMU state to step from elsewhere",
                t, c->s.t);
        return fmi2Error;
    }
    if (prsm_input_violation(u, reason, sizeof reason)) return refuse_call(c, t, h, reason);
    double x_new[PRSM_NX_MAX] = {0.0};
    prsm_stats stats;
    char msg[700];
    prsm_memory mem_before = c->s.mem;
    prsm_auto_memory amem_before = c->s.amem;
    if (c->is_auto ? prsm_auto_advance(&c->au, &c->s.amem, t, c->s.x, u, h, x_new, &stats, msg,
                                       sizeof msg)
                   : prsm_advance(&c->model, &c->s.mem, t, c->s.x, u, h, x_new, &stats, msg,
                                  sizeof msg)) {
        snprintf(reason, sizeof reason, "integration failed: %s", msg);
        return refuse_call(c, t, h, reason);
    }
    if (prsm_model_state_violation(x_new, &c->model, msg, sizeof msg)) {   /* outputs could overflow */
        c->s.mem = mem_before;
        c->s.amem = amem_before;
        snprintf(reason, sizeof reason, "the step would end out of the state's bounds: %s", msg);
        return refuse_call(c, t, h, reason);
    }
    c->has_refused = c->stuck = 0;
    memcpy(c->s.x, x_new, sizeof x_new);
    c->s.t = t + h;
    c->s.u_held[0] = u[0];
    c->s.u_held[1] = u[1];
    c->s.stats[0] = stats.rhs_calls;
    c->s.stats[1] = stats.substeps;
    if (c->is_auto) c->s.stats[2] = auto_level(&c->s.amem);
    c->y_valid = 0;
    return fmi2OK;
}

fmi2Status fmi2CancelStep(fmi2Component comp) {
    COMPONENT_OR_ERROR(comp);
    log_msg(c, fmi2Error, "fmi2CancelStep: doStep always completes synchronously");
    return fmi2Error;
}

fmi2Status fmi2GetStatus(fmi2Component comp, const fmi2StatusKind s, fmi2Status *value) {
    COMPONENT_OR_ERROR(comp);
    (void)s; (void)value;
    return fmi2Discard;
}

fmi2Status fmi2GetRealStatus(fmi2Component comp, const fmi2StatusKind s, fmi2Real *value) {
    COMPONENT_OR_ERROR(comp);
    if (s == fmi2LastSuccessfulTime && value) {
        *value = c->s.t;
        return fmi2OK;
    }
    return fmi2Discard;
}

fmi2Status fmi2GetIntegerStatus(fmi2Component comp, const fmi2StatusKind s, fmi2Integer *value) {
    (void)comp; (void)s; (void)value;
    return fmi2Discard;
}

/* fmi2Terminated: fmi2OK and false while the instance can go on (a refused doStep may be
 * retried from the unchanged state with other inputs, another step size or another state);
 * true once fmi2Terminate has been called, or after the same doStep (t, h, inputs) was refused
 * twice in a row: the FMU is deterministic, so repeating it cannot succeed, and a host that
 * retries without changing anything (fmpy's simulate_fmu, fmusim) stops instead of looping
 * (docs/fmu.md, Errors) */
fmi2Status fmi2GetBooleanStatus(fmi2Component comp, const fmi2StatusKind s, fmi2Boolean *value) {
    COMPONENT_OR_ERROR(comp);
    if (s != fmi2Terminated || !value) {
        log_msg(c, fmi2Discard, "fmi2GetBooleanStatus: only fmi2Terminated is answered");
        return fmi2Discard;
    }
    *value = c->s.phase == PH_TERMINATED || c->stuck ? fmi2True : fmi2False;
    return fmi2OK;
}

fmi2Status fmi2GetStringStatus(fmi2Component comp, const fmi2StatusKind s, fmi2String *value) {
    (void)comp; (void)s; (void)value;
    return fmi2Discard;
}

fmi2Status fmi2SetRealInputDerivatives(fmi2Component comp, const fmi2ValueReference vr[], size_t nvr,
                                       const fmi2Integer order[], const fmi2Real value[]) {
    COMPONENT_OR_ERROR(comp);
    (void)vr; (void)nvr; (void)order; (void)value;
    log_msg(c, fmi2Error, "fmi2SetRealInputDerivatives: inputs are held over a step (canInterpolateInputs = false)");
    return fmi2Error;
}

fmi2Status fmi2GetRealOutputDerivatives(fmi2Component comp, const fmi2ValueReference vr[], size_t nvr,
                                        const fmi2Integer order[], fmi2Real value[]) {
    COMPONENT_OR_ERROR(comp);
    (void)vr; (void)nvr; (void)order; (void)value;
    log_msg(c, fmi2Error, "fmi2GetRealOutputDerivatives is not supported (maxOutputDerivativeOrder = 0)");
    return fmi2Error;
}

fmi2Status fmi2GetDirectionalDerivative(fmi2Component comp, const fmi2ValueReference vUnknown_ref[],
                                        size_t nUnknown, const fmi2ValueReference vKnown_ref[], size_t nKnown,
                                        const fmi2Real dvKnown[], fmi2Real dvUnknown[]) {
    COMPONENT_OR_ERROR(comp);
    (void)vUnknown_ref; (void)nUnknown; (void)vKnown_ref; (void)nKnown; (void)dvKnown; (void)dvUnknown;
    log_msg(c, fmi2Error, "fmi2GetDirectionalDerivative is not supported");
    return fmi2Error;
}

/* ---- FMU state ---------------------------------------------------------------------------------- */
static int finite_all(const double *v, int n) {
    for (int i = 0; i < n; i++)
        if (!isfinite(v[i])) return 0;
    return 1;
}

/* a stepper memory's flags and values */
static int memory_ok(const prsm_memory *mem) {
    return !((mem->has_h_prop != 0 && mem->has_h_prop != 1) || (mem->has_fsal != 0 && mem->has_fsal != 1)
        || (mem->has_cont != 0 && mem->has_cont != 1)
        || (mem->has_h_prop && !(mem->h_prop > 0.0 && mem->h_prop < INFINITY))
        || (mem->has_fsal && !(isfinite(mem->fsal_t) && finite_all(mem->fsal_x, PRSM_NX)
                               && finite_all(mem->fsal_u, 2) && finite_all(mem->fsal_f, PRSM_NX)))
        || (mem->has_cont && !(isfinite(mem->cont_t) && finite_all(mem->cont_x, PRSM_NX_MAX)
                               && finite_all(mem->cont_u, 2)
                               && mem->cont_h > 0.0 && mem->cont_h < INFINITY)));
}

/* auto's memory: its level, counters and estimates in their ranges, both steppers' memories */
static int auto_memory_ok(const prsm_auto_memory *a) {
    return (a->mode == PRSM_AUTO_DYNAMIC || a->mode == PRSM_AUTO_QUASI_STATIC) && a->wait >= 0
           && a->wait <= PRSM_AUTO_MAX_WAIT && a->backoff >= 1 && a->backoff <= PRSM_AUTO_MAX_WAIT
           && a->switches >= 0 && finite_all(a->lag, PRSM_N_STAGES) && isfinite(a->omega_scale)
           && a->omega_scale >= 0.0 && a->gain >= 1.0 && a->gain < INFINITY && isfinite(a->alpha)
           && memory_ok(&a->dyn) && memory_ok(&a->qs);
}

/* Is c's built model (c->model, c->au, c->is_auto) the one build_model builds from the
 * parameters of s (a snapshot in phase stepping or terminated)?  build_model reads the
 * parameters (par_real, par_int, par_bool, par_str) and auto_start of its snapshot and nothing
 * else, and is deterministic; c's model was built from c->s's (the invariant on component.model)
 * while c is in phase stepping or terminated.  So when these are bytewise equal, building again
 * would give the same model and accept it (it was accepted when built).  The model's only
 * contents that stepping changes are the lazily computed slaved laws (prsm_model.law): each is a
 * function of the model's built constants alone, the same values whenever it is computed. */
static int model_built_from(const component *c, const snapshot *s) {
    return c->s.phase >= PH_STEPPING && s->phase >= PH_STEPPING
           && s->auto_start == c->s.auto_start && same_parameters(s, &c->s);
}

/* the whole snapshot checked; the model it needs is built into m (and for auto its stepper into
 * au, *is_auto), or with built (model_built_from(built, s) true) taken from built: built->model
 * is then what build_model would give, and nothing is written to m and au.  The other checks
 * are the same either way.  0, or -1 and the reason */
static int check_snapshot(const snapshot *s, const component *built, prsm_model *m,
                          prsm_auto *au, int *is_auto, char *msg, int len) {
    *is_auto = 0;
    if (memcmp(s->magic, MAGIC, 8) || strncmp(s->guid, PRSM_GUID, sizeof s->guid)
        || s->n_stages != PRSM_N_STAGES) {
        snprintf(msg, (size_t)len, "not a state of this FMU (%s, GUID %s)", PRSM_MODEL_IDENTIFIER, PRSM_GUID);
        return -1;
    }
    if (s->phase < PH_INSTANTIATED || s->phase > PH_TERMINATED) {
        snprintf(msg, (size_t)len, "bad phase %d", s->phase);
        return -1;
    }
    for (int i = 0; i < N_PAR_STRING; i++)
        if (!memchr(s->par_str[i], 0, PRSM_STR_LEN)) {
            snprintf(msg, (size_t)len, "a String parameter is not terminated");
            return -1;
        }
    for (int i = 0; i < N_PAR_BOOL; i++)
        if (s->par_bool[i] != 0 && s->par_bool[i] != 1) {
            snprintf(msg, (size_t)len, "a Boolean parameter is neither true nor false");
            return -1;
        }
    if (!isfinite(s->t)) {
        snprintf(msg, (size_t)len, "time %.17g s is not finite", s->t);
        return -1;
    }
    if (s->stats[0] < 0 || s->stats[1] < 0 || s->stats[2] < 0 || s->stats[2] > 2) {
        snprintf(msg, (size_t)len, "bad step counters");
        return -1;
    }
    if (!memory_ok(&s->mem)) {
        snprintf(msg, (size_t)len, "bad stepper memory");
        return -1;
    }
    if (s->phase >= PH_STEPPING) {
        if (!finite_all(s->x, PRSM_NX_MAX) || !finite_all(s->u_held, 2)) {
            snprintf(msg, (size_t)len, "state vector or held inputs not finite");
            return -1;
        }
        if (prsm_input_violation(s->u_held, msg, len)) return -1;
        char why[600];
        const prsm_model *model = m;
        if (built) {
            model = &built->model;
            *is_auto = built->is_auto;
        } else if (build_model(s, m, au, is_auto, why, sizeof why)) {
            snprintf(msg, (size_t)len, "its parameters are not valid: %s", why);
            return -1;
        }
        if (prsm_model_state_violation(s->x, model, msg, len)) return -1;
        if (*is_auto && !auto_memory_ok(&s->amem)) {
            snprintf(msg, (size_t)len, "bad memory of fidelity auto");
            return -1;
        }
        if (s->stats[2] != (*is_auto ? auto_level(&s->amem) : model_level(model))) {
            snprintf(msg, (size_t)len, "step_fidelity %d does not match the fidelity parameter", s->stats[2]);
            return -1;
        }
    }
    return 0;
}

/* What fmi2GetFMUstate hands out: a tag, the instance it belongs to, where its snapshot came
 * from and the snapshot.  Every call that takes a state checks the tag and the owner before it
 * reads further (a state of another FMU or instance is refused whole: a PRSM2 state is smaller
 * than a PRSM3 snapshot). */
#define BLOCK_TAG "PRSMBLK1"
typedef struct {
    char tag[8];
    const component *owner;
    int from_get;              /* 1: copied from the owner's state by fmi2GetFMUstate; 0: read
                                  from bytes by fmi2DeSerializeFMUstate */
    snapshot s;
} state_block;

/* the block behind a state handed in by the host, or NULL (logged) if it is not one of ours */
static state_block *own_block(component *c, fmi2FMUstate state, const char *call) {
    state_block *b = (state_block *)state;
    if (!b || memcmp(b->tag, BLOCK_TAG, 8) || b->owner != c) {
        log_msg(c, fmi2Error, "%s: the FMU state %p was not made by this instance (%s) of %s "
                "(GUID %s) with fmi2GetFMUstate or fmi2DeSerializeFMUstate; nothing done", call,
                state, c->name, PRSM_MODEL_IDENTIFIER, PRSM_GUID);
        return NULL;
    }
    return b;
}

static state_block *new_block(component *c) {
    state_block *b = (state_block *)malloc(sizeof *b);
    if (!b) return NULL;
    memcpy(b->tag, BLOCK_TAG, 8);
    b->owner = c;
    b->from_get = 0;
    return b;
}

fmi2Status fmi2GetFMUstate(fmi2Component comp, fmi2FMUstate *state) {
    COMPONENT_OR_ERROR(comp);
    if (!state) return fmi2Error;
    state_block *b = *state ? own_block(c, *state, "fmi2GetFMUstate") : new_block(c);
    if (!b) {
        if (!*state) log_msg(c, fmi2Error, "fmi2GetFMUstate: out of memory");
        return fmi2Error;
    }
    memcpy(&b->s, &c->s, sizeof b->s);
    b->from_get = 1;
    *state = b;
    return fmi2OK;
}

fmi2Status fmi2SetFMUstate(fmi2Component comp, fmi2FMUstate state) {
    COMPONENT_OR_ERROR(comp);
    const state_block *b = own_block(c, state, "fmi2SetFMUstate");
    if (!b) return fmi2Error;
    const snapshot *s = &b->s;
    char msg[800];
    /* A state this instance saved with the parameters its model was built from (a master
     * saving and restoring around trial steps) keeps that model: building it again (the
     * parameters' checks, the contact solve of prsm_geometry.c) would give the same one
     * (model_built_from).  Every other state, deserialized ones included, is built from its
     * parameters.  Both are checked whole by check_snapshot, with the same messages. */
    int reuse = b->from_get && model_built_from(c, s);
    prsm_model *m = NULL;
    prsm_auto *au = NULL;
    int is_auto = 0;
    if (!reuse) {
        m = (prsm_model *)malloc(sizeof *m);
        au = (prsm_auto *)malloc(sizeof *au);
        if (!m || !au) {
            free(m);
            free(au);
            return fmi2Error;
        }
    }
    if (check_snapshot(s, reuse ? c : NULL, m, au, &is_auto, msg, sizeof msg)) {
        log_msg(c, fmi2Error, "fmi2SetFMUstate: the state cannot be restored, nothing changed: %s", msg);
        free(m);
        free(au);
        return fmi2Error;
    }
    memcpy(&c->s, s, sizeof c->s);
    c->has_refused = c->stuck = 0;
    if (!reuse && c->s.phase >= PH_STEPPING) {
        c->model = *m;
        c->is_auto = is_auto;
        if (is_auto) c->au = *au;
    }
    free(m);
    free(au);
    c->y_valid = 0;
    return fmi2OK;
}

fmi2Status fmi2FreeFMUstate(fmi2Component comp, fmi2FMUstate *state) {
    COMPONENT_OR_ERROR(comp);
    if (!state || !*state) return fmi2OK;
    if (!own_block(c, *state, "fmi2FreeFMUstate")) return fmi2Error;
    free(*state);
    *state = NULL;
    return fmi2OK;
}

fmi2Status fmi2SerializedFMUstateSize(fmi2Component comp, fmi2FMUstate state, size_t *size) {
    COMPONENT_OR_ERROR(comp);
    if (!own_block(c, state, "fmi2SerializedFMUstateSize") || !size) return fmi2Error;
    *size = sizeof(snapshot);
    return fmi2OK;
}

fmi2Status fmi2SerializeFMUstate(fmi2Component comp, fmi2FMUstate state, fmi2Byte bytes[], size_t size) {
    COMPONENT_OR_ERROR(comp);
    const state_block *b = own_block(c, state, "fmi2SerializeFMUstate");
    if (!b) return fmi2Error;
    if (!bytes || size < sizeof(snapshot)) {
        log_msg(c, fmi2Error, "fmi2SerializeFMUstate: needs %u bytes", (unsigned)sizeof(snapshot));
        return fmi2Error;
    }
    memcpy(bytes, &b->s, sizeof(snapshot));
    return fmi2OK;
}

fmi2Status fmi2DeSerializeFMUstate(fmi2Component comp, const fmi2Byte bytes[], size_t size, fmi2FMUstate *state) {
    COMPONENT_OR_ERROR(comp);
    char msg[800];
    if (!bytes || !state || size != sizeof(snapshot)) {
        log_msg(c, fmi2Error, "fmi2DeSerializeFMUstate: the bytes are not a serialized state of this "
                "FMU (%u bytes, expected %u)", (unsigned)size, (unsigned)sizeof(snapshot));
        return fmi2Error;
    }
    if (*state && !own_block(c, *state, "fmi2DeSerializeFMUstate")) return fmi2Error;
    state_block *b = new_block(c);
    prsm_model *m = (prsm_model *)malloc(sizeof *m);
    prsm_auto *au = (prsm_auto *)malloc(sizeof *au);
    int is_auto = 0;
    if (!b || !m || !au) {
        free(b);
        free(m);
        free(au);
        return fmi2Error;
    }
    memcpy(&b->s, bytes, sizeof b->s);
    if (check_snapshot(&b->s, NULL, m, au, &is_auto, msg, sizeof msg)) {
        log_msg(c, fmi2Error, "fmi2DeSerializeFMUstate: the bytes are not a valid state: %s", msg);
        free(b);
        free(m);
        free(au);
        return fmi2Error;
    }
    free(m);
    free(au);
    if (*state) free(*state);
    *state = b;
    return fmi2OK;
}
