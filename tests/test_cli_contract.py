"""The command-line contract, case by case: bad input exits 2 with one line naming the option
or file, the bad value and what is allowed; nothing is left behind; output paths are checked
before any work starts.

Each case: the arguments (``{tmp}`` is a fresh folder holding the files below), the exit
code and a phrase the message must contain.
"""

from __future__ import annotations

import json

import pytest

from hystmpc.experiments.cli import main

SHORT = ["--duration", "0.2", "--no-plots"]
RUN = ["run", "pam", "square-20", "--controller", "pi"]
FILES = {
    "ragged.csv": "t,angle\n0,0\n0.1,10,3\n",
    "short.csv": "t,angle\n0,0\n1,10\n2,10\n",
    "binary.csv": b"\x00\x81\xff\xfe t,angle",
    "spec_perturb.toml": 'bench = "pam"\nperturb = 3\n',
    "spec_huge.toml": 'bench = "pam"\n[perturb]\n"plant.payload_kg" = 0.2\nsamples = 1000000000\n',
    "spec_long.toml": 'bench = "pam"\nduration = 1e9\n',
    "spec_inf.toml": 'bench = "pam"\nduration = inf\n',
    "spec_ok.toml": 'bench = "pam"\nscenarios = ["square-20"]\ncontrollers = ["pi"]\nduration = 0.2\n',
    "a_file": "not a folder\n",
    "force.csv": "t,force\n0,1\n0.01,1.5\n",
    "full/keep.txt": "a result the user keeps\n",
    "corrupt/sweep.json": "{not json",
}
"""Files under {tmp}, made fresh for each case."""

CASES = [
    # durations and seeds
    (RUN + ["--duration", "0.001", "--no-plots"], 2, "--duration 0.001 s is shorter than 2 samples at 0.02 s"),
    (RUN + ["--duration", "inf", "--no-plots"], 2, "--duration must be a finite number of seconds > 0, got inf"),
    (RUN + ["--duration", "nan", "--no-plots"], 2, "--duration must be a finite number of seconds > 0, got nan"),
    (RUN + ["--duration", "-1", "--no-plots"], 2, "--duration must be a finite number of seconds > 0, got -1"),
    (RUN + ["--duration", "1e9", "--no-plots"], 2, "above the limit of 1,000,000 per run; pass --force"),
    (RUN + ["--seed", "-1"] + SHORT, 2, "--seed must be an integer >= 0, got -1"),
    (RUN + ["--seed", "x"] + SHORT, 2, "argument --seed: invalid int value: 'x'"),
    # work limits
    (["run", "pam", "square-20", "--controller", "nmpc", "--set", "nmpc.horizon=10000"] + SHORT, 2,
     "nmpc.horizon=10000 is above the limit of 200 samples; pass --force"),
    (["codegen", "pam", "--set", "nmpc.horizon=500", "--out", "{tmp}/cg"], 2, "nmpc.horizon=500 is above the limit"),
    (["speed", "pam", "--duration", "0.001", "--out", "{tmp}/sp"], 2, "shorter than 2 samples"),
    # reference files
    (["run", "pam", "--controller", "pi", "--reference", "{tmp}/ragged.csv", "--no-plots"], 2,
     "reference file '{tmp}/ragged.csv', line 3: 3 fields, the header has 2"),
    (["run", "pam", "--controller", "pi", "--reference", "{tmp}/binary.csv", "--no-plots"], 2,
     "reference file '{tmp}/binary.csv' cannot be read as CSV text"),
    (["run", "pam", "--controller", "pi", "--reference", "{tmp}/full", "--no-plots"], 2,
     "reference file '{tmp}/full' cannot be read as CSV text"),
    (["run", "pam", "--controller", "pi", "--reference", "{tmp}/none.csv", "--no-plots"], 2,
     "reference file '{tmp}/none.csv' does not exist"),
    (["run", "pam", "--controller", "pi", "--reference", "{tmp}/short.csv", "--duration", "10", "--no-plots"], 2,
     "--duration 10 s is longer than the reference file '{tmp}/short.csv' (2 s); allowed: up to 2 s"),
    (["run", "pam", "--controller", "pi", "--no-plots"], 2, "name a scenario (square-10"),
    # options that would otherwise be ignored, and the command line itself
    ([], 2, "name a command: list, run, compare"),
    (["compare", "pam", "sine-30", "--controllers=", "--no-plots"], 2, "--controllers is empty; allowed: a "
     "comma-separated list of pi, pi-hc"),
    (["compare", "pam", "--no-plots", "sine-30", "--bogus"], 2, "unrecognized arguments: --bogus"),
    (["codegen", "pam", "--duration", "5", "--out", "{tmp}/cg"], 2, "--duration 5 sets the length of the --verify "
     "run; add --verify"),
    (["identify", "prandtl-ishlinskii", "{tmp}/none.csv", "--dynamics-data", "{tmp}/none.csv"], 2,
     "fits the dynamics, but --dynamics is none; allowed with it: --dynamics first-order or second-order"),
    (["identify", "prandtl-ishlinskii", "{tmp}/none.csv", "--max-delay", "5"], 2,
     "--max-delay 5 bounds the dynamics' dead time, but --dynamics is none"),
    (["identify", "reluctance", "--units", "N"], 2, "--units is for a model family; 'identify reluctance' takes"),
    (["run", "reluctance", "ramp-1.2mm", "--controller", "hyst-inverse", "--reference", "{tmp}/force.csv",
      "--set", "rig.gap_mm=1.4", "--no-plots"], 2, "--set rig.gap_mm conflicts with scenario 'ramp-1.2mm', whose "
     "condition rig.gap_mm=1.2 the reference file runs under; drop the scenario name"),
    (["run", "reluctance", "ramp-1.2mm", "--controller", "nmpc", "--set", "solver.rti.condensed=false", "--no-plots",
      "--duration", "0.01"], 2, "solver.rti.line_search=descent applies to the condensed step only"),
    (["run", "dea", "single-sine", "--controller", "nmpc", "--set", "nmpc.runtime=c", "--no-plots", "--duration",
      "0.1"], 2, "nmpc.runtime=c runs the generated controller, whose solver is the RTI step; nmpc.solver is 'gn'"),
    (RUN + SHORT + ["--set", "nmpc.inverse_plan=dynamic"], 2,
     "inverse_plan 'dynamic' is unknown; allowed: static, linear-mpc"),
    (RUN + SHORT + ["--set", "nmpc.runtime=fortran"], 2, "runtime 'fortran' is unknown; allowed: python, c, auto"),
    (["run", "pam", "square-20", "--controller", "nmpc", "--set", "nmpc.multistart=true", "--set", "nmpc.solver=sqp",
      "--no-plots", "--duration", "0.1"], 2, "nmpc.multistart compares the costs that solver gn or the RTI step "
     "reports, from the shifted plan and from the inverse model's inputs; nmpc.solver is 'sqp' (allowed with it: gn, "
     "rti, rti-c; or set nmpc.multistart=false)"),
    (["run", "pam", "square-20", "--controller", "nmpc", "--set", "nmpc.multistart=true", "--set",
      "solver.rti.condensed=false", "--no-plots", "--duration", "0.1"], 2, "solver.rti.condensed=false (multiple "
     "shooting only) plans the states too: drop it, or set nmpc.multistart=false"),
    (["codegen", "reluctance", "--set", "nmpc.runtime=python", "--out", "{tmp}/cg"], 2, "drop the setting here "
     "(this bench's default: auto)"),
    (["compare", "dea", "--set", "nmpc.solver=ipopt", "--no-plots", "--out", "{tmp}/cmp"], 2,  # dea: two starts
     "nmpc.solver is 'ipopt' (allowed with it: gn, rti, rti-c; or set nmpc.multistart=false)"),
    (["speed", "reluctance", "--set", "nmpc.runtime=python"], 2, "nmpc.runtime=python chooses where run, compare and "
     "sweep run the controller; codegen writes the generated controller and speed times the solver variants"),
    # output paths, checked before any work
    (RUN + SHORT + ["--out", "{tmp}/a_file"], 2, "--out '{tmp}/a_file' is a file; give a folder"),
    (RUN + SHORT + ["--out", "{tmp}/full"], 2, "--out '{tmp}/full' already holds files; pass --overwrite"),
    (RUN + SHORT + ["--out", "{tmp}/a_file/sub"], 2, "--out '{tmp}/a_file/sub' cannot be written"),
    (RUN + SHORT + ["--out", "{tmp}/o", "--json", "{tmp}/full"], 2, "--json '{tmp}/full' is a folder"),
    (RUN + SHORT + ["--out", "{tmp}/o", "--json", "{tmp}/a_file/x.json"], 2,
     "--json '{tmp}/a_file/x.json' cannot be written"),
    (["codegen", "compliant", "--out", "{tmp}/a_file"], 2, "--out '{tmp}/a_file' is a file"),
    (["speed", "pam", "--out", "{tmp}/full"], 2, "already holds files; pass --overwrite"),
    # sweep specs and resumes
    (["sweep", "{tmp}/spec_perturb.toml", "--out", "{tmp}/sw"], 2, "perturb must be a table of KEY = relative "
     "amplitude, plus samples = N; got 3"),
    (["sweep", "{tmp}/spec_huge.toml", "--out", "{tmp}/sw"], 2, "above the limit of 10,000; pass --force"),
    (["sweep", "{tmp}/spec_long.toml", "--out", "{tmp}/sw"], 2, "above the limit of 1,000,000 per run"),
    (["sweep", "{tmp}/spec_inf.toml", "--out", "{tmp}/sw"], 2, "duration must be a finite number of seconds"),
    (["sweep", "{tmp}/spec_ok.toml", "--retry-failed", "--out", "{tmp}/sw"], 2, "use it with --resume"),
    (["sweep", "{tmp}/spec_ok.toml", "--resume", "--out", "{tmp}/corrupt"], 2,
     "sweep.json cannot be read (JSONDecodeError)"),
    (["sweep", "{tmp}/spec_ok.toml", "--out", "{tmp}/full"], 2, "is not empty and holds no sweep"),
    (["sweep", "{tmp}/spec_ok.toml", "--out", "{tmp}/a_file"], 2, "--out '{tmp}/a_file' is a file"),
    (["sweep", "{tmp}/spec_ok.toml", "--out", "{tmp}/sw", "--json", "{tmp}/full"], 2, "--json '{tmp}/full' is a "
     "folder"),
    # --set
    (RUN + SHORT + ["--set", "pi.kpp=1"], 2, "unknown --set key 'pi.kpp'; did you mean 'pi.kp'?"),
    (RUN + SHORT + ["--set", "plant.nothing_like_it=1"], 2, "'hystmpc list BENCH' shows every key"),
    (["run", "compliant", "sine-2", "--controller", "pid", "--set", "plant.hysteresis.ascending=1,2,3"] + SHORT, 2,
     "expected comma-separated numbers, 2 per point"),
    (["run", "compliant", "sine-2", "--controller", "pid", "--set", "plant.hysteresis.ascending=1,2,3,1"] + SHORT,
     2, "points must increase strictly in s and in tau"),
    # inf only where the setting's own default is inf ("none"); the extra RTI step's tolerance
    (RUN + SHORT + ["--set", "nmpc.q_output=inf"], 2, "--set nmpc.q_output='inf': expected a finite number"),
    (RUN + SHORT + ["--set", "solver.rti.extra_step_tolerance=0"], 2, "extra_step_tolerance must be > 0 (inf: no "
     "extra step), got 0.0"),
    (RUN + SHORT + ["--set", "solver.rti.extra_step_tolerance=nan"], 2, "expected a number or inf"),
    (["run", "reluctance", "ramp-1.2mm", "--controller", "nmpc", "--set", "solver.rti.condensed=false", "--set",
      "solver.rti.line_search=best", "--no-plots", "--duration", "0.01"], 2,
     "solver.rti.extra_step_tolerance=1e-06 applies to the condensed step only"),
]


def _files(tmp):
    for name, content in FILES.items():
        path = tmp / name
        path.parent.mkdir(parents=True, exist_ok=True)
        if isinstance(content, bytes):
            path.write_bytes(content)
        else:
            path.write_text(content)


@pytest.mark.parametrize("argv, code, phrase", CASES, ids=[" ".join(c[0])[:70] for c in CASES])
def test_contract(capsys, tmp_path, argv, code, phrase):
    _files(tmp_path)
    before = sorted(p.relative_to(tmp_path) for p in tmp_path.rglob("*"))
    argv = [a.replace("{tmp}", str(tmp_path)) for a in argv]
    assert main(argv) == code
    out, err = capsys.readouterr()
    assert out == ""
    assert err.count("\n") == 1 and err.startswith("hystmpc: error:"), err
    assert phrase.replace("{tmp}", str(tmp_path)) in err
    after = sorted(p.relative_to(tmp_path) for p in tmp_path.rglob("*"))
    assert after == before  # nothing created, nothing half-written


def test_json_dash_writes_the_document_to_standard_output(capsys, tmp_path):
    assert main(RUN + SHORT + ["--out", str(tmp_path / "o"), "--json", "-"]) == 0
    out, _ = capsys.readouterr()
    doc = json.loads(out)
    assert doc["schema"] == "hystmpc.results/1" and doc["runs"][0]["controller"] == "pi"
    assert not (tmp_path / "-").exists()


def test_overwrite_writes_into_a_used_folder(capsys, tmp_path):
    out = str(tmp_path / "o")
    assert main(RUN + SHORT + ["--out", out, "--quiet"]) == 0
    assert main(RUN + SHORT + ["--out", out, "--quiet"]) == 2
    assert main(RUN + SHORT + ["--out", out, "--quiet", "--overwrite"]) == 0


def test_force_lifts_a_work_limit(capsys, tmp_path):
    argv = ["run", "pam", "square-20", "--controller", "pi", "--set", "nmpc.horizon=201", "--duration", "0.1",
            "--no-plots", "--quiet", "--out", str(tmp_path / "o")]
    assert main(argv) == 2
    assert main(argv + ["--force"]) == 0


def test_list_bench_shows_keys_with_defaults_and_units(capsys):
    assert main(["list", "pam"]) == 0
    out = capsys.readouterr().out
    assert "plant.dp_limit" in out and "6  — Valve command range ±dp_limit (bar)" in out
    assert "nmpc.horizon" in out and "Prediction horizon N in samples" in out
    assert main(["list", "pam", "--json"]) == 0
    keys = {k["key"]: k for k in json.loads(capsys.readouterr().out)["benches"]["pam"]["keys"]}
    assert keys["nmpc.horizon"]["default"] == 20


def test_scenario_names_may_follow_options(tmp_path):
    out = tmp_path / "o"
    assert main(["compare", "pam", "--no-plots", "sine-30", "--controllers", "pi", "--duration", "0.2",
                 "--out", str(out), "--quiet"]) == 0
    doc = json.loads((out / "results.json").read_text())
    assert [r["scenario"] for r in doc["runs"]] == ["sine-30"]


def test_version(capsys):
    with pytest.raises(SystemExit) as stop:
        main(["--version"])
    assert stop.value.code == 0
    from hystmpc.experiments.report import version
    assert capsys.readouterr().out.strip() == f"hystmpc {version()}"


def test_a_reference_file_keeps_the_named_scenarios_conditions(tmp_path):
    from hystmpc.experiments.benches import get_bench
    from hystmpc.experiments.cli.common import scenario_to_run
    bench = get_bench("reluctance")
    named = bench.scenarios["ramp-1.2mm"]
    assert named.conditions  # the gap it runs at
    ref = tmp_path / "ref.csv"
    ref.write_text("t,force\n0,1\n0.01,1.5\n")
    assert scenario_to_run(bench, "ramp-1.2mm", str(ref)).conditions == named.conditions
    assert scenario_to_run(bench, None, str(ref)).conditions == ()


def test_identify_refuses_a_folder_as_its_model_file(capsys, tmp_path):
    from pathlib import Path
    slow = Path(__file__).parents[1] / "docs" / "examples" / "piezo" / "slow.csv"
    assert main(["identify", "prandtl-ishlinskii", str(slow), "--out", f"{tmp_path}/new/", "--no-plots"]) == 2
    assert "is a folder; name the model document's file" in capsys.readouterr().err
    assert not (tmp_path / "new").exists()
