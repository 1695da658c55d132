/*
 * The wire format of rhmpc's processes, version 1 (rhmpc/runtime/wire.py is the same in Python).
 *
 * One UDP datagram per message: a 48-byte header, then rows x width float64 values, all
 * little-endian:
 *   0 magic "RHMP" | 4 uint16 version (1) | 6 uint16 kind | 8 uint32 seq | 12 float64 stamp [s]
 *   | 20 float64 origin [s] | 28 float64 sent [s] | 36 float64 period [s] | 44 uint16 rows
 *   | 46 uint16 width | 48 float64 values[rows * width]
 * Kinds (CRTK names): 1 measured_cp (a tracker's sample: row 0 the POI, rows 1.. the other
 * points, [m]), 2 forecast_cp (row k the POI at stamp + k * period [m]), 3 measured_js (the
 * encoders' joint angles of one tick [rad]), 4 servo_jf (the joint torques computed from them
 * [N*m]). Times are on the run's clock: CLOCK_MONOTONIC less the run's epoch.
 *
 * Header-only, no allocation: encode into and decode from the caller's buffers.
 */
#ifndef RHMPC_WIRE_H
#define RHMPC_WIRE_H

#include <stdint.h>
#include <string.h>

#define RHMPC_WIRE_VERSION 1
#define RHMPC_WIRE_HEADER 48
#define RHMPC_MEASURED_CP 1
#define RHMPC_FORECAST_CP 2
#define RHMPC_MEASURED_JS 3
#define RHMPC_SERVO_JF 4

typedef struct {
  int kind;
  uint32_t seq;
  double stamp, origin, sent, period;
  int rows, width;
} rhmpc_wire_t;

/* This format is little-endian; so are x86-64 and the ARM targets. */
static inline int rhmpc_wire_little_endian(void) {
  const uint16_t one = 1;
  unsigned char first;
  memcpy(&first, &one, 1);
  return first == 1;
}

/* Write the message (header m, values[m->rows * m->width]) into buf of cap bytes; returns its
 * length, or -1 if it does not fit. */
static inline int rhmpc_wire_encode(const rhmpc_wire_t *m, const double *values,
                                    unsigned char *buf, int cap) {
  const int n = m->rows * m->width, len = RHMPC_WIRE_HEADER + 8 * n;
  const uint16_t version = RHMPC_WIRE_VERSION, kind = (uint16_t)m->kind;
  const uint16_t rows = (uint16_t)m->rows, width = (uint16_t)m->width;
  if (len > cap || m->rows < 0 || m->width < 0 || m->rows > 65535 || m->width > 65535) return -1;
  memcpy(buf, "RHMP", 4);
  memcpy(buf + 4, &version, 2);
  memcpy(buf + 6, &kind, 2);
  memcpy(buf + 8, &m->seq, 4);
  memcpy(buf + 12, &m->stamp, 8);
  memcpy(buf + 20, &m->origin, 8);
  memcpy(buf + 28, &m->sent, 8);
  memcpy(buf + 36, &m->period, 8);
  memcpy(buf + 44, &rows, 2);
  memcpy(buf + 46, &width, 2);
  if (n > 0) memcpy(buf + RHMPC_WIRE_HEADER, values, (size_t)n * 8);
  return len;
}

/* Read a datagram of len bytes: the header into m and at most max_values values; returns 0, or
 * -1 for a datagram of another format, version or size (or with more than max_values values). */
static inline int rhmpc_wire_decode(const unsigned char *buf, int len, rhmpc_wire_t *m,
                                    double *values, int max_values) {
  uint16_t version, kind, rows, width;
  if (len < RHMPC_WIRE_HEADER || memcmp(buf, "RHMP", 4) != 0) return -1;
  memcpy(&version, buf + 4, 2);
  memcpy(&kind, buf + 6, 2);
  memcpy(&m->seq, buf + 8, 4);
  memcpy(&m->stamp, buf + 12, 8);
  memcpy(&m->origin, buf + 20, 8);
  memcpy(&m->sent, buf + 28, 8);
  memcpy(&m->period, buf + 36, 8);
  memcpy(&rows, buf + 44, 2);
  memcpy(&width, buf + 46, 2);
  m->kind = kind;
  m->rows = rows;
  m->width = width;
  if (version != RHMPC_WIRE_VERSION || kind < 1 || kind > 4) return -1;
  if (len != RHMPC_WIRE_HEADER + 8 * (int)rows * (int)width || rows * width > max_values)
    return -1;
  if (rows * width > 0) memcpy(values, buf + RHMPC_WIRE_HEADER, (size_t)rows * width * 8);
  return 0;
}

/* Sequence numbers of one kind: returns the messages lost before this one (>= 0), or -1 for a
 * late one (at or below the last taken: reordered or duplicated; drop it). *last < 0: none yet. */
static inline long long rhmpc_wire_take(long long *last, uint32_t seq) {
  if (*last < 0) {
    *last = seq;
    return (long long)seq;
  }
  uint32_t step = seq - (uint32_t)*last;
  if (step == 0 || step > 0x7FFFFFFFu) return -1;
  *last = seq;
  return (long long)step - 1;
}

#endif /* RHMPC_WIRE_H */
