/*
 * A robot's side of the wire (rhmpc_wire.h): the smallest program between the controller and a
 * robot's drivers. At each tick i of the run's clock (epoch + i Ts) it sends the encoders' reading
 * as measured_js (stamp i Ts), waits for the servo_jf of that tick until 0.7 Ts into it (else the
 * last torque holds) and applies it.
 *
 *   cc -std=c99 -O2 -I. robot_client.c -o robot_client
 *   ./robot_client CONTROLLER_PORT ROBOT_PORT EPOCH_NS TICKS [TS_S]
 *
 * Replace read_encoders() and apply_torques() with your drivers' calls. It prints the torques
 * it applied, the ticks it held the last one and the late torques it dropped.
 */
#define _GNU_SOURCE
#include "rhmpc_wire.h"

#include <arpa/inet.h>
#include <math.h>
#include <netinet/in.h>
#include <poll.h>
#include <stdio.h>
#include <stdlib.h>
#include <sys/socket.h>
#include <time.h>

#define NU 3 /* joints */

static long long mono_ns(void) {
  struct timespec t;
  clock_gettime(CLOCK_MONOTONIC, &t);
  return (long long)t.tv_sec * 1000000000LL + t.tv_nsec;
}

/* Your drivers: the encoders' joint angles [rad] and the joint torques [N*m]. */
static double joints[NU];
static void read_encoders(double q[NU]) {
  for (int j = 0; j < NU; j++) q[j] = joints[j];
}
static void apply_torques(const double tau[NU]) { (void)tau; }

int main(int argc, char **argv) {
  if (argc < 5) {
    fprintf(stderr, "usage: %s CONTROLLER_PORT ROBOT_PORT EPOCH_NS TICKS [TS_S]\n", argv[0]);
    return 2;
  }
  const int controller = atoi(argv[1]), port = atoi(argv[2]);
  const long long epoch = atoll(argv[3]), ticks = atoll(argv[4]);
  const double Ts = argc > 5 ? atof(argv[5]) : 0.5e-3;
  int fd = socket(AF_INET, SOCK_DGRAM, 0);
  struct sockaddr_in me = {0}, to = {0};
  me.sin_family = to.sin_family = AF_INET;
  me.sin_addr.s_addr = to.sin_addr.s_addr = htonl(INADDR_LOOPBACK);
  me.sin_port = htons((uint16_t)port);
  to.sin_port = htons((uint16_t)controller);
  if (fd < 0 || bind(fd, (struct sockaddr *)&me, sizeof me) != 0 || !rhmpc_wire_little_endian()) {
    fprintf(stderr, "robot_client: cannot bind port %d\n", port);
    return 1;
  }
  static unsigned char buf[RHMPC_WIRE_HEADER + 8 * 64];
  double q[NU], tau[NU] = {0}, values[64];
  long long applied = 0, held = 0, late = 0, last_seq = -1;
  for (long long i = 0; i < ticks; i++) {
    rhmpc_wire_t m = {RHMPC_MEASURED_JS, (uint32_t)i, i * Ts, NAN, 0.0, 0.0, 1, NU};
    long long start = epoch + (long long)llround(i * Ts * 1e9); /* the tick's instant */
    struct timespec at = {start / 1000000000LL, start % 1000000000LL};
    clock_nanosleep(CLOCK_MONOTONIC, TIMER_ABSTIME, &at, NULL);
    read_encoders(q);
    m.sent = (mono_ns() - epoch) * 1e-9;
    int len = rhmpc_wire_encode(&m, q, buf, sizeof buf);
    sendto(fd, buf, (size_t)len, 0, (struct sockaddr *)&to, sizeof to);
    int got = 0;
    for (;;) { /* this tick's torque, until 0.7 Ts into the tick */
      long long left = epoch + (long long)llround((i + 0.7) * Ts * 1e9) - mono_ns();
      struct pollfd p = {fd, POLLIN, 0};
      if (left <= 0 || poll(&p, 1, (int)((left + 999999) / 1000000)) <= 0) break;
      ssize_t n = recv(fd, buf, sizeof buf, 0);
      if (n <= 0 || rhmpc_wire_decode(buf, (int)n, &m, values, 64) != 0 ||
          m.kind != RHMPC_SERVO_JF || m.width != NU || rhmpc_wire_take(&last_seq, m.seq) < 0)
        continue;
      long long tick = llround(m.stamp / Ts);
      if (tick < i) { late++; continue; } /* for a tick already past: stale */
      for (int j = 0; j < NU; j++) tau[j] = values[j];
      got = 1;
      break;
    }
    held += !got;
    applied += got;
    apply_torques(tau);
  }
  printf("robot_client: %lld torques applied, %lld ticks held the last one, %lld late\n",
         applied, held, late);
  return 0;
}
