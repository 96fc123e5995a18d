"""Identification from measured data: every family predicts a record simulated from itself
(thresholds off any ladder, an output offset, either row alignment) to the noise level, and
the command line reports, warns and refuses as interface.md says."""

import json
from pathlib import Path

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
from hystmpc.models.bouc_wen import BoucWen
from hystmpc.models.document import model_document, read_model_document
from hystmpc.models.generalised_pi import GeneralisedPI
from hystmpc.models.identification import FAMILIES, compiled_response, hysteresis_output, identify
from hystmpc.models.linear_dynamics import LinearDynamics
from hystmpc.models.preisach import Preisach
from hystmpc.models.scaled import Offset, Scaled

DT = 1e-3


def fit_input(lo, hi, n=4000, cycles=12, levels=120):
    """A decaying sine from rest at ``lo`` (the major loop, then nested minor loops), then
    straight moves between ``levels`` random levels (reversals all over the range)."""
    t = np.arange(n) / n
    sine = lo + (hi - lo) * (0.5 - 0.5 * np.cos(2 * np.pi * cycles * t) * (1 - 0.8 * t))
    rng = np.random.default_rng(11)
    ends = lo + (hi - lo) * rng.uniform(0, 1, levels)
    starts = np.concatenate(([sine[-1]], ends[:-1]))
    return np.concatenate((sine, *(np.linspace(a, b, m) for a, b, m in zip(starts, ends, rng.integers(40, 160, levels),
                                                                           strict=True))))


def validation_input(lo, hi, n=3000):
    """Two sines: loops the fit never saw."""
    t = np.arange(n) / n
    return lo + (hi - lo) * (0.5 - 0.3 * np.cos(2 * np.pi * 5 * t) - 0.2 * np.cos(2 * np.pi * 17 * t))


def measured(model, creep_order, u, noise, seed, alignment="next", offset=0.0):
    """A record of ``model``: ``y_k`` measured before ``u_k`` acts (``next``, a rig) or after it
    (``same``, a loop tracer), a sensor offset and white noise."""
    h = hysteresis_output(model, creep_order, u, DT) + offset
    if alignment == "next":
        h = np.concatenate(([h[0]], h[:-1]))
    return h + noise * np.random.default_rng(seed).standard_normal(len(u))


def _power_function_truth():
    """Table V's polylines sampled on an even grid a little wider than the data's span."""
    grid = np.linspace(-0.05, 0.05, 10)
    table = PowerFunctionHysteresis()
    up, down = np.array(table.ascending), np.array(table.descending)
    return PowerFunctionHysteresis(tuple(zip(grid, np.interp(grid, up[:, 0], up[:, 1]), strict=True)),
                                   tuple(zip(grid, np.interp(grid, down[:, 0], down[:, 1]), strict=True)))


_DENSITY = np.abs(np.cumsum(np.random.default_rng(5).normal(0, 0.01, (5, 8)), axis=1)) + 0.01
TRUTHS = {  # family: (truth, creep order, input range, noise std); no threshold on any ladder the fit starts from
    "prandtl-ishlinskii": (PrandtlIshlinskii(0.05, (7.3, 21.1, 38.7), (0.04, 0.03, 0.02)), 0.0, (0.0, 100.0), 0.01),
    "maxwell-slip": (MaxwellSlip((0.5, 0.3, 0.2), (0.5 * 0.37, 0.3 * 1.13, 0.2 * 2.71)), 0.0, (-5.0, 5.0), 0.005),
    "preisach": (Preisach((4.3, 13.9, 27.1, 41.0), tuple(np.linspace(-10, 110, 9)), tuple(map(tuple, _DENSITY))), 0.0,
                 (0.0, 100.0), 0.01),
    "generalised-pi": (GeneralisedPI(0.3, (0.7, 2.3, 4.1), (0.2, 0.3, 0.2), (-1, 2, 5, 8, 12), (0, 1.5, 4, 5, 5.5)),
                       0.0, (0.0, 10.0), 0.005),
    "bouc-wen": (BoucWen(0.3, -0.1, 0.05**1.7, 0.4 * 0.05**1.7, 1.7), 0.0, (0.0, 100.0), 0.01),
    "parametric": (Scaled(ParametricHysteresis(0.8, 1.5), 1.2), 0.0, (0.0, 10.0), 0.01),
    "kp": (Fckp(FckpParams(density_c=2.4, density_sigma=0.8, creep_order=0.0, sample_period=DT, u_min=-3, u_max=12)),
           0.0, (0.0, 10.0), 0.005),
    "fckp": (Fckp(FckpParams(density_c=2.4, density_sigma=0.8, creep_order=0.03, sample_period=DT, u_min=-3,
                             u_max=12)), 0.03, (0.0, 10.0), 0.005),
    "power-function": (_power_function_truth(), 0.0, (-0.046, 0.046), 0.01),
}
QUICK = {("prandtl-ishlinskii", "next"), ("maxwell-slip", "same"), ("bouc-wen", "same"), ("parametric", "next"),
         ("kp", "same")}
"""The cases of the default suite (every case runs with ``-m slow``)."""


def self_fit(family, alignment):
    """Fit ``family`` to its truth's noisy record; returns (identified, validation RMSE, noise, offset)."""
    truth, creep, (lo, hi), noise = TRUTHS[family]
    offset = 18.5 * noise
    u, u_val = fit_input(lo, hi), validation_input(lo, hi)
    fitted = identify(family, u, measured(truth, creep, u, noise, 1, alignment, offset), DT)
    y_val = measured(truth, creep, u_val, noise, 2, alignment, offset)
    return fitted, float(np.sqrt(np.mean((fitted.predict(u_val) - y_val) ** 2))), noise, offset


@pytest.mark.parametrize("family, alignment", [
    pytest.param(f, a, marks=() if (f, a) in QUICK else pytest.mark.slow) for f in TRUTHS for a in ("next", "same")])
def test_each_family_predicts_a_record_of_itself_to_the_noise(family, alignment):
    fitted, rmse, noise, offset = self_fit(family, alignment)
    print(f"\n{family} ({alignment}): validation RMSE {rmse / noise:.3f} × the noise")
    assert fitted.alignment == alignment  # found by the default alignment=auto
    assert rmse <= 1.1 * noise, (rmse, noise)


def test_bouc_wen_at_exponent_one_is_the_closed_form_without_a_bound_warning():
    """Data of the classical model (n = 1): the fit ends at or near the exponent's lower limit,
    writes exactly 1 there (the closed form, not the pieces) and warns of no bound; the
    piezo example's record takes it to the limit itself."""
    truth = BoucWen(0.3, -0.1, 0.05, 0.02)
    u = fit_input(0.0, 100.0)
    fitted = identify("bouc-wen", u, measured(truth, 0.0, u, 0.01, 1), DT)
    exponent = fitted.parameters["exponent"]
    assert exponent == 1.0 or 1.0 + 1e-6 < exponent < 1.01
    assert "exponent" not in fitted.notes["at_bounds"]
    example = Path(__file__).parents[1] / "docs" / "examples" / "piezo" / "slow.csv"
    data = np.loadtxt(example, delimiter=",", skiprows=1)
    at_limit = identify("bouc-wen", data[:, 1], data[:, 2], DT)
    assert at_limit.parameters["exponent"] == 1.0
    assert "exponent" not in at_limit.notes["at_bounds"]


def test_the_families_are_all_tested():
    assert set(TRUTHS) == set(FAMILIES)


@pytest.mark.parametrize("model", [
    PrandtlIshlinskii(0.05, (7.3, 21.1), (0.04, 0.03)), MaxwellSlip((0.5, 0.3), (0.2, 0.4)), TRUTHS["preisach"][0],
    TRUTHS["generalised-pi"][0], BoucWen(0.3, -0.1, 0.05, 0.02), BoucWen(0.0, 1.0, 0.05, -0.02),
    TRUTHS["bouc-wen"][0], Scaled(ParametricHysteresis(0.8, 1.5), 1.2), PowerFunctionHysteresis(),
    Fckp(FckpParams(u_min=-150.0, u_max=150.0, creep_order=0.0))],
    ids=["pi", "ms", "preisach", "gpi", "bouc-wen-piezo", "bouc-wen", "bouc-wen-exponent", "parametric",
         "power-function", "kp-bipolar"])
def test_compiled_recursions_equal_the_exact_steps(model):
    span = 0.046 if isinstance(model, PowerFunctionHysteresis) else 150.0 if isinstance(model, Fckp) else 10.0
    rng = np.random.default_rng(3)
    u = np.clip(np.cumsum(rng.normal(0, 0.05 * span, 3000)), -span, span)
    u[100:120] = u[100]  # a standing input
    assert np.max(np.abs(compiled_response(model, u) - model.simulate(u)[0])) < 1e-9 * (1 + np.ptp(u))
    shifted = Offset(model, 0.3 * span, 2.0)
    assert np.max(np.abs(hysteresis_output(shifted, 0.0, u, DT) - shifted.simulate(u)[0])) < 1e-9 * (1 + np.ptp(u))


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


def test_a_kelvin_voigt_creep_steps_as_its_response_and_starts_settled():
    """The creep's discrete states (what the plant and the NMPC run) repeat the response the fit
    uses, for every kind, from the rest state; and without creep nothing changes."""
    rng = np.random.default_rng(3)
    h = 2.0 + np.cumsum(rng.standard_normal(2000)) * 0.1
    creep = ((0.06, 0.4), (0.03, 3.0))
    for kind, keys in (("none", {}), ("first-order", {"time_constant": 0.004}),
                       ("second-order", {"natural_frequency_hz": 60.0, "damping": 0.1})):
        block = LinearDynamics(kind, creep=creep, **keys)
        step = block.discrete(DT)
        x, out = np.array(step.rest_state(h[0]), float), []
        for value in h:
            out.append(step.output(x, value))
            x = np.array(step.rhs(x, 0.0, value, 0.0), float)
        assert np.max(np.abs(np.array(out) - block.response(h, DT, from_steady_state=True))) < 1e-12, kind
        plain = LinearDynamics(kind, **keys)
        assert np.array_equal(plain.response(h, DT, True), LinearDynamics(kind, creep=(), **keys).response(h, DT, True))
    held = LinearDynamics(creep=creep).response(np.r_[np.zeros(10), np.ones(5000)], DT)
    assert abs(held[11] - 0.91) < 1e-3 and abs(held[-1] - (1 - 0.06 * np.exp(-5 / 0.4) - 0.03 * np.exp(-5 / 3))) < 1e-3


@pytest.mark.parametrize("creep, message", [
    ([[0.6, 1.0], [0.5, 2.0]], "creep shares sum to 1.1; they must sum below 1"),
    ([[0.1, 0.0]], "the share must be >= 0 and the time constant > 0"),
    ([0.1, 1.0], "must be a list of \\[share, time_constant\\] pairs")])
def test_a_bad_creep_is_refused_naming_it(creep, message):
    from hystmpc.models.document import dynamics_from
    with pytest.raises(ValueError, match=message):
        dynamics_from({"kind": "none", "creep": creep}, "model.json")


def _creeping_pi(creep):
    """``record(u, seed)``: a PI stage whose output creeps through Kelvin–Voigt elements ``creep``, noise 0.01."""
    truth = PrandtlIshlinskii(0.05, (13.0, 31.0), (0.04, 0.02))
    block = LinearDynamics(creep=creep)

    def record(u, seed):
        y = block.response(hysteresis_output(truth, 0.0, u, DT) + 0.2, DT, from_steady_state=True)
        return y + 0.01 * np.random.default_rng(seed).standard_normal(len(u))
    return record


def test_a_kelvin_voigt_creep_is_fitted_with_any_family():
    """A PI stage whose output creeps by 9 % over two elements off the fit's time-constant ladder
    validates at the noise; kp, which takes no Grünwald–Letnikov creep, takes this one."""
    u, u_val = fit_input(0, 100, n=2000, levels=40), validation_input(0, 100)
    record = _creeping_pi(((0.05, 0.23), (0.04, 1.7)))
    fitted = identify("prandtl-ishlinskii", u, record(u, 1), DT, creep="kelvin-voigt", alignment="next")
    assert sum(share for share, _ in fitted.dynamics.creep) == pytest.approx(0.09, abs=0.01)
    assert np.sqrt(np.mean((fitted.predict(u_val) - record(u_val, 2)) ** 2)) < 1.1 * 0.01
    assert all(share >= 1e-6 for share, _ in fitted.dynamics.creep)  # the unused elements left out
    record = _creeping_pi(((0.3, 0.37),))  # one large element, its time constant off the start's ladder
    fitted = identify("prandtl-ishlinskii", u, record(u, 1), DT, creep="kelvin-voigt", alignment="next")
    assert np.sqrt(np.mean((fitted.predict(u_val) - record(u_val, 2)) ** 2)) < 1.1 * 0.01
    share, tau = max(fitted.dynamics.creep)  # its twins merged into one element
    assert abs(share / 0.3 - 1) < 0.03 and abs(tau / 0.37 - 1) < 0.03, fitted.dynamics.creep
    assert identify("kp", u, record(u, 1), DT, creep="kelvin-voigt").dynamics.creep
    assert identify("fckp", u, record(u, 1), DT, creep="kelvin-voigt").dynamics.creep  # after its own
    with pytest.raises(ValueError, match="creep 'maxwell'; allowed: grunwald-letnikov, kelvin-voigt"):
        identify("kp", u, u, DT, creep="maxwell")
    with pytest.raises(ValueError, match="needs a record of at least 100 samples .* the record has 99"):
        identify("kp", u[:99], u[:99], DT, creep="kelvin-voigt")


def test_identify_auto_ranks_each_family_with_and_without_the_creep():
    """Asked for a creep, auto fits it and leaves it out, and the validation chooses; a family
    that takes no creep of that form is ranked without it, not as a failure."""
    from hystmpc.experiments.identify import _candidate
    from hystmpc.models.identify_auto import identify_auto
    u, u_val = fit_input(0, 100, n=2000, levels=40), validation_input(0, 100)
    record = _creeping_pi(((0.05, 0.23), (0.04, 1.7)))
    ranking = identify_auto(u, record(u, 1), DT, (u_val, record(u_val, 2)), families=["prandtl-ishlinskii"],
                            creep="kelvin-voigt", alignment="next", workers=1)
    with_creep, without = ranking.candidates
    assert with_creep.label == "prandtl-ishlinskii + kelvin-voigt" and without.label == "prandtl-ishlinskii"
    assert with_creep.validation_rmse < 1.1 * 0.01 < 3 * 0.01 < without.validation_rmse
    assert _candidate(with_creep)["creep"] == "kelvin-voigt" and "creep" not in _candidate(without)
    ranking = identify_auto(u, record(u, 1), DT, (u_val, record(u_val, 2)), families=["prandtl-ishlinskii", "kp"],
                            creep="grunwald-letnikov", alignment="next", workers=1)
    labels = sorted(c.label for c in ranking.candidates)
    assert labels == ["kp", "prandtl-ishlinskii", "prandtl-ishlinskii + grunwald-letnikov"]
    assert not any(c.error for c in ranking.candidates)
    ranking = identify_auto(u[:600], record(u[:600], 1), DT, families=["fckp"], creep=True, workers=1)
    assert [c.label for c in ranking.candidates] == ["fckp"]  # its own creep: fitted once
    with pytest.raises(ValueError, match="at least 100 samples .* the record's fit part has 70"):
        identify_auto(u[:100], u[:100], DT, families=["kp"], creep="kelvin-voigt", workers=1)


def test_model_document_round_trip(tmp_path):
    fitted, _, _, _ = self_fit("parametric", "same")
    path = tmp_path / "model.json"
    path.write_text(json.dumps(model_document(fitted, {"u": "V", "y": "um"}, version="test")))
    back = read_model_document(path)
    u = validation_input(0, 10, 200)
    assert np.array_equal(back.predict(u), fitted.predict(u))
    assert back.alignment == "same" and back.offsets == fitted.offsets and fitted.offsets["output"] != 0
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
    truth = PrandtlIshlinskii(0.05, (13.0, 31.0), (0.04, 0.02))
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
    assert doc["validation"]["rmse"] < 0.011 and doc["fit"]["n_samples"] == len(u)
    assert doc["alignment"] == "next" and set(doc["offsets"]) == {"input", "output"}
    assert out.with_suffix(".png").stat().st_size > 10_000


def test_a_spreadsheets_byte_order_mark_is_read_a_poor_fit_is_said_and_no_model_exits_1(tmp_path, capsys):
    """Excel writes UTF-8 with a byte-order mark; a saturating family on a loop that keeps
    rising fits poorly (a warning); an output that falls as the input rises leaves every
    weight at zero (no model: exit 1, one line)."""
    truth = PrandtlIshlinskii(0.05, (13.0, 31.0), (0.04, 0.02))
    u = fit_input(0, 100, levels=10)
    y = measured(truth, 0.0, u, 0.01, 1)
    good = _write(tmp_path / "good.csv", np.arange(len(u)) * DT, u, y)
    good.write_bytes(b"\xef\xbb\xbf" + good.read_bytes())
    assert main(["identify", "prandtl-ishlinskii", str(good), "--out", str(tmp_path / "a.json"), "--no-plots"]) == 0
    assert "poor fit" not in capsys.readouterr().err
    assert main(["identify", "maxwell-slip", str(good), "--out", str(tmp_path / "b.json"), "--no-plots",
                 "--quiet"]) == 0
    assert "poor fit: RMSE" in capsys.readouterr().err
    flipped = _write(tmp_path / "flipped.csv", np.arange(len(u)) * DT, u, -y)
    assert main(["identify", "prandtl-ishlinskii", str(flipped), "--out", str(tmp_path / "c.json"), "--no-plots"]) == 1
    err = capsys.readouterr().err
    assert err.count("\n") == 1 and "prandtl-ishlinskii: the fit gave no model" in err and "flip the sign" in err, err
    assert not (tmp_path / "c.json").exists()


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
    (["identify", "jiles-atherton", "x.csv"], "unknown model family 'jiles-atherton'"),
    (["identify", "auto", "x.csv", "--set", "plays=3"], "with auto, name the family: FAMILY.OPTION=VALUE"),
    (["identify", "preisach", "x.csv", "--alignment", "before"], "alignment 'before'; allowed: next, same, auto"),
    (["identify", "preisach", "x.csv", "--continue"], "--continue says the validation record continues"),
    (["identify", "preisach", "x.csv", "--warm-up", "195"], "--warm-up 195 leaves fewer than 10"),
    (["identify", "kp"], "needs a measured record"),
    (["identify", "maxwell-slip", "x.csv", "--set", "plays=3"], "unknown option 'plays' for family maxwell-slip"),
    (["identify", "maxwell-slip", "x.csv", "--dynamics", "third-order"], "--dynamics 'third-order'"),
])
def test_bad_identify_usage_exits_2(tmp_path, capsys, argv, needle):
    u = 5 * np.sin(np.linspace(0, 12, 200))
    _write(tmp_path / "x.csv", np.arange(len(u)) * DT, u, u)
    argv = [str(tmp_path / a) if a == "x.csv" else a for a in argv]
    assert main(argv) == 2
    err = capsys.readouterr().err
    assert err.count("\n") == 1 and needle in err, err


@pytest.mark.slow
def test_reluctance_identification_from_a_measured_loop_file(tmp_path, capsys):
    from hystmpc.experiments.benches import get_bench
    from hystmpc.experiments.benches.reluctance_identification import rig
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


def _record_files(tmp_path, truth, u, seed, name, **kw):
    return _write(tmp_path / name, np.arange(len(u)) * DT, u, measured(truth, 0.0, u, 0.01, seed, **kw))


def test_identify_auto_ranks_every_family_against_a_straight_line(tmp_path, capsys):
    truth = PrandtlIshlinskii(0.05, (13.0, 31.0), (0.04, 0.02))
    data = _record_files(tmp_path, truth, fit_input(0, 100, n=2000, levels=25), 1, "data.csv")
    out = tmp_path / "model.json"
    assert main(["identify", "auto", str(data), "--out", str(out), "--no-plots", "--units", "um"]) == 0
    printed = capsys.readouterr().out
    doc = json.loads(out.read_text())
    rows = doc["candidates"]
    assert [r["family"] for r in rows if "error" not in r] and {r["family"] for r in rows} == set(FAMILIES)
    ranked = [r["validation_rmse"] for r in rows if r["validation_rmse"] is not None]
    assert ranked == sorted(ranked) and doc["family"] == rows[0]["family"]
    assert doc["validation"]["rmse"] == rows[0]["validation_rmse"] < 0.011  # the held-out 30 %
    assert "last 30%" in doc["validation"]["how"] and doc["fit"]["n_samples"] == round(0.7 * len(fit_input(
        0, 100, n=2000, levels=25)))
    assert doc["reference"]["family"] == "linear + first-order lag" and doc["reference"]["validation_rmse"] > 0.1
    for family in FAMILIES:
        assert family in printed
    assert "linear + first-order lag" in printed and "vs linear+lag" in printed


def test_a_non_finite_fit_exits_1_in_one_line_naming_the_family(tmp_path, capsys, monkeypatch):
    from hystmpc.models import identification
    truth = PrandtlIshlinskii(0.05, (13.0, 31.0), (0.04, 0.02))
    data = _record_files(tmp_path, truth, fit_input(0, 100, n=1000, levels=5), 1, "data.csv")
    monkeypatch.setattr(identification.Identified, "predict", lambda self, u, alignment=None: np.full(len(u), np.nan))
    out = tmp_path / "model.json"
    assert main(["identify", "bouc-wen", str(data), "--out", str(out), "--no-plots"]) == 1
    err = capsys.readouterr().err
    assert err.count("\n") == 1 and "bouc-wen: the fit's RMSE is not finite" in err, err
    assert not out.exists()


def test_validation_continues_the_fit_record_or_skips_a_warm_up(tmp_path, capsys):
    """Half a record validated on its other half: from rest the model starts in the wrong
    state; continuing the first half's state (--continue), or leaving the start out
    (--warm-up), it predicts to the noise. A fit record whose start is not at rest: --warm-up."""
    truth = PrandtlIshlinskii(0.05, (13.0, 31.0), (0.04, 0.02))
    u = fit_input(0, 100, n=2000, levels=30)
    y = measured(truth, 0.0, u, 0.01, 1)
    half = len(u) // 2
    first = _write(tmp_path / "first.csv", np.arange(half) * DT, u[:half], y[:half])
    second = _write(tmp_path / "second.csv", np.arange(len(u) - half) * DT, u[half:], y[half:])
    rmse = {}
    for extra in ([], ["--continue"], ["--warm-up", "300"]):
        out = tmp_path / f"m{len(rmse)}.json"
        assert main(["identify", "prandtl-ishlinskii", str(first), "--validate", str(second), "--out", str(out),
                     "--no-plots", "--quiet", *extra]) == 0
        rmse[" ".join(extra)] = json.loads(out.read_text())["validation"]["rmse"]
    assert rmse[""] > 2 * 0.01, rmse  # a wrong start, and the warning says what to do
    assert "--continue or --warm-up" in capsys.readouterr().err
    assert rmse["--continue"] < 1.1 * 0.01 and rmse["--warm-up 300"] < 1.1 * 0.01, rmse
    assert main(["identify", "prandtl-ishlinskii", str(second), "--out", str(tmp_path / "w.json"), "--no-plots",
                 "--quiet", "--warm-up", "300"]) == 0
    assert json.loads((tmp_path / "w.json").read_text())["fit"]["rmse"] < 1.1 * 0.01


def test_a_record_too_slow_for_a_resonance_is_refused(tmp_path, capsys):
    truth = PrandtlIshlinskii(0.05, (13.0, 31.0), (0.04, 0.02))
    data = _record_files(tmp_path, truth, fit_input(0, 100, n=2000, levels=10), 1, "data.csv")
    assert main(["identify", "prandtl-ishlinskii", str(data), "--dynamics", "second-order", "--no-plots",
                 "--out", str(tmp_path / "m.json")]) == 2
    err = capsys.readouterr().err
    assert err.count("\n") == 1 and "too slow to show a resonance" in err and "--dynamics-data" in err, err


@pytest.mark.slow  # 16 s: the creep's FFT in every step of the fit (CI runs it)
def test_a_creep_is_fitted_after_any_family():
    """A PI model whose output (offset included, as hystmpc's models hold it) creeps."""
    truth = Offset(PrandtlIshlinskii(0.05, (13.0, 31.0), (0.04, 0.02)), 0.0, 0.2)
    u, u_val = fit_input(0, 100, n=2000, levels=40), validation_input(0, 100)
    fitted = identify("prandtl-ishlinskii", u, measured(truth, 0.03, u, 0.01, 1), DT, creep=True)
    y_val = measured(truth, 0.03, u_val, 0.01, 2)
    assert abs(fitted.parameters["creep_order"] / 0.03 - 1) < 0.05 and abs(fitted.offsets["output"] - 0.2) < 0.01
    assert np.sqrt(np.mean((fitted.predict(u_val) - y_val) ** 2)) < 1.1 * 0.01
    with pytest.raises(ValueError, match="kp takes no Grünwald–Letnikov creep; fckp is kp with it"):
        identify("kp", u, u, DT, creep=True)


@pytest.mark.parametrize("doc, needle", [
    ({"validation": {"rmse": 0.5}}, "validation RMSE 0.5 is 5.0 × the fit's 0.1"),
    ({"fit": {"at_bounds": ["beta"]}}, "bouc-wen: beta at a bound of the search"),
    ({"validation": {"rmse": 0.2}, "reference": {"validation_rmse": 0.15}}, "no family beats a straight line"),
])
def test_warnings_say_what_is_wrong(caplog, doc, needle):
    from hystmpc.experiments.identify import _warn
    base = {"family": "bouc-wen", "fit": {"rmse": 0.1}}
    base["fit"].update(doc.pop("fit", {}))
    _warn(base | doc, np.linspace(0, 100, 50))
    assert needle in caplog.text
