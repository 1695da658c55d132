/*
 * A robot's side of the wire (rhmpc_wire.h): the template between the controller and a robot's
 * drivers. Copy it, replace read_encoders(), apply_torques() and enter_safe_state() with your
 * drivers' calls, and keep the rest: it is what makes the arm obey only the run's controller.
 *
 *   rhmpc_robot_client --key-file KEY --controller-port P --port R --epoch NS --ticks N
 *                      [--log FILE]
 *
 * At each tick i of the run's clock (epoch + i Ts) it reads the encoders, sends them as
 * measured_js (stamp i Ts) and waits, until 0.7 Ts into the tick, for the servo_jf of tick i.
 * It applies a torque only when the datagram
 *   - carries the code of the run's key (HMAC-SHA-256; the key file is 0600, or a descriptor),
 *   - is a servo_jf of RHMPC_NU values whose sequence number follows the last one taken (a
 *     replay or a number far ahead is dropped, never adopted),
 *   - is stamped with this very tick (an earlier tick's is late, a later tick's implausible),
 *     its send time within the last MAX_AGE_S,
 *   - holds finite torques within the arm's limits (rhmpc_tau_max, from the robot file).
 * Anything else is counted under its reason and dropped. Without a torque for this tick the
 * last one taken holds; after WATCHDOG_TICKS ticks without one the drivers enter their safe
 * state (brakes, or gravity compensation with viscous braking) and stay there until torques
 * come again.
 *
 * At the end it prints one line: the torques applied, the ticks held and in the safe state,
 * and the datagrams dropped per reason; --log FILE writes each tick's mode and torque (CSV,
 * after the run: nothing in the loop allocates or writes).
 */
#define _GNU_SOURCE
#include "rhmpc.h"
#include "rhmpc_wire.h"

#include <arpa/inet.h>
#include <errno.h>
#include <math.h>
#include <netinet/in.h>
#include <poll.h>
#include <signal.h>
#include <stdio.h>
#include <stdlib.h>
#include <string.h>
#include <sys/socket.h>
#include <time.h>

#define NU RHMPC_NU
/* Ticks without a torque after which the drivers enter their safe state (10 ms at 2 kHz: the
 * last torque cannot move the tool by a millimetre in that time on the PHANToM's inertia). */
#define WATCHDOG_TICKS 20
#define WAIT 0.7      /* how far into a tick its torque may come [ticks] */
#define MAX_AGE_S 0.1 /* the oldest send time taken [s] */

enum { MODE_TORQUE, MODE_HOLD, MODE_SAFE };
static const char *const mode_names[] = {"torque", "hold", "safe"};

/* ---- your drivers ------------------------------------------------------------------------- */
static double joints[NU];
/* the encoders' joint angles [rad] */
static void read_encoders(double q[NU]) {
  for (int j = 0; j < NU; j++) q[j] = joints[j];
}
/* the joint torques to hold until the next call [N*m] */
static void apply_torques(const double tau[NU]) { (void)tau; }
/* the drivers' own safe state: brakes on, or gravity compensation with viscous braking */
static void enter_safe_state(void) {}
/* ------------------------------------------------------------------------------------------- */

static long long mono_ns(void) {
  struct timespec t;
  clock_gettime(CLOCK_MONOTONIC, &t);
  return (long long)t.tv_sec * 1000000000LL + t.tv_nsec;
}

static volatile sig_atomic_t stop_requested = 0;
static void on_signal(int sig) { (void)sig; stop_requested = 1; }

typedef struct {
  rhmpc_wire_key_t key;
  long long epoch, ticks, dropped[RHMPC_WIRE_N_VERDICTS];
  uint64_t last_seq;
  int have_seq, fd, controller, port;
  double Ts;
  const char *key_file, *log;
} client_t;

static unsigned char buf[RHMPC_WIRE_HEADER + 8 * NU * RHMPC_WIRE_MAX_ROWS + RHMPC_WIRE_MAC];
static double values[NU * RHMPC_WIRE_MAX_ROWS];

/* The verdict on one datagram for tick i: RHMPC_WIRE_TAKEN puts its torques in tau. */
static int judge(client_t *c, long long len, long long i, double tau[NU]) {
  rhmpc_wire_t m;
  long long lost = 0;
  int verdict = rhmpc_wire_unseal(&c->key, buf, len, NU, &m, values, NU * RHMPC_WIRE_MAX_ROWS);
  if (verdict != RHMPC_WIRE_TAKEN) return verdict;
  if (m.kind != RHMPC_SERVO_JF) return RHMPC_DROP_UNEXPECTED;
  const double now = (mono_ns() - c->epoch) * 1e-9, tick = m.stamp / c->Ts;
  if (!isfinite(m.stamp) || tick > i + 0.5 || !(m.sent >= now - MAX_AGE_S && m.sent <= now + c->Ts))
    return RHMPC_DROP_IMPLAUSIBLE;
  for (int j = 0; j < NU; j++)
    if (!(fabs(values[j]) <= rhmpc_tau_max[j])) return RHMPC_DROP_IMPLAUSIBLE; /* NaN fails */
  verdict = rhmpc_wire_order(&c->last_seq, &c->have_seq, m.seq, &lost);
  if (verdict != RHMPC_WIRE_TAKEN) return verdict;
  if (tick < i - 0.5) return RHMPC_DROP_LATE; /* for a tick already past */
  memcpy(tau, values, sizeof(double) * NU);
  return RHMPC_WIRE_TAKEN;
}

/* This tick's torque, awaited until WAIT into the tick; 1 if one came. */
static int await_torque(client_t *c, long long i, double tau[NU]) {
  for (;;) {
    long long left = c->epoch + (long long)llround((i + WAIT) * c->Ts * 1e9) - mono_ns();
    struct pollfd p = {c->fd, POLLIN, 0};
    struct timespec wait = {left / 1000000000LL, left % 1000000000LL};
    if (left <= 0 || ppoll(&p, 1, &wait, NULL) <= 0) return 0;
    ssize_t n = recv(c->fd, buf, sizeof buf, MSG_DONTWAIT);
    if (n <= 0) continue;
    int verdict = judge(c, n, i, tau);
    if (verdict == RHMPC_WIRE_TAKEN) return 1;
    c->dropped[verdict]++;
  }
}

static int run(client_t *c, signed char *mode, double *applied) {
  static unsigned char out[RHMPC_WIRE_HEADER + 8 * NU + RHMPC_WIRE_MAC];
  struct sockaddr_in to = {0};
  double q[NU], tau[NU] = {0}, taken[NU];
  long long silent = WATCHDOG_TICKS + 1; /* no torque yet: the safe state until the first */
  to.sin_family = AF_INET;
  to.sin_addr.s_addr = htonl(INADDR_LOOPBACK);
  to.sin_port = htons((uint16_t)c->controller);
  for (long long i = 0; i < c->ticks && !stop_requested; i++) {
    rhmpc_wire_t m = {RHMPC_MEASURED_JS, (uint64_t)i, i * c->Ts, NAN, 0.0, 0.0, 1, NU};
    long long start = c->epoch + (long long)llround(i * c->Ts * 1e9);
    struct timespec at = {start / 1000000000LL, start % 1000000000LL};
    while (clock_nanosleep(CLOCK_MONOTONIC, TIMER_ABSTIME, &at, NULL) == EINTR && !stop_requested) {}
    read_encoders(q);
    m.sent = (mono_ns() - c->epoch) * 1e-9;
    int len = rhmpc_wire_seal(&c->key, &m, q, out, sizeof out);
    if (len > 0) sendto(c->fd, out, (size_t)len, 0, (struct sockaddr *)&to, sizeof to);
    if (await_torque(c, i, taken)) {
      memcpy(tau, taken, sizeof tau);
      silent = 0;
    } else {
      silent++;
    }
    mode[i] = silent == 0 ? MODE_TORQUE : silent <= WATCHDOG_TICKS ? MODE_HOLD : MODE_SAFE;
    if (mode[i] == MODE_SAFE) enter_safe_state();
    else apply_torques(tau);
    memcpy(applied + NU * i, mode[i] == MODE_SAFE ? (double[NU]){0} : tau, sizeof tau);
  }
  return 0;
}

static long long integer(const char *text, const char *what) {
  char *end = NULL;
  errno = 0;
  long long v = strtoll(text, &end, 10);
  if (end == text || *end != '\0' || errno) {
    fprintf(stderr, "rhmpc_robot_client: an integer must follow %s\n", what);
    exit(2);
  }
  return v;
}

static void report(const client_t *c, const signed char *mode, const double *applied) {
  long long n[3] = {0};
  for (long long i = 0; i < c->ticks; i++) n[mode[i]] += mode[i] >= 0;
  printf("rhmpc_robot_client: %lld torques applied, %lld ticks held the last one, %lld in the "
         "safe state; dropped", n[MODE_TORQUE], n[MODE_HOLD], n[MODE_SAFE]);
  for (int v = 1; v < RHMPC_WIRE_N_VERDICTS; v++)
    printf(" %s %lld", rhmpc_wire_verdict_names[v], c->dropped[v]);
  printf("\n");
  FILE *f = c->log ? fopen(c->log, "w") : NULL;
  if (c->log && f == NULL) fprintf(stderr, "rhmpc_robot_client: cannot write %s\n", c->log);
  for (long long i = 0; f && i < c->ticks && mode[i] >= 0; i++) {
    fprintf(f, "%lld,%s", i, mode_names[mode[i]]);
    for (int j = 0; j < NU; j++) fprintf(f, ",%.17g", applied[NU * i + j]);
    fprintf(f, "\n");
  }
  if (f) fclose(f);
}

int main(int argc, char **argv) {
  static client_t c;
  char why[512];
  c.Ts = RHMPC_TS, c.epoch = -1, c.ticks = -1;
  for (int i = 1; i + 1 < argc; i += 2) {
    const char *a = argv[i], *v = argv[i + 1];
    if (!strcmp(a, "--key-file")) c.key_file = v;
    else if (!strcmp(a, "--controller-port")) c.controller = (int)integer(v, a);
    else if (!strcmp(a, "--port")) c.port = (int)integer(v, a);
    else if (!strcmp(a, "--epoch")) c.epoch = integer(v, a);
    else if (!strcmp(a, "--ticks")) c.ticks = integer(v, a);
    else if (!strcmp(a, "--log")) c.log = v;
    else argc = 0; /* unknown: the usage below */
  }
  if (argc % 2 == 0 || c.key_file == NULL || c.controller <= 0 || c.controller > 65535 ||
      c.port <= 0 || c.port > 65535 || c.epoch < 0 || c.ticks < 0 || c.ticks > 100000000LL) {
    fprintf(stderr, "usage: %s --key-file KEY --controller-port P --port R --epoch NS --ticks N "
                    "[--log FILE]\n", argv[0]);
    return 2;
  }
  if (rhmpc_wire_key_read(&c.key, c.key_file, why, sizeof why) != 0) {
    fprintf(stderr, "rhmpc_robot_client: %s\n", why);
    return 2;
  }
  struct sockaddr_in me = {0};
  me.sin_family = AF_INET;
  me.sin_addr.s_addr = htonl(INADDR_LOOPBACK);
  me.sin_port = htons((uint16_t)c.port);
  c.fd = socket(AF_INET, SOCK_DGRAM, 0);
  const int buffer = 1 << 20; /* a burst of foreign datagrams must not push out the run's own */
  if (c.fd >= 0 && setsockopt(c.fd, SOL_SOCKET, SO_RCVBUFFORCE, &buffer, sizeof buffer) != 0)
    setsockopt(c.fd, SOL_SOCKET, SO_RCVBUF, &buffer, sizeof buffer); /* up to rmem_max */
  if (c.fd < 0 || bind(c.fd, (struct sockaddr *)&me, sizeof me) != 0) {
    fprintf(stderr, "rhmpc_robot_client: cannot bind UDP port %d: %s\n", c.port, strerror(errno));
    return 1;
  }
  signal(SIGINT, on_signal);
  signal(SIGTERM, on_signal);
  signed char *mode = malloc((size_t)c.ticks + 1);
  double *applied = calloc((size_t)c.ticks * NU + 1, sizeof *applied);
  if (mode == NULL || applied == NULL) return 1;
  memset(mode, -1, (size_t)c.ticks + 1);
  run(&c, mode, applied);
  enter_safe_state(); /* the run is over: the drivers hold the arm */
  report(&c, mode, applied);
  return 0;
}
