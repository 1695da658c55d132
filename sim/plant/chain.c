/* Rigid-body dynamics of a tree of revolute joints, for the plant's inner loop (sim/plant/native.py).
 *
 * Recursive Newton-Euler (RNEA) and the composite-rigid-body algorithm (CRBA) in body coordinates,
 * spatial vectors ordered (angular; linear), with the parameters of a Pinocchio model: joint
 * placement (R_p, p_p) in the parent body, joint axis a, spatial inertia and rotor armature. Body
 * i's pose in its parent: (R_p Rot(a, qb_i), p_p), qb_i = s_i q[c_i] + o_i: a body follows one
 * degree of freedom, scaled and offset (mimic joints: a closed linkage such as a parallelogram
 * written as a tree). The forward dynamics are q'' = M(q)^-1 (tau - h(q, q')), M by CRBA and h by
 * RNEA from one set of body poses, transforms and inertias kept in their structured form.
 * Friction acts on the motors' output rates w = S q' (S the motor map) and reaches the joints as
 * S^T f(w). Dynamics only: no controller logic. The reference is Pinocchio
 * (tests/sim/plant/test_native.py compares every function with it).
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
    double motor[MAXJ * MAXJ];  /* S (n x n, row-major): motor output rates w = S q' */
    int mapped;                 /* S is not the identity */
    double damping[MAXJ];       /* viscous friction D of each motor [N m s/rad] */
    double coulomb[MAXJ];       /* Coulomb friction F_c of each motor [N m] */
    double inv_stiction;        /* 1 / v_s [s/rad] */
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

/* The coordinate axis that body i turns about with an identity placement rotation, or -1. */
static int plane_axis(const chain_t *m, int i) {
    static const double I3[9] = {1, 0, 0, 0, 1, 0, 0, 0, 1};
    const double *a = m->axis[i];
    if (memcmp(m->Rp[i], I3, sizeof I3) != 0) return -1;
    for (int k = 0; k < 3; k++)
        if (a[k] == 1.0 && a[(k + 1) % 3] == 0.0 && a[(k + 2) % 3] == 0.0) return k;
    return -1;
}

/* E = (R_p Rot(a, q))^T with Rot(a, q) = I + s K + (1 - c) K^2 (Rodrigues), K = a x. */
static void general_rotation(const chain_t *m, int i, double q, double E[9]) {
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

/* The bodies' poses at the body angles qb: E = Rot(e_k, -q) directly for a joint about
 * coordinate axis k of an unrotated placement (RX, RY, RZ), else the general rotation. */
static void poses(const chain_t *m, const double *qb, pose_t *X) {
    for (int i = 0; i < m->nb; i++) {
        pose_t *P = &X[i];
        int k = plane_axis(m, i), u = (k + 1) % 3, w = (k + 2) % 3;
        memcpy(P->p, m->pp[i], sizeof P->p);
        if (k < 0) {
            general_rotation(m, i, qb[i], P->E);
            continue;
        }
        double c = cos(qb[i]), s = sin(qb[i]);
        memset(P->E, 0, sizeof P->E);
        P->E[4 * k] = 1.0;
        P->E[4 * u] = P->E[4 * w] = c;
        P->E[3 * u + w] = s;
        P->E[3 * w + u] = -s;
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

/* Friction torque S^T (D w + F_c tanh(w / v_s)), w = S qd (S = I: D qd + F_c tanh(qd / v_s)). */
static void friction(const chain_t *m, const double *qd, double *out) {
    int n = m->n;
    if (!m->mapped) {
        for (int i = 0; i < n; i++)
            out[i] = m->damping[i] * qd[i] + m->coulomb[i] * tanh(qd[i] * m->inv_stiction);
        return;
    }
    double f[MAXJ];
    for (int k = 0; k < n; k++) {
        double w = 0;
        for (int l = 0; l < n; l++) w += m->motor[n * k + l] * qd[l];
        f[k] = m->damping[k] * w + m->coulomb[k] * tanh(w * m->inv_stiction);
    }
    for (int j = 0; j < n; j++) {
        double s = 0;
        for (int k = 0; k < n; k++) s += m->motor[n * k + j] * f[k];
        out[j] = s;
    }
}

/* Explicit midpoint, `substeps` steps of h, torque held (sim.plant.ArmPlant._midpoint_steps):
 * qd_half = qd + h/2 a(q, qd), q_half = q + h/2 qd, q+ = q + h qd_half, qd+ = qd + h a(q_half,
 * qd_half), with a = forward dynamics(q, qd, tau - friction(qd)). Updates q and qd in place. */
void chain_midpoint(const chain_t *m, double *q, double *qd, const double *tau, double h,
                    int substeps) {
    int n = m->n;
    double f[MAXJ], t[MAXJ], a[MAXJ], qh[MAXJ], vh[MAXJ], hh = 0.5 * h;
    for (int s = 0; s < substeps; s++) {
        friction(m, qd, f);
        for (int i = 0; i < n; i++) t[i] = tau[i] - f[i];
        chain_forward(m, q, qd, t, a);
        for (int i = 0; i < n; i++) {
            vh[i] = qd[i] + hh * a[i];
            qh[i] = q[i] + hh * qd[i];
        }
        friction(m, vh, f);
        for (int i = 0; i < n; i++) t[i] = tau[i] - f[i];
        chain_forward(m, qh, vh, t, a);
        for (int i = 0; i < n; i++) {
            q[i] += h * vh[i];
            qd[i] += h * a[i];
        }
    }
}

/* Position [m] in the world of `point` (body coordinates of body `joint`) at configuration q,
 * for `count` configurations (rows of q, n each) -> out (count x 3): world rotation R_i =
 * R_parent E_i^T and origin o_i = o_parent + R_parent p_i, from the base to the body. */
void chain_point(const chain_t *m, const double *q, int count, int joint, const double *point,
                 double *out) {
    double R[MAXJ][9], o[MAXJ][3], qc[MAXJ];
    pose_t X[MAXJ];
    for (int c = 0; c < count; c++) {
        expand(m, q + (size_t)c * m->n, 1, qc);
        poses(m, qc, X);
        for (int i = 0; i <= joint; i++) {
            int pa = m->parent[i];
            const double *E = X[i].E;
            for (int k = 0; k < 3; k++) {
                for (int l = 0; l < 3; l++)
                    R[i][3 * k + l] = pa < 0 ? E[3 * l + k] : R[pa][3 * k] * E[3 * l] +
                                      R[pa][3 * k + 1] * E[3 * l + 1] + R[pa][3 * k + 2] * E[3 * l + 2];
                o[i][k] = pa < 0 ? X[i].p[k] : o[pa][k] + R[pa][3 * k] * X[i].p[0] +
                          R[pa][3 * k + 1] * X[i].p[1] + R[pa][3 * k + 2] * X[i].p[2];
            }
        }
        for (int k = 0; k < 3; k++)
            out[3 * c + k] = o[joint][k] + R[joint][3 * k] * point[0] +
                             R[joint][3 * k + 1] * point[1] + R[joint][3 * k + 2] * point[2];
    }
}

/* ---- The hardware-like plant's tick (sim/plant/hardware.py HardwarePlant): motor currents
 * through a first-order lag, Stribeck friction on the motors' output rates, optional two-mass
 * cables; the same equations as the Python reference there. ---- */

typedef struct {
    const chain_t *arm;         /* M(q) and h(q, q') (its own friction fields unused) */
    int cables, steps;
    double S[MAXJ * MAXJ];      /* motor map, n x n row-major */
    double gain[MAXJ];          /* eta K_t: output torque per ampere */
    double coulomb[MAXJ], damping[MAXJ];
    double ratio, v_stribeck, inv_smooth;
    double rotor[MAXJ];         /* J_r on each output coordinate */
    double R[MAXJ * MAXJ];      /* S^T diag(J_r) S, taken off M with cables */
    double k[MAXJ], c[MAXJ];    /* cable stiffness and damping */
    double q0[MAXJ];
    double tau_e, h;            /* current lag, step [s] */
} hw_t;

static double hw_friction(const hw_t *w, int k, double rate) {
    double x = rate / w->v_stribeck;
    double peak = w->coulomb[k] * (1.0 + (w->ratio - 1.0) * exp(-x * x));
    return w->damping[k] * rate + peak * tanh(rate * w->inv_smooth);
}

/* d/dt of x = [q, q', theta_r, theta_r'] (4n) with winding currents cur. */
static void hw_rates(const hw_t *w, const double *x, const double *cur, double *dx) {
    int n = w->arm->n;
    const double *q = x, *v = x + n, *th = x + 2 * n, *om = x + 3 * n;
    double out[MAXJ], joint[MAXJ];
    for (int k = 0; k < n; k++) {
        double sq = 0, sv = 0;
        for (int l = 0; l < n; l++) {
            sq += w->S[n * k + l] * (q[l] - w->q0[l]);
            sv += w->S[n * k + l] * v[l];
        }
        double motor = w->gain[k] * cur[k];
        if (w->cables) {
            out[k] = w->k[k] * (th[k] - sq) + w->c[k] * (om[k] - sv);  /* cable torque */
            dx[3 * n + k] = (motor - out[k] - hw_friction(w, k, om[k])) / w->rotor[k];
        } else {
            out[k] = motor - hw_friction(w, k, sv);
            dx[3 * n + k] = 0.0;
        }
        dx[2 * n + k] = om[k];
    }
    for (int j = 0; j < n; j++) {
        double s = 0;
        for (int k = 0; k < n; k++) s += w->S[n * k + j] * out[k];
        joint[j] = s;
        dx[j] = v[j];
    }
    if (!w->cables) {
        chain_forward(w->arm, q, v, joint, dx + n);
        return;
    }
    double h[MAXJ], M[MAXJ][MAXJ], b[MAXJ];
    bias_and_mass(w->arm, q, v, h, M);
    for (int i = 0; i < n; i++) {
        b[i] = joint[i] - h[i];
        for (int j = 0; j < n; j++) M[i][j] -= w->R[n * i + j];
    }
    spd_solve(n, M, b, dx + n);
}

/* One tick: `steps` explicit-midpoint steps, each with the current's exact mean over the step
 * (command cmd held, lag tau_e from i0); x (4n) and i0 updated in place. */
void hw_integrate(const hw_t *w, double *x, double *i0, const double *cmd) {
    int n = w->arm->n, nx = 4 * n;
    double k1[4 * MAXJ], mid[4 * MAXJ], k2[4 * MAXJ], cur[MAXJ], h = w->h;
    for (int s = 0; s < w->steps; s++) {
        double t = s * h;
        for (int k = 0; k < n; k++)
            cur[k] = w->tau_e > 0 ? cmd[k] + (i0[k] - cmd[k]) * (w->tau_e / h) *
                                                 (exp(-t / w->tau_e) - exp(-(t + h) / w->tau_e))
                                  : cmd[k];
        hw_rates(w, x, cur, k1);
        for (int k = 0; k < nx; k++) mid[k] = x[k] + 0.5 * h * k1[k];
        hw_rates(w, mid, cur, k2);
        for (int k = 0; k < nx; k++) x[k] += h * k2[k];
    }
    for (int k = 0; k < n; k++)
        i0[k] = w->tau_e > 0 ? cmd[k] + (i0[k] - cmd[k]) * exp(-w->steps * h / w->tau_e) : cmd[k];
}
