"""Prediction models for the NMPC, built from a hysteresis model and the actuator's dynamics.

An actuator is a hysteresis model and the dynamics around it. Two arrangements cover the
actuators here, and :func:`build_prediction_model` composes both the same way:

* **input-driven** (Hammerstein): the input, after an optional dead time, drives the
  hysteresis and its output ``h`` drives the dynamics (a piezo stage, the DEA) or is
  mapped statically to the output (the reluctance actuator's force table);
* **state-driven**: a state of the dynamics drives the hysteresis, whose output feeds
  back into the dynamics (the PAM joint: Δp_hys of the joint angle) or is the output
  (the compliant actuator: torque of the spring's deformation).

The dynamics are a right-hand side ``rhs(x, u, h, d)`` in continuous time (integrated
with :func:`hystmpc.models.integrators.rk4`) or in discrete time. ``d`` is the
offset-free disturbance the NMPC's estimator tracks and holds over the horizon; where it
enters is a choice (``disturbance``): added to the output, to the hysteresis output, or
left to ``rhs``. With creep (a Grünwald–Letnikov fractional integral between the
hysteresis and the dynamics), the prediction is not a Markov step: the builder then
returns a :class:`CreepPredictionModel`, whose horizon prediction takes the creep history
as parameters (docs/dea.md, "Model").

The result carries what a controller needs to know beyond the step: sensor names and,
for input-driven models, :class:`InputMemory`, the parts of the state that follow exactly
from the applied inputs (dead time, hysteresis, creep), so that an estimator only has to
estimate the dynamics.
"""

from __future__ import annotations

from collections.abc import Callable
from dataclasses import dataclass, field

import casadi as ca
import numpy as np

from hystmpc.models.base import HysteresisModel
from hystmpc.models.fractional import gl_weights
from hystmpc.models.integrators import rk4

DISTURBANCES = ("auto", "output", "hysteresis", "dynamics", "none")
"""Where the offset-free disturbance ``d`` enters: added to the tracked output, added to the
hysteresis output before it drives the dynamics (an input disturbance), passed to ``rhs``
(the dynamics decide), or nowhere (feed-forward actuators). ``auto``: ``hysteresis`` for an
input-driven model with dynamic states, ``output`` otherwise."""


@dataclass(frozen=True)
class Smoothing:
    """How the switching of the hysteresis is smoothed in a prediction model (``--set smoothing.*``)."""

    eps: float = 1e-3
    """Smoothing width of the switching (clips, kinks, branch blends), in the hysteresis input's units."""
    direction_eps: float = 0.0
    """Width of the input-direction detection, for models that have one; 0: the model's
    default (``eps``). Must be well below the input change per sample."""

    def __post_init__(self):
        if not (np.isfinite(self.eps) and self.eps > 0):
            raise ValueError(f"eps must be finite and > 0, got {self.eps}")
        if not (np.isfinite(self.direction_eps) and self.direction_eps >= 0):
            raise ValueError(f"direction_eps must be finite and >= 0 (0: eps), got {self.direction_eps}")

    @property
    def direction(self) -> float | None:
        """``direction_eps`` as the models take it (None: the model's default)."""
        return self.direction_eps or None


@dataclass(frozen=True)
class PredictionModel:
    """Nominal model ``x+ = step(x, u, d)``, ``y = output(x, d)``, ``z = measure(x, d)``.

    ``d`` is an unknown disturbance the estimator tracks and the NMPC holds constant over
    the horizon; it is what makes the tracking offset-free.
    """

    step: ca.Function
    """``(x, u, d) -> x_next``, smooth (CasADi SX)."""
    output: ca.Function
    """``(x, d) -> y``, the tracked output (scalar)."""
    measure: ca.Function
    """``(x, d) -> z``, what the sensors see (vector)."""
    sample_period: float
    """Sample period (s)."""
    state_names: tuple[str, ...]
    """One name per state, for logs and errors."""
    sensor_names: tuple[str, ...] = ("y",)
    """One name per entry of ``z``: ``y`` is the measured tracked output, any other name a
    key of the plant's ``Measurement.sensors``."""
    memory: InputMemory | None = None
    """For input-driven models: the states that follow exactly from the applied inputs."""

    def __post_init__(self):
        for name, fun, n_in in (("step", self.step, 3), ("output", self.output, 2),
                                ("measure", self.measure, 2)):
            if fun.n_in() != n_in:
                raise ValueError(f"{name} must take {n_in} inputs, got {fun.n_in()}")
        if len(self.state_names) != self.nx:
            raise ValueError(f"{len(self.state_names)} state names for {self.nx} states")
        if len(self.sensor_names) != self.nz:
            raise ValueError(f"{len(self.sensor_names)} sensor names for {self.nz} measured signals")

    @property
    def nx(self) -> int:
        """Number of states."""
        return self.step.size1_in(0)

    @property
    def nu(self) -> int:
        """Number of inputs."""
        return self.step.size1_in(1)

    @property
    def nd(self) -> int:
        """Number of disturbance states."""
        return self.step.size1_in(2)

    @property
    def nz(self) -> int:
        """Number of measured signals."""
        return self.measure.size1_out(0)

    def rollout(self, x0, u_seq, d) -> np.ndarray:
        """States ``x_0..x_N`` (shape ``(N+1, nx)``) under the inputs ``u_seq`` (shape ``(N, nu)``).

        Parameters
        ----------
        x0 : array_like
            Initial state.
        u_seq : array_like
            Inputs, reshaped to ``(N, nu)``.
        d : array_like or float
            Disturbance, held over the rollout.

        Returns
        -------
        ndarray, shape (N+1, nx)
            The states, ``x0`` first.
        """
        u_seq = np.asarray(u_seq, float).reshape(-1, self.nu)
        xs = np.empty((len(u_seq) + 1, self.nx))
        xs[0] = np.asarray(x0, float).ravel()
        for k, u in enumerate(u_seq):
            xs[k + 1] = np.asarray(self.step(xs[k], u, d)).ravel()
        return xs


@dataclass(frozen=True)
class InputMemory:
    """The part of an input-driven model that the applied inputs fix exactly.

    The model's state is ``[x_dyn, hysteresis state, dead-time queue]``; a controller can run
    the exact ``hysteresis`` (and the creep, if any) on the inputs it applied, and estimate
    only ``x_dyn`` with ``dynamics``.
    """

    hysteresis: HysteresisModel
    """The exact hysteresis model (the smooth one predicts)."""
    delay_samples: int
    """Samples of dead time before the hysteresis."""
    dynamics: PredictionModel | None
    """``x_dyn+ = step(x_dyn, h, d)`` driven by the hysteresis (and creep) output ``h``, with
    the model's output and sensors; None when the dynamics cannot be split off (no dynamic
    states, the input acting on them besides the hysteresis, or the output reading ``h``):
    an estimator then runs on the whole model with the exact states held."""
    creep_order: float = 0.0
    """α of the Grünwald–Letnikov creep integral between hysteresis and dynamics (0: none)."""
    steady_input: Callable | None = None
    """``y -> h``: the hysteresis output that holds the output at ``y`` at rest (NumPy)."""
    disturbance: str = "output"
    """Where ``d`` enters (one of :data:`DISTURBANCES` but ``auto``)."""

    n_dynamic: int = 0
    """Number of dynamic states (the model's first states; the estimated ones)."""
    steady_correction: Callable | None = None
    """``(h, d) -> h`` with ``disturbance='dynamics'``: the hysteresis output that drives the
    dynamics as ``h`` does without disturbance (None: ``h``, no correction)."""
    rest_state: Callable | None = None
    """``h -> sequence``: the dynamic states at rest under the hysteresis output ``h`` (NumPy or
    CasADi); None: they start at zero."""


@dataclass(frozen=True)
class Dynamics:
    """The actuator around its hysteresis, for :func:`build_prediction_model`.

    Every callable takes CasADi expressions; written with plain arithmetic (and ``xp``
    arguments where a function is needed) the same callables serve a NumPy plant.
    """

    state_names: tuple[str, ...] = ()
    """Names of the dynamic states ``x``."""
    rhs: Callable | None = None
    """``(x, u, h, d) -> sequence``: ``x'`` (continuous) or ``x+`` (``discrete``). ``u`` is the
    input after the dead time, ``h`` the hysteresis output (plus ``d`` where the disturbance
    enters there), ``d`` the disturbance where it enters the dynamics (else 0)."""
    output: Callable = field(default=lambda x, h: h)
    """``(x, h) -> y``: the tracked output before an output disturbance (default: ``h``)."""
    hysteresis_input: Callable | None = None
    """``(x, u) -> v``: the state drives the hysteresis (evaluated along the integration);
    None: the input drives it."""
    shares_last_input: bool = False
    """With a state-driven hysteresis whose input is itself a state: the hysteresis' last
    input (``state[0]``) is that state's value at the sample start, not stored again."""
    sensor_names: tuple[str, ...] = ("y",)
    """Measured signals (``y``: the tracked output; others: ``Measurement.sensors`` keys);
    empty for a feed-forward actuator."""
    measure: Callable | None = None
    """``(x, h, y) -> sequence`` of the sensor values; None: ``[y]`` (or nothing)."""
    steady_input: Callable | None = None
    """``y -> h``: the hysteresis output that holds the output at ``y`` at rest (the static
    inverse of the dynamics; NumPy). Default inverse warm starts need it."""
    discrete: bool = False
    """``rhs`` gives the next state over one sample instead of the derivative."""
    rest_state: Callable | None = None
    """``h -> sequence``: the states at rest under the hysteresis output ``h`` (NumPy or CasADi),
    for states that remember it for long (a creep); None: the states start at zero."""
    disturbances: int = 1
    """Entries of ``d`` that ``rhs`` reads (``disturbance="dynamics"`` only): the estimator
    tracks them all and the NMPC holds them over the horizon, so besides the offset-free
    one they can be slow model errors, such as a gain, that the estimator learns."""
    steady_correction: Callable | None = None
    """``(h, d) -> h`` with ``disturbance='dynamics'``: the hysteresis output that drives the
    dynamics under the disturbances ``d`` as ``h`` does without (NumPy or CasADi); the
    default inverse warm start corrects ``steady_input`` with it. None: no correction."""

    def __post_init__(self):
        if self.state_names and self.rhs is None:
            raise ValueError("dynamics with states need a rhs")
        if self.shares_last_input and self.hysteresis_input is None:
            raise ValueError("shares_last_input needs a state-driven hysteresis (hysteresis_input)")
        if isinstance(self.disturbances, bool) or not isinstance(self.disturbances, (int, np.integer)) \
                or self.disturbances < 1:
            raise ValueError(f"disturbances must be an integer >= 1, got {self.disturbances!r}")


def _resolve_disturbance(disturbance: str, dynamics: Dynamics) -> str:
    if disturbance not in DISTURBANCES:
        raise ValueError(f"disturbance {disturbance!r} is unknown; allowed: {', '.join(DISTURBANCES)}")
    if dynamics.disturbances != 1 and disturbance != "dynamics":
        raise ValueError(f"{dynamics.disturbances} disturbances need disturbance='dynamics' (rhs reads them), "
                         f"got {disturbance!r}")
    if disturbance != "auto":
        return disturbance
    input_driven = dynamics.hysteresis_input is None
    return "hysteresis" if input_driven and dynamics.state_names else "output"


def _stack(values) -> ca.SX:
    if isinstance(values, (ca.SX, ca.MX)):
        return values
    values = list(values) if isinstance(values, (list, tuple)) else [values]
    return ca.vertcat(*values) if values else ca.SX(0, 1)


def _rhs(dynamics: Dynamics, x, u, h, d) -> ca.SX:
    """``rhs`` stacked, checked for one entry per state."""
    value = _stack(dynamics.rhs(x, u, h, d))
    if value.numel() != len(dynamics.state_names):
        raise ValueError(f"the dynamics' rhs gives {value.numel()} entries for {len(dynamics.state_names)} states "
                         f"{dynamics.state_names}")
    return value


def check_sampling(sample_period: float, delay_samples: int, substeps: int) -> None:
    """``ValueError`` unless the sample period, the dead time and the RK4 substeps are valid.

    Parameters
    ----------
    sample_period : float
        Sample period (s), finite and > 0.
    delay_samples : int
        Dead time (samples), an integer >= 0.
    substeps : int
        RK4 steps per sample, an integer >= 1.
    """
    if not (np.isfinite(sample_period) and sample_period > 0):
        raise ValueError(f"sample_period must be finite and > 0, got {sample_period}")
    for name, value, least in (("delay_samples", delay_samples, 0), ("substeps", substeps, 1)):
        if isinstance(value, bool) or not isinstance(value, (int, np.integer)) or value < least:
            raise ValueError(f"{name} must be an integer >= {least}, got {value!r}")


def _no_hysteresis(_):
    return 0.0


class _Parts:
    """Symbols and the dynamics' one-sample map shared by the Markov and creep builders."""

    def __init__(self, dynamics: Dynamics, disturbance: str, sample_period: float, substeps: int):
        self.dynamics, self.mode = dynamics, disturbance
        self.substep = sample_period / substeps
        self.substeps = substeps
        self.nd = 0 if disturbance == "none" else dynamics.disturbances if disturbance == "dynamics" else 1

    def h_in(self, h, d):
        """Hysteresis output as the dynamics and the output see it."""
        return h + d if self.mode == "hysteresis" else h

    def d_in(self, d):
        """Disturbance as ``rhs`` sees it."""
        return d if self.mode == "dynamics" else 0.0

    def advance(self, x, u, h_of, d):
        """Dynamic states after one sample; ``h_of(x_stage)`` gives the hysteresis output."""
        dyn = self.dynamics
        if not dyn.state_names:
            return x
        probe = ca.SX.sym("h")
        if not ca.depends_on(_rhs(dyn, x, u, probe, self.d_in(d)), probe):
            h_of = _no_hysteresis  # the dynamics do not see h: do not build it at every stage
        if dyn.discrete:
            return _rhs(dyn, x, u, self.h_in(h_of(x), d), self.d_in(d))
        return rk4(lambda xs, t: _rhs(dyn, xs, u, self.h_in(h_of(xs), d), self.d_in(d)), x, self.substep, self.substeps)

    def output_and_sensors(self, x, h, d):
        """Tracked output and sensor vector for dynamic state ``x`` and hysteresis output ``h``."""
        dyn = self.dynamics
        y = dyn.output(x, self.h_in(h, d))
        if self.mode == "output":
            y = y + d
        if not dyn.sensor_names:
            return y, ca.SX(0, 1)
        z = [y] if dyn.measure is None else list(dyn.measure(x, self.h_in(h, d), y))
        return y, _stack(z)

    def dynamics_model(self, sample_period: float) -> PredictionModel | None:
        """``x_dyn+ = f(x_dyn, h, d)``: the dynamics driven by the hysteresis output alone.

        None when there are no dynamic states, or when the input acts on the dynamics
        other than through the hysteresis, or the output or sensors see ``h`` directly:
        then the hysteresis cannot be split off the estimated part.
        """
        dyn = self.dynamics
        if not dyn.state_names:
            return None
        x = ca.SX.sym("x", len(dyn.state_names))
        u, h, d = ca.SX.sym("u"), ca.SX.sym("h"), ca.SX.sym("d", self.nd)
        dd = d if self.nd else 0.0
        x_next = self.advance(x, u, lambda _: h, dd)
        y, z = self.output_and_sensors(x, h, dd)
        if ca.depends_on(x_next, u) or ca.depends_on(ca.vertcat(y, z), h):
            return None
        return PredictionModel(
            step=ca.Function("dynamics_step", [x, h, d], [x_next], ["x", "h", "d"], ["x_next"]),
            output=ca.Function("dynamics_output", [x, d], [y], ["x", "d"], ["y"]),
            measure=ca.Function("dynamics_measure", [x, d], [z], ["x", "d"], ["z"]),
            sample_period=sample_period, state_names=dyn.state_names, sensor_names=dyn.sensor_names)


def build_prediction_model(hysteresis: HysteresisModel, sample_period: float, *,
                           dynamics: Dynamics | None = None, eps: float = 1e-3,
                           direction_eps: float | None = None, disturbance: str = "auto",
                           delay_samples: int = 0, substeps: int = 2, creep_order: float = 0.0,
                           name: str = "model") -> PredictionModel | CreepPredictionModel:
    """The NMPC's prediction model of ``hysteresis`` composed with ``dynamics``.

    Parameters
    ----------
    hysteresis : HysteresisModel
        Its ``smooth_step(eps, direction_eps)`` predicts.
    sample_period : float
        Sample period (s).
    dynamics : Dynamics, optional
        The actuator around the hysteresis; None: the output is the hysteresis output.
    eps, direction_eps : float, optional
        Smoothing widths (see the hysteresis model's ``smooth_step``).
    disturbance : str, optional
        Where the offset-free disturbance enters, one of :data:`DISTURBANCES`.
    delay_samples : int, optional
        Samples of dead time between the input and the actuator.
    substeps : int, optional
        RK4 steps per sample for continuous dynamics.
    creep_order : float, optional
        α > 0 puts a Grünwald–Letnikov creep integral between an input-driven hysteresis
        and the dynamics; the result is then a :class:`CreepPredictionModel`.
    name : str, optional
        Prefix of the CasADi Functions.

    Returns
    -------
    PredictionModel or CreepPredictionModel
        States ``[x_dyn, hysteresis state, dead-time queue]``, named after the dynamics'
        states, the hysteresis' ``state_names`` and ``delay_1..delay_D``.
    """
    check_sampling(sample_period, delay_samples, substeps)
    dynamics = Dynamics(steady_input=lambda y: y) if dynamics is None else dynamics
    mode = _resolve_disturbance(disturbance, dynamics)
    if dynamics.steady_correction is not None and mode != "dynamics":
        raise ValueError(f"steady_correction corrects for disturbances the dynamics read (disturbance='dynamics'); "
                         f"here d enters as {mode!r}, where the inverse corrects for it itself: drop it")
    if not (np.isfinite(creep_order) and 0 <= creep_order < 1):
        raise ValueError(f"creep_order must be in [0, 1), got {creep_order}")
    if creep_order > 0:
        if dynamics.hysteresis_input is not None or delay_samples:
            raise ValueError("creep is supported between an input-driven hysteresis and the dynamics, "
                             "without dead time")
        return CreepPredictionModel(hysteresis, dynamics, sample_period, creep_order, eps, direction_eps,
                                    mode, substeps)
    parts = _Parts(dynamics, mode, sample_period, substeps)
    smooth = hysteresis.smooth_step(eps, direction_eps)
    hys_names = tuple(hysteresis.state_names)[1 if dynamics.shares_last_input else 0:]
    n_dyn, n_hys, D = len(dynamics.state_names), len(hys_names), delay_samples
    x = ca.SX.sym("x", n_dyn + n_hys + D)
    u = ca.SX.sym("u")
    d = ca.SX.sym("d", parts.nd)
    dd = d if parts.nd else 0.0
    x_dyn, memory, queue = x[:n_dyn], x[n_dyn: n_dyn + n_hys], x[n_dyn + n_hys:]
    u_in = queue[0] if D else u
    drive = dynamics.hysteresis_input
    hys0 = ca.vertcat(drive(x_dyn, u_in), memory) if dynamics.shares_last_input else memory
    if drive is None:
        hys_next, h = smooth(hys0, u_in)
        x_dyn_next = parts.advance(x_dyn, u_in, lambda _: h, dd)
    else:
        x_dyn_next = parts.advance(x_dyn, u_in, lambda xs: smooth(hys0, drive(xs, u_in))[1], dd)
        hys_next, _ = smooth(hys0, drive(x_dyn_next, u_in))
    if dynamics.shares_last_input:
        hys_next = hys_next[1:]
    x_next = ca.vertcat(x_dyn_next, hys_next, *[queue[i] for i in range(1, D)], *([u] if D else []))
    y, z = parts.output_and_sensors(x_dyn, hysteresis.output(hys0), dd)
    if parts.nd and not ca.depends_on(ca.vertcat(x_next, y), d):
        raise ValueError(f"disturbance={mode!r}: the dynamics' rhs never reads d, so the tracking would not be "
                         "offset-free; let rhs use d or choose another disturbance")
    read = ca.vertcat(x_next, y)
    unread = [i for i in range(parts.nd) if not ca.depends_on(read, d[i])] if parts.nd > 1 else []
    if unread:
        raise ValueError(f"the dynamics' rhs never reads d[{unread[0]}] of its {parts.nd} disturbances: "
                         "an estimator could not learn it")
    names = (*dynamics.state_names, *hys_names, *(f"delay_{i + 1}" for i in range(D)))
    memory_info = None
    if drive is None:
        memory_info = InputMemory(hysteresis, D, parts.dynamics_model(sample_period),
                                  steady_input=dynamics.steady_input, disturbance=mode, n_dynamic=n_dyn,
                                  steady_correction=dynamics.steady_correction, rest_state=dynamics.rest_state)
    return PredictionModel(
        step=ca.Function(f"{name}_step", [x, u, d], [x_next], ["x", "u", "d"], ["x_next"]),
        output=ca.Function(f"{name}_output", [x, d], [y], ["x", "d"], ["y"]),
        measure=ca.Function(f"{name}_measure", [x, d], [z], ["x", "d"], ["z"]),
        sample_period=sample_period, state_names=names, sensor_names=dynamics.sensor_names,
        memory=memory_info)


class CreepPredictionModel:
    """Input-driven hysteresis, then ``D^(−α)`` creep, then dynamics: a prediction over a horizon.

    The creep output of predicted sample ``i`` is ``h^α Σ_{j<=i} c_j w_{k+i−j} + hist_i``
    over the predicted hysteresis outputs ``w`` plus ``hist_i``, the part the stored past
    fixes (:meth:`hystmpc.models.fractional.GrunwaldLetnikov.history_terms`), so the NLP
    stays small however long the memory (docs/dea.md, "Model"). Built by
    :func:`build_prediction_model` with ``creep_order > 0``.

    Parameters
    ----------
    hysteresis : HysteresisModel
        Input-driven hysteresis; its ``smooth_step(eps, direction_eps)`` predicts.
    dynamics : Dynamics
        The dynamics after the creep, driven by the creep output alone (``ValueError`` otherwise).
    sample_period : float
        Sample period (s).
    creep_order : float
        α of the creep integral.
    eps : float
        Smoothing width of the hysteresis.
    direction_eps : float or None
        Width of the input-direction detection (None: the model's default).
    disturbance : str
        Where ``d`` enters, one of :data:`DISTURBANCES` but ``auto``.
    substeps : int
        RK4 steps per sample for continuous dynamics.
    """

    def __init__(self, hysteresis: HysteresisModel, dynamics: Dynamics, sample_period: float,
                 creep_order: float, eps: float, direction_eps: float | None, disturbance: str, substeps: int):
        self.hysteresis, self.sample_period, self.creep_order = hysteresis, sample_period, creep_order
        self.smooth = hysteresis.smooth_step(eps, direction_eps)
        self._parts = _Parts(dynamics, disturbance, sample_period, substeps)
        self.dynamics = self._parts.dynamics_model(sample_period)
        if self.dynamics is None:
            raise ValueError("a creep model needs dynamics driven by the creep output alone: dynamic states whose "
                             "rhs does not read the input, and an output that does not read h")
        self.sensor_names = dynamics.sensor_names
        self.memory = InputMemory(hysteresis, 0, self.dynamics, creep_order, dynamics.steady_input, disturbance,
                                  steady_correction=dynamics.steady_correction, n_dynamic=self.dynamics.nx,
                                  rest_state=dynamics.rest_state)

    @property
    def nd(self) -> int:
        """Number of disturbance states."""
        return self._parts.nd

    def parameter_layout(self, horizon: int) -> dict[str, slice]:
        """Where each part sits in the ``p`` vector of :meth:`horizon_function`.

        Parameters
        ----------
        horizon : int
            Prediction horizon N (samples).

        Returns
        -------
        dict of str to slice
            Slices of ``hysteresis``, ``x``, ``d`` and ``history`` in ``p``.
        """
        nh, nx = len(self.hysteresis.state_names), self.dynamics.nx
        return {"hysteresis": slice(0, nh), "x": slice(nh, nh + nx), "d": slice(nh + nx, nh + nx + self.nd),
                "history": slice(nh + nx + self.nd, nh + nx + self.nd + horizon)}

    def horizon_function(self, horizon: int, inline: bool = True) -> ca.Function:
        """``(p, U) -> Y``: outputs y_{k+1..k+N} for inputs u_k..u_{k+N−1}.

        ``p = [hysteresis state, x_dyn, d, hist_1..hist_N]`` (:meth:`parameter_layout`).

        Parameters
        ----------
        horizon : int
            Prediction horizon N (samples).
        inline : bool, optional
            One SX expression graph (fast in-process); False: an MX graph that calls one
            hysteresis step and one dynamics step per sample (small generated C).

        Returns
        -------
        casadi.Function
            ``(p, U) -> Y``.
        """
        if not inline:
            return self._horizon(horizon, linear=False)
        layout = self.parameter_layout(horizon)
        p = ca.SX.sym("p", layout["history"].stop)
        U = ca.SX.sym("U", horizon)
        state, x = p[layout["hysteresis"]], p[layout["x"]]
        d, hist = p[layout["d"]], p[layout["history"]]
        c = gl_weights(-self.creep_order, horizon)
        scale = self.sample_period ** self.creep_order
        ws, ys = [], []
        for i in range(horizon):
            state, w = self.smooth(state, U[i])
            ws.append(w)
            W = scale * sum(c[j] * ws[i - j] for j in range(i + 1)) + hist[i]
            x = self.dynamics.step(x, W, d)
            ys.append(self.dynamics.output(x, d))
        return ca.Function("creep_predict", [p, U], [ca.vertcat(*ys)], ["p", "U"], ["Y"])

    def horizon_jacobian(self, horizon: int) -> ca.Function:
        """``(p, U) -> (Y, dY/dU)``: :meth:`horizon_function` and its Jacobian (lower triangular).

        Built from one hysteresis step and one dynamics step with their Jacobians, called once
        per predicted sample, with the sensitivities to the inputs carried forward (through the
        hysteresis state, the Grünwald–Letnikov sum and the dynamic state). Differentiating the
        unrolled horizon instead gives the same numbers with one C expression per entry, far
        more generated C (docs/realtime.md).

        Parameters
        ----------
        horizon : int
            Prediction horizon N (samples).

        Returns
        -------
        casadi.Function
            ``(p, U) -> (Y, dY_dU)``.
        """
        return self._horizon(horizon, linear=True)

    def _horizon(self, horizon: int, linear: bool) -> ca.Function:
        layout = self.parameter_layout(horizon)
        nh, nx = layout["hysteresis"].stop, self.dynamics.nx
        s_sym, u_sym = ca.SX.sym("s", nh), ca.SX.sym("u")
        s_next, w = self.smooth(s_sym, u_sym)
        x_sym, W_sym, d_sym = ca.SX.sym("x", nx), ca.SX.sym("W"), ca.SX.sym("d", self.nd)
        x_next = self.dynamics.step(x_sym, W_sym, d_sym)
        y_next = self.dynamics.output(x_next, d_sym)
        hysteresis_out, dynamics_out = [s_next, w], [x_next, y_next]
        if linear:
            hysteresis_out += [ca.jacobian(s_next, s_sym), ca.jacobian(s_next, u_sym), ca.jacobian(w, s_sym),
                               ca.jacobian(w, u_sym)]
            x_out = ca.SX.sym("x_out", nx)
            output_jacobian = ca.Function("output_jacobian", [x_out, d_sym],
                                          [ca.jacobian(self.dynamics.output(x_out, d_sym), x_out)])
            dynamics_out += [ca.jacobian(x_next, x_sym), ca.jacobian(x_next, W_sym), output_jacobian(x_next, d_sym)]
        suffix = "_linear" if linear else ""
        hysteresis_step = ca.Function(f"hysteresis_step{suffix}", [s_sym, u_sym], hysteresis_out)
        dynamics_step = ca.Function(f"dynamics_step{suffix}", [x_sym, W_sym, d_sym], dynamics_out)
        p = ca.MX.sym("p", layout["history"].stop)
        U = ca.MX.sym("U", horizon)
        state, x = p[layout["hysteresis"]], p[layout["x"]]
        d, hist = p[layout["d"]], p[layout["history"]]
        c = gl_weights(-self.creep_order, horizon)
        scale = self.sample_period ** self.creep_order
        S_state, S_x = ca.MX(nh, horizon), ca.MX(nx, horizon)  # d(state)/dU, d(x)/dU
        ws, dws, ys, dys = [], [], [], []
        for i in range(horizon):
            state_next, w_i, *hysteresis_jac = hysteresis_step(state, U[i])
            ws.append(w_i)
            W = scale * sum(c[j] * ws[i - j] for j in range(i + 1)) + hist[i]
            x, y, *dynamics_jac = dynamics_step(x, W, d)
            ys.append(y)
            if linear:
                A_s, B_s, C_w, D_w = hysteresis_jac
                A_x, B_x, C_y = dynamics_jac
                unit = ca.DM.zeros(1, horizon)  # dense: a sparse one runs hardly faster and makes far more code
                unit[i] = 1
                dws.append(C_w @ S_state + D_w @ unit)
                S_state = A_s @ S_state + B_s @ unit
                dW = scale * sum(c[j] * dws[i - j] for j in range(i + 1))
                S_x = A_x @ S_x + B_x @ dW
                dys.append(C_y @ S_x)
            state = state_next
        if linear:
            return ca.Function("creep_predict_jacobian", [p, U], [ca.vertcat(*ys), ca.vertcat(*dys)],
                               ["p", "U"], ["Y", "dY_dU"])
        return ca.Function("creep_predict_calls", [p, U], [ca.vertcat(*ys)], ["p", "U"], ["Y"])
