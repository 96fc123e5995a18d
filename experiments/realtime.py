"""The ``hystmpc codegen`` and ``hystmpc speed`` commands on a bench.

``codegen`` writes the bench's RTI step (:mod:`hystmpc.mpc.rti`) as C99 with a replay program
(:mod:`hystmpc.mpc.codegen.step`; needs libm and, with the default QP, the DAQP library that
CasADi ships) and, where the bench's controller allows it, the whole controller
(:mod:`hystmpc.experiments.firmware`, in ``<out>/controller``); ``verify`` runs the bench's
default scenario closed loop with the in-process and with the compiled step and reports the
largest difference in applied input. ``speed`` times each solver variant on that scenario.
"""

from __future__ import annotations

import shutil
import time
from dataclasses import replace
from pathlib import Path

import casadi as ca
import numpy as np

from hystmpc.experiments.bench import Bench
from hystmpc.experiments.firmware import verify_controller, write_controller
from hystmpc.mpc.codegen import RecordingStep, cross_compile, run_program, write_step
from hystmpc.mpc.embedded import NotGeneratable
from hystmpc.mpc.settings import MULTISTART_SOLVERS


def _problem_of(controller):
    problem = getattr(controller, "problem", None)
    if getattr(problem, "rti", None) is None:
        raise ValueError("this bench's nmpc has no RTI step")
    return problem


def check_codegen_settings(bench: Bench, config: dict) -> None:
    """``ValueError`` for an NMPC setting that ``codegen`` and ``speed`` do not read.

    Such a setting is a runtime other than the bench's default (cheap: checked before any work).
    ``ValueError`` also when the bench has no NMPC settings.

    Parameters
    ----------
    bench : Bench
        The bench.
    config : dict
        Its parameter groups, as configured.
    """
    if "nmpc" not in config:
        raise ValueError(f"bench {bench.name!r} has no nmpc settings")
    runtime, default = config["nmpc"].runtime, bench.configure(tuned=False)["nmpc"].runtime
    if runtime != default:  # the bench's default says nothing here
        raise ValueError(f"nmpc.runtime={runtime} chooses where run, compare and sweep run the controller; "
                         "codegen writes the generated controller and speed times the solver variants whatever "
                         f"it says: drop the setting here (this bench's default: {default})")


def _rti_config(bench: Bench, config: dict, solver: str) -> dict:
    """``config`` with ``solver``, run in Python.

    It has two starts where the bench has them and the solver reports the cost they compare
    (IPOPT and sqp are timed with one).
    """
    check_codegen_settings(bench, config)
    multistart = config["nmpc"].multistart and solver in MULTISTART_SOLVERS
    return {**config, "nmpc": replace(config["nmpc"], solver=solver, runtime="python", multistart=multistart)}


def write_solver(bench: Bench, config: dict, out: Path) -> ca.Function:
    """Write the bench's RTI step as C into ``out``, build it, and return the compiled step.

    The C comes with a header, ``main.c`` and a Makefile; the build makes the shared library and
    the replay program, and the compiled step is loaded back
    (:func:`hystmpc.mpc.codegen.write_step`).

    Parameters
    ----------
    bench : Bench
        The bench.
    config : dict
        Its parameter groups; the NMPC's solver is set to ``rti``.
    out : Path
        The folder to write into.

    Returns
    -------
    casadi.Function
        The compiled step.
    """
    config = _rti_config(bench, config, "rti")
    return write_step(_problem_of(bench.build_controller("nmpc", config)).rti, out)


def codegen(bench: Bench, config: dict, out: Path, verify: bool, duration: float | None = None,
            target: str | None = None) -> dict:
    """``hystmpc codegen``: write and build the C solver.

    With ``verify``, replay the default scenario closed loop with both solvers and run the
    standalone program on its inputs; with ``target='cortex-m7'``, also cross-compile the whole
    controller and report its size.

    Parameters
    ----------
    bench : Bench
        The bench.
    config : dict
        Its parameter groups.
    out : Path
        The folder to write into (the whole controller in ``<out>/controller``).
    verify : bool
        Also run the closed-loop and standalone comparisons.
    duration : float, optional
        Length of the verification run (s); default: the scenario's.
    target : str, optional
        ``cortex-m7`` or None.

    Returns
    -------
    dict
        The report: bench, folder, files written and the whole controller's report (or why it
        was skipped); with ``verify``, also the scenario, the samples, the largest input
        difference, both runs' RMSE and the standalone program's differences and timing.
    """
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
    """``hystmpc speed``: per-step compute of each solver variant on the default scenario.

    Parameters
    ----------
    bench : Bench
        The bench.
    config : dict
        Its parameter groups.
    variants : iterable of str
        NMPC solver names to time; with ``rti-c`` and ``out``, the generated C is also
        built, verified and timed (:func:`codegen`).
    duration : float, optional
        Length of each run (s); default: the scenario's.
    out : Path, optional
        Folder for the generated C.

    Returns
    -------
    dict
        Bench, scenario, sample period (ms) and per variant its RMSE, step and solve timing,
        failures and wall time; ``standalone_c`` and ``controller_c`` for the generated C.
    """
    scenario = bench.scenarios[bench.default_scenario]
    period_ms = 1e3 * bench.sample_period
    rows = []
    for variant in variants:
        variant_config = _rti_config(bench, config, variant)
        prepared = bench.prepare(scenario, "nmpc", variant_config)
        start = time.perf_counter()
        run = bench.run(scenario, "nmpc", duration=duration, prepared=prepared)
        solve_ms = 1e3 * np.asarray(getattr(prepared.controller, "solve_times", [np.nan]))
        nmpc = variant_config["nmpc"]
        rows.append({"variant": variant, "multistart": nmpc.multistart,
                     "second_start_error": nmpc.second_start_error if nmpc.multistart else None,
                     "second_starts": getattr(prepared.controller, "second_starts", None) if nmpc.multistart else None,
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
    """Markdown table of :func:`speed`'s result.

    Parameters
    ----------
    result : dict
        What :func:`speed` returned.

    Returns
    -------
    str
        A title line, then the table.
    """
    period = result["sample_period_ms"]
    lines = [f"{result['bench']} · {result['scenario']} · sample period {period:g} ms", "",
             "| variant | RMSE | step ms median / p95 / max | solve ms median / p95 / max "
             "| median % of period | failures |",
             "|---|---|---|---|---|---|"]
    for r in result["variants"]:
        variant = r["variant"]
        if r.get("multistart"):
            variant += (", two starts" if not r.get("second_start_error") else
                        f", a second start on {r['second_starts']} samples" if r.get("second_starts") is not None else
                        ", a second start where the first plan misses")
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
