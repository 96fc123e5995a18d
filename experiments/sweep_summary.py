"""A sweep's summary: metric quartiles and how often ``nmpc`` beats the baselines.

The quartiles of each metric per scenario and controller, how often ``nmpc`` beats each
baseline and the best of them per case, as JSON, CSV, a table and figures.
"""

from __future__ import annotations

import csv
import math
from pathlib import Path
from typing import Any

import numpy as np

from hystmpc.experiments.sweep_spec import CHALLENGER, METRICS, SweepSpec, run_id

SUMMARY_SCHEMA = "hystmpc.sweep-summary/1"


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

    Parameters
    ----------
    spec : SweepSpec
        The sweep.
    records : dict
        Run records by run id (:func:`~hystmpc.experiments.sweep_spec.run_id`).
    metric : str, optional
        The metric the win rates compare.

    Returns
    -------
    dict
        The summary document (``hystmpc.sweep-summary/1``): run counts, ``groups`` (one per
        scenario and controller) and, when the sweep has ``nmpc`` and a baseline, ``win_rates``
        over all scenarios (``all``) and per scenario.
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
    """One row per scenario and controller; ``nmpc_win_rate`` is nmpc's rate against that row's controller.

    Parameters
    ----------
    summary : dict
        What :func:`summarize` returned.
    path : Path
        The CSV file to write.
    """
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
    """Markdown table: per scenario and controller, RMSE quartiles, failures and nmpc's win rate.

    Parameters
    ----------
    summary : dict
        What :func:`summarize` returned.
    units : str
        Units of the output.

    Returns
    -------
    str
        The table.
    """
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
    """Box plots of RMSE per controller (one panel per scenario) and nmpc against the best baseline.

    Only successful runs are drawn; the second figure needs ``nmpc`` and a baseline in the sweep.

    Parameters
    ----------
    spec : SweepSpec
        The sweep.
    records : dict
        Run records by run id.
    out : Path
        The existing folder the PNG files are saved in.
    units : str
        Units of the output.

    Returns
    -------
    list of Path
        ``rmse_box.png`` and, if drawn, ``nmpc_vs_best_baseline.png``.
    """
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
