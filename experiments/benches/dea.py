"""Bench ``dea``: dielectric elastomer actuator with FCKP hysteresis and creep (wang2025).

Controllers (all see the laser displacement; none knows the plant's true parameters):

* ``pid``: K_P 0.8 V/mm, K_I 1.67 V/(mm s), K_D 0.01 V s/mm (Section 5.2), unchanged: our
  units (mm, V, s) are the paper's;
* ``backstepping``: the adaptive backstepping law of Section 3.1 (RBFNN for g⁻¹f and g⁻¹)
  with its temporary control W turned into volts by the mean static slope, no hysteresis
  or creep compensation;
* ``bic``: the paper's scheme: the same law, then the creep inverse (Section 2.3) and the
  implicit inverse through the adaptive KP density (Section 3.2); ``bic.creep_inverse=false``
  is Table 3's "without creep compensation";
* ``linear-mpc``: OSQP on a linear model linearised at the first reference, Ts 0.01 s,
  prediction 15, control horizon 5, output weight 0.13, rate weight 0.75, u ∈ [0, 10] V,
  with an input-disturbance Kalman filter for offset-free tracking;
* ``nmpc``: single-shooting NMPC on the smooth FCKP model with the GL sum split into
  in-horizon terms and a history term computed outside the NLP (design/nmpc.md).

Every scenario starts with a 2 s raised-cosine approach from rest to the reference's first
value, then runs the paper's 40 s; the metrics cover all 42 s.
"""

from __future__ import annotations

from dataclasses import dataclass, replace

import casadi as ca
import numpy as np

from experiments.baselines import Pid, PidGains
from experiments.bench import Bench, ControllerSpec, Scenario
from models.fckp import Fckp
from models.fractional import gl_weights
from mpc import DisturbanceEKF, NmpcSettings, PredictionModel
from mpc.shooting import SingleShootingNmpc
from plants.base import Measurement
from plants.dea import DeaActuator, DeaParams

NOMINAL = DeaParams()
"""What the controllers believe (the FCKP parameters as identified, our mechanics)."""

PLANT = replace(
    NOMINAL,
    fckp=replace(NOMINAL.fckp, delta=0.16, density_c=2.2, density_sigma=0.95, stroke=4.1),
    natural_frequency=1.08 * NOMINAL.natural_frequency,
    damping_ratio=0.8,
    stiffening=0.026,
    gain_variation=0.12,
    disturbance=0.003,
)
"""The simulated truth: wider kernel slopes, another density shape, a 2.5 % longer stroke, a
stiffer, more damped membrane, and a bounded slow disturbance. The creep order is the
paper's identified 0.02 in both."""

APPROACH = 2.0
"""Seconds of raised-cosine approach from rest before the paper's 40 s."""

PAPER_TABLE_2 = {"bic": (0.0035, 0.0044), "backstepping": (0.0046, 0.0071), "pid": (0.0255, 0.0304),
                 "linear-mpc": (0.0058, 0.008)}
"""wang2025 Table 2, single-sine: MAE and RMSE (mm)."""
PAPER_TABLE_3 = {"bic": (0.0111, 0.0133), "bic-no-creep": (0.0202, 0.0235)}
"""wang2025 Table 3, composite: MAE and RMSE (mm), with and without creep compensation."""


@dataclass(frozen=True)
class BicSettings:
    """Backstepping implicit-inverse adaptive control, Section 5.2 (``--set bic.KEY=VALUE``)."""

    k1: float = 20.0
    """Outer-loop gain (1/s). The paper's 3.5 gives 0.033 mm on ``single-sine`` here; 20 is
    the middle of the stable region of a scan over k1, λ and the velocity filter (docs/dea.md)."""
    k2: float = 3.5
    """Inner-loop gain, applied as λ·k2 (see :class:`Backstepping`)."""
    gamma_theta: float = 2.0
    """Γ11 = diag{gamma_theta}."""
    gamma_delta: float = 2.0
    """Γ12 = diag{gamma_delta}."""
    sigma1: float = 0.2
    r1: float = 0.2
    r2: float = 10.0
    gamma_mu: float = 0.1
    rbf_nodes: int = 11
    """RBF centres evenly spaced in [−1, 1] (η = 1)."""
    zeta: float = 0.01
    """Implicit-inverse search step (V)."""
    creep_inverse: bool = True
    """Compensate the creep by the GL derivative of order α (Section 2.3)."""
    velocity_filter: float = 0.05
    """Time constant of the filter on the differenced displacement (s)."""
    unit_scale: float = 0.025
    """λ: k2, Γ11 and Γ12 act as λ·k2, λ·Γ11, λ·Γ12 in our units (see :class:`Backstepping`)."""

    def __post_init__(self):
        for name in ("k1", "k2", "gamma_theta", "gamma_delta", "sigma1", "r1", "r2", "gamma_mu", "zeta",
                     "velocity_filter", "unit_scale"):
            value = getattr(self, name)
            if not (np.isfinite(value) and value >= 0):
                raise ValueError(f"{name} must be finite and >= 0, got {value}")
        if self.rbf_nodes < 2 or self.zeta <= 0:
            raise ValueError("rbf_nodes must be >= 2 and zeta > 0")


@dataclass(frozen=True)
class LinearMpcSettings:
    """Linear MPC of Section 5.2 (``--set linear_mpc.KEY=VALUE``)."""

    prediction: int = 15
    control: int = 5
    q_output: float = 0.13
    r_rate: float = 0.75
    r_input: float = 0.0

    def __post_init__(self):
        if not 1 <= self.control <= self.prediction:
            raise ValueError(f"need 1 <= control <= prediction, got {self.control}, {self.prediction}")
        for name in ("q_output", "r_rate", "r_input"):
            if not (np.isfinite(getattr(self, name)) and getattr(self, name) >= 0):
                raise ValueError(f"{name} must be finite and >= 0, got {getattr(self, name)}")


@dataclass(frozen=True)
class MemorySettings:
    """The creep memory the model-based controllers keep (``--set memory.window=200``)."""

    window: int = 0
    """Past samples in the GL sums of the prediction and history terms; 0: the full memory."""

    def __post_init__(self):
        if self.window < 0:
            raise ValueError(f"window must be >= 0 (0: full), got {self.window}")

    @property
    def length(self) -> int | None:
        """Window for :class:`models.fractional.GrunwaldLetnikov` (None: full)."""
        return self.window or None


def _static_curve(model: Fckp, n: int = 401):
    """Mean of the rising and falling major-loop branches of w(u): (u, w)."""
    u = np.linspace(0.0, model.params.u_max, n)
    state = model.initial_state()
    up = np.empty(n)
    for i, v in enumerate(u):
        state, up[i] = model.kp_step(state, v)
    down = np.empty(n)
    for i, v in enumerate(u[::-1]):
        state, down[i] = model.kp_step(state, v)
    return u, 0.5 * (up + down[::-1])


class ReferenceDerivatives:
    """ẋd and ẍd from the sampled reference by central differences (one sample of preview)."""

    def __init__(self, dt: float):
        self.dt = dt
        self.reset()

    def reset(self) -> None:
        self._last = None

    def __call__(self, ref_window) -> tuple[float, float, float]:
        r0, r1 = float(ref_window[0]), float(ref_window[1])
        rm = r0 if self._last is None else self._last
        self._last = r0
        return r0, (r1 - rm) / (2 * self.dt), (r1 - 2 * r0 + rm) / self.dt**2


class VelocityFilter:
    """x2 from the laser displacement: differenced, then a first-order low-pass."""

    def __init__(self, dt: float, tau: float):
        self.dt, self.alpha = dt, dt / (tau + dt) if tau > 0 else 1.0
        self.reset()

    def reset(self) -> None:
        self._last, self.value = None, 0.0

    def __call__(self, y: float) -> float:
        if self._last is not None:
            self.value += self.alpha * ((y - self._last) / self.dt - self.value)
        self._last = y
        return self.value


class DeaPid:
    """PID on the displacement error, output in volts."""

    horizon = 0

    def __init__(self, gains: PidGains, model: DeaParams):
        self.pid = Pid(gains, model.sample_period, (0.0, model.fckp.u_max))
        self.reset()

    def reset(self) -> None:
        """Clear the integrator."""
        self.pid.reset()
        self.predicted_output = float("nan")

    def step(self, measurement: Measurement, ref_window) -> float:
        """Voltage for this sample."""
        return self.pid.update(float(ref_window[0]) - measurement.y)

    def stats(self) -> None:
        return None


class Backstepping:
    """Adaptive backstepping of Section 3.1, with or without the paper's compensation.

    ``e1 = x1 − xd``, ``x2d = −k1 e1 + ẋd``, ``e2 = x2 − x2d`` and the temporary control
    (eq. (20)) ``W = −θ̂ᵀξ(x1) + δ̂ᵀη(x1) (ẋ2d − k2 e2)``, where θ̂ᵀξ ≈ g⁻¹f and δ̂ᵀη ≈ g⁻¹
    (eq. (18)) and the updates are eq. (25).

    Our units (mm, V, s; W a displacement, g ≈ ω² ≈ 1400 s⁻²) need these decisions:

    * λ (``unit_scale``) scales k2, Γ11 and Γ12. Literally, ``− k2 e2`` makes e2 decay at
      g·k2 ≈ 5000 /s, which a 100 Hz loop cannot realise: the input chatters 0 ↔ 10 V.
    * δ̂ ≈ g⁻¹ adapts 1/ω² slower still and is projected onto [0, 2/ω²]; unscaled it grew
      to 1e4 times g⁻¹.
    * The RBFs see x1 mapped from [0, 4] mm onto the centres' [−1, 1].
    * x2 is the differenced laser signal through a first-order low-pass (``velocity_filter``).
    * k1 = 20 instead of 3.5 (see :class:`BicSettings`). θ̂ and δ̂ start from zero, as printed.

    Without compensation (``backstepping``) the voltage is W over the mean static slope.
    With it (``bic``), W goes through the creep inverse D^α (Section 2.3, on the history of
    W commands) and then the implicit inverse (Section 3.2) of the KP model with the
    adaptive density μ̂ (eq. (26)): ``μ̂' = γμ (e2 κ_ρ − r2 (μ̂ − μ̂0))``, μ̂ ≥ 0, where μ̂0 is
    the nominal density (a leak towards zero, as printed, would empty the model the inverse
    searches).
    """

    horizon = 1

    def __init__(self, settings: BicSettings, model: DeaParams, memory: MemorySettings, compensate: bool):
        self.s, self.model, self.compensate = settings, model, compensate
        self.fckp = Fckp(model.fckp)
        self.dt = model.sample_period
        self.centres = np.linspace(-1.0, 1.0, settings.rbf_nodes)
        u, w = _static_curve(self.fckp)
        self._slope = (w[-1] - w[0]) / (u[-1] - u[0])
        kp = self.fckp.kp
        self._mu0 = self.fckp.params.stroke * 0.5 * kp.weights / kp.total_weight  # mm per kernel
        self._memory = memory
        self._rate = 1.0 / model.natural_frequency**2
        self.reset()

    def reset(self) -> None:
        """Initial estimates of Section 5.2 (θ̂ = δ̂ = 0, μ̂ = μ̂0); empty memories."""
        self.theta = np.zeros(self.s.rbf_nodes)
        self.delta = np.zeros(self.s.rbf_nodes)
        self.mu = self._mu0.copy()
        self._kp_state = self.fckp.initial_state()
        self._creep_inv = self.fckp.creep_inverse(self._memory.length)
        self._refs = ReferenceDerivatives(self.dt)
        self._velocity = VelocityFilter(self.dt, self.s.velocity_filter)
        self.predicted_output = float("nan")

    def _rbf(self, x1):
        """Gaussian RBFs (η = 1) of the displacement mapped from [0, 4] mm onto the centres' [−1, 1]."""
        return np.exp(-(((x1 - 2.0) / 2.0 - self.centres) ** 2) / 2.0)

    def step(self, measurement: Measurement, ref_window) -> float:
        """Voltage for this sample."""
        s, dt = self.s, self.dt
        x1 = measurement.y
        x2 = self._velocity(x1)
        xd, xd_dot, xd_ddot = self._refs(ref_window)
        e1 = x1 - xd
        e2 = x2 - (-s.k1 * e1 + xd_dot)
        x2d_dot = -s.k1 * (x2 - xd_dot) + xd_ddot
        xi = self._rbf(x1)
        lam = s.unit_scale
        W = -self.theta @ xi + (self.delta @ xi) * x2d_dot - lam * s.k2 * e2
        self.theta += dt * lam * s.gamma_theta * (e2 * xi - s.sigma1 * self.theta)
        self.delta += dt * lam * self._rate * s.gamma_delta * (-e2 * xi * x2d_dot - s.r1 * self.delta)
        self.delta = np.clip(self.delta, 0.0, 2 * self._rate)  # projection: 0 < g⁻¹ < 2/ω²
        if not self.compensate:
            u = W / self._slope
        else:
            w_target = self._creep_inv.push(W) if s.creep_inverse else W
            kernels = self._kp_state[1:]
            self.mu = np.maximum(self.mu + dt * s.gamma_mu * (e2 * kernels - s.r2 * (self.mu - self._mu0)), 0.0)
            kappa_target = w_target - self.fckp.params.stroke * 0.5  # w = Σ μ̂ ξ + stroke/2
            _, p = self.fckp.kp.inverse_step(self._kp_state, kappa_target, -1.0, 1.0,
                                             step=2 * s.zeta / self.fckp.params.u_max, weights=self.mu)
            u = float(self.fckp.denormalise(p))
        u = float(np.clip(u, 0.0, self.fckp.params.u_max))
        if self.compensate:
            self._kp_state, _ = self.fckp.kp.step(self._kp_state, float(self.fckp.normalise(u)))
        return u

    def stats(self) -> None:
        return None


class LinearMpc:
    """Linear MPC with OSQP (Section 5.2): the paper's horizons and weights, u ∈ [0, 10] V.

    Model: the nominal mechanics linearised at ``x1 = 1.5 mm`` (mid-range), driven by
    ``W ≈ a u + b`` (a least-squares line through the mean static curve of the nominal FCKP
    model) plus an input disturbance ``d`` (in W units) that a Kalman filter estimates from
    the laser: hysteresis, creep and mismatch all land in ``d``, which makes the tracking
    offset-free. The QP is condensed over the control moves Δu_0..Δu_{Nc−1}; the input is
    held after the control horizon; the reference over the prediction horizon is previewed.
    """

    def __init__(self, settings: LinearMpcSettings, model: DeaParams):
        import osqp
        from scipy import sparse
        from scipy.linalg import expm

        self.s, self.model = settings, model
        self.horizon = settings.prediction
        dt = model.sample_period
        fckp = Fckp(model.fckp)
        u, w = _static_curve(fckp)
        mid = (w > 0.1 * w.max()) & (w < 0.9 * w.max())
        self.a, self.b = np.polyfit(u[mid], w[mid], 1)
        x0, h = 1.5, 1e-6
        k_spring = -(model.f(x0 + h, 0.0) - model.f(x0 - h, 0.0)) / (2 * h)
        c_damp = -(model.f(x0, h) - model.f(x0, -h)) / (2 * h)
        g0 = float(model.g(x0))
        # continuous [x1, x2, d] with input W; the spring is linearised around x0 (f(x0) + g0 W0 = 0)
        Ac = np.array([[0.0, 1.0, 0.0], [-k_spring, -c_damp, g0], [0.0, 0.0, 0.0]])
        Bc = np.array([[0.0], [g0], [0.0]])
        M = expm(np.block([[Ac, Bc], [np.zeros((1, 4))]]) * dt)
        self.A, self.B = M[:3, :3], M[:3, 3:]
        w_eq = (float(model.f(x0, 0.0)) + k_spring * x0) / -g0  # W offset of the affine spring
        self._w_offset = w_eq
        self.C = np.array([[1.0, 0.0, 0.0]])
        Np, Nc = settings.prediction, settings.control
        n = 3
        Phi = np.zeros((Np, n))
        Gamma = np.zeros((Np, Np))  # response of y_{k+1..k+Np} to u_k..u_{k+Np−1}
        Ak = np.eye(n)
        for i in range(Np):
            Ak = self.A @ Ak
            Phi[i] = (self.C @ Ak).ravel()
        for i in range(Np):
            for j in range(i + 1):
                Gamma[i, j] = (self.C @ np.linalg.matrix_power(self.A, i - j) @ self.B).item()
        # u_j = u_prev + Σ_{m<=min(j, Nc−1)} Δu_m
        S = np.tril(np.ones((Np, Nc)))
        self._Phi, self._S = Phi, S
        self._G = Gamma @ S * self.a
        self._Gamma = Gamma
        q, r = settings.q_output, settings.r_rate
        L = np.tril(np.ones((Nc, Nc)))
        P = 2 * (q * self._G.T @ self._G + r * np.eye(Nc) + settings.r_input * S.T @ S)
        self._solver = osqp.OSQP()
        self._solver.setup(P=sparse.csc_matrix(P), q=np.zeros(Nc), A=sparse.csc_matrix(L),
                           l=np.zeros(Nc), u=np.full(Nc, model.fckp.u_max), verbose=False, warm_starting=True,
                           eps_abs=1e-8, eps_rel=1e-8, max_iter=4000, polishing=False)
        # Kalman filter on [x1, x2, d]
        self._Q = np.diag([1e-10, 1e-6, 1e-6])
        self._R = model.noise**2 if model.noise > 0 else 1e-12
        self.reset()

    def reset(self) -> None:
        """At rest, no disturbance estimate."""
        self.x = np.zeros(3)
        self.P = np.diag([1e-6, 1e-4, 1.0])
        self._u = 0.0
        self._started = False
        self.failures = 0
        self.predicted_output = float("nan")

    def _affine(self, u):
        """W of the linear model for voltage u, relative to the spring's linearisation."""
        return self.a * u + self.b - self._w_offset

    def step(self, measurement: Measurement, ref_window) -> float:
        """Voltage for this sample."""
        if self._started:  # time update with the applied input
            self.x = self.A @ self.x + (self.B * self._affine(self._u)).ravel()
            self.P = self.A @ self.P @ self.A.T + self._Q
        self.predicted_output = float(self.x[0])
        S = self.P[0, 0] + self._R
        K = self.P[:, 0] / S
        self.x = self.x + K * (measurement.y - self.x[0])
        self.P = self.P - np.outer(K, self.P[0])
        self._started = True
        s = self.s
        ref = np.asarray(ref_window[1: s.prediction + 1], float)
        free = self._Phi @ self.x + self._Gamma @ np.full(s.prediction, self._affine(self._u))
        q = 2 * s.q_output * self._G.T @ (free - ref) + 2 * s.r_input * self._S.T @ np.full(s.prediction, self._u)
        room = np.ones(s.control)
        self._solver.update(q=q, l=-self._u * room, u=(self.model.fckp.u_max - self._u) * room)
        result = self._solver.solve(raise_error=False)
        if result.info.status_val not in (1, 2) or not np.all(np.isfinite(result.x)):
            self.failures += 1
            u = self._u  # hold the last input
        else:
            u = float(np.clip(self._u + result.x[0], 0.0, self.model.fckp.u_max))
        self._u = u
        return u

    def stats(self) -> dict:
        """OSQP failures (input held)."""
        return {"name": "osqp", "failures": self.failures, "fallbacks": self.failures}


def mechanics_model(model: DeaParams, substeps: int = 2) -> PredictionModel:
    """Nominal mechanics ``x = [x1, x2]`` driven by ``W + d`` (d: W offset), RK4, one sample."""
    x = ca.SX.sym("x", 2)
    w = ca.SX.sym("w")
    d = ca.SX.sym("d")
    h = model.sample_period / substeps

    def rhs(q):
        return ca.vertcat(q[1], model.f(q[0], q[1]) + model.g(q[0], tanh=ca.tanh) * (w + d))

    q = x
    for _ in range(substeps):
        k1 = rhs(q)
        k2 = rhs(q + h / 2 * k1)
        k3 = rhs(q + h / 2 * k2)
        k4 = rhs(q + h * k3)
        q = q + h / 6 * (k1 + 2 * k2 + 2 * k3 + k4)
    return PredictionModel(
        step=ca.Function("dea_mech_step", [x, w, d], [q], ["x", "u", "d"], ["x_next"]),
        output=ca.Function("dea_output", [x, d], [x[0]], ["x", "d"], ["y"]),
        measure=ca.Function("dea_measure", [x, d], [x[0]], ["x", "d"], ["z"]),
        sample_period=model.sample_period, state_names=("displacement", "velocity"))


def prediction_function(model: DeaParams, horizon: int, eps: float, direction_eps: float) -> ca.Function:
    """``(p, U) -> Y``: displacements y_{k+1..k+N} for voltages u_k..u_{k+N−1}.

    ``p = [KP state, x1, x2, d, hist_1..hist_N]``. The creep output of predicted sample i is
    ``h^α Σ_{j<=i} c_j w_{k+i−j}`` over the predicted KP outputs plus ``hist_i``, the part the
    stored past fixes (:meth:`models.fractional.GrunwaldLetnikov.history_terms`).
    """
    fckp = Fckp(model.fckp)
    kp_step = fckp.smooth_kp_step(eps, direction_eps)
    mech = mechanics_model(model)
    nk = fckp.kp.n_kernels + 1
    N = horizon
    p = ca.SX.sym("p", nk + 3 + N)
    U = ca.SX.sym("U", N)
    kp_state, x, d, hist = p[:nk], p[nk: nk + 2], p[nk + 2], p[nk + 3:]
    c = gl_weights(-model.fckp.creep_order, N)
    scale = model.sample_period ** model.fckp.creep_order
    ws, ys = [], []
    for i in range(N):
        kp_state, w = kp_step(kp_state, U[i])
        ws.append(w)
        W = scale * sum(c[j] * ws[i - j] for j in range(i + 1)) + hist[i]
        x = mech.step(x, W, d)
        ys.append(x[0])
    return ca.Function("dea_predict", [p, U], [ca.vertcat(*ys)], ["p", "U"], ["Y"])


class DeaNmpc:
    """NMPC with the FCKP model: the controller's own exact FCKP (creep memory with window
    L) gives W for the estimator and the history terms; an EKF estimates [x1, x2] and a
    W offset d from the laser; the NLP is :class:`mpc.shooting.SingleShootingNmpc`.

    Warm start: the shifted previous plan; at start-up and after a failed solve, the inverse
    model (static mechanics, creep inverse, implicit inverse). A failed solve applies the
    previous plan's next input (or the inverse's), is counted and reported.
    """

    def __init__(self, settings: NmpcSettings, model: DeaParams, memory: MemorySettings):
        self.settings, self.model, self.memory = settings, model, memory
        self.horizon = settings.horizon
        self.fckp = Fckp(model.fckp)
        self.ocp = SingleShootingNmpc(prediction_function(model, settings.horizon, settings.eps,
                                                          settings.direction_eps or settings.eps),
                                      settings, 0.0, model.fckp.u_max)
        mech = mechanics_model(model)
        self.ekf = DisturbanceEKF(mech, [1e-10, 1e-4, 1e-6], [max(model.noise, 1e-6) ** 2])
        self._c = gl_weights(-model.fckp.creep_order, settings.horizon)
        self._scale = model.sample_period ** model.fckp.creep_order
        self.reset()

    def reset(self) -> None:
        """At rest, empty memories, no plan; counters to zero."""
        self.ekf.reset(np.zeros(2), np.zeros(1), [1e-6, 1e-4, 1e-2])
        self._kp = self.fckp.initial_state()
        self._creep = self.fckp.creep(self.memory.length)
        self._u = 0.0
        self._W = 0.0
        self._plan = None
        self._started = False
        self.failures = 0
        self.iterations: list[int] = []
        self.solve_times: list[float] = []
        self.statuses: dict[str, int] = {}
        self.predicted_output = float("nan")

    @property
    def nmpc(self) -> SingleShootingNmpc:
        """The NLP (its ``rti`` step is what ``hystmpc codegen`` generates)."""
        return self.ocp

    def _inverse(self, hist, refs, d) -> np.ndarray:
        m = self.model
        r = np.asarray(refs, float)
        W_target = (r + m.stiffening * r**3) / (1 + m.gain_variation * np.tanh(r / 2.0)) - d
        state, ws, out = self._kp.copy(), [], np.empty(len(r))
        for i in range(len(r)):
            past = sum(self._c[j] * ws[i - j] for j in range(1, i + 1))
            w = (W_target[i] - hist[i]) / self._scale - past
            state, out[i] = self.fckp.implicit_inverse(state, float(w), zeta=0.01)
            ws.append(float(self.fckp.static(self.fckp.kp.output(state))))
        return np.clip(out, 0.0, m.fckp.u_max)

    def step(self, measurement: Measurement, ref_window) -> float:
        """Voltage for this sample."""
        if self._started:
            self.ekf.predict([self._W])
        self.predicted_output = float(self.ekf.x[0])
        self.ekf.update([measurement.y])
        self._started = True
        x, d = self.ekf.x, float(self.ekf.d[0])
        N = self.horizon
        refs = np.asarray(ref_window[1: N + 1], float)
        hist = self._creep.history_terms(N)
        if self._plan is None:
            guess = self._inverse(hist, refs, d)
        else:
            guess = np.concatenate((self._plan[1:], self._plan[-1:]))
        params = np.concatenate((self._kp, x, [d], hist))
        result = self.ocp.solve(params, self._u, refs, guess)
        self.iterations.append(result.iterations)
        self.solve_times.append(result.solve_time)
        self.statuses[result.status] = self.statuses.get(result.status, 0) + 1
        if result.success:
            u = float(result.u_plan[0, 0])
            self._plan = result.u_plan[:, 0]
        else:
            self.failures += 1
            u = float(self._plan[1]) if self._plan is not None else float(guess[0])
            self._plan = None
        if not np.isfinite(u):
            u = self._u
        u = float(np.clip(u, 0.0, self.model.fckp.u_max))
        self._kp, self._W = self.fckp.step(self._kp, self._creep, u)
        self._u = u
        return u

    def stats(self) -> dict:
        """Solver statistics."""
        its = np.asarray(self.iterations) if self.iterations else np.zeros(1)
        return {"name": self.settings.solver, "failures": self.failures, "fallbacks": self.failures,
                "iterations_median": float(np.median(its)), "iterations_max": int(its.max()),
                "statuses": dict(self.statuses)}


def _with_approach(name: str, description: str, core) -> Scenario:
    """The paper's 40 s reference ``core(t)`` after a 2 s raised-cosine approach from 0."""
    start = float(core(np.zeros(1))[0])

    def reference(t):
        t = np.asarray(t, float)
        ramp = start * 0.5 * (1 - np.cos(np.pi * np.clip(t / APPROACH, 0.0, 1.0)))
        return np.where(t < APPROACH, ramp, core(t - APPROACH))
    return Scenario(name, description, APPROACH + 40.0, reference)


def _triangle(t):
    phase = np.mod(np.asarray(t, float) / 2.0 + 0.25, 1.0)  # period 2 s, starts at the mean, rising
    return 1.0 + 0.2 * (4 * np.abs(phase - 0.5) - 1) * -1


def _square(t):
    return 1.0 + 0.2 * np.where(np.mod(np.asarray(t, float), 4.0) < 2.0, 1.0, -1.0)


def _scenarios() -> dict[str, Scenario]:
    pi = np.pi
    out = [
        _with_approach("single-sine", "0.2 sin(πt) + 1.0 mm, 40 s (Figs. 10–11, Table 2)",
                       lambda t: 0.2 * np.sin(pi * t) + 1.0),
        _with_approach("composite", "0.2 sin(0.4πt) + 0.4 sin(0.2πt) + 0.6 sin(0.6πt) + 2 mm, 40 s (Table 3)",
                       lambda t: 0.2 * np.sin(0.4 * pi * t) + 0.4 * np.sin(0.2 * pi * t)
                       + 0.6 * np.sin(0.6 * pi * t) + 2.0),
        _with_approach("triangle", "triangle 1.0 ± 0.2 mm, period 2 s, 40 s (Fig. 17)", _triangle),
        _with_approach("square", "square 1.0 ± 0.2 mm, period 4 s, 40 s (Fig. 18)", _square),
    ]
    return {s.name: s for s in out}


def _defaults() -> dict:
    return {"plant": PLANT, "model": NOMINAL, "memory": MemorySettings(),
            "pid": PidGains(kp=0.8, ki=1.67, kd=0.01), "bic": BicSettings(),
            "linear_mpc": LinearMpcSettings(),
            "nmpc": NmpcSettings(horizon=15, q_output=1e4, r_rate=1.0, eps=1e-3, direction_eps=1e-4,
                                 solver="gn", max_iter=60, tol=1e-3)}


def _controllers() -> dict[str, ControllerSpec]:
    return {
        "pid": ControllerSpec("pid", "PID, K_P 0.8, K_I 1.67, K_D 0.01 (Section 5.2)",
                              lambda c: DeaPid(c["pid"], c["model"])),
        "backstepping": ControllerSpec("backstepping", "adaptive backstepping, no hysteresis compensation",
                                       lambda c: Backstepping(c["bic"], c["model"], c["memory"], False)),
        "bic": ControllerSpec("bic", "backstepping implicit-inverse adaptive control with creep inverse",
                              lambda c: Backstepping(c["bic"], c["model"], c["memory"], True)),
        "linear-mpc": ControllerSpec("linear-mpc", "linear MPC (OSQP), Np 15, Nc 5, Section 5.2 weights",
                                     lambda c: LinearMpc(c["linear_mpc"], c["model"])),
        "nmpc": ControllerSpec("nmpc", "NMPC on the smooth FCKP model, GL history as parameters",
                               lambda c: DeaNmpc(c["nmpc"], c["model"], c["memory"])),
    }


BENCH = Bench(
    name="dea",
    description="Dielectric elastomer actuator, FCKP hysteresis with fractional creep (wang2025)",
    paper="wang2025_fckp_creep_hysteresis_dea_control",
    output_name="displacement",
    units="mm",
    input_units="V",
    sample_period=NOMINAL.sample_period,
    scenarios=_scenarios(),
    controllers=_controllers(),
    defaults=_defaults,
    make_plant=lambda c: DeaActuator(c["plant"]),
    output_range=(0.0, 4.0),
    paper_figures={("single-sine", k): {"mae": v[0], "rmse": v[1]} for k, v in PAPER_TABLE_2.items()}
    | {("composite", "bic"): {"mae": PAPER_TABLE_3["bic"][0], "rmse": PAPER_TABLE_3["bic"][1]}},
    input_bounds=(0.0, NOMINAL.fckp.u_max),
    loop=("voltage", "W", "voltage [V]", "FCKP output W [mm]"),
    default_scenario="single-sine",
)
