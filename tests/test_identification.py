"""Identification from measured data: every family recovers known parameters from noisy
simulated records and predicts a record it was not fitted on to the noise level."""

import json

import numpy as np
import pytest

from hystmpc.experiments.cli import main
from hystmpc.models import (
    Fckp,
    FckpParams,
    MaxwellSlip,
    ParametricHysteresis,
    PowerFunctionHysteresis,
    PrandtlIshlinskii,
)
from hystmpc.models.document import model_document, read_model_document
from hystmpc.models.identification import (
    hysteresis_output,
    identify,
    parametric_response,
    power_function_response,
    threshold_ladder,
)
from hystmpc.models.linear_dynamics import LinearDynamics
from hystmpc.models.power_function import ASCENDING_POINTS, DESCENDING_POINTS, TABLE_V
from hystmpc.models.scaled import Scaled

DT = 1e-3


def fit_input(lo, hi, n=4000, cycles=12):
    """A decaying sine from rest at ``lo``: the major loop first, then nested minor loops."""
    t = np.arange(n) / n
    return lo + (hi - lo) * (0.5 - 0.5 * np.cos(2 * np.pi * cycles * t) * (1 - 0.8 * t))


def validation_input(lo, hi, n=3000):
    """Two sines: loops the fit never saw."""
    t = np.arange(n) / n
    return lo + (hi - lo) * (0.5 - 0.3 * np.cos(2 * np.pi * 5 * t) - 0.2 * np.cos(2 * np.pi * 17 * t))


def measured(model, creep_order, u, noise, seed):
    """The rig's record: y_k measured before u_k acts, with white sensor noise."""
    h = hysteresis_output(model, creep_order, u, DT)
    return np.concatenate(([h[0]], h[:-1])) + noise * np.random.default_rng(seed).standard_normal(len(u))


def _grid(lo, hi):
    return threshold_ladder(fit_input(lo, hi)[:-1], 10)


CASES = {  # family: (truth, creep order, input range, noise std, fit options)
    "prandtl-ishlinskii": (PrandtlIshlinskii(0.05, tuple(_grid(0, 100)[[1, 4, 7]]), (0.04, 0.03, 0.02)), 0.0,
                           (0.0, 100.0), 0.01, {}),
    "maxwell-slip": (MaxwellSlip((0.5, 0.3, 0.2), tuple(np.array([0.5, 0.3, 0.2]) * _grid(-5, 5)[[1, 4, 7]])), 0.0,
                     (-5.0, 5.0), 0.005, {}),
    "parametric": (Scaled(ParametricHysteresis(0.8, 1.5), 1.2), 0.0, (0.0, 10.0), 0.01, {}),
    "kp": (Fckp(FckpParams(density_c=2.4, density_sigma=0.8, creep_order=0.0, sample_period=DT)), 0.0, (0.0, 10.0),
           0.005, {"u_max": 10.0}),
    "fckp": (Fckp(FckpParams(density_c=2.4, density_sigma=0.8, creep_order=0.03, sample_period=DT)), 0.03,
             (0.0, 10.0), 0.005, {"u_max": 10.0}),
    "power-function": (PowerFunctionHysteresis(), 0.0, (-0.046, 0.046), 0.01,
                       {"ascending_s": tuple(TABLE_V[p][0] for p in ASCENDING_POINTS),
                        "descending_s": tuple(TABLE_V[p][0] for p in DESCENDING_POINTS)}),
}


def dominant_errors(family, truth, fitted) -> dict[str, float]:
    """Relative errors of the parameters that shape the output most."""
    def rel(a, b):
        return float(np.max(np.abs(np.asarray(a, float) - np.asarray(b, float)) / np.abs(np.asarray(b, float))))
    if family == "prandtl-ishlinskii":
        weights = dict(zip(np.round(fitted["thresholds"], 9), fitted["weights"], strict=True))
        found = [weights.get(round(r, 9), 0.0) for r in truth.thresholds]
        return {"linear_gain": rel(fitted["linear_gain"], truth.linear_gain), "weights": rel(found, truth.weights)}
    if family == "maxwell-slip":
        k = dict(zip(np.round(np.divide(fitted["breakaway"], fitted["stiffness"]), 6), fitted["stiffness"],
                     strict=True))
        found = [k.get(round(w / s, 6), 0.0) for s, w in zip(truth.k, truth.w, strict=True)]
        return {"stiffness": rel(found, truth.k)}
    if family == "parametric":
        return {"p1": rel(fitted["p1"], truth.inner.p1), "p2": rel(fitted["p2"], truth.inner.p2),
                "gain": rel(fitted["gain"], truth.gain)}
    if family in ("kp", "fckp"):
        p = truth.params
        errors = {"density_c": rel(fitted["density_c"], p.density_c),
                  "density_sigma": rel(fitted["density_sigma"], p.density_sigma),
                  "stroke": rel(fitted["stroke"], p.stroke)}
        return errors | ({"creep_order": rel(fitted["creep_order"], p.creep_order)} if family == "fckp" else {})
    scale = max(abs(q[1]) for q in truth.ascending)  # polylines: error over the torque span
    tau = {name: np.max(np.abs(np.array(fitted[name])[:, 1] - np.array(getattr(truth, name))[:, 1])) / scale
           for name in ("ascending", "descending")}
    return {"ascending (of max |tau|)": float(tau["ascending"]), "descending (of max |tau|)": float(tau["descending"])}


def identification_case(family):
    """Fit ``family`` to its truth's noisy record; returns (validation RMSE, noise, errors)."""
    truth, creep, (lo, hi), noise, options = CASES[family]
    u, u_val = fit_input(lo, hi), validation_input(lo, hi)
    fitted = identify(family, u, measured(truth, creep, u, noise, 1), DT, options)
    y_val = measured(truth, creep, u_val, noise, 2)
    rmse = float(np.sqrt(np.mean((fitted.predict(u_val) - y_val) ** 2)))
    return rmse, noise, dominant_errors(family, truth, fitted.parameters), fitted


@pytest.mark.parametrize("family", list(CASES))
def test_identification_recovers_the_truth_to_the_noise_level(family):
    rmse, noise, errors, _ = identification_case(family)
    print(f"\n{family}: validation RMSE {rmse:.4g} (noise {noise}); " +
          ", ".join(f"{k} {100 * v:.2f} %" for k, v in errors.items()))
    assert rmse <= 1.5 * noise, (rmse, noise)
    for name, error in errors.items():
        assert error <= 0.05, (name, error)


def test_vectorised_responses_equal_the_exact_steps():
    s = np.concatenate((fit_input(-0.04, 0.04, 1500), np.full(20, 0.01), validation_input(-0.03, 0.04, 800)))
    model = PowerFunctionHysteresis()
    assert np.max(np.abs(power_function_response(model, s) - model.simulate(s)[0])) < 1e-12
    op = ParametricHysteresis(0.8, 1.5)
    u = 1000 * s
    assert np.max(np.abs(parametric_response(op, u) - op.simulate(u)[0])) < 1e-9


def test_dynamics_and_dead_time_are_recovered_from_a_faster_record():
    truth = PrandtlIshlinskii(0.05, (10.0, 30.0), (0.03, 0.02))
    block = LinearDynamics("second-order", natural_frequency_hz=120.0, damping=0.3, delay_samples=2)
    slow = fit_input(0, 100)
    t = np.arange(1500) * DT
    fast = np.where(t < 0.05, 0.0, np.random.default_rng(0).uniform(20, 80, 15)[(t // 0.1).astype(int)])
    noise = np.random.default_rng(5)

    def record(u):
        return block.response(hysteresis_output(truth, 0.0, u, DT), DT) + 0.005 * noise.standard_normal(len(u))
    fitted = identify("prandtl-ishlinskii", slow, record(slow), DT, dynamics="second-order",
                      dynamics_data=(fast, record(fast)))
    d = fitted.dynamics
    assert d.delay_samples == 2
    assert abs(d.natural_frequency_hz / 120.0 - 1) < 0.03 and abs(d.damping / 0.3 - 1) < 0.05, d


def test_model_document_round_trip(tmp_path):
    _, _, _, fitted = identification_case("parametric")
    path = tmp_path / "model.json"
    path.write_text(json.dumps(model_document(fitted, {"u": "V", "y": "um"}, version="test")))
    back = read_model_document(path)
    u = validation_input(0, 10, 200)
    assert np.array_equal(back.predict(u), fitted.predict(u))
    doc = json.loads(path.read_text())
    doc["parameters"].pop("p2")
    path.write_text(json.dumps(doc))
    with pytest.raises(ValueError, match="parameter 'p2' of family parametric is missing"):
        read_model_document(path)


def _write(path, t, u, y):
    rows = (f"{float(a)!r},{float(b)!r},{float(c)!r}" for a, b, c in zip(t, u, y, strict=True))
    path.write_text("t,u,y\n" + "\n".join(rows) + "\n")
    return path


def test_identify_command_writes_model_figure_and_validation(tmp_path, capsys):
    truth = PrandtlIshlinskii(0.05, tuple(_grid(0, 100)[[2, 6]]), (0.04, 0.02))
    u, v = fit_input(0, 100), validation_input(0, 100)
    data = _write(tmp_path / "data.csv", np.arange(len(u)) * DT, u, measured(truth, 0.0, u, 0.01, 1))
    val = _write(tmp_path / "val.csv", np.arange(len(v)) * DT, v, measured(truth, 0.0, v, 0.01, 2))
    out = tmp_path / "model.json"
    assert main(["identify", "prandtl-ishlinskii", str(data), "--validate", str(val), "--out", str(out),
                 "--units", "um", "--input-units", "V"]) == 0
    printed = capsys.readouterr().out
    assert "validation RMSE" in printed and "linear_gain" in printed
    doc = json.loads(out.read_text())
    assert doc["schema"] == "hystmpc.model/1" and doc["units"] == {"u": "V", "y": "um"}
    assert doc["validation"]["rmse"] < 0.015 and doc["fit"]["n_samples"] == len(u)
    assert out.with_suffix(".png").stat().st_size > 10_000


def test_a_spreadsheets_byte_order_mark_is_read_and_a_poor_fit_is_said(tmp_path, capsys):
    """Excel writes UTF-8 with a byte-order mark; a sensor offset makes the fit poor (a warning)."""
    truth = PrandtlIshlinskii(0.05, tuple(_grid(0, 100)[[2, 6]]), (0.04, 0.02))
    u = fit_input(0, 100)
    y = measured(truth, 0.0, u, 0.01, 1)
    good = _write(tmp_path / "good.csv", np.arange(len(u)) * DT, u, y)
    good.write_bytes(b"\xef\xbb\xbf" + good.read_bytes())
    assert main(["identify", "prandtl-ishlinskii", str(good), "--out", str(tmp_path / "a.json"), "--no-plots"]) == 0
    assert "poor fit" not in capsys.readouterr().err
    offset = _write(tmp_path / "offset.csv", np.arange(len(u)) * DT, u, y + np.ptp(y))
    assert main(["identify", "prandtl-ishlinskii", str(offset), "--out", str(tmp_path / "b.json"), "--no-plots",
                 "--quiet"]) == 0
    assert "poor fit: RMSE" in capsys.readouterr().err


@pytest.mark.parametrize("rows, needle", [
    ("t,u,y\n" + "".join(f"{k * 1e-3},{k},{k}\n" for k in range(10)), "needs at least 50 rows"),
    ("t,u,y\n" + "".join(f"{k * 1e-3 if k != 30 else 0.0305},{k % 7},{k}\n" for k in range(100)),
     "uniformly sampled"),
    ("t,u,y\n" + "".join(f"{k * 1e-3},1.5,{k}\n" for k in range(100)), "input u is constant"),
    ("t,u,y\n" + "".join(f"{k * 1e-3},{k % 7},{'nan' if k == 40 else k}\n" for k in range(100)), "NaN"),
    ("t,u\n" + "".join(f"{k * 1e-3},{k}\n" for k in range(100)), "lacks column 'y'"),
])
def test_bad_records_exit_2_with_one_line(tmp_path, capsys, rows, needle):
    path = tmp_path / "bad.csv"
    path.write_text(rows)
    assert main(["identify", "maxwell-slip", str(path), "--out", str(tmp_path / "m.json")]) == 2
    err = capsys.readouterr().err
    assert err.count("\n") == 1 and needle in err, err


@pytest.mark.parametrize("argv, needle", [
    (["identify", "preisach", "x.csv"], "unknown model family 'preisach'"),
    (["identify", "kp"], "needs a measured record"),
    (["identify", "maxwell-slip", "x.csv", "--set", "plays=3"], "unknown option 'plays' for family maxwell-slip"),
    (["identify", "maxwell-slip", "x.csv", "--dynamics", "third-order"], "--dynamics 'third-order'"),
])
def test_bad_identify_usage_exits_2(tmp_path, capsys, argv, needle):
    u = fit_input(-5, 5, 200)
    _write(tmp_path / "x.csv", np.arange(len(u)) * DT, u, u)
    argv = [str(tmp_path / a) if a == "x.csv" else a for a in argv]
    assert main(argv) == 2
    err = capsys.readouterr().err
    assert err.count("\n") == 1 and needle in err, err


@pytest.mark.slow
def test_reluctance_identification_from_a_measured_loop_file(tmp_path, capsys):
    from hystmpc.experiments.benches import get_bench
    from hystmpc.experiments.benches.reluctance import rig
    from hystmpc.plants.reluctance import major_loop_measurement
    plant, _, force_max = rig(get_bench("reluctance").configure())
    rows = []
    for k, gap in enumerate((1.2, 1.3, 1.5, 1.7, 1.75)):  # the bench's gaps, other noise seeds
        current, force = major_loop_measurement(plant, gap * 1e-3, force_max * 1.03, 2.0, seed=10 + k)
        rows += [f"{j * 5 * plant.sample_period},{float(i)!r},{float(f)!r},{gap}"
                 for j, (i, f) in enumerate(zip(current, force, strict=True))]
    loops = tmp_path / "loops.csv"
    loops.write_text("t,u,y,gap_mm\n" + "\n".join(rows) + "\n")
    out = tmp_path / "identified.json"
    assert main(["identify", "reluctance", "--data-file", str(loops), "--out", str(out), "--quiet"]) == 0
    doc = json.loads(out.read_text())
    assert abs(doc["p1_A"] / plant.p1 - 1) < 0.10 and abs(doc["p2_per_A_m"] / plant.p2 - 1) < 0.10, doc
