/* Replay of recorded controller inputs through an exported C controller, ticks back to back
 * (issue 15 measurement; not part of the library). Inputs: rows of [x (NX); ref (NY*N);
 * extra (NEXTRA)] as float64, written by the snippet in docs/notes/issue-15.md.
 *   gcc -O2 -I<export dir> docs/notes/issue-15-replay.c <build dir>/librhmpc.a -lm -o replay
 *   ./replay inputs.bin 5   # 5 passes; prints the C tick per cascade level of the last pass */
#include "rhmpc.h"
#include <stdio.h>
#include <stdlib.h>
#include <time.h>
#define ROW (RHMPC_NX + RHMPC_NY*RHMPC_N + RHMPC_NEXTRA)
static int cmp(const void *a, const void *b) { long long x = *(const long long*)a, y = *(const long long*)b; return (x > y) - (x < y); }
int main(int argc, char **argv) {
  if (argc < 2) { fprintf(stderr, "usage: replay INPUTS.bin [passes]\n"); return 2; }
  FILE *f = fopen(argv[1], "rb");
  if (!f) { perror(argv[1]); return 1; }
  static double buf[5500 * ROW];
  size_t n = fread(buf, sizeof(double) * ROW, 5500, f);
  int reps = argc > 2 ? atoi(argv[2]) : 1;
  static rhmpc_t ctl; double tau[3];
  static long long t[5500]; static int lv[5500];
  for (int r = 0; r < reps; ++r) {
    rhmpc_init(&ctl);
    for (size_t k = 0; k < n; ++k) {
      const double *row = buf + k * ROW;
      rhmpc_tick_ext(&ctl, row, row + RHMPC_NX, NULL, row + RHMPC_NX + RHMPC_NY*RHMPC_N, tau);
      t[k] = ctl.tick_ns; lv[k] = ctl.level;
    }
  }
  for (int L = 0; L <= 3; ++L) { /* 0: every tick */
    static long long s[5500]; int m = 0;
    for (size_t k = 500; k < n; ++k) if (L == 0 || lv[k] == L) s[m++] = t[k];
    if (!m) continue;
    qsort(s, m, sizeof(long long), cmp);
    printf("%s %d: n %d p50 %.2f p99 %.2f max %.2f us\n", L ? "level" : "all ticks, level >=", L, m, s[m/2]/1e3, s[(int)(0.99*(m-1))]/1e3, s[m-1]/1e3);
  }
  return 0;
}
