"""Automatic PID tuning for an actuator hystmpc does not know: the same rule for every
PID-based baseline, so that a comparison on a new actuator is not against a strawman.

The rule: minimise the mean RMSE over the actuator's default scenarios, simulated on the
*nominal* model (the controllers' own model, exact and noise-free; never the plant the
comparison runs on), over the PID gains, by Nelder–Mead on their logarithms. Around a
SIMC-style guess for a static gain ``K`` behind a dead time ``θ`` (``ki = 1/(2Kθ)``,
``kp = 0.2/K``) a coarse grid (``kp`` × 0.15, 1, 5; ``ki`` × 0.1, 0.3, 1, 3, 10) picks the
start, so the search does not settle in a poor local minimum; from there it tunes a PI,
then a PID from the PI's optimum, and keeps the better.
"""

from __future__ import annotations

from collections.abc import Callable

import numpy as np

from hystmpc.experiments.baselines import PidGains
from hystmpc.experiments.runner import Scenario, simulate


def mean_rmse(controller, plant, scenarios: list[Scenario]) -> float:
    """Mean RMSE of ``controller`` on ``scenarios`` against ``plant`` (inf if not finite)."""
    value = float(np.mean([simulate(plant, controller, s).metrics["rmse"] for s in scenarios]))
    return value if np.isfinite(value) else np.inf


def coarse_start(cost: Callable, static_gain: float, dead_time: float, sample_period: float):
    """The best ``(log kp, log ki)`` of the coarse grid around the SIMC-style guess, and its cost."""
    k = max(abs(static_gain), 1e-12)
    theta = max(dead_time, sample_period)
    guess = np.log([0.2 / k, 1.0 / (2 * k * theta)])
    grid = [guess + np.log([a, b]) for a in (0.15, 1.0, 5.0) for b in (0.1, 0.3, 1.0, 3.0, 10.0)]
    costs = [cost(z) for z in grid]
    best = int(np.argmin(costs))
    return grid[best], costs[best]


def tune_pid(build: Callable[[PidGains], object], plant, scenarios: list[Scenario], static_gain: float,
             dead_time: float, sample_period: float, max_evaluations: int = 40,
             stages: tuple[str, ...] = ("pi", "pid")) -> tuple[PidGains, float]:
    """The PID gains of ``build(gains)`` that minimise the mean RMSE on ``scenarios``.

    Parameters
    ----------
    build : callable
        ``PidGains -> controller`` (the baseline, feed-forward included).
    plant : Plant
        The nominal model as a plant (no noise).
    scenarios : list of Scenario
        References the cost averages over.
    static_gain : float
        Output per input unit at low frequency (for the starting guess).
    dead_time : float
        Dead time plus lag of the actuator (s), for the starting guess.
    sample_period : float
        Sample period (s); the derivative filter is three samples.
    max_evaluations : int
        Cost evaluations per Nelder–Mead stage.
    stages : tuple of str
        ``("pi",)`` stops after the PI stage.

    Returns
    -------
    (PidGains, float)
        The gains and their mean RMSE.
    """
    from scipy.optimize import minimize
    filt = 3 * sample_period

    def gains_of(z) -> PidGains:
        kp, ki = np.exp(z[0]), np.exp(z[1])
        kd = np.exp(z[2]) if len(z) > 2 else 0.0
        return PidGains(kp=float(kp), ki=float(ki), kd=float(kd), derivative_filter=filt)

    def cost(z) -> float:
        try:
            gains = gains_of(z)
        except ValueError:
            return np.inf
        return mean_rmse(build(gains), plant, scenarios)

    start, _ = coarse_start(cost, static_gain, dead_time, sample_period)
    theta = max(dead_time, sample_period)
    options = {"maxfev": max_evaluations, "xatol": 0.02, "fatol": 1e-9, "initial_simplex": None}
    simplex = np.array([start, start + [1.0, 0.0], start + [0.0, 1.0]])
    pi = minimize(cost, start, method="Nelder-Mead", options=options | {"initial_simplex": simplex})
    if "pid" not in stages:
        return gains_of(pi.x), float(pi.fun)
    z_pid = np.concatenate((pi.x, [np.log(0.05 * np.exp(pi.x[0]) * theta + 1e-12)]))
    simplex = np.array([z_pid] + [z_pid + 1.0 * np.eye(3)[i] for i in range(3)])
    pid = minimize(cost, z_pid, method="Nelder-Mead", options=options | {"initial_simplex": simplex})
    best = pid if pid.fun < pi.fun else pi
    return gains_of(best.x), float(best.fun)
