/* Rigid-body dynamics of a tree of revolute joints, for the plant's inner loop (sim/native.py).
 *
 * Featherstone's articulated-body algorithm (ABA) and recursive Newton-Euler (RNEA) in body
 * coordinates, spatial vectors ordered (angular; linear), with the parameters of a Pinocchio
 * model: joint placement (R_p, p_p) in the parent body, joint axis a, spatial inertia and rotor
 * armature. Body i's pose in its parent: (R_p Rot(a, qb_i), p_p), qb_i = s_i q[c_i] + o_i: a
 * body follows one degree of freedom, scaled and offset (mimic joints: a closed linkage such as a
 * parallelogram written as a tree). Without mimic bodies qb = q and the dynamics are ABA; with
 * them, M(q) by the composite-rigid-body algorithm, h by RNEA and q'' = M^-1 (tau - h) by
 * Cholesky; both with transforms and inertias kept in their structured form. Friction acts on the
 * motors' output rates w = S q' (S the motor map) and reaches the joints as S^T f(w). The
 * reference is Pinocchio (tests/sim/plant/test_native.py compares every function with it).
 */
#define _POSIX_C_SOURCE 199309L /* clock_gettime */
#include <math.h>
#include <string.h>
#include <time.h>

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
    int projected;              /* some body is not simply "body i = degree of freedom i" */
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

/* X (6x6, row-major): motion transform from the parent's to body i's coordinates. */
static void transform(const chain_t *m, int i, double q, double X[36], double R[9]) {
    const double *a = m->axis[i], *P = m->Rp[i], *r = m->pp[i];
    double s = sin(q), c = 1.0 - cos(q);
    double K[9] = {0, -a[2], a[1], a[2], 0, -a[0], -a[1], a[0], 0};
    double J[9];  /* Rot(a, q) = I + s K + c K^2 */
    for (int k = 0; k < 3; k++)
        for (int l = 0; l < 3; l++) {
            double kk = K[3 * k] * K[l] + K[3 * k + 1] * K[3 + l] + K[3 * k + 2] * K[6 + l];
            J[3 * k + l] = (k == l) + s * K[3 * k + l] + c * kk;
        }
    for (int k = 0; k < 3; k++)  /* R = P J */
        for (int l = 0; l < 3; l++)
            R[3 * k + l] = P[3 * k] * J[l] + P[3 * k + 1] * J[3 + l] + P[3 * k + 2] * J[6 + l];
    double E[9];  /* E = R^T: parent -> body coordinates */
    for (int k = 0; k < 3; k++)
        for (int l = 0; l < 3; l++) E[3 * k + l] = R[3 * l + k];
    double rx[9] = {0, -r[2], r[1], r[2], 0, -r[0], -r[1], r[0], 0};
    memset(X, 0, 36 * sizeof(double));
    for (int k = 0; k < 3; k++)
        for (int l = 0; l < 3; l++) {
            double er = E[3 * k] * rx[l] + E[3 * k + 1] * rx[3 + l] + E[3 * k + 2] * rx[6 + l];
            X[6 * k + l] = E[3 * k + l];
            X[6 * (k + 3) + l + 3] = E[3 * k + l];
            X[6 * (k + 3) + l] = -er;
        }
}

static void mat6_vec(const double A[36], const double x[6], double y[6]) {
    for (int k = 0; k < 6; k++) {
        double s = 0;
        for (int l = 0; l < 6; l++) s += A[6 * k + l] * x[l];
        y[k] = s;
    }
}

static void mat6T_vec(const double A[36], const double x[6], double y[6]) {
    for (int k = 0; k < 6; k++) {
        double s = 0;
        for (int l = 0; l < 6; l++) s += A[6 * l + k] * x[l];
        y[k] = s;
    }
}

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

/* A += X^T B X (6x6) */
static void add_congruence(double A[36], const double X[36], const double B[36]) {
    double BX[36];
    for (int k = 0; k < 6; k++)
        for (int l = 0; l < 6; l++) {
            double s = 0;
            for (int j = 0; j < 6; j++) s += B[6 * k + j] * X[6 * j + l];
            BX[6 * k + l] = s;
        }
    for (int k = 0; k < 6; k++)
        for (int l = 0; l < 6; l++) {
            double s = 0;
            for (int j = 0; j < 6; j++) s += X[6 * j + k] * BX[6 * j + l];
            A[6 * k + l] += s;
        }
}

/* ABA of a model without mimic bodies (qb = q). */
static void body_aba(const chain_t *m, const double *q, const double *qd, const double *tau,
                     double *qdd) {
    int n = m->n;
    double X[MAXJ][36], R[9], v[MAXJ][6], c[MAXJ][6], IA[MAXJ][36], pA[MAXJ][6];
    double U[MAXJ][6], D[MAXJ], u[MAXJ], a[MAXJ][6], zero[6] = {0};
    double a0[6] = {0, 0, 0, -m->gravity[0], -m->gravity[1], -m->gravity[2]};
    for (int i = 0; i < n; i++) {
        const double *ax = m->axis[i];
        transform(m, i, q[i], X[i], R);
        mat6_vec(X[i], m->parent[i] < 0 ? zero : v[m->parent[i]], v[i]);
        double vJ[6] = {ax[0] * qd[i], ax[1] * qd[i], ax[2] * qd[i], 0, 0, 0};
        for (int k = 0; k < 6; k++) v[i][k] += vJ[k];
        crm(v[i], vJ, c[i]);
        double h[6];
        memcpy(IA[i], m->inertia[i], sizeof IA[i]);
        mat6_vec(m->inertia[i], v[i], h);
        crf(v[i], h, pA[i]);
    }
    for (int i = n - 1; i >= 0; i--) {
        const double *ax = m->axis[i];
        for (int k = 0; k < 6; k++)
            U[i][k] = IA[i][6 * k] * ax[0] + IA[i][6 * k + 1] * ax[1] + IA[i][6 * k + 2] * ax[2];
        D[i] = ax[0] * U[i][0] + ax[1] * U[i][1] + ax[2] * U[i][2] + m->armature[i];
        u[i] = tau[i] - (ax[0] * pA[i][0] + ax[1] * pA[i][1] + ax[2] * pA[i][2]);
        int p = m->parent[i];
        if (p >= 0) {
            double Ia[36], pa[6], t[6];
            for (int k = 0; k < 6; k++)
                for (int l = 0; l < 6; l++) Ia[6 * k + l] = IA[i][6 * k + l] - U[i][k] * U[i][l] / D[i];
            mat6_vec(Ia, c[i], t);
            for (int k = 0; k < 6; k++) pa[k] = pA[i][k] + t[k] + U[i][k] * u[i] / D[i];
            add_congruence(IA[p], X[i], Ia);
            mat6T_vec(X[i], pa, t);
            for (int k = 0; k < 6; k++) pA[p][k] += t[k];
        }
    }
    for (int i = 0; i < n; i++) {
        const double *ax = m->axis[i];
        double ap[6];
        mat6_vec(X[i], m->parent[i] < 0 ? a0 : a[m->parent[i]], ap);
        for (int k = 0; k < 6; k++) ap[k] += c[i][k];
        double Ua = 0;
        for (int k = 0; k < 6; k++) Ua += U[i][k] * ap[k];
        qdd[i] = (u[i] - Ua) / D[i];
        for (int k = 0; k < 6; k++) a[i][k] = ap[k];
        a[i][0] += ax[0] * qdd[i]; a[i][1] += ax[1] * qdd[i]; a[i][2] += ax[2] * qdd[i];
    }
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

/* The bodies' poses at the body angles qb: E = Rot(e_k, -q) directly for a joint about
 * coordinate axis k of an unrotated placement (RX, RY, RZ), else from the general transform. */
static void poses(const chain_t *m, const double *qb, pose_t *X) {
    double D[36], R[9];
    for (int i = 0; i < m->nb; i++) {
        pose_t *P = &X[i];
        int k = plane_axis(m, i), u = (k + 1) % 3, w = (k + 2) % 3;
        memcpy(P->p, m->pp[i], sizeof P->p);
        if (k < 0) {
            transform(m, i, qb[i], D, R);
            for (int r = 0; r < 3; r++)
                for (int l = 0; l < 3; l++) P->E[3 * r + l] = R[3 * l + r];
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

/* q'' = M(q)^-1 (tau - h(q, q')) by Cholesky: the dynamics of a model with mimic bodies. */
static void projected_fd(const chain_t *m, const double *q, const double *qd, const double *tau,
                         double *qdd) {
    double h[MAXJ], M[MAXJ][MAXJ], b[MAXJ];
    bias_and_mass(m, q, qd, h, M);
    for (int i = 0; i < m->n; i++) b[i] = tau[i] - h[i];
    spd_solve(m->n, M, b, qdd);
}

/* qdd = forward dynamics: M(q) qdd + C(q, qd) qd + g(q) = tau, M with the armature. */
void chain_aba(const chain_t *m, const double *q, const double *qd, const double *tau,
               double *qdd) {
    if (m->projected)
        projected_fd(m, q, qd, tau, qdd);
    else
        body_aba(m, q, qd, tau, qdd);
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
 * qd_half), with a = ABA(q, qd, tau - friction(qd)). Updates q and qd in place. */
void chain_midpoint(const chain_t *m, double *q, double *qd, const double *tau, double h,
                    int substeps) {
    int n = m->n;
    double f[MAXJ], t[MAXJ], a[MAXJ], qh[MAXJ], vh[MAXJ], hh = 0.5 * h;
    for (int s = 0; s < substeps; s++) {
        friction(m, qd, f);
        for (int i = 0; i < n; i++) t[i] = tau[i] - f[i];
        chain_aba(m, q, qd, t, a);
        for (int i = 0; i < n; i++) {
            vh[i] = qd[i] + hh * a[i];
            qh[i] = q[i] + hh * qd[i];
        }
        friction(m, vh, f);
        for (int i = 0; i < n; i++) t[i] = tau[i] - f[i];
        chain_aba(m, qh, vh, t, a);
        for (int i = 0; i < n; i++) {
            q[i] += h * vh[i];
            qd[i] += h * a[i];
        }
    }
}

/* Position [m] in the world of `point` (body coordinates of joint `joint`) at configuration q,
 * for `count` configurations (rows of q, n each) -> out (count x 3). */
void chain_point(const chain_t *m, const double *q, int count, int joint, const double *point,
                 double *out) {
    double X[36], R[MAXJ][9], p[MAXJ][3], Rl[9], qc[MAXJ];
    for (int c = 0; c < count; c++) {
        expand(m, q + (size_t)c * m->n, 1, qc);
        for (int i = 0; i <= joint; i++) {
            int pa = m->parent[i];
            transform(m, i, qc[i], X, Rl);
            if (pa < 0) {
                memcpy(R[i], Rl, sizeof Rl);
                memcpy(p[i], m->pp[i], sizeof p[i]);
            } else {
                for (int k = 0; k < 3; k++) {
                    for (int l = 0; l < 3; l++)
                        R[i][3 * k + l] = R[pa][3 * k] * Rl[l] + R[pa][3 * k + 1] * Rl[3 + l] +
                                          R[pa][3 * k + 2] * Rl[6 + l];
                    p[i][k] = p[pa][k] + R[pa][3 * k] * m->pp[i][0] +
                              R[pa][3 * k + 1] * m->pp[i][1] + R[pa][3 * k + 2] * m->pp[i][2];
                }
            }
        }
        for (int k = 0; k < 3; k++)
            out[3 * c + k] = p[joint][k] + R[joint][3 * k] * point[0] +
                             R[joint][3 * k + 1] * point[1] + R[joint][3 * k + 2] * point[2];
    }
}

/* The output offset of a linearised arm, d = p(q0 + x_q) - (C x + y0) (rhmpc.control.offset):
 * the end-point of `point` in joint `joint`'s frame by forward kinematics at q = q0 + x[0..n-1],
 * minus the linear model's output; C is 3 x 2n, row-major. */
void chain_offset(const chain_t *m, const double *x, const double *q0, const double *C,
                  const double *y0, int joint, const double *point, double *out) {
    int n = m->n;
    double q[MAXJ], p[3];
    for (int i = 0; i < n; i++) q[i] = q0[i] + x[i];
    chain_point(m, q, 1, joint, point, p);
    for (int r = 0; r < 3; r++) {
        double lin = 0.0;
        for (int k = 0; k < 2 * n; k++) lin += C[2 * n * r + k] * x[k];
        out[r] = p[r] - (lin + y0[r]);
    }
}

/* ---- The loop's tick around the MPC (sim/native.py NativeTick): encoders, observer,
 * cancellation and plant, the same operations in the same order as sim/loop.py's Python path
 * (sim.sensors encoder quantisation, sim.plant.observer.JointObserver, sim.plant). ---- */

typedef struct {
    const chain_t *plant;       /* the true arm */
    const chain_t *model;       /* the controller's model (mismatch), for the cancellation */
    double h;                   /* integration step [s] */
    int substeps;
    int quantise;               /* encoders present */
    double resolution[MAXJ], inv_resolution[MAXJ];
    double tau_max[MAXJ];
    double correct[2 * MAXJ][3 * MAXJ + 1];  /* x = C [x_prior; q~; 1] */
    double predict[2 * MAXJ][3 * MAXJ];      /* x_prior = P [x; u] */
    double q[MAXJ], v[MAXJ];    /* plant state */
    double prior[3 * MAXJ + 1]; /* [x_prior; q~; 1] */
    double post[3 * MAXJ];      /* [x; u_applied] */
    double u[MAXJ];             /* MPC torque, written by the caller */
    double tau[MAXJ];           /* commanded torque (before the clip) */
    int saturated;
} tick_t;

/* Encoders and the observer's correction: post[0:2n] = x_hat. */
void tick_sense(tick_t *t) {
    int n = t->plant->n, nx = 2 * n;
    for (int i = 0; i < n; i++)
        t->prior[nx + i] = t->quantise ? rint(t->q[i] * t->inv_resolution[i]) * t->resolution[i]
                                       : t->q[i];
    t->prior[3 * n] = 1.0;
    for (int k = 0; k < nx; k++) {
        double s = 0;
        for (int l = 0; l <= 3 * n; l++) s += t->correct[k][l] * t->prior[l];
        t->post[k] = s;
    }
}

/* Commanded torque tau = u + RNEA_model(q~, v_hat, 0) + D v_hat + F_c tanh(v_hat / v_s). */
void tick_actuate(tick_t *t) {
    const chain_t *m = t->model;
    int n = m->n;
    double zero[MAXJ] = {0}, bias[MAXJ];
    const double *q = t->prior + 2 * n, *v = t->post + n;
    chain_rnea(m, q, v, zero, bias);
    if (m->mapped) {
        double f[MAXJ];
        friction(m, v, f);
        for (int i = 0; i < n; i++) t->tau[i] = t->u[i] + bias[i] + f[i];
        return;
    }
    for (int i = 0; i < n; i++)
        t->tau[i] = t->u[i] + bias[i] + m->damping[i] * v[i] +
                    m->coulomb[i] * tanh(v[i] * m->inv_stiction);
}

/* Clip, integrate one tick, and predict the observer with the MPC torque that acted. */
void tick_advance(tick_t *t) {
    int n = t->plant->n, nx = 2 * n;
    double applied[MAXJ];
    t->saturated = 0;
    for (int i = 0; i < n; i++) {
        double a = t->tau[i];
        if (a < -t->tau_max[i]) a = -t->tau_max[i];
        if (a > t->tau_max[i]) a = t->tau_max[i];
        applied[i] = a;
        if (a != t->tau[i]) t->saturated = 1;
    }
    chain_midpoint(t->plant, t->q, t->v, applied, t->h, t->substeps);
    for (int i = 0; i < n; i++)
        t->post[nx + i] = t->saturated ? t->u[i] + (applied[i] - t->tau[i]) : t->u[i];
    for (int k = 0; k < nx; k++) {
        double s = 0;
        for (int l = 0; l < 3 * n; l++) s += t->predict[k][l] * t->post[l];
        t->prior[k] = s;
    }
}

/* ---- Control ticks in one call (sim/plant/native.py NativeTick.run_ticks): a compiled
 * controller between the encoders and the cancellation, with no interpreter between ticks. ---- */

/* A compiled controller's tick (rhmpc_tick_ext of an exported controller): u from the state x,
 * the N reference points ref, u_{-1} (NULL: the controller's own last u) and the extra per-tick
 * inputs (NULL: the controller's own). */
typedef int (*control_fn)(void *state, const double *x, const double *ref, const double *u_prev,
                          const double *extra, double *u);

/* The reference points of row k, after the refresh slices due on it have run (the compiled
 * refresh's plan_points, rhmpc/control/refresh.c), or NULL: the points come from `refs`. */
typedef const double *(*points_fn)(void *plan, int k);

/* A chunk of ticks' records, row 0 first (sim/loop/results.py Recorder.start_chunk). */
typedef struct {
    control_fn control;
    void *state;                /* the controller's */
    double *last;               /* its output u (nu = n), read as u_{-1} by the next tick */
    long long *parts;           /* (m, 3): sense, control, actuate [ns] */
    double *tau_mpc, *tau, *q;  /* (m, n): u, the commanded torque, q after the tick */
    double *ref0;               /* (m, 3): the first reference point */
    double *x_saved;            /* (m / every + 1, 2n): x_hat of rows k = phase (mod every) */
    int every, phase;
    points_fn points;           /* NULL, or the points of each row with its slices run */
    void *plan;                 /* points' state */
    double *ref_saved;          /* NULL, or (m / every + 1, N, 3): the points of those rows */
    int ref_len;                /* 3 N */
} records_t;

static long long now_ns(void) {
    struct timespec ts;
    clock_gettime(CLOCK_MONOTONIC, &ts);  /* time.perf_counter_ns's clock on Linux */
    return (long long)ts.tv_sec * 1000000000LL + ts.tv_nsec;
}

/* Rows k0 .. k0 + count - 1: per tick, the encoders and the observer (tick_sense), the controller
 * on x_hat and its N reference points (N x 3, C-ordered, at refs + (k - k0) ref_step: the
 * ticks' points may overlap, as windows of one array do; or from r->points, which first runs
 * the refresh slices due on the row), the commanded torque (tick_actuate) and the plant
 * (tick_advance) -- the calls and the order of the loop's Python path (sim/loop/ticks.py
 * run_ticks), timed at the same places. u_first: u_{-1} of the first tick, or NULL. */
void tick_run(tick_t *t, const records_t *r, int k0, int count, const double *refs,
              long ref_step, const double *u_first) {
    int n = t->plant->n, nx = 2 * n;
    size_t row = n * sizeof(double);
    for (int k = k0; k < k0 + count; k++) {
        const double *ref = r->points ? r->points(r->plan, k) : refs + (k - k0) * ref_step;
        long long t0 = now_ns();
        tick_sense(t);
        long long t1 = now_ns();
        r->control(r->state, t->post, ref, k == k0 ? u_first : NULL, NULL, r->last);
        long long t2 = now_ns();
        memcpy(t->u, r->last, row);
        tick_actuate(t);
        long long t3 = now_ns();
        r->parts[3 * k] = t1 - t0;
        r->parts[3 * k + 1] = t2 - t1;
        r->parts[3 * k + 2] = t3 - t2;
        memcpy(r->tau_mpc + (size_t)k * n, r->last, row);
        memcpy(r->tau + (size_t)k * n, t->tau, row);
        memcpy(r->ref0 + 3 * (size_t)k, ref, 3 * sizeof(double));
        if (r->every > 0 && k % r->every == r->phase) {
            memcpy(r->x_saved + (size_t)(k / r->every) * nx, t->post, nx * sizeof(double));
            if (r->ref_saved)
                memcpy(r->ref_saved + (size_t)(k / r->every) * r->ref_len, ref,
                       (size_t)r->ref_len * sizeof(double));
        }
        tick_advance(t);
        memcpy(r->q + (size_t)k * n, t->q, row);
    }
}

/* ---- The hardware-like plant's tick (sim/plant/hardware.py HardwareTick): motor currents
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
        chain_aba(w->arm, q, v, joint, dx + n);
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
