"""Bench reluctance: conditions, identify command, baselines, NMPC (short); calibration (slow)."""

import json

import casadi as ca
import numpy as np
import pytest

from hystmpc.experiments.baselines import Replay
from hystmpc.experiments.benches.reluctance import BENCH
from hystmpc.experiments.benches.reluctance_identification import identified_model, rig
from hystmpc.experiments.cli import main
from hystmpc.experiments.config import apply_overrides
from hystmpc.experiments.runner import reference_samples, simulate
from hystmpc.models.reluctance import offline_optimum


def test_identify_command_writes_the_model(tmp_path, capsys):
    out = tmp_path / "id.json"
    assert main(["identify", "reluctance", "--out", str(out), "--quiet"]) == 0
    doc = json.loads(out.read_text())
    assert doc["schema"] == "hystmpc.identified/1" and doc["core"] == "E"
    assert doc["p1_A"] == pytest.approx(doc["true_p1_A"], rel=0.10)
    assert doc["p2_per_A_m"] == pytest.approx(doc["true_p2_per_A_m"], rel=0.10)
    assert len(doc["tables"]) == 5
    assert main(["identify", "pam"]) == 2
    assert "has no identification step" in capsys.readouterr().err


def test_scenario_fixes_the_air_gap():
    run = BENCH.run(BENCH.scenarios["ramp-1.2mm"], "poly-inverse", BENCH.configure(), duration=0.01)
    assert run.parameters["rig"]["gap_mm"] == 1.2
    run = BENCH.run(BENCH.scenarios["ccore-ramp-1.5mm"], "poly-inverse", BENCH.configure(), duration=0.01)
    assert run.parameters["rig"]["core"] == "C"


def test_controllers_use_the_identified_model_not_the_plant():
    model = identified_model(BENCH.configure())
    plant = BENCH.configure()["ecore"]
    assert model.p1 != plant.p1 and model.p2 != plant.p2


def test_hyst_inverse_beats_poly_inverse_on_a_ramp_start():
    config = BENCH.configure()
    scenario = BENCH.scenarios["ramp-1.5mm"]
    hyst = BENCH.run(scenario, "hyst-inverse", config, duration=1.0)
    poly = BENCH.run(scenario, "poly-inverse", config, duration=1.0)
    assert hyst.metrics["max_abs_error"] < 0.1
    assert hyst.metrics["rmse"] < 0.5 * poly.metrics["rmse"]


def test_nmpc_on_the_first_force_steps():
    """Feed-forward NMPC with preview ramps the current before the step; slew limit held."""
    config = BENCH.configure()
    scenario = BENCH.scenarios["steps-1.5mm"]
    nmpc = BENCH.run(scenario, "nmpc", config, duration=0.12)
    hyst = BENCH.run(scenario, "hyst-inverse", config, duration=0.12)
    plant = config["ecore"]
    assert np.all(np.isfinite(nmpc.input))
    assert np.max(np.abs(np.diff(nmpc.input))) <= plant.slew_limit * plant.sample_period + 1e-9
    assert nmpc.solver["fallbacks"] == nmpc.solver["failures"]
    assert nmpc.metrics["rmse"] < hyst.metrics["rmse"]


def test_offline_optimum_bounds_the_steps_ratio():
    """Knowing the whole reference, the best slew-limited currents reach only ~0.52× the
    hyst-inverse RMSE on steps-1.5mm: a criterion of ≤ 0.5 is below what any controller can do."""
    scenario = BENCH.scenarios["steps-1.5mm"]
    config = apply_overrides(BENCH.configure(), list(scenario.conditions))
    _, ref = reference_samples(scenario, BENCH.sample_period)
    plant, gap, _ = rig(config)
    slew = plant.slew_limit * plant.sample_period
    currents = offline_optimum(identified_model(config), gap, ref, plant.current_limit, slew)
    assert np.max(np.abs(np.diff(currents))) <= slew + plant.p1
    best = simulate(BENCH.build_plant(config), Replay(currents), ref).metrics["rmse"]
    hyst = BENCH.run(scenario, "hyst-inverse", BENCH.configure()).metrics["rmse"]
    assert 0.5 < best / hyst < 0.55, best / hyst


@pytest.mark.slow
def test_calibration_on_the_e_core_ramps():
    """katalenic2013: hysteresis inverse ≤ 0.3 N (paper 0.1 N) and ≥ 5× better than the polynomial."""
    config = BENCH.configure()
    for gap in ("1.2", "1.3", "1.5", "1.7"):
        scenario = BENCH.scenarios[f"ramp-{gap}mm"]
        hyst = BENCH.run(scenario, "hyst-inverse", config).metrics["max_abs_error"]
        poly = BENCH.run(scenario, "poly-inverse", config).metrics["max_abs_error"]
        assert hyst <= 0.3, (gap, hyst)
        assert poly >= 5 * hyst, (gap, poly, hyst)


def test_the_nmpc_model_reads_the_table_exactly_or_rounded():
    """kink_eps = 0: the table's polyline itself (value and slope, extended linearly beyond
    it, on floats, arrays and CasADi symbols); kink_eps > 0: within kink_eps/2 × the sum of
    the slope changes of it; negative refused; the bench's NMPC uses the configured one."""
    config = BENCH.configure()
    _, gap, _ = rig(config)
    model = identified_model(config)
    xs, fs = model.force_table(gap)
    slopes = np.diff(fs) / np.diff(xs)
    inside = np.linspace(xs[0], xs[-1], 997)
    beyond = np.array([xs[-1] + 0.3, xs[0] - 0.2])
    exact = model.smooth_force_of_x(gap, kink_eps=0.0)
    assert np.allclose([exact(v) for v in inside], np.interp(inside, xs, fs), rtol=1e-13, atol=1e-10)
    assert np.array_equal(exact(inside.reshape(-1, 1)).ravel(), [exact(v) for v in inside])
    assert exact(beyond[0]) == pytest.approx(fs[-1] + 0.3 * slopes[-1], rel=1e-12)
    assert exact(beyond[1]) == pytest.approx(fs[0] - 0.2 * slopes[0], rel=1e-12)
    v = ca.SX.sym("v")
    slope = ca.Function("slope", [v], [ca.jacobian(exact(v), v)])
    middles = 0.5 * (xs[1:] + xs[:-1])
    assert np.allclose([float(slope(m)) for m in middles], slopes, rtol=1e-12)
    assert np.all(np.isfinite([float(slope(x)) for x in xs]))  # a slope at the kinks too
    rounded = model.smooth_force_of_x(gap, kink_eps=1e-4)
    bound = 0.5e-4 * np.abs(np.diff(slopes)).sum()
    assert np.max(np.abs([rounded(v) - exact(v) for v in inside])) <= bound
    with pytest.raises(ValueError, match="kink_eps must be finite and >= 0"):
        model.smooth_force_of_x(gap, kink_eps=-1e-4)
    with pytest.raises(ValueError, match="kink_eps must be finite and >= 0"):
        apply_overrides(config, ["table.kink_eps=-1"])
    kink = np.r_[np.zeros(4), xs[len(xs) // 2]]  # H's state with its output X on a kink
    outputs = [float(BENCH.build_controller("nmpc", apply_overrides(config, ["nmpc.runtime=python",
                                                                         f"table.kink_eps={eps}"]))
                     .model.output(kink, []))
               for eps in (0.0, 1e-4)]
    assert outputs[0] == pytest.approx(fs[len(xs) // 2], rel=1e-14)
    assert abs(outputs[1] - outputs[0]) > 1e-9  # the rounded kink
