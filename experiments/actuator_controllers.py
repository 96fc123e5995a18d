"""The controllers an actuator file builds: ``pid``, ``inverse-ff-pid``, ``inverse-lmpc`` and ``nmpc``.

:class:`ActuatorControllers` is the part of
:class:`~hystmpc.experiments.actuator_file.ActuatorSpec` that builds each controller from the
parameter groups, with the baselines' gains tuned on the tuning ensemble
(:mod:`hystmpc.experiments.actuator_tuning`).
"""

from __future__ import annotations

from typing import Any

import numpy as np

from hystmpc.experiments.actuator_groups import ActuatorModel
from hystmpc.experiments.actuator_tuning import tuned_baselines
from hystmpc.experiments.baselines import (
    InverseCompensation,
    ModeNotch,
    PidController,
    PidGains,
    inverse_feedforward_pid,
)
from hystmpc.experiments.baselines.pid import NOTCH_DAMPING
from hystmpc.models.prediction import Smoothing, build_prediction_model
from hystmpc.mpc import InputBounds, NmpcController, default_observer
from hystmpc.mpc.linear_mpc import InverseLinearMpc, LinearMpcSettings


class ActuatorControllers:
    """Controller builders of an actuator file (mixed into :class:`~hystmpc.experiments.actuator_file.ActuatorSpec`)."""

    def build_pid(self, config: dict, feedforward: bool, gains: PidGains | None = None):
        """``pid`` or ``inverse-ff-pid`` on the ``model`` group.

        Parameters
        ----------
        config : dict
            Parameter groups.
        feedforward : bool
            Build ``inverse-ff-pid`` (the inverse hysteresis feed-forward), else ``pid``.
        gains : PidGains, optional
            The gains (default: the config's ``inverse_ff_pid`` or ``pid`` group).

        Returns
        -------
        PidController
            The controller.
        """
        model: ActuatorModel = config["model"]
        gains = gains if gains is not None else config["inverse_ff_pid" if feedforward else "pid"]
        notch = self.command_notch(model)
        if not feedforward:
            return PidController(gains, self.sample_period, self.input_bounds, rate=self.input_rate,
                                 command_filter=notch)
        hysteresis, _ = self.hysteresis(model)
        return inverse_feedforward_pid(hysteresis, gains, self.sample_period, self.input_bounds,
                                       preview=gains.preview, rate=self.input_rate, command_filter=notch)

    def command_notch(self, model: ActuatorModel) -> ModeNotch | None:
        """The PID baselines' notch on the command, where the model's mode is lightly damped.

        A second-order block with damping below :data:`NOTCH_DAMPING` rings at every step
        of the command, whatever the PID's gains; an engineer puts a notch at the mode in front
        of such an actuator. The notch replaces the model's mode by one damped at
        :data:`NOTCH_DAMPING` (:class:`~hystmpc.experiments.baselines.ModeNotch`).

        Parameters
        ----------
        model : ActuatorModel
            The ``model`` group.

        Returns
        -------
        ModeNotch or None
            The notch, or None (no second-order block, or one damped at least that much).
        """
        block = model.dynamics
        if block.kind != "second-order" or block.damping >= NOTCH_DAMPING:
            return None
        return ModeNotch(block, self.sample_period, NOTCH_DAMPING)

    def _estimator_noise(self) -> float:
        """The sensor noise the NMPC's EKF and inverse-lmpc's Kalman filter are tuned for.

        It is at least 0.1 % of the output range, so that a noise-free file still filters.
        """
        return max(self.noise, 1e-3 * (self.output_range[1] - self.output_range[0]))

    def build_nmpc(self, config: dict) -> NmpcController:
        """The NMPC on the smoothed model, EKF from the sensor noise, inverse warm start.

        Parameters
        ----------
        config : dict
            Parameter groups (``model``, ``smoothing``, ``nmpc``, ``solver``, ``estimator``: the
            EKF's disturbance walk).

        Returns
        -------
        NmpcController
            The controller.
        """
        model: ActuatorModel = config["model"]
        smoothing: Smoothing = config["smoothing"]
        hysteresis, creep_order = self.hysteresis(model)
        pm = build_prediction_model(hysteresis, self.sample_period,
                                    dynamics=model.dynamics.discrete(self.sample_period, hold=creep_order > 0),
                                    eps=smoothing.eps, direction_eps=smoothing.direction,
                                    delay_samples=model.dynamics.delay_samples, creep_order=creep_order)
        bounds = InputBounds(*self.input_bounds, self.input_rate)
        observer = default_observer(pm, self._estimator_noise(),
                                    disturbance_walk=np.sqrt(config["estimator"].disturbance))
        return NmpcController(pm, bounds, config["nmpc"], config["solver"], observer=observer)

    def build_inverse_lmpc(self, config: dict, settings: LinearMpcSettings | None = None) -> InverseLinearMpc:
        """``inverse-lmpc`` on the ``model`` group: the exact inverse hysteresis and a linear MPC.

        The exact inverse hysteresis in series with the input (its memory follows the inputs sent)
        turns a virtual input ``v`` into the input; a linear MPC with an input disturbance
        (offset-free; creep lands in it) controls the linear block and dead time from ``v``.

        Parameters
        ----------
        config : dict
            Parameter groups.
        settings : LinearMpcSettings, optional
            The linear MPC's settings (default: the config's ``lmpc`` group).

        Returns
        -------
        InverseLinearMpc
            The controller.
        """
        model: ActuatorModel = config["model"]
        hysteresis, _ = self.hysteresis(model)
        linear = model.dynamics.virtual_input_model(self.sample_period)
        noise = self._estimator_noise()
        n_block = linear.nx - model.dynamics.delay_samples
        # as the NMPC's EKF (DisturbanceEKF.from_sensor_noise); the queue of virtual inputs is known exactly
        process = [(0.01 * noise) ** 2] * n_block + [1e-12 * noise**2] * model.dynamics.delay_samples + \
            [config["lmpc_estimator"].disturbance]
        initial = [(10 * noise) ** 2] * n_block + [1e-12 * noise**2] * model.dynamics.delay_samples + \
            [(1000 * noise) ** 2]
        return InverseLinearMpc(
            linear, InverseCompensation(hysteresis, sensors=("y",),
                                        rest_input=float(np.clip(0.0, *self.input_bounds))),  # the plant's
            InputBounds(*self.input_bounds, self.input_rate), settings or config["lmpc"], process_noise=process,
            measurement_noise=[noise**2], initial_state=lambda z: np.concatenate(
                (model.dynamics.rest_state(z[0]), np.full(model.dynamics.delay_samples, z[0]))),
            initial_covariance=initial)

    def tuned_gains(self, config: dict) -> dict[str, Any]:
        """The baselines' tuned gains, preview and rate weight, and both estimators' disturbance walks.

        The gains come from :func:`hystmpc.experiments.tuning.tune_pid` on the nominal ``model``
        group. For ``inverse-ff-pid`` also its preview: of dead time + one sample + the block's
        lag and its two neighbours, the one with the best point of the coarse gain grid, before
        the gains are tuned at it. For ``inverse-lmpc`` its rate weight, then its Kalman filter's
        disturbance walk, and the NMPC's EKF's disturbance walk
        (:func:`hystmpc.experiments.actuator_tuning.tuned_baselines`).

        Tuning runs many closed loops, so the result is kept in memory and on disk
        (:func:`hystmpc.mpc.codegen.user_cache_dir`), keyed by everything it depends on.

        Parameters
        ----------
        config : dict
            Parameter groups before tuning, the file's tables applied.

        Returns
        -------
        dict
            ``pid`` (PidGains), ``inverse_ff_pid`` (FeedforwardPidGains), ``lmpc``
            (LinearMpcSettings), ``lmpc_estimator`` and ``estimator`` (DisturbanceWalk).
        """
        model = config["model"]
        key = repr(model)
        if key not in self._tuned:
            self._tuned[key] = tuned_baselines(self, model, config)
        return self._tuned[key]
