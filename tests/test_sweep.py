"""Sweeps: spec checking, seeded perturbations, summaries, failed runs, kill + resume, local vs Dask."""

from __future__ import annotations

import json
import os
import signal
import subprocess
import sys
import time
from pathlib import Path

import pytest

from hystmpc.experiments.cli import main
from hystmpc.experiments.sweep import (
    make_tasks,
    perturbation_factors,
    read_records,
    run_sweep,
    scaled_assignments,
)
from hystmpc.experiments.sweep_spec import SweepSpec, load_spec
from hystmpc.experiments.sweep_summary import summarize


def _spec_file(tmp_path: Path, text: str, name: str = "spec.toml") -> Path:
    path = tmp_path / name
    path.write_text(text)
    return path


PAM_SMALL = """
bench = "pam"
scenarios = ["square-20"]
controllers = ["pi", "pi-hc", "nmpc"]
seeds = [0, 1]
duration = 2.0
[perturb]
"plant.torque_per_bar" = 0.2
"plant.hysteresis.k" = 0.2
samples = 2
"""


@pytest.mark.parametrize("body, needle", [
    ('bench = "pam"\nsamples = 3\n', "unknown key 'samples'; allowed: bench, scenarios"),
    ('bench = "nosuch"\n', "bench: unknown bench 'nosuch'; allowed: pam, compliant, reluctance, dea"),
    ('bench = "pam"\nscenarios = ["square-99"]\n', "unknown scenario 'square-99'; allowed: square-10"),
    ('bench = "pam"\ncontrollers = ["lqr"]\n', "unknown controller 'lqr'; allowed: pi, pi-hc, inverse-lmpc, nmpc"),
    ('bench = "pam"\nseeds = [1, 1]\n', "seeds must be a non-empty list of distinct integers"),
    ('bench = "pam"\n[perturb]\n"plant.nosuch" = 0.1\n', "unknown perturb key 'plant.nosuch'; group plant has 22 keys"),
    ('bench = "pam"\n[perturb]\n"plant.substeps" = 0.1\n', "'plant.substeps' is not a real-valued parameter"),
    ('bench = "pam"\n[perturb]\n"plant.damping" = 1.5\n', "must be a number in (0, 1), got 1.5"),
    ('bench = "pam"\n[perturb]\n"plant.damping" = 0.1\nsamples = 0\n', "perturb.samples must be an integer >= 1"),
    ('bench = "reluctance"\nscenarios = ["ramp-1.2mm"]\n[perturb]\n"rig.gap_mm" = 0.1\n',
     "'rig.gap_mm' is fixed by the scenarios"),
    ('bench = "pam"\nset = ["plant.damping=abc"]\n', "--set plant.damping='abc': expected a finite number"),
    ('bench = "pam"\nduration = -1\n', "duration must be a finite number of seconds > 0"),
    ('bench = "pam"\nscenarios = [\n', "not valid TOML"),
])
def test_bad_spec_exits_2_with_one_line(tmp_path, capsys, body, needle):
    spec = _spec_file(tmp_path, body)
    code = main(["sweep", str(spec), "--out", str(tmp_path / "out")])
    err = capsys.readouterr().err
    assert code == 2
    assert needle in err
    assert err.count("\n") == 1
    assert not (tmp_path / "out").exists()


@pytest.mark.parametrize("argv, needle", [
    (["--executor", "ray"], "unknown executor 'ray'; allowed: local, dask"),
    (["--workers", "0"], "--workers must be >= 1"),
    (["--resume"], "--resume needs --out DIR"),
    (["--scheduler", "tcp://x:8786", "--out", "o"], "use it with --executor dask"),
])
def test_bad_sweep_options_exit_2(tmp_path, capsys, monkeypatch, argv, needle):
    monkeypatch.chdir(tmp_path)
    spec = _spec_file(tmp_path, PAM_SMALL)
    code = main(["sweep", str(spec), *argv])
    assert code == 2
    assert needle in capsys.readouterr().err


def test_missing_spec_file_exits_2(tmp_path, capsys):
    assert main(["sweep", str(tmp_path / "nope.toml")]) == 2
    assert "not found" in capsys.readouterr().err


def test_tasks_are_the_full_factorial_with_shared_seeded_plants(tmp_path):
    spec = load_spec(_spec_file(tmp_path, PAM_SMALL))
    tasks = make_tasks(spec)
    assert spec.n_runs == len(tasks) == 1 * 3 * 2 * 2
    assert len({t.run_id for t in tasks}) == len(tasks)
    # one plant per sample, the same for every controller and seed; reproducible, inside ±20 %
    for sample in range(spec.samples):
        factors = {tuple(sorted(t.factors.items())) for t in tasks if t.sample == sample}
        overrides = {t.overrides for t in tasks if t.sample == sample}
        assert len(factors) == len(overrides) == 1
        assert perturbation_factors(spec, sample) == dict(next(iter(factors)))
        assert all(0.8 <= f <= 1.2 for f in perturbation_factors(spec, sample).values())
    assert perturbation_factors(spec, 0) != perturbation_factors(spec, 1)


def test_tuple_parameters_scale_element_wise():
    from hystmpc.experiments.benches import get_bench
    from hystmpc.experiments.config import apply_overrides, get_value
    config = get_bench("pam").defaults()
    assignments = scaled_assignments(config, {"plant.hysteresis.k": 1.1, "plant.damping": 0.9})
    new = apply_overrides(config, assignments)
    old_k, new_k = get_value(config, "plant.hysteresis.k"), get_value(new, "plant.hysteresis.k")
    assert new_k == pytest.approx(tuple(1.1 * k for k in old_k), rel=1e-15)
    assert get_value(new, "plant.damping") == pytest.approx(0.9 * get_value(config, "plant.damping"), rel=1e-15)


def _record(scenario, controller, seed, sample, rmse, status="ok"):
    run_id = f"{scenario}__{controller}__s{seed}__p{sample:04d}"
    record = {"run_id": run_id, "scenario": scenario, "controller": controller, "seed": seed, "sample": sample,
              "status": status}
    if status == "ok":
        record["metrics"] = {"rmse": rmse, "mae": rmse / 2, "max_abs_error": 3 * rmse}
    else:
        record["error"] = "RuntimeError: boom"
    return run_id, record


def test_summary_counts_wins_per_case_and_ignores_order():
    spec = SweepSpec(bench="pam", scenarios=("a",), controllers=("pi", "pi-hc", "nmpc"), seeds=(0,), samples=4)
    table = [  # (sample, pi, pi-hc, nmpc)
        (0, 1.0, 2.0, 0.5),   # beats both
        (1, 1.0, 0.4, 0.5),   # beats pi only
        (2, 1.0, 2.0, None),  # nmpc failed: loses against both
        (3, None, 2.0, 1.5),  # pi failed: compared with pi-hc only, no best-baseline verdict
    ]
    records = {}
    for sample, *values in table:
        for controller, v in zip(spec.controllers, values, strict=True):
            key, rec = _record("a", controller, 0, sample, v, "ok" if v is not None else "error")
            records[key] = rec
    summary = summarize(spec, records)
    rates = summary["win_rates"]["all"]
    assert rates["vs"]["pi"] == {"wins": 2, "compared": 3, "rate": 2 / 3}
    assert rates["vs"]["pi-hc"] == {"wins": 2, "compared": 4, "rate": 0.5}
    assert rates["vs_best_baseline"] == {"wins": 1, "compared": 3, "rate": 1 / 3}
    assert summary["runs_failed"] == 2
    nmpc = next(g for g in summary["groups"] if g["controller"] == "nmpc")
    assert nmpc["failed"] == 1 and nmpc["rmse"]["median"] == pytest.approx(0.5)
    assert summarize(spec, dict(reversed(list(records.items())))) == summary


def test_a_run_that_raises_is_recorded_and_the_sweep_goes_on(tmp_path):
    # gain_variation must stay below 1: perturbing 0.95 by ±10 % breaks some plants, not others
    spec_path = _spec_file(tmp_path, """
bench = "dea"
scenarios = ["single-sine"]
controllers = ["pid"]
duration = 0.05
set = ["plant.gain_variation=0.95"]
[perturb]
"plant.gain_variation" = 0.1
samples = 6
""")
    spec = load_spec(spec_path)
    outcome = run_sweep(spec, tmp_path / "out", workers=1, plots=False, quiet=True)
    records = read_records(tmp_path / "out" / "records")
    assert len(records) == 6
    failed = [r for r in records.values() if r["status"] == "error"]
    broken = [s for s in range(6) if 0.95 * perturbation_factors(spec, s)["plant.gain_variation"] >= 1]
    assert sorted(r["sample"] for r in failed) == broken and 0 < len(broken) < 6
    assert all("gain_variation must be in [0, 1)" in r["error"] for r in failed)
    assert outcome.summary["runs_failed"] == len(broken) == outcome.failed


def test_resume_refuses_another_spec_and_a_fresh_run_refuses_an_old_folder(tmp_path, capsys):
    spec_path = _spec_file(tmp_path, 'bench = "pam"\ncontrollers = ["pi"]\nduration = 0.1\n')
    out = tmp_path / "out"
    assert main(["sweep", str(spec_path), "--out", str(out), "--quiet", "--no-plots"]) == 0
    assert main(["sweep", str(spec_path), "--out", str(out), "--quiet"]) == 2
    assert "already holds a sweep; add --resume" in capsys.readouterr().err
    assert main(["sweep", str(spec_path), "--out", str(out), "--resume", "--quiet", "--duration", "0.2"]) == 2
    err = capsys.readouterr().err
    assert "spec differs from the one" in err and "changed: duration" in err
    assert main(["sweep", str(spec_path), "--out", str(tmp_path / "empty"), "--resume"]) == 2
    assert "nothing to resume" in capsys.readouterr().err


def _cli(*args) -> list[str]:
    return [sys.executable, "-m", "hystmpc.experiments", "sweep", *args]


def test_sigkill_half_way_then_resume_gives_every_record_once(tmp_path):
    spec_path = _spec_file(tmp_path, """
bench = "pam"
scenarios = ["square-10", "square-20"]
controllers = ["pi", "pi-hc"]
seeds = [0, 1, 2, 3, 4]
duration = 5.0
[perturb]
"plant.damping" = 0.2
samples = 4
""")
    expected = load_spec(spec_path).n_runs
    out = tmp_path / "out"
    records_dir = out / "records"
    log = tmp_path / "stderr.txt"
    with open(log, "w") as stderr:
        proc = subprocess.Popen(_cli(str(spec_path), "--out", str(out), "--workers", "1", "--no-plots", "--quiet"),
                                start_new_session=True, stdout=subprocess.DEVNULL, stderr=stderr)
    deadline = time.monotonic() + 120
    while time.monotonic() < deadline and len(list(records_dir.glob("*.json"))) < 10:
        assert proc.poll() is None, log.read_text()
        time.sleep(0.02)
    os.killpg(proc.pid, signal.SIGKILL)
    proc.wait()
    before = {p.name: p.read_bytes() for p in records_dir.glob("*.json")}
    assert 10 <= len(before) < expected, "the sweep must be killed half-way"
    assert not (out / "summary.json").exists()

    done = subprocess.run(_cli(str(spec_path), "--out", str(out), "--resume", "--workers", "1", "--no-plots",
                               "--quiet"), capture_output=True, text=True, timeout=300)
    assert done.returncode == 0, done.stderr
    after = {p.name: p.read_bytes() for p in records_dir.glob("*.json")}
    assert len(after) == expected
    assert {json.loads(b)["run_id"] for b in after.values()} == {t.run_id for t in make_tasks(load_spec(spec_path))}
    assert all(after[name] == content for name, content in before.items()), "finished runs must not be redone"
    assert not list(records_dir.glob(".*.tmp"))
    summary = json.loads((out / "summary.json").read_text())
    assert summary["runs_recorded"] == expected and summary["runs_failed"] == 0
    assert summary["run_info"]["skipped"] == len(before)


@pytest.mark.slow  # a Dask LocalCluster takes 15 s to start and stop
def test_local_pool_and_dask_local_cluster_give_the_same_summary(tmp_path):
    pytest.importorskip("distributed")
    spec_path = _spec_file(tmp_path, PAM_SMALL)
    summaries = []
    for executor in ("local", "dask"):
        out = tmp_path / executor
        done = subprocess.run(_cli(str(spec_path), "--out", str(out), "--executor", executor, "--workers", "2",
                                   "--no-plots", "--quiet"), capture_output=True, text=True, timeout=300)
        assert done.returncode == 0, done.stderr
        summary = json.loads((out / "summary.json").read_text())
        assert summary.pop("run_info")["executor"] == executor
        summaries.append(summary)
    assert summaries[0]["runs_recorded"] == 12 and summaries[0]["runs_failed"] == 0
    assert summaries[0] == summaries[1]


@pytest.mark.filterwarnings("ignore")  # the cluster's own shutdown chatter is not under test
def test_dask_executor_uses_an_existing_scheduler(tmp_path):
    distributed = pytest.importorskip("distributed")
    spec_path = _spec_file(tmp_path, 'bench = "pam"\ncontrollers = ["pi", "pi-hc"]\nseeds = [0, 1, 2]\n'
                                     'duration = 1.0\n')
    with distributed.LocalCluster(n_workers=1, threads_per_worker=1, processes=True, dashboard_address=None) as cluster:
        done = subprocess.run(_cli(str(spec_path), "--out", str(tmp_path / "out"), "--executor", "dask",
                                   "--scheduler", cluster.scheduler_address, "--no-plots", "--quiet"),
                              capture_output=True, text=True, timeout=300)
    assert done.returncode == 0, done.stderr
    summary = json.loads((tmp_path / "out" / "summary.json").read_text())
    assert summary["runs_recorded"] == 6 and summary["run_info"]["scheduler"] == cluster.scheduler_address


def test_resume_sets_bad_records_aside_retries_failures_and_exits_1_when_all_failed(tmp_path, capsys):
    spec = _spec_file(tmp_path, 'bench = "pam"\nscenarios = ["square-20"]\ncontrollers = ["pi"]\nduration = 0.2\n')
    out = tmp_path / "out"
    base = ["sweep", str(spec), "--out", str(out), "--workers", "1", "--no-plots", "--quiet"]
    assert main(base) == 0
    records = out / "records"
    (run_id,) = [p.stem for p in records.glob("*.json")]
    good = json.loads((records / f"{run_id}.json").read_text())
    # a failed run, a record that does not parse, one of another spec
    (records / f"{run_id}.json").write_text(json.dumps({**good, "status": "error", "error": "RuntimeError: boom"}))
    (records / "square-20__pi__s7__p0000.json").write_text(json.dumps({**good, "run_id": "square-20__pi__s7__p0000"}))
    (records / "broken__pi__s0__p0000.json").write_text("{trunc")
    capsys.readouterr()
    assert main(base + ["--resume"]) == 1  # the only run failed
    err = capsys.readouterr().err
    assert "every run of the sweep failed (1)" in err
    assert "broken__pi__s0__p0000.json does not parse (JSONDecodeError): moved to" in err
    assert "square-20__pi__s7__p0000.json not a run of this sweep's spec" in err
    assert sorted(p.name for p in (out / "set-aside").iterdir()) == ["broken__pi__s0__p0000.json",
                                                                     "square-20__pi__s7__p0000.json"]
    summary = json.loads((out / "summary.json").read_text())
    assert summary["runs_recorded"] == 1 and summary["runs_failed"] == 1
    assert main(base + ["--resume", "--retry-failed"]) == 0
    redone = json.loads((records / f"{run_id}.json").read_text())
    assert redone["status"] == "ok" and redone["metrics"] == good["metrics"]
