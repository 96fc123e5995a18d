"""Figures: tracking, error, input and the hysteresis loop per scenario; RMSE summary."""

from __future__ import annotations

from pathlib import Path
from typing import TYPE_CHECKING

import matplotlib

matplotlib.use("Agg")
import matplotlib.pyplot as plt  # noqa: E402
import numpy as np  # noqa: E402

if TYPE_CHECKING:  # RunResult.plot draws through this module
    from hystmpc.experiments.runner import RunResult


def _finish(fig, path: str | Path | None, dpi: int = 110):
    """Save and close ``fig`` to ``path`` (returns the path), or return the figure."""
    fig.tight_layout()
    if path is None:
        return fig
    path = Path(path)
    path.parent.mkdir(parents=True, exist_ok=True)
    fig.savefig(path, dpi=dpi)
    plt.close(fig)
    return path


def scenario_figure(runs: list[RunResult], path: str | Path | None = None):
    """Four panels for one scenario: reference vs output, error, input, hysteresis loop.

    The signal names, units and loop come from the first run's labels.

    Parameters
    ----------
    runs : list of RunResult
        The runs on the scenario (the first one's reference is drawn).
    path : str or Path, optional
        Where to save the figure, creating the folder (default: do not save).

    Returns
    -------
    Path or matplotlib.figure.Figure
        The path when saved (the figure is closed), else the figure.
    """
    labels = runs[0].labels
    fig, axes = plt.subplots(2, 2, figsize=(12, 7.5))
    (ax_y, ax_loop), (ax_e, ax_u) = axes
    ax_y.plot(runs[0].t, runs[0].reference, "k--", lw=1.2, label="reference")
    loop = labels.loop
    for r in runs:
        ax_y.plot(r.t, r.output, lw=1, label=f"{r.controller} (RMSE {r.metrics['rmse']:.3g})")
        ax_e.plot(r.t, r.reference - r.output, lw=1, label=r.controller)
        ax_u.plot(r.t, r.input, lw=1, label=r.controller)
        if loop is not None and loop[0] in r.truth and loop[1] in r.truth:
            ax_loop.plot(r.truth[loop[0]], r.truth[loop[1]], lw=0.8, label=r.controller)
        elif loop is None:
            ax_loop.plot(r.input, r.output, lw=0.8, label=r.controller)
    units = f" [{labels.units}]" if labels.units else ""
    input_units = f" [{labels.input_units}]" if labels.input_units else ""
    ax_y.set(xlabel="t [s]", ylabel=f"{labels.output_name}{units}", title=f"{runs[0].scenario}: tracking")
    ax_e.set(xlabel="t [s]", ylabel=f"error{units}", title="reference − output")
    ax_u.set(xlabel="t [s]", ylabel=f"input{input_units}", title="input")
    if loop is not None:
        ax_loop.set(xlabel=loop[2], ylabel=loop[3], title="hysteresis loop (plant's true state)")
    else:
        ax_loop.set(xlabel=f"input{input_units}", ylabel=f"measured {labels.output_name}{units}",
                    title="input–output loop")
    for ax in axes.ravel():
        ax.grid(alpha=0.3)
        ax.legend(fontsize=8)
    if labels.title:
        fig.suptitle(labels.title, fontsize=10)
    return _finish(fig, path)


def rmse_figure(runs: list[RunResult], path: str | Path | None = None):
    """Grouped bars: RMSE per scenario and controller (log scale), each bar labelled with its value.

    Parameters
    ----------
    runs : list of RunResult
        The runs; a missing scenario-controller pair leaves its bar empty.
    path : str or Path, optional
        Where to save the figure, creating the folder (default: do not save).

    Returns
    -------
    Path or matplotlib.figure.Figure
        The path when saved (the figure is closed), else the figure.
    """
    scenarios = list(dict.fromkeys(r.scenario for r in runs))
    controllers = list(dict.fromkeys(r.controller for r in runs))
    width = 0.8 / len(controllers)
    fig, ax = plt.subplots(figsize=(max(6, 1.6 * len(scenarios)), 4))
    for j, c in enumerate(controllers):
        values = [next((r.metrics["rmse"] for r in runs if r.scenario == s and r.controller == c), np.nan)
                  for s in scenarios]
        bars = ax.bar(np.arange(len(scenarios)) + j * width, values, width, label=c)
        ax.bar_label(bars, labels=[f"{v:.3g}" if np.isfinite(v) else "" for v in values], fontsize=7,
                     rotation=90 if len(controllers) > 3 else 0, padding=2)
    ax.set_xticks(np.arange(len(scenarios)) + 0.4 - width / 2, scenarios)
    title = runs[0].bench or runs[0].labels.output_name
    ax.set(ylabel=f"RMSE [{runs[0].units}]", yscale="log", title=f"{title}: tracking RMSE")
    ax.set_ylim(top=ax.get_ylim()[1] * 3)  # room for the labels
    ax.grid(alpha=0.3, axis="y")
    ax.legend()
    return _finish(fig, path)


def error_vs_reference_figure(runs: list[RunResult], path: str | Path | None = None):
    """Error against the reference (linearisation error vs force, like katalenic2013 Fig. 11).

    Parameters
    ----------
    runs : list of RunResult
        The runs on the scenario.
    path : str or Path, optional
        Where to save the figure, creating the folder (default: do not save).

    Returns
    -------
    Path or matplotlib.figure.Figure
        The path when saved (the figure is closed), else the figure.
    """
    labels = runs[0].labels
    fig, ax = plt.subplots(figsize=(7, 4.5))
    for r in runs:
        ax.plot(r.reference, r.reference - r.output, lw=0.8,
                label=f"{r.controller} (max {r.metrics['max_abs_error']:.3g})")
    ax.axhline(0, color="k", lw=0.5)
    ax.set(xlabel=f"reference {labels.output_name} [{labels.units}]", ylabel=f"error [{labels.units}]",
           title=f"{runs[0].scenario}: error vs reference")
    ax.grid(alpha=0.3)
    ax.legend(fontsize=8)
    return _finish(fig, path)
