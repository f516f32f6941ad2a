/* FMI 2.0 model exchange of the native PRSM FMU, beside its co-simulation.
 *
 * This file is the FMU's one translation unit for the FMI interface: it includes prsm_fmi2.c
 * (variables, parameters, life cycle, get/set, FMU state: shared, not copied) with
 * PRSM_MODEL_EXCHANGE defined, so that fmi2Instantiate accepts fmi2ModelExchange, and adds the
 * model-exchange functions.  The physics is prsm_model.c's right-hand side (prsm_rhs).
 *
 * Continuous states, in the order of <ModelStructure><Derivatives> (fmu_build.native):
 *   screw_angle [rad], screw_speed [rad/s], stage[k].carrier_speed [rad/s] (k = 1..n),
 *   input_work, output_work, friction_work [J]
 * -- the dynamic level's state vector.  At the kinematic and quasi-static levels the carriers
 * are slaved (zeta_k * screw speed): their states are reported so, their derivatives are
 * zeta_k * screw acceleration, and values set for them are not used.
 *
 * Event indicators (PRSM_N_EVENT_INDICATORS, generated):
 *   z0 = screw speed [rad/s]                     (zero speed: the friction forces reverse)
 *   z1 = screw speed - band speed                (upper edge of the regularised friction band)
 *   z2 = screw speed + band speed                (lower edge)
 *   z3 = +1 where the rigid contact has a solution, -1 where it has none
 * The right-hand side is continuous but has kinks at z0..z2 = 0; an event there lets the host
 * restart its solver at the kink.  Where z3 < 0, fmi2GetDerivatives and fmi2NewDiscreteStates
 * return fmi2Error naming the cause (as a co-simulation step fails there).
 */
#define PRSM_MODEL_EXCHANGE 1
#include "prsm_fmi2.c"

#define ME_NX (5 + PRSM_N_STAGES)

static int me_ready(component *c, const char *call) {
    if (!c->model_exchange) {
        log_msg(c, fmi2Error, "%s: this instance was instantiated for co-simulation", call);
        return 0;
    }
    if (c->s.phase != PH_STEPPING) {
        wrong_phase(c, call);
        return 0;
    }
    return 1;
}

/* the model's state vector as the host's states (module comment) */
static void to_host(const component *c, const double *x, double *xh) {
    const prsm_model *m = &c->model;
    xh[0] = x[0];
    xh[1] = x[1];
    for (int k = 0; k < PRSM_N_STAGES; k++)
        xh[2 + k] = m->dynamic ? x[2 + k] : m->st[k].zeta * x[1];
    for (int i = 0; i < 3; i++) xh[2 + PRSM_N_STAGES + i] = x[m->ie + i];
}

/* the host's states into the model's state vector */
static void from_host(const component *c, const double *xh, double *x) {
    const prsm_model *m = &c->model;
    for (int i = 0; i < PRSM_NX_MAX; i++) x[i] = 0.0;
    x[0] = xh[0];
    x[1] = xh[1];
    if (m->dynamic)
        for (int k = 0; k < PRSM_N_STAGES; k++) x[2 + k] = xh[2 + k];
    for (int i = 0; i < 3; i++) x[m->ie + i] = xh[2 + PRSM_N_STAGES + i];
}

/* "" if the rigid contact has a solution at the current state and inputs, else why not */
static int no_solution(component *c, char *why, size_t len) {
    prsm_outputs o;
    prsm_outputs_at(&c->model, c->s.x, c->s.u, &o);
    if (o.consistent) return 0;
    snprintf(why, len, "the rigid contact has no solution (Painleve: no screw acceleration "
             "balances screw_torque = %.6g N.m at screw_speed = %.6g rad/s, load_force = %.6g N; "
             "contact_status = 1) at t = %.17g s", c->s.u[0], c->s.x[1], c->s.u[1], c->s.t);
    return 1;
}

fmi2Status fmi2SetTime(fmi2Component comp, fmi2Real time) {
    COMPONENT_OR_ERROR(comp);
    if (!c->model_exchange || c->s.phase == PH_TERMINATED) return wrong_phase(c, "fmi2SetTime");
    if (!isfinite(time)) {
        log_msg(c, fmi2Error, "fmi2SetTime: time = %.17g s must be finite", time);
        return fmi2Error;
    }
    c->s.t = time;
    return fmi2OK;
}

fmi2Status fmi2SetContinuousStates(fmi2Component comp, const fmi2Real x[], size_t nx) {
    COMPONENT_OR_ERROR(comp);
    if (!me_ready(c, "fmi2SetContinuousStates")) return fmi2Error;
    if (!x || nx != ME_NX) {
        log_msg(c, fmi2Error, "fmi2SetContinuousStates: nx = %u is not allowed: must be %d",
                (unsigned)nx, ME_NX);
        return fmi2Error;
    }
    for (size_t i = 0; i < nx; i++)
        if (!isfinite(x[i])) {
            log_msg(c, fmi2Error, "fmi2SetContinuousStates: state %u = %.17g is out of range: "
                    "must be finite; the states are unchanged", (unsigned)i, x[i]);
            return fmi2Error;
        }
    from_host(c, x, c->s.x);
    c->y_valid = 0;
    return fmi2OK;
}

fmi2Status fmi2GetContinuousStates(fmi2Component comp, fmi2Real x[], size_t nx) {
    COMPONENT_OR_ERROR(comp);
    if (!me_ready(c, "fmi2GetContinuousStates")) return fmi2Error;
    if (!x || nx != ME_NX) {
        log_msg(c, fmi2Error, "fmi2GetContinuousStates: nx = %u is not allowed: must be %d",
                (unsigned)nx, ME_NX);
        return fmi2Error;
    }
    to_host(c, c->s.x, x);
    return fmi2OK;
}

fmi2Status fmi2GetNominalsOfContinuousStates(fmi2Component comp, fmi2Real x_nominal[], size_t nx) {
    COMPONENT_OR_ERROR(comp);
    if (!x_nominal || nx != ME_NX) return fmi2Error;
    for (size_t i = 0; i < nx; i++) x_nominal[i] = 1.0;
    return fmi2OK;
}

fmi2Status fmi2GetDerivatives(fmi2Component comp, fmi2Real derivatives[], size_t nx) {
    COMPONENT_OR_ERROR(comp);
    if (!me_ready(c, "fmi2GetDerivatives")) return fmi2Error;
    if (!derivatives || nx != ME_NX) {
        log_msg(c, fmi2Error, "fmi2GetDerivatives: nx = %u is not allowed: must be %d",
                (unsigned)nx, ME_NX);
        return fmi2Error;
    }
    if (!(isfinite(c->s.u[0]) && isfinite(c->s.u[1]))) {
        log_msg(c, fmi2Error, "fmi2GetDerivatives: inputs screw_torque = %.17g N.m, load_force = "
                "%.17g N: every input must be finite", c->s.u[0], c->s.u[1]);
        return fmi2Error;
    }
    double dx[PRSM_NX_MAX] = {0.0};
    prsm_rhs(&c->model, c->s.x, c->s.u, dx);
    char why[400];
    if (!finite_sum(dx, c->model.nx)) {
        if (no_solution(c, why, sizeof why)) log_msg(c, fmi2Error, "fmi2GetDerivatives: %s", why);
        else log_msg(c, fmi2Error, "fmi2GetDerivatives: non-finite derivative at t = %.17g s", c->s.t);
        return fmi2Error;
    }
    to_host(c, dx, derivatives);      /* slaved carriers: zeta_k * screw acceleration */
    return fmi2OK;
}

fmi2Status fmi2GetEventIndicators(fmi2Component comp, fmi2Real z[], size_t nz) {
    COMPONENT_OR_ERROR(comp);
    if (!me_ready(c, "fmi2GetEventIndicators")) return fmi2Error;
    if (!z || nz != PRSM_N_EVENT_INDICATORS) {
        log_msg(c, fmi2Error, "fmi2GetEventIndicators: nz = %u is not allowed: must be %d",
                (unsigned)nz, PRSM_N_EVENT_INDICATORS);
        return fmi2Error;
    }
    double w = c->s.x[1], band = c->model.band_speed;
    char why[400];
    z[0] = w;
    z[1] = w - band;
    z[2] = w + band;
    z[3] = (isfinite(c->s.u[0]) && isfinite(c->s.u[1]) && !no_solution(c, why, sizeof why))
           ? 1.0 : -1.0;
    return fmi2OK;
}

fmi2Status fmi2EnterEventMode(fmi2Component comp) {
    COMPONENT_OR_ERROR(comp);
    return me_ready(c, "fmi2EnterEventMode") ? fmi2OK : fmi2Error;
}

fmi2Status fmi2NewDiscreteStates(fmi2Component comp, fmi2EventInfo *info) {
    COMPONENT_OR_ERROR(comp);
    if (!me_ready(c, "fmi2NewDiscreteStates") || !info) return fmi2Error;
    info->newDiscreteStatesNeeded = fmi2False;
    info->terminateSimulation = fmi2False;
    info->nominalsOfContinuousStatesChanged = fmi2False;
    info->valuesOfContinuousStatesChanged = fmi2False;
    info->nextEventTimeDefined = fmi2False;
    info->nextEventTime = 0.0;
    char why[400];
    if (isfinite(c->s.u[0]) && isfinite(c->s.u[1]) && no_solution(c, why, sizeof why)) {
        log_msg(c, fmi2Error, "fmi2NewDiscreteStates: %s", why);
        return fmi2Error;
    }
    return fmi2OK;
}

fmi2Status fmi2EnterContinuousTimeMode(fmi2Component comp) {
    COMPONENT_OR_ERROR(comp);
    return me_ready(c, "fmi2EnterContinuousTimeMode") ? fmi2OK : fmi2Error;
}

fmi2Status fmi2CompletedIntegratorStep(fmi2Component comp, fmi2Boolean noSetFMUStatePriorToCurrentPoint,
                                       fmi2Boolean *enterEventMode, fmi2Boolean *terminateSimulation) {
    COMPONENT_OR_ERROR(comp);
    (void)noSetFMUStatePriorToCurrentPoint;
    if (!me_ready(c, "fmi2CompletedIntegratorStep") || !enterEventMode || !terminateSimulation)
        return fmi2Error;
    *enterEventMode = fmi2False;
    *terminateSimulation = fmi2False;
    return fmi2OK;
}
