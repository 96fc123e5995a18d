"""Identify a hysteresis model, and the linear block after it, from measured data.

Every family hystmpc has can be fitted from an input/output record ``(u_k, y_k)`` sampled
every ``sample_period`` seconds. The convention is a rig's: ``u_k`` is the input applied
from sample ``k`` on, ``y_k`` the output measured at sample ``k``, before ``u_k`` acts, so a
static hysteresis gives ``y_{k+1} = H[u]_k``. Record from rest (the actuator relaxed at
``u_0``): the models start in their relaxed state there.

How each family is fitted (scipy's optimisers throughout):

* ``prandtl-ishlinskii``: thresholds evenly spaced in (0, half the input span); the linear
  gain and play weights are linear in the play outputs: non-negative least squares.
* ``maxwell-slip``: the same grid; ``F_i = k_i (u − Play_{r_i}[u])``, so the stiffnesses are
  a non-negative least-squares fit too, and the break-away levels ``w_i = k_i r_i``.
* ``parametric`` (katalenic2013, eq. (3)): ``y = gain · H_{p1,p2}[u]``; the gain in closed
  form, p1 and p2 by Nelder–Mead on their logarithms after a coarse grid.
* ``kp`` and ``fckp`` (wang2025, eqs. (5)–(9)): on a fixed threshold grid, the density's
  ``c`` and ``σ``, the stroke and (``fckp``) the creep order α by bounded least squares.
* ``power-function`` (zhou2024, eqs. (10)–(19)): the two polylines' torques at fixed knots
  (increasing by construction), the transition widths (Table VI) and exponents (Table VII)
  by bounded least squares on the simulated output, started from polylines fitted to the
  rising and falling samples.

The linear block (:mod:`hystmpc.models.linear_dynamics`) is fitted afterwards, on the same
or a faster record, to the output of the fitted hysteresis: each dead time up to
``max_delay`` samples, and the time constant (first order) or natural frequency and damping
(second order) by least squares; the best fit wins.
"""

from __future__ import annotations

from collections.abc import Callable
from dataclasses import dataclass, field
from typing import Any

import numpy as np

from hystmpc.models.fckp import Fckp, FckpParams
from hystmpc.models.fractional import gl_apply
from hystmpc.models.kp import paper_density
from hystmpc.models.linear_dynamics import KINDS, LinearDynamics
from hystmpc.models.maxwell_slip import MaxwellSlip, play_operator
from hystmpc.models.parametric import ParametricHysteresis
from hystmpc.models.power_function import PowerFunctionHysteresis
from hystmpc.models.prandtl_ishlinskii import PrandtlIshlinskii
from hystmpc.models.scaled import Scaled

MIN_SAMPLES = 50
"""Fewer samples than this are refused: no family can be told from noise on less."""


@dataclass(frozen=True)
class Family:
    """A hysteresis family: how to build it from named parameters and how to fit it."""

    name: str
    description: str
    build: Callable[[dict, float], tuple[Any, float]]
    """``(parameters, sample_period) -> (hysteresis model, creep order)``."""
    fit: Callable[..., dict]
    """``(u, y, sample_period, **options) -> parameters``."""
    options: dict[str, Any]
    """Fit options and their defaults (``hystmpc identify ... --set NAME=VALUE``)."""
    mismatch: tuple[str, ...]
    """Parameters a simulated plant perturbs (the others are structure: grids, ranges)."""


@dataclass
class Identified:
    """A fitted model: hysteresis (with creep) and linear block, and how well it fits."""

    family: str
    parameters: dict
    dynamics: LinearDynamics
    sample_period: float
    rmse: float = float("nan")
    n_samples: int = 0
    options: dict = field(default_factory=dict)

    def hysteresis(self):
        """``(hysteresis model, creep order)``."""
        return FAMILIES[self.family].build(self.parameters, self.sample_period)

    def predict(self, u) -> np.ndarray:
        """Modelled output ``y_k`` for the inputs ``u`` (measurement convention of the module)."""
        model, creep_order = self.hysteresis()
        return self.dynamics.response(hysteresis_output(model, creep_order, u, self.sample_period),
                                      self.sample_period)


def hysteresis_output(model, creep_order: float, u, sample_period: float) -> np.ndarray:
    """Exact hysteresis (and creep) output along ``u`` from the relaxed state at ``u[0]``."""
    u = np.asarray(u, float)
    if isinstance(model, Scaled) and isinstance(model.inner, ParametricHysteresis):
        w = model.gain * parametric_response(model.inner, u)
    elif isinstance(model, PowerFunctionHysteresis):
        w = power_function_response(model, u)
    else:
        w = model.simulate(u)[0]
    return gl_apply(-creep_order, sample_period, w) if creep_order > 0 else w


def check_data(u, y, sample_period: float, what: str = "data") -> tuple[np.ndarray, np.ndarray]:
    """``ValueError`` naming what is wrong with an identification record."""
    u, y = np.asarray(u, float), np.asarray(y, float)
    if u.shape != y.shape or u.ndim != 1:
        raise ValueError(f"{what}: u and y must be columns of the same length")
    if len(u) < MIN_SAMPLES:
        raise ValueError(f"{what}: {len(u)} samples; identification needs at least {MIN_SAMPLES}")
    if not (np.all(np.isfinite(u)) and np.all(np.isfinite(y))):
        raise ValueError(f"{what}: NaN or infinite values in u or y")
    if np.ptp(u) == 0:
        raise ValueError(f"{what}: the input u is constant ({u[0]:g}); a hysteresis needs a varying input")
    if not (np.isfinite(sample_period) and sample_period > 0):
        raise ValueError(f"{what}: sample period must be > 0, got {sample_period}")
    return u, y


# ----- Prandtl–Ishlinskii and Maxwell-slip -------------------------------------------------------

def threshold_ladder(u, n: int) -> np.ndarray:
    """``n`` thresholds evenly spaced in (0, half the input span): ``r_i = i·span / (2(n+1))``."""
    if not (isinstance(n, int) and 1 <= n <= 200):
        raise ValueError(f"the number of plays must be an integer in [1, 200], got {n}")
    return 0.5 * np.ptp(u) * np.arange(1, n + 1) / (n + 1)


def _plays(u, thresholds) -> np.ndarray:
    return np.column_stack([play_operator(u, r, u[0]) for r in thresholds])


def _nnls(columns, target) -> np.ndarray:
    from scipy.optimize import nnls
    scale = np.maximum(np.abs(columns).max(axis=0), 1e-300)  # equilibrated columns
    coef, _ = nnls(columns / scale, target, maxiter=50 * columns.shape[1])
    return coef / scale


def fit_prandtl_ishlinskii(u, y, sample_period: float, plays: int = 10) -> dict:
    """Linear gain and play weights by non-negative least squares on :func:`threshold_ladder`."""
    u_in, y_out = u[:-1], y[1:]
    r = threshold_ladder(u_in, plays)
    coef = _nnls(np.column_stack((u_in, _plays(u_in, r))), y_out)
    keep = coef[1:] > 1e-9 * max(coef.max(), 1e-300)
    return {"linear_gain": float(coef[0]), "thresholds": [float(v) for v in r[keep]],
            "weights": [float(v) for v in coef[1:][keep]]}


def _build_prandtl_ishlinskii(p: dict, sample_period: float):
    return PrandtlIshlinskii(float(p["linear_gain"]), tuple(p["thresholds"]), tuple(p["weights"])), 0.0


def fit_maxwell_slip(u, y, sample_period: float, elements: int = 10) -> dict:
    """Stiffnesses by non-negative least squares on ``u − Play_r[u]``; ``w = k r``."""
    u_in, y_out = u[:-1], y[1:]
    r = threshold_ladder(u_in, elements)
    k = _nnls(u_in[:, None] - _plays(u_in, r), y_out)
    keep = k > 1e-9 * max(k.max(), 1e-300)
    if not keep.any():
        raise ValueError("no Maxwell-slip element carries the data (every stiffness fitted to zero)")
    return {"stiffness": [float(v) for v in k[keep]], "breakaway": [float(v) for v in (k * r)[keep]]}


def _build_maxwell_slip(p: dict, sample_period: float):
    return MaxwellSlip(tuple(float(v) for v in p["stiffness"]), tuple(float(v) for v in p["breakaway"])), 0.0


# ----- the parametric operator --------------------------------------------------------------------

def monotone_segments(u) -> tuple[np.ndarray, list[tuple[int, int]]]:
    """The direction of each move ``u[k] -> u[k+1]`` (a standing input keeps the last one,
    +1 at the start) and the monotone runs ``(a, b)``: samples ``a+1..b`` move away from ``u[a]``
    in ``direction[a]``, so a model's memory is constant over each run."""
    direction = np.sign(np.diff(np.asarray(u, float)))
    last = 1.0
    for k in range(len(direction)):
        if direction[k] == 0:
            direction[k] = last
        last = direction[k]
    if len(direction) == 0:
        return direction, []
    starts = np.concatenate(([0], np.flatnonzero(direction[1:] != direction[:-1]) + 1))
    ends = np.concatenate((starts[1:], [len(u) - 1]))
    return direction, [(int(a), int(b)) for a, b in zip(starts, ends, strict=True)]


def parametric_response(op: ParametricHysteresis, u) -> np.ndarray:
    """H's exact response to ``u`` from the demagnetised state at ``u[0]``, vectorised per
    monotone segment (the memory is constant between reversals, Definition 3.1)."""
    u = np.asarray(u, float)
    v = np.empty_like(u)
    v[0] = u[0]
    direction, segments = monotone_segments(u)
    for a, b in segments:
        v[a + 1: b + 1] = op.direct(u[a + 1: b + 1], direction[a], u[a], v[a])
    return v


def fit_parametric(u, y, sample_period: float) -> dict:
    """``y = gain · H_{p1,p2}[u]``: gain in closed form, (log p1, log p2) by Nelder–Mead."""
    from scipy.optimize import minimize
    u_in, y_out = u[:-1], y[1:]
    span = float(np.ptp(u_in))

    def gain_and_cost(z):
        try:
            v = parametric_response(ParametricHysteresis(float(np.exp(z[0])), float(np.exp(z[1]))), u_in)
        except ValueError:
            return 0.0, np.inf
        vv = float(v @ v)
        if not (np.all(np.isfinite(v)) and vv > 0):
            return 0.0, np.inf
        gain = float(v @ y_out) / vv
        return gain, float(np.sum((gain * v - y_out) ** 2))

    grid = [np.log([span * a, b / span]) for a in (0.003, 0.01, 0.03, 0.1, 0.3) for b in (0.3, 1, 3, 10, 30, 100)]
    start = min(grid, key=lambda z: gain_and_cost(z)[1])
    result = minimize(lambda z: gain_and_cost(z)[1], start, method="Nelder-Mead",
                      options={"xatol": 1e-9, "fatol": 1e-14, "maxiter": 2000})
    gain, _ = gain_and_cost(result.x)
    return {"p1": float(np.exp(result.x[0])), "p2": float(np.exp(result.x[1])), "gain": gain}


def _build_parametric(p: dict, sample_period: float):
    return Scaled(ParametricHysteresis(float(p["p1"]), float(p["p2"])), float(p["gain"])), 0.0


# ----- KP and FCKP ----------------------------------------------------------------------------------

def _kernel_outputs(model: Fckp, u) -> np.ndarray:
    """Every KP kernel's output along ``u`` (rows: samples)."""
    kp = model.kp
    state = model.initial_state(u[0])
    out = np.empty((len(u), kp.n_kernels))
    p = model.normalise(np.asarray(u, float))
    for k, pk in enumerate(p):
        state = np.concatenate(([pk], kp.kernels_step(state, pk)))
        out[k] = state[1:]
    return out


def _fit_kp_family(u, y, sample_period: float, creep: bool, levels: int, max_span: int, delta: float,
                   u_max: float) -> dict:
    from scipy.optimize import least_squares
    if np.min(u) < 0:
        raise ValueError(f"the kp and fckp families take inputs in [0, u_max]; the data go down to {np.min(u):g}")
    u_in, y_out = u[:-1], y[1:]
    u_max = float(u_max) if u_max > 0 else float(np.max(u))
    if np.max(u) > u_max:
        raise ValueError(f"the data's input reaches {np.max(u):g}, above u_max = {u_max:g}")
    grid = FckpParams(levels=levels, max_span=max_span, delta=delta, u_max=u_max, sample_period=sample_period)
    kernels = _kernel_outputs(Fckp(grid), u_in)
    rho1, rho2 = Fckp(grid).kp.rho1, Fckp(grid).kp.rho2

    def model_of(z):
        c, sigma, stroke, alpha = z
        mu = paper_density(rho1, rho2, c, sigma)
        w = stroke * 0.5 * (kernels @ mu / mu.sum() + 1.0)
        return gl_apply(-alpha, sample_period, w) if alpha > 0 else w

    stroke0 = float(np.max(np.abs(y_out))) or 1.0
    lower = [0.05, 0.05, 1e-6 * stroke0, 0.0]
    upper = [20.0, 20.0, 10 * stroke0, 0.5 if creep else 1e-12]
    best = None
    for c0, s0 in ((2.0, 1.0), (1.0, 0.5), (4.0, 2.0)):
        z0 = [c0, s0, stroke0, 0.02 if creep else 0.0]
        fit = least_squares(lambda z: model_of(z) - y_out, z0, bounds=(lower, upper), x_scale="jac",
                            xtol=1e-12, ftol=1e-12)
        if best is None or fit.cost < best.cost:
            best = fit
    c, sigma, stroke, alpha = (float(v) for v in best.x)
    doc = {"levels": levels, "max_span": max_span, "delta": delta, "u_max": u_max, "density_c": c,
           "density_sigma": sigma, "stroke": stroke}
    return doc | ({"creep_order": alpha} if creep else {})


def fit_kp(u, y, sample_period: float, levels: int = 12, max_span: int = 2, delta: float = 0.15,
           u_max: float = 0.0) -> dict:
    """KP (no creep): density ``c``, ``σ`` and stroke on the threshold grid over [0, u_max]
    (``u_max`` 0: the data's largest input)."""
    return _fit_kp_family(u, y, sample_period, False, levels, max_span, delta, u_max)


def fit_fckp(u, y, sample_period: float, levels: int = 12, max_span: int = 2, delta: float = 0.15,
           u_max: float = 0.0) -> dict:
    """FCKP: as :func:`fit_kp`, and the creep order α."""
    return _fit_kp_family(u, y, sample_period, True, levels, max_span, delta, u_max)


def _fckp_params(p: dict, sample_period: float, creep_order: float) -> FckpParams:
    return FckpParams(levels=int(p["levels"]), max_span=int(p["max_span"]), delta=float(p["delta"]),
                      density_c=float(p["density_c"]), density_sigma=float(p["density_sigma"]),
                      creep_order=creep_order, stroke=float(p["stroke"]), u_max=float(p["u_max"]),
                      sample_period=sample_period)


def _build_kp(p: dict, sample_period: float):
    return Fckp(_fckp_params(p, sample_period, 0.0)), 0.0


def _build_fckp(p: dict, sample_period: float):
    alpha = float(p["creep_order"])
    return Fckp(_fckp_params(p, sample_period, alpha)), alpha


# ----- power-function -------------------------------------------------------------------------------

def _polyline_start(s, tau, knots) -> np.ndarray:
    """Torques at ``knots`` of the least-squares polyline through (s, τ), made increasing."""
    knots = np.asarray(knots, float)
    basis = np.column_stack([np.interp(s, knots, np.eye(len(knots))[i]) for i in range(len(knots))])
    values = np.linalg.lstsq(basis, tau, rcond=None)[0]
    step = 1e-3 * max(float(np.ptp(tau)), 1e-12)
    for i in range(1, len(values)):
        values[i] = max(values[i], values[i - 1] + step)
    return values


def power_function_response(model: PowerFunctionHysteresis, s) -> np.ndarray:
    """The exact response of :meth:`PowerFunctionHysteresis.step` along ``s`` from
    ``initial_state(s[0])``, vectorised per monotone segment (the turning points and the
    torque at the reversal are constant between reversals)."""
    s = np.asarray(s, float)
    tau = np.empty_like(s)
    tau[0] = float(model.tau_ascending(s[0]))
    direction, segments = monotone_segments(s)
    s01, s02, tau_r = s[0], s[0] - model.delta_s1(s[0]), tau[0]  # the initial state
    for a, b in segments:
        seg = s[a + 1: b + 1]
        if direction[a] > 0:
            if a > 0:  # s[a] was a minimum: eq. (13), then eq. (10)
                s02, s01, tau_r = s[a], s[a] + model.delta_s2(s[a]), tau[a]
            x = (np.maximum(seg, s02) - s02) / (s01 - s02)
            transition = tau_r + (float(model.tau_ascending(s01)) - tau_r) * x ** model.exponent(s02)
            tau[a + 1: b + 1] = np.where(seg >= s01, model.tau_ascending(seg), transition)
        else:
            s01, s02, tau_r = s[a], s[a] - model.delta_s1(s[a]), tau[a]  # a maximum: eq. (12)
            y = (s01 - np.minimum(seg, s01)) / (s01 - s02)
            transition = tau_r - (tau_r - float(model.tau_descending(s02))) * y ** model.exponent(s01)
            tau[a + 1: b + 1] = np.where(seg <= s02, model.tau_descending(seg), transition)
    return tau


def fit_power_function(u, y, sample_period: float, knots: int = 10, ascending_s: tuple = (),
                       descending_s: tuple = ()) -> dict:
    """Polyline torques at fixed knots, transition widths and exponents by least squares.

    ``knots`` evenly spaced knots over the input span for both polylines, unless
    ``ascending_s`` / ``descending_s`` name them. When both polylines span the same
    knots at their ends, they are made to meet there (a major loop closes at its tips,
    as Table V's points E and R): the descending polyline is never followed near the
    tips, so its ends could not be told from the data otherwise.
    """
    from scipy.optimize import least_squares
    u_in, y_out = u[:-1], y[1:]
    lo, hi = float(np.min(u_in)), float(np.max(u_in))
    span = hi - lo
    s_a = np.asarray(ascending_s, float) if len(ascending_s) else np.linspace(lo, hi, knots)
    s_d = np.asarray(descending_s, float) if len(descending_s) else np.linspace(lo, hi, knots)
    for name, s in (("ascending_s", s_a), ("descending_s", s_d)):
        if len(s) < 2 or np.any(np.diff(s) <= 0):
            raise ValueError(f"{name} must be at least two increasing knots, got {[float(v) for v in s]}")
    na, nd = len(s_a), len(s_d)
    tied = s_a[0] == s_d[0] and s_a[-1] == s_d[-1] and nd >= 3
    rising = np.concatenate(([True], np.diff(u_in) > 0))
    tau_scale = max(float(np.ptp(y_out)), 1e-12)
    n_d = nd - 2 if tied else nd

    def unpack(z):
        a = z[0] + np.concatenate(([0.0], np.cumsum(np.exp(z[1:na]))))
        if tied:
            share = np.exp(np.concatenate(([0.0], z[na: na + n_d])))
            d = a[0] + (a[-1] - a[0]) * np.concatenate(([0.0], np.cumsum(share / share.sum())))
        else:
            d = z[na] + np.concatenate(([0.0], np.cumsum(np.exp(z[na + 1: na + nd]))))
        rest = z[na + n_d:]
        return PowerFunctionHysteresis(tuple(zip(s_a, a * tau_scale, strict=True)),
                                       tuple(zip(s_d, d * tau_scale, strict=True)),
                                       k11=rest[0], k01=rest[1] * span, k12=rest[2], k02=rest[3] * span,
                                       exponent_positive=(rest[4] / span**2, rest[5] / span, rest[6]),
                                       exponent_negative=(rest[7] / span**2, rest[8] / span, rest[9]))

    def pack(a, d):
        a, d = np.asarray(a) / tau_scale, np.asarray(d) / tau_scale
        if tied:
            inc = np.maximum(np.diff(d), 1e-6)
            falling = np.log(inc[1:] / inc[0])
        else:
            falling = np.concatenate(([d[0]], np.log(np.diff(d))))
        transitions = [0.0, 0.05, 0.0, 0.05, 0.0, 0.0, 2.0, 0.0, 0.0, 2.0]  # Δs of 5 % of the span, b = 2
        return np.concatenate(([a[0]], np.log(np.diff(a)), falling, transitions))

    def residual(z):
        try:
            out = power_function_response(unpack(z), u_in)
        except (ValueError, FloatingPointError, OverflowError, ZeroDivisionError):
            return np.full(len(y_out), 1e3)
        r = (out - y_out) / tau_scale
        return np.where(np.isfinite(r), r, 1e3)

    z0 = pack(_polyline_start(u_in[rising], y_out[rising], s_a), _polyline_start(u_in[~rising], y_out[~rising], s_d))
    with np.errstate(all="ignore"):
        fit = least_squares(residual, z0, x_scale="jac", max_nfev=100 * len(z0), xtol=1e-10, ftol=1e-10)
    model = unpack(fit.x)
    return {"ascending": [list(map(float, p)) for p in model.ascending],
            "descending": [list(map(float, p)) for p in model.descending],
            "k11": float(model.k11), "k01": float(model.k01), "k12": float(model.k12), "k02": float(model.k02),
            "exponent_positive": [float(v) for v in model.exponent_positive],
            "exponent_negative": [float(v) for v in model.exponent_negative]}


def _build_power_function(p: dict, sample_period: float):
    return PowerFunctionHysteresis(tuple(tuple(map(float, q)) for q in p["ascending"]),
                                   tuple(tuple(map(float, q)) for q in p["descending"]),
                                   k11=float(p["k11"]), k01=float(p["k01"]), k12=float(p["k12"]),
                                   k02=float(p["k02"]), exponent_positive=tuple(map(float, p["exponent_positive"])),
                                   exponent_negative=tuple(map(float, p["exponent_negative"]))), 0.0


FAMILIES: dict[str, Family] = {f.name: f for f in (
    Family("prandtl-ishlinskii", "linear term + weighted play operators", _build_prandtl_ishlinskii,
           fit_prandtl_ishlinskii, {"plays": 10}, ("linear_gain", "thresholds", "weights")),
    Family("maxwell-slip", "parallel elasto-slide elements", _build_maxwell_slip, fit_maxwell_slip,
           {"elements": 10}, ("stiffness", "breakaway")),
    Family("power-function", "zhou2024 polylines and power-function transitions", _build_power_function,
           fit_power_function, {"knots": 10, "ascending_s": (), "descending_s": ()},
           ("k11", "k01", "k12", "k02", "exponent_positive", "exponent_negative")),
    Family("parametric", "katalenic2013 Lambert-W operator, times a gain", _build_parametric, fit_parametric, {},
           ("p1", "p2", "gain")),
    Family("kp", "wang2025 Krasnoselskii–Pokrovskii model (no creep)", _build_kp, fit_kp,
           {"levels": 12, "max_span": 2, "delta": 0.15, "u_max": 0.0}, ("density_c", "density_sigma", "stroke")),
    Family("fckp", "wang2025 KP model with fractional-order creep", _build_fckp, fit_fckp,
           {"levels": 12, "max_span": 2, "delta": 0.15, "u_max": 0.0},
           ("density_c", "density_sigma", "stroke", "creep_order")),
)}
"""Every hysteresis family hystmpc identifies, by public name."""


def family(name: str) -> Family:
    """The family called ``name``; ``ValueError`` naming the allowed ones otherwise."""
    if name not in FAMILIES:
        raise ValueError(f"unknown model family {name!r}; allowed: {', '.join(FAMILIES)}")
    return FAMILIES[name]


def fit_options(name: str, assignments: dict[str, Any]) -> dict[str, Any]:
    """The family's fit options with ``assignments`` (text or values) applied; ``ValueError``
    naming an unknown option or a bad value."""
    fam = family(name)
    options = dict(fam.options)
    for key, value in assignments.items():
        if key not in options:
            allowed = ", ".join(options) or "none"
            raise ValueError(f"unknown option {key!r} for family {name}; its options: {allowed}")
        default = options[key]
        try:
            if isinstance(default, tuple):
                value = tuple(float(v) for v in (value.split(",") if isinstance(value, str) else value))
            elif isinstance(default, int):
                value = int(value)
            else:
                value = float(value)
        except (TypeError, ValueError):
            raise ValueError(f"option {key}={value!r} for family {name}: expected "
                             f"{'numbers' if isinstance(default, tuple) else type(default).__name__}") from None
        options[key] = value
    return options


def fit_dynamics(h, y, sample_period: float, kind: str, max_delay: int = 20) -> LinearDynamics:
    """The linear block ``kind`` (and dead time, 0..``max_delay`` samples) that best maps the
    hysteresis output ``h`` onto the measured ``y``."""
    from scipy.optimize import least_squares
    if kind not in KINDS:
        raise ValueError(f"dynamics {kind!r} is not one of {', '.join(KINDS)}")
    h, y = np.asarray(h, float), np.asarray(y, float)
    nyquist = 0.5 / sample_period
    best, best_cost = None, np.inf
    for delay in range(max_delay + 1):
        if kind == "none":
            candidates = [LinearDynamics("none", delay_samples=delay)]
        else:
            if kind == "first-order":
                def block(z, delay=delay):
                    return LinearDynamics("first-order", time_constant=float(np.exp(z[0])), delay_samples=delay)
                starts = [[np.log(m * sample_period)] for m in (1.0, 5.0, 30.0)]
            else:
                def block(z, delay=delay):
                    return LinearDynamics("second-order", natural_frequency_hz=float(np.exp(z[0])),
                                          damping=float(np.exp(z[1])), delay_samples=delay)
                starts = [[np.log(f * nyquist), np.log(zeta)] for f in (0.02, 0.1, 0.4) for zeta in (0.2, 0.7)]
            candidates = []
            for z0 in starts:
                fit = least_squares(lambda z, block=block: block(z).response(h, sample_period) - y, z0,
                                    bounds=([-20, -5][: len(z0)], [np.log(nyquist), 2.0][: len(z0)])
                                    if kind == "second-order" else ([np.log(sample_period / 10)], [10.0]))
                candidates.append(block(fit.x))
        for candidate in candidates:
            cost = float(np.mean((candidate.response(h, sample_period) - y) ** 2))
            if cost < best_cost:
                best, best_cost = candidate, cost
    return best


def identify(name: str, u, y, sample_period: float, options: dict | None = None, dynamics: str = "none",
             dynamics_data: tuple | None = None, max_delay: int = 20) -> Identified:
    """Fit family ``name`` to the record ``(u, y)``, then the linear block ``dynamics``.

    Parameters
    ----------
    name : str
        One of :data:`FAMILIES`.
    u, y : array_like
        Input applied from each sample on, output measured at each sample (from rest).
    sample_period : float
        Sample period of the record (s).
    options : dict, optional
        The family's fit options (:attr:`Family.options`).
    dynamics : str
        ``none``, ``first-order`` or ``second-order``: the block after the hysteresis.
    dynamics_data : tuple of array_like, optional
        ``(u, y)`` of a faster record for the block (default: the same record).
    max_delay : int
        Largest dead time tried (samples).
    """
    fam = family(name)
    u, y = check_data(u, y, sample_period)
    params = fam.fit(u, y, sample_period, **fit_options(name, options or {}))
    identified = Identified(name, params, LinearDynamics(), sample_period, options=dict(options or {}))
    if dynamics != "none":
        u_d, y_d = (u, y) if dynamics_data is None else check_data(*dynamics_data, sample_period, "dynamics data")
        model, creep_order = identified.hysteresis()
        h = hysteresis_output(model, creep_order, u_d, sample_period)
        identified.dynamics = fit_dynamics(h, y_d, sample_period, dynamics, max_delay)
    prediction = identified.predict(u)
    identified.rmse = float(np.sqrt(np.mean((prediction - y) ** 2)))
    identified.n_samples = len(u)
    return identified
