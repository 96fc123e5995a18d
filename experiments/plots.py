"""Figures: tracking, error, input and the hysteresis loop per scenario; RMSE summary."""

from __future__ import annotations

from pathlib import Path

import matplotlib

matplotlib.use("Agg")
import matplotlib.pyplot as plt  # noqa: E402
import numpy as np  # noqa: E402

from experiments.bench import Bench  # noqa: E402
from experiments.runner import RunResult  # noqa: E402


def scenario_figure(bench: Bench, runs: list[RunResult], path: str | Path) -> Path:
    """Four panels for one scenario: reference vs output, error, input, hysteresis loop."""
    fig, axes = plt.subplots(2, 2, figsize=(12, 7.5))
    (ax_y, ax_loop), (ax_e, ax_u) = axes
    ax_y.plot(runs[0].t, runs[0].reference, "k--", lw=1.2, label="reference")
    for r in runs:
        ax_y.plot(r.t, r.output, lw=1, label=f"{r.controller} (RMSE {r.metrics['rmse']:.3g})")
        ax_e.plot(r.t, r.reference - r.output, lw=1, label=r.controller)
        ax_u.plot(r.t, r.input, lw=1, label=r.controller)
        if bench.loop is not None and bench.loop[0] in r.truth and bench.loop[1] in r.truth:
            ax_loop.plot(r.truth[bench.loop[0]], r.truth[bench.loop[1]], lw=0.8, label=r.controller)
    ax_y.set(xlabel="t [s]", ylabel=f"{bench.output_name} [{bench.units}]", title=f"{runs[0].scenario}: tracking")
    ax_e.set(xlabel="t [s]", ylabel=f"error [{bench.units}]", title="reference − output")
    ax_u.set(xlabel="t [s]", ylabel=f"input [{bench.input_units}]", title="input")
    if bench.loop is not None:
        ax_loop.set(xlabel=bench.loop[2], ylabel=bench.loop[3], title="hysteresis loop (plant's true state)")
    for ax in axes.ravel():
        ax.grid(alpha=0.3)
        ax.legend(fontsize=8)
    fig.suptitle(f"{bench.name}: {bench.description}", fontsize=10)
    fig.tight_layout()
    path = Path(path)
    path.parent.mkdir(parents=True, exist_ok=True)
    fig.savefig(path, dpi=110)
    plt.close(fig)
    return path


def rmse_figure(bench: Bench, runs: list[RunResult], path: str | Path) -> Path:
    """Grouped bars: RMSE per scenario and controller (log scale)."""
    scenarios = list(dict.fromkeys(r.scenario for r in runs))
    controllers = list(dict.fromkeys(r.controller for r in runs))
    width = 0.8 / len(controllers)
    fig, ax = plt.subplots(figsize=(max(6, 1.6 * len(scenarios)), 4))
    for j, c in enumerate(controllers):
        values = [next((r.metrics["rmse"] for r in runs if r.scenario == s and r.controller == c), np.nan)
                  for s in scenarios]
        ax.bar(np.arange(len(scenarios)) + j * width, values, width, label=c)
    ax.set_xticks(np.arange(len(scenarios)) + 0.4 - width / 2, scenarios)
    ax.set(ylabel=f"RMSE [{bench.units}]", yscale="log", title=f"{bench.name}: tracking RMSE")
    ax.grid(alpha=0.3, axis="y")
    ax.legend()
    fig.tight_layout()
    path = Path(path)
    fig.savefig(path, dpi=110)
    plt.close(fig)
    return path


def error_vs_reference_figure(bench: Bench, runs: list[RunResult], path: str | Path) -> Path:
    """Error against the reference (linearisation error vs force, like katalenic2013 Fig. 11)."""
    fig, ax = plt.subplots(figsize=(7, 4.5))
    for r in runs:
        ax.plot(r.reference, r.reference - r.output, lw=0.8,
                label=f"{r.controller} (max {r.metrics['max_abs_error']:.3g})")
    ax.axhline(0, color="k", lw=0.5)
    ax.set(xlabel=f"reference {bench.output_name} [{bench.units}]", ylabel=f"error [{bench.units}]",
           title=f"{runs[0].scenario}: error vs reference")
    ax.grid(alpha=0.3)
    ax.legend(fontsize=8)
    fig.tight_layout()
    path = Path(path)
    fig.savefig(path, dpi=110)
    plt.close(fig)
    return path
