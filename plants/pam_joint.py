"""Antagonistic pneumatic-muscle joint with Maxwell-slip pressure/angle hysteresis (vo2012).

Static torque (constraint model, eq. (1)): ``T = a(θ)·Δp_eff + b(θ)``, where the pressure
difference that produces torque is the applied one minus the extracted hysteresis,
``Δp_eff = Δp − Δp_hys`` (eqs. (3)–(4)), and ``Δp_hys = MS[θ]`` with θ in degrees.

Dynamics (our choice; the paper gives no equation of motion)::

    J θ'' = a(θ)(Δp − Δp_hys) + b(θ) − m g L sin θ − c θ' + T_creep(t)
    Δp''  = ωp² (Δp_cmd(t − delay) − Δp) − 2 ζp ωp Δp' − ωp² c_v θ'   (|Δp'| ≤ slew)

``a(θ) = a0 (1 − a_drop (θ/40°)²)`` and ``b(θ) = −K (θ + β θ³/θ40²)`` are chosen so that a
1 kg payload needs about ±5 bar at ±40° (Fig. 3), and heavier payloads reach a smaller
angle range within the same pressures.
"""

from __future__ import annotations

import functools
from dataclasses import dataclass, field, replace

import casadi as ca
import numpy as np

from hystmpc.models.base import clip, symbolic
from hystmpc.models.integrators import rk4
from hystmpc.models.maxwell_slip import MaxwellSlip
from hystmpc.models.prediction import Dynamics, PredictionModel, build_prediction_model
from hystmpc.plants.base import Measurement, ParametrisedPlant

GRAVITY = 9.81
DEG = np.pi / 180.0
TABLE_1 = MaxwellSlip(
    k=(0.0557, 0.0170, 0.0021, 0.0033),  # bar/deg, vo2012 Table 1
    w=(0.1680, 0.1383, 0.0342, 0.1335),  # bar, vo2012 Table 1
)


@dataclass(frozen=True)
class PamJointParams:
    """Physical parameters of the PAM joint; the defaults are the *nominal* model."""

    payload_kg: float = 1.0
    """Payload on the lever (kg); vo2012 Fig. 7 uses 1 kg."""
    lever_m: float = 0.30
    """Lever arm of the payload (m); not given in the paper."""
    arm_inertia: float = 0.010
    """Inertia of arm, shaft and gear about the joint (kg m²)."""
    damping: float = 0.80
    """Viscous joint damping c (N m s/rad): about 40 % of critical with 1 kg (muscle sheaths
    are strongly damped)."""
    torque_per_bar: float = 2.0
    """a0: muscle-pair torque per bar of pressure difference at θ = 0 (N m/bar)."""
    torque_per_bar_drop: float = 0.15
    """Relative loss of a(θ) at ±40° (muscle force falls with contraction)."""
    passive_stiffness: float = 7.0
    """K: restoring stiffness of the pre-pressurised muscle pair at θ = 0 (N m/rad)."""
    passive_stiffening: float = 0.3
    """β: cubic stiffening of b(θ), relative, at ±40°."""
    hysteresis: MaxwellSlip = TABLE_1
    """Δp_hys(θ) model (bar, θ in degrees)."""
    pressure_wn: float = 18.0
    """Natural frequency of the closed pressure loop (rad/s); Fig. 8a: lightly damped, ~3 Hz."""
    pressure_zeta: float = 0.45
    """Damping ratio of the pressure loop."""
    pressure_delay_s: float = 0.04
    """Transport delay of the pressure loop (s); a multiple of the sample period."""
    pressure_slew: float = 40.0
    """Largest rate of the pressure difference (bar/s), from valve flow."""
    volume_coupling: float = 0.0
    """c_v: pressure drop per joint rate from muscle volume change (bar per deg/s)."""
    dp_limit: float = 6.0
    """Valve command range ±dp_limit (bar): 6 bar supply."""
    creep_torque: float = 0.0
    """Muscle creep: torque lost as ``creep_torque·(1 − exp(−t/creep_time))`` (N m)."""
    creep_time: float = 20.0
    """Time constant of the creep drift (s)."""
    encoder_counts: int = 8000
    """Encoder counts per revolution after quadrature (2000 PPR × 4)."""
    pressure_noise_bar: float = 0.005
    """Standard deviation of the pressure-difference measurement noise (bar)."""
    sample_period: float = 0.02
    """Control sample period (s), vo2012: 20 ms."""
    substeps: int = 20
    """Integration substeps per sample in the plant."""

    def __post_init__(self):
        positive = ("lever_m", "arm_inertia", "torque_per_bar", "pressure_wn", "pressure_zeta",
                    "pressure_slew", "dp_limit", "creep_time", "sample_period")
        for name in positive:
            value = getattr(self, name)
            if not (np.isfinite(value) and value > 0):
                raise ValueError(f"{name} must be finite and > 0, got {value}")
        nonneg = ("payload_kg", "damping", "passive_stiffness", "pressure_delay_s",
                  "volume_coupling", "creep_torque", "pressure_noise_bar")
        for name in nonneg:
            value = getattr(self, name)
            if not (np.isfinite(value) and value >= 0):
                raise ValueError(f"{name} must be finite and >= 0, got {value}")
        if not 0 <= self.torque_per_bar_drop < 1:
            raise ValueError(f"torque_per_bar_drop must be in [0, 1), got {self.torque_per_bar_drop}")
        if self.encoder_counts < 1 or self.substeps < 1:
            raise ValueError("encoder_counts and substeps must be >= 1")
        ratio = self.pressure_delay_s / self.sample_period
        if abs(ratio - round(ratio)) > 1e-9:
            raise ValueError(
                f"pressure_delay_s={self.pressure_delay_s} must be a multiple of "
                f"sample_period={self.sample_period}")

    @property
    def delay_samples(self) -> int:
        """Pressure-loop delay in samples."""
        return int(round(self.pressure_delay_s / self.sample_period))

    @property
    def inertia(self) -> float:
        """Total inertia about the joint (kg m²)."""
        return self.arm_inertia + self.payload_kg * self.lever_m**2


def torque_slope(p: PamJointParams, theta_deg, xp=np):
    """Constraint-model slope a(θ) in N m/bar, eq. (1).

    Parameters
    ----------
    p : PamJointParams
        The joint parameters.
    theta_deg : float, ndarray or SX
        Joint angle (deg).
    xp : module, optional
        ``np``, or ``ca`` for CasADi expressions (not used: the slope is a polynomial).

    Returns
    -------
    float, ndarray or SX
        a(θ) (N m/bar).
    """
    return p.torque_per_bar * (1.0 - p.torque_per_bar_drop * (theta_deg / 40.0) ** 2)


def torque_intercept(p: PamJointParams, theta_deg, xp=np):
    """Constraint-model intercept b(θ) in N m, eq. (1).

    Parameters
    ----------
    p : PamJointParams
        The joint parameters.
    theta_deg : float, ndarray or SX
        Joint angle (deg).
    xp : module, optional
        ``np``, or ``ca`` for CasADi expressions (not used: the intercept is a polynomial).

    Returns
    -------
    float, ndarray or SX
        b(θ) (N m).
    """
    return -p.passive_stiffness * theta_deg * DEG * (1.0 + p.passive_stiffening * (theta_deg / 40.0) ** 2)


def gravity_torque(p: PamJointParams, theta_deg, xp=np):
    """Torque the payload exerts to pull the lever back to 0 (N m).

    Parameters
    ----------
    p : PamJointParams
        The joint parameters.
    theta_deg : float, ndarray or SX
        Joint angle (deg).
    xp : module, optional
        ``np``, or ``ca`` for CasADi expressions.

    Returns
    -------
    float, ndarray or SX
        ``m g L sin θ`` (N m).
    """
    return p.payload_kg * GRAVITY * p.lever_m * xp.sin(theta_deg * DEG)


def constraint_pressure(p: PamJointParams, theta_deg, xp=np):
    """Δp_cons, eq. (2): pressure difference that holds θ against the payload, no hysteresis.

    Parameters
    ----------
    p : PamJointParams
        The joint parameters.
    theta_deg : float, ndarray or SX
        Joint angle (deg).
    xp : module, optional
        ``np``, or ``ca`` for CasADi expressions.

    Returns
    -------
    float, ndarray or SX
        Δp_cons (bar).
    """
    return (gravity_torque(p, theta_deg, xp) - torque_intercept(p, theta_deg, xp)) / torque_slope(p, theta_deg, xp)


def joint_acceleration(p: PamJointParams, theta_deg, omega_deg, dp, dp_hys, extra_torque, xp=np):
    """θ'' in deg/s² from the torque balance (see module docstring).

    Parameters
    ----------
    p : PamJointParams
        The joint parameters.
    theta_deg : float or SX
        Joint angle θ (deg).
    omega_deg : float or SX
        Joint rate ω (deg/s).
    dp : float or SX
        Pressure difference Δp (bar).
    dp_hys : float or SX
        Hysteresis pressure Δp_hys (bar).
    extra_torque : float or SX
        Torque added to the balance, e.g. the creep (N m).
    xp : module, optional
        ``np``, or ``ca`` for CasADi expressions.

    Returns
    -------
    float or SX
        θ'' (deg/s²).
    """
    torque = (torque_slope(p, theta_deg, xp) * (dp - dp_hys) + torque_intercept(p, theta_deg, xp)
              - gravity_torque(p, theta_deg, xp) - p.damping * omega_deg * DEG + extra_torque)
    return torque / p.inertia / DEG


def joint_rhs(p: PamJointParams, x, dp_cmd, dp_hys, extra_torque, xp=np, wn_scale=None, zeta_scale=None) -> list:
    """Time derivative of ``x = [θ, ω, Δp, Δp']`` (deg, deg/s, bar, bar/s).

    For the plant and the NMPC's model alike (see module docstring; the slew limit is the
    plant's own).

    Parameters
    ----------
    p : PamJointParams
        The joint parameters.
    x : array_like or SX
        State ``[θ, ω, Δp, Δp']``.
    dp_cmd : float or SX
        Pressure-difference command reaching the pressure loop (bar).
    dp_hys : float or SX
        Hysteresis pressure Δp_hys (bar).
    extra_torque : float or SX
        Torque added to the balance, e.g. the creep (N m).
    xp : module, optional
        ``np``, or ``ca`` for CasADi expressions.
    wn_scale : float or SX, optional
        Scale of the pressure loop's natural frequency (an estimator's correction; None: 1).
    zeta_scale : float or SX, optional
        Scale of the pressure loop's damping ratio (an estimator's correction; None: 1).

    Returns
    -------
    list
        ``[θ', ω', Δp', Δp'']``.
    """
    theta, omega, dp, ddp = x[0], x[1], x[2], x[3]
    acc = joint_acceleration(p, theta, omega, dp, dp_hys, extra_torque, xp)
    wn = p.pressure_wn if wn_scale is None else p.pressure_wn * wn_scale
    zeta = p.pressure_zeta if zeta_scale is None else p.pressure_zeta * zeta_scale
    dd = wn**2 * (dp_cmd - dp - p.volume_coupling * omega) - 2 * zeta * wn * ddp
    return [omega, acc, ddp, dd]


ESTIMATES = ("gain", "pressure_frequency", "pressure_damping")
"""Model errors :func:`prediction_model` can let the estimator learn, as relative errors
``e`` (the model's value times ``1 + e``): ``gain`` of the muscles' torque per bar a0,
``pressure_frequency`` and ``pressure_damping`` of the pressure loop's ωp and ζp."""
LEARNED_ERROR_RANGE = (-0.75, 3.0)
"""The models use a learned relative error clipped to this range (a quarter to four times
the nominal value): at rest ωp and ζp are not observable and their estimates may wander, and
a scale of 0 or below would divide by zero in the inverse or undamp the pressure loop. The
estimates pass half and twice the nominal value for a few samples after some steps; a
range that tight cost accuracy on square-20 (docs/pam.md)."""


def _bounded(error, xp=np):
    low, high = LEARNED_ERROR_RANGE
    return ca.fmin(ca.fmax(error, low), high) if xp is ca else np.clip(error, low, high)


def prediction_model(p: PamJointParams, eps: float, direction_eps: float | None = None,
                     substeps: int = 2, estimates: tuple[str, ...] = ()) -> PredictionModel:
    """Smooth discrete-time model of the joint for the NMPC and its EKF.

    ``x = [θ, ω, Δp, Δp', F_1..F_M, q_1..q_D]``, ``d`` = an unknown torque (N m, where the
    plant's creep acts), sensors: angle and pressure. The Maxwell-slip elements move with θ
    relative to the sample's start (their last input *is* θ), so a monotone θ within a
    sample gives the exact update up to eps; the command passes the ``D``-sample delay line.

    Parameters
    ----------
    p : PamJointParams
        The nominal parameters.
    eps : float
        Smoothing width of each Maxwell-slip element's clip (see its ``smooth_step``).
    direction_eps : float, optional
        Must stay None: Maxwell-slip has no direction detection.
    substeps : int, optional
        RK4 steps per sample.
    estimates : tuple of str, optional
        Names from :data:`ESTIMATES`, in that order: relative model errors appended to ``d``,
        which the estimator then learns and the NMPC holds over the horizon; the model uses
        each within :data:`LEARNED_ERROR_RANGE`.

    Returns
    -------
    PredictionModel
        The model, its CasADi Functions named ``pam...``; sensors ``y`` (angle) and ``pressure``.
    """
    if list(estimates) != [name for name in ESTIMATES if name in estimates]:  # also catches unknown names
        raise ValueError(f"estimates must be distinct names from {ESTIMATES} in that order, got {estimates}")
    index = {name: 1 + i for i, name in enumerate(estimates)}

    def rhs(x, u, h, d):
        if not estimates:
            return joint_rhs(p, x, u, h, d, xp=ca)
        extra = d[0]
        if "gain" in index:
            extra = extra + _bounded(d[index["gain"]], ca) * torque_slope(p, x[0], ca) * (x[2] - h)
        scale = {name: 1.0 + _bounded(d[index[name]], ca) if name in index else None
                 for name in ("pressure_frequency", "pressure_damping")}
        return joint_rhs(p, x, u, h, extra, xp=ca, wn_scale=scale["pressure_frequency"],
                         zeta_scale=scale["pressure_damping"])

    dynamics = Dynamics(
        state_names=("angle", "rate", "pressure", "pressure_rate"), disturbances=1 + len(estimates), rhs=rhs,
        output=lambda x, h: x[0], hysteresis_input=lambda x, u: x[0], shares_last_input=True,
        sensor_names=("y", "pressure"), measure=lambda x, h, y: [y, x[2]])
    return build_prediction_model(p.hysteresis, p.sample_period, dynamics=dynamics, eps=eps,
                                  direction_eps=direction_eps, disturbance="dynamics",
                                  delay_samples=p.delay_samples, substeps=substeps, name="pam")


def inverse_inputs(p: PamJointParams, x, d, refs, gain: bool = False):
    """Static inverse along the reference: Δp_cons(r) + Δp_hys(path) − d/a(r), eqs. (2)–(3).

    NumPy, or CasADi expressions for a generated controller. The command reaches the pressure
    ``D`` samples later, so input ``j`` aims at ``r_{j+D}`` (the last reference beyond the window).

    Parameters
    ----------
    p : PamJointParams
        The nominal parameters.
    x : array_like or SX
        State of :func:`prediction_model`.
    d : array_like or SX
        Its disturbance: ``[torque, ...]`` (N m first).
    refs : array_like or SX
        Angle references (deg), one per sample.
    gain : bool, optional
        ``d = [torque, g, ...]`` (:func:`prediction_model` with the ``gain`` estimate): the
        muscles' torque is divided by ``1 + g`` (g within :data:`LEARNED_ERROR_RANGE`).

    Returns
    -------
    ndarray or SX
        One pressure-difference command (bar) per reference.
    """
    D, M = p.delay_samples, p.hysteresis.n_elements
    w = np.asarray(p.hysteresis.w)
    if symbolic(x):
        xp, n = ca, refs.shape[0]
        hys = ca.vertcat(x[0], clip(x[4: 4 + M], ca.DM(-w), ca.DM(w)))
    else:
        refs = np.asarray(refs, float)
        xp, n = np, len(refs)
        hys = np.concatenate(([x[0]], np.clip(x[4: 4 + M], -w, w)))
    need = []
    for j in range(n):
        r = refs[min(j + D, n - 1)]
        hys, dp_hys = p.hysteresis.step(hys, r)
        if gain:
            need.append(dp_hys + (constraint_pressure(p, r, xp) - d[0] / torque_slope(p, r, xp))
                        / (1.0 + _bounded(d[1], xp)))
        else:
            need.append(constraint_pressure(p, r, xp) + dp_hys - d[0] / torque_slope(p, r, xp))
    return ca.vertcat(*need) if xp is ca else np.array(need, float)


def rest_state(p: PamJointParams, z):
    """State of :func:`prediction_model` at rest from the sensor vector ``[θ, Δp]``.

    Relaxed hysteresis, and a delay line holding the measured pressure (at rest the command is
    the pressure, so a joint started pressurised is not predicted to vent; NumPy, or CasADi
    expressions).

    Parameters
    ----------
    p : PamJointParams
        The nominal parameters.
    z : array_like or SX
        Sensor vector ``[θ, Δp]`` (deg, bar).

    Returns
    -------
    ndarray or SX
        The state ``[θ, 0, Δp, 0, 0..0, Δp..Δp]``.
    """
    D, M = p.delay_samples, p.hysteresis.n_elements
    if symbolic(z):
        return ca.vertcat(z[0], 0.0, z[1], 0.0, ca.DM.zeros(M), *([z[1]] * D))
    return np.concatenate(([z[0], 0.0, z[1], 0.0], np.zeros(M), np.full(D, z[1])))


def linear_model(p: PamJointParams, substeps: int = 2) -> PredictionModel:
    """The joint linearised at θ = 0 without hysteresis, for ``inverse-lmpc``.

    Input: the *effective* pressure command ``v`` (bar) that the compensation of
    :func:`static_compensation` turns into a valve command; ``x = [θ, ω, Δp_v, Δp_v',
    q_1..q_D]`` with ``Δp_v`` the effective pressure; ``d``: an unknown torque (N m), as in
    :func:`prediction_model`. ``J θ'' = a0 Δp_v − (K + m g L) θ − c θ' + d``: a(θ), b(θ)
    and the payload linearised at 0. Sensors: angle and effective pressure.

    Parameters
    ----------
    p : PamJointParams
        The nominal parameters.
    substeps : int, optional
        RK4 steps per sample.

    Returns
    -------
    PredictionModel
        The linear model, sensors named ``y`` and ``pressure``.
    """
    D = p.delay_samples
    x, v, d = ca.SX.sym("x", 4 + D), ca.SX.sym("v"), ca.SX.sym("d")
    command = x[4] if D else v
    stiffness = (p.passive_stiffness + p.payload_kg * GRAVITY * p.lever_m) * DEG  # N m/deg

    def rhs(xs, _t):
        acc = (p.torque_per_bar * xs[2] - stiffness * xs[0] - p.damping * xs[1] * DEG + d) / p.inertia / DEG
        dd = p.pressure_wn**2 * (command - xs[2]) - 2 * p.pressure_zeta * p.pressure_wn * xs[3]
        return ca.vertcat(xs[1], acc, xs[3], dd)

    x_dyn = rk4(rhs, x[:4], p.sample_period / substeps, substeps)
    x_next = ca.vertcat(x_dyn, *[x[4 + i] for i in range(1, D)], *([v] if D else []))
    names = ("angle", "rate", "pressure", "pressure_rate", *(f"delay_{i + 1}" for i in range(D)))
    return PredictionModel(
        step=ca.Function("pam_linear_step", [x, v, d], [x_next], ["x", "u", "d"], ["x_next"]),
        output=ca.Function("pam_linear_output", [x, d], [x[0]], ["x", "d"], ["y"]),
        measure=ca.Function("pam_linear_measure", [x, d], [ca.vertcat(x[0], x[2])], ["x", "d"], ["z"]),
        sample_period=p.sample_period, state_names=names, sensor_names=("y", "pressure"))


def static_compensation(p: PamJointParams, theta_deg: float) -> float:
    """What :func:`linear_model` leaves out of the static balance at angle θ (bar).

    Parameters
    ----------
    p : PamJointParams
        The nominal parameters.
    theta_deg : float
        Joint angle θ (deg).

    Returns
    -------
    float
        ``Δp_cons(θ) − Δp_cons'(0) θ`` (bar), eq. (2) minus its slope at 0.
    """
    slope = (p.passive_stiffness + p.payload_kg * GRAVITY * p.lever_m) * DEG / p.torque_per_bar
    return float(constraint_pressure(p, theta_deg)) - slope * theta_deg


@dataclass
class PamJoint(ParametrisedPlant):
    """Simulated antagonistic PAM joint; input: commanded Δp (bar); output: angle (deg)."""

    params: PamJointParams = field(default_factory=PamJointParams)

    def reset(self, seed: int) -> Measurement:
        """Start at rest at θ = 0 with relaxed hysteresis; seed the sensor noise.

        Parameters
        ----------
        seed : int
            Seed of the pressure-sensor noise.

        Returns
        -------
        Measurement
            The first measurement, at rest.
        """
        p = self.params
        self._rng = np.random.default_rng(seed)
        self._t = 0.0
        self._x = np.zeros(4)  # θ (deg), ω (deg/s), Δp (bar), Δp' (bar/s)
        self._hys = p.hysteresis.initial_state(0.0)
        self._queue = [0.0] * p.delay_samples
        return self._measure()

    def _creep(self, t, xp=np):
        return _creep(self.params, t, xp)

    def step(self, u: float) -> Measurement:
        """Apply the commanded pressure difference ``u`` (bar) for one sample.

        Parameters
        ----------
        u : float
            Commanded pressure difference (bar), clipped to ±``dp_limit``; it reaches the
            pressure loop ``delay_samples`` samples later.

        Returns
        -------
        Measurement
            The measurement at the end of the sample.
        """
        if not np.isfinite(u):
            raise ValueError(f"plant input must be finite, got {u}")
        p = self.params
        u = float(np.clip(u, -p.dp_limit, p.dp_limit))
        self._queue.append(u)
        dp_cmd = self._queue.pop(0)
        x, hys = self._sample_function()(self._x, self._hys, self._t, dp_cmd)
        self._x, self._hys = np.asarray(x).ravel(), np.asarray(hys).ravel()
        for _ in range(p.substeps):  # the same sum of substeps as the Function's clock
            self._t = self._t + p.sample_period / p.substeps
        return self._measure()

    def _sample_function(self) -> ca.Function:
        """One sample of the truth as a CasADi Function.

        The Function ``(x, hysteresis state, t, Δp_cmd) -> (x, hysteresis state)`` takes
        ``substeps`` RK4 steps, each followed by the slew limit and the exact Maxwell-slip update
        (clips, not smoothed). Built once per plant; evaluating it is much faster than the same
        arithmetic in NumPy scalars.
        """
        if getattr(self, "_sample", None) is None:
            self._sample = _sample_function(self.params)
        return self._sample

    def _measure(self) -> Measurement:
        p = self.params
        quantum = 360.0 / p.encoder_counts
        theta, _, dp, _ = self._x
        return Measurement(
            t=self._t,
            y=float(np.round(theta / quantum) * quantum),
            sensors={"pressure": float(dp + p.pressure_noise_bar * self._rng.standard_normal())},
            truth={"angle": float(theta), "pressure": float(dp),
                   "dp_hys": p.hysteresis.output(self._hys)},
        )


def perturbed_hysteresis(base: MaxwellSlip, k_scale: float, w_scale: float) -> MaxwellSlip:
    """Maxwell-slip model with stiffnesses and break-away levels scaled element-wise.

    Parameters
    ----------
    base : MaxwellSlip
        The model to scale.
    k_scale : float
        Factor on every stiffness ``k``.
    w_scale : float
        Factor on every break-away level ``w``.

    Returns
    -------
    MaxwellSlip
        A copy of ``base`` with the scaled ``k`` and ``w``.
    """
    return replace(base, k=tuple(k * k_scale for k in base.k), w=tuple(w * w_scale for w in base.w))


def _creep(p: PamJointParams, t, xp=np):
    """Torque lost to muscle creep at time ``t`` (N m)."""
    return -p.creep_torque * (1.0 - xp.exp(-t / p.creep_time))


@functools.lru_cache(maxsize=64)
def _sample_function(p: PamJointParams) -> ca.Function:
    """:meth:`PamJoint._sample_function` for parameters ``p``, built once per process."""
    ms = p.hysteresis
    x = ca.SX.sym("x", 4)
    hys = ca.SX.sym("hys", 1 + ms.n_elements)
    t0, dp_cmd = ca.SX.sym("t"), ca.SX.sym("dp_cmd")
    h = p.sample_period / p.substeps
    xk, last, forces, t = x, hys[0], [hys[1 + i] for i in range(ms.n_elements)], t0
    for _ in range(p.substeps):
        dp_hys = sum(forces)
        xk = rk4(lambda x, t, dp_hys=dp_hys: ca.vertcat(*joint_rhs(p, x, dp_cmd, dp_hys, _creep(p, t, ca),
                                                                    xp=ca)), xk, h, t=t)
        xk = ca.vertcat(xk[:3], ca.fmin(ca.fmax(xk[3], -p.pressure_slew), p.pressure_slew))
        t = t + h
        forces = [ca.fmin(ca.fmax(f + k * (xk[0] - last), -w), w) for f, k, w in zip(forces, ms.k, ms.w,
                                                                                    strict=True)]
        last = xk[0]
    return ca.Function("pam_plant_sample", [x, hys, t0, dp_cmd], [xk, ca.vertcat(last, *forces)])
