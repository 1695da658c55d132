/* The predictor refresh of the closed loop compiled: outlier gate, RLS predictor, interpolation.
 *
 * A C99 mirror of rhmpc.control.reference.PredictedReference around the RLS predictors of
 * predictors/ (GeneralizedRLS, predictors/rls_generalized.py, Tuna et al. 2013 section VI;
 * OneStepRLS, predictors/rls_one_step.py, section V), with the bookkeeping of
 * predictors/base.py (input validation, counts, range guard, non-finite relearn, deferred
 * learning, scoring), predictors/delay_line.py (tapped delay line, ramp repair, cubic gap
 * interpolation, retraction), predictors/rls.py (Haykin, Adaptive Filter Theory, Table 10.1,
 * with its covariance guards), predictors/monitor.py (RangeEnvelope, LeadErrorRMS) and
 * rhmpc/control/gate.py (OutlierGate). The Python modules are the reference: every branch
 * below has its counterpart there, in the same order, so that both make the same decisions and
 * the same numbers up to the summation order of the BLAS products (tests/rhmpc/control/
 * test_compiled_reference.py feeds both the same streams).
 *
 * Everything is allocated by refresh_create; only a forecast longer than every one before it
 * (K beyond the capacity, a latency that grew) reallocates the K-sized arrays. All entry points
 * take a refresh_t *, so that other C code can drive a refresh through function pointers.
 */
#define _POSIX_C_SOURCE 199309L /* clock_gettime */
#include <math.h>
#include <stdlib.h>
#include <string.h>
#include <time.h>

/* indices of refresh_public_t.counts: the names of the Python predictor's Counter */
enum {
    C_UPDATES, C_MISSING, C_OUTLIERS_REJECTED, C_GATE_UNLOCKED, C_RETRACTED, C_FORECAST_CLAMPED,
    C_FORECAST_NONFINITE, C_RLS_RESET, C_RLS_BOUND, C_REFERENCE_GUARD, C_REPAIRED, N_COUNTS
};

#define ENVELOPE_BLOCKS 8   /* RangeEnvelope(blocks=8) */
#define CACHE_SIZE 64       /* PredictedReference._matrices is cleared at 64 entries */
#define MAX_GAP 3           /* TappedDelayLine.INTERPOLATE_GAP */

typedef struct {
    int generalized;        /* 1: GeneralizedRLS, 0: OneStepRLS */
    int order;              /* N, past samples in the regressor */
    int points;             /* M, weight blocks (generalized only) */
    int correlated;         /* one problem with d x d blocks, or one per axis */
    int hold_init;          /* W0 = "hold" (else zeros) */
    int dim;                /* settings.dim; 0: from the first valid sample */
    int dcap;               /* the largest d accepted (1 ... 3) */
    int envelope_block;     /* RangeEnvelope block [samples] */
    double forgetting;      /* lambda */
    double delta;           /* prior weight in data units^2 (P0 = I/delta) */
    double p_max;           /* wind-up bound of diag P */
    double guard_multiple;  /* G of Predictor._guard */
    double error_memory;    /* LeadErrorRMS memory [samples] */
    double Ts, dt;          /* control and predictor periods [s] */
    int horizon;            /* N of the MPC */
    int prediction_points;  /* forecast points before latency compensation */
    int span;               /* points per refresh: refresh_ticks + horizon + 2 */
    int kcap;               /* initial capacity of K */
    double guard_speed, guard_margin;  /* reference guard [m/s, m]; speed 0: off */
    int gate;               /* outlier gate on */
    int max_rejections, relock, calibration;
    double gate_floor;      /* > 0 [m], or NaN: calibrated on the data */
    double min_floor;       /* OutlierGate.MIN_FLOOR */
} refresh_config_t;

/* What the caller reads (and the inputs it may write) without a call: a ctypes structure on
 * the Python side. */
typedef struct {
    long long tick;         /* inputs of refresh_update_input / refresh_update_missing */
    double stamp;
    long long counts[N_COUNTS];
    long long first;        /* tick of the first point of the current refresh */
    long long age_count;
    double age_sum;         /* sum of (now - t_a) over forecasts from a sample [s] */
    double floor;           /* the gate's floor [m]; NaN while calibrating */
    int locked;             /* the gate's state */
    int ready;              /* the predictor's */
    int d;                  /* 0 until known */
    int nz;                 /* components of the staged sample while d is unknown */
    int has_points;         /* a refresh has produced points since the last reset */
    int placed;             /* points are origin + E r_c, (span, 3) */
    int failed;             /* a forecast failed: 1 a K-sized array could not grow, 2 K >= 1e6 */
    int errors_k;           /* K of LeadErrorRMS */
} refresh_public_t;

typedef struct {
    refresh_public_t pub;
    refresh_config_t cfg;
    int L;                  /* delay-line rows: N + M, or N + 1 */
    int B, n, q;            /* RLS problems, regressors and outputs of each (d known) */
    int kcap;
    /* -- gate (OutlierGate) -- */
    int g_rejected, g_inside, g_calibrating, g_ncal;
    double g_miss2, g_threshold2;
    double *g_cal, *g_sorted;
    /* -- reference (PredictedReference) -- */
    double *zin;            /* the caller's sample is staged here */
    int have_anchor, have_held, pending, pending_z, points_ready, points_z, points_k;
    int have_forecast, have_second, have_before;
    long long pending_tick, points_tick;
    double anchor, held_stamp, points_latency;
    double *held, *forecast, *second, *before, *dense, *lead;
    double origin[3];
    int cache_count;
    int cache_nodes[CACHE_SIZE];
    double cache_key[CACHE_SIZE], cache_age[CACHE_SIZE];
    /* -- predictor base (Predictor) -- */
    long long n_upd, bounds_n;
    int dim_known, has_last, deferred;
    double *last, *bounds_lo, *bounds_hi, *x_valid;
    /* RangeEnvelope */
    double *env_lo, *env_hi, *env_done_lo, *env_done_hi, *env_lo_now, *env_hi_now;
    int env_i, env_k, env_known;
    /* score(): the last sample not scored, the last forecast not recorded */
    int have_unscored, have_unrecorded, unrecorded_k;
    long long unscored_n, unrecorded_n;
    double *unscored, *unrecorded;
    /* LeadErrorRMS, ring of K forecasts of K leads: fc[(row K + lead) d + c] (without the
     * state of its fast path, which errors_observe does not need) */
    int ek;
    double e_alpha;
    double *fc, *ms, *ecount;
    long long *made, *length;
    /* -- delay line (TappedDelayLine), rows newest first -- */
    double *buf;
    unsigned char *measured;
    int filled, real_run, fills;
    double cubic[MAX_GAP + 1][MAX_GAP][4];
    /* -- RLS (RecursiveLeastSquares) -- */
    double *W, *P, *pi, *e, *x, *y;
    /* -- scratch -- */
    double *work;           /* N + M d doubles for the forecasts */
    double *points;         /* the forecast of the last predict, K x d */
    double *hist, *chain;   /* forecasts beyond M (generalized), iterated forecast (one-step) */
    double *next, *fill;
} refresh_t;

/* ------------------------------------------------------------------------------------------ */
/* small helpers                                                                              */

static int all_finite(const double *v, int n) {
    for (int i = 0; i < n; i++)
        if (!isfinite(v[i])) return 0;
    return 1;
}

static double sumsq(const double *v, int n) {
    double s = 0.0;
    for (int i = 0; i < n; i++) s += v[i] * v[i];
    return s;
}

/* numpy's pairwise summation (the add.reduce of a contiguous float64 array), so that the
 * calibrated gate floor is the very number np.mean gives */
static double pairwise_sum(const double *a, long n) {
    if (n < 8) {
        double res = 0.0;
        for (long i = 0; i < n; i++) res += a[i];
        return res;
    }
    if (n <= 128) {
        double r[8];
        long i;
        for (int j = 0; j < 8; j++) r[j] = a[j];
        for (i = 8; i < n - (n % 8); i += 8)
            for (int j = 0; j < 8; j++) r[j] += a[i + j];
        double res = ((r[0] + r[1]) + (r[2] + r[3])) + ((r[4] + r[5]) + (r[6] + r[7]));
        for (; i < n; i++) res += a[i];
        return res;
    }
    long n2 = n / 2;
    n2 -= n2 % 8;
    return pairwise_sum(a, n2) + pairwise_sum(a + n2, n - n2);
}

/* floor(x) without a library call where |x| < 2^52 (every integer part is exact there) */
static double floor_exact(double x) {
    if (!(fabs(x) < 4503599627370496.0)) return floor(x);
    double t = (double)(long long)x;
    return t > x ? t - 1.0 : t;
}

static int compare_doubles(const void *a, const void *b) {
    double x = *(const double *)a, y = *(const double *)b;
    return (x > y) - (x < y);
}

/* ------------------------------------------------------------------------------------------ */
/* OutlierGate (rhmpc/control/gate.py)                                                        */

static void gate_reset(refresh_t *s) {
    s->pub.locked = 1;
    s->g_rejected = s->g_inside = 0;
    s->g_miss2 = 0.0;
    s->g_calibrating = isnan(s->cfg.gate_floor);
    s->g_ncal = 0;
    s->pub.floor = s->cfg.gate_floor;
    s->g_threshold2 = s->g_calibrating ? 0.0 : s->cfg.gate_floor * s->cfg.gate_floor;
}

static double miss2(const refresh_t *s, const double *z, const double *forecast) {
    double m2 = 0.0;
    for (int c = 0; c < s->pub.d; c++) {
        double m = z[c] - forecast[c];
        m2 += m * m;
    }
    return m2;
}

/* OutlierGate.inside: whether a locked gate would accept a miss m2 (no state changes) */
static int gate_inside(const refresh_t *s, double m2) {
    if (s->g_calibrating) return 1;
    return s->pub.locked && m2 <= s->g_threshold2;
}

/* OutlierGate._calibrate: after 2 x calibration misses, floor = 4 RMS of the second half's
 * misses e no larger than 5 median(e) */
static void gate_calibrate(refresh_t *s, double m2) {
    int cal = s->cfg.calibration;
    s->g_cal[s->g_ncal++] = m2;
    if (s->g_ncal < 2 * cal) return;
    double *e = s->g_cal + cal;  /* overwritten in place by e = sqrt(m2): not needed again */
    for (int i = 0; i < cal; i++) e[i] = sqrt(e[i]);
    memcpy(s->g_sorted, e, (size_t)cal * sizeof(double));
    qsort(s->g_sorted, (size_t)cal, sizeof(double), compare_doubles);
    double median = cal % 2 ? s->g_sorted[cal / 2]
                            : (s->g_sorted[cal / 2 - 1] + s->g_sorted[cal / 2]) / 2.0;
    int kept = 0;  /* kept**2 in the order of the window, as numpy sums it */
    for (int i = 0; i < cal; i++)
        if (e[i] <= 5.0 * median) s->g_sorted[kept++] = e[i] * e[i];
    double rms4 = 4.0 * sqrt(pairwise_sum(s->g_sorted, kept) / kept);
    s->pub.floor = s->cfg.min_floor > rms4 ? s->cfg.min_floor : rms4;  /* max(rms4, MIN) */
    s->g_calibrating = 0;
}

/* OutlierGate.accept: whether the sample with miss m2 is accepted; events are counted */
static int gate_accept(refresh_t *s, double m2) {
    if (s->g_calibrating) {
        gate_calibrate(s, m2);
    } else {
        int outside = m2 > s->g_threshold2;
        if (!s->pub.locked) {
            s->g_inside = outside ? 0 : s->g_inside + 1;
            s->pub.locked = s->g_inside >= s->cfg.relock;
        } else if (!outside) {
            s->g_rejected = 0;
        } else if (s->g_rejected < s->cfg.max_rejections) {
            s->g_rejected++;
            s->pub.counts[C_OUTLIERS_REJECTED]++;
            return 0;
        } else {
            s->pub.locked = 0;
            s->g_rejected = s->g_inside = 0;
            s->pub.counts[C_GATE_UNLOCKED]++;
        }
    }
    s->g_miss2 += 0.02 * (m2 - s->g_miss2);
    double f = s->pub.floor, f2 = (isnan(f) || f == 0.0) ? 0.0 : f * f;
    double t2 = 16.0 * s->g_miss2;
    s->g_threshold2 = t2 > f2 ? t2 : f2;  /* Python's max(f2, t2) */
    return 1;
}

/* ------------------------------------------------------------------------------------------ */
/* RangeEnvelope and LeadErrorRMS (predictors/monitor.py)                                     */

static void envelope_reset(refresh_t *s) {
    int d = s->pub.d;
    for (int i = 0; i < ENVELOPE_BLOCKS * d; i++) {
        s->env_lo[i] = INFINITY;
        s->env_hi[i] = -INFINITY;
    }
    for (int c = 0; c < d; c++) {
        s->env_done_lo[c] = INFINITY;
        s->env_done_hi[c] = -INFINITY;
        s->env_lo_now[c] = s->env_hi_now[c] = 0.0;
    }
    s->env_i = s->env_k = s->env_known = 0;
}

static void envelope_tick(refresh_t *s, const double *x) {
    int d = s->pub.d;
    double *lo = s->env_lo + s->env_i * d, *hi = s->env_hi + s->env_i * d;
    if (x != NULL) {
        for (int c = 0; c < d; c++) {
            if (x[c] < lo[c]) lo[c] = x[c];
            if (x[c] > hi[c]) hi[c] = x[c];
        }
        s->env_known = 1;
    }
    if (++s->env_k == s->cfg.envelope_block) {
        s->env_k = 0;
        s->env_i = (s->env_i + 1) % ENVELOPE_BLOCKS;
        lo = s->env_lo + s->env_i * d;
        hi = s->env_hi + s->env_i * d;
        for (int c = 0; c < d; c++) {
            lo[c] = INFINITY;
            hi[c] = -INFINITY;
        }
        for (int c = 0; c < d; c++) {  /* the extrema of the full blocks */
            double mn = s->env_lo[c], mx = s->env_hi[c];
            for (int b = 1; b < ENVELOPE_BLOCKS; b++) {
                if (s->env_lo[b * d + c] < mn) mn = s->env_lo[b * d + c];
                if (s->env_hi[b * d + c] > mx) mx = s->env_hi[b * d + c];
            }
            s->env_done_lo[c] = mn;
            s->env_done_hi[c] = mx;
        }
    }
}

/* RangeEnvelope.envelope: the window's (min, max), or the last known one through a gap */
static void envelope_range(refresh_t *s) {
    int d = s->pub.d;
    const double *lo = s->env_lo + s->env_i * d, *hi = s->env_hi + s->env_i * d;
    double first = s->env_done_lo[0] < lo[0] ? s->env_done_lo[0] : lo[0];
    if (first == INFINITY) return;  /* every axis is seen together */
    for (int c = 0; c < d; c++) {
        s->env_lo_now[c] = s->env_done_lo[c] < lo[c] ? s->env_done_lo[c] : lo[c];
        s->env_hi_now[c] = s->env_done_hi[c] > hi[c] ? s->env_done_hi[c] : hi[c];
    }
}

/* LeadErrorRMS._alloc: a ring for forecasts of K points (everything scored so far is dropped) */
static void errors_alloc(refresh_t *s, int K) {
    s->ek = s->pub.errors_k = K;
    memset(s->fc, 0, (size_t)K * K * s->pub.d * sizeof(double));
    for (int k = 0; k < K; k++) {
        s->made[k] = -1;
        s->length[k] = 0;
        s->ms[k] = s->ecount[k] = 0.0;
    }
}

static void errors_record(refresh_t *s, long long n, const double *forecast, int K) {
    int d = s->pub.d;
    if (K > s->ek) errors_alloc(s, K);
    int row = (int)(n % s->ek);
    memcpy(s->fc + (size_t)row * s->ek * d, forecast, (size_t)K * d * sizeof(double));
    s->made[row] = n;
    s->length[row] = K;
}

/* LeadErrorRMS.observe without its fast path, which makes the same numbers: m_k <- m_k +
 * a_k (e_k^2 - m_k), a_k = max(alpha, 1/count_k) if the forecast made k updates ago reaches
 * sample n, else 0 (multiplied, as numpy does, so that a stale inf miss gives NaN there too) */
static void errors_observe(refresh_t *s, long long n, const double *z) {
    int d = s->pub.d, K = s->ek, now = (int)(n % K);
    for (int k = 0; k < K; k++) {
        int row = ((now - (k + 1)) % K + K) % K;
        int ok = s->made[row] == n - (k + 1) && s->length[row] >= k + 1;
        const double *f = s->fc + ((size_t)row * K + k) * d;
        double e2 = 0.0;
        for (int c = 0; c < d; c++) {
            double m = f[c] - z[c];
            e2 += m * m;
        }
        s->ecount[k] += ok;
        double inv = 1.0 / (s->ecount[k] > 1.0 ? s->ecount[k] : 1.0);
        double a = (s->e_alpha >= inv ? s->e_alpha : inv) * (double)ok;
        s->ms[k] += a * (e2 - s->ms[k]);
    }
}

/* ------------------------------------------------------------------------------------------ */
/* RLS (predictors/rls.py)                                                                    */

/* y = A x, A (rows x cols, row-major): each y_j summed over k in order, four rows at a time
 * (independent sums side by side, the parallelism one sum chain lacks) */
static void matvec(const double *A, int rows, int cols, const double *x, double *y) {
    int j = 0;
    for (; j + 4 <= rows; j += 4) {
        const double *a0 = A + (size_t)j * cols, *a1 = a0 + cols, *a2 = a1 + cols,
                     *a3 = a2 + cols;
        double s0 = 0.0, s1 = 0.0, s2 = 0.0, s3 = 0.0;
        for (int k = 0; k < cols; k++) {
            s0 += a0[k] * x[k];
            s1 += a1[k] * x[k];
            s2 += a2[k] * x[k];
            s3 += a3[k] * x[k];
        }
        y[j] = s0;
        y[j + 1] = s1;
        y[j + 2] = s2;
        y[j + 3] = s3;
    }
    for (; j < rows; j++) {
        const double *a = A + (size_t)j * cols;
        double acc = 0.0;
        for (int k = 0; k < cols; k++) acc += a[k] * x[k];
        y[j] = acc;
    }
}

static void rls_reset_covariance(refresh_t *s, int b) {
    int n = s->n;
    double *P = s->P + (size_t)b * n * n, p0 = 1.0 / s->cfg.delta;
    memset(P, 0, (size_t)n * n * sizeof(double));
    for (int i = 0; i < n; i++) P[i * n + i] = p0;
}

/* One Sherman-Morrison step per problem (Haykin Table 10.1):
 *   pi = P x, kappa = lambda + x'pi, e = y - W x, W += e pi'/kappa, P = (P - pi pi'/kappa)/lambda
 * P is kept exactly symmetric (each pair of entries computed once), as the one triangle that
 * dsyr/dsymv keep in the Python kernel; then the reset and wind-up guards. */
static void rls_update(refresh_t *s, const double *x, const double *y) {
    int n = s->n, q = s->q;
    double lam = s->cfg.forgetting;
    for (int b = 0; b < s->B; b++) {
        const double *xb = x + (size_t)b * n, *yb = y + (size_t)b * q;
        double *P = s->P + (size_t)b * n * n, *W = s->W + (size_t)b * q * n, *pi = s->pi;
        for (int i = 0; i < n; i++) pi[i] = 0.0;
        for (int k = 0; k < n; k++) {  /* pi = P x by columns (P symmetric): sums in k order */
            const double *row = P + (size_t)k * n;
            double xk = xb[k];
            for (int i = 0; i < n; i++) pi[i] += row[i] * xk;
        }
        double kappa = 0.0;
        for (int i = 0; i < n; i++) kappa += xb[i] * pi[i];
        kappa += lam;
        if (!(kappa > 0.0 && isfinite(kappa))) {
            s->pub.counts[C_RLS_RESET]++;
            rls_reset_covariance(s, b);
            continue;
        }
        matvec(W, q, n, xb, s->e);  /* a-priori error */
        for (int j = 0; j < q; j++) s->e[j] = yb[j] - s->e[j];
        double gain = 1.0 / kappa, alpha = -1.0 / kappa;
        for (int j = 0; j < q; j++) {  /* dger: W[j, i] += pi_i (e_j / kappa) */
            double t = gain * s->e[j];
            for (int i = 0; i < n; i++) W[j * n + i] += pi[i] * t;
        }
        /* dsyr: P[i, k] += pi_i (-pi_k / kappa) for i <= k, the same number for P[k, i]; then
         * P /= lambda (x 1.0 when lambda = 1, which changes nothing, as the Python skip) */
        double *t = s->e + q, inv = lam != 1.0 ? 1.0 / lam : 1.0;
        for (int k = 0; k < n; k++) t[k] = alpha * pi[k];
        for (int r = 0; r < n; r++) {
            double *row = P + (size_t)r * n, pr = pi[r], tr = t[r];
            for (int c = 0; c < r; c++) row[c] = (row[c] + pi[c] * tr) * inv;
            for (int c = r; c < n; c++) row[c] = (row[c] + pr * t[c]) * inv;
        }
        /* argmax/argmin of numpy: a NaN anywhere wins, which the reset catches */
        double peak = -INFINITY, low = INFINITY;
        int nan = 0;
        for (int i = 0; i < n; i++) {
            double v = P[i * n + i];
            if (isnan(v)) nan = 1;
            if (v > peak) peak = v;
            if (v < low) low = v;
        }
        if (nan || !isfinite(peak) || !(low > 0.0)) {
            s->pub.counts[C_RLS_RESET]++;
            rls_reset_covariance(s, b);
        } else if (peak > s->cfg.p_max) {  /* P <- D P D, D = diag(min(1, sqrt(p_max/P_ii))) */
            s->pub.counts[C_RLS_BOUND]++;
            double *scale = s->e + q;  /* n doubles after e */
            for (int i = 0; i < n; i++) {
                double r = s->cfg.p_max / P[i * n + i];
                scale[i] = sqrt(r < 1.0 ? r : 1.0);
            }
            for (int i = 0; i < n; i++)
                for (int k = 0; k < n; k++) P[i * n + k] *= scale[i] * scale[k];
        }
    }
}

/* ------------------------------------------------------------------------------------------ */
/* the predictors' forecasts                                                                  */

/* Column b of the newest-first rows past (N x d), contiguous: the regressor of axis b */
static const double *axis_column(const refresh_t *s, const double *past, int b, double *out) {
    int d = s->pub.d;
    for (int i = 0; i < s->cfg.order; i++) out[i] = past[i * d + b];
    return out;
}

/* One-step (OneStepRLS._next): z_hat (d) after the newest-first rows past (N x d),
 * W = [A_1 ... A_N] (correlated) or one row of N taps per axis */
static void onestep_next(refresh_t *s, const double *past, double *out) {
    int d = s->pub.d, N = s->cfg.order;
    if (s->cfg.correlated) {
        matvec(s->W, d, s->n, past, out);
    } else {
        for (int b = 0; b < d; b++)
            matvec(s->W + (size_t)b * N, 1, N, axis_column(s, past, b, s->work), out + b);
    }
}

/* Generalized (GeneralizedRLS._block): z_hat_{+1} ... z_hat_{+M} (M x d) after the rows past;
 * weight block j forecasts M - j steps ahead, hence the reversal. first = 1: z_hat_{+1} only
 * (DelayLinePredictor._next: the first row of the reversed block, weight block M - 1). */
static void generalized_block(refresh_t *s, const double *past, double *out, int first) {
    int d = s->pub.d, N = s->cfg.order, M = s->cfg.points, j0 = first ? M - 1 : 0;
    double *raw = s->work + N;  /* raw[j d + c] (correlated), raw[b M + j] (independent) */
    if (s->cfg.correlated) {
        matvec(s->W + (size_t)j0 * d * s->n, (M - j0) * d, s->n, past, raw);
        for (int j = j0; j < M; j++)
            for (int c = 0; c < d; c++) out[(M - 1 - j) * d + c] = raw[(j - j0) * d + c];
    } else {
        for (int b = 0; b < d; b++) {
            const double *column = axis_column(s, past, b, s->work);
            matvec(s->W + ((size_t)b * M + j0) * N, M - j0, N, column, raw);
            for (int j = j0; j < M; j++) out[(M - 1 - j) * d + b] = raw[j - j0];
        }
    }
}

/* DelayLinePredictor._next: the one-step forecast after the newest-first rows past */
static void next_sample(refresh_t *s, const double *past, double *out) {
    if (s->cfg.generalized) generalized_block(s, past, out, 1);
    else onestep_next(s, past, out);
}

/* GeneralizedRLS._predict: K <= M points from one block; beyond, the M forecasts are pushed
 * as if observed and the block applied again, newest first: hist = [block b-1 reversed, ...,
 * block 0 reversed, z_n ... z_{n-N+1}] */
static void generalized_predict(refresh_t *s, int K, double *out) {
    int d = s->pub.d, N = s->cfg.order, M = s->cfg.points;
    if (K <= M) {
        generalized_block(s, s->buf, s->chain, 0);
        memcpy(out, s->chain, (size_t)K * d * sizeof(double));
        return;
    }
    int blocks = (K + M - 1) / M;
    double *all = s->chain, *hist = s->hist;  /* blocks M x d, and (blocks - 1) M + N rows */
    generalized_block(s, s->buf, all, 0);
    memcpy(hist + (size_t)(blocks - 1) * M * d, s->buf, (size_t)N * d * sizeof(double));
    for (int b = 1; b < blocks; b++) {
        int top = (blocks - 1 - b) * M;
        for (int r = 0; r < M; r++)  /* block b - 1, reversed */
            memcpy(hist + (size_t)(top + r) * d, all + (size_t)(b * M - 1 - r) * d,
                   (size_t)d * sizeof(double));
        generalized_block(s, hist + (size_t)top * d, all + (size_t)b * M * d, 0);
    }
    memcpy(out, all, (size_t)K * d * sizeof(double));
}

/* OneStepRLS._predict: the iterated one-step forecast in a newest-first scratch
 * [z_hat_{n+K} ... z_hat_{n+1}, z_n ... z_{n-N+1}], each written just before its window */
static void onestep_predict(refresh_t *s, int K, double *out) {
    int d = s->pub.d, N = s->cfg.order;
    double *b = s->chain;
    memcpy(b + (size_t)K * d, s->buf, (size_t)N * d * sizeof(double));
    for (int k = K * d; k > 0; k -= d) onestep_next(s, b + k, b + k - d);
    for (int k = 0; k < K; k++)
        memcpy(out + (size_t)k * d, b + (size_t)(K - 1 - k) * d, (size_t)d * sizeof(double));
}

/* ------------------------------------------------------------------------------------------ */
/* TappedDelayLine (predictors/delay_line.py)                                                 */

static void line_reset(refresh_t *s) {
    memset(s->buf, 0, (size_t)s->L * s->pub.d * sizeof(double));
    memset(s->measured, 0, (size_t)s->L);
    s->filled = s->real_run = s->fills = 0;
}

/* Rows 0, 1 measured: a gap of g <= 3 rows below them becomes the cubic through rows 0, 1,
 * g + 2, g + 3 when those two are measurements too */
static void line_interpolate_gap(refresh_t *s) {
    int g = 0, d = s->pub.d, L = s->L;
    while (2 + g < L && !s->measured[2 + g] && g <= MAX_GAP) g++;
    if (!(1 <= g && g <= MAX_GAP) || 3 + g >= s->filled) return;
    if (!(s->measured[2 + g] && s->measured[3 + g])) return;
    const double *rows[4] = {s->buf, s->buf + d, s->buf + (size_t)(2 + g) * d,
                             s->buf + (size_t)(3 + g) * d};
    for (int i = 0; i < g; i++)
        for (int c = 0; c < d; c++) {
            const double *w = s->cubic[g][i];
            s->buf[(size_t)(2 + i) * d + c] =
                w[0] * rows[0][c] + w[1] * rows[1][c] + w[2] * rows[2][c] + w[3] * rows[3][c];
        }
}

/* TappedDelayLine.push: after g fills, a measurement z with the forecast `expected` of it
 * corrects fill i (oldest first, i = 1 ... g) by (i/(g+1)) (z - expected), a repair counted */
static void line_push(refresh_t *s, const double *z, int measured, const double *expected) {
    int d = s->pub.d, L = s->L;
    double *buf = s->buf;
    if (measured && s->fills && expected != NULL && all_finite(expected, d)) {
        int g = s->fills < L - 1 ? s->fills : L - 1;
        s->pub.counts[C_REPAIRED]++;
        double diff[3];
        for (int c = 0; c < d; c++) diff[c] = z[c] - expected[c];
        for (int i = 0; i < g; i++) {
            double ramp = (double)(s->fills - i) / (s->fills + 1.0);
            for (int c = 0; c < d; c++) buf[(size_t)i * d + c] += ramp * diff[c];
        }
    }
    memmove(buf + d, buf, (size_t)(L - 1) * d * sizeof(double));
    memcpy(buf, z, (size_t)d * sizeof(double));
    memmove(s->measured + 1, s->measured, (size_t)(L - 1));
    s->measured[0] = (unsigned char)measured;
    s->filled = s->filled + 1 < L ? s->filled + 1 : L;
    s->real_run = measured ? s->real_run + 1 : 0;
    s->fills = measured ? 0 : s->fills + 1;
    if (s->real_run == 2) line_interpolate_gap(s);
}

/* ------------------------------------------------------------------------------------------ */
/* the predictor (Predictor, DelayLinePredictor and the two RLS predictors)                   */

/* _allocate: W0, P0 and an empty delay line */
static void predictor_allocate(refresh_t *s) {
    int d = s->pub.d, N = s->cfg.order, M = s->cfg.points;
    if (s->cfg.generalized) {
        s->B = s->cfg.correlated ? 1 : d;
        s->n = s->cfg.correlated ? N * d : N;
        s->q = s->cfg.correlated ? M * d : M;
        s->L = N + M;
    } else {
        s->B = s->cfg.correlated ? 1 : d;
        s->n = s->cfg.correlated ? N * d : N;
        s->q = s->cfg.correlated ? d : 1;
        s->L = N + 1;
    }
    int n = s->n, q = s->q;
    memset(s->W, 0, (size_t)s->B * q * n * sizeof(double));
    if (s->cfg.hold_init) {  /* every block forecasts the newest sample */
        if (s->cfg.correlated) {
            for (int j = 0; j < q / d; j++)
                for (int c = 0; c < d; c++) s->W[(size_t)(j * d + c) * n + c] = 1.0;
        } else {
            for (int b = 0; b < d; b++)
                for (int j = 0; j < q; j++) s->W[(size_t)(b * q + j) * n] = 1.0;
        }
    }
    for (int b = 0; b < s->B; b++) rls_reset_covariance(s, b);
    line_reset(s);
}

static void predictor_set_dim(refresh_t *s, int d) {
    s->pub.d = d;
    s->dim_known = 1;
    envelope_reset(s);
    errors_alloc(s, 1);
    s->bounds_n = -1;
    predictor_allocate(s);
}

static void predictor_reset(refresh_t *s) {
    s->n_upd = 0;
    memset(s->pub.counts, 0, sizeof(s->pub.counts));
    s->pub.ready = 0;
    s->has_last = 0;
    s->pub.d = 0;
    s->dim_known = 0;
    s->deferred = 0;
    s->have_unscored = s->have_unrecorded = 0;
    if (s->cfg.dim > 0) predictor_set_dim(s, s->cfg.dim);
}

/* _update_bounds: the guard's range [lo - G r, hi + G r], r floored at 10 % of the widest */
static void predictor_update_bounds(refresh_t *s) {
    if (!s->dim_known || s->bounds_n == s->n_upd || !s->env_known) return;
    int d = s->pub.d;
    envelope_range(s);
    double r[3], widest = -INFINITY;
    for (int c = 0; c < d; c++) {
        r[c] = s->env_hi_now[c] - s->env_lo_now[c];
        if (r[c] > widest) widest = r[c];
    }
    double least = 0.1 * widest;
    for (int c = 0; c < d; c++) {
        double rc = s->cfg.guard_multiple * (r[c] >= least ? r[c] : least);
        s->bounds_lo[c] = s->env_lo_now[c] - rc;
        s->bounds_hi[c] = s->env_hi_now[c] + rc;
    }
    s->bounds_n = s->n_upd;
}

/* Predictor.learn: the RLS step deferred by the last update, on the rows it was made from */
static void predictor_learn(refresh_t *s) {
    if (!s->deferred) return;
    s->deferred = 0;
    int d = s->pub.d, N = s->cfg.order, M = s->cfg.points, B = s->B, n = s->n, q = s->q;
    const double *buf = s->buf;
    if (s->cfg.generalized) {  /* rows M ... M+N-1 -> rows 0 ... M-1 */
        if (s->cfg.correlated) {
            memcpy(s->x, buf + (size_t)M * d, (size_t)n * sizeof(double));
            memcpy(s->y, buf, (size_t)q * sizeof(double));
        } else {
            for (int b = 0; b < B; b++) {
                for (int i = 0; i < N; i++) s->x[b * n + i] = buf[(size_t)(M + i) * d + b];
                for (int j = 0; j < M; j++) s->y[b * q + j] = buf[(size_t)j * d + b];
            }
        }
    } else {  /* rows 1 ... N -> row 0 */
        if (s->cfg.correlated) {
            memcpy(s->x, buf + d, (size_t)n * sizeof(double));
            memcpy(s->y, buf, (size_t)d * sizeof(double));
        } else {
            for (int b = 0; b < B; b++) {
                for (int i = 0; i < N; i++) s->x[b * n + i] = buf[(size_t)(1 + i) * d + b];
                s->y[b] = buf[b];
            }
        }
    }
    rls_update(s, s->x, s->y);
    predictor_update_bounds(s);
}

/* Predictor.score: the newest sample scored, then the newest forecast recorded */
static void predictor_score(refresh_t *s) {
    if (s->have_unscored) {
        s->have_unscored = 0;
        errors_observe(s, s->unscored_n, s->unscored);
    }
    if (s->have_unrecorded) {
        s->have_unrecorded = 0;
        errors_record(s, s->unrecorded_n, s->unrecorded, s->unrecorded_k);
    }
}

/* DelayLinePredictor._push / _update of the two predictors */
static void predictor_absorb(refresh_t *s, const double *x) {
    int N = s->cfg.order;
    predictor_learn(s);
    const double *expected = NULL;
    if (s->fills && s->pub.ready) {  /* its forecast repairs the fills */
        next_sample(s, s->buf, s->next);
        expected = s->next;
    }
    line_push(s, x, 1, expected);
    if (s->cfg.generalized ? s->real_run >= N + s->cfg.points : s->real_run > N) {
        predictor_learn(s);  /* _defer: a step still pending runs first */
        s->deferred = 1;
    }
    s->pub.ready = s->filled >= N;
}

/* DelayLinePredictor._missing: run open-loop on the model's own one-step forecast */
static void predictor_missing(refresh_t *s) {
    predictor_learn(s);
    if (s->pub.ready) next_sample(s, s->buf, s->fill);
    else memcpy(s->fill, s->buf, (size_t)s->pub.d * sizeof(double));
    line_push(s, s->fill, 0, NULL);
}

/* Predictor.update: z (NULL, a non-finite component or a square that overflows: missing) of
 * nz components */
static void predictor_update(refresh_t *s, const double *z, int nz) {
    if (s->deferred) predictor_learn(s);
    predictor_score(s);
    int valid = z != NULL && isfinite(sumsq(z, nz));
    s->n_upd++;
    if (!valid) {
        s->pub.counts[C_MISSING]++;
        if (s->dim_known) {
            envelope_tick(s, NULL);
            predictor_missing(s);
        }
        return;
    }
    if (!s->dim_known) predictor_set_dim(s, nz);
    int d = s->pub.d;
    s->pub.counts[C_UPDATES]++;
    memcpy(s->last, z, (size_t)d * sizeof(double));
    s->has_last = 1;
    envelope_tick(s, s->last);
    memcpy(s->unscored, z, (size_t)d * sizeof(double));
    s->unscored_n = s->n_upd;
    s->have_unscored = 1;
    memcpy(s->x_valid, z, (size_t)d * sizeof(double));
    predictor_absorb(s, s->x_valid);
}

static void hold_last(refresh_t *s, int K, double *out) {
    int d = s->pub.d;
    for (int k = 0; k < K; k++) memcpy(out + (size_t)k * d, s->last, (size_t)d * sizeof(double));
}

/* Predictor._relearn: a non-finite forecast; learn again from scratch, hold meanwhile */
static void predictor_relearn(refresh_t *s, int K, double *out) {
    s->pub.counts[C_FORECAST_NONFINITE]++;
    s->pub.ready = 0;
    predictor_allocate(s);
    hold_last(s, K, out);
}

/* Predictor._guard: clip to the recent range (forecast_clamped); relearn if non-finite */
static void predictor_guard(refresh_t *s, int K, double *f) {
    int d = s->pub.d, m = K * d;
    if (!s->env_known) {
        if (!all_finite(f, m)) predictor_relearn(s, K, f);
        return;
    }
    predictor_update_bounds(s);
    double moved = 0.0;
    for (int k = 0; k < K; k++)
        for (int c = 0; c < d; c++) {
            double v = f[k * d + c], g = v;
            if (!isnan(v)) {
                g = v < s->bounds_lo[c] ? s->bounds_lo[c] : v;
                g = g > s->bounds_hi[c] ? s->bounds_hi[c] : g;
            }
            double dv = g - v;
            moved += dv * dv;
        }
    if (!isfinite(moved) && !all_finite(f, m)) {
        predictor_relearn(s, K, f);
        return;
    }
    if (moved != 0.0) s->pub.counts[C_FORECAST_CLAMPED]++;
    for (int k = 0; k < K; k++)  /* the clipped forecast (f itself where it is inside) */
        for (int c = 0; c < d; c++) {
            double v = f[k * d + c];
            v = v < s->bounds_lo[c] ? s->bounds_lo[c] : v;
            f[k * d + c] = v > s->bounds_hi[c] ? s->bounds_hi[c] : v;
        }
}

/* Predictor.predict: K points into out (K x d); the hold forecast while not ready */
static void predictor_predict(refresh_t *s, int K, double *out) {
    if (s->deferred) predictor_learn(s);
    if (!s->pub.ready) {
        hold_last(s, K, out);  /* has_last: the reference predicts after a valid sample only */
    } else {
        if (s->cfg.generalized) generalized_predict(s, K, out);
        else onestep_predict(s, K, out);
        predictor_guard(s, K, out);
    }
    memcpy(s->unrecorded, out, (size_t)K * s->pub.d * sizeof(double));
    s->unrecorded_n = s->n_upd;
    s->unrecorded_k = K;
    s->have_unrecorded = 1;
}

/* Predictor.retract: the newest sample becomes the forecast of it made from the N measured
 * rows below it (DelayLinePredictor._retract) */
static int predictor_retract(refresh_t *s) {
    if (s->deferred) predictor_learn(s);
    int N = s->cfg.order, d = s->pub.d;
    if (!s->pub.ready || s->real_run <= N) return 0;
    next_sample(s, s->buf + d, s->fill);
    memcpy(s->buf, s->fill, (size_t)d * sizeof(double));
    s->measured[0] = 0;
    s->real_run = 0;
    s->fills = 1;
    s->pub.counts[C_RETRACTED]++;
    return 1;
}

/* ------------------------------------------------------------------------------------------ */
/* memory                                                                                     */

static void release_k(refresh_t *s) {
    double **f[] = {&s->points, &s->hist, &s->chain, &s->unrecorded, &s->fc, &s->ms, &s->ecount};
    for (size_t i = 0; i < sizeof f / sizeof f[0]; i++) {
        free(*f[i]);
        *f[i] = NULL;
    }
    free(s->made);
    free(s->length);
    s->made = s->length = NULL;
}

static int grow(void **p, size_t bytes) {
    void *q = realloc(*p, bytes ? bytes : 1);
    if (q == NULL) return 0;
    *p = q;
    return 1;
}

/* The K-sized arrays for K up to kcap; what they hold is kept (LeadErrorRMS keeps its ring
 * until the next record). */
static int ensure_k(refresh_t *s, int K) {
    if (K <= s->kcap && s->points != NULL) return 1;
    int cap = K > 2 * s->kcap ? K : 2 * s->kcap;
    if (s->points == NULL) cap = K;
    size_t dc = (size_t)s->cfg.dcap, N = (size_t)s->cfg.order, M = (size_t)s->cfg.points;
    size_t rows = (size_t)cap + M + N + 1, D = sizeof(double);
    int ok = grow((void **)&s->points, (size_t)cap * dc * D)
             && grow((void **)&s->hist, rows * dc * D)
             && grow((void **)&s->chain, rows * dc * D)
             && grow((void **)&s->unrecorded, (size_t)cap * dc * D)
             && grow((void **)&s->fc, (size_t)cap * cap * dc * D)
             && grow((void **)&s->ms, (size_t)cap * D)
             && grow((void **)&s->ecount, (size_t)cap * D)
             && grow((void **)&s->made, (size_t)cap * sizeof(long long))
             && grow((void **)&s->length, (size_t)cap * sizeof(long long));
    if (!ok) return 0;
    s->kcap = cap;
    return 1;
}

void refresh_free(refresh_t *s) {
    if (s == NULL) return;
    release_k(s);
    free(s);
}

void refresh_reset(refresh_t *s);

/* A refresh for cfg, or NULL (invalid sizes, no memory). One block holds every array whose
 * size is fixed; the K-sized ones are apart, for ensure_k. */
refresh_t *refresh_create(const refresh_config_t *cfg) {
    int dc = cfg->dcap, N = cfg->order, M = cfg->generalized ? cfg->points : 1;
    if (dc < 1 || dc > 3 || N < 1 || M < 1 || cfg->span < 1 || cfg->prediction_points < 2
        || (cfg->dim != 0 && cfg->dim != dc) || cfg->envelope_block < 1
        || (cfg->gate && cfg->calibration < 1))
        return NULL;
    size_t L = (size_t)N + M, n = (size_t)N * dc, q = (size_t)M * dc;
    size_t cal = cfg->gate && isnan(cfg->gate_floor) ? (size_t)cfg->calibration : 0;
    size_t doubles = (q * n)                  /* W (B q n <= (M d)(N d)) */
                     + (n * n)                /* P (B n^2 <= (N d)^2) */
                     + n + (q + n) + 2 * dc * n + 2 * dc * q  /* pi, e + scale, x, y */
                     + L * dc                 /* delay line */
                     + 3 * cal                /* gate calibration window and its sort */
                     + (size_t)cfg->span * dc + (size_t)cfg->span  /* dense, lead */
                     + 24 * dc                /* the d-vectors */
                     + 2 * ENVELOPE_BLOCKS * dc
                     + (size_t)N + q;         /* work */
    size_t bytes = sizeof(refresh_t) + doubles * sizeof(double) + L + 64;
    refresh_t *s = calloc(1, bytes);
    if (s == NULL) return NULL;
    s->cfg = *cfg;
    if (!cfg->generalized) s->cfg.points = 1;
    double *p = (double *)(s + 1);
#define TAKE(field, count) (s->field = p, p += (count))
    TAKE(W, q * n);
    TAKE(P, n * n);
    TAKE(pi, n);
    TAKE(e, q + n);
    TAKE(x, 2 * dc * n);
    TAKE(y, 2 * dc * q);
    TAKE(buf, L * dc);
    TAKE(g_cal, 2 * cal);
    TAKE(g_sorted, cal);
    TAKE(dense, (size_t)cfg->span * dc);
    TAKE(lead, (size_t)cfg->span);
    TAKE(env_lo, ENVELOPE_BLOCKS * dc);
    TAKE(env_hi, ENVELOPE_BLOCKS * dc);
    TAKE(work, (size_t)N + q);
    double **vectors[] = {&s->zin, &s->held, &s->forecast, &s->second, &s->before,
                          &s->last, &s->bounds_lo, &s->bounds_hi, &s->x_valid, &s->env_done_lo,
                          &s->env_done_hi, &s->env_lo_now, &s->env_hi_now, &s->unscored,
                          &s->next, &s->fill};
    for (size_t i = 0; i < sizeof vectors / sizeof vectors[0]; i++) {
        *vectors[i] = p;
        p += dc;
    }
#undef TAKE
    s->measured = (unsigned char *)p;
    s->kcap = cfg->kcap > cfg->prediction_points ? cfg->kcap : cfg->prediction_points;
    if (!ensure_k(s, s->kcap)) {
        refresh_free(s);
        return NULL;
    }
    double ratio = cfg->Ts / cfg->dt;  /* (tau - now)/dt of point i: (i + 1) Ts/dt */
    for (int i = 0; i < cfg->span; i++) s->lead[i] = (double)(i + 1) * ratio;
    for (int g = 1; g <= MAX_GAP; g++) {  /* _cubic_weights(g): Lagrange on 0, 1, g+2, g+3 */
        double nodes[4] = {0.0, 1.0, 2.0 + g, 3.0 + g};
        for (int i = 0; i < g; i++) {
            double at = 2.0 + i;
            for (int j = 0; j < 4; j++) {
                double w = 1.0;
                for (int m = 0; m < 4; m++)
                    if (m != j) w *= (at - nodes[m]) / (nodes[j] - nodes[m]);
                s->cubic[g][i][j] = w;
            }
        }
    }
    s->e_alpha = 1.0 / cfg->error_memory;
    s->L = N + M;
    refresh_reset(s);
    return s;
}

/* ------------------------------------------------------------------------------------------ */
/* the reference (PredictedReference)                                                         */

/* PredictedReference.reset: forget the predictor, the gate and the points (the cache of
 * interpolation windows, like the Python one's matrices, is kept) */
void refresh_reset(refresh_t *s) {
    predictor_reset(s);
    s->pub.failed = 0;
    s->pub.has_points = 0;
    s->pub.first = 0;
    s->pending = s->points_ready = 0;
    s->have_anchor = s->have_held = 0;
    s->have_forecast = s->have_second = s->have_before = 0;
    s->held_stamp = 0.0;
    s->pub.age_sum = 0.0;
    s->pub.age_count = 0;
    if (s->cfg.gate) gate_reset(s);
    else {
        s->pub.locked = 0;
        s->pub.floor = NAN;
    }
}

/* The staged sample's address (nz components, nz = d once known). */
double *refresh_input(refresh_t *s) { return s->zin; }

/* PredictedReference.update: the gate, then the predictor's update with z (NULL: none new)
 * measured at stamp [s], on tick `tick`. Returns -1 (and does nothing) if d is unknown and
 * pub.nz is not 1 ... dcap, -3 if the stamp is not finite, else 0. */
int refresh_update(refresh_t *s, const double *z, long long tick, double stamp) {
    if (!isfinite(stamp)) return -3;
    int nz = s->dim_known ? s->pub.d : s->pub.nz;
    if (z != NULL && !s->dim_known && (nz < 1 || nz > s->cfg.dcap)) return -1;
    int valid = z != NULL && isfinite(sumsq(z, nz));  /* np.vdot: a square that overflows too */
    if (valid && s->have_forecast) {
        double m2 = miss2(s, z, s->forecast);
        /* outside around z_hat_{n+1|n} but inside around z_hat_{n+1|n-1}: z_n was the outlier */
        if (s->have_before && !gate_inside(s, m2) && gate_inside(s, miss2(s, z, s->before))
            && predictor_retract(s)) {
            gate_accept(s, miss2(s, z, s->before));
        } else if (!gate_accept(s, m2)) {
            z = NULL;
            valid = 0;
        }
    }
    predictor_update(s, z, nz);
    s->pending = s->points_ready = 0;
    if (valid) {
        s->have_anchor = s->have_held = 1;
        s->anchor = s->held_stamp = stamp;
        memcpy(s->held, z, (size_t)s->pub.d * sizeof(double));
    } else if (!s->have_anchor) {
        return 0;  /* nothing measured yet: keep holding */
    } else {
        s->anchor += s->cfg.dt;  /* the predictor advanced one period open-loop */
    }
    s->pending = 1;
    s->pending_tick = tick;
    s->pending_z = valid;
    return 0;
}

/* refresh_update with the sample staged at refresh_input(s), tick and stamp in pub: the entry
 * points of a caller that writes its arguments rather than passing them */
int refresh_update_input(refresh_t *s) {
    return refresh_update(s, s->zin, s->pub.tick, s->pub.stamp);
}

int refresh_update_missing(refresh_t *s) {
    return refresh_update(s, NULL, s->pub.tick, s->pub.stamp);
}

void refresh_learn(refresh_t *s) { predictor_learn(s); }

void refresh_score(refresh_t *s) { predictor_score(s); }

/* PredictedReference.predict: K = prediction_points + ceil(latency/dt) points; the gate keeps
 * the one- and two-step ones */
void refresh_predict(refresh_t *s) {
    if (!s->pending) return;
    s->pending = 0;
    double latency = (double)s->pending_tick * s->cfg.Ts - s->anchor;
    if (!(latency > 0.0)) latency = 0.0;  /* max(0.0, x) */
    double steps = ceil(latency / s->cfg.dt - 1e-9);
    if (!(steps < 1e6) || !ensure_k(s, s->cfg.prediction_points + (int)steps)) {
        s->pub.failed = steps < 1e6 ? 1 : 2;
        return;
    }
    int K = s->cfg.prediction_points + (int)steps, d = s->pub.d;
    predictor_predict(s, K, s->points);
    if (s->cfg.gate) {
        s->have_before = s->pending_z && s->have_second;
        if (s->have_before) memcpy(s->before, s->second, (size_t)d * sizeof(double));
        s->have_forecast = s->have_second = s->pub.ready;
        memcpy(s->forecast, s->points, (size_t)d * sizeof(double));
        memcpy(s->second, s->points + d, (size_t)d * sizeof(double));
    }
    s->points_ready = 1;
    s->points_tick = s->pending_tick;
    s->points_z = s->pending_z;
    s->points_latency = latency;
    s->points_k = K;
}

/* The age the weights of (n_nodes, age) are made from: the first age of its key, as
 * PredictedReference._interpolation caches its matrices by (n_nodes, round(age/Ts, 6)) */
static double cached_age(refresh_t *s, int n_nodes, double age) {
    double key = nearbyint(age / s->cfg.Ts * 1e6);
    for (int i = 0; i < s->cache_count; i++)
        if (s->cache_nodes[i] == n_nodes && s->cache_key[i] == key) return s->cache_age[i];
    if (s->cache_count >= CACHE_SIZE) s->cache_count = 0;
    int i = s->cache_count++;
    s->cache_nodes[i] = n_nodes;
    s->cache_key[i] = key;
    s->cache_age[i] = age;
    return age;
}

static void write_points(const refresh_t *s, double *out) {
    int d = s->pub.d, span = s->cfg.span;
    const double *dense = s->dense;
    if (!s->pub.placed) {
        memcpy(out, dense, (size_t)span * d * sizeof(double));
        return;
    }
    double origin[3] = {s->origin[0], s->origin[1], s->origin[2]};
    for (int i = 0; i < span; i++)  /* r = origin + E r_c, E: a 1-D motion along x */
        for (int c = 0; c < 3; c++)
            out[i * 3 + c] = origin[c] + (c < d ? dense[(size_t)i * d + c] : 0.0);
}

/* PredictedReference._diverged: hold the last accepted sample, restart the predictor from it
 * (counts kept) */
static void diverged(refresh_t *s) {
    long long counts[N_COUNTS];
    int d = s->pub.d;  /* the reset forgets it unless settings.dim gives it */
    memcpy(counts, s->pub.counts, sizeof counts);
    predictor_reset(s);
    memcpy(s->pub.counts, counts, sizeof counts);
    s->pub.counts[C_REFERENCE_GUARD]++;
    predictor_update(s, s->held, d);
    s->have_forecast = s->have_second = s->have_before = 0;
    for (int i = 0; i < s->cfg.span; i++)
        memcpy(s->dense + (size_t)i * d, s->held, (size_t)d * sizeof(double));
}

/* PredictedReference.interpolate: the span points of the last predict, interpolated by
 * piecewise-quadratic Lagrange on the nodes z(t_a), z_hat(t_a + dt) ... (s = lead + age/dt,
 * window m = clamp(floor(s), 0, n_nodes - 3), u = s - m), guarded and placed into out
 * ((span, 3) placed, else (span, d)). Returns 1 if points were made, 0 if there was nothing to
 * interpolate, -1 if an array could not grow. */
int refresh_interpolate(refresh_t *s, double *out) {
    if (s->pub.failed) return -1;
    if (!s->points_ready) return 0;
    s->points_ready = 0;
    int d = s->pub.d, K = s->points_k, span = s->cfg.span;
    double now = (double)s->points_tick * s->cfg.Ts, t0;
    const double *nodes = s->points;
    int n_nodes = K;
    if (s->points_z) {  /* nodes z(t_a), then the forecast: held is that z */
        t0 = s->anchor;
        s->pub.age_sum += s->points_latency;
        s->pub.age_count++;
        n_nodes = K + 1;
    } else {
        t0 = s->anchor + s->cfg.dt;
    }
    double shift = cached_age(s, n_nodes, now - t0) / s->cfg.dt, top = (double)(n_nodes - 3);
    double *dense = s->dense;
    const double *held = s->held, *leads = s->lead;
    int off = s->points_z;  /* node k is point k - off (node 0 is z when off = 1) */
    for (int i = 0; i < span; i++) {
        double si = leads[i] + shift, m = floor_exact(si);
        if (m > top) m = top;
        if (!(m >= 0.0)) m = 0.0;  /* also a NaN: the window stays inside the nodes */
        double u = si - m, u2 = u * u;  /* the rows of _LAGRANGE times (u^2, u, 1) */
        double w0 = 0.5 * u2 + -1.5 * u + 1.0, w1 = -1.0 * u2 + 2.0 * u + 0.0,
               w2 = 0.5 * u2 + -0.5 * u + 0.0;
        int j = (int)m;
        const double *r0 = j < off ? held : nodes + (size_t)(j - off) * d,
                     *r1 = nodes + (size_t)(j + 1 - off) * d,
                     *r2 = nodes + (size_t)(j + 2 - off) * d;
        double *o = dense + (size_t)i * d;
        for (int c = 0; c < d; c++) o[c] = w0 * r0[c] + w1 * r1[c] + w2 * r2[c];
    }
    s->pub.first = s->points_tick + 1;
    s->pub.has_points = 1;
    if (s->cfg.guard_speed > 0.0 && s->have_held) {
        double lead = now + span * s->cfg.Ts - s->held_stamp;  /* [s] to the last point */
        double worst = -INFINITY;
        int nan = 0;  /* numpy's argmax picks a NaN, which compares False */
        for (int c = 0; c < d; c++) {  /* an axis at a time: independent maxima */
            double axis = -INFINITY, h = held[c];
            for (int i = 0; i < span; i++) {
                double g = fabs(dense[i * d + c] - h);
                nan |= g != g;
                axis = g > axis ? g : axis;
            }
            worst = axis > worst ? axis : worst;
        }
        if (!nan && worst > s->cfg.guard_margin + s->cfg.guard_speed * lead) diverged(s);
    }
    write_points(s, out);
    return 1;
}

/* PredictedReference.refresh: update, predict and interpolate at once */
int refresh_refresh(refresh_t *s, const double *z, long long tick, double stamp, double *out) {
    if (refresh_update(s, z, tick, stamp) < 0) return -2;
    refresh_predict(s);
    return refresh_interpolate(s, out);
}

/* PredictedReference.place: from now on the points are origin + E r_c, (span, 3); the current
 * ones are placed into out. Returns whether there were points. */
int refresh_place(refresh_t *s, const double *origin, double *out) {
    memcpy(s->origin, origin, 3 * sizeof(double));
    s->pub.placed = 1;
    if (!s->pub.has_points) return 0;
    write_points(s, out);
    return 1;
}

/* Predictor.forecast_error_rms: the pending score first, then the RMS miss per lead (NaN where
 * nothing was scored) into out if it holds K; returns K (0 while d is unknown). */
int refresh_error_rms(refresh_t *s, double *out, int capacity) {
    if (!s->dim_known) return 0;
    predictor_score(s);
    int K = s->ek;
    if (K <= capacity)
        for (int k = 0; k < K; k++) out[k] = s->ecount[k] > 0.0 ? sqrt(s->ms[k]) : NAN;
    return K;
}

/* ---- The slices of a chunk run from the control ticks (sim/loop/ticks.py CompiledTicks):
 * the calls sim/loop/closed_loop.py OpenLoop.segments makes from Python, in the same order, on
 * the same ticks, timed at the same places. ---- */

enum { S_UPDATE, S_LEARN, S_FORECAST, S_INTERPOLATE, S_SCORE, N_SLICES };

typedef struct {
    refresh_t *ref;
    /* the chunk's slices in the order they run (OpenLoop.plan): row = tick - c0 */
    int count, next;
    const int *row, *part;
    const long long *tick;      /* an update's tick (the loop's argument) */
    const double *z;            /* an update's sample, d doubles (a slice's own row) */
    int d;
    const double *stamp;
    const unsigned char *fresh; /* an update has a new sample (else none: NULL is passed) */
    long long *charged;         /* (N_SLICES, m) [ns], added to */
    int error;                  /* 0, or the first failure: an update's code, -1 a forecast's */
    int m;
    long long c0;
    /* the points the ticks read: two arrays (span, 3) taken in turn, or hold before any */
    double *buffer[2];
    int live, has_points;
    const double *hold;         /* (N, 3) */
    /* the points of each refresh on its own tick (OpenLoop.segments' horizons) */
    long long *h_tick;
    double *h_points;           /* (h_cap, N, 3) */
    unsigned char *h_valid;
    int h_count, h_cap;
} plan_t;

static long long plan_clock(void) {
    struct timespec ts;
    clock_gettime(CLOCK_MONOTONIC, &ts);  /* time.perf_counter_ns's clock on Linux */
    return (long long)ts.tv_sec * 1000000000LL + ts.tv_nsec;
}

/* Tick c0 + k's N points (N x 3) in the live array: row k + 1 - first, at most its last. */
static const double *plan_window(const plan_t *p, int k) {
    if (!p->has_points) return p->hold;
    long long last = p->ref->cfg.span - p->ref->cfg.horizon;
    long long row = p->c0 + k + 1 - p->ref->pub.first;
    return p->buffer[p->live] + 3 * (row < last ? row : last);
}

/* One slice; an interpolation's points go to the spare array, which then becomes the live one */
static void plan_slice(plan_t *p, int e, int k) {
    refresh_t *s = p->ref;
    switch (p->part[e]) {
    case S_UPDATE: {
        int code = refresh_update(s, p->fresh[e] ? p->z + (size_t)e * p->d : NULL, p->tick[e],
                                  p->stamp[e]);
        if (code < 0 && !p->error) p->error = code;
        break;
    }
    case S_LEARN: refresh_learn(s); break;
    case S_FORECAST: refresh_predict(s); break;
    case S_SCORE: refresh_score(s); break;
    case S_INTERPOLATE: {
        int made = refresh_interpolate(s, p->buffer[1 - p->live]);
        if (made == 1) {
            p->live = 1 - p->live;
            p->has_points = 1;
        } else if (made < 0 && !p->error) {
            p->error = -1;
        }
        if (p->h_count < p->h_cap) {  /* the refresh's points on its own tick */
            int i = p->h_count++, size = 3 * s->cfg.horizon;
            p->h_tick[i] = p->c0 + k;
            p->h_valid[i] = (unsigned char)p->has_points;
            if (p->has_points)
                memcpy(p->h_points + (size_t)i * size, plan_window(p, k),
                       (size_t)size * sizeof(double));
        }
        break;
    }
    }
}

/* The points of row k after the slices due on it have run, each timed into charged. */
const double *plan_points(plan_t *p, int k) {
    while (p->next < p->count && p->row[p->next] <= k) {
        int e = p->next++;
        long long t0 = plan_clock();
        plan_slice(p, e, k);
        p->charged[(size_t)p->part[e] * p->m + k] += plan_clock() - t0;
    }
    return plan_window(p, k);
}

size_t plan_size(void) { return sizeof(plan_t); }
