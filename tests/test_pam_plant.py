"""PAM joint plant and nominal physics: Fig. 3 ranges, equilibrium, sensors, seeds, errors."""

from dataclasses import replace

import numpy as np
import pytest

from hystmpc.experiments.benches.pam import NOMINAL, PLANT
from hystmpc.plants.pam_joint import PamJoint, PamJointParams, constraint_pressure


def test_constraint_pressure_matches_fig3_ranges():
    # vo2012 Fig. 3: about ±5 bar over ±40° at 1 kg; heavier loads cover less angle.
    assert 4.0 <= constraint_pressure(NOMINAL, 40.0) <= 5.5
    assert constraint_pressure(NOMINAL, -40.0) == pytest.approx(-constraint_pressure(NOMINAL, 40.0))
    heavy = replace(NOMINAL, payload_kg=4.5)
    angles = np.linspace(0, 40, 401)
    reach_light = angles[constraint_pressure(NOMINAL, angles) <= 5.0].max()
    reach_heavy = angles[constraint_pressure(heavy, angles) <= 5.0].max()
    assert reach_heavy < 0.8 * reach_light


def test_constant_pressure_settles_near_static_equilibrium():
    plant = PamJoint(replace(NOMINAL, pressure_noise_bar=0.0))
    plant.reset(0)
    for _ in range(400):
        meas = plant.step(2.0)
    # at rest: a(θ)(Δp − Δp_hys) + b(θ) = m g L sin θ, i.e. Δp − Δp_hys = Δp_cons(θ)
    theta = meas.truth["angle"]
    assert meas.truth["pressure"] == pytest.approx(2.0, abs=1e-3)
    assert 2.0 - meas.truth["dp_hys"] == pytest.approx(constraint_pressure(NOMINAL, theta), abs=2e-3)


def test_encoder_quantisation_and_seeded_noise():
    a, b, c = (PamJoint(PLANT) for _ in range(3))
    ma, mb, mc = a.reset(5), b.reset(5), c.reset(6)
    for _ in range(50):
        ma, mb, mc = a.step(1.0), b.step(1.0), c.step(1.0)
    quantum = 360.0 / PLANT.encoder_counts
    assert ma.y / quantum == pytest.approx(round(ma.y / quantum), abs=1e-9)
    assert abs(ma.y - ma.truth["angle"]) <= quantum / 2 + 1e-12
    assert ma.sensors == mb.sensors
    assert ma.sensors != mc.sensors


def test_command_is_saturated_and_delayed():
    plant = PamJoint(replace(NOMINAL, pressure_noise_bar=0.0))
    plant.reset(0)
    m1 = plant.step(100.0)
    m2 = plant.step(100.0)
    assert m1.truth["pressure"] == 0.0 and m2.truth["pressure"] == 0.0  # 2-sample delay
    for _ in range(200):
        m = plant.step(100.0)
    assert m.truth["pressure"] == pytest.approx(NOMINAL.dp_limit, abs=1e-3)


@pytest.mark.parametrize("change, match", [
    ({"pressure_delay_s": 0.03}, "multiple of"),
    ({"torque_per_bar": 0.0}, "torque_per_bar must be finite and > 0"),
    ({"damping": -1.0}, "damping must be finite and >= 0"),
    ({"torque_per_bar_drop": 1.0}, "torque_per_bar_drop"),
])
def test_parameter_validation(change, match):
    with pytest.raises(ValueError, match=match):
        PamJointParams(**change)


def test_plant_rejects_nan_input():
    plant = PamJoint(NOMINAL)
    plant.reset(0)
    with pytest.raises(ValueError, match="finite"):
        plant.step(float("nan"))


def test_learned_model_errors_act_like_the_changed_parameters():
    """``estimates`` append relative errors to d: gain e predicts like a0·(1 + e), and the
    pressure-loop errors like ωp·(1 + e) and ζp·(1 + e); all zero is the plain model."""
    from hystmpc.plants.pam_joint import ESTIMATES, inverse_inputs, prediction_model
    plain = prediction_model(NOMINAL, 1e-3)
    learned = prediction_model(NOMINAL, 1e-3, estimates=ESTIMATES)
    assert (plain.nd, learned.nd) == (1, 4)
    rng = np.random.default_rng(3)
    x = np.concatenate(([12.0, 30.0, 1.5, 4.0], rng.uniform(-0.1, 0.1, plain.nx - 4)))
    torque = 0.2
    step = lambda model, d: np.asarray(model.step(x, 2.5, d)).ravel()  # noqa: E731
    np.testing.assert_allclose(step(learned, [torque, 0, 0, 0]), step(plain, [torque]), rtol=0, atol=1e-12)
    for k, changed in enumerate((dict(torque_per_bar=NOMINAL.torque_per_bar * 1.1),
                                 dict(pressure_wn=NOMINAL.pressure_wn * 1.1),
                                 dict(pressure_zeta=NOMINAL.pressure_zeta * 1.1))):
        d = [torque, 0.0, 0.0, 0.0]
        d[1 + k] = 0.1
        expected = step(prediction_model(replace(NOMINAL, **changed), 1e-3), [torque])
        assert not np.allclose(expected, step(plain, [torque]))
        np.testing.assert_allclose(step(learned, d), expected, rtol=1e-12, atol=1e-12)
    refs = np.linspace(0.0, 20.0, 8)
    stronger = replace(NOMINAL, torque_per_bar=NOMINAL.torque_per_bar * 1.1)
    np.testing.assert_allclose(inverse_inputs(NOMINAL, x, [torque, 0.1, 0.0, 0.0], refs, gain=True),
                               inverse_inputs(stronger, x, [torque], refs), rtol=1e-12, atol=1e-12)
    for subset in (("pressure_damping",), ("gain", "pressure_damping"), ("pressure_frequency",)):
        d = [torque] + [0.1] * len(subset)
        changed = {"gain": "torque_per_bar", "pressure_frequency": "pressure_wn", "pressure_damping": "pressure_zeta"}
        truth = replace(NOMINAL, **{changed[n]: getattr(NOMINAL, changed[n]) * 1.1 for n in subset})
        np.testing.assert_allclose(step(prediction_model(NOMINAL, 1e-3, estimates=subset), d),
                                   step(prediction_model(truth, 1e-3), [torque]), rtol=1e-12, atol=1e-12)
    # beyond LEARNED_ERROR_RANGE the model stops at a quarter (or four times) the nominal value
    half = replace(NOMINAL, pressure_zeta=NOMINAL.pressure_zeta * 0.25, torque_per_bar=NOMINAL.torque_per_bar * 0.25)
    np.testing.assert_allclose(step(learned, [torque, -3.0, 0.0, -3.0]), step(prediction_model(half, 1e-3), [torque]),
                               rtol=1e-12, atol=1e-12)
    assert np.all(np.isfinite(inverse_inputs(NOMINAL, x, [torque, -1.0, 0.0, 0.0], refs, gain=True)))
    with pytest.raises(ValueError, match="estimates must be distinct names"):
        prediction_model(NOMINAL, 1e-3, estimates=("pressure_damping", "gain"))
    with pytest.raises(ValueError, match="estimates must be distinct names"):
        prediction_model(NOMINAL, 1e-3, estimates=("stiffness",))


def test_a_joint_started_pressurised_is_not_predicted_to_vent():
    """The rest state's delay line holds the measured pressure: held at its holding pressure,
    the model stays put and the EKF learns no error from the start."""
    from hystmpc.experiments.benches.pam import BENCH
    from hystmpc.plants.pam_joint import prediction_model, rest_state
    theta = 10.0
    hold = constraint_pressure(NOMINAL, theta)
    model = prediction_model(NOMINAL, 1e-3)
    x = rest_state(NOMINAL, [theta, hold])
    for _ in range(20):
        x = np.asarray(model.step(x, hold, [0.0])).ravel()
    assert abs(x[0] - theta) < 1e-3 and abs(x[2] - hold) < 1e-9
    observer = BENCH.build_controller("nmpc", BENCH.configure()).observer
    observer.reset()
    observer.update([theta, hold], None)
    for _ in range(50):
        observer.update([theta, hold], hold)
    assert np.all(np.abs(observer.ekf.d[1:]) < 0.01), observer.ekf.d
