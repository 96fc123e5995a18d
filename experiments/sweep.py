"""Scenario sweeps: scenarios × controllers × seeds × plant perturbations, each an independent run.

A sweep is described by a TOML spec (interface.md). Every run is written atomically as its
own record (``records/<run id>.json``) by the process that drives the sweep, as soon as the
run ends, so a killed sweep loses at most the runs in flight; ``resume=True`` skips the
runs already recorded. Runs go to a local process pool or to a Dask cluster; a run that
raises becomes an ``error`` record and the sweep goes on. The summary gives, per scenario
and controller, the quartiles of the metrics and, per case (scenario, seed, perturbation
sample), how often ``nmpc`` beats each baseline and the best of them.
"""

from __future__ import annotations

import contextlib
import io
import json
import multiprocessing
import os
import sys
import time
import traceback
from collections.abc import Callable
from concurrent.futures import ProcessPoolExecutor, as_completed
from dataclasses import dataclass, field
from pathlib import Path
from typing import Any

import numpy as np

from hystmpc.experiments.sweep_spec import CHALLENGER, METRICS, SpecError, SweepSpec, run_id
from hystmpc.experiments.sweep_summary import summarize, summary_table, sweep_figures, write_summary_csv

WARNING_LINES_KEPT = 20
"""Solver warning lines a record keeps (the count is always kept)."""
RECORD_SCHEMA = "hystmpc.sweep-run/1"


@dataclass(frozen=True)
class RunTask:
    """One run of a sweep, self-contained so that it can be shipped to any worker."""

    run_id: str
    bench: str
    scenario: str
    controller: str
    seed: int
    sample: int
    overrides: tuple[str, ...]
    factors: dict[str, float]
    duration: float | None


def perturbation_factors(spec: SweepSpec, sample: int) -> dict[str, float]:
    """Relative factors of perturbation sample ``sample`` (seeded by ``perturb_seed`` and ``sample``).

    Parameters
    ----------
    spec : SweepSpec
        The sweep (its ``perturb`` amplitudes and ``perturb_seed``).
    sample : int
        The perturbation sample.

    Returns
    -------
    dict
        Per parameter key, a factor drawn from U(1 − a, 1 + a).
    """
    rng = np.random.default_rng([spec.perturb_seed, sample])
    return {key: float(1.0 + rng.uniform(-a, a)) for key, a in spec.perturb.items()}


def scaled_assignments(config: dict[str, Any], factors: dict[str, float]) -> list[str]:
    """``KEY=VALUE`` assignments scaling each parameter by its factor (tuples element-wise).

    Parameters
    ----------
    config : dict
        The configuration the values are read from.
    factors : dict
        Factor per parameter key (:func:`perturbation_factors`).

    Returns
    -------
    list of str
        One assignment per key.
    """
    from hystmpc.experiments.config import get_value
    assignments = []
    for key, factor in factors.items():
        value = get_value(config, key)
        if isinstance(value, tuple):
            assignments.append(f"{key}=" + ",".join(repr(factor * v) for v in value))
        else:
            assignments.append(f"{key}={factor * value!r}")
    return assignments


def make_tasks(spec: SweepSpec) -> list[RunTask]:
    """Every run of the sweep, in a fixed order.

    Parameters
    ----------
    spec : SweepSpec
        The sweep.

    Returns
    -------
    list of RunTask
        Per perturbation sample, scenario, seed and controller, in that nesting.
    """
    from hystmpc.experiments.benches import get_bench
    base = get_bench(spec.bench).configure(spec.overrides)
    tasks = []
    for sample in range(spec.samples):
        factors = perturbation_factors(spec, sample)
        overrides = spec.overrides + tuple(scaled_assignments(base, factors))
        for scenario in spec.scenarios:
            for seed in spec.seeds:
                for controller in spec.controllers:
                    tasks.append(RunTask(run_id(scenario, controller, seed, sample), spec.bench, scenario,
                                         controller, seed, sample, overrides, factors, spec.duration))
    return tasks


def execute(task: RunTask) -> dict[str, Any]:
    """Run one task and return its record; an exception inside the run becomes an ``error`` record.

    Parameters
    ----------
    task : RunTask
        The run.

    Returns
    -------
    dict
        The record (JSON-safe): the task, ``status``, the metrics, timing and guard (or the
        error and its traceback), ``elapsed_s`` and the solver warnings it printed.
    """
    from hystmpc.experiments.benches import get_bench
    from hystmpc.experiments.report import json_safe, version
    record: dict[str, Any] = {
        "schema": RECORD_SCHEMA, "run_id": task.run_id, "bench": task.bench, "scenario": task.scenario,
        "controller": task.controller, "seed": task.seed, "sample": task.sample,
        "perturbation": task.factors, "overrides": list(task.overrides), "version": version(),
    }
    start = time.perf_counter()
    warnings_text = io.StringIO()  # solver and CasADi warnings: to the sweep's solver.log, not the terminal
    try:
        bench = get_bench(task.bench)
        config = bench.configure(task.overrides)
        with contextlib.redirect_stderr(warnings_text):
            run = bench.run(task.scenario, task.controller, config, seed=task.seed, duration=task.duration)
        record.update(status="ok", metrics=run.metrics, timing=run.timing, guard=run.guard)
        if run.solver is not None:
            record["solver"] = run.solver
    except Exception as exc:  # noqa: BLE001 - a failed run is data, recorded with its cause
        record.update(status="error", error=f"{type(exc).__name__}: {exc}",
                      traceback=traceback.format_exc(limit=-4))
    record["elapsed_s"] = time.perf_counter() - start
    lines = warnings_text.getvalue().splitlines()
    if lines:
        record["solver_warnings"] = {"lines": len(lines), "first": lines[:WARNING_LINES_KEPT]}
    return json_safe(record)


def write_record(record: dict[str, Any], folder: Path) -> Path:
    """Write a record atomically: a temporary file in the same folder, flushed, then renamed.

    Parameters
    ----------
    record : dict
        The record (:func:`execute`).
    folder : Path
        The records folder (made if missing).

    Returns
    -------
    Path
        ``folder/<run id>.json``.
    """
    folder.mkdir(parents=True, exist_ok=True)
    final = folder / f"{record['run_id']}.json"
    tmp = folder / f".{record['run_id']}.json.tmp"
    with open(tmp, "w") as f:
        json.dump(record, f, indent=1)
        f.write("\n")
        f.flush()
        os.fsync(f.fileno())
    os.replace(tmp, final)
    return final


RECORD_FIELDS = {"run_id": str, "scenario": str, "controller": str, "seed": int, "sample": int, "status": str}


def _record_problem(record: Any, path: Path, expected: set[str] | None) -> str | None:
    """Why a stored record cannot be used (None: it can)."""
    if not isinstance(record, dict):
        return "not a JSON object"
    for key, kind in RECORD_FIELDS.items():
        if not isinstance(record.get(key), kind):
            return f"field {key!r} missing or not {kind.__name__}"
    if record["run_id"] != path.stem:
        return f"run_id {record['run_id']!r} does not match the file name"
    if expected is not None and record["run_id"] not in expected:
        return "not a run of this sweep's spec"
    if record["status"] not in ("ok", "error"):
        return f"status {record['status']!r} is neither ok nor error"
    if record["status"] == "ok":
        metrics = record.get("metrics")
        if not isinstance(metrics, dict) or not all(
                metrics.get(m) is None or isinstance(metrics.get(m), (int, float)) for m in METRICS):
            return "metrics missing or not numbers"
    return None


def read_records(folder: Path, expected: set[str] | None = None,
                 set_aside: Path | None = None) -> dict[str, dict[str, Any]]:
    """Usable records by run id (leftover temporary files of a killed sweep are removed).

    A record that does not parse, lacks a field, or belongs to no run of the spec is not used.

    Parameters
    ----------
    folder : Path
        The records folder (none: no records).
    expected : set of str, optional
        The spec's run ids (default: any run id).
    set_aside : Path, optional
        Where unusable records are moved, with a warning, so that their runs are redone and
        nothing is deleted (default: they stay).

    Returns
    -------
    dict
        Record per run id.
    """
    import logging
    records = {}
    if not folder.is_dir():
        return records
    for tmp in folder.glob(".*.json.tmp"):
        tmp.unlink()
    for path in sorted(folder.glob("*.json")):
        try:
            record = json.loads(path.read_text())
        except (OSError, UnicodeDecodeError, json.JSONDecodeError) as exc:
            problem = f"does not parse ({type(exc).__name__})"
        else:
            problem = _record_problem(record, path, expected)
        if problem is None:
            records[path.stem] = record
        elif set_aside is not None:
            set_aside.mkdir(parents=True, exist_ok=True)
            target, n = set_aside / path.name, 1
            while target.exists():  # an earlier resume set one aside under that name: keep both
                n += 1
                target = set_aside / f"{path.stem}.{n}.json"
            os.replace(path, target)
            logging.getLogger("hystmpc").warning(f"record {path.name} {problem}: moved to {target}; "
                                                 "its run is redone")
    return records


def _run_local(tasks: list[RunTask], workers: int, on_done: Callable[[dict], None]) -> None:
    # spawn, not fork: CasADi/IPOPT and BLAS threads in a forked child are not safe
    with ProcessPoolExecutor(max_workers=workers, mp_context=multiprocessing.get_context("spawn")) as pool:
        futures = [pool.submit(execute, task) for task in tasks]
        try:
            for future in as_completed(futures):
                on_done(future.result())
        except BaseException:
            for future in futures:
                future.cancel()
            raise


def _run_dask(tasks: list[RunTask], workers: int, scheduler: str | None, on_done: Callable[[dict], None]) -> None:
    try:
        from dask.distributed import Client, LocalCluster
        from dask.distributed import as_completed as dask_completed
    except ImportError:
        raise SpecError("--executor dask needs dask.distributed: pip install 'hystmpc[cluster]'") from None
    import logging
    cluster = None
    if scheduler is None:
        cluster = LocalCluster(n_workers=workers, threads_per_worker=1, processes=True, dashboard_address=None,
                               silence_logs=logging.ERROR)
    try:
        with Client(scheduler if scheduler is not None else cluster) as client:
            futures = client.map(execute, tasks, pure=False)
            for future in dask_completed(futures):
                on_done(future.result())
    finally:
        if cluster is not None:
            cluster.close()


@dataclass
class SweepOutcome:
    """What a sweep call did."""

    out: Path
    summary: dict[str, Any]
    ran: int
    skipped: int
    failed: int
    wall_s: float
    figures: list[Path] = field(default_factory=list)


def run_sweep(spec: SweepSpec, out: Path, workers: int | None = None, executor: str = "local",
              scheduler: str | None = None, resume: bool = False, plots: bool = True, quiet: bool = False,
              spec_text: str | None = None, retry_failed: bool = False) -> SweepOutcome:
    """Run (or finish) a sweep into ``out``; see the module docstring.

    Parameters
    ----------
    spec : SweepSpec
        From :func:`load_spec`.
    out : Path
        Results folder: ``sweep.json`` (the spec), ``records/``, ``summary.json``, ``summary.csv``,
        ``summary.md`` and figures.
    workers : int, optional
        Worker processes (default: the core count).
    executor : {"local", "dask"}, optional
        Local process pool, or ``dask.distributed``.
    scheduler : str, optional
        Address of a running Dask scheduler (with ``executor="dask"``); a ``LocalCluster`` otherwise.
    resume : bool, optional
        Skip the runs ``out`` already holds; ``out`` must hold a sweep of the same spec.
        Records that cannot be used are moved to ``out/set-aside/`` and their runs redone.
    plots : bool, optional
        Draw the figures.
    quiet : bool, optional
        No progress bar, and no line per finished run (written to stderr when it is not a terminal).
    spec_text : str, optional
        The spec's TOML text, written to ``out/spec.toml`` when the sweep starts.
    retry_failed : bool, optional
        With ``resume``, also redo the runs recorded as errors.

    Returns
    -------
    SweepOutcome
        The folder, the summary, the runs made, skipped and failed, the wall time (s) and the figures.
    """
    from hystmpc.experiments.benches import get_bench
    from hystmpc.experiments.report import environment, version

    workers = workers or os.cpu_count() or 1
    if executor not in ("local", "dask"):
        raise SpecError(f"unknown executor {executor!r}; allowed: local, dask")
    if scheduler is not None and executor != "dask":
        raise SpecError("--scheduler is the address of a Dask scheduler: use it with --executor dask")
    out = Path(out)
    records_dir = out / "records"
    stored = out / "sweep.json"
    if retry_failed and not resume:
        raise SpecError("--retry-failed redoes the failed runs of a sweep: use it with --resume")
    if out.exists() and not out.is_dir():
        raise SpecError(f"--out {str(out)!r} is a file; give a folder")
    if stored.exists():
        try:
            previous = json.loads(stored.read_text())
            previous = previous.get("spec") if isinstance(previous, dict) else None
        except (OSError, UnicodeDecodeError, json.JSONDecodeError) as exc:
            raise SpecError(f"{stored} cannot be read ({type(exc).__name__}); it is not the record of a sweep "
                            "this version can finish: choose another --out") from None
        if not resume:
            raise SpecError(f"{out} already holds a sweep; add --resume to finish it, or choose another --out")
        if previous != spec.as_dict():
            changed = sorted(k for k in spec.as_dict() if previous is None or previous.get(k) != spec.as_dict()[k])
            raise SpecError(f"--resume: the spec differs from the one {out} was started with "
                            f"(changed: {', '.join(changed)})")
    elif resume:
        raise SpecError(f"--resume: nothing to resume in {out} (no sweep.json)")
    elif out.is_dir() and any(out.iterdir()):
        raise SpecError(f"--out {str(out)!r} is not empty and holds no sweep; choose another folder")
    out.mkdir(parents=True, exist_ok=True)
    if not stored.exists():
        stored.write_text(json.dumps({"schema": "hystmpc.sweep/1", "version": version(), "spec": spec.as_dict(),
                                      "n_runs": spec.n_runs}, indent=1) + "\n")
        if spec_text is not None:
            (out / "spec.toml").write_text(spec_text)

    tasks = make_tasks(spec)
    expected = {t.run_id for t in tasks}
    done = read_records(records_dir, expected, out / "set-aside")
    if retry_failed:
        done = {k: r for k, r in done.items() if r["status"] == "ok"}
    pending = [t for t in tasks if t.run_id not in done]
    # the expensive controller first, so the pool is not left with one long run at the end
    pending.sort(key=lambda t: t.controller != CHALLENGER)
    failed = 0
    finished = len(tasks) - len(pending)
    start = time.perf_counter()
    from tqdm import tqdm
    log_lines = not quiet and not sys.stderr.isatty()
    with tqdm(total=len(tasks), initial=len(tasks) - len(pending), unit="run", disable=True if quiet else None,
              dynamic_ncols=True, desc=f"sweep {spec.bench}") as bar:
        def on_done(record):
            nonlocal failed, finished
            write_record(record, records_dir)
            if record.get("solver_warnings"):
                with open(out / "solver.log", "a") as log:
                    w = record["solver_warnings"]
                    log.write(f"== {record['run_id']}: {w['lines']} lines, the first {len(w['first'])}:\n"
                              + "\n".join(w["first"]) + "\n")
            failed += record["status"] != "ok"
            finished += 1
            bar.update(1)
            bar.set_postfix(failed=failed, refresh=False)
            if log_lines:
                what = (f"rmse {record['metrics']['rmse']:.4g}" if record["status"] == "ok"
                        else f"FAILED {record['error']}")
                print(f"[{finished}/{len(tasks)}] {record['run_id']}: {what} ({record['elapsed_s']:.1f} s)",
                      file=sys.stderr, flush=True)

        if pending:
            if executor == "local":
                _run_local(pending, min(workers, len(pending)), on_done)
            else:
                _run_dask(pending, workers, scheduler, on_done)
    wall = time.perf_counter() - start

    records = read_records(records_dir, expected, out / "set-aside")
    summary = summarize(spec, records)
    summary["run_info"] = {"version": version(), "environment": environment(), "executor": executor,
                           "workers": workers, "scheduler": scheduler, "ran": len(pending),
                           "skipped": len(tasks) - len(pending), "wall_s": wall}
    from hystmpc.experiments.report import json_safe
    summary = json_safe(summary)
    (out / "summary.json").write_text(json.dumps(summary, indent=1) + "\n")
    write_summary_csv(summary, out / "summary.csv")
    units = get_bench(spec.bench).units
    (out / "summary.md").write_text(summary_table(summary, units) + "\n")
    figures = sweep_figures(spec, records, out, units) if plots else []
    return SweepOutcome(out=out, summary=summary, ran=len(pending), skipped=len(tasks) - len(pending),
                        failed=failed, wall_s=wall, figures=figures)
