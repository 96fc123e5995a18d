"""An actuator file's controllers tuned on its tuning ensemble, once, and cached on disk.

:func:`tuned_baselines` gives both PID baselines their gains (:func:`hystmpc.experiments.tuning.tune_pid`,
the generic rule), ``inverse-ff-pid`` its preview, ``inverse-lmpc`` its rate weight, and both
estimators (``inverse-lmpc``'s Kalman filter, the NMPC's EKF) their disturbance walk, each by the
least mean RMSE on the ensemble with no ringing run (:data:`TUNING_RULE`).
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
from hystmpc.experiments.config import apply_values
from hystmpc.experiments.report import version
from hystmpc.experiments.runner import Scenario
from hystmpc.experiments.tuning import coarse_start, mean_rmse, pid_cost, tune_pid
from hystmpc.mpc.codegen import user_cache_dir
from hystmpc.mpc.linear_mpc import LinearMpcSettings

if TYPE_CHECKING:  # an actuator file's spec is passed in; it imports this module
    from hystmpc.experiments.actuator_file import ActuatorSpec

LOG = logging.getLogger("hystmpc")

TUNING_RULE = "mean-rmse-ensemble-rings-below-3-gain-margin-2-mode-notch-estimator-walk/13"
"""Names the tuning rule in the cache key: change it when the rule changes, or the closed loops it
runs do (the controllers' code: the version in the key does not change in a development install)."""

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
        Parameter groups before tuning, the file's tables applied.

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
    # the walks at the rate weight that will run: the file's [lmpc] wins over the tuned one
    tuned = apply_values(config | {"model": model, "lmpc": lmpc},
                         [(k, v) for k, v in spec.table_values if k.startswith("lmpc.")])
    noisy = spec.tuning_ensemble(model, spec.noise)
    lmpc_walk = _tune_walk(lambda walk: spec.build_inverse_lmpc(tuned | {"lmpc_estimator": walk}),
                           config["lmpc_estimator"], noisy, scenarios, "inverse-lmpc", "lmpc_estimator")

    def nmpc(walk):
        controller = spec.build_nmpc(tuned | {"estimator": walk})
        if controller.settings.inverse_plan == "linear-mpc":  # as the bench gives it its inverse-lmpc
            controller.planner = spec.build_inverse_lmpc(tuned | {"lmpc_estimator": lmpc_walk})
        return controller
    nmpc_walk = _tune_walk(nmpc, config["estimator"], noisy, scenarios, "nmpc", "estimator")
    return {"pid": pid, "inverse_ff_pid": FeedforwardPidGains(**dataclasses.asdict(gains), preview=preview),
            "lmpc": lmpc, "lmpc_estimator": lmpc_walk, "estimator": nmpc_walk}


def _tune_walk(build: Callable, base: DisturbanceWalk, plants: list, scenarios: list[Scenario], name: str,
               group: str) -> DisturbanceWalk:
    """A controller's disturbance walk: of ``base`` times each of :data:`WALK_FACTORS`, the least mean RMSE.

    The rule of :func:`_tune_lmpc`'s rate weight: the mean RMSE over ``scenarios`` on the
    noisy tuning ensemble ``plants`` (seed :data:`TUNING_SEED`), no run ringing; ``base`` when
    the controller cannot be built or run, or every walk fails.
    """
    walks = [(factor, DisturbanceWalk(base.disturbance * factor)) for factor in WALK_FACTORS]
    try:
        clean, any_run, _, best = _least_mean_rmse(walks, build, plants, scenarios)
    except Exception as exc:  # noqa: BLE001 - the other controllers' tuning must not end here; a run says why
        LOG.warning("%s: its disturbance walk is not tuned, it keeps %.4g (%s: %s)", name, base.disturbance,
                    type(exc).__name__, exc)
        return base
    if not np.isfinite(any_run):
        LOG.warning("%s: every disturbance walk tried failed; it keeps the default %.4g (set %s.disturbance)",
                    name, base.disturbance, group)
        return base
    if not np.isfinite(clean):
        LOG.warning("%s: every disturbance walk tried rings on the tuning ensemble; it takes the one with the least "
                    "mean RMSE, %.4g (set %s.disturbance)", name, best.disturbance, group)
    return best


def _least_mean_rmse(candidates: list[tuple], build: Callable, plants: list, scenarios: list[Scenario]) -> tuple:
    """``(clean, any_run, factor, value)`` of the ``(factor, value)`` candidate whose controller tracks best.

    ``clean`` is the mean RMSE with a ringing run making it inf (:func:`mean_rmse`), ``any_run``
    the mean RMSE of every run (when ``clean`` is inf); the least ``clean``, then ``any_run``.
    """
    tried = []
    for factor, value in candidates:
        controller = build(value)
        clean = mean_rmse(controller, plants, scenarios, seed=TUNING_SEED)
        any_run = clean if np.isfinite(clean) else mean_rmse(controller, plants, scenarios, False, TUNING_SEED)
        tried.append((clean, any_run, factor, value))
    return min(tried, key=lambda row: row[:2])


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
    rates = [(factor, dataclasses.replace(base, r_rate=base.r_rate * factor)) for factor in LMPC_RATE_FACTORS]
    clean, any_run, factor, best = _least_mean_rmse(
        rates, lambda settings: spec.build_inverse_lmpc(config | {"model": model}, settings), plants, scenarios)
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
