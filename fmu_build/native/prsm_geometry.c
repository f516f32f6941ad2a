/* The screw-roller contact of one PRSM stage (prsm_geometry.h): damped Newton on the five
 * contact equations of prsm_fmu.geometry, written so that every operation is the Python
 * reference's (prsm_fmu/geometry.py, _newton_contact): equal results bit for bit
 * (tests/test_geometry_solver.py).  Compile with -ffp-contract=off.
 */
#include <math.h>
#include <stdio.h>
#include <stdlib.h>
#include <string.h>

#include "prsm_geometry.h"

#define PRSM_CONTACT_MAX_ITER 50
#define PRSM_CONTACT_MAX_HALVINGS 30
#define PRSM_CONTACT_DU 1e-7
#define PRSM_CONTACT_TOL 1e-12

typedef struct {
    double r_s, r_r, a, ell, q, tan_b, big_r, z_r0, floor_h;
} contact_problem;

/* the stage's constants (geometry._ContactProblem.__init__) */
static void problem_init(contact_problem *p, double r_s, double r_r, double lead, int n_s,
                         double beta) {
    p->r_s = r_s;
    p->r_r = r_r;
    p->a = r_s + r_r;
    p->ell = lead / (2.0 * PRSM_PI);
    p->q = p->ell / (double)n_s;
    p->tan_b = tan(beta);
    p->big_r = r_r / sin(beta);
    p->z_r0 = -p->q * PRSM_PI - p->big_r * cos(beta);
    p->floor_h = (1e-9 * p->big_r) * (1e-9 * p->big_r);
}

/* the screw's point and unit normal at u (point, normal may be NULL) and the residual f[5]
 * (geometry._ContactProblem.evaluate) */
static void evaluate(const contact_problem *p, const double u[5], double f[5], double point[3],
                     double normal[3]) {
    double rho = p->r_s * (1.0 + u[0]), psi = u[1], rho_r = p->r_r * (1.0 + u[2]);
    double psi_r = PRSM_PI + u[3], z_r = p->z_r0 + p->r_s * u[4];
    double cp = cos(psi), sp = sin(psi), cr = cos(psi_r), sr = sin(psi_r);
    double h2 = p->big_r * p->big_r - rho_r * rho_r;
    double h = sqrt(h2 > p->floor_h ? h2 : p->floor_h);
    double sx = rho * cp, sy = rho * sp, sz = p->ell * psi + (rho - p->r_s) * p->tan_b;
    double rx = p->a + rho_r * cr, ry = rho_r * sr, rz = (z_r + p->q * psi_r) + h;
    /* dS/drho x dS/dpsi and dRr/drho_r x dRr/dpsi_r: both towards +z */
    double nsx = p->ell * sp - (rho * p->tan_b) * cp;
    double nsy = ((-rho) * p->tan_b) * sp - p->ell * cp;
    double nsz = rho;
    double nrx = p->q * sr + ((rho_r * rho_r) * cr) / h;
    double nry = ((rho_r * rho_r) * sr) / h - p->q * cr;
    double nrz = rho_r;
    double ns = sqrt((nsx * nsx + nsy * nsy) + nsz * nsz);
    double nr = sqrt((nrx * nrx + nry * nry) + nrz * nrz);
    f[0] = (sx - rx) / p->r_s;
    f[1] = (sy - ry) / p->r_s;
    f[2] = (sz - rz) / p->r_s;
    /* both unit normals have z > 0: equal x and y components make them equal */
    f[3] = nsx / ns - nrx / nr;
    f[4] = nsy / ns - nry / nr;
    if (point) {
        point[0] = sx;
        point[1] = sy;
        point[2] = sz;
    }
    if (normal) {
        normal[0] = nsx / ns;
        normal[1] = nsy / ns;
        normal[2] = nsz / ns;
    }
}

/* largest |f_i|, or infinity if one is not finite (geometry._max_abs) */
static double max_abs(const double f[5]) {
    double m = 0.0;
    for (int i = 0; i < 5; i++) {
        if (!isfinite(f[i])) return INFINITY;
        if (fabs(f[i]) > m) m = fabs(f[i]);
    }
    return m;
}

/* solve J d = f in place (Gaussian elimination, partial pivoting): 0, or -1 if singular
 * (geometry._solve5) */
static int solve5(double jac[5][5], double f[5], double d[5]) {
    for (int c = 0; c < 5; c++) {
        int piv = c;
        for (int r = c + 1; r < 5; r++)
            if (fabs(jac[r][c]) > fabs(jac[piv][c])) piv = r;
        if (!(fabs(jac[piv][c]) > 0.0) || !isfinite(jac[piv][c])) return -1;
        if (piv != c) {
            for (int j = 0; j < 5; j++) {
                double t = jac[c][j];
                jac[c][j] = jac[piv][j];
                jac[piv][j] = t;
            }
            double t = f[c];
            f[c] = f[piv];
            f[piv] = t;
        }
        for (int r = c + 1; r < 5; r++) {
            double factor = jac[r][c] / jac[c][c];
            for (int j = c; j < 5; j++) jac[r][j] = jac[r][j] - factor * jac[c][j];
            f[r] = f[r] - factor * f[c];
        }
    }
    for (int r = 4; r >= 0; r--) {
        double s = f[r];
        for (int j = r + 1; j < 5; j++) s = s - jac[r][j] * d[j];
        d[r] = s / jac[r][r];
    }
    return 0;
}

void prsm_contact_solve(double r_s, double r_r, double lead, int n_s, double beta,
                        double out[PRSM_CONTACT_OUT]) {
    contact_problem p;
    problem_init(&p, r_s, r_r, lead, n_s, beta);
    double u[5] = {0.0, 0.0, 0.0, 0.0, 0.0}, f[5];
    evaluate(&p, u, f, NULL, NULL);
    double fn = max_abs(f);
    int it = 0;
    while (it < PRSM_CONTACT_MAX_ITER && fn > 1e-16 && isfinite(fn)) {
        double jac[5][5], d[5], rhs[5];
        for (int j = 0; j < 5; j++) {
            double up[5], um[5], fp[5], fm[5];
            memcpy(up, u, sizeof up);
            memcpy(um, u, sizeof um);
            up[j] = u[j] + PRSM_CONTACT_DU;
            um[j] = u[j] - PRSM_CONTACT_DU;
            evaluate(&p, up, fp, NULL, NULL);
            evaluate(&p, um, fm, NULL, NULL);
            for (int i = 0; i < 5; i++) jac[i][j] = (fp[i] - fm[i]) / (2.0 * PRSM_CONTACT_DU);
        }
        memcpy(rhs, f, sizeof rhs);
        if (solve5(jac, rhs, d)) break;
        it++;
        double t = 1.0;
        int accepted = 0;
        for (int s = 0; s < PRSM_CONTACT_MAX_HALVINGS; s++) {
            double un[5], fnew[5];
            for (int i = 0; i < 5; i++) un[i] = u[i] - t * d[i];
            evaluate(&p, un, fnew, NULL, NULL);
            double nn = max_abs(fnew);
            if (nn < fn) {
                memcpy(u, un, sizeof u);
                memcpy(f, fnew, sizeof f);
                fn = nn;
                accepted = 1;
                break;
            }
            t = 0.5 * t;
        }
        if (!accepted) break;           /* at the round-off floor, or no descent */
    }
    evaluate(&p, u, f, out, out + 3);
    out[6] = p.r_s * (1.0 + u[0]);
    out[7] = u[1];
    out[8] = p.r_r * (1.0 + u[2]);
    out[9] = PRSM_PI + u[3];
    out[10] = p.z_r0 + p.r_s * u[4];
    out[11] = max_abs(f);
    out[12] = (double)it;
}

int prsm_contact_near(double r_s, double r_r, double beta, const double out[PRSM_CONTACT_OUT]) {
    double big_r = r_r / sin(beta);
    double rho = out[6], psi = out[7], rho_r = out[8], psi_r = out[9];
    for (int i = 0; i < 3; i++)
        if (!isfinite(out[i])) return 0;
    double dx = out[0] - r_s, dy = out[1];
    return out[11] < PRSM_CONTACT_TOL && 0.0 < rho_r && rho_r < big_r * (1.0 - 1e-9)
           && rho > 0.0 && fabs(psi) < PRSM_PI / 2.0 && fabs(psi_r - PRSM_PI) < PRSM_PI / 2.0
           && sqrt(dx * dx + dy * dy) < r_r;
}

void prsm_contact_message(char *msg, int len, int k, double r_s, double r_r, double lead, int n_s,
                          double beta) {
    char l[40], b[40], s[40], r[40];
    prsm_fmt_num(l, sizeof l, lead);
    prsm_fmt_num(b, sizeof b, beta);
    prsm_fmt_num(s, sizeof s, r_s);
    prsm_fmt_num(r, sizeof r, r_r);
    snprintf(msg, (size_t)len, "stage[%d].screw_lead = %s m with stage[%d].flank_angle = %s rad "
             "(screw_radius = %s m, roller_radius = %s m, screw_starts = %d) gives no "
             "screw-roller contact near the pitch point: the helix angle is too large for the "
             "flank angle (reduce screw_lead or increase flank_angle)", k, l, k, b, s, r, n_s);
}

/* _Flank.__init__ of a contact with point (x, y) [m] and unit normal n, on a stage with screw
 * lead per radian ell [m/rad], roller axis distance c [m] and n_s starts
 * (ContactGeometry.slip_jacobians) */
static void flank(prsm_flank *fl, double x, double y, const double n[3], double ell, double c,
                  int n_s) {
    double ns = (double)n_s;
    fl->ax = -y;
    fl->ay = x;
    fl->az = ell;
    fl->bx = y - ns * y;
    fl->by = -x + ns * (x - c);
    fl->px = x;
    fl->py = y;
    fl->nz = n[2];
    fl->pn = x * n[1] - y * n[0];
    fl->radius = sqrt(x * x + y * y);
}

int prsm_stage_contact(int k, const prsm_stage_values *v, prsm_flank fl[2], double *zeta_geometric,
                       double *min_normal_z, char *msg, int len) {
    double out[PRSM_CONTACT_OUT];
    double r_s = v->screw_radius, r_r = v->roller_radius, lead = v->screw_lead;
    double beta = v->flank_angle;
    int n_s = v->screw_starts;
    if (!(n_s >= 1 && isfinite(r_s) && r_s > 0.0 && isfinite(r_r) && r_r > 0.0
          && isfinite(lead) && lead > 0.0 && beta > 0.0 && beta < PRSM_PI / 2.0)) {
        prsm_contact_message(msg, len, k + 1, r_s, r_r, lead, n_s, beta);
        return -1;
    }
    prsm_contact_solve(r_s, r_r, lead, n_s, beta, out);
    if (!prsm_contact_near(r_s, r_r, beta, out)) {
        prsm_contact_message(msg, len, k + 1, r_s, r_r, lead, n_s, beta);
        return -1;
    }
    double ell = lead / (2.0 * PRSM_PI), c = r_s + r_r;
    /* the "-" flank: the rotation by pi about the x axis (ContactGeometry.mirrored) */
    const double mirrored_n[3] = {out[3], -out[4], -out[5]};
    flank(&fl[0], out[0], out[1], out + 3, ell, c, n_s);
    flank(&fl[1], out[0], -out[1], mirrored_n, ell, c, n_s);
    /* _Flank.steady_ratio of the "+" flank */
    *zeta_geometric = -(fl[0].ax * fl[0].bx + fl[0].ay * fl[0].by)
                      / (fl[0].bx * fl[0].bx + fl[0].by * fl[0].by);
    *min_normal_z = pmin(fabs(fl[0].nz), fabs(fl[1].nz));
    return 0;
}
