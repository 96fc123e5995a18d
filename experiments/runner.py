"""Closed-loop simulation of one controller on one scenario: ``simulate(...) -> RunResult``."""

from __future__ import annotations

import time
from dataclasses import dataclass, field
from typing import Any

import numpy as np

from experiments.bench import Bench, Scenario
from experiments.metrics import step_metrics, tracking_metrics


@dataclass
class RunResult:
    """Trajectories and figures of one run."""

    bench: str
    scenario: str
    controller: str
    seed: int
    units: str
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
    parameters: dict[str, Any] = field(default_factory=dict)

    @property
    def timing(self) -> dict[str, float]:
        """Controller compute per sample (ms): median, p95, max."""
        ms = 1e3 * self.step_times
        return {"step_ms_median": float(np.median(ms)), "step_ms_p95": float(np.percentile(ms, 95)),
                "step_ms_max": float(ms.max())}


def reference_samples(scenario: Scenario, dt: float, duration: float | None = None):
    """Sample times and reference values of a scenario at period ``dt``."""
    duration = scenario.duration if duration is None else duration
    n = int(round(duration / dt))
    t = dt * np.arange(n)
    return t, np.asarray(scenario.reference(t), float)


def simulate(bench: Bench, scenario: Scenario, controller_name: str, config: dict[str, Any],
             seed: int = 0, duration: float | None = None, progress=None) -> RunResult:
    """Run ``controller_name`` on ``scenario`` against the bench's plant.

    Parameters
    ----------
    bench : Bench
        The bench.
    scenario : Scenario
        Reference trajectory.
    controller_name : str
        One of ``bench.controllers``.
    config : dict
        Parameter groups (``bench.defaults()`` with any overrides).
    seed : int
        Seed of the plant's sensor noise.
    duration : float, optional
        Override of the scenario's duration (s).
    progress : callable, optional
        Called with the number of samples done after each sample.
    """
    if controller_name not in bench.controllers:
        raise ValueError(f"unknown controller {controller_name!r}; allowed: {', '.join(bench.controllers)}")
    if scenario.conditions:
        from experiments.config import apply_overrides
        config = apply_overrides(config, list(scenario.conditions))
    dt = bench.sample_period
    t, ref = reference_samples(scenario, dt, duration)
    plant = bench.make_plant(config)
    controller = bench.controllers[controller_name].build(config)
    controller.reset()
    horizon = controller.horizon
    ref_padded = np.concatenate((ref, np.full(horizon, ref[-1])))
    n = len(t)
    out, u_hist, pred, step_times = (np.empty(n) for _ in range(4))
    truth: dict[str, list[float]] = {}
    meas = plant.reset(seed)
    for k in range(n):
        out[k] = meas.y
        for key, value in meas.truth.items():
            truth.setdefault(key, []).append(value)
        start = time.perf_counter()
        u = controller.step(meas, ref_padded[k: k + horizon + 1])
        step_times[k] = time.perf_counter() - start
        pred[k] = getattr(controller, "predicted_output", float("nan"))
        if not np.isfinite(u):
            raise RuntimeError(f"controller {controller_name} produced a non-finite input {u} at t={t[k]:.3f}")
        u_hist[k] = u
        if k < n - 1:
            meas = plant.step(u)
        if progress is not None:
            progress(1)
    metrics = tracking_metrics(ref, out)
    span = float(np.ptp(ref))
    if span > 0 and np.any(np.abs(np.diff(ref)) > 0.25 * span):  # a stepped reference
        metrics.update(step_metrics(t, ref, out, min_step=0.25 * span) or {})
    return RunResult(bench=bench.name, scenario=scenario.name, controller=controller_name, seed=seed,
                     units=bench.units, sample_period=dt, t=t, reference=ref, output=out, input=u_hist,
                     predicted=pred, truth={k: np.asarray(v) for k, v in truth.items()},
                     step_times=step_times, metrics=metrics, solver=controller.stats(),
                     parameters=_describe(config))


def _describe(config):
    from experiments.config import describe
    return describe(config)
