/* The screw-roller contact of one PRSM stage, solved in C (prsm_geometry.c): the contact point
 * and normal of the "+" flank from the stage's thread geometry, as prsm_fmu.geometry defines
 * them.  No build-time constant is needed: the engine solves it when a model is made, so the
 * geometry parameters can be set at initialization.
 */
#ifndef PRSM_GEOMETRY_H
#define PRSM_GEOMETRY_H

#include "prsm_model.h"

/* number of doubles prsm_contact_solve writes: the contact point (x, y, z) [m], the unit normal
 * (x, y, z) [-], the solution (rho [m], psi [rad], rho_r [m], psi_r [rad], z_r [m]), the largest
 * scaled residual [-] and the Newton iterations taken */
#define PRSM_CONTACT_OUT 13

/* Solve "the screw flank and the roller flank share a point (3 equations) and a normal (2)" for
 * (rho, psi, rho_r, psi_r, z_r) by damped Newton from the pitch point, with a central-difference
 * Jacobian (step 1e-7 in the scaled unknowns), Gaussian elimination with partial pivoting, a
 * halving line search on the largest scaled residual and at most PRSM_CONTACT_MAX_ITER
 * iterations (prsm_fmu.geometry._newton_contact is the same computation, operation for
 * operation).  r_s, r_r: screw and roller radii [m]; lead: screw lead [m]; n_s: screw starts;
 * beta: flank angle [rad].  Always returns after a bounded amount of work; whether the result is
 * a contact is prsm_contact_near's to say. */
void prsm_contact_solve(double r_s, double r_r, double lead, int n_s, double beta,
                        double out[PRSM_CONTACT_OUT]);

/* 1 if out (from prsm_contact_solve) is a contact near the pitch point (residual below 1e-12,
 * the point on the roller's profile arc and on the facing sides), else 0 (prsm_fmu.geometry's
 * acceptance test). */
int prsm_contact_near(double r_s, double r_r, double beta, const double out[PRSM_CONTACT_OUT]);

/* The message of a stage whose geometry gives no contact (prsm_fmu.geometry.contact_geometry's),
 * naming "stage[k]" (k from 1) and its geometry parameters. */
void prsm_contact_message(char *msg, int len, int k, double r_s, double r_r, double lead, int n_s,
                          double beta);

/* Stage k's (from 0) contact constants from its geometry v (mechanics._Stage and _Flank, operation
 * for operation): both flanks ("+" first), the carriers' equilibrium ratio zeta* [-] and the
 * smaller axial part of the two normals [-].  Returns 0, or -1 with prsm_contact_message in msg
 * when the geometry gives no contact. */
int prsm_stage_contact(int k, const prsm_stage_values *v, prsm_flank fl[2], double *zeta_geometric,
                       double *min_normal_z, char *msg, int len);

#endif
