/*
 * The controller process of a deployment: the exported controller (rhmpc.h) on an absolute
 * 2-kHz clock, fed over UDP in the wire format of rhmpc_wire.h.
 *
 *   rhmpc_sil_controller --epoch NS --ticks N --port P --robot-port R --out PREFIX
 *                        [--origin X Y Z [--center X Y Z]] [--cpu C] [--priority P] [--no-internal] [--probe]
 *                        [--phase NS]
 *
 * Each tick i wakes at epoch + i Ts (clock_nanosleep, TIMER_ABSTIME), takes what has arrived
 * (measured_cp: rhmpc_refresh, the internal predictor; forecast_cp: rhmpc_forecast; measured_js:
 * the encoders, whose reading of tick i it awaits until Ts/5 after it began), steps the controller
 * and sends servo_jf to the robot. An encoder reading that is not this tick's is stale: the step gets NaN, the observer's fault path (it predicts, and brakes
 * after its timeout). A lost measured_cp is a missing sample (the predictor runs open-loop); a
 * late one (reordered) is dropped. --no-internal: samples are not given to the internal
 * predictor, so a lost forecast holds the last points.
 * --probe: no controller, the same thread and clock only: the host's own wake-up latency.
 *
 * Real time where the host permits, and said where it does not (PREFIX.json "realtime"):
 * mlockall, SCHED_FIFO at --priority (default 80), pinned to --cpu, /dev/cpu_dma_latency held
 * at 0 (as cyclictest does: no deep C-state). Nothing in the loop
 * allocates; results go to PREFIX.json and raw int64 arrays PREFIX.wake/.work/.step/.s2t [ns]
 * after the loop. SIGINT or SIGTERM ends the loop at the next tick; the process ends with its
 * parent (PR_SET_PDEATHSIG).
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

#define MAX_VALUES 4096
#define MAX_FILL 50 /* the most missing samples one gap of sequence numbers fills */
#define TS_NS ((long long)llround(RHMPC_TS * 1e9))
#define ENCODER_WAIT_NS (TS_NS / 5) /* how long after a tick began its reading may arrive */

enum { SERVED_NONE, SERVED_INTERNAL, SERVED_EXTERNAL, SERVED_HOLD, N_SERVED };
static const char *const served_names[N_SERVED] = {"none", "internal", "external", "hold"};
enum { K_CP, K_FC, K_JS, N_KINDS };
static const char *const kind_names[N_KINDS] = {"measured_cp", "forecast_cp", "measured_js"};

static volatile sig_atomic_t stop_requested = 0;
static void on_signal(int sig) { (void)sig; stop_requested = 1; }

static long long mono_ns(void) {
  struct timespec t;
  clock_gettime(CLOCK_MONOTONIC, &t);
  return (long long)t.tv_sec * 1000000000LL + t.tv_nsec;
}

typedef struct {
  long long epoch, ticks, phase, done, wakeups, behind, last_seq[N_KINDS];
  double origin[3], center[3];
  int placed;
  long long received[N_KINDS], lost[N_KINDS], late[N_KINDS], bad, stale_encoders, misses;
  long long forecasts_rejected, served[N_SERVED], n_s2t, torques_sent, send_errors;
  int port, robot_port, cpu, priority, internal, probe;
  const char *out;
  char realtime[512];
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
  struct sockaddr_in a = {0};
  a.sin_family = AF_INET;
  a.sin_port = htons((uint16_t)port);
  a.sin_addr.s_addr = htonl(INADDR_LOOPBACK);
  if (fd < 0 || bind(fd, (struct sockaddr *)&a, sizeof a) != 0) return -1;
  return fd;
}

static rhmpc_t ctl;
static unsigned char buf[RHMPC_WIRE_HEADER + 8 * MAX_VALUES];
static double values[MAX_VALUES], q[RHMPC_NU], tau[RHMPC_NU];

/* Everything that arrived: samples, forecasts and the encoders' latest reading */
static void take_arrivals(run_t *r, int fd, long long tick, long long *q_tick, int *source,
                          double *origin) {
  rhmpc_wire_t m;
  ssize_t len;
  while ((len = recv(fd, buf, sizeof buf, MSG_DONTWAIT)) > 0) {
    if (rhmpc_wire_decode(buf, (int)len, &m, values, MAX_VALUES) != 0 || m.kind > RHMPC_MEASURED_JS) {
      r->bad++;
      continue;
    }
    int k = m.kind - 1;
    r->received[k]++;
    long long lost = rhmpc_wire_take(&r->last_seq[k], m.seq);
    if (lost < 0) { /* reordered or duplicated: stale, dropped (a sample: already missing) */
      r->late[k]++;
      continue;
    }
    r->lost[k] += lost;
    if (k == K_JS) {
      if (m.rows >= 1 && m.width == RHMPC_NU) {
        memcpy(q, values, sizeof q);
        *q_tick = llround(m.stamp / RHMPC_TS);
      } else r->bad++;
    } else if (k == K_CP && r->internal) {
      long long first = ctl.pub.first;
      for (long long i = 0; i < (lost < MAX_FILL ? lost : MAX_FILL); i++)
        rhmpc_refresh(&ctl, tick, m.stamp, NULL); /* lost samples are missing */
      rhmpc_refresh(&ctl, tick, m.stamp, m.rows >= 1 && m.width == RHMPC_D ? values : NULL);
      if (ctl.pub.first != first) *source = SERVED_INTERNAL, *origin = m.origin;
    } else if (k == K_FC) {
      if (fabs(m.period - RHMPC_DT) > 1e-9 || m.width != RHMPC_D ||
          rhmpc_forecast(&ctl, tick, m.stamp, values, m.rows) != 0)
        r->forecasts_rejected++;
      else
        *source = SERVED_EXTERNAL, *origin = m.origin;
    }
  }
}

static void send_torque(run_t *r, int fd, long long tick) {
  struct sockaddr_in to = {0};
  rhmpc_wire_t m = {RHMPC_SERVO_JF, (uint32_t)r->torques_sent, tick * RHMPC_TS, NAN, 0.0, 0.0,
                    1, RHMPC_NU};
  to.sin_family = AF_INET;
  to.sin_port = htons((uint16_t)r->robot_port);
  to.sin_addr.s_addr = htonl(INADDR_LOOPBACK);
  m.sent = (mono_ns() - r->epoch) * 1e-9;
  int len = rhmpc_wire_encode(&m, tau, buf, sizeof buf);
  if (sendto(fd, buf, (size_t)len, 0, (struct sockaddr *)&to, sizeof to) != len) r->send_errors++;
  r->torques_sent++;
}

static void run_loop(run_t *r, int fd, long long *wake, long long *work, long long *step,
                     long long *s2t) {
  long long q_tick = -1;
  int source = SERVED_NONE;
  for (long long tick = 0; tick < r->ticks && !stop_requested; tick++) {
    long long next = r->epoch + tick * TS_NS + r->phase;
    double origin = NAN; /* when the sample behind this tick's new points left the sensor */
    struct timespec at = {next / 1000000000LL, next % 1000000000LL};
    long long now = mono_ns();
    if (now < next) { /* a wake-up: its latency, measured as cyclictest does */
      while (clock_nanosleep(CLOCK_MONOTONIC, TIMER_ABSTIME, &at, NULL) == EINTR && !stop_requested) {}
      now = mono_ns();
      wake[r->wakeups++] = now - next;
    } else { /* the last tick ended after this one's start: no sleep, a tick behind */
      r->behind += 1;
    }
    r->done = tick + 1;
    if (r->probe) continue;
    take_arrivals(r, fd, tick, &q_tick, &source, &origin);
    while (q_tick != tick) { /* the reading of this tick may still be on its way */
      long long left = now + ENCODER_WAIT_NS - mono_ns(); /* from the tick's start */
      struct pollfd p = {fd, POLLIN, 0};
      struct timespec wait = {0, left > 0 ? left : 0};
      if (left <= 0 || ppoll(&p, 1, &wait, NULL) <= 0) break;
      take_arrivals(r, fd, tick, &q_tick, &source, &origin);
    }
    if (q_tick != tick) { /* stale or missing: the observer's fault path */
      for (int j = 0; j < RHMPC_NU; j++) q[j] = NAN;
      r->stale_encoders++;
    }
    rhmpc_step(&ctl, tick, q, tau);
    step[tick] = ctl.pub.step_ns;
    send_torque(r, fd, tick);
    long long sent = mono_ns();
    if (isfinite(origin)) s2t[r->n_s2t++] = sent - r->epoch - llround(origin * 1e9);
    work[tick] = sent - now;
    r->misses += sent > next + TS_NS; /* its torque went out after the next tick's start */
    int held = source != SERVED_NONE && tick + 1 - ctl.pub.first > RHMPC_REFRESH_TICKS;
    r->served[held ? SERVED_HOLD : source]++;
  }
}

static void write_array(const char *prefix, const char *ext, const long long *a, long long n) {
  char path[4096];
  snprintf(path, sizeof path, "%s.%s", prefix, ext);
  FILE *f = fopen(path, "wb");
  if (f != NULL) {
    fwrite(a, sizeof *a, (size_t)n, f);
    fclose(f);
  }
}

static void write_results(const run_t *r, long long done) {
  char path[4096];
  snprintf(path, sizeof path, "%s.json", r->out);
  FILE *f = fopen(path, "w");
  if (f == NULL) return;
  fprintf(f, "{\"ticks\": %lld, \"deadline_misses\": %lld, \"ticks_behind\": %lld, "
             "\"realtime\": \"%s\", "
             "\"stale_encoders\": %lld, \"bad\": %lld, \"forecasts_rejected\": %lld, "
             "\"send_errors\": %lld, \"interrupted\": %d, \"probe\": %d",
          done, r->misses, r->behind, r->realtime, r->stale_encoders, r->bad, r->forecasts_rejected,
          r->send_errors, (int)stop_requested, r->probe);
  for (int k = 0; k < N_KINDS; k++)
    fprintf(f, ", \"%s\": {\"received\": %lld, \"lost\": %lld, \"late\": %lld}", kind_names[k],
            r->received[k], r->lost[k], r->late[k]);
  fprintf(f, ", \"served\": {");
  for (int s = 0; s < N_SERVED; s++) fprintf(f, "%s\"%s\": %lld", s ? ", " : "", served_names[s], r->served[s]);
  fprintf(f, "}, \"counts\": {");
  for (int c = 0; c < RHMPC_N_COUNTS; c++)
    fprintf(f, "%s\"%s\": %lld", c ? ", " : "", rhmpc_count_name(c), ctl.pub.counts[c]);
  fprintf(f, "}, \"fallbacks\": {");
  for (int s = 1; s < RHMPC_N_SOURCES; s++)
    fprintf(f, "%s\"%s\": %lld", s > 1 ? ", " : "", rhmpc_source_name(s), ctl.pub.fallbacks[s]);
  fprintf(f, "}, \"failures\": {");
  for (int s = 1, first = 1; s < RHMPC_N_STATUS; s++)
    if (ctl.pub.failures[s]) {
      fprintf(f, "%s\"%s\": %lld", first ? "" : ", ", rhmpc_status_name(s), ctl.pub.failures[s]);
      first = 0;
    }
  fprintf(f, "}, \"encoder_held\": %lld, \"n_s2t\": %lld}\n", ctl.pub.encoder_held, r->n_s2t);
  fclose(f);
}

static long long number(const char *text, const char *what) {
  char *end = NULL;
  long long v = strtoll(text, &end, 10);
  if (end == text || *end != '\0') {
    fprintf(stderr, "rhmpc_sil_controller: %s must be an integer, got %s\n", what, text);
    exit(2);
  }
  return v;
}

int main(int argc, char **argv) {
  static run_t r;
  r.cpu = -1, r.priority = 80, r.internal = 1, r.epoch = -1, r.ticks = -1;
  for (int k = 0; k < N_KINDS; k++) r.last_seq[k] = -1;
  for (int i = 1; i < argc; i++) {
    const char *a = argv[i], *v = i + 1 < argc ? argv[i + 1] : "";
    if (!strcmp(a, "--no-internal")) r.internal = 0;
    else if (!strcmp(a, "--probe")) r.probe = 1;
    else if (!strcmp(a, "--epoch")) r.epoch = number(v, a), i++;
    else if (!strcmp(a, "--ticks")) r.ticks = number(v, a), i++;
    else if (!strcmp(a, "--phase")) r.phase = number(v, a), i++;
    else if (!strcmp(a, "--port")) r.port = (int)number(v, a), i++;
    else if (!strcmp(a, "--robot-port")) r.robot_port = (int)number(v, a), i++;
    else if (!strcmp(a, "--cpu")) r.cpu = (int)number(v, a), i++;
    else if (!strcmp(a, "--priority")) r.priority = (int)number(v, a), i++;
    else if (!strcmp(a, "--out")) r.out = v, i++;
    else if ((!strcmp(a, "--origin") || !strcmp(a, "--center")) && i + 3 < argc) {
      /* where the motion sits [m]: the sensor's point --center at --origin (rhmpc_place) */
      double *to = a[2] == 'o' ? r.origin : r.center;
      for (int c = 0; c < 3; c++) {
        char *end = NULL;
        to[c] = strtod(argv[i + 1 + c], &end);
        if (end == argv[i + 1 + c] || *end != '\0' || !isfinite(to[c])) {
          fprintf(stderr, "rhmpc_sil_controller: %s takes 3 finite numbers [m]\n", a);
          return 2;
        }
      }
      r.placed |= a[2] == 'o', i += 3;
    }
    else { fprintf(stderr, "rhmpc_sil_controller: unknown option %s\n", a); return 2; }
  }
  if (r.epoch < 0 || r.ticks < 0 || r.ticks > 1000000000LL || r.out == NULL ||
      (!r.probe && (r.port <= 0 || r.robot_port <= 0)) || !rhmpc_wire_little_endian()) {
    fprintf(stderr, "rhmpc_sil_controller: needs --epoch, --ticks, --out and (unless --probe) "
                    "--port and --robot-port on a little-endian host\n");
    return 2;
  }
  prctl(PR_SET_PDEATHSIG, SIGTERM);
  signal(SIGINT, on_signal);
  signal(SIGTERM, on_signal);
  long long *wake = calloc((size_t)r.ticks + 1, sizeof *wake), *work = calloc((size_t)r.ticks + 1, sizeof *work);
  long long *step = calloc((size_t)r.ticks + 1, sizeof *step), *s2t = calloc((size_t)r.ticks + 1, sizeof *s2t);
  int fd = r.probe ? -1 : open_socket(r.port);
  if (wake == NULL || work == NULL || step == NULL || s2t == NULL || (!r.probe && fd < 0)) {
    fprintf(stderr, "rhmpc_sil_controller: cannot allocate or bind port %d\n", r.port);
    return 1;
  }
  rhmpc_init(&ctl);
  if (r.placed) rhmpc_place(&ctl, r.origin, r.center);
  for (int j = 0; j < RHMPC_NU; j++) q[j] = NAN;
  go_realtime(&r);
  run_loop(&r, fd, wake, work, step, s2t);
  write_array(r.out, "wake", wake, r.wakeups);
  write_array(r.out, "work", work, r.done);
  write_array(r.out, "step", step, r.done);
  write_array(r.out, "s2t", s2t, r.n_s2t);
  write_results(&r, r.done);
  return 0;
}
