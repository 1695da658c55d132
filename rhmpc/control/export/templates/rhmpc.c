/*
 * The controller of rhmpc.h (bound to Python as rhmpc.control.controller.Controller).
 *
 *   refresh:  the reference (rhmpc_reference.c): gate -> predictor -> interpolation -> guard
 *   forecast: a forecast made outside -> interpolation -> guard (rhmpc_reference.c)
 *   step:     x_hat = [I - L H, L, -L q0] [x_prior; q; 1]          (the observer's correction;
 *                                 a reading d ticks late: into the prior of its tick, then d
 *                                 predictions with the torques that acted since)
 *             d = p(q0 + x_q) - (C x_hat + y0)                     (rhmpc_model.c: offset)
 *             u = MPC(x_hat, r_{tick+1..tick+N}, d)                (rhmpc_mpc.c)
 *             tau_c = u + g(q) + C(q, qdot) qdot + f(qdot)         (rhmpc_model.c: cancel)
 *             tau = clip(tau_c, +-tau_max)
 *             x_prior = [A, B] [x_hat; u_acting]                   (the observer's prediction)
 * with u_acting the MPC torque that acts over the tick (RHMPC_INPUT_DELAY ticks old), plus
 * what the clip took off it.
 */
#ifndef _POSIX_C_SOURCE
#define _POSIX_C_SOURCE 199309L /* clock_gettime under -std=c99 */
#endif
#include "rhmpc.h"
#include "rhmpc_data.h"
#include "rhmpc_model.h"

#include <math.h>
#include <string.h>
#ifndef RHMPC_NO_TIMING
#include <time.h>
#endif

static long long now_ns(void) {
#ifndef RHMPC_NO_TIMING
  struct timespec ts;
  clock_gettime(CLOCK_MONOTONIC, &ts);
  return (long long)ts.tv_sec * 1000000000LL + ts.tv_nsec;
#else
  return 0;
#endif
}

void rhmpc_init(rhmpc_t *ctl) {
  memset(ctl, 0, sizeof *ctl);
  rhmpc_mpc_reset(ctl);
  static const double zero[3] = {0.0, 0.0, 0.0};
  rhmpc_place(ctl, rhmpc_y0, zero);
  rhmpc_reference_reset(ctl);
  ctl->pub.fused = -1;
  for (int i = 0; i <= RHMPC_MAX_DELAY; i++) ctl->past_tick[i] = -1;
}

int rhmpc_refresh(rhmpc_t *ctl, long long tick, double stamp, const double *z) {
  long long t0 = now_ns();
  int status = rhmpc_reference_refresh(ctl, tick, stamp, z);
  ctl->pub.refresh_ns = now_ns() - t0;
  return status;
}

int rhmpc_forecast(rhmpc_t *ctl, long long tick, double stamp, const double *points, int count) {
  long long t0 = now_ns();
  int status = rhmpc_reference_forecast(ctl, tick, stamp, points, count);
  ctl->pub.refresh_ns = now_ns() - t0;
  return status;
}

const double *rhmpc_horizon(const rhmpc_t *ctl, long long tick) {
  long long start = tick + 1 - ctl->pub.first;
  start = start < 0 ? 0 : (start > RHMPC_SPAN - RHMPC_N ? RHMPC_SPAN - RHMPC_N : start);
  return ctl->pub.points + 3 * start;
}

/* y = M [a; b; 1] for M (rows x (na + nb + 1), row-major) */
static void affine(const double *M, int rows, const double *a, int na, const double *b, int nb,
                   double *y) {
  const int cols = na + nb + 1;
  for (int r = 0; r < rows; r++) {
    const double *m = M + (size_t)r * cols;
    double s = 0.0;
    for (int k = 0; k < na; k++) s += m[k] * a[k];
    for (int k = 0; k < nb; k++) s += m[na + k] * b[k];
    y[r] = s + m[cols - 1];
  }
}

/* CasADi's generated function f(arg) -> res with static work arrays */
static void model_call(int (*f)(const double **, double **, long long *, double *, int),
                       const double **arg, double **res) {
  static long long iw[RHMPC_MODEL_SZ_IW + 1];
  static double w[RHMPC_MODEL_SZ_W + 1];
  f(arg, res, iw, w, 0);
}

/* The observer's innovation gate (JointObserver.correct) on the reading q of the tick whose
 * prior is `prior`: 1 if the reading is held out, then qf holds the prediction; 0 if it is
 * fused (qf = q), maybe taken again after a hold (which moves the prior to it). */
static int held_out(rhmpc_t *ctl, double prior[RHMPC_NX], const double q[RHMPC_NU],
                    double qf[RHMPC_NU]) {
  int past[RHMPC_NU], any = 0, finite = 1, moved = 1;
  memcpy(qf, q, RHMPC_NU * sizeof(double));
  for (int j = 0; j < RHMPC_NU; j++) finite &= isfinite(q[j]) != 0;
  if (ctl->grace > 0 && finite) { /* after a hold: fused whatever it says (if it is a number),
                                     while the filter settles */
    ctl->grace -= 1;
    return 0;
  }
  for (int j = 0; j < RHMPC_NU; j++) {
    const double nu = (q[j] - rhmpc_q0[j]) - prior[j];
    past[j] = !(fabs(nu) <= rhmpc_gate[j]); /* NaN is past */
    any |= past[j];
    if (ctl->suspect[j] && !(q[j] != ctl->first[j])) moved = 0;
  }
  if (!any) {
    ctl->held = 0;
    return 0;
  }
  if (ctl->held >= RHMPC_REACQUIRE_TICKS && finite && moved) { /* alive: take it again */
    int first_finite = 1;
    for (int j = 0; j < RHMPC_NU; j++) first_finite &= isfinite(ctl->first[j]) != 0;
    for (int j = 0; j < RHMPC_NU; j++) {
      if (first_finite)
        prior[RHMPC_NU + j] = (q[j] - ctl->first[j]) / ((double)ctl->held * RHMPC_TS);
      prior[j] = q[j] - rhmpc_q0[j];
    }
    ctl->held = 0;
    ctl->grace = RHMPC_REACQUIRE_TICKS;
    ctl->pub.encoder_reacquired += 1;
    return 0;
  }
  if (ctl->held == 0) {
    memcpy(ctl->first, q, sizeof ctl->first);
    memcpy(ctl->suspect, past, sizeof ctl->suspect);
  }
  ctl->held += 1;
  ctl->pub.encoder_held += 1;
  for (int j = 0; j < RHMPC_NU; j++) qf[j] = rhmpc_q0[j] + prior[j];
  return 1;
}

void rhmpc_tool_position(const double q[RHMPC_NU], double p[3]) {
#if RHMPC_TOOL
  const double *arg[1] = {q};
  double *res[1] = {p};
  model_call(rhmpc_tool, arg, res);
#else
  for (int c = 0; c < 3; c++) { /* y = C x + y0 at rest: x = [q - q0; 0] */
    p[c] = rhmpc_y0[c];
    for (int j = 0; j < RHMPC_NU; j++) p[c] += rhmpc_output[c * RHMPC_NX + j] * (q[j] - rhmpc_q0[j]);
  }
#endif
}

/* d = p(q0 + x_q) - (C x + y0) into d (RHMPC_NEXTRA values; zeros without the offset) */
static void output_offset(const double x[RHMPC_NX], double *d) {
#if RHMPC_OFFSET
  const double *arg[1] = {x};
  double *res[1] = {d};
  model_call(rhmpc_offset, arg, res);
#else
  (void)x;
  (void)d;
#endif
}

int rhmpc_mpc(rhmpc_t *ctl, const double x[RHMPC_NX], const double *ref, double u[RHMPC_NU]) {
  long long t0 = now_ns();
  double d[RHMPC_NEXTRA + 1] = {0};
  output_offset(x, d);
  int status = rhmpc_mpc_tick(ctl, x, ref, d, u);
  memcpy(ctl->pub.u, u, sizeof ctl->pub.u);
  ctl->pub.step_ns = now_ns() - t0;
  return status;
}

/* The slot of `tick` in the ring of the last ticks */
static int past(long long tick) {
  const long long n = RHMPC_MAX_DELAY + 1;
  return (int)(((tick % n) + n) % n);
}

/* The observer's estimate x of `tick` from the reading q of tick `of` <= tick, and the angles qf
 * the cancellation takes: the reading itself when it is this tick's and fused, else the
 * estimate's. A late reading corrects the prior of its own tick, and the predictions carry it
 * to this tick through the torques that acted (the ring's priors after it are redone). */
static void observe(rhmpc_t *ctl, long long tick, long long of, const double q[RHMPC_NU],
                    double x[RHMPC_NX], double qf[RHMPC_NU]) {
  double none[RHMPC_NU];
  int finite = 1;
  ctl->past_tick[past(tick)] = tick;
  memcpy(ctl->past_prior[past(tick)], ctl->x_prior, sizeof ctl->x_prior);
  if (of != tick && (of > tick || tick - of > RHMPC_MAX_DELAY || of <= ctl->pub.fused ||
                     ctl->past_tick[past(of)] != of))
  { /* too late, superseded or from the future: no reading */
    for (int j = 0; j < RHMPC_NU; j++) none[j] = NAN;
    q = none, of = tick;
  }
  for (int j = 0; j < RHMPC_NU; j++) finite &= isfinite(q[j]) != 0;
  if (finite) ctl->pub.fused = of;
  double *prior = ctl->past_prior[past(of)];
  if (held_out(ctl, prior, q, qf)) /* x_hat = x_prior */
    memcpy(x, prior, sizeof ctl->x_prior);
  else
    affine(rhmpc_correct, RHMPC_NX, prior, RHMPC_NX, qf, RHMPC_NU, x);
  for (long long t = of; t < tick; t++) {
    affine(rhmpc_predict, RHMPC_NX, x, RHMPC_NX, ctl->past_acting[past(t)], RHMPC_NU,
           ctl->past_prior[past(t + 1)]);
    memcpy(x, ctl->past_prior[past(t + 1)], sizeof ctl->x_prior);
  }
  if (of != tick) {
    memcpy(ctl->x_prior, x, sizeof ctl->x_prior);
    for (int j = 0; j < RHMPC_NU; j++) qf[j] = rhmpc_q0[j] + x[j];
  }
}

int rhmpc_step(rhmpc_t *ctl, long long tick, const double q[RHMPC_NU], double tau[RHMPC_NU]) {
  return rhmpc_step_delayed(ctl, tick, 0, q, tau);
}

int rhmpc_step_delayed(rhmpc_t *ctl, long long tick, long long delay, const double q[RHMPC_NU],
                       double tau[RHMPC_NU]) {
  long long t0 = now_ns();
  rhmpc_public_t *pub = &ctl->pub;
  double *x = pub->x_hat, d[RHMPC_NEXTRA + 1] = {0}, acting[RHMPC_NU], qf[RHMPC_NU], sum;
  observe(ctl, tick, tick - delay, q, x, qf);
  output_offset(x, d);
  int status = ctl->held >= RHMPC_FAULT_TIMEOUT_TICKS
                   ? rhmpc_mpc_brake(ctl, x, RHMPC_ENCODER_FAULT, pub->u)
                   : rhmpc_mpc_tick(ctl, x, rhmpc_horizon(ctl, tick), d, pub->u);
#if RHMPC_CANCEL
  {
    const double *arg[3] = {qf, x + RHMPC_NU, pub->u};
    double *res[1] = {pub->tau_command};
    model_call(rhmpc_cancel, arg, res);
  }
#else
  memcpy(pub->tau_command, pub->u, sizeof pub->u);
#endif
  sum = 0.0;
  for (int i = 0; i < RHMPC_NU; i++) sum += pub->tau_command[i] * pub->tau_command[i];
  if (!isfinite(sum)) /* the cancellation of a faulty reading: hold the last torque */
    memcpy(pub->tau_command, pub->tau, sizeof pub->tau);
  pub->saturated = 0;
  for (int i = 0; i < RHMPC_NU; i++) {
    double c = pub->tau_command[i], lim = rhmpc_tau_max[i];
    tau[i] = c > lim ? lim : (c < -lim ? -lim : c);
    pub->saturated |= !(tau[i] == c);
    pub->tau[i] = tau[i];
  }
  for (int i = 0; i < RHMPC_NU; i++)
    acting[i] = pub->saturated ? pub->u[i] + (tau[i] - pub->tau_command[i]) : pub->u[i];
  if (RHMPC_INPUT_DELAY > 0) { /* the torque computed RHMPC_INPUT_DELAY steps ago acts now */
    double *oldest = ctl->acting[ctl->acting_next], now[RHMPC_NU];
    memcpy(now, acting, sizeof now);
    memcpy(acting, oldest, sizeof now);
    memcpy(oldest, now, sizeof now);
    ctl->acting_next = (ctl->acting_next + 1) % (RHMPC_INPUT_DELAY > 0 ? RHMPC_INPUT_DELAY : 1);
  }
  affine(rhmpc_predict, RHMPC_NX, x, RHMPC_NX, acting, RHMPC_NU, ctl->x_prior);
  memcpy(ctl->past_acting[past(tick)], acting, sizeof acting);
  pub->step_ns = now_ns() - t0;
  return status;
}

static const char *const status_names[RHMPC_N_STATUS] = {@STATUS_NAMES@};
static const char *const source_names[RHMPC_N_SOURCES] = {@SOURCE_NAMES@};
static const char *const count_names[RHMPC_N_COUNTS] = {@COUNT_NAMES@};

const char *rhmpc_status_name(int status) {
  return (status >= 0 && status < RHMPC_N_STATUS) ? status_names[status] : "unknown";
}
const char *rhmpc_source_name(int source) {
  return (source >= 0 && source < RHMPC_N_SOURCES) ? source_names[source] : "unknown";
}
const char *rhmpc_count_name(int count) {
  return (count >= 0 && count < RHMPC_N_COUNTS) ? count_names[count] : "unknown";
}
long long rhmpc_sizeof(void) { return (long long)sizeof(rhmpc_t); }
long long rhmpc_public_sizeof(void) { return (long long)sizeof(rhmpc_public_t); }
void rhmpc_dims(int out[14]) {
  const int dims[14] = {RHMPC_N,  RHMPC_NX, RHMPC_NU,   RHMPC_NY,       RHMPC_NV,
                        RHMPC_M,  RHMPC_NPAR, RHMPC_NZ, RHMPC_NEXTRA,   RHMPC_D,
                        RHMPC_SPAN, RHMPC_N_STATUS, RHMPC_N_SOURCES, RHMPC_N_COUNTS};
  memcpy(out, dims, sizeof dims);
}
