"""Closed loop: ``simulate(plant, controller, reference) -> RunResult``.

Any plant (:class:`hystmpc.plants.base.Plant`) with any controller (:class:`Controller`): the
benches, code generation checks, speed measurements, peer comparisons and tests all run
through :func:`simulate`.
"""

from __future__ import annotations

import logging
import time
from collections.abc import Callable
from dataclasses import dataclass, field
from pathlib import Path
from typing import Any, Protocol, runtime_checkable

import numpy as np

from hystmpc.experiments.metrics import input_metrics, oscillation_metrics, step_metrics, tracking_metrics
from hystmpc.experiments.report import json_safe
from hystmpc.plants.base import Measurement, Plant

ESTIMATE_STEPS = 5
"""Steps timed for the early estimate of a slow run (after the first, which may build or compile)."""
SLOW_FACTOR = 10.0
"""A run is announced as slow when its steps take this many periods or more..."""
SLOW_SECONDS = 10.0
"""... and the rest of it is expected to take this long or more (s)."""


@runtime_checkable
class Controller(Protocol):
    """Shape shared by every controller: ``reset()``, then ``step(measurement, ref_window)``.

    ``ref_window`` holds the reference at this sample and the next ``horizon`` ones.
    :func:`simulate` also takes a controller without ``horizon`` (then 0) or ``stats``;
    optionally a controller has ``predicted_output`` (its model's one-step-ahead
    prediction of this sample's output, for the run's CSV).
    """

    horizon: int
    """Future reference samples the controller wants beyond the current one (0: causal)."""

    def reset(self) -> None:
        """Forget every past sample: the next ``step`` is a run's first."""

    def step(self, measurement: Measurement, ref_window: np.ndarray) -> float:
        """The input for this sample, from its measurement and ``horizon + 1`` reference samples.

        Parameters
        ----------
        measurement : Measurement
            This sample's sensors.
        ref_window : ndarray
            The reference at this sample and the next ``horizon`` ones.

        Returns
        -------
        float
            The input to apply.
        """

    def stats(self) -> dict | None:
        """Solver statistics of the run so far for the result (None: the controller solves nothing)."""


@dataclass(frozen=True)
class Scenario:
    """A reference trajectory with a name and a duration."""

    name: str
    description: str
    duration: float
    """Length of the run (s)."""
    reference: Callable[[np.ndarray], np.ndarray]
    """Reference as a function of time (vectorised)."""
    conditions: tuple[str, ...] = ()
    """Operating conditions the scenario fixes, as ``--set`` assignments (``rig.gap_mm=1.2``)."""


@dataclass(frozen=True)
class Labels:
    """How to name a run's signals in tables and figures."""

    output_name: str = "output"
    """The tracked output (``angle``, ``torque``...)."""
    units: str = ""
    """Units of the output."""
    input_units: str = ""
    """Units of the input."""
    loop: tuple[str, str, str, str] | None = None
    """Hysteresis-loop plot: (truth key on x, truth key on y, x label, y label)."""
    title: str = ""
    """Figure title."""
    sensor_units: tuple[tuple[str, str], ...] = ()
    """Units of the other sensors, ``((name, units), ...)`` (for the generated controller's header)."""


@dataclass
class RunResult:
    """Trajectories and figures of one run."""

    scenario: str
    controller: str
    seed: int
    sample_period: float
    t: np.ndarray
    reference: np.ndarray
    output: np.ndarray
    input: np.ndarray
    predicted: np.ndarray
    truth: dict[str, np.ndarray]
    step_times: np.ndarray
    metrics: dict[str, float]
    solver: dict | None
    labels: Labels = field(default_factory=Labels)
    parameters: dict[str, Any] = field(default_factory=dict)
    """The parameters that made the run (a bench's configuration)."""
    paper: dict[str, float] | None = None
    """The paper's figures for this scenario and controller, where there are some."""
    bench: str = ""
    guard: dict[str, Any] | None = None
    """What the plant guard did (:class:`InputGuard`): its bounds and ``clips``, the
    samples whose input it changed (``non_finite`` of them were not a number)."""

    @property
    def units(self) -> str:
        """Units of the output."""
        return self.labels.units

    @property
    def timing(self) -> dict[str, float]:
        """Controller compute per sample (ms): median, p95, max.

        Also the median and p95 as a share of the sample period (``real_time``: the median fits in
        the period).
        """
        ms = 1e3 * self.step_times
        median, p95 = float(np.median(ms)), float(np.percentile(ms, 95))
        period_ms = 1e3 * self.sample_period
        return {"step_ms_median": median, "step_ms_p95": p95, "step_ms_max": float(ms.max()),
                "median_share_of_period": median / period_ms, "p95_share_of_period": p95 / period_ms,
                "real_time": bool(median <= period_ms)}

    def real_time_verdict(self) -> str:
        """One line: the median and p95 step against the sample period.

        It also says whether the controller keeps up with it on this machine (judged on the median).

        Returns
        -------
        str
            The line, without a newline.
        """
        t = self.timing
        if not t["real_time"]:
            verdict = "NOT real time: the median step exceeds the period"
        elif t["p95_share_of_period"] > 1:
            verdict = "real time on the median, but 1 step in 20 or more exceeds the period"
        else:
            verdict = "real time"
        return (f"{self.scenario} · {self.controller}: median {t['step_ms_median']:.3g} ms "
                f"({t['median_share_of_period']:.0%} of the {1e3 * self.sample_period:g} ms period), "
                f"p95 {t['step_ms_p95']:.3g} ms ({t['p95_share_of_period']:.0%}): {verdict}")

    def to_json(self) -> dict[str, Any]:
        """The run as an element of a result document's ``runs`` (interface.md), strict JSON.

        Returns
        -------
        dict
            Scenario, controller, seed, units, sample period, metrics, timing and parameters, with
            ``solver``, ``guard`` and ``paper`` where the run has them.
        """
        entry: dict[str, Any] = {
            "scenario": self.scenario, "controller": self.controller, "seed": self.seed, "units": self.units,
            "sample_period_s": self.sample_period, "metrics": self.metrics, "timing": self.timing,
        }
        if self.solver is not None:
            entry["solver"] = self.solver
            if self.guard is not None:
                entry["solver"] = {**self.solver, "guard_clips": self.guard["clips"]}
        if self.guard is not None:
            entry["guard"] = self.guard
        if self.paper:
            entry["paper"] = dict(self.paper)
        entry["parameters"] = self.parameters
        return json_safe(entry)

    def plot(self, path: str | Path | None = None, others: list[RunResult] = ()):
        """The figure ``compare`` draws for a scenario: tracking, error, input, hysteresis loop.

        Parameters
        ----------
        path : str or Path, optional
            Where to save the figure (default: do not save).
        others : list of RunResult, optional
            More runs on the same reference, drawn with this one.

        Returns
        -------
        Path or matplotlib.figure.Figure
            The path when saved, else the figure.
        """
        from hystmpc.experiments.plots import scenario_figure  # here: matplotlib loads only when a figure is drawn
        return scenario_figure([self, *others], path)


@dataclass(frozen=True)
class InputGuard:
    """The actuator's physical input limits, enforced between any controller and the plant.

    Independent of every controller and model setting: a controller that asks for an input
    outside ``[lower, upper]``, more than ``rate`` away from the last applied input, or not a
    number, gets it clipped (a non-finite input holds the last applied one, at the first
    sample ``rest`` clipped into the bounds) and the sample is counted.
    """

    lower: float = -np.inf
    upper: float = np.inf
    rate: float = np.inf
    """Largest change per sample (``inf``: none)."""
    rest: float = 0.0
    """The input held when the very first one is not a number."""

    def __post_init__(self):
        if not self.lower < self.upper or not self.rate > 0:
            raise ValueError(f"the input guard needs lower < upper and rate > 0, got {self.lower}, {self.upper}, "
                             f"{self.rate}")

    def apply(self, u: float, last: float | None) -> tuple[float, bool, bool]:
        """``(applied input, clipped, non_finite)`` for the requested ``u`` after ``last``.

        Parameters
        ----------
        u : float
            The input the controller asks for.
        last : float or None
            The last applied input (None at the first sample).

        Returns
        -------
        tuple of (float, bool, bool)
            The input to apply, whether it differs from ``u``, whether ``u`` was not a number.
        """
        if not np.isfinite(u):
            held = float(np.clip(self.rest, self.lower, self.upper)) if last is None else last
            return held, True, True
        applied = float(u)
        if last is not None and np.isfinite(self.rate):
            applied = min(max(applied, last - self.rate), last + self.rate)
        applied = min(max(applied, self.lower), self.upper)
        # a controller that respects the same rate lands within rounding of it: applied, not counted
        return applied, abs(applied - u) > 1e-12 * max(1.0, abs(u)), False

    def describe(self) -> dict[str, float]:
        """The bounds, for a run's result.

        Returns
        -------
        dict
            ``lower``, ``upper`` and ``rate``.
        """
        return {"lower": self.lower, "upper": self.upper, "rate": self.rate}


def reference_samples(reference, dt: float, duration: float | None = None) -> tuple[np.ndarray, np.ndarray]:
    """Sample times and reference values at period ``dt``.

    Parameters
    ----------
    reference : Scenario, callable or array_like
        A scenario, a function of time (then ``duration`` is needed) or an array of samples
        at ``dt``.
    dt : float
        Sample period (s).
    duration : float, optional
        Length (s); default: the scenario's or the array's (for an array it may only shorten it).

    Returns
    -------
    t : ndarray
        Sample times (s), ``dt * arange(n)``.
    values : ndarray
        The reference at those times.
    """
    if isinstance(reference, Scenario):
        duration = reference.duration if duration is None else duration
        reference = reference.reference
    if callable(reference):
        if duration is None:
            raise ValueError("a reference given as a function of time needs a duration")
        n = int(round(duration / dt))
        t = dt * np.arange(n)
        return t, np.asarray(reference(t), float)
    values = np.asarray(reference, float).ravel()
    n = len(values) if duration is None else min(len(values), int(round(duration / dt)))
    return dt * np.arange(n), values[:n]


def _checked(t: np.ndarray, ref: np.ndarray) -> np.ndarray:
    ref = np.broadcast_to(np.asarray(ref, float), t.shape).copy()  # a constant reference is fine
    if not np.all(np.isfinite(ref)):
        raise ValueError(f"the reference is not finite at t = {t[~np.isfinite(ref)][0]:g} s")
    return ref


def _slow_run_notice(step_seconds, samples: int, sample_period: float) -> str | None:
    """The controller's expected time for the rest of a run whose first steps were slow, or None.

    Slow: the median of ``step_seconds`` is :data:`SLOW_FACTOR` periods or more, and the
    ``samples`` still to run take the controller :data:`SLOW_SECONDS` or more at that rate.
    """
    step_seconds = np.asarray(step_seconds, float)
    if step_seconds.size == 0 or not np.all(np.isfinite(step_seconds)):
        return None
    per_step = float(np.median(step_seconds))
    rest = per_step * samples
    if per_step < SLOW_FACTOR * sample_period or rest < SLOW_SECONDS:
        return None
    return (f"{per_step * 1e3:.3g} ms per step (median of steps 2–{step_seconds.size + 1}), "
            f"{per_step / sample_period:.0f} × the {sample_period * 1e3:.3g} ms period: the controller alone "
            f"needs about {_duration(rest)} for the remaining {samples:,} samples")


def _duration(seconds: float) -> str:
    if seconds < 120:
        return f"{seconds:.0f} s"
    return f"{seconds / 60:.0f} min" if seconds < 7200 else f"{seconds / 3600:.1f} h"


def simulate(plant: Plant, controller: Controller, reference, duration: float | None = None, seed: int = 0, *,
             name: str | None = None, scenario: str | None = None, labels: Labels = Labels(),
             progress: Callable[[int], Any] | None = None, guard: InputGuard | None = None) -> RunResult:
    """Run ``controller`` against ``plant`` along ``reference``.

    Parameters
    ----------
    plant : Plant
        Reset with ``seed``, then stepped once per sample.
    controller : Controller
        Reset first; it sees the measurement and ``controller.horizon`` samples of preview
        (the reference is held at its last value beyond the end).
    reference : Scenario, callable or array_like
        See :func:`reference_samples`.
    duration : float, optional
        Length of the run (s); default: the scenario's or the array's.
    seed : int
        Seed of the plant's sensor noise.
    name, scenario : str, optional
        Names of the controller and the reference in the result.
    labels : Labels
        Signal names and units for the result's table and figures.
    progress : callable, optional
        Called with 1 after each sample.
    guard : InputGuard, optional
        The actuator's physical input limits; every input passes through it before
        ``plant.step`` (default: only finiteness is enforced, a non-finite input holds the
        last one). The result's ``input`` is the applied input.

    Returns
    -------
    RunResult
        The trajectories, with tracking, step (for a stepped reference), oscillation and input
        metrics, the solver's statistics and what the guard did.
    """
    dt = plant.sample_period
    t, ref = reference_samples(reference, dt, duration)
    if len(t) < 2:
        raise ValueError(f"the run needs at least 2 samples at {dt:g} s, got {len(t)}")
    ref = _checked(t, ref)
    if scenario is None:
        scenario = reference.name if isinstance(reference, Scenario) else "reference"
    name = name or type(controller).__name__
    controller.reset()
    horizon = getattr(controller, "horizon", 0)
    ref_padded = np.concatenate((ref, np.full(horizon, ref[-1])))
    n = len(t)
    out, u_hist, pred, step_times = (np.empty(n) for _ in range(4))
    truth: dict[str, list[float]] = {}
    guard = guard or InputGuard()
    clips = non_finite = 0
    last = None
    meas = plant.reset(seed)
    for k in range(n):
        out[k] = meas.y
        for key, value in meas.truth.items():
            truth.setdefault(key, []).append(value)
        start = time.perf_counter()
        u = controller.step(meas, ref_padded[k: k + horizon + 1])
        step_times[k] = time.perf_counter() - start
        if k == ESTIMATE_STEPS:
            notice = _slow_run_notice(step_times[1: k + 1], n - k - 1, dt)
            if notice:  # live: a compare worker writes it at once, not with the run's result
                logging.getLogger("hystmpc").info(f"slow run: {scenario} · {name}: {notice}", extra={"live": True})
        pred[k] = getattr(controller, "predicted_output", float("nan"))
        u, clipped, bad = guard.apply(float(u), last)
        clips += clipped
        non_finite += bad
        u_hist[k] = last = u
        if k < n - 1:
            meas = plant.step(u)
        if progress is not None:
            progress(1)
    metrics = tracking_metrics(ref, out)
    span = float(np.ptp(ref))
    if span > 0 and np.any(np.abs(np.diff(ref)) > 0.25 * span):  # a stepped reference
        metrics.update(step_metrics(t, ref, out, min_step=0.25 * span) or {})
    metrics.update(oscillation_metrics(t, ref, out))
    metrics.update(input_metrics(u_hist))
    return RunResult(scenario=scenario, controller=name, seed=seed,
                     sample_period=dt, t=t, reference=ref, output=out, input=u_hist, predicted=pred,
                     truth={k: np.asarray(v) for k, v in truth.items()}, step_times=step_times,
                     metrics=metrics, solver=controller.stats() if hasattr(controller, "stats") else None,
                     labels=labels, guard={**guard.describe(), "clips": clips, "non_finite": non_finite})
