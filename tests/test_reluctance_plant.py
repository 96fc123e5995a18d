"""Reluctance actuator plant (katalenic2013 Table 1) and identification from its major loops."""

from dataclasses import replace

import numpy as np
import pytest
from conftest import numpy_uses_the_c_library

from hystmpc.models.parametric import identify_major_loop
from hystmpc.plants.reluctance import C_CORE, ReluctanceActuator, ReluctanceParams, major_loop_measurement, static_force

GAPS = [1.2e-3, 1.3e-3, 1.5e-3, 1.7e-3, 1.75e-3]


def test_first_principles_force_levels():
    """E-core: 400 N needs about 7 A at 1.5 mm (F ≈ μ0 A N² i² / (2g)²); smaller gaps need less."""
    e_core = ReluctanceParams()
    grid = np.linspace(0, 20, 20001)
    i_400 = {g: np.interp(400.0, static_force(e_core, grid, g), grid) for g in GAPS}
    assert 6.0 < i_400[1.5e-3] < 8.0
    assert all(i_400[a] < i_400[b] for a, b in zip(GAPS, GAPS[1:], strict=False))
    lin = 4e-7 * np.pi * e_core.area * e_core.turns**2 * 7.0**2 / (2 * 1.5e-3) ** 2
    assert 0.85 * lin < static_force(e_core, 7.0, 1.5e-3) < lin  # saturation and leakage only reduce it


def test_amplifier_slew_limit_and_hysteresis_width():
    p = replace(ReluctanceParams(), force_noise=0.0)
    plant = ReluctanceActuator(p, 1.5e-3)
    plant.reset(0)
    meas = plant.step(5.0)
    assert meas.sensors["current"] == pytest.approx(p.slew_limit * p.sample_period)  # 0.2 A per sample
    up = [ReluctanceActuator(p, 1.5e-3) for _ in range(1)][0]
    up.reset(0)
    for i in np.linspace(0, 6, 3000):
        f_up = up.step(i).truth["force"]
    for i in np.linspace(6, 0, 3000):
        m = up.step(i)
        if m.sensors["current"] <= 4.0:
            break
    rising = ReluctanceActuator(p, 1.5e-3)
    rising.reset(0)
    for i in np.linspace(0, 4.0, 3000):
        f_rise = rising.step(i).truth["force"]
    assert f_up > 0
    assert m.truth["force"] - f_rise > 0.3  # descending branch above ascending: about 2·p1·dF/di


@pytest.mark.parametrize("core, force_max", [pytest.param(ReluctanceParams(), 400.0, marks=pytest.mark.slow),
                                             (C_CORE, 240.0)])
def test_identification_from_noisy_measurements_recovers_the_plant(core, force_max):
    """Section 3.5 on simulated noisy major loops (σ = 0.05 N) at five air gaps."""
    loops = {g: major_loop_measurement(core, g, force_max, seed=k) for k, g in enumerate(GAPS)}
    p1, p2, luts = identify_major_loop(loops)
    assert p1 == pytest.approx(core.p1, rel=0.10)
    assert p2 == pytest.approx(core.p2, rel=0.10)
    assert set(luts) == set(GAPS)


def test_plant_rejects_bad_input():
    with pytest.raises(ValueError, match="gap must be"):
        ReluctanceActuator(ReluctanceParams(), 5e-3)
    with pytest.raises(ValueError, match="finite"):
        ReluctanceActuator().step(float("nan"))


def test_force_and_polynomial_features_of_one_float_match_arrays():
    """The per-sample float paths (plant force, polynomial inverse) agree with the array paths
    to 2 ulp where NumPy and ``math`` share the C library's pow (bit-identical there). Where
    NumPy has its own (AVX-512), an ulp apart, the force's two powers and the products after
    them carry the difference to at most 8 ulp."""
    from hystmpc.models.reluctance import poly_features
    ulps = 2 if numpy_uses_the_c_library("power") else 8
    currents = np.random.default_rng(2).uniform(-25.0, 25.0, 3000)
    for params, gap in ((ReluctanceParams(), 1.2e-3), (C_CORE, 1.75e-3)):
        one_by_one = np.array([static_force(params, float(i), gap) for i in currents])
        np.testing.assert_array_max_ulp(one_by_one, static_force(params, currents, gap), maxulp=ulps)
    forces = np.concatenate(([0.0, -3.0], np.random.default_rng(3).uniform(0.0, 450.0, 3000)))
    one_by_one = np.array([poly_features(float(f), 1.5e-3) for f in forces])
    np.testing.assert_array_max_ulp(one_by_one, poly_features(forces, 1.5e-3), maxulp=ulps)


def test_interp_of_one_float_is_numpys():
    """Pure IEEE arithmetic on the same operands: equal to np.interp to the bit, ends, table
    points and NaN included."""
    from hystmpc.models.reluctance import interp_float
    rng = np.random.default_rng(4)
    xp = np.cumsum(rng.uniform(0.01, 1.0, 60))
    fp = np.sin(xp) * 100.0
    x = np.concatenate((rng.uniform(xp[0] - 1.0, xp[-1] + 1.0, 20000), xp, [np.nan, xp[0], xp[-1]]))
    one_by_one = np.array([interp_float(float(v), xp.tolist(), fp.tolist()) for v in x])
    np.testing.assert_array_equal(one_by_one, np.interp(x, xp, fp))
