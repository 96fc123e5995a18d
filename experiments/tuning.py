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
import hashlib
import json
import logging
import os
from collections.abc import Callable
from typing import TYPE_CHECKING, Any

import numpy as np

from hystmpc.experiments.actuator_groups import DisturbanceWalk
from hystmpc.experiments.baselines import FeedforwardPidGains, PidGains
from hystmpc.experiments.report import version
from hystmpc.experiments.runner import Scenario, simulate
from hystmpc.mpc.codegen import user_cache_dir
from hystmpc.mpc.linear_mpc import LinearMpcSettings

if TYPE_CHECKING:  # an actuator file's spec is passed in; it imports this module
    from hystmpc.experiments.actuator_file import ActuatorSpec

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


TUNING_RULE = "mean-rmse-ensemble-rings-below-3-gain-margin-2-mode-notch-estimator-walk/13"
"""Names the tuning rule in the cache key: change it when the rule changes."""

LMPC_RATE_FACTORS = (0.01, 0.1, 1.0, 10.0, 100.0, 1e3, 1e4)
"""The rate weights ``inverse-lmpc``'s tuning tries, relative to the default (the NMPC's
normalised rate weight, on the output span instead of the input span)."""

WALK_FACTORS = (1.0, 0.01)
"""The disturbance walks the NMPC's EKF and ``inverse-lmpc``'s Kalman filter are tuned over, as
multiples of the default variance per sample (the sensor noise squared): the noise's own pace
(the model's error may move as fast as a sample of noise), and a tenth of it in standard
deviation (the model is trusted to drift slowly; less noise reaches the input)."""

TUNING_SEED = 1
"""Sensor-noise seed of the tuning runs (the comparison's default is 0)."""


def tuned_baselines(spec: ActuatorSpec, model, config: dict) -> dict[str, Any]:
    """An actuator file's baselines tuned on its nominal model (PID, inverse-ff-pid, inverse-lmpc), and the NMPC's walk.

    The PID gains come from :func:`tune_pid` on the tuning ensemble
    (:meth:`~hystmpc.experiments.actuator_file.ActuatorSpec.tuning_ensemble`); ``inverse-ff-pid``
    also gets its preview (of dead time + one sample + the block's lag and its two
    neighbours, the one with the best point of the coarse grid), ``inverse-lmpc`` its rate
    weight (the multiple of the default in :data:`LMPC_RATE_FACTORS` with the least mean RMSE
    and no ringing run, on the ensemble with the file's sensor noise, seed
    :data:`TUNING_SEED`), then the disturbance walk of its Kalman filter and of the NMPC's EKF
    (of the default variance times each of :data:`WALK_FACTORS`, by the same rule). The result
    is cached on disk
    (:func:`hystmpc.mpc.codegen.user_cache_dir`), keyed by everything it depends on.

    Parameters
    ----------
    spec : ActuatorSpec
        The actuator file.
    model : ActuatorModel
        The nominal ``model`` group.
    config : dict
        Parameter groups before tuning (``lmpc`` is read).

    Returns
    -------
    dict
        ``pid`` (PidGains), ``inverse_ff_pid`` (FeedforwardPidGains), ``lmpc``
        (LinearMpcSettings), ``lmpc_estimator`` and ``estimator`` (DisturbanceWalk).
    """
    identity = json.dumps({"rule": TUNING_RULE, "version": version(), "model": dataclasses.asdict(model),
                           "sample_period": spec.sample_period, "bounds": spec.input_bounds,
                           "rate": str(spec.input_rate), "scenarios": [spec.sine_hz, spec.step_s, spec.duration_s],
                           "output_range": spec.output_range, "noise": spec.noise,
                           "lmpc": dataclasses.asdict(config["lmpc"]),
                           "lmpc_estimator": dataclasses.asdict(config["lmpc_estimator"]),
                           "lmpc_factors": LMPC_RATE_FACTORS, "walk_factors": WALK_FACTORS,
                           "nmpc": [dataclasses.asdict(config[g])
                                    for g in ("nmpc", "smoothing", "solver", "estimator")],
                           "runner_up": spec.runner_up(),
                           "runner_up_weight": spec.runner_up_weight() if spec.runner_up() else None},
                          sort_keys=True, default=str)
    path = user_cache_dir() / f"tuning-{hashlib.sha256(identity.encode()).hexdigest()[:20]}.json"
    try:
        stored = json.loads(path.read_text())
        return {"pid": PidGains(**stored["pid"]), "inverse_ff_pid": FeedforwardPidGains(**stored["inverse_ff_pid"]),
                "lmpc": LinearMpcSettings(**stored["lmpc"]),
                "lmpc_estimator": DisturbanceWalk(**stored["lmpc_estimator"]),
                "estimator": DisturbanceWalk(**stored["estimator"])}
    except (OSError, ValueError, KeyError, TypeError):
        pass
    LOG.info("tuning the baselines of %s on its nominal model%s (once; cached in %s)", spec.name,
             " and the runner-up blend" if spec.runner_up() else "", path.parent)
    tuned = _tune(spec, model, config)
    try:
        path.parent.mkdir(parents=True, exist_ok=True)
        partial = path.with_suffix(f".{os.getpid()}.tmp")
        partial.write_text(json.dumps({k: dataclasses.asdict(v) for k, v in tuned.items()}))
        partial.replace(path)
    except OSError as exc:  # a read-only home: tune again next time
        LOG.info("could not cache the tuned gains (%s)", exc)
    return tuned


def _tune(spec: ActuatorSpec, model, config: dict) -> dict[str, Any]:
    hysteresis, _ = spec.hysteresis(model)
    state = hysteresis.initial_state(spec.input_bounds[0])
    _, y_lo = hysteresis.step(state, spec.input_bounds[0])
    _, y_hi = hysteresis.step(state, spec.input_bounds[1])
    gain = (y_hi - y_lo) / (spec.input_bounds[1] - spec.input_bounds[0])
    dead = (model.dynamics.delay_samples + 1) * spec.sample_period + model.dynamics.lag()
    plants = spec.tuning_ensemble(model, 0.0)
    scenarios = list(spec.scenarios().values())
    pid = tune_pid(lambda g: spec.build_pid(config | {"model": model}, False, g), plants, scenarios,
                   gain, dead, spec.sample_period)[0]
    rule = model.dynamics.delay_samples + 1 + int(round(model.dynamics.lag() / spec.sample_period))

    def feedforward(preview):
        return lambda g: spec.build_pid(config | {"model": model}, True,
                                        FeedforwardPidGains(**dataclasses.asdict(g), preview=preview))

    def coarse(preview, reject, margin):
        def cost(z):
            gains = PidGains(kp=float(np.exp(z[0])), ki=float(np.exp(z[1])),
                             derivative_filter=3 * spec.sample_period)
            return pid_cost(feedforward(preview), gains, plants, scenarios, reject, margin)
        return coarse_start(cost, gain, dead, spec.sample_period)[1]
    previews = (rule - 1, rule, rule + 1)
    for reject, margin in ((True, True), (True, False), (False, False)):  # as tune_pid falls back
        costs = {p: coarse(p, reject, margin) for p in previews}
        if np.isfinite(min(costs.values())):
            break
    preview = min(previews, key=costs.get)
    gains = tune_pid(feedforward(preview), plants, scenarios, gain, dead, spec.sample_period)[0]
    lmpc = _tune_lmpc(spec, model, config, scenarios)
    noisy = spec.tuning_ensemble(model, spec.noise)
    lmpc_walk = _tune_walk(lambda walk: spec.build_inverse_lmpc(config | {"model": model, "lmpc_estimator": walk},
                                                                lmpc),
                           config["lmpc_estimator"], noisy, scenarios, "inverse-lmpc", "lmpc_estimator")
    nmpc_walk = _tune_walk(lambda walk: spec.build_nmpc(config | {"model": model, "estimator": walk}),
                           config["estimator"], noisy, scenarios, "nmpc", "estimator")
    return {"pid": pid, "inverse_ff_pid": FeedforwardPidGains(**dataclasses.asdict(gains), preview=preview),
            "lmpc": lmpc, "lmpc_estimator": lmpc_walk, "estimator": nmpc_walk}


def _tune_walk(build: Callable, base: DisturbanceWalk, plants: list, scenarios: list[Scenario], name: str,
               group: str) -> DisturbanceWalk:
    """A controller's disturbance walk: of ``base`` times each of :data:`WALK_FACTORS`, the least mean RMSE.

    The rule of :func:`_tune_lmpc`'s rate weight: the mean RMSE over ``scenarios`` on the
    noisy tuning ensemble ``plants`` (seed :data:`TUNING_SEED`), no run ringing; ``base`` when
    the controller cannot be built or every walk fails.
    """
    tried = []
    for factor in WALK_FACTORS:
        walk = DisturbanceWalk(base.disturbance * factor)
        try:
            controller = build(walk)
        except ValueError as exc:  # the run would refuse it too, and say so there
            LOG.info("%s: its disturbance walk is not tuned (%s)", name, exc)
            return base
        clean = mean_rmse(controller, plants, scenarios, seed=TUNING_SEED)
        any_run = clean if np.isfinite(clean) else mean_rmse(controller, plants, scenarios, False, TUNING_SEED)
        tried.append((clean, any_run, factor, walk))
    clean, any_run, _, best = min(tried, key=lambda row: row[:2])
    if not np.isfinite(any_run):
        LOG.warning("%s: every disturbance walk tried failed; it keeps the default %.4g (set %s.disturbance)",
                    name, base.disturbance, group)
        return base
    if not np.isfinite(clean):
        LOG.warning("%s: every disturbance walk tried rings on the tuning ensemble; it takes the one with the least "
                    "mean RMSE, %.4g (set %s.disturbance)", name, best.disturbance, group)
    return best


def _tune_lmpc(spec: ActuatorSpec, model, config: dict, scenarios: list[Scenario]) -> LinearMpcSettings:
    """``inverse-lmpc``'s rate weight, chosen among multiples of the default by mean RMSE.

    Of the default times each of :data:`LMPC_RATE_FACTORS`, it is the one with the least mean
    RMSE over ``scenarios`` on the tuning ensemble (:meth:`tuning_ensemble`) with no run that
    rings (:data:`~hystmpc.experiments.tuning.RING_CYCLES`; when every one does, the least mean
    RMSE, with a warning), with the file's sensor noise (the noise sets how fast it may act),
    drawn with another seed than the comparison's.
    """
    plants = spec.tuning_ensemble(model, spec.noise)
    base: LinearMpcSettings = config["lmpc"]
    tried = []
    for factor in LMPC_RATE_FACTORS:
        settings = dataclasses.replace(base, r_rate=base.r_rate * factor)
        controller = spec.build_inverse_lmpc(config | {"model": model}, settings)
        clean = mean_rmse(controller, plants, scenarios, seed=TUNING_SEED)
        any_run = clean if np.isfinite(clean) else mean_rmse(controller, plants, scenarios, False, TUNING_SEED)
        tried.append((clean, any_run, factor, settings))
    clean, any_run, factor, best = min(tried, key=lambda row: row[:2])
    if not np.isfinite(any_run):
        LOG.warning("inverse-lmpc: every rate weight tried failed; it keeps the default %.4g (set lmpc.r_rate)",
                    base.r_rate)
        return base
    if not np.isfinite(clean):
        LOG.warning("inverse-lmpc: every rate weight tried rings on the tuning ensemble; it takes the one "
                    "with the least mean RMSE, %.4g (set lmpc.r_rate)", best.r_rate)
    elif factor in (LMPC_RATE_FACTORS[0], LMPC_RATE_FACTORS[-1]):
        LOG.warning("inverse-lmpc: the tuned rate weight %.4g is at the edge of the grid tried; a better one may "
                    "lie beyond (set lmpc.r_rate)", best.r_rate)
    return best
