/* Replays the same recorded problems through hystmpc's generated RTI step and a generated
   acados solver in one program, in alternating blocks, and writes every solve's time.
   Built by hystmpc.experiments.peer_acados, which writes replay_model.h: the acados solver's
   header and CALL(suffix), its function <model name><suffix>.
   HYSTMPC_INPUTS: first line "n_w n_p count", then count lines of n_w + n_p numbers (w0, p).
   ACADOS_INPUTS: first line "nx nu np ny ny_e N count", then per problem: x0 (nx), the initial
   states x_0..x_N ((N+1) nx), the initial inputs u_0..u_{N-1} (N nu), the parameters of
   stages 0..N ((N+1) np), the cost references of stages 0..N-1 (N ny) and of stage N (ny_e).
   OUTPUTS: per problem, hystmpc's first input, acados' status and first input.
   TIMES: per solve, hystmpc's and acados' time (µs), in the order of the problems, per pass.
   Usage: twin_replay HYSTMPC_INPUTS ACADOS_INPUTS OUTPUTS TIMES REPEATS BLOCK SEED */
#define _POSIX_C_SOURCE 199309L /* clock_gettime under -std=c99 */
#include <stdio.h>
#include <stdlib.h>
#include <time.h>
#include "rti_step.h"
#include "replay_model.h"

static double* read_numbers(const char* path, int header_count, long* header, long (*per)(const long*)) {
  FILE* in = fopen(path, "r");
  if (!in) { fprintf(stderr, "cannot open %s\n", path); exit(2); }
  for (int i = 0; i < header_count; ++i)
    if (fscanf(in, "%ld", &header[i]) != 1) { fprintf(stderr, "bad header in %s\n", path); exit(2); }
  long n = header[header_count - 1] * per(header);
  double* data = malloc(sizeof(double) * (n > 0 ? n : 1));
  if (!data) { fprintf(stderr, "out of memory reading %s\n", path); exit(1); }
  for (long i = 0; i < n; ++i)
    if (fscanf(in, "%lf", &data[i]) != 1) { fprintf(stderr, "bad data at %ld in %s\n", i, path); exit(2); }
  fclose(in);
  return data;
}

static long hystmpc_per(const long* h) { return h[0] + h[1]; }

static long acados_per(const long* h) {
  long nx = h[0], nu = h[1], np = h[2], ny = h[3], ny_e = h[4], N = h[5];
  return nx + (N + 1) * nx + N * nu + (N + 1) * np + N * ny + ny_e;
}

static double elapsed_us(struct timespec t0, struct timespec t1) {
  return (t1.tv_sec - t0.tv_sec) * 1e6 + (t1.tv_nsec - t0.tv_nsec) * 1e-3;
}

int main(int argc, char** argv) {
  if (argc != 8) {
    fprintf(stderr, "usage: %s HYSTMPC_INPUTS ACADOS_INPUTS OUTPUTS TIMES REPEATS BLOCK SEED\n", argv[0]);
    return 2;
  }
  int repeats = atoi(argv[5]), block = atoi(argv[6]);
  srand((unsigned)atoi(argv[7]));
  long ours_header[3], theirs_header[7];
  double* ours_in = read_numbers(argv[1], 3, ours_header, hystmpc_per);
  double* theirs_in = read_numbers(argv[2], 7, theirs_header, acados_per);
  long n_w = ours_header[0], n_p = ours_header[1], count = ours_header[2];
  long nx = theirs_header[0], nu = theirs_header[1], np = theirs_header[2], ny = theirs_header[3];
  long N = theirs_header[5], per = acados_per(theirs_header);
  if (theirs_header[6] != count || repeats < 1 || block < 1) {
    fprintf(stderr, "mismatched problems or arguments\n");
    return 2;
  }

  casadi_int sz_arg, sz_res, sz_iw, sz_w;
  rti_step_work(&sz_arg, &sz_res, &sz_iw, &sz_w);
  const casadi_real** arg = malloc(sizeof(casadi_real*) * sz_arg);
  casadi_real** res = malloc(sizeof(casadi_real*) * sz_res);
  casadi_int* iw = malloc(sizeof(casadi_int) * (sz_iw > 0 ? sz_iw : 1));
  casadi_real* w = malloc(sizeof(casadi_real) * (sz_w > 0 ? sz_w : 1));
  double* w_next = malloc(sizeof(double) * n_w);
  for (casadi_int i = 0; i < sz_res; ++i) res[i] = 0; /* only w_next is written */
  rti_step_incref();
  int mem = rti_step_checkout();

  CALL(_solver_capsule)* capsule = CALL(_acados_create_capsule)();
  if (CALL(_acados_create)(capsule)) { fprintf(stderr, "acados_create failed\n"); return 1; }
  ocp_nlp_config* config = CALL(_acados_get_nlp_config)(capsule);
  ocp_nlp_dims* dims = CALL(_acados_get_nlp_dims)(capsule);
  ocp_nlp_in* nlp_in = CALL(_acados_get_nlp_in)(capsule);
  ocp_nlp_out* nlp_out = CALL(_acados_get_nlp_out)(capsule);

  double* ours_us = malloc(sizeof(double) * count * repeats);
  double* theirs_us = malloc(sizeof(double) * count * repeats);
  double* ours_first = malloc(sizeof(double) * count);
  double* theirs_first = malloc(sizeof(double) * count * nu);
  int* status = malloc(sizeof(int) * count);
  if (!arg || !res || !iw || !w || !w_next || !ours_us || !theirs_us || !ours_first || !theirs_first || !status) {
    fprintf(stderr, "out of memory\n");
    return 1;
  }
  struct timespec t0, t1;
  for (int r = 0; r < repeats; ++r) {
    for (long start = 0; start < count; start += block) {
      long stop = start + block < count ? start + block : count;
      int hystmpc_turn = rand() & 1; /* 0: hystmpc's step runs first on this block, 1: second */
      for (int turn = 0; turn < 2; ++turn) {
        if (turn == hystmpc_turn) {
          for (long k = start; k < stop; ++k) {
            arg[0] = ours_in + k * (n_w + n_p);
            arg[1] = ours_in + k * (n_w + n_p) + n_w;
            res[0] = w_next;
            clock_gettime(CLOCK_MONOTONIC, &t0);
            int flag = rti_step(arg, res, iw, w, mem);
            clock_gettime(CLOCK_MONOTONIC, &t1);
            if (flag) { fprintf(stderr, "rti_step failed at problem %ld\n", k); return 1; }
            ours_us[r * count + k] = elapsed_us(t0, t1);
            ours_first[k] = w_next[0];
          }
        } else {
          for (long k = start; k < stop; ++k) {
            double* x0 = theirs_in + k * per;
            double* xs = x0 + nx;
            double* u = xs + (N + 1) * nx;
            double* p = u + N * nu;
            double* yref = p + (N + 1) * np;
            ocp_nlp_constraints_model_set(config, dims, nlp_in, 0, "lbx", x0);
            ocp_nlp_constraints_model_set(config, dims, nlp_in, 0, "ubx", x0);
            for (int i = 0; i <= N; ++i) {
              ocp_nlp_out_set(config, dims, nlp_out, i, "x", xs + i * nx);
              if (i < N) ocp_nlp_out_set(config, dims, nlp_out, i, "u", u + i * nu);
              if (np > 0) CALL(_acados_update_params)(capsule, i, p + i * np, (int)np);
              ocp_nlp_cost_model_set(config, dims, nlp_in, i, "yref", yref + i * ny);
            }
            clock_gettime(CLOCK_MONOTONIC, &t0);
            int flag = CALL(_acados_solve)(capsule);
            clock_gettime(CLOCK_MONOTONIC, &t1);
            theirs_us[r * count + k] = elapsed_us(t0, t1);
            status[k] = flag;
            ocp_nlp_out_get(config, dims, nlp_out, 0, "u", theirs_first + k * nu);
          }
        }
      }
    }
  }
  FILE* o = fopen(argv[3], "w");
  if (!o) { fprintf(stderr, "cannot write %s\n", argv[3]); return 1; }
  for (long k = 0; k < count; ++k) fprintf(o, "%.17g %d %.17g\n", ours_first[k], status[k], theirs_first[k * nu]);
  fclose(o);
  FILE* t = fopen(argv[4], "w");
  if (!t) { fprintf(stderr, "cannot write %s\n", argv[4]); return 1; }
  for (long i = 0; i < count * repeats; ++i) fprintf(t, "%.3f %.3f\n", ours_us[i], theirs_us[i]);
  fclose(t);
  rti_step_release(mem);
  rti_step_decref();
  CALL(_acados_free)(capsule);
  CALL(_acados_free_capsule)(capsule);
  return 0;
}
