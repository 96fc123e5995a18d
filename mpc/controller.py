"""NMPC as a sampled controller: estimate, warm-start, solve, fall back when a solve fails."""

from __future__ import annotations

from collections.abc import Callable

import numpy as np

from mpc.estimator import DisturbanceEKF
from mpc.nmpc import Nmpc, NmpcSettings, NmpcStep

InverseFn = Callable[[np.ndarray, np.ndarray, np.ndarray], np.ndarray]
"""``(x, d, ref[N]) -> u[N]``: inputs that the inverse model says track ``ref``."""


class NmpcController:
    """Offset-free NMPC loop around :class:`mpc.nmpc.Nmpc`.

    Each sample: EKF time and measurement update, initial guess (inverse model at start-up,
    after a reference jump enters the horizon and after a failure; shifted previous plan
    otherwise), NLP solve; on failure the previous plan's next input (or, without one, the
    inverse model's) is applied, clipped to the bounds, and the failure is counted.

    Parameters
    ----------
    nmpc : Nmpc
        The optimal control problem.
    estimator : DisturbanceEKF
        State and disturbance estimator on the same model.
    initial_state : callable
        ``z -> x0``: a state estimate from the first sensor vector.
    inverse : callable
        ``(x, d, ref) -> u``: inverse-model inputs over the horizon.
    initial_covariance : array_like
        Diagonal of the EKF's initial covariance on ``[x; d]``.
    jump_threshold : float
        A reference change larger than this between samples counts as a jump.
    """

    def __init__(self, nmpc: Nmpc, estimator: DisturbanceEKF, initial_state: Callable,
                 inverse: InverseFn, initial_covariance, jump_threshold: float):
        self.nmpc = nmpc
        self.settings: NmpcSettings = nmpc.settings
        self.estimator = estimator
        self.initial_state = initial_state
        self.inverse = inverse
        self.initial_covariance = np.asarray(initial_covariance, float)
        self.jump_threshold = float(jump_threshold)
        self.reset()

    @property
    def horizon(self) -> int:
        """Prediction horizon in samples."""
        return self.settings.horizon

    def reset(self) -> None:
        """Forget estimate, plan and counters."""
        self._started = False
        self._u_last = 0.0
        self._plan: NmpcStep | None = None
        self._last_ref_end = None
        self.failures = 0
        self.fallbacks = 0
        self.reinitialisations = 0
        self.estimator_resets = 0
        self.iterations: list[int] = []
        self.solve_times: list[float] = []
        self.statuses: dict[str, int] = {}
        self.predicted_output = float("nan")

    def step(self, z, ref_window) -> float:
        """One sample: sensor vector ``z`` and references ``r_k..r_{k+N}`` in, input out."""
        N = self.horizon
        ref_window = np.asarray(ref_window, float).ravel()
        if len(ref_window) != N + 1:
            raise ValueError(f"ref_window needs {N + 1} samples, got {len(ref_window)}")
        if not self.settings.preview:
            ref_window = np.full(N + 1, ref_window[0])
        est = self.estimator
        if not self._started:
            x0 = np.asarray(self.initial_state(z), float)
            est.reset(x0, np.zeros(self.nmpc.model.nd), self.initial_covariance)
        else:
            est.predict([self._u_last])
        self.predicted_output = float(self.nmpc.model.output(est.x, est.d))
        est.update(z)
        if not (np.all(np.isfinite(est.x)) and np.all(np.isfinite(est.d))):
            self.estimator_resets += 1  # never plan from a NaN estimate: start it again
            est.reset(np.asarray(self.initial_state(z), float), np.zeros(self.nmpc.model.nd),
                      self.initial_covariance)
            self._plan = None
        x, d = est.x, est.d
        refs = ref_window[1:]
        cache = []

        def u_inv():  # the inverse model is only needed for warm starts, fallbacks and r_input
            if not cache:
                cache.append(np.clip(np.asarray(self.inverse(x, d, refs), float).ravel(),
                                     self.nmpc.u_min, self.nmpc.u_max))
            return cache[0]

        jump = (self._last_ref_end is not None
                and abs(refs[-1] - self._last_ref_end) > self.jump_threshold)
        self._last_ref_end = refs[-1]
        u_guess, x_guess = self._initial_guess(u_inv, jump, x, d)
        u_ff = u_inv() if self.settings.r_input > 0 else np.zeros(N)  # zero weight: value unused
        result = self.nmpc.solve(x, d, self._u_last, refs, u_guess, x_guess, u_ff=u_ff)
        self.iterations.append(result.iterations)
        self.solve_times.append(result.solve_time)
        self.statuses[result.status] = self.statuses.get(result.status, 0) + 1
        if result.success:
            u = float(result.u_plan[0, 0])
            self._plan = result
        else:
            self.failures += 1
            self.fallbacks += 1
            if self._plan is not None:
                u = float(self._plan.u_plan[min(1, N - 1), 0])
            else:
                u = float(u_inv()[0])
            self._plan = None
        if not np.isfinite(u):  # never send NaN to an actuator
            u = float(u_inv()[0]) if np.isfinite(u_inv()[0]) else self._u_last
        u = float(np.clip(u, self._u_last - self.nmpc.du_max, self._u_last + self.nmpc.du_max))
        u = float(np.clip(u, self.nmpc.u_min, self.nmpc.u_max))
        self._u_last = u
        self._started = True
        return u

    def _initial_guess(self, u_inv, jump, x, d):
        mode = self.settings.warm_start
        N = self.horizon
        if mode == "cold":
            return np.zeros(N), None
        reinit = self._plan is None or jump
        if reinit and mode == "inverse":
            self.reinitialisations += 1
            return u_inv(), None
        if self._plan is None:
            return np.full(N, self._u_last), None
        u_prev = self._plan.u_plan[:, 0]
        u_guess = np.concatenate((u_prev[1:], u_prev[-1:]))
        if getattr(self.nmpc, "condensed", False):  # the condensed RTI step rolls out the states itself
            return u_guess, None
        x_prev = self._plan.x_plan
        x_tail = np.asarray(self.nmpc.model.step(x_prev[-1], u_prev[-1], d)).ravel()
        x_guess = np.vstack((x_prev[1:], x_tail))
        x_guess[0] = x
        return u_guess, x_guess

    def stats(self) -> dict:
        """Solver statistics of the run so far (for the results document)."""
        its = np.asarray(self.iterations) if self.iterations else np.zeros(1)
        return {"name": self.settings.solver, "failures": self.failures, "fallbacks": self.fallbacks,
                "iterations_median": float(np.median(its)), "iterations_max": int(its.max()),
                "reinitialisations": self.reinitialisations, "estimator_resets": self.estimator_resets,
                "statuses": dict(self.statuses)}
