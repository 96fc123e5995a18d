"""Every hysteresis model against the one contract of ``models/base.py``.

Smooth → exact as eps → 0 within each model's stated bound, CasADi derivatives against
finite differences, inverse round trip, state in and out. Model-specific facts (paper
tables, closed forms) stay in the per-model test files.
"""

from dataclasses import dataclass, field

import casadi as ca
import numpy as np
import pytest

from hystmpc.models import (
    Fckp,
    FckpParams,
    HysteresisModel,
    MaxwellSlip,
    ParametricHysteresis,
    PowerFunctionHysteresis,
    PrandtlIshlinskii,
    Scaled,
)
from hystmpc.models.bouc_wen import BoucWen
from hystmpc.models.generalised_pi import GeneralisedPI
from hystmpc.models.preisach import Preisach
from hystmpc.models.scaled import Offset

RNG = np.random.default_rng


@dataclass
class Case:
    """One model and the paths, widths and bounds it is checked with."""

    name: str
    model: HysteresisModel
    inputs: np.ndarray
    """An input path with reversals, from ``initial_state(inputs[0])``."""
    targets: np.ndarray
    """Reachable output targets for the inverse round trip."""
    eps: tuple[float, ...]
    """Widths, decreasing; the error must decrease with them."""
    bound: object
    """``bound(eps, n_steps)``: the stated largest output error of the smooth step."""
    inverse_tol: float
    fd: dict = field(default_factory=dict)
    """Derivative check: eps, step h, rtol, atol."""
    direction: object = None
    """``eps -> direction_eps`` (None: the model's default)."""


def _walk(seed, n, scale, start=0.0):
    u = start + np.cumsum(RNG(seed).normal(0.0, scale, n))
    u[0] = start
    return u


def _power_function_path():
    """s along the inverse of a two-tone torque: steps down to ~5e-7 (see the bound)."""
    model = PowerFunctionHysteresis()
    t = np.arange(0.0, 20.0, 0.01)
    state, s = model.initial_state(), []
    for r in 1.5 * np.sin(0.2 * np.pi * t) + 0.3 * np.sin(1.3 * np.pi * t):
        state, v = model.inverse_step(state, r)
        s.append(v)
    return np.asarray(s)


MS = MaxwellSlip(k=(0.0557, 0.0170, 0.0021, 0.0033), w=(0.1680, 0.1383, 0.0342, 0.1335))  # vo2012 Table 1
PI = PrandtlIshlinskii(0.8, (0.5, 1.5, 3.0), (0.4, 0.3, 0.2))
KP = Fckp().kp
E_CORE = ParametricHysteresis(p1=0.0071, p2=0.0014 / 1.5e-3)  # katalenic2013 Table 2 at g = 1.5 mm
PREISACH = Preisach((0.5, 1.5, 3.0), (-2.0, -1.0, 0.0, 1.0, 2.0, 3.0),
                    tuple(map(tuple, RNG(0).uniform(0.05, 1.0, (4, 5)))))
GPI = GeneralisedPI(0.5, (0.5, 1.5), (0.3, 0.2), (-2.0, 0.0, 1.0, 3.0), (-1.0, 0.0, 2.0, 2.5))
BOUC_WEN = BoucWen(0.9, -0.5, 0.8, 0.2)  # the piezo form (A < 0)
BOUC_WEN_POWER = BoucWen(0.9, -0.5, 0.8, 0.2, 1.6)

CASES = [
    Case("maxwell-slip", MS, _walk(7, 400, 2.5), RNG(3).uniform(-0.99, 0.99, 200) * MS.saturation,
         (1e-2, 1e-3, 1e-4), lambda eps, n: n * 4 * eps / 2, 1e-12,
         {"eps": 1e-2, "h": 1e-6, "rtol": 1e-6, "atol": 1e-6}),
    Case("prandtl-ishlinskii", PI, _walk(8, 400, 0.6), _walk(9, 200, 0.8, 1.0),
         (1e-2, 1e-3, 1e-4), lambda eps, n: n * 3 * eps / 2, 1e-9,
         {"eps": 1e-2, "h": 1e-6, "rtol": 1e-6, "atol": 1e-6}),
    # converges once eps is below the smallest input step on the path (~5e-7 here): within
    # 0.1 % of the 1.8 N m amplitude at 1e-8 (the model's docstring)
    Case("power-function", PowerFunctionHysteresis(), _power_function_path(),
         2.0 * np.sin(np.linspace(0, 6 * np.pi, 600)), (1e-5, 1e-6, 1e-7, 1e-8),
         lambda eps, n: 1e-3 * 1.8 if eps <= 1e-8 else np.inf, 1e-9,
         {"eps": 1e-4, "h": 1e-9, "rtol": 1e-4, "atol": 1e-3}),
    # O(eps): within 1 % of the loop width p1 at eps = 1e-5
    Case("parametric", E_CORE, _walk(2, 600, 0.02, 3.0), np.abs(_walk(3, 600, 0.3)) + 0.1,
         (1e-3, 1e-4, 1e-5), lambda eps, n: 1e-2 * E_CORE.p1 if eps <= 1e-5 else np.inf, 1e-9,
         {"eps": 1e-3, "h": 1e-7, "rtol": 1e-5, "atol": 1e-6}),
    # O(eps) with direction width eps/10: 2.4 eps Σμ in κ (the FCKP's 1.2 eps·stroke in mm)
    Case("kp", KP, np.clip(_walk(4, 600, 0.01, -0.4), -1, 1),
         np.clip(_walk(5, 100, 0.05, 0.0), -0.9, 0.9) * KP.total_weight,
         (1e-2, 1e-3, 1e-4), lambda eps, n: 2.4 * eps * KP.total_weight, 1e-6 * KP.total_weight,
         {"eps": 1e-2, "h": 1e-6, "rtol": 1e-5, "atol": 1e-7}, direction=lambda eps: eps / 10),
    # the parametric family of `hystmpc identify`: the operator behind a gain (µm per A here)
    Case("scaled-parametric", Scaled(E_CORE, 250.0), _walk(2, 600, 0.02, 3.0),
         250.0 * (np.abs(_walk(3, 600, 0.3)) + 0.1),
         (1e-3, 1e-4, 1e-5), lambda eps, n: 250.0 * 1e-2 * E_CORE.p1 if eps <= 1e-5 else np.inf, 250.0 * 1e-9,
         {"eps": 1e-3, "h": 1e-7, "rtol": 1e-5, "atol": 250.0 * 1e-6}),
    Case("fckp", Fckp(), np.clip(_walk(4, 600, 0.05, 3.0), 0.0, 10.0), np.clip(_walk(6, 100, 0.1, 1.5), 0.2, 3.8),
         (1e-2, 1e-3, 1e-4), lambda eps, n: 1.2 * eps * 4.0, 1e-6,
         {"eps": 1e-2, "h": 1e-6, "rtol": 1e-5, "atol": 1e-7}, direction=lambda eps: eps / 10),
    # kp over a bipolar range (wang2025's grid laid on [-150, 150] V)
    Case("fckp-bipolar", Fckp(FckpParams(u_min=-150.0, u_max=150.0, creep_order=0.0)),
         np.clip(_walk(4, 600, 1.5, 0.0), -150.0, 150.0), np.clip(_walk(6, 25, 0.1, 2.0), 0.2, 3.8),
         (1e-2, 1e-3, 1e-4), lambda eps, n: 1.2 * eps * 4.0, 1e-6,
         {"eps": 1e-2, "h": 1e-6, "rtol": 1e-5, "atol": 1e-7}, direction=lambda eps: eps / 10),
    # plays and kinks each err by at most eps/2 (the model's docstring)
    Case("preisach", PREISACH, _walk(8, 400, 0.5), _walk(9, 200, 0.8, 2.0), (1e-2, 1e-3, 1e-4),
         lambda eps, n: (n * eps / 2 + eps / 2) * float(np.sum(PREISACH.density)), 1e-9,
         {"eps": 1e-2, "h": 1e-6, "rtol": 1e-5, "atol": 1e-6}),
    Case("generalised-pi", GPI, _walk(8, 400, 0.3), _walk(9, 200, 0.3), (1e-2, 1e-3, 1e-4),
         lambda eps, n: 2.0 * (n * 2 * eps / 2) + 2 * eps, 1e-9, {"eps": 1e-2, "h": 1e-6, "rtol": 1e-5, "atol": 1e-6}),
    # O(eps), the direction and the side of zeta = 0 blended (the model's docstring)
    Case("bouc-wen", BOUC_WEN, _walk(8, 400, 0.3), _walk(9, 200, 0.5), (1e-2, 1e-3, 1e-4),
         lambda eps, n: 0.25 * eps, 1e-9, {"eps": 1e-2, "h": 1e-7, "rtol": 1e-4, "atol": 1e-5}),
    Case("bouc-wen-exponent", BOUC_WEN_POWER, _walk(8, 400, 0.3), _walk(9, 200, 0.5), (1e-2, 1e-3, 1e-4),
         lambda eps, n: 0.25 * eps, 1e-9, {"eps": 1e-2, "h": 1e-7, "rtol": 1e-4, "atol": 1e-5}),
    Case("offset-preisach", Offset(PREISACH, 0.7, -3.0), _walk(8, 400, 0.5), _walk(9, 200, 0.8, -1.0),
         (1e-2, 1e-3, 1e-4), lambda eps, n: (n * eps / 2 + eps / 2) * float(np.sum(PREISACH.density)), 1e-9,
         {"eps": 1e-2, "h": 1e-6, "rtol": 1e-5, "atol": 1e-6}),
]


@pytest.fixture(params=CASES, ids=[c.name for c in CASES])
def case(request) -> Case:
    return request.param


def _smooth(case: Case, eps: float) -> ca.Function:
    return case.model.smooth_step(eps, None if case.direction is None else case.direction(eps))


def _exact_path(case: Case):
    model = case.model
    states, outputs = [model.initial_state(case.inputs[0])], []
    for u in case.inputs[1:]:
        state, y = model.step(states[-1], u)
        states.append(state)
        outputs.append(y)
    return states, np.asarray(outputs)


def test_is_a_hysteresis_model(case):
    assert isinstance(case.model, HysteresisModel)


def test_smooth_step_converges_to_the_exact_step_within_the_stated_bound(case):
    states, exact = _exact_path(case)
    errors = []
    for eps in case.eps:
        smooth, state, out = _smooth(case, eps), states[0], []
        for u in case.inputs[1:]:
            state, y = smooth(state, u)
            out.append(float(y))
        errors.append(float(np.max(np.abs(np.asarray(out) - exact))))
    assert all(a > b for a, b in zip(errors, errors[1:], strict=False)), errors
    assert errors[-1] <= case.bound(case.eps[-1], len(exact)), errors
    assert errors[-1] > 0  # two different code paths, not one compared with itself


def test_smooth_step_derivatives_match_finite_differences(case):
    fd = case.fd
    smooth = _smooth(case, fd["eps"])
    n = len(case.model.state_names)
    z = ca.SX.sym("z", n + 1)
    nxt, y = smooth(z[:n], z[n])
    value = ca.Function("value", [z], [ca.vertcat(nxt, y)])
    jacobian = ca.Function("jacobian", [z], [ca.jacobian(ca.vertcat(nxt, y), z)])
    states, _ = _exact_path(case)
    rng = RNG(11)
    spread = np.std(np.diff(case.inputs))
    for k in rng.choice(np.arange(1, len(states)), 8, replace=False):
        point = np.concatenate((states[k], [case.inputs[k] + rng.normal(0, spread)]))
        numeric = np.empty((n + 1, n + 1))
        for j in range(n + 1):
            plus, minus = point.copy(), point.copy()
            plus[j] += fd["h"]
            minus[j] -= fd["h"]
            numeric[:, j] = (np.asarray(value(plus)).ravel() - np.asarray(value(minus)).ravel()) / (2 * fd["h"])
        np.testing.assert_allclose(np.asarray(jacobian(point)), numeric, rtol=fd["rtol"], atol=fd["atol"])


def test_inverse_step_reaches_each_target_and_returns_the_state_after_it(case):
    model = case.model
    state = model.initial_state(case.inputs[0])
    for target in case.targets:
        new_state, u = model.inverse_step(state, float(target))
        stepped, y = model.step(state, u)
        assert y == pytest.approx(target, abs=case.inverse_tol)
        np.testing.assert_allclose(new_state, stepped, rtol=0, atol=1e-12)  # Fckp: volts <-> normalised
        state = new_state


def test_symbolic_step_and_inverse_repeat_the_numpy_ones(case):
    """A generated controller runs the exact step and the inverse on CasADi expressions
    (the inverse warm start and the fallback): the same states and inputs as NumPy's."""
    model = case.model
    x, v = ca.SX.sym("state", len(model.state_names)), ca.SX.sym("v")
    step = ca.Function("step", [x, v], list(model.step(x, v)))
    inverse = ca.Function("inverse", [x, v], list(model.inverse_step(x, v)))
    state = model.initial_state(case.inputs[0])
    for u in case.inputs[1:60]:
        expected, y = model.step(state, u)
        got, y_got = (np.asarray(value, float).ravel() for value in step(state, u))
        np.testing.assert_allclose(got, expected, rtol=0, atol=1e-12)
        assert y_got[0] == pytest.approx(y, abs=1e-12)
        state = expected
    for target in case.targets[:60]:
        expected, u = model.inverse_step(state, float(target))
        got, u_got = (np.asarray(value, float).ravel() for value in inverse(state, target))
        assert u_got[0] == pytest.approx(u, abs=1e-9 * (1 + abs(u)))
        assert np.all(np.abs(got - expected) <= 1e-9 * (1 + np.abs(expected))), (got, expected)
        state = expected


def test_state_goes_in_and_comes_out(case):
    model = case.model
    state = model.initial_state(case.inputs[0])
    assert len(state) == len(model.state_names)
    before = state.copy()
    nxt, y = model.step(state, case.inputs[1])
    np.testing.assert_array_equal(state, before)  # the memory is passed in, never changed in place
    assert model.output(nxt) == pytest.approx(y, abs=1e-12)
    symbolic = ca.SX.sym("state", len(model.state_names))
    output = ca.Function("output", [symbolic], [model.output(symbolic)])
    assert float(output(nxt)) == pytest.approx(y, abs=1e-12)
    smooth = _smooth(case, case.eps[0])
    assert smooth.name_in() == ["state", "u"] and smooth.name_out() == ["state_next", "y"]
    assert smooth.size1_in(0) == len(state) and smooth.size1_out(0) == len(state)
    half = len(case.inputs) // 2
    whole, _ = model.simulate(case.inputs)
    first, middle = model.simulate(case.inputs[:half])
    second, _ = model.simulate(case.inputs[half:], middle)
    np.testing.assert_array_equal(whole, np.concatenate((first, second)))


@pytest.mark.parametrize("model", [MS, PI], ids=["maxwell-slip", "prandtl-ishlinskii"])
def test_models_without_direction_detection_reject_direction_eps(model):
    with pytest.raises(ValueError, match="direction_eps does not apply"):
        model.smooth_step(1e-3, 1e-4)


@pytest.mark.parametrize("case", CASES, ids=[c.name for c in CASES])
@pytest.mark.parametrize("eps", [0.0, -1.0, float("nan")])
def test_smooth_step_rejects_a_bad_width(case, eps):
    with pytest.raises(ValueError, match="eps must be"):
        case.model.smooth_step(eps)


def _bouc_wen_integrated(model: BoucWen, u: np.ndarray, pieces: int = 200) -> np.ndarray:
    """Bouc–Wen's output along ``u`` with the equation integrated finely (classical RK4 in the input)."""
    beta, gamma, n = model.beta, model.gamma, model.exponent

    def rate(z, s):
        return 1.0 - (beta * s * np.sign(z) + gamma) * abs(z) ** n
    z, last, out = 0.0, u[0], []
    for v in u:
        h, s = (v - last) / pieces, np.sign(v - last)
        for _ in range(pieces if v != last else 0):
            k1 = rate(z, s)
            k2 = rate(z + h / 2 * k1, s)
            k3 = rate(z + h / 2 * k2, s)
            z += h * (k1 + 2 * k2 + 2 * k3 + rate(z + h * k3, s)) / 6
        last = v
        out.append(model.linear_gain * v + model.a * z)
    return np.asarray(out)


@pytest.mark.parametrize("exponent, asymmetry, tolerance", [
    (1.05, 1 / 3, 2e-3), (1.2, 1 / 3, 2e-3), (1.6, 1 / 3, 2e-3), (2.5, 1 / 3, 2e-3), (4.0, 1 / 3, 5e-3),
    (1.2, -0.5, 4e-3), (1.2, -0.9, 3e-2), (2.5, -0.9, 7e-2)])
def test_bouc_wen_with_an_exponent_follows_its_equation_whatever_the_sampling(exponent, asymmetry, tolerance):
    """The module's figures, on the loop alone (``k = 0``: the error over the span of ``A·ζ``):
    against the equation integrated finely, on slow moves, a sine and jumps of several loop
    widths a sample, and against the same path sampled ten times finer."""
    scale = 8.0 ** (1 - exponent)  # loop widths comparable across exponents
    model = BoucWen(0.0, 1.0, 0.3 * scale, asymmetry * 0.3 * scale, exponent)
    rng = RNG(0)
    u = np.concatenate((np.cumsum(rng.normal(0, 0.3, 600)), 20 * np.sin(np.linspace(0, 30, 400)),
                        np.repeat(rng.uniform(-30, 30, 20), 10)))
    y = model.simulate(u)[0]
    span = np.ptp(y)
    assert np.max(np.abs(y - _bouc_wen_integrated(model, u))) <= tolerance * span
    fine = np.interp(np.arange(10 * (len(u) - 1) + 1) / 10, np.arange(len(u)), u)
    assert np.max(np.abs(model.simulate(fine)[0][::10] - y)) <= tolerance * span


@pytest.mark.parametrize("exponent", [1.2, 2.5, 4.0])
def test_bouc_wen_stays_within_its_bound_on_any_jump(exponent):
    model = BoucWen(0.0, 1.0, 1.0, 0.0, exponent)  # the bound is 1
    for jump in (0.5, 50.0, 1000.0, -1000.0):
        zeta = model.step(model.initial_state(0.0), jump)[0][1]
        assert abs(zeta) <= 1.0 and (abs(jump) < 10 or abs(zeta) > 1 - 1e-9), (jump, zeta)


@pytest.mark.parametrize("exponent", [1.0, 1.2, 4.0])
def test_bouc_wen_inverse_reaches_targets_near_a_saturated_loop(exponent):
    """The textbook form without a reversible slope (``k = 0``): targets up to 1e-4 of the
    loop's reach from its asymptote, from states all over the loop."""
    model = BoucWen(0.0, 1.0, 1.0, 0.5, exponent)
    bound = 1.5 ** (-1 / exponent)
    rng, state = RNG(4), model.initial_state(0.0)
    for _ in range(60):
        state, _ = model.step(state, float(rng.normal(0, 3 * bound)))
        target = float(np.sign(rng.normal()) * bound * (1 - 10 ** -rng.uniform(0.5, 4)))
        _, u = model.inverse_step(state, target)
        assert model.step(state, u)[1] == pytest.approx(target, abs=1e-9 * bound)
