"""Bench compliant: plant sensors, calibration against Table IV, NMPC closed loop."""

import json
from dataclasses import replace

import numpy as np
import pytest

from hystmpc.experiments.benches.compliant import BENCH, NOMINAL, PAPER_TABLE_IV, PLANT
from hystmpc.experiments.cli import main
from hystmpc.experiments.report import validate_document
from hystmpc.plants.compliant import CompliantActuator


def test_plant_starts_at_zero_torque_and_quantises_like_the_sensor():
    plant = CompliantActuator(replace(PLANT, torque_noise=0.0))
    meas = plant.reset(0)
    assert abs(meas.truth["torque"]) < 1e-12
    for _ in range(50):
        meas = plant.step(0.3)
    steps = meas.y / PLANT.torque_resolution
    assert steps == pytest.approx(round(steps), abs=1e-9)
    assert meas.truth["torque"] > 0.5


def test_command_delay_and_backlash_are_invisible_to_the_encoder():
    plant = CompliantActuator(replace(PLANT, torque_noise=0.0, backlash=0.01))
    start = plant.reset(0).sensors["angle"]
    assert plant.step(0.2).sensors["angle"] == start  # one sample of command delay
    for _ in range(100):
        meas = plant.step(0.2)
    for _ in range(100):
        back = plant.step(0.19)
    # the motor moved back 0.01 rad but the output stayed inside the clearance
    assert back.sensors["angle"] == pytest.approx(0.19, abs=1e-4)
    assert back.truth["angle"] == pytest.approx(meas.truth["angle"], abs=1e-9)


def test_calibration_against_table_iv():
    """inverse-ff-pid within a factor of 3 of zhou2024 Table IV, and better than plain PID."""
    config = BENCH.configure()
    for amplitude, (paper_rmse, _) in PAPER_TABLE_IV.items():
        scenario = BENCH.scenarios[f"sine-{amplitude:g}"]
        ff = BENCH.run(scenario, "inverse-ff-pid", config).metrics["rmse"]
        pid = BENCH.run(scenario, "pid", config).metrics["rmse"]
        assert paper_rmse / 3 <= ff <= 3 * paper_rmse, (amplitude, ff)
        assert ff < pid, (amplitude, ff, pid)


def test_nmpc_short_closed_loop():
    config = BENCH.configure()
    scenario = BENCH.scenarios["sine-1"]
    nmpc = BENCH.run(scenario, "nmpc", config, duration=4.0)
    ff = BENCH.run(scenario, "inverse-ff-pid", config, duration=4.0)
    assert nmpc.solver["failures"] == 0
    assert np.all(np.isfinite(nmpc.input)) and np.all(np.abs(nmpc.input) <= NOMINAL.angle_limit)
    assert np.max(np.abs(np.diff(nmpc.input))) <= NOMINAL.rate_limit * NOMINAL.sample_period + 1e-12
    assert nmpc.metrics["rmse"] < ff.metrics["rmse"]


@pytest.mark.slow
def test_full_comparison_meets_the_issue(tmp_path):
    doc_path = tmp_path / "out.json"
    assert main(["compare", "compliant", "--json", str(doc_path), "--out", str(tmp_path / "res"), "--quiet"]) == 0
    doc = json.loads(doc_path.read_text())
    validate_document(doc)
    runs = {(r["scenario"], r["controller"]): r for r in doc["runs"]}
    assert len(runs) == 12
    for scenario in BENCH.scenarios:
        rmse = {c: runs[(scenario, c)]["metrics"]["rmse"] for c in ("pid", "inverse-ff-pid", "inverse-lmpc", "nmpc")}
        assert rmse["nmpc"] <= 0.5 * rmse["inverse-ff-pid"] < rmse["pid"], (scenario, rmse)
        assert rmse["nmpc"] <= 0.8 * rmse["inverse-lmpc"], (scenario, rmse)  # at least 20 % better
        assert runs[(scenario, "inverse-ff-pid")]["paper"]["rmse"] > 0
        solver = runs[(scenario, "nmpc")]["solver"]
        assert solver["failures"] == 0 and solver["fallbacks"] == 0, (scenario, solver)
        assert (tmp_path / "res" / f"{scenario}.png").is_file()
        for c in rmse:
            data = np.genfromtxt(tmp_path / "res" / "runs" / f"{scenario}__{c}.csv", delimiter=",", names=True)
            assert all(np.all(np.isfinite(data[col])) for col in ("t", "reference", "output", "input"))
