"""An actuator file's simulated plant may carry the model's real error (``plant.truth =
"runner-up"``: the model moved toward the runner-up of an ``identify auto`` ranking by what
the model missed on the validation record); the baselines are tuned on the nominal model and
that blend, and never take a ringing candidate."""

import copy
import json
import shutil
from pathlib import Path

import numpy as np
import pytest

from hystmpc.experiments.actuator_file import ActuatorSpec
from hystmpc.experiments.baselines import PidController, PidGains
from hystmpc.experiments.cli import main
from hystmpc.experiments.runner import Scenario
from hystmpc.experiments.tuning import GAIN_MARGIN, mean_rmse, pid_cost, tune_pid
from hystmpc.models.linear_dynamics import LinearDynamics
from hystmpc.models.prandtl_ishlinskii import PrandtlIshlinskii
from hystmpc.plants.actuator import BlendedActuator, HysteresisActuator

EXAMPLE = Path(__file__).resolve().parents[1] / "docs" / "examples" / "piezo"
DT = 1e-3


def _ranked_folder(folder: Path, distance: float = 0.3) -> Path:
    """The worked example with ``plant.truth = "runner-up"`` and a ranking whose runner-up has
    20 % more gain."""
    (folder / "piezo.toml").write_text((EXAMPLE / "piezo.toml").read_text().replace(
        "[plant]", '[plant]\ntruth = "runner-up"'))
    doc = json.loads((EXAMPLE / "piezo_model.json").read_text())
    other = copy.deepcopy(doc)
    other["parameters"]["weights"] = [1.2 * w for w in doc["parameters"]["weights"]]
    other["parameters"]["linear_gain"] = 1.2 * doc["parameters"]["linear_gain"]
    doc["candidates"] = [
        {"family": doc["family"], "validation_rmse": doc["validation"]["rmse"], "model": copy.deepcopy(doc),
         "distance_to_best": 0.0},
        {"family": doc["family"], "validation_rmse": 0.5, "model": other, "distance_to_best": distance}]
    (folder / "piezo_model.json").write_text(json.dumps(doc))
    return folder / "piezo.toml"


def _lag_plant(hysteresis, noise=0.0) -> HysteresisActuator:
    dynamics = LinearDynamics("first-order", time_constant=0.003, delay_samples=1)
    return HysteresisActuator(hysteresis, DT, dynamics.discrete(DT), 1, noise, (0.0, 100.0))


def test_the_blend_is_each_plant_at_its_ends_and_their_mean_between():
    a, b = PrandtlIshlinskii(0.05, (10.0, 30.0), (0.04, 0.02)), PrandtlIshlinskii(0.07, (15.0,), (0.05,))
    u = 50 + 40 * np.sin(np.linspace(0, 12, 300))
    outputs = {}
    for weight in (0.0, 0.5, 1.0):
        blend = BlendedActuator(_lag_plant(a), _lag_plant(b), weight)
        blend.reset(0)
        outputs[weight] = np.array([blend.step(v).y for v in u])
    alone = {}
    for name, h in (("a", a), ("b", b)):
        plant = _lag_plant(h)
        plant.reset(0)
        alone[name] = np.array([plant.step(v).y for v in u])
    assert np.allclose(outputs[0.0], alone["a"]) and np.allclose(outputs[1.0], alone["b"])
    assert np.allclose(outputs[0.5], 0.5 * (alone["a"] + alone["b"]))
    assert np.ptp(alone["a"] - alone["b"]) > 0.5  # the two differ: the check above can fail
    with pytest.raises(ValueError, match="weight must be in"):
        BlendedActuator(_lag_plant(a), _lag_plant(b), 1.5)


def test_the_runner_up_plant_is_the_blend_by_the_models_validation_error(tmp_path):
    spec = ActuatorSpec(_ranked_folder(tmp_path))
    assert spec.plant.truth == "runner-up"
    v, noise = json.loads((tmp_path / "piezo_model.json").read_text())["validation"]["rmse"], spec.noise
    assert spec.runner_up_weight() == pytest.approx(np.sqrt(v**2 - noise**2) / 0.3)
    config = spec._configured()
    plant = spec.make_plant(config)
    assert isinstance(plant, BlendedActuator) and plant.noise == noise
    ensemble = spec.tuning_ensemble(config["model"], 0.0)
    assert len(ensemble) == 2 and ensemble[1].weight == spec.runner_up_weight()


def test_a_runner_up_closer_than_the_models_error_is_taken_whole(tmp_path):
    spec = ActuatorSpec(_ranked_folder(tmp_path, distance=1e-4))
    assert spec.runner_up_weight() == 1.0


@pytest.mark.parametrize("model_creep", ["kelvin-voigt", None])
def test_the_runner_up_is_not_the_model_with_its_creep_added_or_left_out(tmp_path, model_creep):
    """``identify auto --creep`` ranks each family with and without it: the model's own family
    fitted the other way is passed over for the next row."""
    path = _ranked_folder(tmp_path)
    doc = json.loads((tmp_path / "piezo_model.json").read_text())
    best, other = doc["candidates"]
    twin = copy.deepcopy(best) | {"distance_to_best": 0.01}
    for row, creep in ((best, model_creep), (other, model_creep), (twin, "grunwald-letnikov" if model_creep is None
                                                                   else None)):
        row.pop("creep", None)  # the fixture's runner-up is of the model's family, fitted as the model
        if creep:
            row["creep"] = creep
    doc["candidates"] = [best, twin, other]
    (tmp_path / "piezo_model.json").write_text(json.dumps(doc))
    assert ActuatorSpec(path).runner_up()["distance_to_best"] == 0.3


def test_truth_model_and_a_document_path_are_single_plants(tmp_path):
    path = _ranked_folder(tmp_path)
    shutil.copy(EXAMPLE / "piezo_model.json", tmp_path / "other.json")
    for truth in ("model", "other.json"):
        text = path.read_text().replace('truth = "runner-up"', f'truth = "{truth}"')
        (tmp_path / f"{truth}.toml").write_text(text)
        spec = ActuatorSpec(tmp_path / f"{truth}.toml")
        assert isinstance(spec.make_plant(spec._configured()), HysteresisActuator)
        assert spec.plant.truth == truth
    plain = ActuatorSpec(EXAMPLE / "piezo.toml")  # a document without a ranking
    assert plain.plant.truth == "model" and len(plain.tuning_ensemble(plain._configured()["model"], 0.0)) == 1
    shutil.copy(EXAMPLE / "piezo.toml", tmp_path / "default.toml")  # the ranked document, no truth given
    ranked = ActuatorSpec(tmp_path / "default.toml")
    assert ranked.plant.truth == "model" and len(ranked.tuning_ensemble(ranked._configured()["model"], 0.0)) == 2


@pytest.mark.parametrize("truth, needle", [
    ("runner-up", "needs a model document written by identify auto"),
    ("elsewhere.txt", "allowed: runner-up, model, or a model document's path"),
    ("missing.json", "no such file"),
])
def test_a_bad_truth_exits_2_in_one_line(tmp_path, capsys, truth, needle):
    shutil.copy(EXAMPLE / "piezo_model.json", tmp_path / "piezo_model.json")
    (tmp_path / "bad.toml").write_text((EXAMPLE / "piezo.toml").read_text().replace(
        "[plant]", f'[plant]\ntruth = "{truth}"'))
    assert main(["list", str(tmp_path / "bad.toml")]) == 2
    err = capsys.readouterr().err
    assert err.count("\n") == 1 and needle in err, err


def test_a_ringing_candidate_is_never_the_cheapest():
    plant = _lag_plant(PrandtlIshlinskii(0.1, (10.0,), (0.02,)))
    steps = Scenario("steps", "", 0.4, lambda t: np.where(np.asarray(t) < 0.2, 3.0, 6.0))
    calm = PidController(PidGains(kp=0.5, ki=300.0), DT, (0.0, 100.0))
    wild = PidController(PidGains(kp=60.0, ki=300.0), DT, (0.0, 100.0))
    assert np.isfinite(mean_rmse(calm, plant, [steps]))
    assert mean_rmse(wild, plant, [steps]) == np.inf  # it rings: rejected
    assert np.isfinite(mean_rmse(wild, plant, [steps], reject_oscillating=False))


def test_a_document_without_a_validation_takes_the_runner_up_whole(tmp_path):
    path = _ranked_folder(tmp_path)
    doc = json.loads((tmp_path / "piezo_model.json").read_text())
    doc["validation"] = None
    (tmp_path / "piezo_model.json").write_text(json.dumps(doc))
    assert ActuatorSpec(path).runner_up_weight() == 1.0


def test_a_candidate_without_its_gain_margin_is_rejected():
    plant = _lag_plant(PrandtlIshlinskii(0.1, (10.0,), (0.02,)))
    steps = Scenario("steps", "", 0.4, lambda t: np.where(np.asarray(t) < 0.2, 3.0, 6.0))
    built = []

    def build(gains):
        built.append(gains)
        return PidController(gains, DT, (0.0, 100.0))
    # kp 20 and ki 600 ring on this plant, kp 10 and ki 300 do not
    edge = PidGains(kp=10.0, ki=300.0, kd=1e-4, derivative_filter=0.004)
    safe = PidGains(kp=5.0, ki=300.0, kd=1e-4, derivative_filter=0.004)
    assert np.isfinite(mean_rmse(build(edge), plant, [steps]))  # calm at its own gains
    built.clear()
    assert pid_cost(build, edge, plant, [steps]) == np.inf  # but without its gain margin: rejected
    assert built == [edge, PidGains(kp=10.0 * GAIN_MARGIN, ki=300.0 * GAIN_MARGIN, kd=1e-4 * GAIN_MARGIN,
                                    derivative_filter=0.004)]  # every gain times the margin, the filter kept
    assert pid_cost(build, edge, plant, [steps], margin=False) == mean_rmse(build(edge), plant, [steps])
    assert pid_cost(build, edge, plant, [steps], reject_oscillating=False) == mean_rmse(build(edge), plant, [steps])
    assert pid_cost(build, safe, plant, [steps]) == mean_rmse(build(safe), plant, [steps])


def test_tuned_gains_keep_their_margin():
    plant = _lag_plant(PrandtlIshlinskii(0.1, (10.0,), (0.02,)))
    steps = Scenario("steps", "", 0.4, lambda t: np.where(np.asarray(t) < 0.2, 3.0, 6.0))

    def build(gains):
        return PidController(gains, DT, (0.0, 100.0))
    gains, cost = tune_pid(build, plant, [steps], static_gain=0.12, dead_time=0.005, sample_period=DT,
                           max_evaluations=12, stages=("pi",))
    assert np.isfinite(cost)
    doubled = PidGains(kp=gains.kp * GAIN_MARGIN, ki=gains.ki * GAIN_MARGIN, kd=gains.kd * GAIN_MARGIN,
                       derivative_filter=gains.derivative_filter)
    assert np.isfinite(mean_rmse(build(doubled), plant, [steps]))  # the doubled gains do not ring
    free, _ = tune_pid(build, plant, [steps], static_gain=0.12, dead_time=0.005, sample_period=DT,
                       max_evaluations=12, stages=("pi",), margin=False)
    assert free.kp > gains.kp or free.ki > gains.ki  # without the margin it tunes bolder
