"""Real time: code-generated RTI solvers (``hystmpc codegen``) and speed per variant (``hystmpc speed``).

``codegen`` also writes the whole controller where the bench's controller allows it
(:mod:`hystmpc.experiments.firmware`, in ``<out>/controller``).

The RTI step of a bench's NMPC (:mod:`hystmpc.mpc.rti`) is written as C99 (needs libm and,
with the default QP, the DAQP library that CasADi ships), with a header, a small C ``main``
that replays recorded solver inputs without Python, and a Makefile. It is compiled with the
system C compiler and loaded back into Python; ``verify`` runs the bench's default scenario closed loop with the
in-process and with the compiled step and reports the largest difference in applied input.
"""

from __future__ import annotations

import logging
import shlex
import shutil
import subprocess
import time
from dataclasses import replace
from pathlib import Path

import casadi as ca
import numpy as np

from hystmpc.experiments.bench import Bench
from hystmpc.experiments.firmware import cross_compile, verify_controller, write_controller
from hystmpc.mpc.embedded import NotGeneratable
from hystmpc.mpc.rti import COMPILE_FLAGS, _accept_last_qp_iterate, c_compiler, library_flags
from hystmpc.mpc.settings import MULTISTART_SOLVERS

MAIN_C = r"""/* Replays recorded RTI inputs through rti_step without Python; prints timings.
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
"""

MAKEFILE = """# Builds the RTI solver as a shared library (for Python) and the standalone replay program.
# QP_INCLUDE and QP_LIBS: the QP library the step calls (DAQP from the CasADi package), if any.
CC ?= cc
CFLAGS ?= {cflags}
QP_INCLUDE ?= {qp_include}
QP_LIBS ?= {qp_libs}
all: librti_step.so rti_main
librti_step.so: rti_step.c rti_step.h
\t$(CC) $(CFLAGS) $(QP_INCLUDE) -fPIC -shared rti_step.c -o librti_step.so $(QP_LIBS) -lm
rti_main: main.c rti_step.c rti_step.h
\t$(CC) $(CFLAGS) $(QP_INCLUDE) main.c rti_step.c -o rti_main $(QP_LIBS) -lm
clean:
\trm -f librti_step.so rti_main
"""


class RecordingStep:
    """Wraps an RTI Function: records every ``(w0, p)`` it is called with."""

    def __init__(self, fun):
        self.fun = fun
        self.calls: list[np.ndarray] = []

    def __call__(self, w0, p):
        self.calls.append(np.concatenate((np.ravel(w0), np.ravel(p))))
        return self.fun(w0, p)


def _problem_of(controller):
    problem = getattr(controller, "problem", None)
    if getattr(problem, "rti", None) is None:
        raise ValueError("this bench's nmpc has no RTI step")
    return problem


def check_codegen_settings(bench: Bench, config: dict) -> None:
    """``ValueError`` for an NMPC setting that ``codegen`` and ``speed`` do not read: a runtime
    other than the bench's default (cheap: checked before any work)."""
    if "nmpc" not in config:
        raise ValueError(f"bench {bench.name!r} has no nmpc settings")
    runtime, default = config["nmpc"].runtime, bench.configure(tuned=False)["nmpc"].runtime
    if runtime != default:  # the bench's default says nothing here
        raise ValueError(f"nmpc.runtime={runtime} chooses where run, compare and sweep run the controller; "
                         "codegen writes the generated controller and speed times the solver variants whatever "
                         f"it says: drop the setting here (this bench's default: {default})")


def _rti_config(bench: Bench, config: dict, solver: str) -> dict:
    """``config`` with ``solver``, run in Python; with two starts where the bench has them and the
    solver reports the cost they compare (IPOPT and sqp are timed with one)."""
    check_codegen_settings(bench, config)
    multistart = config["nmpc"].multistart and solver in MULTISTART_SOLVERS
    return {**config, "nmpc": replace(config["nmpc"], solver=solver, runtime="python", multistart=multistart)}


def _compile(out: Path) -> None:
    gcc = shutil.which("gcc")
    cc = c_compiler() or ([gcc] if gcc else None)
    if cc is None:
        raise RuntimeError("no C compiler (cc or gcc) on the PATH")
    size = (out / "rti_step.c").stat().st_size
    logging.getLogger("hystmpc").info(f"compiling rti_step.c ({size / 1e3:.0f} kB) and the replay program with "
                                      f"{' '.join(cc)} {' '.join(COMPILE_FLAGS)} in {out}")
    include, libraries = library_flags((out / "rti_step.c").read_text())
    for cmd in (["make", f"CC={shlex.join(cc)}", "-s"],) if shutil.which("make") else (
            [*cc, *COMPILE_FLAGS, *include, "-fPIC", "-shared", "rti_step.c", "-o", "librti_step.so", *libraries,
             "-lm"],
            [*cc, *COMPILE_FLAGS, *include, "main.c", "rti_step.c", "-o", "rti_main", *libraries, "-lm"]):
        done = subprocess.run(cmd, cwd=out, capture_output=True, text=True)
        if done.returncode != 0:
            raise RuntimeError(f"build failed ({' '.join(cmd)}): {done.stderr.strip()[:2000]}")


def write_solver(bench: Bench, config: dict, out: Path) -> ca.Function:
    """Write the bench's RTI step as C (+ header, ``main.c``, Makefile) into ``out``, build
    the shared library and the replay program, and return the compiled step loaded back."""
    config = _rti_config(bench, config, "rti")
    problem = _problem_of(bench.build_controller("nmpc", config))
    out.mkdir(parents=True, exist_ok=True)
    gen = ca.CodeGenerator("rti_step.c", {"with_header": True})
    gen.add(problem.rti)
    gen.generate(str(out) + "/")
    (out / "rti_step.c").write_text(_accept_last_qp_iterate((out / "rti_step.c").read_text()))
    (out / "main.c").write_text(MAIN_C)
    include, libraries = library_flags((out / "rti_step.c").read_text())
    makefile = MAKEFILE.replace("{cflags}", " ".join(COMPILE_FLAGS))
    (out / "Makefile").write_text(makefile.replace("{qp_include}", shlex.join(include))
                                  .replace("{qp_libs}", shlex.join(libraries)))
    _compile(out)
    return ca.external("rti_step", str(out / "librti_step.so"))


def run_program(out: Path, calls: np.ndarray, n_w: int, repeats: int = 1) -> tuple[np.ndarray, dict]:
    """Run the standalone program on recorded calls; returns (w_next per call, timing in µs)."""
    inputs, outputs = out / "inputs.txt", out / "outputs.txt"
    header = f"{n_w} {calls.shape[1] - n_w} {calls.shape[0]}"
    np.savetxt(inputs, calls, fmt="%.17g", header=header, comments="")
    done = subprocess.run([str(out / "rti_main"), str(inputs), str(outputs), str(repeats)],
                          capture_output=True, text=True)
    if done.returncode != 0:
        raise RuntimeError(f"rti_main failed: {done.stderr.strip()[:500]}")
    timing = {k: float(v) for k, v in (line.split() for line in done.stdout.split("\n") if line)}
    return np.loadtxt(outputs, ndmin=2), timing


def codegen(bench: Bench, config: dict, out: Path, verify: bool, duration: float | None = None,
            target: str | None = None) -> dict:
    """``hystmpc codegen``: write and build the C solver; with ``verify``, replay the default
    scenario closed loop with both solvers and run the standalone program on its inputs; with
    ``target='cortex-m7'``, also cross-compile the whole controller and report its size."""
    if target not in (None, "cortex-m7"):
        raise ValueError(f"target {target!r} is unknown; allowed: cortex-m7")
    try:  # the whole controller first: a target that needs it fails before the solver is built
        controller = write_controller(bench, config, out / "controller")
    except NotGeneratable as exc:  # this bench's controller has parts without a CasADi form yet
        shutil.rmtree(out / "controller", ignore_errors=True)
        if target is not None:
            raise ValueError(f"--target {target} builds the whole controller, which cannot be generated: "
                             f"{exc}") from None
        controller = {"skipped": str(exc)}
    compiled = write_solver(bench, config, out)
    report = {"bench": bench.name, "out": str(out), "files": sorted(p.name for p in out.iterdir()),
              "controller": controller}
    if target is not None:
        report["controller"][target] = cross_compile(out / "controller", report["controller"]["name"])
    if not verify:
        return report
    if "skipped" not in report["controller"]:
        report["controller"]["verify"] = verify_controller(bench, config, out / "controller",
                                                           report["controller"]["name"], duration)
    scenario = bench.scenarios[bench.default_scenario]
    config = _rti_config(bench, config, "rti")
    results, recorded = {}, None
    for label in ("in-process", "compiled"):
        prepared = bench.prepare(scenario, "nmpc", config)
        problem = _problem_of(prepared.controller)
        problem.rti = RecordingStep(problem.rti if label == "in-process" else compiled)
        results[label] = bench.run(scenario, "nmpc", duration=duration, prepared=prepared)
        if label == "in-process":
            recorded = np.asarray(problem.rti.calls)
            n_w = problem.rti.fun.size1_in(0)
            in_process_out = np.array([np.asarray(problem.rti.fun(c[:n_w], c[n_w:])[0]).ravel()
                                       for c in recorded[:200]])
    diff = float(np.max(np.abs(results["in-process"].input - results["compiled"].input)))
    program_out, timing = run_program(out, recorded, n_w, repeats=3)
    program_diff = float(np.max(np.abs(program_out[:200] - in_process_out)))
    report.update({
        "scenario": scenario.name, "samples": int(len(results["compiled"].input)),
        "max_input_difference": diff,
        "rmse": {k: v.metrics["rmse"] for k, v in results.items()},
        "standalone": {"max_output_difference_first_200": program_diff, **timing},
    })
    return report


def speed(bench: Bench, config: dict, variants, duration: float | None = None, out: Path | None = None) -> dict:
    """``hystmpc speed``: per-step compute of each solver variant on the default scenario."""
    scenario = bench.scenarios[bench.default_scenario]
    period_ms = 1e3 * bench.sample_period
    rows = []
    for variant in variants:
        variant_config = _rti_config(bench, config, variant)
        prepared = bench.prepare(scenario, "nmpc", variant_config)
        start = time.perf_counter()
        run = bench.run(scenario, "nmpc", duration=duration, prepared=prepared)
        solve_ms = 1e3 * np.asarray(getattr(prepared.controller, "solve_times", [np.nan]))
        rows.append({"variant": variant, "multistart": variant_config["nmpc"].multistart,
                     "rmse": run.metrics["rmse"], **run.timing,
                     "solve_ms_median": float(np.median(solve_ms)), "solve_ms_p95": float(np.percentile(solve_ms, 95)),
                     "solve_ms_max": float(np.max(solve_ms)), "failures": run.solver["failures"],
                     "wall_s": time.perf_counter() - start})
    result = {"bench": bench.name, "scenario": scenario.name, "sample_period_ms": period_ms, "variants": rows}
    if "rti-c" in variants and out is not None:
        report = codegen(bench, config, out, verify=True, duration=duration)
        result["standalone_c"] = report["standalone"]
        if "verify" in report["controller"]:
            result["controller_c"] = report["controller"]["verify"]["example_loop"]
    return result


def speed_table(result: dict) -> str:
    """Markdown table of :func:`speed`'s result."""
    period = result["sample_period_ms"]
    lines = [f"{result['bench']} · {result['scenario']} · sample period {period:g} ms", "",
             "| variant | RMSE | step ms median / p95 / max | solve ms median / p95 / max "
             "| median % of period | failures |",
             "|---|---|---|---|---|---|"]
    for r in result["variants"]:
        variant = f"{r['variant']}, two starts" if r.get("multistart") else r["variant"]
        lines.append(f"| {variant} | {r['rmse']:.4g} | {r['step_ms_median']:.3f} / {r['step_ms_p95']:.3f} / "
                     f"{r['step_ms_max']:.3f} | {r['solve_ms_median']:.3f} / {r['solve_ms_p95']:.3f} / "
                     f"{r['solve_ms_max']:.3f} | {100 * r['step_ms_median'] / period:.1f} % | {r['failures']} |")
    if "standalone_c" in result:
        c = result["standalone_c"]
        lines.append(f"| rti-c, standalone C program | – | – | {c['median_us'] / 1e3:.3f} / {c['p95_us'] / 1e3:.3f} / "
                     f"{c['max_us'] / 1e3:.3f} | {100 * c['median_us'] / 1e3 / period:.1f} % | – |")
    if "controller_c" in result:
        c = result["controller_c"]
        lines.append(f"| whole controller in C (estimator included), feedback latency | – | – | "
                     f"{c['step_median_us'] / 1e3:.3f} / {c['step_p95_us'] / 1e3:.3f} / {c['step_max_us'] / 1e3:.3f} "
                     f"| {100 * c['step_median_us'] / 1e3 / period:.1f} % | {c['failures']:.0f} |")
        lines.append(f"| whole controller in C, prepare (after the input is sent) | – | – | "
                     f"{c['prepare_median_us'] / 1e3:.3f} / {c['prepare_p95_us'] / 1e3:.3f} / "
                     f"{c['prepare_max_us'] / 1e3:.3f} | {100 * c['prepare_median_us'] / 1e3 / period:.1f} % | – |")
    return "\n".join(lines)
