"""Result documents (``hystmpc.results/1``), per-run CSV trajectories and the comparison table."""

from __future__ import annotations

import csv
import datetime as dt
import json
import math
from pathlib import Path
from typing import TYPE_CHECKING

import numpy as np

if TYPE_CHECKING:  # runs are made by the runner, which writes itself through json_safe
    from hystmpc.experiments.runner import RunResult

SCHEMA = "hystmpc.results/1"


def version() -> str:
    """Installed hystmpc version (or ``0+unknown`` when running from a bare checkout).

    Returns
    -------
    str
        The version string.
    """
    from importlib.metadata import PackageNotFoundError
    from importlib.metadata import version as _version
    try:
        return _version("hystmpc")
    except PackageNotFoundError:
        return "0+unknown"


ENVIRONMENT_PACKAGES = ("casadi", "numpy", "scipy", "osqp")
"""Libraries whose version can move a closed loop's last digits (docs/realtime.md)."""


def environment() -> dict[str, str]:
    """What else made a result: Python, the numerical libraries' versions and the CPU architecture.

    The same command can differ in its last digits across these.

    Returns
    -------
    dict
        ``python``, ``machine`` and each of :data:`ENVIRONMENT_PACKAGES` to its version
        (``not installed`` when missing).
    """
    import platform
    from importlib.metadata import PackageNotFoundError
    from importlib.metadata import version as _version
    out = {"python": platform.python_version(), "machine": platform.machine()}
    for name in ENVIRONMENT_PACKAGES:
        try:
            out[name] = _version(name)
        except PackageNotFoundError:
            out[name] = "not installed"
    return out


def results_document(bench: str, runs: list[RunResult], command: list[str] | None = None) -> dict:
    """The full result document (``hystmpc.results/1``) for a list of runs on bench ``bench``.

    Parameters
    ----------
    bench : str
        Name of the bench.
    runs : list of RunResult
        The runs, in the document's order.
    command : list of str, optional
        The command line that made the runs, stored as ``command`` when given.

    Returns
    -------
    dict
        The document (strict JSON, :func:`json_safe`), stamped with its UTC creation time, the
        hystmpc version and the :func:`environment`.
    """
    doc = {"schema": SCHEMA, "bench": bench,
           "created": dt.datetime.now(dt.UTC).strftime("%Y-%m-%dT%H:%M:%SZ"),
           "version": version(), "environment": environment(), "runs": [r.to_json() for r in runs]}
    if command is not None:
        doc["command"] = command
    return json_safe(doc)


def json_safe(obj):
    """Replace NaN/inf by None so the document is strict JSON.

    Parameters
    ----------
    obj : object
        A value, walked through dicts, lists and tuples.

    Returns
    -------
    object
        A copy with non-finite floats as None, tuples as lists and NumPy scalars as Python
        ``float``/``int``.
    """
    if isinstance(obj, dict):
        return {k: json_safe(v) for k, v in obj.items()}
    if isinstance(obj, (list, tuple)):
        return [json_safe(v) for v in obj]
    if isinstance(obj, (float, np.floating)):
        return float(obj) if np.isfinite(obj) else None
    if isinstance(obj, np.integer):
        return int(obj)
    return obj


def validate_document(doc: dict) -> None:
    """Check the keys and types interface.md promises; ``ValueError`` on the first problem.

    Parameters
    ----------
    doc : dict
        A result document, as read from JSON.
    """
    for key, kind in (("schema", str), ("bench", str), ("created", str), ("version", str), ("runs", list)):
        if not isinstance(doc.get(key), kind):
            raise ValueError(f"results document: {key!r} missing or not {kind.__name__}")
    if doc["schema"] != SCHEMA:
        raise ValueError(f"results document: schema is {doc['schema']!r}, expected {SCHEMA!r}")
    for i, run in enumerate(doc["runs"]):
        for key, kind in (("scenario", str), ("controller", str), ("seed", int), ("units", str),
                          ("sample_period_s", float), ("metrics", dict), ("timing", dict)):
            if not isinstance(run.get(key), kind):
                raise ValueError(f"results document: runs[{i}].{key} missing or not {kind.__name__}")
        for key in ("rmse", "mae", "max_abs_error"):
            value = run["metrics"].get(key)
            if not isinstance(value, float) or not np.isfinite(value):
                raise ValueError(f"results document: runs[{i}].metrics.{key} is not a finite number")
        if not isinstance(run["metrics"].get("n_samples"), int):
            raise ValueError(f"results document: runs[{i}].metrics.n_samples is not an integer")
        for key in ("step_ms_median", "step_ms_p95", "step_ms_max"):
            if not isinstance(run["timing"].get(key), float):
                raise ValueError(f"results document: runs[{i}].timing.{key} is not a number")
        if "solver" in run:
            for key in ("name", "failures", "fallbacks"):
                if key not in run["solver"]:
                    raise ValueError(f"results document: runs[{i}].solver.{key} missing")


def write_json(doc: dict, path: str | Path) -> None:
    """Write a document as indented strict JSON, creating the folder.

    Parameters
    ----------
    doc : dict
        The document (strict JSON: no NaN or inf, see :func:`json_safe`).
    path : str or Path
        The file to write.
    """
    path = Path(path)
    path.parent.mkdir(parents=True, exist_ok=True)
    path.write_text(json.dumps(doc, indent=2, allow_nan=False) + "\n")


def write_run_csv(run: RunResult, folder: str | Path) -> Path:
    """``runs/<scenario>__<controller>.csv`` with t, reference, output, input, predicted.

    One more column ``true_<key>`` per truth signal of the run; 9 significant digits, a
    non-finite value as an empty cell.

    Parameters
    ----------
    run : RunResult
        The run to write.
    folder : str or Path
        The folder the ``runs`` subfolder is made in.

    Returns
    -------
    Path
        The written file.
    """
    folder = Path(folder) / "runs"
    folder.mkdir(parents=True, exist_ok=True)
    path = folder / f"{run.scenario}__{run.controller}.csv"
    extra = sorted(run.truth)
    with path.open("w", newline="") as fh:
        writer = csv.writer(fh)
        writer.writerow(["t", "reference", "output", "input", "predicted", *(f"true_{k}" for k in extra)])
        columns = [run.t, run.reference, run.output, run.input, run.predicted, *(run.truth[key] for key in extra)]
        for row in zip(*(np.asarray(c, float).tolist() for c in columns), strict=True):  # floats: ~10 × faster
            writer.writerow(["" if not math.isfinite(v) else f"{v:.9g}" for v in row])
    return path


def _fmt(value, digits=3) -> str:
    """``digits`` significant digits, trailing zeros kept (a dash for a missing value)."""
    if value is None or (isinstance(value, float) and not np.isfinite(value)):
        return "–"
    if isinstance(value, (int, np.integer)):
        return str(value)
    if value == 0:
        return "0"
    if abs(value) >= 10 ** digits:
        return f"{value:.0f}"
    if abs(value) >= 1e-4:
        return f"{value:#.{digits}g}".rstrip(".")
    return f"{value:.{digits - 1}e}"


def _best_per_scenario(runs: list[RunResult]) -> set[int]:
    best: dict[str, int] = {}
    for i, r in enumerate(runs):
        rmse = r.metrics["rmse"]
        j = best.get(r.scenario)
        if np.isfinite(rmse) and (j is None or rmse < runs[j].metrics["rmse"]):
            best[r.scenario] = i
    counts = {s: sum(r.scenario == s for r in runs) for s in best}
    return {i for s, i in best.items() if counts[s] > 1}


def _oscillation_cell(metrics: dict) -> str:
    cycles = metrics.get("oscillation_cycles")
    if cycles is None:
        return "–"
    if metrics.get("oscillating"):
        return f"{cycles:g} at {metrics['oscillation_hz']:.2g} Hz (oscillating)"
    return f"{cycles:g}"


def comparison_table(runs: list[RunResult]) -> str:
    """Markdown table (readable in a terminal) of every run, like a paper's table.

    Four significant digits for the errors, three for the rest; the least RMSE of each
    scenario in bold; the paper's RMSE beside ours where the paper has one; the input's
    total variation, the longest output oscillation (cycles, with its frequency when it is
    flagged), the step time against the sample period; a ``guard clips`` column when the
    plant guard changed any input.

    Parameters
    ----------
    runs : list of RunResult
        The runs, one row each in this order (units from the first).

    Returns
    -------
    str
        The Markdown table.
    """
    stepped = any("overshoot_pct" in r.metrics for r in runs)
    papers = any(r.paper and "rmse" in r.paper for r in runs)
    guarded = any(r.guard and r.guard["clips"] for r in runs)
    units = runs[0].units if runs else ""
    head = ["scenario", "controller", f"RMSE [{units}]"] + (["paper RMSE"] if papers else []) + [
        f"MAE [{units}]", f"max abs error [{units}]"]
    if stepped:
        head += ["overshoot [%]", "settling 2% [s]", f"ss error [{units}]"]
    input_units = runs[0].labels.input_units if runs else ""
    head += [f"input TV [{input_units}]", "osc. cycles", "ms/step median", "ms/step p95", "median/period",
             "fails/fallbacks"] + (["guard clips"] if guarded else [])
    lines = ["| " + " | ".join(head) + " |", "|" + "|".join("---" for _ in head) + "|"]
    best = _best_per_scenario(runs)
    for i, r in enumerate(runs):
        m = r.metrics
        rmse = _fmt(m["rmse"], 4)
        cells = [r.scenario, r.controller, f"**{rmse}**" if i in best else rmse]
        if papers:
            paper = (r.paper or {}).get("rmse")
            cells.append("–" if paper is None else f"{paper:.4g}")  # as printed in the paper
        cells += [_fmt(m["mae"], 4), _fmt(m["max_abs_error"], 4)]
        if stepped:
            cells += [_fmt(m.get("overshoot_pct")), _fmt(m.get("settling_time_s")),
                      _fmt(m.get("steady_state_error"), 4)]
        timing = r.timing
        cells += [_fmt(m.get("input_tv")), _oscillation_cell(m),
                  _fmt(timing["step_ms_median"]), _fmt(timing["step_ms_p95"]),
                  f"{timing['median_share_of_period']:.0%}" + ("" if timing["real_time"] else " (not real time)"),
                  f"{r.solver['failures']}/{r.solver['fallbacks']}" if r.solver else "–"]
        if guarded:
            cells.append(str(r.guard["clips"]) if r.guard else "–")
        lines.append("| " + " | ".join(cells) + " |")
    return "\n".join(lines)
