"""Power-function hysteresis (zhou2024): Table V points, continuity, inverse, smoothing, derivatives."""

import casadi as ca
import numpy as np
import pytest

from hystmpc.models.power_function import (
    ASCENDING_POINTS,
    DESCENDING_POINTS,
    TABLE_V,
    PowerFunctionHysteresis,
    VirtualDeformation,
)

T = np.arange(0.0, 20.0, 0.01)


@pytest.fixture
def model() -> PowerFunctionHysteresis:
    return PowerFunctionHysteresis()


def _sweep(a, b, n=4001):
    return np.linspace(a, b, n)


def test_polylines_pass_through_table_v(model):
    for name in ASCENDING_POINTS:
        s, tau = TABLE_V[name]
        assert model.tau_ascending(s) == pytest.approx(tau, abs=1e-9)
    for name in DESCENDING_POINTS:
        s, tau = TABLE_V[name]
        assert model.tau_descending(s) == pytest.approx(tau, abs=1e-9)


def test_major_loop_reproduces_table_v_points_beyond_the_transitions(model):
    """Drive s R → E → R → E through every Table V abscissa; where the model is on a
    polyline (past the transition after each reversal), τ equals Table V to 1e-9."""
    s_r, s_e = TABLE_V["R"][0], TABLE_V["E"][0]
    knots = sorted({p[0] for p in TABLE_V.values()})
    up = np.unique(np.concatenate((_sweep(s_r, s_e), [k for k in knots if s_r <= k <= s_e])))
    path = np.concatenate((up, up[::-1][1:], up[1:]))
    state = model.initial_state(s_r)
    checked = 0
    for i, s in enumerate(path[1:], start=1):
        state, tau = model.step(state, s)
        on_line = s >= state[2] if state[1] > 0.5 else s <= state[3]
        if i > len(up) and on_line:  # after the first reversal at E
            names = ASCENDING_POINTS if state[1] > 0.5 else DESCENDING_POINTS
            for name in names:
                if TABLE_V[name][0] == s:
                    assert tau == pytest.approx(TABLE_V[name][1], abs=1e-9)
                    checked += 1
    assert checked >= 20  # most points are met on a polyline, not inside a transition


@pytest.mark.parametrize("seed", [0, 1, 2])
def test_no_jump_where_a_transition_meets_a_polyline(model, seed):
    """Major loop and random minor loops: at s01 (s02) the transition equals the polyline."""
    rng = np.random.default_rng(seed)
    turning = np.concatenate(([TABLE_V["R"][0], TABLE_V["E"][0]], rng.uniform(-0.045, 0.045, 30)))
    state = model.initial_state(0.0)
    met = 0
    for target in turning:
        path = np.linspace(state[0], target, 400)[1:]
        for s in path:
            prev = state
            state, tau = model.step(state, s)
            up = state[1] > 0.5
            edge = state[2] if up else state[3]
            crossed = (prev[0] < edge <= s) if up else (s <= edge < prev[0])
            if crossed:
                _, at_edge = model.step(prev, edge)
                line = model.tau_ascending(edge) if up else model.tau_descending(edge)
                assert abs(at_edge - line) <= 1e-9
                met += 1
    assert met >= 10


def test_output_has_no_jumps_anywhere(model):
    """Also at reversals inside a transition (our continuous variant of eqs. (12)–(13))."""
    rng = np.random.default_rng(5)
    s = np.cumsum(rng.normal(0, 2e-5, 20000))
    s = np.clip(s, -0.045, 0.045)
    tau, _ = model.simulate(s)
    slope_bound = 5e3  # N m per unit s: steeper than any polyline or transition here
    assert np.max(np.abs(np.diff(tau)) - slope_bound * np.abs(np.diff(s))) <= 1e-9


def test_smooth_model_is_total():
    """Nonsense states (s02 above s01, up outside [0, 1]) must not give NaN inside an NLP."""
    smooth = PowerFunctionHysteresis().smooth_step(1e-4)
    z = ca.SX.sym("z", 7)
    nxt, tau = smooth(z[:6], z[6])
    jac = ca.Function("pf_jacobian_total", [z], [ca.jacobian(ca.vertcat(nxt, tau), z)])
    rng = np.random.default_rng(9)
    for _ in range(200):
        point = rng.normal(0, 1, 7) * np.array([0.05, 2, 0.05, 0.05, 3, 3, 0.05])
        assert np.all(np.isfinite(np.asarray(smooth(point[:6], point[6])[1])))
        assert np.all(np.isfinite(np.asarray(jac(point))))


def test_virtual_deformation_maps_table_i_range_onto_table_v():
    vd = VirtualDeformation()
    assert vd.s(0.5) == pytest.approx(0.046, abs=5e-5)
    assert vd.s(-0.5) == pytest.approx(-vd.s(0.5))
    theta = np.linspace(-0.5, 0.5, 101)
    np.testing.assert_allclose(vd.theta(vd.s(theta)), theta, atol=1e-12)


@pytest.mark.parametrize("kwargs, match", [
    ({"ascending": ((0.0, 0.0),)}, "at least two"),
    ({"ascending": ((0.0, 0.0), (0.01, -0.1))}, "increase strictly"),
    ({"torque_scale": 0.0}, "torque_scale must be > 0"),
])
def test_parameter_validation(kwargs, match):
    with pytest.raises(ValueError, match=match):
        PowerFunctionHysteresis(**kwargs)


def test_inverse_rejects_nan(model):
    with pytest.raises(ValueError, match="finite"):
        model.inverse_step(model.initial_state(), float("nan"))
