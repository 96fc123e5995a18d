"""CLI: error cases exit 2 with one line naming the problem; a short run writes a valid document."""

import json
import os
import subprocess
import sys

import pytest

from hystmpc.experiments.cli import main
from hystmpc.experiments.report import validate_document


def _run(capsys, argv):
    code = main(argv)
    captured = capsys.readouterr()
    return code, captured.out, captured.err


def _csv(tmp_path, text, name="ref.csv"):
    path = tmp_path / name
    path.write_text(text)
    return str(path)


@pytest.mark.parametrize("argv, needle", [
    (["run", "pam", "nosuch", "--controller", "nmpc"],
     "unknown scenario 'nosuch'; allowed: square-10, square-20, square-30, square-40, sine-30"),
    (["run", "pam", "square-10", "--controller", "lqr"],
     "unknown controller 'lqr'; allowed: pi, pi-hc, inverse-lmpc, nmpc"),
    (["run", "nosuch", "square-10", "--controller", "pi"],
     "unknown bench 'nosuch'; allowed: pam, compliant, reluctance"),
    (["compare", "pam", "--controllers", "pi,lqr"], "unknown controller 'lqr'"),
    (["run", "pam", "square-10", "--controller", "pi", "--set", "nmpc.nosuch=3"],
     "unknown --set key 'nmpc.nosuch'; keys of group nmpc: horizon, q_output"),
    (["run", "pam", "square-10", "--controller", "pi", "--set", "nmpc.horizn=3"],
     "unknown --set key 'nmpc.horizn'; did you mean 'nmpc.horizon'?"),
    (["run", "pam", "square-10", "--controller", "pi", "--set", "nmpc.eps=1e-4"],
     "--set nmpc.eps is now smoothing.eps"),
    (["run", "pam", "square-10", "--controller", "pi", "--set", "model.creep_time=3"],
     "--set model.creep_time cannot be changed on this bench: the controllers' model has no creep"),
    (["run", "pam", "square-10", "--controller", "nmpc", "--set", "smoothing.direction_eps=1e-4"],
     "direction_eps does not apply"),
    (["run", "pam", "square-10", "--controller", "pi", "--set", "nmpc.horizon=abc"],
     "--set nmpc.horizon='abc': expected an integer"),
    (["run", "pam", "square-10", "--controller", "pi", "--set", "nmpc.horizon=1"], "horizon must be >= 2"),
    (["run", "pam", "square-10", "--controller", "pi", "--set", "nmpc.solver=acados"],
     "allowed: ipopt, sqp"),
    (["run", "pam", "square-10", "--controller", "pi", "--set", "pi.kp"], "expected KEY=VALUE"),
    (["run", "pam", "square-10", "--controller", "pi", "--duration", "-1"],
     "--duration must be a finite number of seconds > 0"),
    (["run", "pam", "square-10"], "--controller"),
    (["compare", "pam", "--workers", "0"], "--workers must be >= 1, got 0"),
    (["compare", "pam", "--workers", "2", "--plant", "my_rig:heavy"], "--plant's plant is one"),
    (["frobnicate", "pam"], "invalid choice: 'frobnicate'"),
    (["identify", "preisach", "--creep", "rec.csv"], "--creep 'rec.csv': not a creep form; allowed: "
     "grunwald-letnikov, kelvin-voigt (--creep alone: grunwald-letnikov; if that was the family or the record, put "
     "--creep after them or write --creep=FORM)"),
])
def test_bad_usage_exits_2_with_one_line(capsys, argv, needle):
    code, out, err = _run(capsys, argv)
    assert code == 2
    assert out == ""
    assert err.count("\n") == 1 and err.startswith("hystmpc: error:")
    assert needle in err


@pytest.mark.parametrize("content, needle", [
    ("t,angle\n0,1\n0.1,nan\n0.2,3\n", "NaN or infinite values (line 3)"),
    ("t,angle\n0,1\n0.2,2\n0.1,3\n", "t must be strictly increasing (line 4)"),
    ("t,angle\n0,1\n0.1,1\n0.1,3\n", "t must be strictly increasing"),
    ("t,force\n0,1\n0.1,2\n", "lacks column 'angle'; needs 't' and 'angle' (or 'ref')"),
    ("time,angle\n0,1\n0.1,2\n", "lacks column 't'"),
    ("t,angle\n0,1\n0.1,abc\n", "line 3: 'abc' is not a number"),
    ("t,angle\n0,1\n0.1,\n", "line 3: a value is missing"),
    ("t,angle\n0,1\n0.1\n", "line 3: 1 fields, the header has 2"),
    ("t,angle\n0,1\n0.1,2,3\n", "line 3: 3 fields, the header has 2"),
    ("t,angle\n", "needs at least 2 rows"),
    ("", "is empty"),
    ("t,angle\n0.5,1\n1.0,2\n", "t must start at 0"),
    ("t,angle\n0,1\n1,90\n", "angle must lie in [-45.0, 45.0] deg"),
])
def test_malformed_reference_csv_exits_2(capsys, tmp_path, content, needle):
    path = _csv(tmp_path, content)
    code, out, err = _run(capsys, ["run", "pam", "square-10", "--controller", "pi", "--reference", path,
                                   "--out", str(tmp_path / "out"), "--no-plots"])
    assert code == 2
    assert err.count("\n") == 1
    assert needle in err


def test_missing_reference_file_exits_2(capsys, tmp_path):
    code, _, err = _run(capsys, ["run", "pam", "square-10", "--controller", "pi",
                                 "--reference", str(tmp_path / "none.csv")])
    assert code == 2 and "does not exist" in err


def test_reference_csv_run_and_valid_document(capsys, tmp_path):
    path = _csv(tmp_path, "t,ref\n0,0\n1,10\n2,10\n3,-5\n")
    out_dir = tmp_path / "out"
    code, out, err = _run(capsys, ["run", "pam", "square-10", "--controller", "pi-hc", "--reference", path,
                                   "--out", str(out_dir), "--json", str(tmp_path / "doc.json"),
                                   "--set", "pi.kp=0.07", "--quiet"])
    assert code == 0, err
    assert out == ""
    doc = json.loads((tmp_path / "doc.json").read_text())
    validate_document(doc)
    run = doc["runs"][0]
    assert run["scenario"] == "ref" and run["controller"] == "pi-hc"
    assert run["metrics"]["n_samples"] == 150
    assert run["parameters"]["pi"]["kp"] == 0.07
    assert (out_dir / "runs" / "ref__pi-hc.csv").is_file()
    assert (out_dir / "ref.png").is_file()


def test_same_seed_same_numbers(capsys, tmp_path):
    docs = []
    for i in range(2):
        code, _, _ = _run(capsys, ["run", "pam", "square-10", "--controller", "pi", "--duration", "2",
                                   "--seed", "4", "--out", str(tmp_path / str(i)), "--no-plots", "--quiet"])
        assert code == 0
        docs.append(json.loads((tmp_path / str(i) / "results.json").read_text()))
    assert docs[0]["runs"][0]["metrics"] == docs[1]["runs"][0]["metrics"]


def test_list_json(capsys):
    code, out, _ = _run(capsys, ["list", "--json"])
    assert code == 0
    info = json.loads(out)
    assert info["benches"]["pam"]["controllers"] == ["pi", "pi-hc", "inverse-lmpc", "nmpc"]
    assert info["benches"]["compliant"]["controllers"] == ["pid", "inverse-ff-pid", "inverse-lmpc", "nmpc"]
    assert "ipopt" in info["solvers"]


def test_scenario_conditions_cannot_be_overridden(capsys):
    code, _, err = _run(capsys, ["run", "reluctance", "ramp-1.2mm", "--controller", "hyst-inverse",
                                 "--set", "rig.gap_mm=1.4"])
    assert code == 2
    assert "--set rig.gap_mm conflicts with scenario 'ramp-1.2mm', which fixes rig.gap_mm=1.2" in err


def test_module_entry_point_exit_code():
    proc = subprocess.run([sys.executable, "-m", "hystmpc.experiments", "run", "pam", "nosuch", "--controller", "nmpc"],
                          capture_output=True, text=True, timeout=120)
    assert proc.returncode == 2
    assert proc.stderr.strip().splitlines() == [
        "hystmpc: error: unknown scenario 'nosuch'; allowed: square-10, square-20, square-30, square-40, sine-30"]


def test_compare_on_two_processes_gives_the_runs_of_one(capsys, tmp_path):
    """Every run is seeded and self-contained: the same metrics, CSVs and order on 2 processes
    as on 1, with a reference file and an actuator setting as well."""
    path = _csv(tmp_path, "t,ref\n0,0\n0.2,10\n0.3,-5\n")
    common = ["compare", "pam", "square-10", "--controllers", "pi,nmpc", "--duration", "0.3", "--no-plots",
              "--quiet", "--set", "pi.kp=0.07", "--reference", path]
    docs = {}
    for workers in ("1", "2"):
        code, _, err = _run(capsys, common + ["--workers", workers, "--out", str(tmp_path / workers),
                                              "--json", str(tmp_path / f"{workers}.json")])
        assert code == 0, err
        docs[workers] = json.loads((tmp_path / f"{workers}.json").read_text())
    one, two = ([(r["scenario"], r["controller"], r["metrics"]) for r in docs[w]["runs"]] for w in ("1", "2"))
    assert one == two and [c for _, c, _ in one] == ["pi", "nmpc"]
    for name in ("ref__pi.csv", "ref__nmpc.csv"):
        assert (tmp_path / "1" / "runs" / name).read_text() == (tmp_path / "2" / "runs" / name).read_text()


def test_default_workers_start_processes_only_for_long_work():
    from hystmpc.experiments.cli.workers import MIN_SAMPLES_PER_WORKER, default_workers
    assert default_workers(MIN_SAMPLES_PER_WORKER - 1, 8) == 1  # a short compare: no process to start
    assert default_workers(100 * MIN_SAMPLES_PER_WORKER, 1) == 1  # one run
    assert 1 <= default_workers(100 * MIN_SAMPLES_PER_WORKER, 8) <= min(8, os.cpu_count() or 1)
