/*
 * The reference of rhmpc_refresh: outlier gate, RLS predictor, interpolation, guard.
 *
 * The reference's per-sample work, whose settings rhmpc.control.reference describes: the
 * outlier gate, the anchor and the nodes of a forecast, the interpolation, the guard and the
 * placement live here only (rhmpc.control.reference.PredictedReference binds them). The one
 * logic kept in two languages is the library's own @PREDICTOR@ predictor, for a target with no
 * predictor process: the twin of predictors/rls_generalized.py (Tuna et al. 2013, section VI) or
 * predictors/rls_one_step.py (section V), with the bookkeeping of predictors/base.py (counts,
 * range guard, non-finite relearn), predictors/delay_line.py (tapped delay line, ramp repair,
 * cubic gap interpolation, retraction) and predictors/rls.py (Haykin, Adaptive Filter Theory,
 * Table 10.1, with its covariance guards); each of its functions names its twin there, and
 * tests/rhmpc/control/test_export.py holds the two to the same torques tick by tick.
 */
#include "rhmpc.h"
#include "rhmpc_data.h"

#include <math.h>
#include <string.h>

#define D RHMPC_D
#define NO RHMPC_ORDER
#define MP RHMPC_POINTS
#define RB RHMPC_RLS_B
#define RN RHMPC_RLS_N
#define RQ RHMPC_RLS_Q
#define L RHMPC_LINE

static int all_finite(const double *v, int n) {
  for (int i = 0; i < n; i++)
    if (!isfinite(v[i])) return 0;
  return 1;
}

/* is_measured (predictors/base.py): every component finite and the squared norm too */
static int measured(const double *z) {
  if (z == NULL) return 0;
  double s = 0.0;
  for (int c = 0; c < D; c++) s += z[c] * z[c];
  return isfinite(s);
}

static double miss2(const double *z, const double *forecast) {
  double m2 = 0.0;
  for (int c = 0; c < D; c++) m2 += (z[c] - forecast[c]) * (z[c] - forecast[c]);
  return m2;
}

/* ---- OutlierGate ------------------------------------------------------------------------ */

static void gate_reset(rhmpc_t *ctl) {
  rhmpc_reference_t *s = &ctl->ref;
  ctl->pub.gate_locked = 1;
  s->g_rejected = s->g_inside = s->g_ncal = 0;
  s->g_miss2 = 0.0;
  s->g_calibrating = isnan(RHMPC_GATE_FLOOR);
  ctl->pub.gate_floor = RHMPC_GATE_FLOOR;
  s->g_threshold2 = s->g_calibrating ? 0.0 : RHMPC_GATE_FLOOR * RHMPC_GATE_FLOOR;
}

/* OutlierGate.inside: whether a locked gate would accept a miss m2 (no state changes) */
static int gate_inside(const rhmpc_t *ctl, double m2) {
  if (ctl->ref.g_calibrating) return 1;
  return ctl->pub.gate_locked && m2 <= ctl->ref.g_threshold2;
}

/* Heapsort in place, ascending: O(n log n) at worst, no allocation (libc's qsort may take its
 * buffer from the heap) */
static void sift_down(double *a, int root, int n) {
  for (int child; (child = 2 * root + 1) < n; root = child) {
    if (child + 1 < n && a[child + 1] > a[child]) child++;
    if (!(a[child] > a[root])) return;
    double t = a[root];
    a[root] = a[child];
    a[child] = t;
  }
}

static void heapsort_doubles(double *a, int n) {
  for (int i = n / 2 - 1; i >= 0; i--) sift_down(a, i, n);
  for (int end = n - 1; end > 0; end--) {
    double t = a[0];
    a[0] = a[end];
    a[end] = t;
    sift_down(a, 0, end);
  }
}

/* OutlierGate._calibrate: after 2 x calibration misses, floor = 4 RMS of the second half's
 * misses e no larger than 5 median(e), at least RHMPC_MIN_FLOOR */
static void gate_calibrate(rhmpc_t *ctl, double m2) {
  rhmpc_reference_t *s = &ctl->ref;
  const int cal = RHMPC_GATE_CALIBRATION;
  s->g_cal[s->g_ncal++] = m2;
  if (s->g_ncal < 2 * cal) return;
  double *e = s->g_cal + cal, sum = 0.0;
  for (int i = 0; i < cal; i++) e[i] = sqrt(e[i]);
  memcpy(s->g_sorted, e, (size_t)cal * sizeof(double));
  heapsort_doubles(s->g_sorted, cal);
  double median = cal % 2 ? s->g_sorted[cal / 2]
                          : (s->g_sorted[cal / 2 - 1] + s->g_sorted[cal / 2]) / 2.0;
  int kept = 0;
  for (int i = 0; i < cal; i++)
    if (e[i] <= 5.0 * median) {
      sum += e[i] * e[i];
      kept++;
    }
  double rms4 = 4.0 * sqrt(sum / kept);
  ctl->pub.gate_floor = rms4 > RHMPC_MIN_FLOOR ? rms4 : RHMPC_MIN_FLOOR;
  s->g_calibrating = 0;
}

/* OutlierGate.accept: whether the sample with miss m2 is accepted; events are counted */
static int gate_accept(rhmpc_t *ctl, double m2) {
  rhmpc_reference_t *s = &ctl->ref;
  if (s->g_calibrating) {
    gate_calibrate(ctl, m2);
  } else {
    int outside = m2 > s->g_threshold2;
    if (!ctl->pub.gate_locked) {
      s->g_inside = outside ? 0 : s->g_inside + 1;
      ctl->pub.gate_locked = s->g_inside >= RHMPC_RELOCK;
    } else if (!outside) {
      s->g_rejected = 0;
    } else if (s->g_rejected < RHMPC_MAX_REJECTIONS) {
      s->g_rejected++;
      ctl->pub.counts[RHMPC_OUTLIERS_REJECTED]++;
      return 0;
    } else {
      ctl->pub.gate_locked = 0;
      s->g_rejected = s->g_inside = 0;
      ctl->pub.counts[RHMPC_GATE_UNLOCKED]++;
    }
  }
  s->g_miss2 += 0.02 * (m2 - s->g_miss2);
  double f = ctl->pub.gate_floor, f2 = (isnan(f) || f == 0.0) ? 0.0 : f * f;
  double t2 = 16.0 * s->g_miss2;
  s->g_threshold2 = t2 > f2 ? t2 : f2;
  return 1;
}

/* ---- RangeEnvelope (predictors/monitor.py) ----------------------------------------------- */

static void envelope_reset(rhmpc_reference_t *s) {
  for (int i = 0; i < RHMPC_ENVELOPE_BLOCKS * D; i++) {
    s->env_lo[i] = INFINITY;
    s->env_hi[i] = -INFINITY;
  }
  for (int c = 0; c < D; c++) {
    s->env_done_lo[c] = INFINITY;
    s->env_done_hi[c] = -INFINITY;
    s->env_lo_now[c] = s->env_hi_now[c] = 0.0;
  }
  s->env_i = s->env_k = s->env_known = 0;
}

static void envelope_tick(rhmpc_reference_t *s, const double *x) {
  double *lo = s->env_lo + s->env_i * D, *hi = s->env_hi + s->env_i * D;
  if (x != NULL) {
    for (int c = 0; c < D; c++) {
      if (x[c] < lo[c]) lo[c] = x[c];
      if (x[c] > hi[c]) hi[c] = x[c];
    }
    s->env_known = 1;
  }
  if (++s->env_k < RHMPC_ENVELOPE_BLOCK) return;
  s->env_k = 0;
  s->env_i = (s->env_i + 1) % RHMPC_ENVELOPE_BLOCKS;
  for (int c = 0; c < D; c++) {
    s->env_lo[s->env_i * D + c] = INFINITY;
    s->env_hi[s->env_i * D + c] = -INFINITY;
  }
  for (int c = 0; c < D; c++) { /* the extrema of the full blocks */
    double mn = s->env_lo[c], mx = s->env_hi[c];
    for (int b = 1; b < RHMPC_ENVELOPE_BLOCKS; b++) {
      if (s->env_lo[b * D + c] < mn) mn = s->env_lo[b * D + c];
      if (s->env_hi[b * D + c] > mx) mx = s->env_hi[b * D + c];
    }
    s->env_done_lo[c] = mn;
    s->env_done_hi[c] = mx;
  }
}

/* RangeEnvelope.envelope: the window's (min, max), or the last known one through a gap */
static void envelope_range(rhmpc_reference_t *s) {
  const double *lo = s->env_lo + s->env_i * D, *hi = s->env_hi + s->env_i * D;
  double first = s->env_done_lo[0] < lo[0] ? s->env_done_lo[0] : lo[0];
  if (first == INFINITY) return;
  for (int c = 0; c < D; c++) {
    s->env_lo_now[c] = s->env_done_lo[c] < lo[c] ? s->env_done_lo[c] : lo[c];
    s->env_hi_now[c] = s->env_done_hi[c] > hi[c] ? s->env_done_hi[c] : hi[c];
  }
}

/* ---- RecursiveLeastSquares (predictors/rls.py) -------------------------------------------- */

/* y = A x, A (rows x cols, row-major) */
static void matvec(const double *A, int rows, int cols, const double *x, double *y) {
  for (int j = 0; j < rows; j++) {
    const double *a = A + (size_t)j * cols;
    double acc = 0.0;
    for (int k = 0; k < cols; k++) acc += a[k] * x[k];
    y[j] = acc;
  }
}

static void rls_reset_covariance(rhmpc_reference_t *s, int b) {
  double *P = s->P + (size_t)b * RN * RN;
  memset(P, 0, (size_t)RN * RN * sizeof(double));
  for (int i = 0; i < RN; i++) P[i * RN + i] = 1.0 / RHMPC_DELTA;
}

/* One Sherman-Morrison step per problem (Haykin Table 10.1):
 *   pi = P x, kappa = lambda + x'pi, e = y - W x, W += e pi'/kappa, P = (P - pi pi'/kappa)/lambda
 * then the reset (kappa or P not positive/finite) and wind-up (diag P > p_max) guards. */
static void rls_update(rhmpc_t *ctl, const double *x, const double *y) {
  rhmpc_reference_t *s = &ctl->ref;
  const double lam = RHMPC_FORGETTING, inv = 1.0 / lam;
  for (int b = 0; b < RB; b++) {
    const double *xb = x + (size_t)b * RN, *yb = y + (size_t)b * RQ;
    double *P = s->P + (size_t)b * RN * RN, *W = s->W + (size_t)b * RQ * RN, *pi = s->pi;
    double kappa = lam;
    matvec(P, RN, RN, xb, pi);
    for (int i = 0; i < RN; i++) kappa += xb[i] * pi[i];
    if (!(kappa > 0.0 && isfinite(kappa))) {
      ctl->pub.counts[RHMPC_RLS_RESET]++;
      rls_reset_covariance(s, b);
      continue;
    }
    matvec(W, RQ, RN, xb, s->e); /* the a-priori error */
    for (int j = 0; j < RQ; j++) {
      double t = (yb[j] - s->e[j]) / kappa;
      for (int i = 0; i < RN; i++) W[j * RN + i] += pi[i] * t;
    }
    double peak = -INFINITY, low = INFINITY;
    for (int r = 0; r < RN; r++) {
      for (int c = 0; c < RN; c++) P[r * RN + c] = (P[r * RN + c] - pi[r] * pi[c] / kappa) * inv;
      double v = P[r * RN + r];
      peak = isnan(v) || v > peak ? v : peak;
      low = v < low ? v : low;
    }
    if (!isfinite(peak) || !(low > 0.0)) {
      ctl->pub.counts[RHMPC_RLS_RESET]++;
      rls_reset_covariance(s, b);
    } else if (peak > RHMPC_P_MAX) { /* P <- D P D, D = diag(min(1, sqrt(p_max/P_ii))) */
      ctl->pub.counts[RHMPC_RLS_BOUND]++;
      double *scale = s->e + RQ;
      for (int i = 0; i < RN; i++) {
        double r = RHMPC_P_MAX / P[i * RN + i];
        scale[i] = sqrt(r < 1.0 ? r : 1.0);
      }
      for (int i = 0; i < RN; i++)
        for (int k = 0; k < RN; k++) P[i * RN + k] *= scale[i] * scale[k];
    }
  }
}

/* ---- the forecasts (OneStepRLS._next / _predict, GeneralizedRLS._block / _predict) ------- */

/* The rows past (N x D, newest first) as the regressor of axis b (independent axes) */
static const double *axis_column(const double *past, int b, double *out) {
  for (int i = 0; i < NO; i++) out[i] = past[i * D + b];
  return out;
}

/* z_hat_{+1} ... z_hat_{+M} (M x D) after the rows past (weight block j forecasts M - j
 * steps ahead); first = 1: z_hat_{+1} only (the one-step predictor's only block). */
static void block_forecast(rhmpc_reference_t *s, const double *past, double *out, int first) {
  const int j0 = first ? MP - 1 : 0;
  double *raw = s->work + NO;
  if (RHMPC_CORRELATED) {
    matvec(s->W + (size_t)j0 * D * RN, (MP - j0) * D, RN, past, raw);
    for (int j = j0; j < MP; j++)
      for (int c = 0; c < D; c++) out[(MP - 1 - j) * D + c] = raw[(j - j0) * D + c];
  } else {
    for (int b = 0; b < D; b++) {
      matvec(s->W + ((size_t)b * MP + j0) * NO, MP - j0, NO, axis_column(past, b, s->work),
             raw);
      for (int j = j0; j < MP; j++) out[(MP - 1 - j) * D + b] = raw[j - j0];
    }
  }
}

/* DelayLinePredictor._next: the one-step forecast after the rows past */
static void next_sample(rhmpc_reference_t *s, const double *past, double *out) {
  block_forecast(s, past, out, 1);
}

/* K points: the generalized predictor chains its M-point blocks (the M forecasts pushed as if
 * observed); the one-step predictor iterates its one-step forecast. */
static void forecast(rhmpc_reference_t *s, int K, double *out) {
  if (!RHMPC_GENERALIZED) { /* newest first: [z_hat_{n+K} ... z_hat_{n+1}, z_n ... z_{n-N+1}] */
    double *b = s->chain;
    memcpy(b + (size_t)K * D, s->buf, (size_t)NO * D * sizeof(double));
    for (int k = K * D; k > 0; k -= D) next_sample(s, b + k, b + k - D);
    for (int k = 0; k < K; k++)
      memcpy(out + (size_t)k * D, b + (size_t)(K - 1 - k) * D, D * sizeof(double));
    return;
  }
  int blocks = (K + MP - 1) / MP;
  double *all = s->chain, *hist = s->hist;
  block_forecast(s, s->buf, all, 0);
  memcpy(hist + (size_t)(blocks - 1) * MP * D, s->buf, (size_t)NO * D * sizeof(double));
  for (int b = 1; b < blocks; b++) {
    int top = (blocks - 1 - b) * MP;
    for (int r = 0; r < MP; r++) /* block b - 1, reversed */
      memcpy(hist + (size_t)(top + r) * D, all + (size_t)(b * MP - 1 - r) * D,
             D * sizeof(double));
    block_forecast(s, hist + (size_t)top * D, all + (size_t)b * MP * D, 0);
  }
  memcpy(out, all, (size_t)K * D * sizeof(double));
}

/* ---- TappedDelayLine (predictors/delay_line.py) ------------------------------------------ */

/* Rows 0, 1 measured: a gap of g <= 3 rows below them becomes the cubic through rows 0, 1,
 * g + 2, g + 3 when those two are measurements too */
static void line_interpolate_gap(rhmpc_reference_t *s) {
  int g = 0;
  while (2 + g < L && !s->measured[2 + g] && g <= RHMPC_MAX_GAP) g++;
  if (!(1 <= g && g <= RHMPC_MAX_GAP) || 3 + g >= s->filled) return;
  if (!(s->measured[2 + g] && s->measured[3 + g])) return;
  const double nodes[4] = {0.0, 1.0, 2.0 + g, 3.0 + g};
  const int rows[4] = {0, 1, 2 + g, 3 + g};
  for (int i = 0; i < g; i++) {
    double w[4], at = 2.0 + i;
    for (int j = 0; j < 4; j++) {
      w[j] = 1.0;
      for (int m = 0; m < 4; m++)
        if (m != j) w[j] *= (at - nodes[m]) / (nodes[j] - nodes[m]);
    }
    for (int c = 0; c < D; c++) {
      double v = 0.0;
      for (int j = 0; j < 4; j++) v += w[j] * s->buf[rows[j] * D + c];
      s->buf[(2 + i) * D + c] = v;
    }
  }
}

/* TappedDelayLine.push: after g fills, a measurement z with its forecast `expected` corrects
 * fill i (oldest first, i = 1 ... g) by (i/(g+1)) (z - expected), a repair counted */
static void line_push(rhmpc_t *ctl, const double *z, int is_measured, const double *expected) {
  rhmpc_reference_t *s = &ctl->ref;
  double *buf = s->buf;
  if (is_measured && s->fills && expected != NULL && all_finite(expected, D)) {
    int g = s->fills < L - 1 ? s->fills : L - 1;
    ctl->pub.counts[RHMPC_REPAIRED]++;
    for (int i = 0; i < g; i++) {
      double ramp = (double)(s->fills - i) / (s->fills + 1.0);
      for (int c = 0; c < D; c++) buf[i * D + c] += ramp * (z[c] - expected[c]);
    }
  }
  memmove(buf + D, buf, (size_t)(L - 1) * D * sizeof(double));
  memcpy(buf, z, D * sizeof(double));
  memmove(s->measured + 1, s->measured, (size_t)(L - 1));
  s->measured[0] = (unsigned char)is_measured;
  s->filled = s->filled + 1 < L ? s->filled + 1 : L;
  s->real_run = is_measured ? s->real_run + 1 : 0;
  s->fills = is_measured ? 0 : s->fills + 1;
  if (s->real_run == 2) line_interpolate_gap(s);
}

/* ---- the predictor (Predictor, DelayLinePredictor, the RLS predictors) -------------------- */

/* _allocate: W0 (every block forecasts the newest sample with init "hold"), P0, an empty line */
static void predictor_allocate(rhmpc_reference_t *s) {
  memset(s->W, 0, sizeof s->W);
  if (RHMPC_HOLD_INIT && RHMPC_CORRELATED) {
    for (int j = 0; j < MP; j++)
      for (int c = 0; c < D; c++) s->W[(size_t)(j * D + c) * RN + c] = 1.0;
  } else if (RHMPC_HOLD_INIT) {
    for (int b = 0; b < D; b++)
      for (int j = 0; j < RQ; j++) s->W[(size_t)(b * RQ + j) * RN] = 1.0;
  }
  for (int b = 0; b < RB; b++) rls_reset_covariance(s, b);
  memset(s->buf, 0, sizeof s->buf);
  memset(s->measured, 0, sizeof s->measured);
  s->filled = s->real_run = s->fills = 0;
}

static void predictor_reset(rhmpc_t *ctl) {
  rhmpc_reference_t *s = &ctl->ref;
  s->n_upd = 0;
  s->bounds_n = -1;
  s->has_last = 0;
  ctl->pub.ready = 0;
  memset(ctl->pub.counts, 0, sizeof ctl->pub.counts);
  envelope_reset(s);
  predictor_allocate(s);
}

/* _update_bounds: the guard's range [lo - G r, hi + G r], r floored at 10 % of the widest */
static void predictor_bounds(rhmpc_reference_t *s) {
  if (s->bounds_n == s->n_upd || !s->env_known) return;
  envelope_range(s);
  double r[D], widest = -INFINITY;
  for (int c = 0; c < D; c++) {
    r[c] = s->env_hi_now[c] - s->env_lo_now[c];
    widest = r[c] > widest ? r[c] : widest;
  }
  for (int c = 0; c < D; c++) {
    double rc = RHMPC_GUARD_MULTIPLE * (r[c] >= 0.1 * widest ? r[c] : 0.1 * widest);
    s->bounds_lo[c] = s->env_lo_now[c] - rc;
    s->bounds_hi[c] = s->env_hi_now[c] + rc;
  }
  s->bounds_n = s->n_upd;
}

/* The RLS step of the newest rows: [rows M .. M+N-1] -> [rows 0 .. M-1] (rows 1..N -> row 0
 * for the one-step predictor, M = 1) */
static void predictor_learn(rhmpc_t *ctl) {
  rhmpc_reference_t *s = &ctl->ref;
  if (RHMPC_CORRELATED) {
    memcpy(s->x, s->buf + MP * D, (size_t)RN * sizeof(double));
    memcpy(s->y, s->buf, (size_t)RQ * sizeof(double));
  } else {
    for (int b = 0; b < D; b++) {
      for (int i = 0; i < NO; i++) s->x[b * RN + i] = s->buf[(MP + i) * D + b];
      for (int j = 0; j < MP; j++) s->y[b * RQ + j] = s->buf[j * D + b];
    }
  }
  rls_update(ctl, s->x, s->y);
}

/* Predictor.update with a measured sample x: the line (repairing the fills of a gap with the
 * forecast of x), the RLS step once N + M rows (N + 1: one-step) in a row are measured */
static void predictor_measured(rhmpc_t *ctl, const double *x) {
  rhmpc_reference_t *s = &ctl->ref;
  ctl->pub.counts[RHMPC_UPDATES]++;
  memcpy(s->last, x, D * sizeof(double));
  s->has_last = 1;
  envelope_tick(s, x);
  const double *expected = NULL;
  if (s->fills && ctl->pub.ready) {
    next_sample(s, s->buf, s->next);
    expected = s->next;
  }
  line_push(ctl, x, 1, expected);
  if (RHMPC_GENERALIZED ? s->real_run >= NO + MP : s->real_run > NO) predictor_learn(ctl);
  ctl->pub.ready = s->filled >= NO;
}

/* Predictor.update: a missing sample runs the model open-loop (its own one-step forecast fills
 * the line), once the first sample has come */
static void predictor_update(rhmpc_t *ctl, const double *z) {
  rhmpc_reference_t *s = &ctl->ref;
  s->n_upd++;
  if (z != NULL) {
    predictor_measured(ctl, z);
    return;
  }
  ctl->pub.counts[RHMPC_MISSING]++;
  if (!s->has_last) return;
  envelope_tick(s, NULL);
  if (ctl->pub.ready) next_sample(s, s->buf, s->next);
  else memcpy(s->next, s->buf, D * sizeof(double));
  line_push(ctl, s->next, 0, NULL);
}

/* Predictor._guard: clip to the recent range (forecast_clamped); a non-finite forecast relearns
 * from scratch and holds the last sample meanwhile (forecast_nonfinite) */
static void predictor_guard(rhmpc_t *ctl, int K, double *f) {
  rhmpc_reference_t *s = &ctl->ref;
  int finite = all_finite(f, K * D), moved = 0;
  if (finite && s->env_known) {
    predictor_bounds(s);
    for (int k = 0; k < K * D; k++) {
      int c = k % D;
      double v = f[k] < s->bounds_lo[c] ? s->bounds_lo[c] : f[k];
      v = v > s->bounds_hi[c] ? s->bounds_hi[c] : v;
      moved |= v != f[k];
      f[k] = v;
    }
    if (moved) ctl->pub.counts[RHMPC_FORECAST_CLAMPED]++;
  }
  if (finite) return;
  ctl->pub.counts[RHMPC_FORECAST_NONFINITE]++;
  ctl->pub.ready = 0;
  predictor_allocate(s);
  for (int k = 0; k < K; k++) memcpy(f + (size_t)k * D, s->last, D * sizeof(double));
}

/* Predictor.predict: K points into out; the hold forecast while not ready */
static void predictor_predict(rhmpc_t *ctl, int K, double *out) {
  rhmpc_reference_t *s = &ctl->ref;
  if (!ctl->pub.ready) {
    for (int k = 0; k < K; k++) memcpy(out + (size_t)k * D, s->last, D * sizeof(double));
    return;
  }
  forecast(s, K, out);
  predictor_guard(ctl, K, out);
}

/* Predictor.retract: the newest sample becomes the forecast made from the N measured rows
 * below it (DelayLinePredictor._retract) */
static int predictor_retract(rhmpc_t *ctl) {
  rhmpc_reference_t *s = &ctl->ref;
  if (!ctl->pub.ready || s->real_run <= NO) return 0;
  next_sample(s, s->buf + D, s->next);
  memcpy(s->buf, s->next, D * sizeof(double));
  s->measured[0] = 0;
  s->real_run = 0;
  s->fills = 1;
  ctl->pub.counts[RHMPC_RETRACTED]++;
  return 1;
}

/* ---- the reference (PredictedReference) ------------------------------------------------- */

void rhmpc_reference_reset(rhmpc_t *ctl) {
  rhmpc_reference_t *s = &ctl->ref;
  predictor_reset(ctl);
  s->have_anchor = s->have_held = s->have_points = 0;
  s->have_forecast = s->have_second = s->have_before = 0;
  s->held_stamp = 0.0;
  s->ext_stamp = -INFINITY;
  s->ext_until = 0;
  ctl->pub.age_sum = 0.0;
  ctl->pub.age_count = 0;
  ctl->pub.first = 0;
  for (int i = 0; i < RHMPC_SPAN; i++) memcpy(ctl->pub.points + 3 * i, s->origin, sizeof s->origin);
  if (RHMPC_GATE) {
    gate_reset(ctl);
  } else {
    ctl->pub.gate_locked = 0;
    ctl->pub.gate_floor = NAN;
  }
}

void rhmpc_place(rhmpc_t *ctl, const double origin[3], const double center[3]) {
  rhmpc_reference_t *s = &ctl->ref;
  memmove(s->origin, origin, sizeof s->origin);
  memmove(s->center, center, sizeof s->center);
  if (!s->have_points) { /* nothing interpolated yet: hold the origin */
    for (int i = 0; i < RHMPC_SPAN; i++) memcpy(ctl->pub.points + 3 * i, s->origin, sizeof s->origin);
    return;
  }
  for (int i = 0; i < RHMPC_SPAN; i++)
    for (int c = 0; c < 3; c++)
      ctl->pub.points[3 * i + c] = s->origin[c] + (c < D ? s->dense[i * D + c] - s->center[c] : 0.0);
}

/* The outlier gate (PredictedReference._gated): z if the gate accepts it (retracting the
 * previous sample where it was the outlier, when `retract` can), else NULL */
int rhmpc_outlier_gate(rhmpc_t *ctl, const double *z, rhmpc_retract_t retract, void *arg) {
  rhmpc_reference_t *s = &ctl->ref;
  if (!measured(z)) return 0;
  if (!RHMPC_GATE || !s->have_forecast) return 1;
  double m2 = miss2(z, s->forecast);
  if (s->have_before && !gate_inside(ctl, m2) && gate_inside(ctl, miss2(z, s->before))
      && retract != NULL && retract(arg)) {
    gate_accept(ctl, miss2(z, s->before));
    return 1;
  }
  return gate_accept(ctl, m2);
}

static int internal_retract(void *arg) { return predictor_retract((rhmpc_t *)arg); }

/* Hold `held`; with `restart`, forget the gate's forecasts, and with restart 2 restart the
 * library's own predictor from it (counts kept; a predictor outside restarts itself:
 * rhmpc_interpolate says so) */
static void diverged(rhmpc_t *ctl, const double *held_in, int restart) {
  rhmpc_reference_t *s = &ctl->ref;
  long long counts[RHMPC_N_COUNTS];
  double held[D];
  memcpy(held, held_in, sizeof held);
  if (restart) {
    if (RHMPC_INTERNAL && restart == 2) {
      memcpy(counts, ctl->pub.counts, sizeof counts);
      predictor_reset(ctl);
      memcpy(ctl->pub.counts, counts, sizeof counts);
      predictor_update(ctl, held);
    }
    s->have_forecast = s->have_second = s->have_before = 0;
  }
  ctl->pub.counts[RHMPC_REFERENCE_GUARD]++;
  for (int i = 0; i < RHMPC_SPAN; i++) memcpy(s->dense + i * D, held, sizeof held);
}

/* The span points after `tick` from the nodes at t0 + k dt, piecewise-cubic Lagrange (s = lead +
 * age/dt, window m = clamp(floor(s) - 1, 0, nodes - 4), u = s - m), guarded against `held`
 * (measured at held_stamp; NULL: none) and placed; 1 if the guard found them diverged */
static int interpolate(rhmpc_t *ctl, long long tick, int n_nodes, double t0,
                       const double *held, double held_stamp, int restart) {
  rhmpc_reference_t *s = &ctl->ref;
  const double now = (double)tick * RHMPC_TS, shift = (now - t0) / RHMPC_DT;
  const double top = (double)(n_nodes - 4);
  int tripped = 0;
  for (int i = 0; i < RHMPC_SPAN; i++) {
    double si = (i + 1) * (RHMPC_TS / RHMPC_DT) + shift, m = floor(si) - 1.0;
    m = m > top ? top : m;
    m = m >= 0.0 ? m : 0.0;
    double u = si - m, u1 = u - 1.0, u2 = u - 2.0, u3 = u - 3.0;
    double w[4] = {-u1 * u2 * u3 / 6.0, u * u2 * u3 / 2.0, -u * u1 * u3 / 2.0,
                   u * u1 * u2 / 6.0};
    const double *r = s->nodes + (int)m * D;
    for (int c = 0; c < D; c++)
      s->dense[i * D + c] = w[0] * r[c] + w[1] * r[D + c] + w[2] * r[2 * D + c] + w[3] * r[3 * D + c];
  }
  ctl->pub.first = tick + 1;
  s->have_points = 1;
  if (RHMPC_GUARD_SPEED > 0.0 && held != NULL) {
    double reach = RHMPC_GUARD_MARGIN +
                   RHMPC_GUARD_SPEED * (now + RHMPC_SPAN * RHMPC_TS - held_stamp);
    for (int k = 0; k < RHMPC_SPAN * D; k++)
      if (fabs(s->dense[k] - held[k % D]) > reach) {
        diverged(ctl, held, restart);
        tripped = 1;
        break;
      }
  }
  rhmpc_place(ctl, s->origin, s->center);
  return tripped;
}

int rhmpc_sample(rhmpc_t *ctl, long long tick, double stamp, const double *z,
                 rhmpc_retract_t retract, void *arg, int *accepted) {
  rhmpc_reference_t *s = &ctl->ref;
  int ok;
  *accepted = 0;
  if (!isfinite(stamp)) return RHMPC_BAD_STAMP;
  ok = rhmpc_outlier_gate(ctl, z, retract, arg);
  if (!ok && !s->have_anchor) return 0; /* nothing measured yet (nor lost): hold */
  if (ok) {
    s->have_anchor = s->have_held = 1;
    s->anchor = s->held_stamp = stamp;
    memcpy(s->held, z, D * sizeof(double));
  } else {
    s->anchor += RHMPC_DT; /* the predictor advances one period open-loop */
  }
  s->measured_now = *accepted = ok;
  double latency = (double)tick * RHMPC_TS - s->anchor;
  s->latency = latency > 0.0 ? latency : 0.0;
  double steps = ceil(s->latency / RHMPC_DT - 1e-9);
  int K = RHMPC_PREDICTION_POINTS + (steps < RHMPC_KMAX ? (int)steps : RHMPC_KMAX);
  if (K > RHMPC_KMAX) {
    K = RHMPC_KMAX;
    ctl->pub.counts[RHMPC_FORECAST_CAPPED]++;
  }
  return K;
}

int rhmpc_nodes(rhmpc_t *ctl, const double *points, int count, int ready, double *t0) {
  rhmpc_reference_t *s = &ctl->ref;
  const int off = s->measured_now; /* node 0 is the sample itself when measured */
  if (points == NULL || count < 2 || count > RHMPC_KMAX) return RHMPC_BAD_FORECAST;
  if (off) memcpy(s->nodes, s->held, D * sizeof(double));
  memmove(s->nodes + off * D, points, (size_t)count * D * sizeof(double));
  if (RHMPC_GATE) { /* the one- and two-step forecasts the gate judges the next samples by */
    s->have_before = off && s->have_second;
    if (s->have_before) memcpy(s->before, s->second, D * sizeof(double));
    s->have_forecast = s->have_second = ready != 0;
    memcpy(s->forecast, s->nodes + off * D, D * sizeof(double));
    memcpy(s->second, s->nodes + (off + 1) * D, D * sizeof(double));
  }
  if (off) {
    ctl->pub.age_sum += s->latency;
    ctl->pub.age_count++;
  }
  s->n_nodes = count + off;
  s->t0 = off ? s->anchor : s->anchor + RHMPC_DT;
  if (t0 != NULL) *t0 = s->t0;
  return s->n_nodes;
}

const double *rhmpc_node_values(const rhmpc_t *ctl) { return ctl->ref.nodes; }

static int interpolate_nodes(rhmpc_t *ctl, long long tick, int restart) {
  rhmpc_reference_t *s = &ctl->ref;
  if (tick < s->ext_until || s->n_nodes < 4) return -1; /* a forecast from outside serves */
  return interpolate(ctl, tick, s->n_nodes, s->t0, s->have_held ? s->held : NULL,
                     s->held_stamp, restart);
}

int rhmpc_interpolate(rhmpc_t *ctl, long long tick) { return interpolate_nodes(ctl, tick, 1); }

int rhmpc_reference_refresh(rhmpc_t *ctl, long long tick, double stamp, const double *z) {
  rhmpc_reference_t *s = &ctl->ref;
  int accepted;
  if (!RHMPC_INTERNAL) return isfinite(stamp) ? 0 : RHMPC_BAD_STAMP;
  int K = rhmpc_sample(ctl, tick, stamp, z, internal_retract, ctl, &accepted);
  if (K <= 0) return K;
  predictor_update(ctl, accepted ? z : NULL);
  predictor_predict(ctl, K, s->nodes + accepted * D);
  rhmpc_nodes(ctl, s->nodes + accepted * D, K, ctl->pub.ready, NULL);
  interpolate_nodes(ctl, tick, 2);
  return 0;
}

void rhmpc_points(rhmpc_t *ctl, long long tick, const double *points, int count) {
  for (int i = 0; i < RHMPC_SPAN; i++)
    memcpy(ctl->pub.points + 3 * i, points + 3 * (i < count ? i : count - 1), 3 * sizeof(double));
  ctl->pub.first = tick + 1;
}

/* PredictedReference.forecast: points made outside, interpolated and guarded as the refresh's
 * own nodes (the guard holds points[0]) */
int rhmpc_reference_forecast(rhmpc_t *ctl, long long tick, double stamp, const double *points,
                             int count) {
  rhmpc_reference_t *s = &ctl->ref;
  if (!isfinite(stamp) || stamp > (double)(tick + 1) * RHMPC_TS) { /* none from the future */
    ctl->pub.counts[RHMPC_EXTERNAL_REJECTED]++;
    return RHMPC_BAD_STAMP;
  }
  if (points == NULL || count < 4 || count > RHMPC_KMAX + 1 || !all_finite(points, count * D)) {
    ctl->pub.counts[RHMPC_EXTERNAL_REJECTED]++;
    return RHMPC_BAD_FORECAST;
  }
  if (stamp < s->ext_stamp || (double)tick * RHMPC_TS - stamp > RHMPC_LATENCY_CAP) {
    ctl->pub.counts[RHMPC_EXTERNAL_STALE]++;
    return RHMPC_STALE_FORECAST;
  }
  ctl->pub.counts[RHMPC_EXTERNAL]++;
  s->ext_stamp = stamp;
  s->ext_until = tick + RHMPC_REFRESH_TICKS;
  memcpy(s->nodes, points, (size_t)count * D * sizeof(double));
  interpolate(ctl, tick, count, stamp, s->nodes, stamp, 0);
  return 0;
}
