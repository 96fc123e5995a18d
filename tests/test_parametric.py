"""Lambert W for CasADi, parametric hysteresis operator H / IH, Proposition 3.7, identification."""

import casadi as ca
import numpy as np
import pytest
from conftest import numpy_uses_the_c_library
from scipy.special import lambertw as scipy_lambertw

from hystmpc.models.lambertw import INV_E, lambertw, lambertw_function
from hystmpc.models.parametric import ParametricHysteresis, identify_major_loop, major_loop

EPS = np.finfo(float).eps
E_CORE = ParametricHysteresis(p1=0.0071, p2=0.0014 / 1.5e-3)  # katalenic2013 Table 2 at g = 1.5 mm


def _grid():
    return np.concatenate((-INV_E + np.logspace(-9, np.log10(INV_E), 400), np.linspace(-0.3, 10, 400),
                           np.logspace(1, 6, 400), [0.0]))


def test_lambertw_matches_scipy_within_conditioning():
    """Relative 1e-12, widened only by the conditioning κ = 1/|1+W| near the branch point
    (κ = 1.4e4 at −1/e + 1e-9: rounding x alone costs ε·κ = 3e-12 there, for any method)."""
    x = _grid()
    ref = scipy_lambertw(x).real
    fun = lambertw_function()
    w = np.array([float(fun(v)) for v in x])
    kappa = 1.0 / np.abs(1.0 + ref)
    rel = np.abs(w - ref) / np.maximum(np.abs(ref), 1e-300)
    assert np.all(rel <= 1e-12 + 2 * EPS * kappa)
    far = x > -INV_E + 1e-3
    assert np.max(rel[far]) <= 1e-12
    rel_numpy = np.abs(lambertw(x) - ref) / np.maximum(np.abs(ref), 1e-300)  # NumPy twin, same bound
    assert np.all(rel_numpy <= 1e-12 + 2 * EPS * kappa)


def test_lambertw_derivative_matches_closed_form():
    """W'(x) = W/(x(1+W)); its own conditioning grows like κ², hence the bound."""
    x = _grid()
    x = x[x != 0.0]
    ref = scipy_lambertw(x).real
    exact = ref / (x * (1.0 + ref))
    sym = ca.SX.sym("x")
    dfun = ca.Function("lambertw_derivative", [sym], [ca.jacobian(lambertw_function()(sym), sym)])
    d = np.array([float(dfun(v)) for v in x])
    kappa = 1.0 / np.abs(1.0 + ref)
    rel = np.abs(d - exact) / np.abs(exact)
    assert np.all(rel <= 1e-12 + 4 * EPS * kappa**2)
    assert np.max(rel[x > -INV_E + 1e-3]) <= 1e-12


def test_lambertw_of_one_float_is_the_array_algorithm():
    """The ``math`` path a simulation takes per sample does the array path's operations: equal
    to 2 ulp where NumPy and ``math`` share the C library's exp and log. Where NumPy has its
    own (AVX-512), their last-bit differences reach W multiplied by its condition number
    ``κ = 1 / |1 + W|``: within ``2 eps (1 + κ)`` of it, relative.
    The branch point, where Halley divides by zero, falls back to the array rules."""
    x = np.concatenate((_grid(), np.random.default_rng(5).uniform(-INV_E, 50.0, 20000), [-INV_E, -0.25, 20.0]))
    whole = lambertw(x)
    one_by_one = np.array([lambertw(float(v)) for v in x])
    assert all(isinstance(lambertw(float(v)), float) for v in x[:5])
    finite = np.isfinite(whole)
    np.testing.assert_array_equal(np.isfinite(one_by_one), finite)
    one_by_one, whole = one_by_one[finite], whole[finite]
    if numpy_uses_the_c_library("exp") and numpy_uses_the_c_library("log"):
        np.testing.assert_array_max_ulp(one_by_one, whole, maxulp=2)
        return
    condition = 1.0 / np.abs(1.0 + whole)
    nonzero = whole != 0
    np.testing.assert_array_equal(one_by_one[~nonzero], 0.0)
    relative = np.abs(one_by_one - whole)[nonzero] / np.abs(whole[nonzero])
    assert np.all(relative <= 2 * EPS * (1.0 + condition[nonzero]))


def test_operator_steps_of_floats_match_array_evaluation():
    """``step``/``inverse_step`` on floats (the plant's per-sample path) agree with ``direct`` and
    ``inverse`` evaluated on arrays of the same memories, and keep IH[H] = identity."""
    state = E_CORE.initial_state(0.0)
    inputs = 5.0 * np.sin(np.linspace(0.0, 9.0, 800)) + np.linspace(0.0, 2.0, 800)
    memories, outputs = [], []
    for u in inputs:
        state, v = E_CORE.step(state, u)
        assert isinstance(v, float)
        memories.append(state[1:4])
        outputs.append(v)
    s, u0, v0 = np.array(memories).T
    np.testing.assert_array_max_ulp(np.array(outputs), E_CORE.direct(inputs, s, u0, v0), maxulp=4)
    state = E_CORE.initial_state(0.0)
    for v in outputs[:300]:
        state, u = E_CORE.inverse_step(state, v)
        assert state[4] == pytest.approx(v, abs=1e-12)


def test_lambertw_rejects_out_of_domain():
    with pytest.raises(ValueError, match="x >= -1/e"):
        lambertw(-0.5)


def _reversing_targets(seed=3, n=3000):
    rng = np.random.default_rng(seed)
    return np.abs(np.cumsum(rng.normal(0.0, 0.3, n))) + 0.1


def test_operators_approach_the_asymptotes():
    up = np.linspace(0.0, 30.0, 3001)
    v_up, state = E_CORE.simulate(up)
    down = np.linspace(30.0, 0.0, 3001)
    v_down, _ = E_CORE.simulate(down, state)
    assert v_up[-1] == pytest.approx(up[-1] - E_CORE.p1, abs=1e-9)  # H: v → u − p1 rising
    assert v_down[-1] == pytest.approx(down[-1] + E_CORE.p1, abs=1e-9)  # and u + p1 falling
    assert np.all(np.abs(v_up - up) <= E_CORE.p1 + 1e-12)
    i_up = [E_CORE.inverse(u, 1.0, 0.0, 0.0) for u in up]
    assert i_up[-1] == pytest.approx(up[-1] + E_CORE.p1, abs=1e-9)  # IH: the mirror asymptote


def test_proposition_3_7_scaling_of_the_hysteretic_part():
    """Eq. (8): a·M_{p1,p2}[b·u] − M_{a·p1, b·p2}[u] → 0 under persistent excitation."""
    rng = np.random.default_rng(8)
    u = np.cumsum(rng.choice([-1.0, 1.0], 4000) * rng.uniform(0.05, 0.5, 4000))
    a, b = 2.5, 0.7
    base = ParametricHysteresis(0.3, 1.5)
    scaled = ParametricHysteresis(a * 0.3, b * 1.5)
    lhs = a * base.hysteretic_part(b * u, v0_star=0.1)
    rhs = scaled.hysteretic_part(u, v0_star=-0.2)  # different initial memory
    diff = np.abs(lhs - rhs)
    assert diff[0] > 0.1
    assert diff[-100:].max() < 1e-12
    same = scaled.hysteretic_part(u, v0_star=a * 0.1)  # consistent memory: equal throughout
    assert np.max(np.abs(lhs - same)) < 1e-12


def _major_loop_data(p1, p2, gaps, n=801, i_max=7.0):
    current = np.concatenate((np.linspace(0, i_max, n // 2 + 1), np.linspace(i_max, 0, n // 2 + 1)[1:]))
    loops = {}
    for g in gaps:
        x = major_loop(ParametricHysteresis(p1, p2 / g), current)
        loops[g] = (current, 9.67 * (1.5e-3 / g) ** 2 * x**2 * (1 - 0.02 * x))  # a monotone static map
    return loops


def test_identification_recovers_known_parameters_from_noise_free_data():
    loops = _major_loop_data(0.0071, 0.0014, [1.2e-3, 1.5e-3, 1.75e-3])
    p1, p2, luts = identify_major_loop(loops)
    assert p1 == pytest.approx(0.0071, rel=2e-3)
    assert p2 == pytest.approx(0.0014, rel=2e-3)
    f_tab, x_tab = luts[1.5e-3]
    assert np.all(np.diff(f_tab) >= 0) and len(f_tab) == len(x_tab)


@pytest.mark.parametrize("kwargs, match", [({"p1": 0.0, "p2": 1.0}, "p1 must be"),
                                           ({"p1": 1.0, "p2": float("nan")}, "p2 must be")])
def test_parameter_validation(kwargs, match):
    with pytest.raises(ValueError, match=match):
        ParametricHysteresis(**kwargs)
