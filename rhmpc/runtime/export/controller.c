/*
 * The controller process of a deployment: the exported controller (rhmpc.h) on an absolute
 * clock, fed over UDP in the authenticated wire format of rhmpc_wire.h, and a supervisor that
 * stops the run in the safe state when the host or the tracking fails.
 *
 *   rhmpc_sil_controller --key-file KEY --epoch NS --ticks N --robot-port R --out PREFIX
 *                        (--port P | --socket-fd FD) [--origin X Y Z [--center X Y Z]]
 *                        [--radius M] [--settle S] [--tool-bound M] [--rms-bound M]
 *                        [--miss-rate F] [--robot-timeout S] [--cpu C] [--priority P]
 *                        [--no-internal]
 *   rhmpc_sil_controller --probe --epoch NS --ticks N --out PREFIX [--phase NS] [--cpu C]
 *                        [--priority P]
 *
 * Each tick i wakes at epoch + i Ts (clock_nanosleep, TIMER_ABSTIME) and takes what has
 * arrived. Every datagram is authenticated under the run's key before any field of it is read,
 * then its kind, its bounds and its sequence number are judged (rhmpc_wire.h); what fails is
 * counted under its reason and dropped. The bounds: samples and forecasts within --radius of
 * the registration (--center), joint readings within the export's limits widened by
 * JOINT_MARGIN, stamps between MAX_AGE before the clock and AHEAD after it, a forecast's period
 * RHMPC_DT. A measured_cp feeds rhmpc_refresh (the internal predictor; not with --no-internal),
 * a forecast_cp rhmpc_forecast, a measured_js the step: the reading of tick i is awaited until
 * Ts/5 after the tick began; else the newest reading not yet taken, up to RHMPC_MAX_DELAY ticks
 * old, is fused late (rhmpc_step_delayed: a robot behind a middleware); else the step gets NaN
 * (the observer's hold). The step's torque goes to the robot as servo_jf.
 *
 * The supervisor stops the run (the controller falls silent; the robot's drivers brake to
 * their safe state after their watchdog) and the program exits 3 with the cause on one line of
 * stderr and in PREFIX.json ("stopped") when
 *   - more than --miss-rate (default 20 %) of the ticks of one MISS_WINDOW (one second)
 *     missed their deadline (the torque went out after the next tick began);
 *   - no new reading from the robot for --robot-timeout (default 0.1 s), or more than
 *     --miss-rate of the ticks of one second have no reading of their own that came within
 *     RHMPC_MAX_DELAY ticks;
 *   - after --settle seconds, the tool (forward kinematics of the readings) lies more than
 *     --tool-bound (default 5 mm) from a sample of the POI at that sample's instant, or the
 *     RMS of those distances over one second of samples (or over the last ones, or over the
 *     whole run, judged at its end) exceeds --rms-bound (default 1 mm).
 * SIGINT or SIGTERM ends the loop at the next tick (exit 1: interrupted); the process ends with
 * its parent (PR_SET_PDEATHSIG).
 *
 * Real time where the host permits, and said where it does not (PREFIX.json "realtime"):
 * mlockall, SCHED_FIFO at --priority (default 80), pinned to --cpu, /dev/cpu_dma_latency held
 * at 0 (as cyclictest does: no deep C-state). Nothing in the loop allocates but libcrypto's
 * HMAC, which duplicates a digest context per message. Results go to PREFIX.json and raw int64
 * arrays PREFIX.wake/.work/.step/.s2t [ns] after the loop.
 * --probe: no controller, the same thread and clock only: the host's own wake-up latency.
 */
#define _GNU_SOURCE
#include "rhmpc.h"
#include "rhmpc_wire.h"

#include <arpa/inet.h>
#include <errno.h>
#include <fcntl.h>
#include <math.h>
#include <netinet/in.h>
#include <poll.h>
#include <sched.h>
#include <signal.h>
#include <stdio.h>
#include <stdlib.h>
#include <string.h>
#include <sys/mman.h>
#include <sys/prctl.h>
#include <sys/socket.h>
#include <time.h>
#include <unistd.h>

#define MAX_VALUES (RHMPC_WIRE_MAX_ROWS * 3)
#define MAX_FILL 50 /* the most missing samples one gap of sequence numbers fills */
#define TS_NS ((long long)llround(RHMPC_TS * 1e9))
#define ENCODER_WAIT_NS (TS_NS / 5) /* how long after a tick began its reading may arrive */
#define JOINT_MARGIN 0.1            /* how far beyond its limits a joint reading may lie [rad] */
#define MAX_AGE RHMPC_LATENCY_CAP   /* the oldest stamp taken [s] */
#define AHEAD 2e-3                  /* the latest stamp taken after the clock [s] */
#define MISS_WINDOW 2000            /* ticks over which the deadline misses are counted */
#define TOOL_RING 1024              /* ticks of tool positions kept for the samples' instants */

enum { SERVED_NONE, SERVED_INTERNAL, SERVED_EXTERNAL, SERVED_HOLD, N_SERVED };
static const char *const served_names[N_SERVED] = {"none", "internal", "external", "hold"};

static volatile sig_atomic_t stop_requested = 0;
static void on_signal(int sig) { (void)sig; stop_requested = 1; }

static long long mono_ns(void) {
  struct timespec t;
  clock_gettime(CLOCK_MONOTONIC, &t);
  return (long long)t.tv_sec * 1000000000LL + t.tv_nsec;
}

typedef struct {
  double settle, tool_bound, rms_bound, miss_rate, robot_timeout;
  long long misses[MISS_WINDOW / 100];  /* misses per 100-tick block, a ring */
  long long stale[MISS_WINDOW / 100];   /* ticks without their reading, the same */
  long long stale_run;                  /* ticks in a row without their reading */
  double tool[TOOL_RING][3];            /* the tool after each tick's reading, a ring */
  long long tool_tick[TOOL_RING];
  double block_sum, block_start, error_sum, error_max;
  long long block_n, error_n;
} supervisor_t;

typedef struct {
  long long epoch, ticks, phase, done, wakeups, behind;
  double origin[3], center[3], radius;
  int placed;
  uint64_t last_seq[RHMPC_WIRE_N_KINDS];
  int have_seq[RHMPC_WIRE_N_KINDS];
  long long received[RHMPC_WIRE_N_KINDS], lost[RHMPC_WIRE_N_KINDS];
  long long dropped[RHMPC_WIRE_N_VERDICTS], stale_encoders, late_readings, delay_max, misses;
  long long forecasts_rejected, served[N_SERVED], n_s2t, torques_sent, send_errors;
  int fd, port, robot_port, cpu, priority, internal, probe;
  const char *out, *key_file;
  char realtime[512], stopped[256];
  rhmpc_wire_key_t key;
  supervisor_t sup;
} run_t;

static void note(run_t *r, const char *text) {
  size_t used = strlen(r->realtime);
  snprintf(r->realtime + used, sizeof r->realtime - used, "%s%s", used ? "; " : "", text);
}

/* mlockall, SCHED_FIFO and a pinned core where permitted; each outcome noted */
static void go_realtime(run_t *r) {
  char text[160];
  if (mlockall(MCL_CURRENT | MCL_FUTURE) == 0) note(r, "memory locked (mlockall)");
  else snprintf(text, sizeof text, "memory not locked (mlockall: %s)", strerror(errno)), note(r, text);
  struct sched_param sp = {.sched_priority = r->priority};
  if (sched_setscheduler(0, SCHED_FIFO, &sp) == 0)
    snprintf(text, sizeof text, "SCHED_FIFO priority %d", r->priority);
  else snprintf(text, sizeof text, "SCHED_OTHER (SCHED_FIFO not permitted: %s)", strerror(errno));
  note(r, text);
  if (r->cpu >= 0) {
    cpu_set_t set;
    CPU_ZERO(&set);
    CPU_SET(r->cpu, &set);
    if (sched_setaffinity(0, sizeof set, &set) == 0) snprintf(text, sizeof text, "pinned to CPU %d", r->cpu);
    else snprintf(text, sizeof text, "not pinned (CPU %d: %s)", r->cpu, strerror(errno));
    note(r, text);
  }
  int dma = open("/dev/cpu_dma_latency", O_RDWR); /* no deep C-state while it stays open */
  const int32_t zero = 0;
  if (dma >= 0 && write(dma, &zero, sizeof zero) == (ssize_t)sizeof zero)
    note(r, "/dev/cpu_dma_latency held at 0");
  else if (dma >= 0)
    close(dma);
  volatile unsigned char stack[256 * 1024]; /* fault the stack in before the loop */
  memset((void *)stack, 0, sizeof stack);
}

static int open_socket(int port) {
  int fd = socket(AF_INET, SOCK_DGRAM, 0);
  const int buffer = 1 << 20; /* a burst of foreign datagrams must not push out the run's own */
  struct sockaddr_in a = {0};
  if (fd >= 0 && setsockopt(fd, SOL_SOCKET, SO_RCVBUFFORCE, &buffer, sizeof buffer) != 0)
    setsockopt(fd, SOL_SOCKET, SO_RCVBUF, &buffer, sizeof buffer); /* up to rmem_max */
  a.sin_family = AF_INET;
  a.sin_port = htons((uint16_t)port);
  a.sin_addr.s_addr = htonl(INADDR_LOOPBACK);
  if (fd < 0 || bind(fd, (struct sockaddr *)&a, sizeof a) != 0) return -1;
  return fd;
}

static rhmpc_t ctl;
static unsigned char buf[RHMPC_WIRE_HEADER + 8 * MAX_VALUES + RHMPC_WIRE_MAC];
static double values[MAX_VALUES], q[RHMPC_NU], tau[RHMPC_NU];

static void stop_run(run_t *r, const char *why) {
  if (r->stopped[0] == '\0') snprintf(r->stopped, sizeof r->stopped, "%s", why);
}

/* ---- the bounds of what is taken ---------------------------------------------------------- */

static int in_window(double t, double now) { return t >= now - MAX_AGE && t <= now + AHEAD; }

/* every finite row within the radius of the registration; a row of NaN passes if allowed */
static int near(const run_t *r, const double *rows, int n, int allow_missing) {
  for (int i = 0; i < n; i++) {
    const double *p = rows + 3 * i;
    if (allow_missing && isnan(p[0]) && isnan(p[1]) && isnan(p[2])) continue;
    double d2 = 0.0;
    for (int c = 0; c < 3; c++) d2 += (p[c] - r->center[c]) * (p[c] - r->center[c]);
    if (!(d2 <= r->radius * r->radius)) return 0; /* NaN or infinite fails */
  }
  return 1;
}

static int plausible(const run_t *r, const rhmpc_wire_t *m, double now) {
  if (!in_window(m->stamp, now) || !in_window(m->sent, now)) return 0;
  if (m->kind == RHMPC_MEASURED_CP) return near(r, values, 1, 1); /* the POI: the others unused */
  if (m->kind == RHMPC_FORECAST_CP)
    return fabs(m->period - RHMPC_DT) <= 1e-9 && near(r, values, m->rows, 0);
  for (int j = 0; j < RHMPC_NU; j++) /* measured_js */
    if (!(values[j] >= rhmpc_q_min[j] - JOINT_MARGIN && values[j] <= rhmpc_q_max[j] + JOINT_MARGIN))
      return 0;
  return 1;
}

/* One datagram: authenticated, of a kind taken here, plausible and in order; else counted. */
static int take(run_t *r, long long len, rhmpc_wire_t *m, long long *lost) {
  int verdict = rhmpc_wire_unseal(&r->key, buf, len, RHMPC_NU, m, values, MAX_VALUES);
  if (verdict == RHMPC_WIRE_TAKEN && m->kind == RHMPC_SERVO_JF) verdict = RHMPC_DROP_UNEXPECTED;
  if (verdict == RHMPC_WIRE_TAKEN && !plausible(r, m, (mono_ns() - r->epoch) * 1e-9))
    verdict = RHMPC_DROP_IMPLAUSIBLE;
  if (verdict == RHMPC_WIRE_TAKEN)
    verdict = rhmpc_wire_order(&r->last_seq[m->kind], &r->have_seq[m->kind], m->seq, lost);
  if (verdict != RHMPC_WIRE_TAKEN) {
    r->dropped[verdict]++;
    return 0;
  }
  r->received[m->kind]++;
  r->lost[m->kind] += *lost;
  return 1;
}

/* ---- the supervisor ----------------------------------------------------------------------- */

/* The tool's distance from a sample of the POI (z, in the tracker's frame) at its instant. */
static void judge_sample(run_t *r, double stamp, const double *z) {
  supervisor_t *s = &r->sup;
  long long k = llround(stamp / RHMPC_TS);
  if (stamp < s->settle || k < 0 || s->tool_tick[k % TOOL_RING] != k) return;
  double e2 = 0.0, text_mm;
  for (int c = 0; c < 3; c++) {
    double poi = r->origin[c] + z[c] - r->center[c];
    e2 += (s->tool[k % TOOL_RING][c] - poi) * (s->tool[k % TOOL_RING][c] - poi);
  }
  char why[256];
  text_mm = sqrt(e2) * 1e3;
  s->error_sum += e2, s->error_n++;
  s->error_max = text_mm > s->error_max ? text_mm : s->error_max;
  if (sqrt(e2) > s->tool_bound) {
    snprintf(why, sizeof why, "the tool left its %g-mm bound around the POI: %.2f mm at %.3f s",
             s->tool_bound * 1e3, text_mm, stamp);
    stop_run(r, why);
  }
  if (stamp - s->block_start >= 1.0) { /* a second of samples: its RMS */
    if (s->block_n > 0 && sqrt(s->block_sum / s->block_n) > s->rms_bound) {
      snprintf(why, sizeof why, "the tool's RMS distance from the POI over %.3f-%.3f s is "
               "%.2f mm, above its %g-mm bound", s->block_start, stamp,
               sqrt(s->block_sum / s->block_n) * 1e3, s->rms_bound * 1e3);
      stop_run(r, why);
    }
    s->block_start = stamp, s->block_sum = 0.0, s->block_n = 0;
  }
  s->block_sum += e2, s->block_n++;
}

/* The tool after a tick's reading, for the samples of that instant. */
static void keep_tool(run_t *r, long long tick, const double *reading) {
  supervisor_t *s = &r->sup;
  rhmpc_tool_position(reading, s->tool[tick % TOOL_RING]);
  s->tool_tick[tick % TOOL_RING] = tick;
}

/* The share of events (misses, ticks without their reading) over the last MISS_WINDOW
 * ticks, in 100-tick blocks of a ring: the sum once a block is complete, else -1. */
static long long window_share(long long *blocks, long long tick, int event) {
  const int n = MISS_WINDOW / 100;
  if (tick % 100 == 0) blocks[(tick / 100) % n] = 0;
  blocks[(tick / 100) % n] += event;
  if (tick + 1 < MISS_WINDOW || (tick + 1) % 100 != 0) return -1;
  long long sum = 0;
  for (int b = 0; b < n; b++) sum += blocks[b];
  return sum;
}

/* A tick's deadline: too many missed in the last second stop the run. */
static void judge_deadline(run_t *r, long long tick, int missed) {
  supervisor_t *s = &r->sup;
  r->misses += missed;
  long long sum = window_share(s->misses, tick, missed);
  if (sum > s->miss_rate * MISS_WINDOW) {
    char why[256];
    snprintf(why, sizeof why, "%lld of the last %d ticks missed their deadline (%.1f %%, above "
             "%g %%): this host does not run the controller in time", sum, MISS_WINDOW,
             100.0 * sum / MISS_WINDOW, 100.0 * s->miss_rate);
    stop_run(r, why);
  }
}

/* A tick's reading: no new one for --robot-timeout in a row, or too many ticks of the last
 * second whose own reading did not come (judged RHMPC_MAX_DELAY ticks on, when it can no longer
 * be fused), stop the run (the tool cannot be judged blind). */
static void judge_readings(run_t *r, long long tick, int fresh) {
  supervisor_t *s = &r->sup;
  char why[256];
  const long long own = tick - RHMPC_MAX_DELAY; /* the reading of tick `own` came, or never will */
  s->stale_run = fresh ? 0 : s->stale_run + 1;
  if (own < 0) return;
  long long sum = window_share(s->stale, own, s->tool_tick[own % TOOL_RING] != own);
  if (s->stale_run * RHMPC_TS >= s->robot_timeout && tick * RHMPC_TS >= s->robot_timeout) {
    snprintf(why, sizeof why, "no reading from the robot for %g ms (its drivers, its host or "
             "its link failed)", s->robot_timeout * 1e3);
    stop_run(r, why);
  } else if (sum > s->miss_rate * MISS_WINDOW) {
    snprintf(why, sizeof why, "%lld of the last %d ticks had no reading of their own (%.1f %%, "
             "above %g %%): the robot's side does not keep the clock", sum, MISS_WINDOW,
             100.0 * sum / MISS_WINDOW, 100.0 * s->miss_rate);
    stop_run(r, why);
  }
}

/* ---- the loop ----------------------------------------------------------------------------- */

/* Everything that arrived: samples, forecasts and the encoders' latest reading */
static void take_arrivals(run_t *r, long long tick, long long *q_tick, int *source, double *origin) {
  rhmpc_wire_t m;
  ssize_t len;
  long long lost = 0;
  while ((len = recv(r->fd, buf, sizeof buf, MSG_DONTWAIT)) > 0) {
    if (!take(r, len, &m, &lost)) continue;
    if (m.kind == RHMPC_MEASURED_JS) {
      memcpy(q, values, sizeof q);
      *q_tick = llround(m.stamp / RHMPC_TS);
      keep_tool(r, *q_tick, q);
    } else if (m.kind == RHMPC_MEASURED_CP) {
      const int tracked = !isnan(values[0]);
      if (tracked) judge_sample(r, m.stamp, values);
      if (!r->internal) continue;
      long long first = ctl.pub.first;
      for (long long i = 0; i < (lost < MAX_FILL ? lost : MAX_FILL); i++)
        rhmpc_refresh(&ctl, tick, m.stamp, NULL); /* lost samples are missing */
      rhmpc_refresh(&ctl, tick, m.stamp, tracked ? values : NULL);
      if (ctl.pub.first != first) *source = SERVED_INTERNAL, *origin = m.origin;
    } else if (rhmpc_forecast(&ctl, tick, m.stamp, values, m.rows) != 0) {
      r->forecasts_rejected++;
    } else {
      *source = SERVED_EXTERNAL, *origin = m.origin;
    }
  }
}

static void send_torque(run_t *r, long long tick) {
  struct sockaddr_in to = {0};
  rhmpc_wire_t m = {RHMPC_SERVO_JF, (uint64_t)r->torques_sent, tick * RHMPC_TS, NAN, 0.0, 0.0,
                    1, RHMPC_NU};
  to.sin_family = AF_INET;
  to.sin_port = htons((uint16_t)r->robot_port);
  to.sin_addr.s_addr = htonl(INADDR_LOOPBACK);
  m.sent = (mono_ns() - r->epoch) * 1e-9;
  int len = rhmpc_wire_seal(&r->key, &m, tau, buf, sizeof buf);
  if (len < 0 || sendto(r->fd, buf, (size_t)len, 0, (struct sockaddr *)&to, sizeof to) != len)
    r->send_errors++;
  r->torques_sent++;
}

/* Sleep until the tick's start; its wake-up latency, as cyclictest measures it. */
static long long wake_up(run_t *r, long long next, long long *wake) {
  struct timespec at = {next / 1000000000LL, next % 1000000000LL};
  long long now = mono_ns();
  if (now < next) {
    while (clock_nanosleep(CLOCK_MONOTONIC, TIMER_ABSTIME, &at, NULL) == EINTR && !stop_requested) {}
    now = mono_ns();
    wake[r->wakeups++] = now - next;
  } else { /* the last tick ended after this one's start: no sleep, a tick behind */
    r->behind += 1;
  }
  return now;
}

/* The run's end: the last second's samples, and the whole run's RMS, against the RMS bound. */
static void judge_end(run_t *r) {
  supervisor_t *s = &r->sup;
  char why[256];
  if (s->block_n >= 5 && sqrt(s->block_sum / s->block_n) > s->rms_bound) {
    snprintf(why, sizeof why, "the tool's RMS distance from the POI over its last %lld samples "
             "is %.2f mm, above its %g-mm bound", s->block_n,
             sqrt(s->block_sum / s->block_n) * 1e3, s->rms_bound * 1e3);
    stop_run(r, why);
  }
  if (s->error_n > 0 && sqrt(s->error_sum / s->error_n) > s->rms_bound) {
    snprintf(why, sizeof why, "the tool's RMS distance from the POI over the run is %.2f mm, "
             "above its %g-mm bound", sqrt(s->error_sum / s->error_n) * 1e3, s->rms_bound * 1e3);
    stop_run(r, why);
  }
}

static void run_loop(run_t *r, long long *wake, long long *work, long long *step, long long *s2t) {
  long long q_tick = -1; /* the newest reading's tick */
  int source = SERVED_NONE;
  for (long long tick = 0; tick < r->ticks && !stop_requested && !r->stopped[0]; tick++) {
    long long next = r->epoch + tick * TS_NS + r->phase, now = wake_up(r, next, wake);
    double origin = NAN; /* when the sample behind this tick's new points left the sensor */
    r->done = tick + 1;
    if (r->probe) continue;
    take_arrivals(r, tick, &q_tick, &source, &origin);
    while (q_tick != tick) { /* the reading of this tick may still be on its way */
      long long left = now + ENCODER_WAIT_NS - mono_ns(); /* from the tick's start */
      struct pollfd p = {r->fd, POLLIN, 0};
      struct timespec wait = {0, left > 0 ? left : 0};
      if (left <= 0 || ppoll(&p, 1, &wait, NULL) <= 0) break;
      take_arrivals(r, tick, &q_tick, &source, &origin);
    }
    long long delay = tick - q_tick, taken = ctl.pub.fused;
    rhmpc_step_delayed(&ctl, tick, delay, q, tau); /* the newest reading: taken, or the hold */
    const int fresh = ctl.pub.fused > taken;
    if (!fresh)
      r->stale_encoders++;
    else if (delay > 0) {
      r->late_readings++;
      r->delay_max = delay > r->delay_max ? delay : r->delay_max;
    }
    judge_readings(r, tick, fresh);
    step[tick] = ctl.pub.step_ns;
    if (r->stopped[0]) break; /* the supervisor stopped the run: no torque goes out */
    send_torque(r, tick);
    long long sent = mono_ns();
    if (isfinite(origin)) s2t[r->n_s2t++] = sent - r->epoch - llround(origin * 1e9);
    work[tick] = sent - now;
    judge_deadline(r, tick, sent > next + TS_NS); /* its torque went out after the next tick began */
    int held = source != SERVED_NONE && tick + 1 - ctl.pub.first > RHMPC_REFRESH_TICKS;
    r->served[held ? SERVED_HOLD : source]++;
  }
}

/* ---- results and arguments ---------------------------------------------------------------- */

static void write_array(const char *prefix, const char *ext, const long long *a, long long n) {
  char path[4096];
  snprintf(path, sizeof path, "%s.%s", prefix, ext);
  FILE *f = fopen(path, "wb");
  if (f != NULL) {
    fwrite(a, sizeof *a, (size_t)n, f);
    fclose(f);
  }
}

#define KEY(k) rhmpc_report_keys[RHMPC_REPORT_##k]

static void write_per_kind(FILE *f, const char *key, const long long *count) {
  fprintf(f, ", \"%s\": {", key);
  for (int k = 1, first = 1; k < RHMPC_WIRE_N_KINDS; k++)
    if (k != RHMPC_SERVO_JF) fprintf(f, "%s\"%s\": %lld", first ? "" : ", ", rhmpc_wire_kind_names[k], count[k]), first = 0;
  fprintf(f, "}");
}

static void write_results(const run_t *r) {
  char path[4096];
  snprintf(path, sizeof path, "%s.json", r->out);
  FILE *f = fopen(path, "w");
  if (f == NULL) return;
  const supervisor_t *s = &r->sup;
  fprintf(f, "{\"%s\": %lld, \"%s\": %lld, \"%s\": %lld, \"%s\": \"%s\", \"%s\": %lld, "
             "\"%s\": %lld, \"%s\": %lld, \"%s\": %lld, \"%s\": %lld, \"%s\": %d, "
             "\"%s\": \"%s\", \"%s\": %d",
          KEY(TICKS), r->done, KEY(DEADLINE_MISSES), r->misses, KEY(TICKS_BEHIND), r->behind,
          KEY(REALTIME), r->realtime, KEY(STALE_ENCODERS), r->stale_encoders,
          KEY(LATE_READINGS), r->late_readings, KEY(DELAY_MAX), r->delay_max,
          KEY(FORECASTS_REJECTED), r->forecasts_rejected, KEY(SEND_ERRORS), r->send_errors,
          KEY(INTERRUPTED), (int)stop_requested, KEY(STOPPED), r->stopped, KEY(PROBE), r->probe);
  write_per_kind(f, KEY(RECEIVED), r->received);
  write_per_kind(f, KEY(LOST), r->lost);
  fprintf(f, ", \"%s\": {", KEY(DROPPED));
  for (int v = 1; v < RHMPC_WIRE_N_VERDICTS; v++)
    fprintf(f, "%s\"%s\": %lld", v > 1 ? ", " : "", rhmpc_wire_verdict_names[v], r->dropped[v]);
  fprintf(f, "}, \"%s\": {", KEY(SERVED));
  for (int c = 0; c < N_SERVED; c++) fprintf(f, "%s\"%s\": %lld", c ? ", " : "", served_names[c], r->served[c]);
  fprintf(f, "}, \"%s\": {", KEY(COUNTS));
  for (int c = 0; c < RHMPC_N_COUNTS; c++)
    fprintf(f, "%s\"%s\": %lld", c ? ", " : "", rhmpc_count_name(c), ctl.pub.counts[c]);
  fprintf(f, "}, \"%s\": {", KEY(FALLBACKS));
  for (int c = 1; c < RHMPC_N_SOURCES; c++)
    fprintf(f, "%s\"%s\": %lld", c > 1 ? ", " : "", rhmpc_source_name(c), ctl.pub.fallbacks[c]);
  fprintf(f, "}, \"%s\": {", KEY(FAILURES));
  for (int c = 1, first = 1; c < RHMPC_N_STATUS; c++)
    if (ctl.pub.failures[c]) {
      fprintf(f, "%s\"%s\": %lld", first ? "" : ", ", rhmpc_status_name(c), ctl.pub.failures[c]);
      first = 0;
    }
  fprintf(f, "}, \"%s\": %lld, \"%s\": {\"rms\": %.6g, \"max\": %.6g, \"samples\": %lld}, "
             "\"%s\": %lld}\n", KEY(ENCODER_HELD), ctl.pub.encoder_held, KEY(TOOL_ERROR_MM),
          s->error_n ? sqrt(s->error_sum / s->error_n) * 1e3 : 0.0, s->error_max, s->error_n,
          KEY(N_S2T), r->n_s2t);
  fclose(f);
}

static void fail(const char *text, const char *what) {
  fprintf(stderr, "rhmpc_sil_controller: %s%s\n", text, what);
  exit(2);
}

static long long integer(const char *text, const char *what) {
  char *end = NULL;
  errno = 0;
  long long v = strtoll(text, &end, 10);
  if (end == text || *end != '\0' || errno) fail("an integer must follow ", what);
  return v;
}

static double real(const char *text, const char *what) {
  char *end = NULL;
  double v = strtod(text, &end);
  if (end == text || *end != '\0' || !isfinite(v)) fail("a finite number must follow ", what);
  return v;
}

static void parse(run_t *r, int argc, char **argv) {
  for (int i = 1; i < argc; i++) {
    const char *a = argv[i], *v = i + 1 < argc ? argv[i + 1] : "";
    if (!strcmp(a, "--no-internal")) r->internal = 0;
    else if (!strcmp(a, "--probe")) r->probe = 1;
    else if (!strcmp(a, "--epoch")) r->epoch = integer(v, a), i++;
    else if (!strcmp(a, "--ticks")) r->ticks = integer(v, a), i++;
    else if (!strcmp(a, "--phase")) r->phase = integer(v, a), i++;
    else if (!strcmp(a, "--port")) r->port = (int)integer(v, a), i++;
    else if (!strcmp(a, "--socket-fd")) r->fd = (int)integer(v, a), i++;
    else if (!strcmp(a, "--robot-port")) r->robot_port = (int)integer(v, a), i++;
    else if (!strcmp(a, "--cpu")) r->cpu = (int)integer(v, a), i++;
    else if (!strcmp(a, "--priority")) r->priority = (int)integer(v, a), i++;
    else if (!strcmp(a, "--radius")) r->radius = real(v, a), i++;
    else if (!strcmp(a, "--settle")) r->sup.settle = real(v, a), i++;
    else if (!strcmp(a, "--tool-bound")) r->sup.tool_bound = real(v, a), i++;
    else if (!strcmp(a, "--rms-bound")) r->sup.rms_bound = real(v, a), i++;
    else if (!strcmp(a, "--miss-rate")) r->sup.miss_rate = real(v, a), i++;
    else if (!strcmp(a, "--robot-timeout")) r->sup.robot_timeout = real(v, a), i++;
    else if (!strcmp(a, "--out")) r->out = v, i++;
    else if (!strcmp(a, "--key-file")) r->key_file = v, i++;
    else if ((!strcmp(a, "--origin") || !strcmp(a, "--center")) && i + 3 < argc) {
      /* where the motion sits [m]: the sensor's point --center at --origin (rhmpc_place) */
      double *to = a[2] == 'o' ? r->origin : r->center;
      for (int c = 0; c < 3; c++) to[c] = real(argv[i + 1 + c], a);
      r->placed |= a[2] == 'o', i += 3;
    } else fail("unknown option ", a);
  }
  if (r->epoch < 0 || r->ticks < 0 || r->ticks > 1000000000LL || r->out == NULL)
    fail("needs --epoch, --ticks and --out", "");
  if (!r->probe && (r->key_file == NULL || r->robot_port <= 0 || r->robot_port > 65535 ||
                    (r->port <= 0 && r->fd < 0)))
    fail("needs --key-file, --robot-port and --port or --socket-fd (unless --probe)", "");
  if (!(r->radius > 0 && r->sup.tool_bound > 0 && r->sup.rms_bound > 0 && r->sup.miss_rate > 0 &&
        r->sup.robot_timeout > 0))
    fail("--radius, --tool-bound, --rms-bound, --miss-rate and --robot-timeout must be > 0", "");
}

int main(int argc, char **argv) {
  static run_t r;
  r.cpu = -1, r.priority = 80, r.internal = 1, r.epoch = -1, r.ticks = -1, r.fd = -1;
  r.radius = 0.05, r.sup.settle = 2.0, r.sup.tool_bound = 5e-3, r.sup.rms_bound = 1e-3;
  r.sup.miss_rate = 0.2, r.sup.robot_timeout = 0.1;
  for (int k = 0; k < TOOL_RING; k++) r.sup.tool_tick[k] = -1;
  parse(&r, argc, argv);
  if (!rhmpc_wire_little_endian()) fail("the wire format needs a little-endian host", "");
  prctl(PR_SET_PDEATHSIG, SIGTERM);
  signal(SIGINT, on_signal);
  signal(SIGTERM, on_signal);
  char why[512];
  if (!r.probe && rhmpc_wire_key_read(&r.key, r.key_file, why, sizeof why) != 0) fail(why, "");
  if (!r.probe && r.fd < 0 && (r.fd = open_socket(r.port)) < 0) {
    snprintf(why, sizeof why, "cannot bind UDP port %d on 127.0.0.1: %s", r.port, strerror(errno));
    fail(why, "");
  }
  long long *wake = calloc((size_t)r.ticks + 1, sizeof *wake), *work = calloc((size_t)r.ticks + 1, sizeof *work);
  long long *step = calloc((size_t)r.ticks + 1, sizeof *step), *s2t = calloc((size_t)r.ticks + 1, sizeof *s2t);
  if (wake == NULL || work == NULL || step == NULL || s2t == NULL) fail("out of memory", "");
  rhmpc_init(&ctl);
  if (r.placed) rhmpc_place(&ctl, r.origin, r.center);
  go_realtime(&r);
  run_loop(&r, wake, work, step, s2t);
  if (!r.probe && !stop_requested) judge_end(&r);
  write_array(r.out, "wake", wake, r.wakeups);
  write_array(r.out, "work", work, r.done);
  write_array(r.out, "step", step, r.done);
  write_array(r.out, "s2t", s2t, r.n_s2t);
  write_results(&r);
  if (r.stopped[0]) {
    fprintf(stderr, "rhmpc_sil_controller: stopped in the safe state: %s\n", r.stopped);
    return 3;
  }
  return stop_requested ? 1 : 0;
}
