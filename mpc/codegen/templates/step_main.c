/* Replays recorded RTI inputs through rti_step without Python; prints timings.
   Input file: first line "n_w n_p count", then count lines of n_w + n_p numbers (w0, p).
   Output file: one line of n_w numbers (w_next) per input line; qp_error is not written.
   Usage: rti_main INPUTS OUTPUTS [repeats] -> stdout: median, p95 and max per call (µs). */
#include <stdio.h>
#include <stdlib.h>
#include <time.h>
#include "rti_step.h"

static int cmp(const void* a, const void* b) {
  double x = *(const double*)a, y = *(const double*)b;
  return (x > y) - (x < y);
}

int main(int argc, char** argv) {
  if (argc < 3) { fprintf(stderr, "usage: %s INPUTS OUTPUTS [repeats]\n", argv[0]); return 2; }
  int repeats = argc > 3 ? atoi(argv[3]) : 1;
  FILE* in = fopen(argv[1], "r");
  if (!in) { fprintf(stderr, "cannot open %s\n", argv[1]); return 2; }
  long n_w, n_p, count;
  if (fscanf(in, "%ld %ld %ld", &n_w, &n_p, &count) != 3) { fprintf(stderr, "bad header\n"); return 2; }
  double* data = malloc(sizeof(double) * count * (n_w + n_p));
  for (long i = 0; i < count * (n_w + n_p); ++i)
    if (fscanf(in, "%lf", &data[i]) != 1) { fprintf(stderr, "bad data at %ld\n", i); return 2; }
  fclose(in);
  casadi_int sz_arg, sz_res, sz_iw, sz_w;
  rti_step_work(&sz_arg, &sz_res, &sz_iw, &sz_w);
  const casadi_real** arg = malloc(sizeof(casadi_real*) * sz_arg);
  casadi_real** res = malloc(sizeof(casadi_real*) * sz_res);
  casadi_int* iw = malloc(sizeof(casadi_int) * (sz_iw > 0 ? sz_iw : 1));
  casadi_real* w = malloc(sizeof(casadi_real) * (sz_w > 0 ? sz_w : 1));
  double* out = malloc(sizeof(double) * count * n_w);
  double* us = malloc(sizeof(double) * count * repeats);
  for (casadi_int i = 0; i < sz_res; ++i) res[i] = 0; /* only w_next is written */
  rti_step_incref();
  int mem = rti_step_checkout();
  for (int r = 0; r < repeats; ++r) {
    for (long k = 0; k < count; ++k) {
      arg[0] = data + k * (n_w + n_p);
      arg[1] = data + k * (n_w + n_p) + n_w;
      res[0] = out + k * n_w;
      struct timespec t0, t1;
      clock_gettime(CLOCK_MONOTONIC, &t0);
      int flag = rti_step(arg, res, iw, w, mem);
      clock_gettime(CLOCK_MONOTONIC, &t1);
      if (flag) { fprintf(stderr, "rti_step failed at line %ld\n", k); return 1; }
      us[r * count + k] = (t1.tv_sec - t0.tv_sec) * 1e6 + (t1.tv_nsec - t0.tv_nsec) * 1e-3;
    }
  }
  rti_step_release(mem);
  rti_step_decref();
  FILE* o = fopen(argv[2], "w");
  for (long k = 0; k < count; ++k) {
    for (long j = 0; j < n_w; ++j) fprintf(o, "%.17g%c", out[k * n_w + j], j + 1 < n_w ? ' ' : '\n');
  }
  fclose(o);
  long n = count * repeats;
  qsort(us, n, sizeof(double), cmp);
  printf("median_us %.3f\np95_us %.3f\nmax_us %.3f\ncalls %ld\n", us[n / 2], us[(long)(0.95 * (n - 1))], us[n - 1], n);
  return 0;
}
