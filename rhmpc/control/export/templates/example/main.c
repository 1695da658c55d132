/*
 * A fixed-rate loop around the generated controller (robot "@ROBOT@"): a fake sensor, a toy
 * plant, and the two calls of rhmpc.h.
 *
 *   ./rhmpc_example [seconds]      (default 2; 0 runs 2 s as fast as it can, without pacing;
 *                                   at most RHMPC_EXAMPLE_MAX_S)
 *
 * The fake sensor samples a heart-like motion (a beat of 1.2 Hz, 8 mm peak to peak in x) every
 * RHMPC_DT seconds and delivers each sample one tick after it was taken. The toy plant is the
 * controller's own linear model of the arm driven by the MPC's torque (ctl.pub.u): a real arm
 * receives tau, whose part beyond u cancels its gravity, Coriolis and friction. Replace both
 * with your sensor's and your robot's drivers; keep the loop. It prints the tool's tracking
 * error (the toy plant's tool y = C x + y0 against the motion, over the run's second half).
 */
#include "rhmpc.h"
#include "rhmpc_data.h" /* rhmpc_predict: the toy plant's model (not needed with a real arm) */

#include <math.h>
#include <stdio.h>
#include <stdlib.h>
#include <time.h>

#define PI 3.14159265358979323846
#define RHMPC_EXAMPLE_MAX_S 86400.0 /* the longest run it takes [s]: a day */

/* The point of interest [m], centred on its mean: what the fake sensor measures at time t. */
static void heart(double t, double z[RHMPC_D]) {
  double beat = 2 * PI * 1.2 * t;
  z[0] = 4e-3 * sin(beat) + 1e-3 * sin(2 * beat + 0.4);
  z[1] = 2e-3 * sin(beat + 1.0);
  z[2] = 1.5e-3 * sin(2 * PI * 0.25 * t);
}

/* The toy plant: x+ = A x + B u with [A, B, 0] = rhmpc_predict; returns the joint angles. */
static void plant(double x[RHMPC_NX], const double u[RHMPC_NU], double q[RHMPC_NU]) {
  double next[RHMPC_NX];
  const int cols = RHMPC_NX + RHMPC_NU + 1;
  for (int r = 0; r < RHMPC_NX; r++) {
    double s = 0.0;
    for (int k = 0; k < RHMPC_NX; k++) s += rhmpc_predict[r * cols + k] * x[k];
    for (int k = 0; k < RHMPC_NU; k++) s += rhmpc_predict[r * cols + RHMPC_NX + k] * u[k];
    next[r] = s;
  }
  for (int r = 0; r < RHMPC_NX; r++) x[r] = next[r];
  for (int j = 0; j < RHMPC_NU; j++) q[j] = rhmpc_q0[j] + x[j];
}

static void advance(struct timespec *t, long ns) {
  t->tv_nsec += ns;
  while (t->tv_nsec >= 1000000000L) {
    t->tv_nsec -= 1000000000L;
    t->tv_sec += 1;
  }
}

int main(int argc, char **argv) {
  static rhmpc_t ctl; /* static: no heap, no large stack frame */
  char *end = NULL;
  const double seconds = argc > 1 ? strtod(argv[1], &end) : 2.0;
  if (argc > 2 || (argc > 1 && (end == argv[1] || *end != '\0')) || !isfinite(seconds) ||
      seconds < 0.0 || seconds > RHMPC_EXAMPLE_MAX_S) {
    fprintf(stderr, "usage: %s [seconds]: a duration from 0 to %g s (0: 2 s unpaced), got %s\n",
            argv[0], RHMPC_EXAMPLE_MAX_S, argc > 1 ? argv[1] : "");
    return 2;
  }
  const long long ticks = (long long)llround((seconds > 0 ? seconds : 2.0) / RHMPC_TS);
  const long long every = (long long)llround(RHMPC_DT / RHMPC_TS); /* ticks per sample */
  double x[RHMPC_NX] = {0}, q[RHMPC_NU], tau[RHMPC_NU], z[RHMPC_D], truth[RHMPC_D];
  double miss2 = 0.0, worst_ns = 0.0;
  long long scored = 0;
  struct timespec next;

  rhmpc_init(&ctl);
  const double center[3] = {0.0, 0.0, 0.0}; /* the heart's mean in the sensor's frame */
  rhmpc_place(&ctl, rhmpc_y0, center);       /* … at the tool's home position */
  for (int j = 0; j < RHMPC_NU; j++) q[j] = rhmpc_q0[j];
  clock_gettime(CLOCK_MONOTONIC, &next);
  for (long long tick = 0; tick < ticks; tick++) {
    if (tick % every == 1) { /* a sample taken one tick ago arrives */
      double stamp = (tick - 1) * RHMPC_TS;
      heart(stamp, z);
      rhmpc_refresh(&ctl, tick, stamp, z);
    }
    rhmpc_step(&ctl, tick, q, tau); /* tau goes to the motors */
    plant(x, ctl.pub.u, q);
    if (ctl.pub.step_ns + ctl.pub.refresh_ns > worst_ns && tick > 100)
      worst_ns = (double)(ctl.pub.step_ns + ctl.pub.refresh_ns);
    if (2 * tick >= ticks) { /* the tool after the tick against the motion then */
      heart((tick + 1) * RHMPC_TS, truth);
      for (int c = 0; c < RHMPC_NY; c++) {
        double miss = -truth[c];
        for (int k = 0; k < RHMPC_NX; k++) miss += rhmpc_output[c * RHMPC_NX + k] * x[k];
        miss2 += miss * miss;
      }
      scored++;
    }
    if (seconds > 0) { /* a fixed rate: wake at the next tick's start */
      advance(&next, (long)llround(RHMPC_TS * 1e9));
      clock_nanosleep(CLOCK_MONOTONIC, TIMER_ABSTIME, &next, NULL);
    }
  }
  printf("rhmpc_example: %lld ticks of %g ms, %lld refreshes; tool's tracking error RMS %.4f mm; "
         "longest tick %.1f us; QP fallbacks %lld; status %s\n",
         ticks, 1e3 * RHMPC_TS, ctl.pub.counts[RHMPC_UPDATES],
         1e3 * sqrt(miss2 / (scored > 0 ? scored : 1)), worst_ns / 1e3,
         ctl.pub.fallbacks[RHMPC_SOURCE_PLAN] + ctl.pub.fallbacks[RHMPC_SOURCE_LQ] +
             ctl.pub.fallbacks[RHMPC_SOURCE_BRAKE] + ctl.pub.fallbacks[RHMPC_SOURCE_ZERO],
         rhmpc_status_name(ctl.pub.status));
  return ctl.pub.counts[RHMPC_UPDATES] > 0 ? 0 : 1;
}
