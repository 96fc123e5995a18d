"""Maxwell-slip model: exact step, play-operator identity, inverse, smooth step, derivatives."""

import numpy as np
import pytest

from hystmpc.models.maxwell_slip import MaxwellSlip, play_operator


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


def test_inverse_rejects_unreachable_target(table1):
    with pytest.raises(ValueError, match="outside the reachable range"):
        table1.inverse_step(table1.initial_state(), table1.saturation)


@pytest.mark.parametrize("kwargs, match", [
    ({"k": (1.0,), "w": (1.0, 2.0)}, "differ in length"),
    ({"k": (), "w": ()}, "at least one element"),
    ({"k": (-1.0,), "w": (1.0,)}, "k must be finite and > 0"),
    ({"k": (1.0,), "w": (float("nan"),)}, "w must be finite and > 0"),
])
def test_parameter_validation(kwargs, match):
    with pytest.raises(ValueError, match=match):
        MaxwellSlip(**kwargs)


def test_smoothing_error_report_is_within_bound(table1, reversing_input):
    from hystmpc.experiments.analysis import smoothing_error
    eps, window = 1e-3, 20
    report = smoothing_error(table1, reversing_input, eps, window)
    assert 0 < report["max_in_window"] <= window * table1.n_elements * eps / 2
    assert report["rms_in_window"] <= report["max_in_window"]
