"""The NMPC as a sampled controller: estimate, warm-start, solve, fall back when a solve fails.

One loop for every prediction model: a :class:`~hystmpc.models.prediction.PredictionModel`
gets the multiple-shooting problem, a
:class:`~hystmpc.models.prediction.CreepPredictionModel` the single-shooting one; a
state-driven model an EKF on all its states, an input-driven one the exact memory and an
EKF on its dynamics (:mod:`hystmpc.mpc.observer`).
"""

from __future__ import annotations

from collections.abc import Callable

import numpy as np

from hystmpc.models.prediction import CreepPredictionModel, PredictionModel
from hystmpc.mpc.estimator import DisturbanceEKF
from hystmpc.mpc.multiple_shooting import MultipleShootingProblem
from hystmpc.mpc.observer import Estimate, MemoryObserver, StateObserver, memory_inverse
from hystmpc.mpc.problem import Solution, TrackingProblem
from hystmpc.mpc.settings import InputBounds, NmpcSettings, SolverSettings, second_start_cost
from hystmpc.mpc.single_shooting import SingleShootingProblem

Inverse = Callable[[Estimate, np.ndarray], np.ndarray]
"""``(estimate, ref[N]) -> u[N]``: inputs that an inverse model says track ``ref``."""


def default_observer(model: PredictionModel | CreepPredictionModel, sensor_noise=None,
                     creep_window: int | None = None, disturbance_walk: float | None = None):
    """The observer a model gets when none is given.

    Parameters
    ----------
    model : PredictionModel or CreepPredictionModel
        The prediction model.
    sensor_noise : float or array_like, optional
        Standard deviation of each sensor; the EKFs are tuned from it
        (:meth:`DisturbanceEKF.from_sensor_noise`). Needed when the model has sensors.
    creep_window : int, optional
        Past samples in the creep sums of an input-driven model's observer (None: all).
    disturbance_walk : float, optional
        The EKF's disturbance step per sample (default: the sensor noise; see
        :meth:`DisturbanceEKF.from_sensor_noise`).

    Returns
    -------
    MemoryObserver or StateObserver
        Exact memory + an EKF on the dynamics for an input-driven model (no EKF for one without
        dynamic states or sensors), an EKF on every state otherwise.
    """
    memory = model.memory
    if memory is not None and not (memory.n_dynamic or model.sensor_names):
        return MemoryObserver(model, creep_window=creep_window)  # feed-forward: the inputs fix the state
    if model.sensor_names and sensor_noise is None:
        raise ValueError(f"the model has sensors {model.sensor_names}: give sensor_noise (each sensor's standard "
                         "deviation) or an observer")
    if memory is not None:
        ekf, p0 = DisturbanceEKF.from_sensor_noise(memory.dynamics or model, sensor_noise, disturbance_walk)
        return MemoryObserver(model, ekf, initial_covariance=p0, creep_window=creep_window)
    ekf, p0 = DisturbanceEKF.from_sensor_noise(model, sensor_noise, disturbance_walk)
    return StateObserver(model, ekf, lambda z: np.zeros(model.nx), p0)


class NmpcController:
    """Offset-free NMPC loop.

    Each sample: the observer's time and measurement update (restarted from the sensors if
    the estimate is not finite, which counts as a failure: the fallback input is applied);
    an initial guess (inverse model at start-up, after a
    reference jump enters the horizon and after a failure; the shifted previous plan
    otherwise); the solve; on failure the previous plan's next input (or, without one, the
    inverse model's) is applied, and the failure is counted. The input sent is always
    finite and inside ``bounds``.

    Parameters
    ----------
    model : PredictionModel or CreepPredictionModel
        The nominal prediction model (:func:`hystmpc.models.prediction.build_prediction_model`).
    bounds : InputBounds
        Input bounds and rate bound.
    settings : NmpcSettings, optional
        Horizon, weights, solver variant, preview, warm start (default: the defaults).
    solvers : SolverSettings, optional
        The solvers' own settings (default: the defaults).
    observer : StateObserver or MemoryObserver, optional
        Default: :func:`default_observer` with ``sensor_noise``.
    inverse : callable, optional
        ``(estimate, refs) -> u``; default for input-driven models:
        :func:`hystmpc.mpc.observer.memory_inverse`. Needed for ``warm_start='inverse'``
        and ``r_input > 0``.
    sensor_noise : float or array_like, optional
        Standard deviation of each sensor, for the default observer.
    planner : InverseLinearMpc, optional
        For ``inverse_plan='linear-mpc'``: the inverse-model inputs are its plan each sample
        (:meth:`~hystmpc.mpc.linear_mpc.InverseLinearMpc.plan`); it is told the input sent.
        A bench gives its ``inverse-lmpc`` (or set :attr:`planner` before the first sample).
    jump_threshold : float
        A reference change larger than this between samples counts as a jump (default: never).
    creep_window : int, optional
        Past samples in the creep sums of a creep model's default observer (None: all).
    """

    def __init__(self, model: PredictionModel | CreepPredictionModel, bounds: InputBounds,
                 settings: NmpcSettings | None = None, solvers: SolverSettings | None = None, *,
                 observer=None, inverse: Inverse | None = None, planner=None, sensor_noise=None,
                 jump_threshold: float = np.inf, creep_window: int | None = None):
        settings, solvers = settings or NmpcSettings(), solvers or SolverSettings()
        settings.check_combination(solvers)  # before a solver is built (and compiled)
        self.model, self.bounds, self.settings, self.solvers = model, bounds, settings, solvers
        if isinstance(model, CreepPredictionModel):
            N = settings.horizon
            compact = {}
            if settings.solver in ("rti", "rti-c"):  # the RTI step is generated: build it from small parts
                compact = {"predict_jacobian": model.horizon_jacobian(N),
                           "compact_predict": model.horizon_function(N, inline=False)}
            self.problem: TrackingProblem = SingleShootingProblem(model.horizon_function(N), settings, bounds, solvers,
                                                                  **compact)
        else:
            self.problem = MultipleShootingProblem(model, settings, bounds, solvers)
        if observer is not None and sensor_noise is not None:
            raise ValueError("sensor_noise tunes the default observer: give it or an observer, not both")
        self.observer = observer if observer is not None else default_observer(model, sensor_noise, creep_window)
        if inverse is None and model.memory is not None and model.memory.steady_input is not None:
            inverse = memory_inverse(model.memory, model.sample_period)
        static = settings.inverse_plan == "static"  # else a planner's inputs stand for the inverse model's
        if inverse is None and static and (settings.warm_start == "inverse" or settings.r_input > 0):
            reason = ("the hysteresis is driven by a state" if model.memory is None else
                      "the model's Dynamics give no steady_input (the hysteresis output that holds an output at rest)")
            raise ValueError(f"no default inverse model for the warm start and r_input: {reason}; give inverse=..., "
                             "or use nmpc.warm_start=shift with nmpc.r_input=0")
        if settings.multistart and inverse is None and static:
            raise ValueError("nmpc.multistart also solves from the inverse model's inputs, and this model has none: "
                             "give inverse=..., or set nmpc.multistart=false")
        self.inverse = inverse
        prepare = getattr(inverse, "prepare", None) if static else None  # else a planner's inputs are used
        if prepare is not None:  # its Function built and compiled now, not inside the first sample
            try:
                prepare(self.observer.estimate(settings.horizon), settings.horizon)
            except Exception:  # noqa: BLE001 - an observer with no estimate yet: built at the first sample
                pass
        if planner is not None and static:
            raise ValueError("a planner gives the inverse-model inputs with nmpc.inverse_plan=linear-mpc; "
                             "nmpc.inverse_plan is 'static': set it, or give no planner")
        self.planner = planner
        self.jump_threshold = float(jump_threshold)
        self.reset()

    @property
    def horizon(self) -> int:
        """Prediction horizon in samples (the reference preview this controller asks for)."""
        return self.settings.horizon

    @property
    def sensor_names(self) -> tuple[str, ...]:
        """Measured signals the controller reads (``y``: the tracked output)."""
        return self.model.sensor_names

    def reset(self) -> None:
        """Forget estimate, plan and counters."""
        self.observer.reset()
        if self.planner is not None:
            self.planner.reset()
        self._started = False
        self._u_last = 0.0
        self._plan: Solution | None = None
        self._last_ref_end = None
        self.failures = 0
        self.fallbacks = 0
        self.reinitialisations = 0
        self.inverse_starts_kept = 0
        self.second_starts = 0
        self._paused = 0  # samples left without a second start after one that lost
        self.estimator_resets = 0
        self.iterations: list[int] = []
        self.solve_times: list[float] = []
        self.statuses: dict[str, int] = {}
        self.predicted_output = float("nan")

    def sensors(self, measurement) -> np.ndarray:
        """The sensor vector ``z`` of a plant's measurement.

        Parameters
        ----------
        measurement : Measurement
            A plant's measurement.

        Returns
        -------
        ndarray
            One value per name of :attr:`sensor_names` (``y``: the measured output).
        """
        return np.array([measurement.y if name == "y" else measurement.sensors[name]
                         for name in self.sensor_names], float)

    def step(self, measurement, ref_window) -> float:
        """One sample: a measurement and the references ``r_k..r_{k+N}`` in, the input out.

        Parameters
        ----------
        measurement : Measurement
            This sample's measurement.
        ref_window : array_like
            The ``N + 1`` references ``r_k..r_{k+N}``; the problem tracks ``r_{k+1}..r_{k+N}``
            (all held at ``r_k`` without ``preview``).

        Returns
        -------
        float
            The input to send, finite and inside ``bounds``.
        """
        # a diverging estimate or cost is tested for and counted below, not warned about
        with np.errstate(over="ignore", invalid="ignore", divide="ignore"):
            return self._step(measurement, ref_window)

    def _step(self, measurement, ref_window) -> float:
        N = self.horizon
        ref_window = np.asarray(ref_window, float).ravel()
        if len(ref_window) != N + 1:
            raise ValueError(f"ref_window needs {N + 1} samples, got {len(ref_window)}")
        if not self.settings.preview:
            ref_window = np.full(N + 1, ref_window[0])
        planned = None
        if self.settings.inverse_plan == "linear-mpc":
            if self.planner is None:
                raise ValueError("nmpc.inverse_plan=linear-mpc takes its inputs from a linear MPC's plan, and this "
                                 "controller has none: give planner=InverseLinearMpc(...), or set "
                                 "nmpc.inverse_plan=static")
            planned = self.planner.plan(measurement, ref_window)  # every sample: its estimate follows the loop
        estimate_lost = self.observer.update(self.sensors(measurement), self._u_last if self._started else None)
        if estimate_lost:
            self.estimator_resets += 1  # never plan from a NaN estimate: it started again from the sensors
            self._plan = None
        self.predicted_output = self.observer.predicted_output
        est = self.observer.estimate(N)
        refs = ref_window[1:]
        cache = []

        def u_inv():  # the inverse model is only needed for warm starts, fallbacks and r_input
            if not cache:
                u = np.asarray(self.inverse(est, refs) if planned is None else planned, float).ravel()
                u = np.where(np.isfinite(u), u, self._u_last)
                cache.append(np.clip(u, self.bounds.lower, self.bounds.upper))
            return cache[0]

        jump = (self._last_ref_end is not None
                and abs(refs[-1] - self._last_ref_end) > self.jump_threshold)
        self._last_ref_end = refs[-1]
        paused, self._paused = self._paused > 0, max(self._paused - 1, 0)  # counts every sample, as in C
        if estimate_lost:  # a failure: the restarted estimate has not seen one update yet
            result = Solution(u_plan=np.full((N, 1), np.nan), x_plan=None, success=False,
                              status="Non_Finite_Estimate", iterations=0, solve_time=0.0)
        else:
            reinitialised = self.reinitialisations
            u_guess, x_guess = self._initial_guess(u_inv, jump, est)
            from_inverse = self.reinitialisations > reinitialised  # this sample already starts from the inverse
            u_ff = u_inv() if self.settings.r_input > 0 else np.zeros(N)  # zero weight: value unused
            condition = self.observer.condition(est)
            result = self.problem.solve(condition, self._u_last, refs, u_guess, x_guess, u_ff=u_ff)
            if self.settings.multistart and not from_inverse and self._plan_is_off(result, paused):
                self.second_starts += 1
                other = self.problem.solve(condition, self._u_last, refs, u_inv(), None, u_ff=u_ff)
                if other.success and (not result.success or other.cost < result.cost):
                    self.inverse_starts_kept += 1
                    other.solve_time += result.solve_time
                    other.iterations += result.iterations
                    result = other
                else:
                    self._paused = self.settings.second_start_pause
                    result.solve_time += other.solve_time
                    result.iterations += other.iterations
            if result.success and not np.all(np.isfinite(result.u_plan)):
                result.success, result.status = False, f"{result.status}_Non_Finite"
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
            elif self.inverse is not None or planned is not None:
                u = float(u_inv()[0])
            else:
                u = self._u_last
            self._plan = None
        if not np.isfinite(u):  # never send NaN to an actuator (u_inv is finite: it fills in the last input)
            u = float(u_inv()[0]) if self.inverse is not None or planned is not None else self._u_last
        u = self.bounds.clip(u, self._u_last)
        if planned is not None:
            self.planner.applied(u)
        self._u_last = u
        self._started = True
        return u

    def _plan_is_off(self, result: Solution, paused: bool) -> bool:
        """Whether to solve again from the inverse: ``result`` failed, or it is off.

        Off: always with ``nmpc.second_start_error`` 0; else, unless ``paused``, where it both
        costs more and ends further off than the error allows (a NaN counts as over).
        """
        limit = second_start_cost(self.settings)
        if limit is None or not result.success:
            return True
        return not (paused or result.cost <= limit or abs(result.end_error) <= self.settings.second_start_error)

    def _initial_guess(self, u_inv, jump: bool, est: Estimate):
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
        if not self.problem.multiple_shooting or getattr(self.problem, "condensed", False):
            return u_guess, None  # only the inputs are unknowns (or the step rolls out the states itself)
        x_prev = self._plan.x_plan
        x_tail = np.asarray(self.model.step(x_prev[-1], u_prev[-1], est.d)).ravel()
        x_guess = np.vstack((x_prev[1:], x_tail))
        x_guess[0] = est.x
        return u_guess, x_guess

    def stats(self) -> dict:
        """Solver statistics of the run so far (for the results document).

        Returns
        -------
        dict
            ``name`` (the solver), ``failures``, ``fallbacks``, ``iterations_median``,
            ``iterations_max``, ``reinitialisations``, ``estimator_resets``, ``statuses``
            (status -> samples), with ``multistart`` also ``second_starts`` (samples solved from
            the inverse too) and ``inverse_starts_kept``, with a
            linear-MPC planner also ``planner_failures``.
        """
        its = np.asarray(self.iterations) if self.iterations else np.zeros(1)
        return {"name": self.settings.solver, "failures": self.failures, "fallbacks": self.fallbacks,
                "iterations_median": float(np.median(its)), "iterations_max": int(its.max()),
                "reinitialisations": self.reinitialisations, "estimator_resets": self.estimator_resets,
                "statuses": dict(self.statuses),
                **({"second_starts": self.second_starts, "inverse_starts_kept": self.inverse_starts_kept}
                   if self.settings.multistart else {}),
                **({"planner_failures": self.planner.failures}
                   if self.settings.inverse_plan == "linear-mpc" and self.planner is not None else {})}
