/* The FMU's output quantities (Q_*) and their values at one state, shared by the native FMU
 * (prsm_fmi2.c: its output variables, mapped by the generated prsm_variables.h) and the
 * engine's flat interface (prsm_api.c: prsm_api_outputs, in the order of the generated
 * PRSM_API_OUTPUT_* tables of prsm_constants.h, from fmu_build.native.API_OUTPUTS).
 */
#ifndef PRSM_QUANTITY_H
#define PRSM_QUANTITY_H

#include "prsm_model.h"

enum {
    Q_SCREW_SPEED, Q_SCREW_ANGLE, Q_SCREW_ACCELERATION, Q_SCREW_TORQUE, Q_ROD_POSITION,
    Q_ROD_VELOCITY, Q_LOAD_FORCE, Q_CONTACT_FORCE, Q_NORMAL_FORCE, Q_DRIVEN_TORQUE,
    Q_SPLINE_FRICTION, Q_CARRIER_SPEED, Q_CARRIER_SPEED_RATIO, Q_EFFICIENCY, Q_FRICTION_POWER,
    Q_INPUT_POWER, Q_OUTPUT_POWER, Q_INPUT_WORK, Q_OUTPUT_WORK, Q_FRICTION_WORK,
    Q_KINETIC_ENERGY, Q_FRICTION_POWER_COULOMB, Q_FRICTION_POWER_VISCOUS,
    Q_FRICTION_POWER_DIFFERENTIAL, Q_FRICTION_POWER_JOINTS, Q_SCREW_FRICTION_TORQUE,
    Q_OVERALL_EFFICIENCY, Q_CARRIER_ACCELERATION
};

/* Quantity q (of stage k for the per-stage ones) at state x with inputs u, from the outputs o
 * (prsm_outputs_at of the same m, x, u). */
static inline double prsm_quantity(const prsm_model *m, const double *x, const double *u,
                                   const prsm_outputs *o, int q, int k) {
    double omega = x[1], load = u[1], c_out = m->c_out;
    int ie = m->ie;
    switch (q) {
    case Q_SCREW_SPEED: return omega;
    case Q_SCREW_ANGLE: return x[0];
    case Q_SCREW_ACCELERATION: return o->alpha;
    case Q_SCREW_TORQUE: return o->motor;
    case Q_ROD_POSITION: return c_out * x[0];
    case Q_ROD_VELOCITY: return c_out * omega;
    case Q_LOAD_FORCE: return load;
    case Q_CONTACT_FORCE: return o->contact_force[k];
    case Q_NORMAL_FORCE: return o->normal_force[k];
    case Q_DRIVEN_TORQUE: return o->driven_torque[k];
    case Q_SPLINE_FRICTION: return o->spline_friction[k];
    case Q_CARRIER_SPEED: return o->carrier_speed[k];
    case Q_CARRIER_SPEED_RATIO: return o->carrier_speed_ratio[k];
    case Q_EFFICIENCY: return o->efficiency;
    case Q_FRICTION_POWER: return o->friction_power;
    case Q_INPUT_POWER: return o->motor * omega;
    case Q_OUTPUT_POWER: return load * (c_out * omega);
    case Q_INPUT_WORK: return x[ie];
    case Q_OUTPUT_WORK: return x[ie + 1];
    case Q_FRICTION_WORK: return x[ie + 2];
    case Q_FRICTION_POWER_COULOMB: return o->p_coulomb;
    case Q_FRICTION_POWER_VISCOUS: return o->p_viscous;
    case Q_FRICTION_POWER_DIFFERENTIAL: return o->p_differential;
    case Q_FRICTION_POWER_JOINTS: return o->p_joints;
    case Q_SCREW_FRICTION_TORQUE:
        return o->motor - load * c_out - m->equivalent_inertia * o->alpha;
    case Q_OVERALL_EFFICIENCY: return x[ie] > 0.0 ? x[ie + 1] / x[ie] : 0.0;
    case Q_CARRIER_ACCELERATION:     /* the carrier state's derivative (prsm_fmi2_me.c) */
        if (m->dynamic) {
            double dx[PRSM_NX_MAX] = {0.0};
            prsm_rhs(m, x, u, dx);
            return dx[2 + k];
        }
        return m->st[k].zeta * o->alpha;
    default: return o->kinetic_energy;
    }
}

#endif
