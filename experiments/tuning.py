"""Automatic PID tuning for an actuator hystmpc does not know.

It applies the same rule to every PID-based baseline, so that a comparison on a new actuator
is not against a strawman.

The rule: minimise the mean RMSE over the actuator's default scenarios on an *ensemble* of
plants (the nominal model, and where the identification ranked a runner-up the nominal
moved toward it; exact and noise-free, never perturbed as the comparison's plant is), over
the PID gains, by Nelder–Mead on their logarithms. A candidate that rings :data:`RING_CYCLES`
cycles or more on any run costs infinity, and so does one that rings with its gains times
:data:`GAIN_MARGIN` (a 6 dB gain margin); when every candidate of the coarse grid does, the
rule runs again without the margin, then without either test, with a warning each time. Around a
SIMC-style guess for a static gain ``K`` behind a dead time ``θ`` (``ki = 1/(2Kθ)``,
``kp = 0.2/K``) a coarse grid (``kp`` × 0.15, 1, 5; ``ki`` × 0.1, 0.3, 1, 3, 10) picks the
start, so the search does not settle in a poor local minimum; from there it tunes a PI,
then a PID from the PI's optimum, and keeps the better.
"""

from __future__ import annotations

import dataclasses
import logging
from collections.abc import Callable

import numpy as np

from hystmpc.experiments.baselines import PidGains
from hystmpc.experiments.runner import Scenario, simulate

LOG = logging.getLogger("hystmpc")
RING_CYCLES = 3.0
"""A tuned candidate rings fewer cycles than this on every run of the ensemble: a margin below
the :data:`~hystmpc.experiments.metrics.OSCILLATING_CYCLES` that flags a run, for a plant that
differs from the ensemble (a candidate tuned to the edge rings over it on a 5 % heavier plant)."""

GAIN_MARGIN = 2.0
"""A tuned PID keeps this gain margin (6 dB, the textbook least): with each of its gains times
this factor it still rings on no run of the ensemble. The ensemble holds only the model's error
the identification saw; where the actuator's loop is steeper than the model's, or its slope turns
after a reversal, a PID tuned to the ensemble's edge rings on the rig."""


def mean_rmse(controller, plants, scenarios: list[Scenario], reject_oscillating: bool = True, seed: int = 0
              ) -> float:
    """Mean RMSE of ``controller`` on ``scenarios`` against each of ``plants`` (one plant or a list).

    Parameters
    ----------
    controller : Controller
        The controller, reset before each run.
    plants : Plant or list of Plant
        One plant or the ensemble.
    scenarios : list of Scenario
        The references.
    reject_oscillating : bool, optional
        A run that rings :data:`RING_CYCLES` cycles or more makes the cost inf.
    seed : int, optional
        Seed of every run.

    Returns
    -------
    float
        The mean RMSE; inf if it is not finite or a run rings (with ``reject_oscillating``).
    """
    rmses = []
    for plant in plants if isinstance(plants, list | tuple) else [plants]:
        for scenario in scenarios:
            metrics = simulate(plant, controller, scenario, seed=seed).metrics
            if reject_oscillating and metrics["oscillation_cycles"] >= RING_CYCLES:
                return np.inf
            rmses.append(metrics["rmse"])
    value = float(np.mean(rmses))
    return value if np.isfinite(value) else np.inf


def pid_cost(build: Callable[[PidGains], object], gains: PidGains, plants, scenarios: list[Scenario],
             reject_oscillating: bool = True, margin: bool = True) -> float:
    """:func:`mean_rmse` of ``build(gains)``; inf also if the gains times :data:`GAIN_MARGIN` ring.

    Parameters
    ----------
    build : callable
        ``PidGains -> controller``.
    gains : PidGains
        The candidate.
    plants : Plant or list of Plant
        The ensemble.
    scenarios : list of Scenario
        The references.
    reject_oscillating : bool, optional
        A run that rings makes the cost inf (without: the mean RMSE alone).
    margin : bool, optional
        With ``reject_oscillating``, so does a run that rings with the gains times
        :data:`GAIN_MARGIN`.

    Returns
    -------
    float
        The mean RMSE, or inf.
    """
    value = mean_rmse(build(gains), plants, scenarios, reject_oscillating)
    if not (reject_oscillating and margin and np.isfinite(value)):
        return value
    bolder = dataclasses.replace(gains, kp=gains.kp * GAIN_MARGIN, ki=gains.ki * GAIN_MARGIN,
                                 kd=gains.kd * GAIN_MARGIN)
    return value if np.isfinite(mean_rmse(build(bolder), plants, scenarios)) else np.inf


def coarse_start(cost: Callable, static_gain: float, dead_time: float, sample_period: float):
    """The best ``(log kp, log ki)`` of the coarse grid around the SIMC-style guess, and its cost.

    Parameters
    ----------
    cost : callable
        Cost of ``(log kp, log ki)``.
    static_gain : float
        Output per input unit at low frequency (its magnitude is used).
    dead_time : float
        Dead time plus lag (s); at least ``sample_period`` is used.
    sample_period : float
        Sample period (s).

    Returns
    -------
    z : ndarray
        The best grid point ``(log kp, log ki)``.
    cost : float
        Its cost.
    """
    k = max(abs(static_gain), 1e-12)
    theta = max(dead_time, sample_period)
    guess = np.log([0.2 / k, 1.0 / (2 * k * theta)])
    grid = [guess + np.log([a, b]) for a in (0.15, 1.0, 5.0) for b in (0.1, 0.3, 1.0, 3.0, 10.0)]
    costs = [cost(z) for z in grid]
    best = int(np.argmin(costs))
    return grid[best], costs[best]


def tune_pid(build: Callable[[PidGains], object], plant, scenarios: list[Scenario], static_gain: float,
             dead_time: float, sample_period: float, max_evaluations: int = 40,
             stages: tuple[str, ...] = ("pi", "pid"), reject_oscillating: bool = True, margin: bool = True
             ) -> tuple[PidGains, float]:
    """The PID gains of ``build(gains)`` that minimise the mean RMSE on ``scenarios``.

    Parameters
    ----------
    build : callable
        ``PidGains -> controller`` (the baseline, feed-forward included).
    plant : Plant or list of Plant
        The ensemble (noise-free): the nominal model, and others the actuator may be.
    scenarios : list of Scenario
        References the cost averages over.
    static_gain : float
        Output per input unit at low frequency (for the starting guess).
    dead_time : float
        Dead time plus lag of the actuator (s), for the starting guess.
    sample_period : float
        Sample period (s); the derivative filter is three samples.
    max_evaluations : int, optional
        Cost evaluations per Nelder–Mead stage.
    stages : tuple of str, optional
        ``("pi",)`` stops after the PI stage.
    reject_oscillating : bool, optional
        A candidate that rings :data:`RING_CYCLES` cycles or more on any run is never chosen.
    margin : bool, optional
        With ``reject_oscillating``, nor one that rings with its gains times :data:`GAIN_MARGIN`.

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
        return pid_cost(build, gains, plant, scenarios, reject_oscillating, margin)

    start, start_cost = coarse_start(cost, static_gain, dead_time, sample_period)
    if not np.isfinite(start_cost) and reject_oscillating:
        if margin:
            LOG.warning(f"no PID gain of the coarse grid keeps a gain margin of {GAIN_MARGIN:g} on the tuning "
                        f"ensemble; tuning without the margin")
            return tune_pid(build, plant, scenarios, static_gain, dead_time, sample_period, max_evaluations, stages,
                            margin=False)
        LOG.warning("every PID gain of the coarse grid rings or fails on the tuning ensemble; tuning without the "
                    "ringing test")
        return tune_pid(build, plant, scenarios, static_gain, dead_time, sample_period, max_evaluations, stages,
                        reject_oscillating=False, margin=False)
    theta = max(dead_time, sample_period)
    options = {"maxfev": max_evaluations, "xatol": 0.02, "fatol": 1e-9, "initial_simplex": None}
    simplex = np.array([start, start + [1.0, 0.0], start + [0.0, 1.0]])
    with np.errstate(invalid="ignore"):  # a rejected candidate's inf in the simplex
        pi = minimize(cost, start, method="Nelder-Mead", options=options | {"initial_simplex": simplex})
    if "pid" not in stages:
        return gains_of(pi.x), float(pi.fun)
    z_pid = np.concatenate((pi.x, [np.log(0.05 * np.exp(pi.x[0]) * theta + 1e-12)]))
    simplex = np.array([z_pid] + [z_pid + 1.0 * np.eye(3)[i] for i in range(3)])
    with np.errstate(invalid="ignore"):
        pid = minimize(cost, z_pid, method="Nelder-Mead", options=options | {"initial_simplex": simplex})
    best = pid if pid.fun < pi.fun else pi
    return gains_of(best.x), float(best.fun)
