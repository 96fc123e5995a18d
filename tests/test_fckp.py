"""FCKP (wang2025): KP kernel (Fig. 2), Grünwald–Letnikov, creep and its inverse, smoothing, derivatives."""

import numpy as np
import pytest
from scipy.special import gamma

from hystmpc.models.fckp import Fckp, FckpParams
from hystmpc.models.fractional import GrunwaldLetnikov, gl_apply, gl_weights
from hystmpc.models.kp import KrasnoselskiiPokrovskii, threshold_grid


def _fig2_kernel() -> KrasnoselskiiPokrovskii:
    return KrasnoselskiiPokrovskii([-0.5], [0.5], [1.0], 0.01)


def test_kp_kernel_of_fig2_switches_at_its_thresholds():
    """ρ1 = −0.5, ρ2 = 0.5, δ = 0.01: up over [0.5, 0.51], down over [−0.5, −0.49]."""
    kp = _fig2_kernel()
    state = kp.initial_state(-1.0)
    up = np.linspace(-1, 1, 2001)
    out_up = []
    for u in up:
        state, y = kp.step(state, u)
        out_up.append(y)
    out_up = np.array(out_up)
    assert np.all(out_up[up <= 0.5] == -1.0)
    assert np.all(out_up[up >= 0.51] == 1.0)
    assert out_up[np.argmin(np.abs(up - 0.505))] == pytest.approx(0.0, abs=1e-9)
    out_down = []
    for u in up[::-1]:
        state, y = kp.step(state, u)
        out_down.append(y)
    out_down, down = np.array(out_down), up[::-1]
    assert np.all(out_down[down >= -0.49] == 1.0)  # stays up until the lower threshold
    assert np.all(out_down[down <= -0.5] == -1.0)
    rng = np.random.default_rng(3)
    for u in np.cumsum(rng.normal(0, 0.2, 2000)):
        state, y = kp.step(state, u)
        assert -1.0 <= y <= 1.0


def test_kp_model_output_is_bounded_and_has_memory():
    model = Fckp()
    kp = model.kp
    state = kp.initial_state(-1.0)
    _, y_up = kp.step(kp.step(state, 0.0)[0], 0.0)
    after_peak = kp.step(kp.step(state, 0.9)[0], 0.0)[1]
    assert after_peak > y_up  # same input, different history
    assert abs(after_peak) <= kp.total_weight


def _search_inverse_by_steps(kp, state, y_target, step=0.01, weights=None):
    """The implicit inverse written on whole ``step`` calls (the search of Section 3.2)."""
    u_last = float(np.clip(state[0], -1.0, 1.0))
    sign = 1.0 if y_target > kp.step(state, u_last, weights)[1] else -1.0
    reached = (lambda y: y >= y_target) if sign > 0 else (lambda y: y <= y_target)
    lo = u = u_last
    while True:
        u = float(np.clip(u + sign * step, -1.0, 1.0))
        if reached(kp.step(state, u, weights)[1]):
            break
        lo = u
        if u == (1.0 if sign > 0 else -1.0):
            return u
    hi = u
    for _ in range(30):
        mid = 0.5 * (lo + hi)
        hi, lo = (mid, lo) if reached(kp.step(state, mid, weights)[1]) else (hi, mid)
    return hi


def test_kp_inverse_is_the_search_on_whole_steps_to_the_bit():
    """inverse_step evaluates trial inputs without building states: the same input to the bit,
    with the model's density and with a replaced one, beyond the range included."""
    kp = Fckp().kp
    rng = np.random.default_rng(6)
    state = kp.initial_state(-1.0)
    other = kp.weights * rng.uniform(0.5, 1.5, len(kp.weights))
    for _ in range(200):
        target = float(rng.uniform(-1.1, 1.1) * kp.total_weight)
        weights = other if rng.uniform() < 0.3 else None
        new_state, u = kp.inverse_step(state, target, weights=weights)
        assert u == _search_inverse_by_steps(kp, state, target, weights=weights)
        assert np.array_equal(new_state, kp.step(state, u)[0])
        state = new_state


def test_threshold_grid_respects_span_and_slope():
    r1, r2 = threshold_grid(12, 0.15, 2)
    assert len(r1) == 11 + 10
    assert np.all(r2 >= r1 + 0.15) and np.all(r1 < r2)
    with pytest.raises(ValueError, match="delta"):
        threshold_grid(5, 3.0)


def test_gl_weights_partial_sums_are_the_weights_of_order_minus_one():
    """Σ_{j<=n} w_j^(α) = w_n^(α−1), for orders of both signs."""
    for order in (-0.7, -0.02, 0.02, 0.5, 1.3):
        w = gl_weights(order, 200)
        assert np.cumsum(w) == pytest.approx(gl_weights(order - 1, 200), rel=1e-12, abs=1e-14)


@pytest.mark.parametrize("order", [-0.5, -0.02, 0.3, 0.7])
@pytest.mark.parametrize("k", [1.0, 2.0])
def test_gl_against_closed_form_with_first_order_convergence(order, k):
    """D^q t^k = Γ(k+1)/Γ(k+1−q) t^(k−q); the GL error at t = 1 halves with h."""
    exact = gamma(k + 1) / gamma(k + 1 - order)
    errors = []
    for n in (200, 400, 800, 1600):
        h = 1.0 / n
        t = h * np.arange(n + 1)
        errors.append(abs(gl_apply(order, h, t**k)[-1] - exact))
    ratios = np.array(errors[:-1]) / np.array(errors[1:])
    assert errors[-1] < 5e-3 * max(1.0, exact)
    assert np.all((ratios > 1.8) & (ratios < 2.2)), ratios


def test_constant_input_rises_like_t_to_the_creep_order():
    """D^(−α) 1 = t^α / Γ(1+α): a slow rise for α = 0.02 (benches.md)."""
    alpha, h = 0.02, 0.01
    t = h * np.arange(1, 4001)
    creep = GrunwaldLetnikov(-alpha, h)
    out = np.array([creep.push(1.0) for _ in t])
    assert np.all(np.diff(out) > 0)
    # sample k sits at (k+1) h; the first-order discretisation error decays like h/t
    exact = t**alpha / gamma(1 + alpha)
    assert out == pytest.approx(exact, rel=1.5e-2)
    assert out[10:] == pytest.approx(exact[10:], rel=2e-3)


def test_streaming_gl_matches_the_batch_sum_and_the_window():
    rng = np.random.default_rng(0)
    f = rng.normal(size=600)
    for window in (None, 50):
        op = GrunwaldLetnikov(-0.02, 0.01, window, capacity=16)  # also exercises growing
        stream = np.array([op.push(v) for v in f])
        assert stream == pytest.approx(gl_apply(-0.02, 0.01, f, window), rel=1e-12, abs=1e-12)


def test_history_terms_split_the_sum_exactly():
    """Past part (history_terms) + in-horizon part = the full GL value at each future sample."""
    rng = np.random.default_rng(1)
    past, future = rng.normal(size=300), rng.normal(size=10)
    for window in (None, 40):
        op = GrunwaldLetnikov(-0.02, 0.01, window)
        for v in past:
            op.push(v)
        hist = op.history_terms(len(future))
        w = gl_weights(-0.02, len(future))
        full = gl_apply(-0.02, 0.01, np.concatenate((past, future)), window)[len(past):]
        split = [0.01**0.02 * sum(w[j] * future[i - j] for j in range(i + 1)) + hist[i] for i in range(len(future))]
        assert split == pytest.approx(full, rel=1e-12, abs=1e-12)


def test_creep_inverse_undoes_the_creep():
    """D^(+α) ∘ D^(−α) = identity for the same h and full memory (the weights convolve to 1)."""
    rng = np.random.default_rng(2)
    w = 2.0 + np.cumsum(rng.normal(0, 0.05, 3000))
    model = Fckp()
    creep, inverse = model.creep(), model.creep_inverse()
    back = np.array([inverse.push(creep.push(v)) for v in w])
    assert np.max(np.abs(back - w)) < 1e-9


def test_bad_parameters_are_rejected():
    with pytest.raises(ValueError, match="creep_order"):
        FckpParams(creep_order=1.5)
    with pytest.raises(ValueError, match="rho2 >= rho1 \\+ delta"):
        KrasnoselskiiPokrovskii([0.0], [0.005], [1.0], 0.01)
    with pytest.raises(ValueError, match="finite"):
        Fckp().kp.step(Fckp().initial_state(), float("nan"))


def test_kp_inverse_refuses_a_search_it_cannot_end():
    kp = Fckp().kp
    state = kp.initial_state(-1.0)
    for kwargs in ({"step": float("nan")}, {"step": 0.0}, {"u_min": float("nan")}, {"u_max": float("inf")}):
        with pytest.raises(ValueError, match="must be finite"):
            kp.inverse_step(state, 0.5 * kp.total_weight, **kwargs)
