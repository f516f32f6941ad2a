/* fidelity = "auto" in C: the dynamic level while the carriers lag, the quasi-static level while
 * they follow their equilibrium, chosen again at every communication step.
 *
 * A translation of prsm_fmu/models/adaptive.py (AdaptiveModel: the switching criteria;
 * SwitchingStepper: the stepping, with ROS34PW2 for every dynamic step, i.e. the Python stepper
 * of name "rosenbrock") and of prsm_fmu/models/auto.py's carrier time constants
 * (carrier_time_constants, effective_load), operation for operation, so that the states equal
 * the Python stepper's bit for bit (tests/test_engine_differential.py).  The only libm function
 * on the way besides sqrt is exp, which Python's math.exp calls as it is.
 *
 * The state is the dynamic level's layout throughout (carrier speeds included): while
 * quasi-static the carriers are stored at zeta* omega.
 */
#ifndef PRSM_AUTO_H
#define PRSM_AUTO_H

#include "prsm_model.h"

/* the two levels a run switches between (adaptive.MODES) */
#define PRSM_AUTO_DYNAMIC 0
#define PRSM_AUTO_QUASI_STATIC 1

typedef struct {
    prsm_model dyn;            /* the dynamic level (the run's drive): dynamic steps, rhs */
    prsm_model qs;             /* the quasi-static level: its closed-form steps and outputs */
    double tolerance;          /* accepted model error [-] (AdaptiveModel.tolerance) */
    int start;                 /* level of the first step (PRSM_AUTO_*) */
    double nut_term;           /* m c_out of the last nut [kg m/rad] (auto.effective_load) */
    double slaved_inertia;     /* inertia on the screw axis, carriers slaved [kg m2] */
    /* c_k = tau_k |F| / |omega| per carrier [N s2/rad]: [0] back-driven, [1] driving
     * (AdaptiveModel.lag_coefficients(forward)) */
    double coef[2][PRSM_N_STAGES];
} prsm_auto;

/* what a step carries to the next (SwitchingStepper.get_memory) */
typedef struct {
    int mode;                  /* PRSM_AUTO_* of the last step */
    double lag[PRSM_N_STAGES]; /* each carrier's estimated lag d_k [rad/s] */
    double omega_scale;        /* largest |screw speed| so far [rad/s] */
    int wait, backoff, switches;
    double gain;               /* output change per carrier deviation of the last refusal */
    double alpha;              /* the last step's mean screw acceleration [rad/s2] */
    prsm_memory dyn, qs;       /* the two steppers' memories */
} prsm_auto_memory;

/* Build from a configuration (its level and stepper fields are ignored: the dynamic and the
 * quasi-static level are built from it, the quasi-static one with the exponential band step),
 * the tolerance [-] (> 0, finite) and the start level.  Returns 0, or -1 with a one-line
 * message naming the parameter, its value and its allowed range. */
int prsm_auto_init(prsm_auto *a, const prsm_config *cfg, double tolerance, int start, char *msg,
                   int msg_len);

/* The memory at the start of a run (SwitchingStepper.reset). */
void prsm_auto_reset(const prsm_auto *a, prsm_auto_memory *mem);

/* The steppers' tolerances: ROS34PW2's as prsm_api_set_tolerances sets them, the quasi-static
 * closed form's band step at ROS34PW2's (SwitchingStepper passes the dynamic stepper's rtol
 * and atol on to it). */
void prsm_auto_set_tolerances(prsm_auto *a, double rtol, double atol);

/* Advance from t over h with inputs u held (SwitchingStepper.advance).  Returns 0 and the new
 * state in x_new, or -1 with the reason in msg; memory is changed only on success. */
int prsm_auto_advance(prsm_auto *a, prsm_auto_memory *mem, double t, const double x[PRSM_NX_MAX],
                      const double u[2], double h, double x_new[PRSM_NX_MAX], prsm_stats *stats,
                      char *msg, int msg_len);

/* The outputs of the level of mode at state x (AdaptiveModel.outputs): the model they come from
 * and the state in its layout (x_level, the carriers dropped while quasi-static). */
const prsm_model *prsm_auto_outputs_at(prsm_auto *a, int mode, const double x[PRSM_NX_MAX],
                                       const double u[2], double x_level[PRSM_NX_MAX],
                                       prsm_outputs *y);

/* The level fidelity = "auto" starts with (models/auto.py choose_for_start under the torque
 * drive, the communication step not known): 0 kinematic, 1 quasi-static, 2 dynamic, with the
 * estimated model errors of the kinematic and the quasi-static level in errors; -1 with the
 * reason in msg.  inputs: motor torque [N.m] and load [N] at the start; screw_speed [rad/s] at
 * the start; carriers_at_rest: 1 carriers at rest, 0 at their equilibrium; kinematic_efficiency:
 * the kinematic level's constant efficiency [-]. */
int prsm_auto_choose(const prsm_config *cfg, double tolerance, const double inputs[2],
                     double screw_speed, int carriers_at_rest, double kinematic_efficiency,
                     double errors[2], char *msg, int msg_len);

#endif
