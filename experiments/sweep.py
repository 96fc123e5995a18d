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
import csv
import io
import json
import math
import multiprocessing
import os
import sys
import time
import tomllib
import traceback
from collections.abc import Callable, Iterable
from concurrent.futures import ProcessPoolExecutor, as_completed
from dataclasses import asdict, dataclass, field
from pathlib import Path
from typing import Any

import numpy as np

SPEC_KEYS = ("bench", "scenarios", "controllers", "seeds", "perturb", "duration", "set", "perturb_seed")
METRICS = ("rmse", "mae", "max_abs_error", "input_tv", "oscillation_cycles")
CHALLENGER = "nmpc"
"""The controller whose wins against the others the summary counts."""
WARNING_LINES_KEPT = 20
"""Solver warning lines a record keeps (the count is always kept)."""
RECORD_SCHEMA = "hystmpc.sweep-run/1"
SUMMARY_SCHEMA = "hystmpc.sweep-summary/1"


class SpecError(ValueError):
    """A sweep spec (or its combination with the command line) that cannot be run."""


@dataclass(frozen=True)
class SweepSpec:
    """What to run: the full factorial of scenarios, controllers, seeds and perturbation samples."""

    bench: str
    scenarios: tuple[str, ...]
    controllers: tuple[str, ...]
    seeds: tuple[int, ...] = (0,)
    perturb: dict[str, float] = field(default_factory=dict)
    """Relative amplitude per parameter key: each sample scales the value by U(1 − a, 1 + a)."""
    samples: int = 1
    """Perturbed plants per (scenario, seed); the same plants for every controller."""
    duration: float | None = None
    overrides: tuple[str, ...] = ()
    """``KEY=VALUE`` assignments applied to every run before the perturbation."""
    perturb_seed: int = 0

    @property
    def n_runs(self) -> int:
        """Number of runs in the sweep."""
        return len(self.scenarios) * len(self.controllers) * len(self.seeds) * self.samples

    def as_dict(self) -> dict[str, Any]:
        """JSON-ready form (stored beside the records, compared on resume)."""
        d = asdict(self)
        for key in ("scenarios", "controllers", "seeds", "overrides"):
            d[key] = list(d[key])
        return d


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


def _fail(path, message: str):
    raise SpecError(f"{path}: {message}")


def _string_list(path, raw: dict, key: str, allowed: Iterable[str], default: list[str]) -> tuple[str, ...]:
    value = raw.get(key, default)
    if isinstance(value, str):
        value = [value]
    if not isinstance(value, list) or not value or not all(isinstance(v, str) for v in value):
        _fail(path, f"{key} must be a non-empty list of names")
    allowed = list(allowed)
    for name in value:
        if name not in allowed:
            _fail(path, f"unknown {key[:-1]} {name!r}; allowed: {', '.join(allowed)}")
    if len(set(value)) != len(value):
        _fail(path, f"{key} names a {key[:-1]} twice: {value}")
    return tuple(value)


def load_spec(path: str | Path, extra_overrides: Iterable[str] = (), duration: float | None = None,
              force: bool = False) -> SweepSpec:
    """Read and check a sweep spec.

    Parameters
    ----------
    path : str or Path
        TOML file (format in interface.md).
    extra_overrides : iterable of str
        ``KEY=VALUE`` assignments from the command line, applied after the spec's ``set``.
    duration : float, optional
        Run length (s) from the command line; replaces the spec's ``duration``.
    force : bool
        Lift the work ceilings of :mod:`hystmpc.experiments.limits` (horizon, samples per
        run, runs and samples per sweep).

    Raises
    ------
    SpecError
        Naming the file, the bad entry and what is allowed.
    """
    from hystmpc.experiments.benches import get_bench, is_actuator_file
    from hystmpc.experiments.config import allowed_keys, get_value, unknown_key

    path = Path(path)
    try:
        raw = tomllib.loads(path.read_text())
    except FileNotFoundError:
        raise SpecError(f"sweep spec {str(path)!r} not found") from None
    except (OSError, UnicodeDecodeError) as exc:
        raise SpecError(f"sweep spec {str(path)!r} cannot be read: {exc}") from None
    except tomllib.TOMLDecodeError as exc:
        raise SpecError(f"{path}: not valid TOML: {exc}") from None
    unknown = sorted(set(raw) - set(SPEC_KEYS))
    if unknown:
        _fail(path, f"unknown key {unknown[0]!r}; allowed: {', '.join(SPEC_KEYS)}")
    if not isinstance(raw.get("bench"), str):
        _fail(path, f"bench = {raw.get('bench')!r}; a bench name or an actuator file (relative to the spec)")
    if is_actuator_file(raw["bench"]):  # workers find it by its absolute path
        raw["bench"] = str((path.parent / raw["bench"]).resolve())
    try:
        bench = get_bench(raw["bench"])
    except ValueError as exc:
        _fail(path, f"bench: {exc}")
    scenarios = _string_list(path, raw, "scenarios", bench.scenarios, [bench.default_scenario])
    controllers = _string_list(path, raw, "controllers", bench.controllers, list(bench.controllers))
    seeds = raw.get("seeds", [0])
    if (not isinstance(seeds, list) or not seeds or not all(isinstance(s, int) and s >= 0 for s in seeds)
            or len(set(seeds)) != len(seeds)):
        _fail(path, f"seeds must be a non-empty list of distinct integers >= 0, got {seeds!r}")
    perturb_seed = raw.get("perturb_seed", 0)
    if not isinstance(perturb_seed, int) or perturb_seed < 0:
        _fail(path, f"perturb_seed must be an integer >= 0, got {perturb_seed!r}")
    if duration is None:
        duration = raw.get("duration")
    if duration is not None and (isinstance(duration, bool) or not isinstance(duration, (int, float))
                                 or not math.isfinite(duration) or not duration > 0):
        _fail(path, f"duration must be a finite number of seconds > 0, got {duration!r}")
    overrides = raw.get("set", [])
    if not isinstance(overrides, list) or not all(isinstance(o, str) for o in overrides):
        _fail(path, "set must be a list of 'KEY=VALUE' strings")
    overrides = tuple(overrides) + tuple(extra_overrides)
    try:
        config = bench.configure(overrides)
    except ValueError as exc:
        _fail(path, str(exc))

    if not isinstance(raw.get("perturb", {}), dict):
        _fail(path, f"perturb must be a table of KEY = relative amplitude, plus samples = N; got "
                    f"{raw['perturb']!r}")
    perturb = dict(raw.get("perturb", {}))
    samples = perturb.pop("samples", 10 if perturb else 1)
    if isinstance(samples, bool) or not isinstance(samples, int) or samples < 1:
        _fail(path, f"perturb.samples must be an integer >= 1, got {samples!r}")
    allowed = allowed_keys(config)
    fixed = {c.split("=", 1)[0] for name in scenarios for c in bench.scenarios[name].conditions}
    for key, amplitude in perturb.items():
        if key not in allowed:
            _fail(path, str(unknown_key(key, config)).replace("--set key", "perturb key"))
        if key in fixed:
            _fail(path, f"perturb key {key!r} is fixed by the scenarios; perturb another parameter")
        value = get_value(config, key)
        real = isinstance(value, float) or (isinstance(value, tuple) and all(isinstance(v, float) for v in value))
        if not real:
            _fail(path, f"perturb key {key!r} is not a real-valued parameter (it is {value!r})")
        if isinstance(amplitude, bool) or not isinstance(amplitude, (int, float)) or not 0 < amplitude < 1:
            _fail(path, f"perturb amplitude of {key!r} must be a number in (0, 1), got {amplitude!r}")
    spec = SweepSpec(bench=raw["bench"], scenarios=scenarios, controllers=controllers, seeds=tuple(seeds),
                     perturb={k: float(v) for k, v in sorted(perturb.items())}, samples=samples,
                     duration=None if duration is None else float(duration), overrides=overrides,
                     perturb_seed=perturb_seed)
    from hystmpc.experiments.limits import check_horizons, check_run_samples, check_sweep, run_samples
    try:
        per_scenario = {name: run_samples(spec.duration or bench.scenarios[name].duration, bench.sample_period,
                                          "duration") for name in scenarios}
        for name, n in per_scenario.items():
            check_run_samples(n, f"a run of {name}", force)
        check_horizons(config, force)
        if "nmpc" in controllers:
            from hystmpc.experiments.firmware import check_runtime
            check_runtime(config)
            config["nmpc"].check_combination(config.get("solver"))
        check_sweep(spec.n_runs, sum(per_scenario.values()) * spec.n_runs // len(scenarios), force)
    except ValueError as exc:
        _fail(path, str(exc))
    return spec


def perturbation_factors(spec: SweepSpec, sample: int) -> dict[str, float]:
    """Relative factors of perturbation sample ``sample`` (seeded by ``perturb_seed`` and ``sample``)."""
    rng = np.random.default_rng([spec.perturb_seed, sample])
    return {key: float(1.0 + rng.uniform(-a, a)) for key, a in spec.perturb.items()}


def scaled_assignments(config: dict[str, Any], factors: dict[str, float]) -> list[str]:
    """``KEY=VALUE`` assignments scaling each parameter by its factor (tuples element-wise)."""
    from hystmpc.experiments.config import get_value
    assignments = []
    for key, factor in factors.items():
        value = get_value(config, key)
        if isinstance(value, tuple):
            assignments.append(f"{key}=" + ",".join(repr(factor * v) for v in value))
        else:
            assignments.append(f"{key}={factor * value!r}")
    return assignments


def run_id(scenario: str, controller: str, seed: int, sample: int) -> str:
    """Name of a run's record: ``<scenario>__<controller>__s<seed>__p<sample>``."""
    return f"{scenario}__{controller}__s{seed}__p{sample:04d}"


def make_tasks(spec: SweepSpec) -> list[RunTask]:
    """Every run of the sweep, in a fixed order."""
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
    """Run one task and return its record; an exception inside the run becomes an ``error`` record."""
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
    """Write a record atomically: a temporary file in the same folder, flushed, then renamed."""
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

    A record that does not parse, lacks a field, or (with ``expected``, the spec's run ids)
    belongs to no run of the spec is not used; with ``set_aside`` it is moved there, with
    a warning, so that its run is redone and nothing is deleted.
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


def _quartiles(values: list[float]) -> dict[str, float | None]:
    if not values:
        return {"q1": None, "median": None, "q3": None, "min": None, "max": None}
    q1, med, q3 = np.percentile(values, [25, 50, 75])
    return {"q1": float(q1), "median": float(med), "q3": float(q3), "min": float(min(values)),
            "max": float(max(values))}


def _rate(wins: int, compared: int) -> dict[str, Any]:
    return {"wins": wins, "compared": compared, "rate": wins / compared if compared else None}


def summarize(spec: SweepSpec, records: dict[str, dict[str, Any]], metric: str = "rmse") -> dict[str, Any]:
    """Per scenario and controller: run and failure counts, quartiles of the metrics; win rates of nmpc.

    A *case* is one (scenario, seed, perturbation sample): the same plant and noise for every
    controller. ``nmpc`` wins against a baseline in a case when its ``metric`` is strictly
    lower; a failed nmpc run loses the case, a case whose baseline failed is not compared.
    The result depends on the records only, not on the order they arrived in.
    """
    groups = []
    for scenario in spec.scenarios:
        for controller in spec.controllers:
            rs = [r for r in records.values() if r["scenario"] == scenario and r["controller"] == controller]
            ok = [r for r in rs if r["status"] == "ok"]
            group = {"scenario": scenario, "controller": controller, "runs": len(rs),
                     "failed": len(rs) - len(ok)}
            for m in METRICS:
                group[m] = _quartiles([r["metrics"][m] for r in ok if r["metrics"].get(m) is not None])
            group["oscillating"] = int(sum(bool(r["metrics"].get("oscillating")) for r in ok))
            group["guard_clips"] = int(sum((r.get("guard") or {}).get("clips", 0) for r in ok))
            if any("solver" in r for r in ok):
                group["solver_failures"] = int(sum(r.get("solver", {}).get("failures", 0) for r in ok))
                group["fallbacks"] = int(sum(r.get("solver", {}).get("fallbacks", 0) for r in ok))
            groups.append(group)

    summary: dict[str, Any] = {
        "schema": SUMMARY_SCHEMA, "bench": spec.bench, "metric": metric, "spec": spec.as_dict(),
        "runs_expected": spec.n_runs, "runs_recorded": len(records),
        "runs_failed": sum(r["status"] != "ok" for r in records.values()), "groups": groups,
    }
    baselines = [c for c in spec.controllers if c != CHALLENGER]
    if CHALLENGER in spec.controllers and baselines:
        summary["win_rates"] = {name: _win_rates(spec, records, metric, baselines, scenarios)
                                for name, scenarios in [("all", spec.scenarios)] + [(s, (s,)) for s in spec.scenarios]}
    return summary


def _win_rates(spec, records, metric, baselines, scenarios) -> dict[str, Any]:
    def value(scenario, controller, seed, sample):
        r = records.get(run_id(scenario, controller, seed, sample))
        if r is None:
            return None  # not run yet
        return r["metrics"][metric] if r["status"] == "ok" else math.inf

    wins = {b: [0, 0] for b in baselines}
    best = [0, 0]
    ratios = []
    for scenario in scenarios:
        for seed in spec.seeds:
            for sample in range(spec.samples):
                mine = value(scenario, CHALLENGER, seed, sample)
                if mine is None:
                    continue
                theirs = {b: value(scenario, b, seed, sample) for b in baselines}
                for b, v in theirs.items():
                    if v is not None and math.isfinite(v):
                        wins[b][0] += mine < v
                        wins[b][1] += 1
                if all(v is not None and math.isfinite(v) for v in theirs.values()):
                    best_value = min(theirs.values())
                    best[0] += mine < best_value
                    best[1] += 1
                    if math.isfinite(mine) and best_value > 0:
                        ratios.append(mine / best_value)
    return {"vs": {b: _rate(*wins[b]) for b in baselines}, "vs_best_baseline": _rate(*best),
            f"{metric}_ratio_to_best_baseline": _quartiles(ratios)}


def write_summary_csv(summary: dict[str, Any], path: Path) -> None:
    """One row per scenario and controller; ``nmpc_win_rate`` is nmpc's rate against that row's controller."""
    wins = summary.get("win_rates", {})
    with open(path, "w", newline="") as f:
        writer = csv.writer(f)
        writer.writerow(["scenario", "controller", "runs", "failed", "oscillating"]
                        + [f"{m}_{q}" for m in METRICS for q in ("q1", "median", "q3")]
                        + ["nmpc_win_rate", "nmpc_win_rate_vs_best_baseline"])
        for g in summary["groups"]:
            rates = wins.get(g["scenario"], {})
            vs = rates.get("vs", {}).get(g["controller"], {}).get("rate")
            best = rates.get("vs_best_baseline", {}).get("rate") if g["controller"] == CHALLENGER else None
            writer.writerow([g["scenario"], g["controller"], g["runs"], g["failed"], g.get("oscillating", "")]
                            + [_fmt(g[m][q]) for m in METRICS for q in ("q1", "median", "q3")]
                            + [_fmt(vs), _fmt(best)])


def _fmt(value) -> str:
    return "" if value is None else f"{value:.6g}"


def summary_table(summary: dict[str, Any], units: str) -> str:
    """Markdown table: per scenario and controller, RMSE quartiles, failures and nmpc's win rate."""
    lines = [f"| scenario | controller | runs | failed | oscillating | RMSE median [{units}] | RMSE q1–q3 | "
             "input TV median | nmpc wins |",
             "|---|---|---:|---:|---:|---:|---|---:|---:|"]
    wins = summary.get("win_rates", {})
    for g in summary["groups"]:
        r = g["rmse"]
        rates = wins.get(g["scenario"], {})
        if g["controller"] == CHALLENGER:
            rate = rates.get("vs_best_baseline", {})
            label = "vs best"
        else:
            rate = rates.get("vs", {}).get(g["controller"], {})
            label = ""
        win = f"{rate['rate']:.0%} of {rate['compared']} {label}".strip() if rate.get("rate") is not None else "–"
        spread = f"{r['q1']:.4g}–{r['q3']:.4g}" if r["median"] is not None else "–"
        median = f"{r['median']:.4g}" if r["median"] is not None else "–"
        tv = g.get("input_tv", {}).get("median")
        lines.append(f"| {g['scenario']} | {g['controller']} | {g['runs']} | {g['failed']} | "
                     f"{g.get('oscillating', '–')} | {median} | {spread} | {'–' if tv is None else f'{tv:.4g}'} | "
                     f"{win} |")
    return "\n".join(lines)


def sweep_figures(spec: SweepSpec, records: dict[str, dict[str, Any]], out: Path, units: str) -> list[Path]:
    """Box plots of RMSE per controller (one panel per scenario) and nmpc against the best baseline."""
    import matplotlib
    matplotlib.use("Agg")
    import matplotlib.pyplot as plt

    paths = []
    fig, axes = plt.subplots(1, len(spec.scenarios), figsize=(3.2 + 2.2 * len(spec.scenarios), 3.8), squeeze=False)
    for ax, scenario in zip(axes[0], spec.scenarios, strict=True):
        data = [[r["metrics"]["rmse"] for r in records.values() if r["status"] == "ok"
                 and r["scenario"] == scenario and r["controller"] == c] for c in spec.controllers]
        ax.boxplot([d if d else [np.nan] for d in data], tick_labels=list(spec.controllers))
        positive = [v for d in data for v in d if v > 0]
        if positive and max(positive) / min(positive) > 20:
            _log_axis(ax.yaxis, ax.set_yscale)
        ax.set_title(scenario, fontsize=9)
        ax.set_ylabel(f"RMSE [{units}]")
        ax.tick_params(axis="x", labelrotation=30, labelsize=8)
        ax.grid(alpha=0.3)
    perturbed = (f"{len(spec.perturb)} parameters perturbed by up to ±{max(spec.perturb.values()):.0%}"
                 if spec.perturb else "no perturbation")
    fig.suptitle(f"{spec.bench}: {spec.n_runs} runs, {perturbed}", fontsize=9)
    fig.tight_layout()
    paths.append(out / "rmse_box.png")
    fig.savefig(paths[-1], dpi=120)
    plt.close(fig)

    baselines = [c for c in spec.controllers if c != CHALLENGER]
    if CHALLENGER in spec.controllers and baselines:
        fig, ax = plt.subplots(figsize=(4.6, 4.4))
        for scenario in spec.scenarios:
            xs, ys = [], []
            for seed in spec.seeds:
                for sample in range(spec.samples):
                    rs = [records.get(run_id(scenario, c, seed, sample)) for c in spec.controllers]
                    if all(r is not None and r["status"] == "ok" for r in rs):
                        values = {c: r["metrics"]["rmse"] for c, r in zip(spec.controllers, rs, strict=True)}
                        xs.append(min(values[b] for b in baselines))
                        ys.append(values[CHALLENGER])
            ax.scatter(xs, ys, s=12, alpha=0.7, label=scenario)
        values = [v for line in ax.collections for v in line.get_offsets().ravel() if v > 0]
        low, top = (min(values), max(values)) if values else (1e-3, 1.0)
        if top / low > 20:
            _log_axis(ax.xaxis, ax.set_xscale)
            _log_axis(ax.yaxis, ax.set_yscale)
            low, top = low / 1.5, top * 1.5
        else:
            low, top = 0.0, 1.05 * top
        ax.plot([low, top], [low, top], "k--", lw=0.8, label="equal")
        ax.set_xlim(low, top)
        ax.set_ylim(low, top)
        ax.set_xlabel(f"best baseline RMSE [{units}]")
        ax.set_ylabel(f"nmpc RMSE [{units}]")
        ax.set_title("each point: one plant and noise realisation", fontsize=9)
        ax.legend(fontsize=7)
        ax.grid(alpha=0.3)
        fig.tight_layout()
        paths.append(out / "nmpc_vs_best_baseline.png")
        fig.savefig(paths[-1], dpi=120)
        plt.close(fig)
    return paths


def _log_axis(axis, set_scale) -> None:
    from matplotlib.ticker import FormatStrFormatter, LogLocator, NullFormatter
    set_scale("log")
    axis.set_major_locator(LogLocator(subs=(1.0, 2.0, 5.0)))
    axis.set_major_formatter(FormatStrFormatter("%g"))
    axis.set_minor_formatter(NullFormatter())


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
    executor : {"local", "dask"}
        Local process pool, or ``dask.distributed``.
    scheduler : str, optional
        Address of a running Dask scheduler (with ``executor="dask"``); a ``LocalCluster`` otherwise.
    resume : bool
        Skip the runs ``out`` already holds; ``out`` must hold a sweep of the same spec.
        Records that cannot be used are moved to ``out/set-aside/`` and their runs redone.
    retry_failed : bool
        With ``resume``, also redo the runs recorded as errors.
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
