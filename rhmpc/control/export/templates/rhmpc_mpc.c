/*
 * The MPC of rhmpc_step, the per-tick work of the problem rhmpc.control.mpc.RecedingHorizonMPC
 * describes (its CasADi formulation, rhmpc.control.qp). Numbers (QP maps, screening map, shift,
 * LQ gain) come from rhmpc_data.c, generated from that CondensedQP; level 3 is OSQP's generated
 * code.
 *
 *   p = [x; r_1..r_N; u_prev; d]                 (finiteness check: sum of squares)
 *   l, u = l0 - G p, u0 - G p                    (only with parameter-dependent bounds)
 *   q_z = F_z [p; 1]                             (the slacks' part of q is the constant rho_1)
 *   level 1: z* = -W q_z; if l <= A [z*; 0] <= u: tau = u_max o z*_0, done    (exact)
 *   level 2: the torque-box QP by a primal-dual active set on W, then the dual active set: if it
 *            converges, its KKT residual is small and every envelope row holds: done (exact);
 *            at its cap (RHMPC_BOX_MAX_ITER solves): the fallback
 *   back-off: after k consecutive failed ticks, levels 2 and 3 rest for
 *            min(2^k - 1, RHMPC_BACKOFF_MAX_TICKS) ticks (the fallback unless level 1 settles)
 *   level 3: osqp_update_data_vec; warm start (plan shifted one tick); osqp_solve
 *   solved: tau = clip(u_max o z_0)   else: plan shifted -> clipped LQ (or braking) -> zero
 * Dense maps used every tick are stored column-major (transposed), so that each mat-vec is a
 * sequence of vectorisable axpy's; the sum order per entry is the plain column order.
 */
#include "rhmpc.h"
#include "rhmpc_data.h"
#include "osqp.h"
#include "@OSQP_PREFIX@workspace.h"

#include <math.h>
#include <string.h>

#define SOLVER (&@OSQP_PREFIX@solver)
#define NPE (RHMPC_NPAR + 1)


/* out[r] = sum_c M[r][c] v[c], M row-major (rows x cols) */
static void matvec(const double *M, const double *v, int rows, int cols, double *out) {
  for (int r = 0; r < rows; ++r) {
    const double *row = M + (long)r * cols;
    double s0 = 0.0, s1 = 0.0;
    int c = 0;
    for (; c + 1 < cols; c += 2) {
      s0 += row[c] * v[c];
      s1 += row[c + 1] * v[c + 1];
    }
    if (c < cols) s0 += row[c] * v[c];
    out[r] = s0 + s1;
  }
}

/* Sparse (CSR) matrices: row r holds val[ptr[r]..ptr[r+1]) in the columns col[...]. */
#define CSR(name) rhmpc_##name##_p, rhmpc_##name##_i, rhmpc_##name##_x

static double row_dot(const int *ptr, const int *col, const double *val, int r, const double *v) {
  double s = 0.0;
  for (int k = ptr[r]; k < ptr[r + 1]; ++k) s += val[k] * v[col[k]];
  return s;
}

static void spmv(const int *ptr, const int *col, const double *val, int rows, const double *v,
                 double *out) {
  for (int r = 0; r < rows; ++r) out[r] = row_dot(ptr, col, val, r, v);
}

/* out = M v with M (rows x cols) stored column-major with a column stride of `stride` >= rows
 * entries, a multiple of 8 (zero padding): MT[c * stride + r]. Blocks of 8 rows accumulate
 * over all columns in registers (vectorised, no scalar tail); each entry sums in column
 * order; only the first `rows` entries are written. */
static inline void matvec_cm(const double *restrict MT, const double *restrict v, int rows,
                             int stride, int cols, double *restrict out) {
  for (int r0 = 0; r0 < rows; r0 += 8) {
    double acc[8] = {0.0, 0.0, 0.0, 0.0, 0.0, 0.0, 0.0, 0.0};
    const double *col = MT + r0;
    for (int c = 0; c < cols; ++c, col += stride) {
      const double vc = v[c];
      for (int j = 0; j < 8; ++j) acc[j] += col[j] * vc;
    }
    const int nr = rows - r0 < 8 ? rows - r0 : 8;
    for (int j = 0; j < nr; ++j) out[r0 + j] = acc[j];
  }
}

/* out[perm[r]] = (M v)_r for a block-sparse M (rhmpc_data.h): per block of 8 rows only the
 * listed columns, which hold every non-zero of the block; each entry sums in column order. */
static inline void matvec_blocks(const double *restrict MT, const int *restrict cptr,
                                 const int *restrict cols, const int *restrict perm,
                                 const double *restrict v, int rows, double *restrict out) {
  const int stride = RHMPC_PAD8(rows);
  for (int r0 = 0, b = 0; r0 < rows; r0 += 8, ++b) {
    double acc[8] = {0.0, 0.0, 0.0, 0.0, 0.0, 0.0, 0.0, 0.0};
    for (int ci = cptr[b]; ci < cptr[b + 1]; ++ci) {
      const int c = cols[ci];
      const double vc = v[c];
      const double *col = MT + (long)c * stride + r0;
      for (int j = 0; j < 8; ++j) acc[j] += col[j] * vc;
    }
    const int nr = rows - r0 < 8 ? rows - r0 : 8;
    for (int j = 0; j < nr; ++j) out[perm[r0 + j]] = acc[j];
  }
}

static double clip(double v, double hi) { return v > hi ? hi : (v < -hi ? -hi : v); }

static int status_of(OSQPInt status_val) {
  switch (status_val) {
    case OSQP_SOLVED: return RHMPC_SOLVED;
    case OSQP_SOLVED_INACCURATE: return RHMPC_SOLVED_INACCURATE;
    case OSQP_PRIMAL_INFEASIBLE:
    case OSQP_PRIMAL_INFEASIBLE_INACCURATE: return RHMPC_PRIMAL_INFEASIBLE;
    case OSQP_DUAL_INFEASIBLE:
    case OSQP_DUAL_INFEASIBLE_INACCURATE: return RHMPC_DUAL_INFEASIBLE;
    case OSQP_MAX_ITER_REACHED: return RHMPC_MAX_ITER_REACHED;
    case OSQP_TIME_LIMIT_REACHED: return RHMPC_TIME_LIMIT;
    case OSQP_NON_CVX: return RHMPC_NON_CONVEX;
    case OSQP_SIGINT: return RHMPC_INTERRUPTED;
    default: return RHMPC_UNSOLVED;
  }
}

/* Failures whose OSQP iterate is carried over to the next tick's warm start. */
static int continues(int status) {
  return status == RHMPC_MAX_ITER_REACHED || status == RHMPC_TIME_LIMIT ||
         status == RHMPC_SOLVED_INACCURATE || status == RHMPC_INJECTED;
}

/* RecedingHorizonMPC.reset: no plan, u_prev = 0, OSQP warm start at zero (counters are zeroed
 * by rhmpc_init) */
void rhmpc_mpc_reset(rhmpc_t *ctl) {
  static const double zeros_z[RHMPC_NV] = {0};
  memset(&ctl->mpc, 0, sizeof ctl->mpc);
  ctl->mpc.p_ext[RHMPC_NPAR] = 1.0;
  memcpy(ctl->mpc.l, rhmpc_l0, sizeof(ctl->mpc.l));
  memcpy(ctl->mpc.u, rhmpc_u0, sizeof(ctl->mpc.u));
  for (int i = RHMPC_NZ; i < RHMPC_NV; ++i) ctl->mpc.q[i] = rhmpc_F_ext[i * NPE + RHMPC_NPAR];
  osqp_warm_start(SOLVER, zeros_z, rhmpc_y_plan);
}

void rhmpc_take_over(rhmpc_t *ctl, const double u[RHMPC_NU]) {
  double *p_u = ctl->mpc.p_ext + RHMPC_NX + RHMPC_NY * RHMPC_N;
  for (int i = 0; i < RHMPC_NU; ++i)
    p_u[i] = isfinite(u[i]) ? clip(u[i], rhmpc_u_max[i]) : 0.0;
}

void rhmpc_force_failures(rhmpc_t *ctl, long long count) {
  if (count > 0) ctl->mpc.forced += count;
}

/* The torque that stops the joints within RHMPC_BRAKE_TICKS (fallback.brake_torque):
 * tau = -M0 qdot / (RHMPC_BRAKE_TICKS Ts), clipped by the caller. */
static void brake(const double qdot[RHMPC_NU], double tau[RHMPC_NU]) {
  const double span = RHMPC_BRAKE_TICKS * RHMPC_TS;
  for (int i = 0; i < RHMPC_NU; ++i) {
    double s = 0.0;
    for (int j = 0; j < RHMPC_NU; ++j) s += rhmpc_M0[i * RHMPC_NU + j] * qdot[j];
    tau[i] = -s / span;
  }
}

#if RHMPC_BRAKE
/* The clipped LQ input if its whole clipped plan (slacks zero) keeps every constraint row
 * beyond the torque rows, else the torque that stops the joints within RHMPC_BRAKE_TICKS:
 * tau = -M0 qdot / (RHMPC_BRAKE_TICKS Ts) (clipped by the caller). */
static int lq_or_brake(rhmpc_t *ctl, double tau[RHMPC_NU]) {
  double *v = ctl->mpc.v_lq;
  int holds = 1;
  matvec(rhmpc_minimiser, ctl->mpc.p_ext, RHMPC_NV, NPE, v);
  for (int i = 0; i < RHMPC_NV; ++i) v[i] = i < RHMPC_NZ ? clip(v[i], 1.0) : 0.0; /* slacks 0 */
#if RHMPC_PARAM_BOUNDS
  for (int i = RHMPC_NZ; holds && i < RHMPC_M; ++i) {
    double g = row_dot(CSR(A), i, v);
    holds = g >= ctl->mpc.l[i] && g <= ctl->mpc.u[i];
  }
#endif
  if (holds) {
    for (int i = 0; i < RHMPC_NU; ++i) tau[i] = v[i] * rhmpc_u_max[i];
    return RHMPC_SOURCE_LQ;
  }
  brake(ctl->mpc.p_ext + RHMPC_NX / 2, tau);
  return RHMPC_SOURCE_BRAKE;
}
#endif

/* The bookkeeping of a step whose torque is not the QP's (RecedingHorizonMPC._fallen_back):
 * the failure, the back-off, the plan's age, tau (zero if not finite, source -1: none)
 * clipped into u_prev, the next warm start. */
static int fallen_back(rhmpc_t *ctl, int status, int source, double tau[RHMPC_NU]) {
  ctl->pub.status = status;
  ctl->pub.failures[status] += 1;
  if (status != RHMPC_NONFINITE_INPUT && status != RHMPC_INJECTED && status != RHMPC_BACKOFF &&
      status != RHMPC_ENCODER_FAULT) {
    /* back-off: after k consecutive failed ticks levels 2-3 rest min(2^k - 1, max) ticks */
    if (ctl->mpc.streak < 30) ctl->mpc.streak += 1;
    const long long rest = (1LL << ctl->mpc.streak) - 1;
    ctl->mpc.rest = rest < RHMPC_BACKOFF_MAX_TICKS ? rest : RHMPC_BACKOFF_MAX_TICKS;
  }
  ctl->mpc.plan_age += 1;
  int finite = source >= 0;
  for (int i = 0; finite && i < RHMPC_NU; ++i) finite = isfinite(tau[i]);
  if (!finite) {
    for (int i = 0; i < RHMPC_NU; ++i) tau[i] = 0.0;
    source = RHMPC_SOURCE_ZERO;
  }
  for (int i = 0; i < RHMPC_NU; ++i) tau[i] = clip(tau[i], rhmpc_u_max[i]);
  ctl->pub.source = source;
  ctl->pub.fallbacks[source] += 1;
  for (int i = 0; i < RHMPC_NU; ++i) ctl->mpc.p_ext[RHMPC_NX + RHMPC_NY * RHMPC_N + i] = tau[i];
  ctl->mpc.ws_pending = 0;
  if (ctl->mpc.plan_valid) {
    spmv(CSR(shift), RHMPC_NV, ctl->mpc.plan, ctl->mpc.ws_x);
    memcpy(ctl->mpc.ws_y, rhmpc_y_plan, sizeof(ctl->mpc.ws_y));
    ctl->mpc.ws_x_set = ctl->mpc.ws_y_set = 1;
  }
  return status;
}

/* The fallback chain: plan shifted to this tick -> clipped LQ input (or braking) -> zero. */
static int fallback(rhmpc_t *ctl, int status, int inputs_finite, double tau[RHMPC_NU]) {
  int source = -1;
  const int k = ctl->mpc.plan_age + 1; /* the tick of the plan this one is */
  if (ctl->mpc.plan_valid && k <= RHMPC_PLAN_FALLBACK_TICKS) {
    int b = rhmpc_block_of_tick[k < RHMPC_N - 1 ? k : RHMPC_N - 1];
    for (int i = 0; i < RHMPC_NU; ++i) tau[i] = ctl->mpc.plan[b * RHMPC_NU + i] * rhmpc_u_max[i];
    source = RHMPC_SOURCE_PLAN;
  }
  if (source < 0 && inputs_finite) {
#if RHMPC_BRAKE
    source = lq_or_brake(ctl, tau);
#else
    matvec(rhmpc_gain, ctl->mpc.p_ext, RHMPC_NU, RHMPC_NPAR, tau);
    for (int i = 0; i < RHMPC_NU; ++i) tau[i] += rhmpc_gain0[i];
    source = RHMPC_SOURCE_LQ;
#endif
  }
  return fallen_back(ctl, status, source, tau);
}

/* A step without the QP, for a fault of the state's source (RecedingHorizonMPC.brake): the
 * torque that stops the joints of x within RHMPC_BRAKE_TICKS, counted as `status`. */
int rhmpc_mpc_brake(rhmpc_t *ctl, const double x[RHMPC_NX], int status, double tau[RHMPC_NU]) {
  ctl->pub.ticks += 1;
  ctl->pub.level = ctl->pub.box_iterations = ctl->pub.iterations = 0;
  ctl->mpc.last_screened = 0;
  brake(x + RHMPC_NX / 2, tau);
  return fallen_back(ctl, status, RHMPC_SOURCE_BRAKE, tau);
}

/* Every envelope row (rows NV..M) at [z; 0]: l <= A_env z <= u. The upper and lower row of a
 * limit share their z part, so A_env z is computed once per distinct row (RHMPC_NENV_U). */
static int envelope_holds_at(rhmpc_t *ctl, const double *z) {
#if RHMPC_M > RHMPC_NV
  double *g = ctl->mpc.g_env;
  matvec_blocks(rhmpc_A_env_T, rhmpc_A_env_cptr, rhmpc_A_env_cols, rhmpc_A_env_perm, z,
                RHMPC_NENV_U, g);
  for (int i = 0; i < RHMPC_M - RHMPC_NV; ++i) {
    const double gi = g[rhmpc_env_row[i]];
    if (!(gi - ctl->mpc.u[RHMPC_NV + i] <= 0.0 && ctl->mpc.l[RHMPC_NV + i] - gi <= 0.0)) return 0;
  }
#else
  (void)ctl;
  (void)z;
#endif
  return 1;
}

/* Level 1: z* = -W q_z (slacks 0); 1 if [z*; 0] satisfies every row: torque rows |z*_i| <= 1,
 * slack rows l <= 0 <= u, envelope rows. */
static int screened(rhmpc_t *ctl) {
  matvec_cm(rhmpc_neg_W, ctl->mpc.q, RHMPC_NZ, RHMPC_PAD8(RHMPC_NZ), RHMPC_NZ, ctl->mpc.z_star);
  for (int i = 0; i < RHMPC_NZ; ++i)
    if (!(ctl->mpc.z_star[i] - ctl->mpc.u[i] <= 0.0 && ctl->mpc.l[i] - ctl->mpc.z_star[i] <= 0.0)) return 0;
  for (int i = RHMPC_NZ; i < RHMPC_NV; ++i)
    if (!(0.0 <= ctl->mpc.u[i] && ctl->mpc.l[i] <= 0.0)) return 0;
  return envelope_holds_at(ctl, ctl->mpc.z_star);
}

/* Cholesky W_AA = L L' of the rows/columns idx[0..k) of W (L lower, row-major, stride NZ);
 * 0 if a pivot is not positive. */
static int chol_active(const int *idx, int k, double *L) {
  for (int a = 0; a < k; ++a) {
    for (int b = 0; b <= a; ++b) {
      double s = rhmpc_W[idx[a] * RHMPC_NZ + idx[b]];
      for (int c = 0; c < b; ++c) s -= L[a * RHMPC_NZ + c] * L[b * RHMPC_NZ + c];
      if (a == b) {
        if (!(s > 0.0)) return 0;
        L[a * RHMPC_NZ + a] = sqrt(s);
      } else {
        L[a * RHMPC_NZ + b] = s / L[b * RHMPC_NZ + b];
      }
    }
  }
  return 1;
}

/* out = (L L')^-1 rhs (k entries); tmp: k scratch entries. */
static void chol_solve(const double *L, int k, const double *rhs, double *tmp, double *out) {
  for (int a = 0; a < k; ++a) {
    double s = rhs[a];
    for (int c = 0; c < a; ++c) s -= L[a * RHMPC_NZ + c] * tmp[c];
    tmp[a] = s / L[a * RHMPC_NZ + a];
  }
  for (int a = k - 1; a >= 0; --a) {
    double s = tmp[a];
    for (int c = a + 1; c < k; ++c) s -= L[c * RHMPC_NZ + a] * out[c];
    out[a] = s / L[a * RHMPC_NZ + a];
  }
}

/* Phase 1, primal-dual active set (at most RHMPC_BOX_PDAS_ITER solves):
 *   W_AA mu_A = z*_A - b_A,  z = z* - W_:A mu_A,  z_A = b_A,
 *   A+ = {i in A: b_i mu_i >= -eps_d (1 + |q|_inf)} u {i not in A: |z_i| > 1 + eps_p},
 * until A+ = A. 1 with box_z, box_mu (full length) set; 0 if it did not converge. */
static int box_pdas(rhmpc_t *ctl, double dual_tol) {
  const double *zs = ctl->mpc.z_star;
  signed char *act = ctl->mpc.box_act;
  int *idx = ctl->mpc.box_idx;
  double *L = ctl->mpc.box_L, *y = ctl->mpc.box_y, *mu = ctl->mpc.box_rhs, *z = ctl->mpc.box_z;
  const double upper = 1.0 + RHMPC_BOX_PRIMAL_TOL;
  const int limit = RHMPC_BOX_PDAS_ITER < RHMPC_BOX_MAX_ITER ? RHMPC_BOX_PDAS_ITER
                                                             : RHMPC_BOX_MAX_ITER;
  for (int i = 0; i < RHMPC_NZ; ++i) act[i] = zs[i] > 1.0 ? 1 : (zs[i] < -1.0 ? -1 : 0);
  for (int it = 1; it <= limit; ++it) {
    int k = 0;
    for (int i = 0; i < RHMPC_NZ; ++i)
      if (act[i]) idx[k++] = i;
    ctl->pub.box_iterations = it;
    if (!chol_active(idx, k, L)) return 0;
    for (int a = 0; a < k; ++a) ctl->mpc.box_step[a] = zs[idx[a]] - (double)act[idx[a]];
    chol_solve(L, k, ctl->mpc.box_step, y, mu);
    for (int r = 0; r < RHMPC_NZ; ++r) ctl->mpc.box_tmp[r] = 0.0;
    for (int a = 0; a < k; ++a) { /* mu' W_A (W symmetric: rows idx[a]) */
      const double m = mu[a], *w = rhmpc_W + idx[a] * RHMPC_NZ;
      for (int r = 0; r < RHMPC_NZ; ++r) ctl->mpc.box_tmp[r] += m * w[r];
    }
    for (int r = 0; r < RHMPC_NZ; ++r) z[r] = zs[r] - ctl->mpc.box_tmp[r];
    for (int a = 0; a < k; ++a) z[idx[a]] = (double)act[idx[a]];
    int changed = 0;
    for (int i = 0; i < RHMPC_NZ; ++i) { /* free variables past a bound join */
      if (act[i]) continue;
      if (z[i] > upper) { act[i] = 1; changed = 1; }
      else if (z[i] < -upper) { act[i] = -1; changed = 1; }
    }
    for (int a = 0; a < k; ++a) { /* active bounds with a wrong-sign multiplier leave */
      int i = idx[a];
      if ((double)act[i] * mu[a] < -dual_tol) { act[i] = 0; changed = 1; }
    }
    if (!changed) {
      for (int i = 0; i < RHMPC_NZ; ++i) ctl->mpc.box_mu[i] = 0.0;
      for (int a = 0; a < k; ++a) ctl->mpc.box_mu[idx[a]] = mu[a];
      return 1;
    }
    int n_act = 0;
    for (int i = 0; i < RHMPC_NZ; ++i) n_act += act[i] != 0;
    if (n_act == 0) return 0; /* every bound left: z*, which violates them */
  }
  return 0;
}

/* The largest violation |z_i| - 1, and the lowest index within the primal tolerance of it (a
 * tie: the rounding of one processor against another's never decides which bound enters). */
static int argmax_violation(const double *z, double *viol) {
  double best = fabs(z[0]) - 1.0;
  for (int i = 1; i < RHMPC_NZ; ++i) {
    double v = fabs(z[i]) - 1.0;
    if (v > best || v != v) best = v;
  }
  int p = 0;
  while (p < RHMPC_NZ - 1 && !(fabs(z[p]) - 1.0 >= best - RHMPC_BOX_PRIMAL_TOL)) p++;
  *viol = best;
  return p;
}

/* Phase 2, the Goldfarb-Idnani dual active set from z* (A empty), bounds added in order of
 * largest violation: raise lambda_p of bound p (sigma_p z_p <= 1) along
 *   s = W n_p - W N r,  r = (N'WN)^-1 N'W n_p,  z -= t s,  lambda_A -= t r,  lambda_p += t,
 * t = min(full step to z_p = sigma_p, first active lambda reaching 0 (that bound leaves)).
 * Solves of phase 1 count towards RHMPC_BOX_MAX_ITER. 1 with box_z, box_mu set. */
static int box_dual(rhmpc_t *ctl, double dual_tol) {
  double *z = ctl->mpc.box_z, *sig = ctl->mpc.box_sig, *lam = ctl->mpc.box_lam, *step = ctl->mpc.box_step;
  double *L = ctl->mpc.box_L, *y = ctl->mpc.box_y, *rhs = ctl->mpc.box_rhs, *tmp = ctl->mpc.box_tmp;
  int *act = ctl->mpc.box_idx;
  int k = 0, it = ctl->pub.box_iterations;
  double viol;
  for (int r = 0; r < RHMPC_NZ; ++r) z[r] = ctl->mpc.z_star[r];
  int p = argmax_violation(z, &viol);
  while (viol > RHMPC_BOX_PRIMAL_TOL) {
    const double sp = z[p] > 0.0 ? 1.0 : -1.0;
    const double *wp = rhmpc_W + p * RHMPC_NZ;
    double lam_p = 0.0;
    for (;;) {
      if (++it > RHMPC_BOX_MAX_ITER) {
        ctl->mpc.box_capped = 1;
        return 0;
      }
      ctl->pub.box_iterations = it;
      int j = -1;
      double t;
      if (k) {
        if (!chol_active(act, k, L)) return 0;
        for (int a = 0; a < k; ++a) rhs[a] = rhmpc_W[act[a] * RHMPC_NZ + p] * sp;
        chol_solve(L, k, rhs, tmp, y);
        for (int r = 0; r < RHMPC_NZ; ++r) tmp[r] = 0.0;
        for (int a = 0; a < k; ++a) { /* y' W_A */
          const double m = y[a], *w = rhmpc_W + act[a] * RHMPC_NZ;
          for (int r = 0; r < RHMPC_NZ; ++r) tmp[r] += m * w[r];
        }
        for (int r = 0; r < RHMPC_NZ; ++r) step[r] = sp * wp[r] - tmp[r];
        for (int a = 0; a < k; ++a) rhs[a] = sig[a] * y[a]; /* r, the dual direction */
        t = (sp * z[p] - 1.0) / (sp * step[p]);
        for (int a = 0; a < k; ++a) {
          if (rhs[a] > 0.0) {
            const double ratio = lam[a] / rhs[a];
            if (ratio < t) { t = ratio; j = a; }
          }
        }
        for (int r = 0; r < RHMPC_NZ; ++r) z[r] -= t * step[r];
        for (int a = 0; a < k; ++a) lam[a] -= t * rhs[a];
        for (int a = 0; a < k; ++a) z[act[a]] = sig[a];
      } else {
        for (int r = 0; r < RHMPC_NZ; ++r) step[r] = sp * wp[r];
        t = (sp * z[p] - 1.0) / (sp * step[p]);
        for (int r = 0; r < RHMPC_NZ; ++r) z[r] -= t * step[r];
      }
      lam_p += t;
      if (j < 0) break;
      for (int a = j; a < k - 1; ++a) { /* bound j leaves; p is still the target */
        act[a] = act[a + 1];
        sig[a] = sig[a + 1];
        lam[a] = lam[a + 1];
      }
      k -= 1;
    }
    act[k] = p;
    sig[k] = sp;
    lam[k] = lam_p;
    k += 1;
    z[p] = sp;
    p = argmax_violation(z, &viol);
  }
  for (int a = 0; a < k; ++a)
    if (lam[a] < -dual_tol) return 0;
  for (int i = 0; i < RHMPC_NZ; ++i) ctl->mpc.box_mu[i] = 0.0;
  for (int a = 0; a < k; ++a) ctl->mpc.box_mu[act[a]] = sig[a] * lam[a];
  return 1;
}

/* Level 2: min 1/2 z'Hz + q'z s.t. -1 <= z <= 1, exactly (held to DAQP's solution by
 * tests/rhmpc/control/test_mpc.py): phase 1 PDAS, else phase 2 the dual active set, at most
 * RHMPC_BOX_MAX_ITER Cholesky solves in all; then accepted iff
 * |H z + q + mu|_inf <= eps_kkt (1 + |q|_inf) and every envelope row holds at [z; 0]. */
static int box_solved(rhmpc_t *ctl) {
  const double *q = ctl->mpc.q;
  double zmax = 0.0, qmax = 0.0;
  ctl->pub.box_iterations = 0;
  ctl->mpc.box_capped = 0;
  for (int i = 0; i < RHMPC_NZ; ++i) zmax = fabs(ctl->mpc.z_star[i]) > zmax ? fabs(ctl->mpc.z_star[i]) : zmax;
  if (!(zmax > 1.0)) return 0; /* z* is the box QP's minimiser: an envelope row rejected it */
  for (int i = 0; i < RHMPC_NZ; ++i) qmax = fabs(q[i]) > qmax ? fabs(q[i]) : qmax;
  const double scale = 1.0 + qmax;
  const double dual_tol = RHMPC_BOX_DUAL_TOL * scale;
  if (!box_pdas(ctl, dual_tol) && !box_dual(ctl, dual_tol)) return 0;
  /* KKT certificate from H and q (not W): r = H z + q + mu */
  double *r = ctl->mpc.box_tmp;
  matvec_cm(rhmpc_H, ctl->mpc.box_z, RHMPC_NZ, RHMPC_PAD8(RHMPC_NZ), RHMPC_NZ, r);
  double rmax = 0.0;
  for (int i = 0; i < RHMPC_NZ; ++i) {
    r[i] += q[i];
    r[i] += ctl->mpc.box_mu[i];
    rmax = fabs(r[i]) > rmax ? fabs(r[i]) : rmax;
  }
  if (!(rmax <= RHMPC_BOX_KKT_TOL * scale)) return 0;
  return envelope_holds_at(ctl, ctl->mpc.box_z);
}

/* One MPC tick (RecedingHorizonMPC.step): tau = tau_mpc for the state x, the reference ref
 * (N x 3) and the output offset d (RHMPC_NEXTRA values); u_prev is the last tau. */
int rhmpc_mpc_tick(rhmpc_t *ctl, const double x[RHMPC_NX], const double *ref, const double *d,
                   double tau[RHMPC_NU]) {
  double *p = ctl->mpc.p_ext;
  double *p_u = p + RHMPC_NX + RHMPC_NY * RHMPC_N;
  double *p_extra = p_u + RHMPC_NU;
  double ss = 0.0;
  ctl->pub.ticks += 1;
  memcpy(p, x, RHMPC_NX * sizeof(double));
  memcpy(p + RHMPC_NX, ref, RHMPC_NY * RHMPC_N * sizeof(double));
  for (int i = 0; i < RHMPC_NEXTRA; ++i) p_extra[i] = d[i];
  for (int i = 0; i < NPE; ++i) ss += p[i] * p[i];
  ctl->pub.iterations = 0;
  ctl->pub.level = 0;
  ctl->pub.box_iterations = 0;
  if (!isfinite(ss)) /* NaN, +-inf (or absurd > 1e154) */
    return fallback(ctl, RHMPC_NONFINITE_INPUT, 0, tau);

#if RHMPC_PARAM_BOUNDS
  /* l, u = l0 - G p, u0 - G p: G is zero but on the envelope rows and the bound columns, and
   * an upper and a lower row of a limit share it (one product per distinct row). */
  for (int j = 0; j < RHMPC_NBC; ++j) ctl->mpc.p_bc[j] = p[rhmpc_bound_columns[j]];
  matvec_cm(rhmpc_G_env_T, ctl->mpc.p_bc, RHMPC_NENV_U, RHMPC_PAD8(RHMPC_NENV_U), RHMPC_NBC,
            ctl->mpc.g_env);
  for (int i = 0; i < RHMPC_M - RHMPC_NV; ++i) {
    const double gi = ctl->mpc.g_env[rhmpc_env_row[i]];
    ctl->mpc.l[RHMPC_NV + i] = rhmpc_l0[RHMPC_NV + i] - gi;
    ctl->mpc.u[RHMPC_NV + i] = rhmpc_u0[RHMPC_NV + i] - gi;
  }
#endif
  if (ctl->mpc.forced == 0) {
    const double *zsol = NULL;
    /* q_z; q[NZ..NV) = rho_1 since rhmpc_init */
    matvec_blocks(rhmpc_F_z_T, rhmpc_F_z_cptr, rhmpc_F_z_cols, rhmpc_F_z_perm, p, RHMPC_NZ,
                  ctl->mpc.q);
    if (screened(ctl)) {
      zsol = ctl->mpc.z_star;
      ctl->pub.level = 1;
      ctl->pub.screened += 1;
    } else if (ctl->mpc.rest > 0) {
      ctl->mpc.rest -= 1;
      ctl->pub.level = 1;
      ctl->mpc.last_screened = 0;
      return fallback(ctl, RHMPC_BACKOFF, 1, tau);
    } else if (box_solved(ctl)) {
      zsol = ctl->mpc.box_z;
      ctl->pub.level = 2;
      ctl->pub.boxed += 1;
    } else if (ctl->mpc.box_capped) { /* ADMM would not finish it within MAX_ITER either */
      ctl->pub.level = 2;
      ctl->mpc.last_screened = 0;
      return fallback(ctl, RHMPC_BOX_CAPPED, 1, tau);
    }
    if (zsol != NULL) {
      for (int i = 0; i < RHMPC_NU; ++i) {
        tau[i] = clip(zsol[i] * rhmpc_u_max[i], rhmpc_u_max[i]); /* level 2: |z| <= 1 + eps_p */
        p_u[i] = tau[i];
      }
      memcpy(ctl->mpc.plan, zsol, RHMPC_NZ * sizeof(double));
      for (int i = RHMPC_NZ; i < RHMPC_NV; ++i) ctl->mpc.plan[i] = 0.0;
      ctl->mpc.plan_valid = 1;
      ctl->mpc.plan_age = 0;
      ctl->mpc.streak = 0;
      ctl->mpc.ws_pending = 1;
      ctl->mpc.last_screened = 1;
      ctl->pub.status = RHMPC_SOLVED;
      ctl->pub.source = RHMPC_SOURCE_QP;
      return RHMPC_SOLVED;
    }
  } else {
    matvec(rhmpc_F_ext, p, RHMPC_NV, NPE, ctl->mpc.q);
  }
  ctl->mpc.last_screened = 0;
  ctl->pub.level = 3;
#if RHMPC_PARAM_BOUNDS
  OSQPInt err = osqp_update_data_vec(SOLVER, ctl->mpc.q, ctl->mpc.l, ctl->mpc.u);
#else
  OSQPInt err = osqp_update_data_vec(SOLVER, ctl->mpc.q, OSQP_NULL, OSQP_NULL);
#endif
  if (ctl->mpc.ws_pending) {
    spmv(CSR(shift), RHMPC_NV, ctl->mpc.plan, ctl->mpc.ws_x);
    memcpy(ctl->mpc.ws_y, rhmpc_y_plan, sizeof(ctl->mpc.ws_y));
    ctl->mpc.ws_x_set = ctl->mpc.ws_y_set = 1;
    ctl->mpc.ws_pending = 0;
  }
  if (!err && ctl->mpc.ws_x_set) {
    err = osqp_warm_start(SOLVER, ctl->mpc.ws_x, ctl->mpc.ws_y_set ? ctl->mpc.ws_y : OSQP_NULL);
    ctl->mpc.ws_x_set = ctl->mpc.ws_y_set = 0;
  }
  if (!err) err = osqp_solve(SOLVER);
  if (err) return fallback(ctl, RHMPC_SOLVER_ERROR, 1, tau);

  const OSQPFloat *z = SOLVER->solution->x;
  const OSQPFloat *y = SOLVER->solution->y;
  int status;
  ctl->pub.iterations = (int)SOLVER->info->iter;
  if (ctl->mpc.forced > 0) {
    ctl->mpc.forced -= 1;
    status = RHMPC_INJECTED;
  } else {
    status = status_of(SOLVER->info->status_val);
  }
  if (status == RHMPC_SOLVED) {
    double s = 0.0;
    for (int i = 0; i < RHMPC_NU; ++i) {
      tau[i] = z[i] * rhmpc_u_max[i];
      s += tau[i] * tau[i];
    }
    if (!isfinite(s)) status = RHMPC_NONFINITE_SOLUTION;
  }
  if (status != RHMPC_SOLVED) {
    fallback(ctl, status, 1, tau);
    if (continues(status)) {
      /* An unfinished solve is a good start for the next, nearly identical QP. */
      int finite = 1;
      for (int i = 0; finite && i < RHMPC_NV; ++i) finite = isfinite(z[i]);
      for (int i = 0; finite && i < RHMPC_M; ++i) finite = isfinite(y[i]);
      if (finite) {
        spmv(CSR(shift), RHMPC_NV, z, ctl->mpc.ws_x);
        spmv(CSR(shift_dual), RHMPC_M, y, ctl->mpc.ws_y);
        ctl->mpc.ws_x_set = ctl->mpc.ws_y_set = 1;
      }
    }
    return status;
  }
  for (int i = 0; i < RHMPC_NU; ++i) {
    tau[i] = clip(tau[i], rhmpc_u_max[i]);
    p_u[i] = tau[i];
  }
  memcpy(ctl->mpc.plan, z, sizeof(ctl->mpc.plan));
  ctl->mpc.plan_valid = 1;
  ctl->mpc.plan_age = 0;
  ctl->mpc.streak = 0;
  spmv(CSR(shift), RHMPC_NV, z, ctl->mpc.ws_x); /* the plan shifted; OSQP keeps its dual */
  ctl->mpc.ws_x_set = 1;
  ctl->pub.status = RHMPC_SOLVED;
  ctl->pub.source = RHMPC_SOURCE_QP;
  return RHMPC_SOLVED;
}
