/*
 * rhmpc_tick: the per-tick logic of rhmpc.control.mpc.RecedingHorizonMPC.step, in C.
 * Numbers (QP maps, screening map, shift, LQ gain) come from rhmpc_data.c, generated from the
 * same CondensedQP the Python controller uses; the QP is solved by OSQP's generated code.
 *
 *   p = [x; r_1..r_N; u_prev]                    (finiteness check: sum of squares)
 *   l, u = l0 - G p, u0 - G p                    (only with parameter-dependent bounds)
 *   z* = Z [p; 1]; if l <= A z* <= u: tau = u_max o z*_0, done       (screening, exact)
 *   q = F [p; 1]; osqp_update_data_vec; warm start (plan shifted one tick); osqp_solve
 *   solved: tau = clip(u_max o z_0)   else: plan shifted -> clipped LQ -> zero
 */
#include "rhmpc.h"
#include "rhmpc_data.h"
#include "osqp.h"
#include "@OSQP_PREFIX@workspace.h"

#include <math.h>
#include <string.h>
#ifndef RHMPC_NO_TIMING
#include <time.h>
#endif

#define SOLVER (&@OSQP_PREFIX@solver)
#define NPE (RHMPC_NPAR + 1)


static long long now_ns(void) {
#ifndef RHMPC_NO_TIMING
  struct timespec ts;
  clock_gettime(CLOCK_MONOTONIC, &ts);
  return (long long)ts.tv_sec * 1000000000LL + ts.tv_nsec;
#else
  return 0;
#endif
}

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

static const char *const status_names[RHMPC_N_STATUS] = {
    "solved", "nonfinite_input", "nonfinite_solution", "solver_error", "injected",
    "solved_inaccurate", "primal_infeasible", "dual_infeasible", "max_iter", "time_limit",
    "non_convex", "interrupted", "unsolved"};
static const char *const source_names[RHMPC_N_SOURCES] = {"qp", "plan", "lq", "brake", "zero"};

const char *rhmpc_status_name(int status) {
  return (status >= 0 && status < RHMPC_N_STATUS) ? status_names[status] : "unknown";
}
const char *rhmpc_source_name(int source) {
  return (source >= 0 && source < RHMPC_N_SOURCES) ? source_names[source] : "unknown";
}
long long rhmpc_sizeof(void) { return (long long)sizeof(rhmpc_t); }
void rhmpc_dims(int out[9]) {
  out[0] = RHMPC_N; out[1] = RHMPC_NX; out[2] = RHMPC_NU; out[3] = RHMPC_NY;
  out[4] = RHMPC_NV; out[5] = RHMPC_M; out[6] = RHMPC_NPAR; out[7] = RHMPC_NZ;
  out[8] = RHMPC_NEXTRA;
}

void rhmpc_init(rhmpc_t *ctl) {
  static const double zeros_z[RHMPC_NV] = {0};
  memset(ctl, 0, sizeof(*ctl));
  ctl->p_ext[RHMPC_NPAR] = 1.0;
  memcpy(ctl->l, rhmpc_l0, sizeof(ctl->l));
  memcpy(ctl->u, rhmpc_u0, sizeof(ctl->u));
  osqp_warm_start(SOLVER, zeros_z, rhmpc_y_plan);
}

void rhmpc_force_failures(rhmpc_t *ctl, long long count) {
  if (count > 0) ctl->forced += count;
}

#if RHMPC_BRAKE
/* The clipped LQ input if its whole clipped plan (slacks zero) keeps every constraint row
 * beyond the torque rows, else the torque that stops the joints within RHMPC_BRAKE_TICKS:
 * tau = -M0 qdot / (RHMPC_BRAKE_TICKS Ts) (clipped by the caller). */
static int lq_or_brake(rhmpc_t *ctl, double tau[RHMPC_NU]) {
  double *v = ctl->v_lq;
  int holds = 1;
  matvec(rhmpc_minimiser, ctl->p_ext, RHMPC_NV, NPE, v);
  for (int i = 0; i < RHMPC_NV; ++i) v[i] = i < RHMPC_NZ ? clip(v[i], 1.0) : 0.0; /* slacks 0 */
#if RHMPC_PARAM_BOUNDS
  for (int i = RHMPC_NZ; holds && i < RHMPC_M; ++i) {
    double g = row_dot(CSR(A), i, v);
    holds = g >= ctl->l[i] && g <= ctl->u[i];
  }
#endif
  if (holds) {
    for (int i = 0; i < RHMPC_NU; ++i) tau[i] = v[i] * rhmpc_u_max[i];
    return RHMPC_SOURCE_LQ;
  }
  const double *qdot = ctl->p_ext + RHMPC_NX / 2;
  const double span = RHMPC_BRAKE_TICKS * RHMPC_TS;
  for (int i = 0; i < RHMPC_NU; ++i) {
    double s = 0.0;
    for (int j = 0; j < RHMPC_NU; ++j) s += rhmpc_M0[i * RHMPC_NU + j] * qdot[j];
    tau[i] = -s / span;
  }
  return RHMPC_SOURCE_BRAKE;
}
#endif

/* The fallback chain: plan shifted to this tick -> clipped LQ input (or braking) -> zero. */
static int fallback(rhmpc_t *ctl, int status, int inputs_finite, double tau[RHMPC_NU]) {
  int source = -1;
  ctl->status = status;
  ctl->failures[status] += 1;
  ctl->plan_age += 1;
  if (ctl->plan_valid && ctl->plan_age <= RHMPC_PLAN_FALLBACK_TICKS) {
    int k = ctl->plan_age < RHMPC_N - 1 ? ctl->plan_age : RHMPC_N - 1;
    int b = rhmpc_block_of_tick[k];
    for (int i = 0; i < RHMPC_NU; ++i) tau[i] = ctl->plan[b * RHMPC_NU + i] * rhmpc_u_max[i];
    source = RHMPC_SOURCE_PLAN;
  }
  if (source < 0 && inputs_finite) {
#if RHMPC_BRAKE
    source = lq_or_brake(ctl, tau);
#else
    matvec(rhmpc_gain, ctl->p_ext, RHMPC_NU, RHMPC_NPAR, tau);
    for (int i = 0; i < RHMPC_NU; ++i) tau[i] += rhmpc_gain0[i];
    source = RHMPC_SOURCE_LQ;
#endif
  }
  int finite = source >= 0;
  for (int i = 0; finite && i < RHMPC_NU; ++i) finite = isfinite(tau[i]);
  if (!finite) {
    for (int i = 0; i < RHMPC_NU; ++i) tau[i] = 0.0;
    source = RHMPC_SOURCE_ZERO;
  }
  for (int i = 0; i < RHMPC_NU; ++i) tau[i] = clip(tau[i], rhmpc_u_max[i]);
  ctl->source = source;
  ctl->fallbacks[source] += 1;
  for (int i = 0; i < RHMPC_NU; ++i) ctl->p_ext[RHMPC_NX + RHMPC_NY * RHMPC_N + i] = tau[i];
  ctl->ws_pending = 0;
  if (ctl->plan_valid && RHMPC_WARM_START != RHMPC_WS_NONE) {
    spmv(CSR(shift), RHMPC_NV, ctl->plan, ctl->ws_x);
    memcpy(ctl->ws_y, rhmpc_y_plan, sizeof(ctl->ws_y));
    ctl->ws_x_set = ctl->ws_y_set = 1;
  }
  return status;
}

static int screened(rhmpc_t *ctl) {
  matvec(rhmpc_minimiser, ctl->p_ext, RHMPC_NV, NPE, ctl->z_star);
#if !RHMPC_PARAM_BOUNDS
  for (int i = 0; i < RHMPC_NV; ++i)
    if (!(fabs(ctl->z_star[i]) <= 1.0)) return 0;
  return 1;
#else
  spmv(CSR(A), RHMPC_M, ctl->z_star, ctl->g);
  for (int i = 0; i < RHMPC_M; ++i)
    if (!(ctl->g[i] - ctl->u[i] <= 0.0 && ctl->l[i] - ctl->g[i] <= 0.0)) return 0;
  return 1;
#endif
}

static int finish(rhmpc_t *ctl, long long t0, int status) {
  ctl->tick_ns = now_ns() - t0;
  return status;
}

int rhmpc_tick(rhmpc_t *ctl, const double x[RHMPC_NX], const double ref[RHMPC_NY * RHMPC_N],
               const double u_prev[RHMPC_NU], double tau[RHMPC_NU]) {
  return rhmpc_tick_ext(ctl, x, ref, u_prev, NULL, tau);
}

int rhmpc_tick_ext(rhmpc_t *ctl, const double x[RHMPC_NX], const double ref[RHMPC_NY * RHMPC_N],
                   const double u_prev[RHMPC_NU], const double *extra, double tau[RHMPC_NU]) {
  long long t0 = now_ns();
  double *p = ctl->p_ext;
  double *p_u = p + RHMPC_NX + RHMPC_NY * RHMPC_N;
  double *p_extra = p_u + RHMPC_NU;
  double ss = 0.0;
  ctl->ticks += 1;
  memcpy(p, x, RHMPC_NX * sizeof(double));
  memcpy(p + RHMPC_NX, ref, RHMPC_NY * RHMPC_N * sizeof(double));
  if (u_prev != NULL)
    for (int i = 0; i < RHMPC_NU; ++i) p_u[i] = clip(u_prev[i], rhmpc_u_max[i]);
  if (extra != NULL)
    for (int i = 0; i < RHMPC_NEXTRA; ++i) p_extra[i] = extra[i];
  for (int i = 0; i < NPE; ++i) ss += p[i] * p[i];
  ctl->iterations = 0;
  if (!isfinite(ss)) /* NaN, +-inf (or absurd > 1e154) */
    return finish(ctl, t0, fallback(ctl, RHMPC_NONFINITE_INPUT, 0, tau));

#if RHMPC_PARAM_BOUNDS
  spmv(CSR(G), RHMPC_M, p, ctl->g);
  for (int i = 0; i < RHMPC_M; ++i) {
    ctl->l[i] = rhmpc_l0[i] - ctl->g[i];
    ctl->u[i] = rhmpc_u0[i] - ctl->g[i];
  }
#endif
  if (RHMPC_SCREENING && ctl->forced == 0 && screened(ctl)) {
    for (int i = 0; i < RHMPC_NU; ++i) tau[i] = ctl->z_star[i] * rhmpc_u_max[i];
    for (int i = 0; i < RHMPC_NU; ++i) p_u[i] = tau[i];
    memcpy(ctl->plan, ctl->z_star, sizeof(ctl->plan));
    ctl->plan_valid = 1;
    ctl->plan_age = 0;
    ctl->ws_pending = RHMPC_WARM_START != RHMPC_WS_NONE;
    ctl->last_screened = 1;
    ctl->screened += 1;
    ctl->status = RHMPC_SOLVED;
    ctl->source = RHMPC_SOURCE_QP;
    return finish(ctl, t0, RHMPC_SOLVED);
  }
  ctl->last_screened = 0;
  matvec(rhmpc_F_ext, p, RHMPC_NV, NPE, ctl->q);
#if RHMPC_PARAM_BOUNDS
  OSQPInt err = osqp_update_data_vec(SOLVER, ctl->q, ctl->l, ctl->u);
#else
  OSQPInt err = osqp_update_data_vec(SOLVER, ctl->q, OSQP_NULL, OSQP_NULL);
#endif
  if (ctl->ws_pending) {
    spmv(CSR(shift), RHMPC_NV, ctl->plan, ctl->ws_x);
    memcpy(ctl->ws_y, rhmpc_y_plan, sizeof(ctl->ws_y));
    ctl->ws_x_set = ctl->ws_y_set = 1;
    ctl->ws_pending = 0;
  }
  if (!err && ctl->ws_x_set) {
    err = osqp_warm_start(SOLVER, ctl->ws_x, ctl->ws_y_set ? ctl->ws_y : OSQP_NULL);
    ctl->ws_x_set = ctl->ws_y_set = 0;
  }
  if (!err) err = osqp_solve(SOLVER);
  if (err) return finish(ctl, t0, fallback(ctl, RHMPC_SOLVER_ERROR, 1, tau));

  const OSQPFloat *z = SOLVER->solution->x;
  const OSQPFloat *y = SOLVER->solution->y;
  int status;
  ctl->iterations = (int)SOLVER->info->iter;
  if (ctl->forced > 0) {
    ctl->forced -= 1;
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
    if (continues(status) && RHMPC_WARM_START != RHMPC_WS_NONE) {
      /* An unfinished solve is a good start for the next, nearly identical QP. */
      int finite = 1;
      for (int i = 0; finite && i < RHMPC_NV; ++i) finite = isfinite(z[i]);
      for (int i = 0; finite && i < RHMPC_M; ++i) finite = isfinite(y[i]);
      if (!finite) {
      } else if (RHMPC_WARM_START != RHMPC_WS_KEEP) {
        spmv(CSR(shift), RHMPC_NV, z, ctl->ws_x);
        spmv(CSR(shift_dual), RHMPC_M, y, ctl->ws_y);
        ctl->ws_x_set = ctl->ws_y_set = 1;
      } else {
        ctl->ws_x_set = 0; /* "keep": OSQP's own iterate */
      }
    }
    return finish(ctl, t0, status);
  }
  for (int i = 0; i < RHMPC_NU; ++i) {
    tau[i] = clip(tau[i], rhmpc_u_max[i]);
    p_u[i] = tau[i];
  }
  memcpy(ctl->plan, z, sizeof(ctl->plan));
  ctl->plan_valid = 1;
  ctl->plan_age = 0;
  if (RHMPC_WARM_START == RHMPC_WS_SHIFT) {
    spmv(CSR(shift), RHMPC_NV, z, ctl->ws_x);
    spmv(CSR(shift_dual), RHMPC_M, y, ctl->ws_y);
    ctl->ws_x_set = ctl->ws_y_set = 1;
  } else if (RHMPC_WARM_START == RHMPC_WS_SHIFT_PRIMAL) {
    spmv(CSR(shift), RHMPC_NV, z, ctl->ws_x);
    ctl->ws_x_set = 1;
  }
  ctl->status = RHMPC_SOLVED;
  ctl->source = RHMPC_SOURCE_QP;
  return finish(ctl, t0, RHMPC_SOLVED);
}
