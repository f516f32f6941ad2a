/* The sweep's speed-tracking master in C: the step loop of prsm_fmu.sweep.fmu_runner.FmuRunner
 * (_run's loop over the communication steps and _track's secant iteration), operation for
 * operation.
 *
 * What it is: the fast path of FmuRunner.  Python loads and initializes the FMU, finds the
 * t = 0 torque, evaluates the reference speed at every communication point and hands this
 * loop the FMU's own FMI functions (the instance fmpy created); the loop saves the state,
 * steps with the trial torques, restores, reads the outputs into their rows and counts the
 * trials and right-hand-side calls exactly as the Python loop does, with the Python loop's
 * constants (TORQUE_RTOL, MAX_TRIALS) passed in.  Every arithmetic operation is the Python
 * code's, in the same order, with IEEE doubles and no contraction (compiled with
 * -ffp-contract=off), so the FMI calls, their arguments and the results are the Python loop's
 * bit for bit (tests/test_fmu_track.py, on seeded random points).  Python's min(a, b) /
 * max(a, b) keep the first argument unless the second is strictly smaller / larger: written
 * out below.  "gain is None" is NaN here: the only test on it is !(gain > 0), true for both.
 *
 * A failing FMI call (status above fmi2Warning) ends the loop: the state saved for the step is
 * freed, as the Python loop's finally clause frees it (a failing free is then the failure, as
 * there), and the call, its status, the step and the torque are returned for Python to raise
 * what the Python loop raises.
 */
#include <math.h>
#include <stddef.h>

typedef int (*set_real_fn)(void *, const unsigned int *, size_t, const double *);
typedef int (*get_real_fn)(void *, const unsigned int *, size_t, double *);
typedef int (*get_int_fn)(void *, const unsigned int *, size_t, int *);
typedef int (*do_step_fn)(void *, double, double, int);
typedef int (*get_state_fn)(void *, void **);
typedef int (*set_state_fn)(void *, void *);
typedef int (*free_state_fn)(void *, void **);

/* the FMI calls the loop makes, in the order of prsm_fmu.sweep.native_track.CALLS */
enum { C_SET_REAL = 0, C_GET_REAL = 1, C_GET_INTEGER = 2, C_DO_STEP = 3, C_GET_STATE = 4,
       C_SET_STATE = 5, C_FREE_STATE = 6, N_CALLS = 7 };

#define FMI2_WARNING 1

typedef struct {
    void *comp;
    set_real_fn set_real;
    get_real_fn get_real;
    get_int_fn get_integer;
    do_step_fn do_step;
    get_state_fn get_state;
    set_state_fn set_state;
    free_state_fn free_state;
    unsigned int torque_vr, speed_vr, rhs_vr;
    const unsigned int *out_vrs;
    size_t n_out;
} track_fmu;

/* where a run stopped on a failed call: the call (enum above), its status, the step index and
 * the torque last set */
typedef struct {
    int call, status;
    long step;
    double torque;
} track_failure;

static int failed(track_failure *f, int call, int status, long step, double torque) {
    f->call = call;
    f->status = status;
    f->step = step;
    f->torque = torque;
    return 1;
}

/* FmuRunner._trial: restore the saved state (restore != 0), set the torque, step, read the
 * speed into *speed.  0, or the failed call's status recorded in *fail. */
static int trial(const track_fmu *m, void *state, int restore, double t, double h,
                 double torque, double *speed, long step, track_failure *fail) {
    int s;
    if (restore && (s = m->set_state(m->comp, state)) > FMI2_WARNING)
        return failed(fail, C_SET_STATE, s, step, torque);
    if ((s = m->set_real(m->comp, &m->torque_vr, 1, &torque)) > FMI2_WARNING)
        return failed(fail, C_SET_REAL, s, step, torque);
    if ((s = m->do_step(m->comp, t, h, 0)) > FMI2_WARNING)
        return failed(fail, C_DO_STEP, s, step, torque);
    if ((s = m->get_real(m->comp, &m->speed_vr, 1, speed)) > FMI2_WARNING)
        return failed(fail, C_GET_REAL, s, step, torque);
    return 0;
}

/* FmuRunner._track: the torque held over [t, t + h] that ends the step at target; leaves the
 * FMU there.  *torque_io: the guess in, the torque out; *gain_io: the learnt gain (NaN: none);
 * *n_out: the trials.  0, or 1 with *fail filled. */
static int track(const track_fmu *m, void *state, double t, double h, double target,
                 double *torque_io, double *gain_io, long *n_out, double torque_rtol,
                 long max_trials, double t_scale, long step, track_failure *fail) {
    double torque = *torque_io, gain = *gain_io, speed, err, new_t, new_err;
    double lo_t = 0.0, hi_t = 0.0, best_abs, best_t;
    int have_lo = 0, have_hi = 0;
    long n;
    if (trial(m, state, 0, t, h, torque, &speed, step, fail)) return 1;
    err = speed - target;
    n = 1;
    best_abs = fabs(err);
    best_t = torque;
    for (;;) {
        if (err < 0.0) {
            lo_t = torque;
            have_lo = 1;
        } else if (err > 0.0) {
            hi_t = torque;
            have_hi = 1;
        } else {
            break;
        }
        if (!(gain > 0.0)) {
            double stp = 1e-3 * (fabs(torque) + t_scale);
            new_t = torque + (err < 0.0 ? stp : -stp);
        } else {
            new_t = torque - err / gain;
            if (have_lo && have_hi) {
                double mn = hi_t < lo_t ? hi_t : lo_t;    /* min(lo, hi) */
                double mx = hi_t > lo_t ? hi_t : lo_t;    /* max(lo, hi) */
                if (!(mn < new_t && new_t < mx)) new_t = 0.5 * (lo_t + hi_t);
            }
        }
        if (fabs(new_t - torque) <= torque_rtol * (fabs(torque) + t_scale)) break;
        if (n >= max_trials) {
            torque = best_t;
            if (trial(m, state, 1, t, h, torque, &speed, step, fail)) return 1;
            n += 1;
            break;
        }
        if (trial(m, state, 1, t, h, new_t, &speed, step, fail)) return 1;
        new_err = speed - target;
        n += 1;
        if (new_t != torque && new_err != err) {
            double slope = (new_err - err) / (new_t - torque);
            if (slope > 0.0) gain = slope;
        }
        torque = new_t;
        err = new_err;
        if (fabs(err) < best_abs) {
            best_abs = fabs(err);
            best_t = torque;
        }
    }
    *torque_io = torque;
    *gain_io = gain;
    *n_out = n;
    return 0;
}

/* FmuRunner._run's loop over steps 0 .. n_steps - 1.
 *
 * targets[i]: the reference speed at (i + 1)·h; torque0: the t = 0 torque; out: the rows of
 * communication points 1 .. n_steps (n_out doubles each, the first at out); counts[0] += the
 * trials, counts[1] += the right-hand-side calls.  Returns 0, or 1 with *fail filled. */
int fmu_track_run(const track_fmu *m, long n_steps, double h, const double *targets,
                  double torque0, double torque_rtol, long max_trials, double t_scale,
                  double *out, long counts[2], track_failure *fail) {
    double last = torque0, before = 0.0, gain = NAN;
    int have_before = 0;
    for (long i = 0; i < n_steps; i++) {
        double t = (double)i * h, target = targets[i];
        double torque = have_before ? 2.0 * last - before : last;
        void *state = NULL;
        long n = 0;
        int s, bad;
        int rhs = 0;
        if ((s = m->get_state(m->comp, &state)) > FMI2_WARNING)
            return failed(fail, C_GET_STATE, s, i, torque);
        bad = track(m, state, t, h, target, &torque, &gain, &n, torque_rtol, max_trials, t_scale,
                    i, fail);
        /* the Python loop frees in a finally clause: a failing free is what it raises */
        if ((s = m->free_state(m->comp, &state)) > FMI2_WARNING)
            return failed(fail, C_FREE_STATE, s, i, torque);
        if (bad) return 1;
        counts[0] += n;
        before = last;
        last = torque;
        have_before = 1;
        if ((s = m->get_real(m->comp, m->out_vrs, m->n_out, out + (size_t)i * m->n_out))
            > FMI2_WARNING)
            return failed(fail, C_GET_REAL, s, i, torque);
        if ((s = m->get_integer(m->comp, &m->rhs_vr, 1, &rhs)) > FMI2_WARNING)
            return failed(fail, C_GET_INTEGER, s, i, torque);
        counts[1] += rhs;
    }
    return 0;
}
