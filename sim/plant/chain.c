/* The plant's dynamics kernel (sim/plant/kernel.py): a tree of revolute joints and its drives.
 *
 * Rigid-body dynamics: recursive Newton-Euler (RNEA) and the composite-rigid-body algorithm (CRBA)
 * in body coordinates, spatial vectors ordered (angular; linear), with the parameters of a
 * Pinocchio model: joint placement (R_p, p_p) in the parent body, joint axis a, spatial inertia and
 * rotor armature. Body i's pose in its parent: (R_p Rot(a, qb_i), p_p), qb_i = s_i q[c_i] + o_i: a
 * body follows one degree of freedom, scaled and offset (mimic joints: a closed linkage such as a
 * parallelogram written as a tree). The forward dynamics are q'' = M(q)^-1 (tau - h(q, q')), M by
 * CRBA and h by RNEA from one set of body poses, transforms and inertias kept in their structured
 * form (Featherstone, Rigid Body Dynamics Algorithms, 2008).
 *
 * The drives (plant_tick): each motor's command from the joint torques (torque limits, the DAC's
 * step and range), its current following the command through a first-order lag, its torque on
 * its output coordinate through the motor map S, Stribeck friction on the output rate, and
 * optionally a two-mass cable between rotor and link; explicit midpoint steps over the tick. The equations are those of sim/plant/hardware.py's docstring; the ideal
 * plant is the case with the current equal to the command, no stiction peak and rigid cables.
 * Pinocchio and a plain reference in tests/sim/plant/ check every function.
 */
#include <math.h>
#include <string.h>

#define MAXJ 8

/* The small spatial helpers inlined: the compilers' heuristics leave them as calls, which
 * doubles the cost of RNEA. */
#if defined(__GNUC__)
#define SPATIAL static inline __attribute__((always_inline))
#else
#define SPATIAL static inline
#endif

typedef struct {
    int n;                      /* degrees of freedom */
    int nb;                     /* bodies (joints of the tree), nb >= n */
    int parent[MAXJ];           /* parent body index, -1 for the base; parent[i] < i */
    int coord[MAXJ];            /* the degree of freedom body i follows */
    double scale[MAXJ];         /* qb_i = scale_i q[coord_i] + offset_i */
    double offset[MAXJ];
    double Rp[MAXJ][9];         /* joint placement rotation, row-major */
    double pp[MAXJ][3];         /* joint placement translation [m] */
    double axis[MAXJ][3];       /* unit joint axis in the body frame */
    double inertia[MAXJ][36];   /* 6x6 spatial inertia about the body origin, (ang; lin) */
    double armature[MAXJ];      /* rotor inertia reflected to each degree of freedom [kg m^2] */
    double gravity[3];          /* [m/s^2], e.g. (0, 0, -9.81) */
} chain_t;

SPATIAL void cross3(const double a[3], const double b[3], double c[3]) {
    c[0] = a[1] * b[2] - a[2] * b[1];
    c[1] = a[2] * b[0] - a[0] * b[2];
    c[2] = a[0] * b[1] - a[1] * b[0];
}

/* motion cross product v x m */
SPATIAL void crm(const double v[6], const double m[6], double out[6]) {
    double t[3];
    cross3(v, m, out);
    cross3(v, m + 3, out + 3);
    cross3(v + 3, m, t);
    out[3] += t[0]; out[4] += t[1]; out[5] += t[2];
}

/* force cross product v x* f */
SPATIAL void crf(const double v[6], const double f[6], double out[6]) {
    double t[3];
    cross3(v, f, out);
    cross3(v + 3, f + 3, t);
    out[0] += t[0]; out[1] += t[1]; out[2] += t[2];
    cross3(v, f + 3, out + 3);
}

/* Body angles (or rates, offset = 0) of the degrees of freedom x. */
static void expand(const chain_t *m, const double *x, int with_offset, double *xb) {
    for (int i = 0; i < m->nb; i++)
        xb[i] = m->scale[i] * x[m->coord[i]] + (with_offset ? m->offset[i] : 0.0);
}

/* ---- Spatial algebra by its structure (Featherstone, Rigid Body Dynamics Algorithms, 2008,
 * chapter 2; Pinocchio's SE3 and Inertia): a transform as a rotation and a
 * translation, a rigid-body inertia as a mass, a first moment and a rotational inertia. ---- */

/* Body i's pose in its parent: E = R^T (parent -> body coordinates) and the joint origin p in
 * the parent [m]; the motion transform X = [E 0; -E p x  E]. */
typedef struct {
    double E[9], p[3];
} pose_t;

/* A rigid-body inertia about a body's origin: mass m [kg], first moment h = m c [kg m] and
 * rotational inertia I_o [kg m^2]; the spatial inertia [I_o  h x; -h x  m 1]. */
typedef struct {
    double m, h[3], I[9];
} rbi_t;

/* E = (R_p Rot(a, q))^T with Rot(a, q) = I + s K + (1 - c) K^2 (Rodrigues), K = a x. */
static void rotation(const chain_t *m, int i, double q, double E[9]) {
    const double *a = m->axis[i], *P = m->Rp[i];
    double s = sin(q), c = 1.0 - cos(q), J[9];
    double K[9] = {0, -a[2], a[1], a[2], 0, -a[0], -a[1], a[0], 0};
    for (int k = 0; k < 3; k++)
        for (int l = 0; l < 3; l++) {
            double kk = K[3 * k] * K[l] + K[3 * k + 1] * K[3 + l] + K[3 * k + 2] * K[6 + l];
            J[3 * k + l] = (k == l) + s * K[3 * k + l] + c * kk;
        }
    for (int k = 0; k < 3; k++)  /* E[l][k] = R[k][l], R = P J */
        for (int l = 0; l < 3; l++)
            E[3 * l + k] = P[3 * k] * J[l] + P[3 * k + 1] * J[3 + l] + P[3 * k + 2] * J[6 + l];
}

/* The bodies' poses at the body angles qb. */
static void poses(const chain_t *m, const double *qb, pose_t *X) {
    for (int i = 0; i < m->nb; i++) {
        memcpy(X[i].p, m->pp[i], sizeof X[i].p);
        rotation(m, i, qb[i], X[i].E);
    }
}

/* out = A x (3 x 3, row-major) */
SPATIAL void mat3_vec(const double A[9], const double x[3], double out[3]) {
    for (int r = 0; r < 3; r++) out[r] = A[3 * r] * x[0] + A[3 * r + 1] * x[1] + A[3 * r + 2] * x[2];
}

/* out = E x and out = E^T x */
SPATIAL void rot(const pose_t *X, const double x[3], double out[3]) {
    mat3_vec(X->E, x, out);
}

SPATIAL void rotT(const pose_t *X, const double x[3], double out[3]) {
    const double *E = X->E;
    for (int r = 0; r < 3; r++) out[r] = E[r] * x[0] + E[3 + r] * x[1] + E[6 + r] * x[2];
}

/* A motion vector from the parent's coordinates to the body's: (E w, E (v - p x w)). */
SPATIAL void motion_in(const pose_t *X, const double v[6], double out[6]) {
    double pw[3], d[3];
    cross3(X->p, v, pw);
    for (int k = 0; k < 3; k++) d[k] = v[3 + k] - pw[k];
    rot(X, v, out);
    rot(X, d, out + 3);
}

/* A force from the body's coordinates to the parent's, X^T f: (E^T n + p x E^T f, E^T f). */
SPATIAL void force_out(const pose_t *X, const double f[6], double out[6]) {
    double n[3], pf[3];
    rotT(X, f + 3, out + 3);
    rotT(X, f, n);
    cross3(X->p, out + 3, pf);
    for (int k = 0; k < 3; k++) out[k] = n[k] + pf[k];
}

/* Body i's inertia, read from its spatial inertia: m = I[3][3], h from the block h x. */
SPATIAL void rbi_of(const chain_t *m, int i, rbi_t *out) {
    const double *S = m->inertia[i];
    out->m = S[21];
    out->h[0] = -S[6 * 1 + 5];
    out->h[1] = S[6 * 0 + 5];
    out->h[2] = -S[6 * 0 + 4];
    for (int k = 0; k < 3; k++)
        for (int l = 0; l < 3; l++) out->I[3 * k + l] = S[6 * k + l];
}

/* f = I v: (I_o w + h x v, m v - h x w). */
SPATIAL void rbi_apply(const rbi_t *I, const double v[6], double f[6]) {
    double hv[3], hw[3];
    cross3(I->h, v + 3, hv);
    cross3(I->h, v, hw);
    mat3_vec(I->I, v, f);
    for (int k = 0; k < 3; k++) {
        f[k] += hv[k];
        f[3 + k] = I->m * v[3 + k] - hw[k];
    }
}

/* parent += the child's inertia in the parent's coordinates, X^T I X: with R = E^T and
 * g = R h, h' = g + m p and I_o' = R I_o R^T - (p g^T + g p^T - 2 (g.p) 1) - m (p p^T - |p|^2 1)
 * (the parallel-axis theorem from the child's origin to the parent's). */
static void rbi_add_out(const pose_t *X, const rbi_t *I, rbi_t *parent) {
    const double *p = X->p;
    double g[3], B[9], A[9], col[3], out[3];
    rotT(X, I->h, g);
    for (int l = 0; l < 3; l++) {  /* B = R I_o, column by column; then A = R B^T = R I_o R^T */
        col[0] = I->I[l], col[1] = I->I[3 + l], col[2] = I->I[6 + l];
        rotT(X, col, out);
        B[l] = out[0], B[3 + l] = out[1], B[6 + l] = out[2];
    }
    for (int l = 0; l < 3; l++) {
        rotT(X, B + 3 * l, out);
        A[l] = out[0], A[3 + l] = out[1], A[6 + l] = out[2];
    }
    double gp = g[0] * p[0] + g[1] * p[1] + g[2] * p[2];
    double pp = p[0] * p[0] + p[1] * p[1] + p[2] * p[2];
    for (int k = 0; k < 3; k++) {
        for (int l = 0; l < 3; l++) {
            double d = (k == l) ? 2.0 * gp + I->m * pp : 0.0;
            parent->I[3 * k + l] += A[3 * k + l] - (p[k] * g[l] + g[k] * p[l]) -
                                    I->m * p[k] * p[l] + d;
        }
        parent->h[k] += g[k] + I->m * p[k];
    }
    parent->m += I->m;
}

/* RNEA over the bodies at their poses X, body rates qd and accelerations qdd, with gravity,
 * projected on the degrees of freedom: tau_j = sum over the bodies i following j of
 * s_i (a_i . n_i); no armature. */
static void body_rnea(const chain_t *m, const pose_t *X, const double *qd, const double *qdd,
                      double *tau) {
    int nb = m->nb;
    double v[MAXJ][6], a[MAXJ][6], f[MAXJ][6], zero[6] = {0};
    double a0[6] = {0, 0, 0, -m->gravity[0], -m->gravity[1], -m->gravity[2]};
    for (int i = 0; i < nb; i++) {
        const double *ax = m->axis[i];
        int p = m->parent[i];
        double vJ[6] = {ax[0] * qd[i], ax[1] * qd[i], ax[2] * qd[i], 0, 0, 0};
        double t[6], h[6];
        rbi_t I;
        motion_in(&X[i], p < 0 ? zero : v[p], v[i]);
        for (int k = 0; k < 3; k++) v[i][k] += vJ[k];
        crm(v[i], vJ, t);
        motion_in(&X[i], p < 0 ? a0 : a[p], a[i]);
        for (int k = 0; k < 6; k++) a[i][k] += t[k];
        for (int k = 0; k < 3; k++) a[i][k] += ax[k] * qdd[i];
        rbi_of(m, i, &I);
        rbi_apply(&I, a[i], f[i]);
        rbi_apply(&I, v[i], h);
        crf(v[i], h, t);
        for (int k = 0; k < 6; k++) f[i][k] += t[k];
    }
    for (int j = 0; j < m->n; j++) tau[j] = 0.0;
    for (int i = nb - 1; i >= 0; i--) {
        const double *ax = m->axis[i];
        tau[m->coord[i]] += m->scale[i] * (ax[0] * f[i][0] + ax[1] * f[i][1] + ax[2] * f[i][2]);
        int p = m->parent[i];
        if (p >= 0) {
            double t[6];
            force_out(&X[i], f[i], t);
            for (int k = 0; k < 6; k++) f[p][k] += t[k];
        }
    }
}

/* tau = RNEA(q, qd, qdd) = M(q) qdd + C(q, qd) qd + g(q), M with the armature. */
void chain_rnea(const chain_t *m, const double *q, const double *qd, const double *qdd,
                double *tau) {
    double qb[MAXJ], vb[MAXJ], ab[MAXJ];
    pose_t X[MAXJ];
    expand(m, q, 1, qb);
    expand(m, qd, 0, vb);
    expand(m, qdd, 0, ab);
    poses(m, qb, X);
    body_rnea(m, X, vb, ab, tau);
    for (int j = 0; j < m->n; j++) tau[j] += m->armature[j] * qdd[j];
}

/* M(q) with the armature by the composite-rigid-body algorithm (Featherstone 2008, chapter 6)
 * over the bodies at their poses X, projected on the degrees of freedom:
 * M_jk = sum over the bodies i following j and l following k of s_i s_l Mb_il. */
static void body_mass(const chain_t *m, const pose_t *X, double M[MAXJ][MAXJ]) {
    rbi_t C[MAXJ];
    for (int i = 0; i < m->nb; i++) rbi_of(m, i, &C[i]);
    for (int i = m->nb - 1; i > 0; i--)
        if (m->parent[i] >= 0) rbi_add_out(&X[i], &C[i], &C[m->parent[i]]);
    for (int j = 0; j < m->n; j++)
        for (int k = 0; k < m->n; k++) M[j][k] = (j == k) ? m->armature[j] : 0.0;
    for (int i = 0; i < m->nb; i++) {
        const double *ax = m->axis[i];
        double F[6], t[6];  /* F = C_i S_i, S_i = (axis; 0) */
        mat3_vec(C[i].I, ax, F);
        cross3(ax, C[i].h, F + 3);
        int ci = m->coord[i];
        M[ci][ci] += m->scale[i] * m->scale[i] * (ax[0] * F[0] + ax[1] * F[1] + ax[2] * F[2]);
        for (int j = i; m->parent[j] >= 0;) {
            force_out(&X[j], F, t);
            memcpy(F, t, sizeof F);
            j = m->parent[j];
            const double *aj = m->axis[j];
            double Mij = m->scale[i] * m->scale[j] * (aj[0] * F[0] + aj[1] * F[1] + aj[2] * F[2]);
            M[ci][m->coord[j]] += Mij;
            M[m->coord[j]][ci] += Mij;
        }
    }
}

/* M(q) with the armature, n x n row-major. */
void chain_mass(const chain_t *m, const double *q, double *out) {
    double qb[MAXJ], M[MAXJ][MAXJ];
    pose_t X[MAXJ];
    expand(m, q, 1, qb);
    poses(m, qb, X);
    body_mass(m, X, M);
    for (int k = 0; k < m->n; k++)
        for (int j = 0; j < m->n; j++) out[m->n * k + j] = M[k][j];
}

/* Solve A x = b (n x n, symmetric positive definite) by Cholesky. */
static void spd_solve(int n, double A[MAXJ][MAXJ], const double *b, double *x) {
    double L[MAXJ][MAXJ], y[MAXJ];
    for (int j = 0; j < n; j++) {
        double d = A[j][j];
        for (int k = 0; k < j; k++) d -= L[j][k] * L[j][k];
        L[j][j] = sqrt(d);
        for (int i = j + 1; i < n; i++) {
            double s = A[i][j];
            for (int k = 0; k < j; k++) s -= L[i][k] * L[j][k];
            L[i][j] = s / L[j][j];
        }
    }
    for (int i = 0; i < n; i++) {
        double s = b[i];
        for (int k = 0; k < i; k++) s -= L[i][k] * y[k];
        y[i] = s / L[i][i];
    }
    for (int i = n - 1; i >= 0; i--) {
        double s = y[i];
        for (int k = i + 1; k < n; k++) s -= L[k][i] * x[k];
        x[i] = s / L[i][i];
    }
}

/* h(q, q') = C(q, q') q' + g(q) and M(q) with the armature, from one set of body poses: the
 * bias by RNEA at zero acceleration, M by the composite-rigid-body algorithm (mimic bodies). */
static void bias_and_mass(const chain_t *m, const double *q, const double *qd, double *h,
                          double M[MAXJ][MAXJ]) {
    double qb[MAXJ], vb[MAXJ], zero[MAXJ] = {0};
    pose_t X[MAXJ];
    expand(m, q, 1, qb);
    expand(m, qd, 0, vb);
    poses(m, qb, X);
    body_rnea(m, X, vb, zero, h);
    body_mass(m, X, M);
}

/* Forward dynamics: M(q) qdd + C(q, qd) qd + g(q) = tau, M with the armature, solved as
 * qdd = M(q)^-1 (tau - h(q, qd)) by Cholesky. */
void chain_forward(const chain_t *m, const double *q, const double *qd, const double *tau,
                   double *qdd) {
    double h[MAXJ], M[MAXJ][MAXJ], b[MAXJ];
    bias_and_mass(m, q, qd, h, M);
    for (int i = 0; i < m->n; i++) b[i] = tau[i] - h[i];
    spd_solve(m->n, M, b, qdd);
}

/* ---- The drives between the motor commands and the arm ---- */

typedef struct {
    const chain_t *arm;         /* M(q) and h(q, q') */
    int cables, steps;          /* two-mass cables (else rigid); midpoint steps per tick */
    double S[MAXJ * MAXJ];      /* motor map, n x n row-major: output angles theta = S (q - q0) */
    double gain[MAXJ];          /* output torque per unit of command (eta K_t per ampere) */
    double coulomb[MAXJ], damping[MAXJ];  /* F_c [N m], D [N m s/rad] on each output */
    double ratio, v_stribeck, inv_smooth; /* F_s / F_c, v_S [rad/s], 1 / v_s [s/rad] */
    double rotor[MAXJ];         /* J_r on each output coordinate [kg m^2] */
    double R[MAXJ * MAXJ];      /* S^T diag(J_r) S, the rotors taken off M with cables */
    double k[MAXJ], c[MAXJ];    /* cable stiffness [N m/rad] and damping [N m s/rad] */
    double q0[MAXJ];            /* home posture, where the cables are relaxed [rad] */
    double tau_e, h;            /* current lag, step [s] */
    double tau_max[MAXJ];       /* joint torque limits [N m] (INFINITY: none) */
    double map[MAXJ * MAXJ];    /* the motors' commands from the joint torques, n x n */
    double c_max, c_step;       /* the command's full scale (INFINITY: none), its DAC step (0) */
} plant_t;

/* f(w) = D w + [F_c + (F_s - F_c) exp(-(w / v_S)^2)] tanh(w / v_s) on output k. */
static double friction(const plant_t *p, int k, double w) {
    double x = w / p->v_stribeck, peak = p->coulomb[k];
    if (p->ratio != 1.0) peak *= 1.0 + (p->ratio - 1.0) * exp(-x * x);
    return p->damping[k] * w + peak * tanh(w * p->inv_smooth);
}

/* d/dt of x = [q, q', theta_r, theta_r'] (4n) with the winding currents cur: rigid,
 * M q'' + h = S^T (eta K_t i - f(S q')); with cables, tau_s = k (theta_r - S (q - q0)) +
 * c (theta_r' - S q'), (M - S^T J_r S) q'' + h = S^T tau_s, J_r theta_r'' = eta K_t i - tau_s -
 * f(theta_r'). */
static void rates(const plant_t *p, const double *x, const double *cur, double *dx) {
    int n = p->arm->n;
    const double *q = x, *v = x + n, *th = x + 2 * n, *om = x + 3 * n;
    double out[MAXJ], joint[MAXJ];
    for (int k = 0; k < n; k++) {
        double sq = 0, sv = 0;
        for (int l = 0; l < n; l++) {
            sq += p->S[n * k + l] * (q[l] - p->q0[l]);
            sv += p->S[n * k + l] * v[l];
        }
        double motor = p->gain[k] * cur[k];
        if (p->cables) {
            out[k] = p->k[k] * (th[k] - sq) + p->c[k] * (om[k] - sv);
            dx[3 * n + k] = (motor - out[k] - friction(p, k, om[k])) / p->rotor[k];
        } else {
            out[k] = motor - friction(p, k, sv);
            dx[3 * n + k] = 0.0;
        }
        dx[2 * n + k] = om[k];
    }
    for (int j = 0; j < n; j++) {
        double s = 0;
        for (int k = 0; k < n; k++) s += p->S[n * k + j] * out[k];
        joint[j] = s;
        dx[j] = v[j];
    }
    if (!p->cables) {
        chain_forward(p->arm, q, v, joint, dx + n);
        return;
    }
    double h[MAXJ], M[MAXJ][MAXJ], b[MAXJ];
    bias_and_mass(p->arm, q, v, h, M);
    for (int i = 0; i < n; i++) {
        b[i] = joint[i] - h[i];
        for (int j = 0; j < n; j++) M[i][j] -= p->R[n * i + j];
    }
    spd_solve(n, M, b, dx + n);
}

/* The command of each motor for the joint torques tau: c = map clip(tau, +-tau_max), rounded to
 * the DAC's step c_step (c_step > 0; to even on a tie) and clipped to +-c_max. Returns 1 if a
 * limit cut the torque or the command. */
static int command(const plant_t *p, const double *tau, double *cmd) {
    int n = p->arm->n, cut = 0;
    double u[MAXJ];
    for (int j = 0; j < n; j++) {
        u[j] = tau[j] > p->tau_max[j] ? p->tau_max[j] : tau[j] < -p->tau_max[j] ? -p->tau_max[j]
                                                                                 : tau[j];
        cut |= u[j] != tau[j];
    }
    for (int k = 0; k < n; k++) {
        double c = 0;
        for (int j = 0; j < n; j++) c += p->map[n * k + j] * u[j];
        cut |= fabs(c) > p->c_max;
        if (p->c_step > 0) c = p->c_step * nearbyint(c / p->c_step);
        cmd[k] = c > p->c_max ? p->c_max : c < -p->c_max ? -p->c_max : c;
    }
    return cut;
}

/* One tick with the joint torques tau held: the motors' command (command()), then `steps`
 * explicit-midpoint steps of h, x+ = x + h f(x + h/2 f(x, i_s), i_s), each with the current's
 * exact mean over its step, i_s = c + (i0 - c) (tau_e / h) (e^(-t/tau_e) - e^(-(t+h)/tau_e))
 * (i_s = c when tau_e = 0); then i0 = c + (i0 - c) e^(-steps h / tau_e). x (4n) and i0 (n) are
 * updated in place. Returns command()'s cut. */
int plant_tick(const plant_t *p, double *x, double *i0, const double *tau) {
    int n = p->arm->n, nx = 4 * n;
    double k1[4 * MAXJ], mid[4 * MAXJ], k2[4 * MAXJ], cur[MAXJ], cmd[MAXJ], h = p->h;
    int cut = command(p, tau, cmd);
    for (int s = 0; s < p->steps; s++) {
        double t = s * h;
        for (int k = 0; k < n; k++)
            cur[k] = p->tau_e > 0 ? cmd[k] + (i0[k] - cmd[k]) * (p->tau_e / h) *
                                                 (exp(-t / p->tau_e) - exp(-(t + h) / p->tau_e))
                                  : cmd[k];
        rates(p, x, cur, k1);
        for (int k = 0; k < nx; k++) mid[k] = x[k] + 0.5 * h * k1[k];
        rates(p, mid, cur, k2);
        for (int k = 0; k < nx; k++) x[k] += h * k2[k];
    }
    for (int k = 0; k < n; k++)
        i0[k] = p->tau_e > 0 ? cmd[k] + (i0[k] - cmd[k]) * exp(-p->steps * h / p->tau_e) : cmd[k];
    return cut;
}

/* The closed loop's ticks tick0 ... tick0 + count - 1 on the ideal plant (sim/loop/closed_loop.py,
 * between two refreshes): each tick the encoders' reading q~ = res round(q / res) (q where res
 * is NULL), the controller's step (the exported library's rhmpc_step, called through `step`),
 * then plant_tick; each tick's records, row k: q after the tick, the reference point r_{tick+1}
 * (the first of the library's rhmpc_horizon), u, tau, tau_command and the step's time, read
 * from the controller's public fields. Returns plant_tick's cut of the last tick. */
typedef int (*step_fn)(void *ctl, long long tick, const double *q, double *tau);
typedef const double *(*horizon_fn)(const void *ctl, long long tick);
typedef struct {
    step_fn step;
    horizon_fn horizon;
    void *ctl;
    const double *res;                  /* the encoders' resolution [rad], or NULL */
    const double *u, *tau_command;      /* the controller's public fields */
    const long long *step_ns;
} loop_t;

int plant_run(const plant_t *p, double *x, double *i0, const loop_t *L, long long tick0,
              int count, double *q_log, double *ref0, double *u_log, double *tau_log,
              double *cmd_log, long long *step_ns) {
    int n = p->arm->n, cut = 0;
    double q[MAXJ], tau[MAXJ];
    for (int k = 0; k < count; k++) {
        long long tick = tick0 + k;
        for (int j = 0; j < n; j++) q[j] = L->res ? L->res[j] * rint(x[j] / L->res[j]) : x[j];
        L->step(L->ctl, tick, q, tau);
        cut = plant_tick(p, x, i0, tau);
        memcpy(ref0 + 3 * k, L->horizon(L->ctl, tick), 3 * sizeof(double));
        memcpy(q_log + n * k, x, n * sizeof(double));
        memcpy(u_log + n * k, L->u, n * sizeof(double));
        memcpy(tau_log + n * k, tau, n * sizeof(double));
        memcpy(cmd_log + n * k, L->tau_command, n * sizeof(double));
        step_ns[k] = *L->step_ns;
    }
    return cut;
}
