"""Maxwell-slip model: exact step, play-operator identity, inverse, smooth step, derivatives."""

import numpy as np
import pytest

from models.maxwell_slip import MaxwellSlip, play_operator


def test_exact_step_matches_hand_derived_sequence():
    # element 1: k=2, w=1; element 2: k=1, w=0.2; start relaxed at u=0.
    # u:        0.3       0.8       0.5        -0.5       0.0
    # F1: 0.6 -> 1.0 (clip 1.6) -> 0.4 -> -1.0 (clip -1.6) -> 0.0
    # F2: 0.2 (clip 0.3) -> 0.2 -> -0.1 -> -0.2 (clip -1.1) -> 0.2 (clip 0.3)
    model = MaxwellSlip(k=(2.0, 1.0), w=(1.0, 0.2))
    outputs, state = model.simulate([0.0, 0.3, 0.8, 0.5, -0.5, 0.0])
    np.testing.assert_allclose(outputs, [0.0, 0.8, 1.2, 0.3, -1.2, 0.2], atol=1e-15)
    np.testing.assert_allclose(state, [0.0, 0.0, 0.2], atol=1e-15)


def test_equals_sum_of_play_operators(table1, reversing_input):
    u = reversing_input
    y, _ = table1.simulate(u)
    plays = sum(k * (u - play_operator(u, w / k)) for k, w in zip(table1.k, table1.w, strict=True))
    assert np.max(np.abs(y - plays)) <= 1e-12


def test_output_bounded_by_saturation(table1, reversing_input):
    y, _ = table1.simulate(10 * reversing_input)
    assert np.max(np.abs(y)) <= table1.saturation + 1e-15
    assert np.max(np.abs(y)) > 0.99 * table1.saturation  # large swings do saturate


def test_inverse_reaches_targets_exactly(table1):
    rng = np.random.default_rng(3)
    state = table1.initial_state(0.0)
    for target in rng.uniform(-0.99, 0.99, 200) * table1.saturation:
        state, u = table1.inverse_step(state, target)
        assert state[0] == u
        assert table1.output(state) == pytest.approx(target, abs=1e-12)


def test_inverse_rejects_unreachable_target(table1):
    with pytest.raises(ValueError, match="outside the reachable range"):
        table1.inverse_step(table1.initial_state(), table1.saturation)


@pytest.mark.parametrize("eps", [1e-2, 1e-3, 1e-4])
def test_smooth_step_within_stated_bound(table1, reversing_input, eps):
    smooth = table1.smooth_step(eps)
    exact_state = table1.initial_state(0.0)
    smooth_state = exact_state.copy()
    worst = 0.0
    for n, u in enumerate(reversing_input[1:], start=1):
        exact_state, y_exact = table1.step(exact_state, u)
        smooth_state, y_smooth = smooth(smooth_state, u)
        smooth_state = np.asarray(smooth_state).ravel()
        worst = max(worst, abs(float(y_smooth) - y_exact))
        assert abs(float(y_smooth) - y_exact) <= n * table1.n_elements * eps / 2
    assert worst > 0  # the comparison is not vacuous


def test_smooth_step_converges_linearly_in_eps(table1, reversing_input):
    def max_error(eps):
        smooth = table1.smooth_step(eps)
        s_exact = s_smooth = table1.initial_state(0.0)
        worst = 0.0
        for u in reversing_input[1:]:
            s_exact, y_exact = table1.step(s_exact, u)
            s_smooth, y_smooth = smooth(s_smooth, u)
            s_smooth = np.asarray(s_smooth).ravel()
            worst = max(worst, abs(float(y_smooth) - y_exact))
        return worst
    errors = [max_error(eps) for eps in (1e-2, 1e-3, 1e-4)]
    assert errors[0] > errors[1] > errors[2]
    assert errors[2] < 0.2 * errors[1]  # at least first order in eps


def test_smooth_step_derivatives_match_finite_differences(table1):
    import casadi as ca
    smooth = table1.smooth_step(1e-2)
    x = ca.SX.sym("x", table1.n_state)
    u = ca.SX.sym("u")
    x_next, y = smooth(x, u)
    jac = ca.Function("smooth_jacobian", [x, u], [ca.jacobian(ca.vertcat(x_next, y), ca.vertcat(x, u))])
    rng = np.random.default_rng(11)
    for _ in range(20):
        state = np.concatenate(([rng.normal(0, 5)], rng.uniform(-1, 1, 4) * np.asarray(table1.w)))
        uu = state[0] + rng.normal(0, 3)
        point = np.concatenate((state, [uu]))
        analytic = np.asarray(jac(state, uu))
        h = 1e-6
        numeric = np.empty_like(analytic)
        for j in range(len(point)):
            plus, minus = point.copy(), point.copy()
            plus[j] += h
            minus[j] -= h
            fp = np.concatenate([np.asarray(v).ravel() for v in smooth(plus[:-1], plus[-1])])
            fm = np.concatenate([np.asarray(v).ravel() for v in smooth(minus[:-1], minus[-1])])
            numeric[:, j] = (fp - fm) / (2 * h)
        np.testing.assert_allclose(analytic, numeric, atol=1e-6)


@pytest.mark.parametrize("kwargs, match", [
    ({"k": (1.0,), "w": (1.0, 2.0)}, "differ in length"),
    ({"k": (), "w": ()}, "at least one element"),
    ({"k": (-1.0,), "w": (1.0,)}, "k must be finite and > 0"),
    ({"k": (1.0,), "w": (float("nan"),)}, "w must be finite and > 0"),
])
def test_parameter_validation(kwargs, match):
    with pytest.raises(ValueError, match=match):
        MaxwellSlip(**kwargs)


def test_smooth_step_rejects_nonpositive_eps(table1):
    with pytest.raises(ValueError, match="eps must be > 0"):
        table1.smooth_step(0.0)


def test_smoothing_error_report_is_within_bound(table1, reversing_input):
    from experiments.analysis import smoothing_error
    eps, window = 1e-3, 20
    report = smoothing_error(table1, reversing_input, eps, window)
    assert 0 < report["max_in_window"] <= window * table1.n_elements * eps / 2
    assert report["rms_in_window"] <= report["max_in_window"]
