"""Your own plant (``--plant MODULE:CALLABLE``, ``Bench.run(plant=...)``): the controllers run
against it, not against the bench's plant; the guard stays between them; a plant that does
not fit the bench is refused with one line (exit 2) before anything runs."""

import json
import textwrap

import numpy as np
import pytest

from hystmpc.experiments.benches import get_bench
from hystmpc.experiments.cli import main

RIG = textwrap.dedent('''
    from hystmpc.experiments.benches import get_bench
    from hystmpc.plants.base import Measurement

    def heavy():
        """pam's plant with a 2.5 kg payload: what --set plant.payload_kg=2.5 builds."""
        bench = get_bench("pam")
        plant = bench.build_plant(bench.configure(["plant.payload_kg=2.5"]))
        plant.description = "pam joint, 2.5 kg"
        return plant

    class Recording:
        """pam's own plant, keeping every input it receives."""
        def __init__(self):
            bench = get_bench("pam")
            self.inner = bench.build_plant(bench.configure())
            self.sample_period = self.inner.sample_period
            self.received = []
        def reset(self, seed):
            return self.inner.reset(seed)
        def step(self, u):
            self.received.append(u)
            return self.inner.step(u)

    RECORDING = Recording()

    def recording():
        return RECORDING

    class Slow:
        sample_period = 0.04
        def reset(self, seed):
            return Measurement(0.0, 0.0, {"pressure": 0.0})
        def step(self, u):
            return Measurement(0.0, 0.0, {"pressure": 0.0})

    class Blind(Slow):
        sample_period = 0.02
        def reset(self, seed):
            return Measurement(0.0, 0.0)

    def slow():
        return Slow()

    def blind():
        return Blind()

    def broken():
        return 42

    class Blank(Slow):
        sample_period = 0.02
        def reset(self, seed):
            return Measurement(0.0, float("nan"), {"pressure": 0.0})

    def blank():
        return Blank()

    def unplugged():
        raise OSError("no device on /dev/ttyUSB0")

    class Failing(Recording):
        def step(self, u):
            if len(self.received) == 20:
                raise OSError("serial timeout")
            return super().step(u)

    def failing():
        return Failing()

    class Blinding(Recording):
        def step(self, u):
            measured = super().step(u)
            if len(self.received) > 20:
                measured.y = float("nan")
            return measured

    def blinding():
        return Blinding()
''')


@pytest.fixture
def rig(tmp_path, monkeypatch):
    (tmp_path / "my_rig.py").write_text(RIG)
    monkeypatch.chdir(tmp_path)
    monkeypatch.syspath_prepend(str(tmp_path))
    yield tmp_path


def _metrics(capsys, argv):
    code = main(argv + ["--duration", "3", "--no-plots", "--quiet"])
    assert code == 0, capsys.readouterr().err
    out = argv[argv.index("--out") + 1]
    return json.loads((__import__("pathlib").Path(out) / "results.json").read_text())["runs"][0]


def test_the_run_is_on_your_plant(rig, capsys):
    """--plant gives the numbers of the bench's plant with the same change made by --set, not
    those of the bench's default plant; the result names the plant and drops the paper's figure."""
    common = ["run", "pam", "square-10", "--controller", "pi"]
    own = _metrics(capsys, common + ["--plant", "my_rig:heavy", "--out", "own"])
    same = _metrics(capsys, common + ["--set", "plant.payload_kg=2.5", "--out", "set"])
    default = _metrics(capsys, common + ["--out", "default"])
    assert own["metrics"]["rmse"] == same["metrics"]["rmse"]
    assert own["metrics"]["rmse"] != default["metrics"]["rmse"]
    assert own["parameters"]["plant"] == {"own_plant": "pam joint, 2.5 kg"}


def test_python_route_matches_the_command_line(rig, capsys):
    import my_rig

    bench = get_bench("pam")
    run = bench.run("square-10", "pi", duration=3.0, plant=my_rig.heavy())
    cli = _metrics(capsys, ["run", "pam", "square-10", "--controller", "pi", "--plant", "my_rig:heavy", "--out", "o"])
    assert run.metrics["rmse"] == cli["metrics"]["rmse"]
    assert run.parameters["plant"] == cli["parameters"]["plant"] == {"own_plant": "pam joint, 2.5 kg"}
    with pytest.raises(ValueError, match="sample_period 0.04 s differs"):
        bench.run("square-10", "pi", duration=3.0, plant=my_rig.slow())


def test_the_guard_stays_between_the_controller_and_your_plant(rig):
    """A controller asking for 100 bar, then NaN, then -100 bar: your plant receives only
    inputs inside pam's ±6 bar (the guard clips, and holds the last input on NaN)."""
    import dataclasses

    import my_rig

    class Wild:
        def __init__(self):
            self.k = 0
        def reset(self):
            self.k = 0
        def step(self, measurement, ref_window):
            self.k += 1
            return (100.0, float("nan"), -100.0)[self.k % 3]
        def stats(self):
            return None

    bench = get_bench("pam")
    prepared = bench.prepare("square-10", "pi", bench.configure(), plant=my_rig.RECORDING)
    run = bench.run("square-10", "pi", duration=1.0, prepared=dataclasses.replace(prepared, controller=Wild()))
    received = np.array(my_rig.RECORDING.received)
    lo, hi = bench.input_bounds
    assert run.guard["clips"] > 0 and len(received) == run.metrics["n_samples"] - 1
    assert np.all(np.isfinite(received)) and received.min() >= lo and received.max() <= hi
    assert received.max() == hi and received.min() == lo


@pytest.mark.parametrize("spec, needle", [
    ("my_rig:slow", "sample_period 0.04 s differs from the bench's 0.02 s"),
    ("my_rig:blind", "lacks sensor(s) 'pressure'"),
    ("my_rig:broken", "lacks sample_period, reset, step of the Plant protocol"),
    ("my_rig:blank", "first measurement y is nan; allowed: a finite number"),
    ("my_rig:unplugged", "unplugged() raised OSError: no device on /dev/ttyUSB0"),
    ("my_rig:nothing", "has no callable 'nothing'"),
    ("my_rig", "is not MODULE:CALLABLE"),
    ("no_such_module:make", "cannot import 'no_such_module'"),
    ("missing.py:make", "cannot import 'missing.py' (no file 'missing.py')"),
])
def test_a_plant_that_does_not_fit_is_refused(rig, capsys, spec, needle):
    code = main(["run", "pam", "square-10", "--controller", "pi", "--plant", spec, "--out", "x"])
    err = capsys.readouterr().err
    assert code == 2 and err.count("\n") == 1 and needle in err, err
    assert not (rig / "x").exists()


def test_settings_of_the_replaced_plant_are_refused(rig, capsys):
    code = main(["compare", "pam", "--plant", "my_rig:heavy", "--set", "plant.payload_kg=3", "--out", "x"])
    err = capsys.readouterr().err
    assert code == 2 and "--set plant.payload_kg sets the bench's simulated plant, which --plant replaces" in err


def test_the_rig_example_runs():
    """docs/examples/rig/my_rig.py, loaded by its path as --plant does, drives the piezo example
    (untuned gains: tuning is compare's business, and takes half a minute here)."""
    from pathlib import Path

    from hystmpc.experiments.own_plant import check_plant, load_plant

    docs = Path(__file__).parents[1] / "docs" / "examples"
    bench = get_bench(str(docs / "piezo" / "piezo.toml"))
    rig = load_plant(f"{docs / 'rig' / 'my_rig.py'}:connect")
    config = bench.configure(tuned=False)
    check_plant(rig, bench.sample_period, bench.sensors(config))
    run = bench.run("sine", "pid", config, duration=0.2, plant=rig)
    assert run.parameters["plant"] == {"own_plant": "piezo rig (simulated stand-in)"}
    assert run.metrics["n_samples"] == 200 and np.isfinite(run.metrics["rmse"])


def test_a_plant_failing_during_a_run_is_named_in_one_line(rig, capsys):
    code = main(["run", "pam", "square-10", "--controller", "pi", "--plant", "my_rig:failing", "--duration", "3",
                 "--out", "x", "--no-plots", "--quiet"])
    err = capsys.readouterr().err
    assert code == 1 and err.count("\n") == 1
    assert "during square-10 · pi on --plant my_rig:failing: OSError: serial timeout" in err


def test_a_py_file_with_a_dataclass_loads_by_its_path(tmp_path, capsys):
    """Loaded by path, the module is registered, so its dataclasses work."""
    (tmp_path / "dc_rig.py").write_text(textwrap.dedent('''
        from __future__ import annotations
        from dataclasses import dataclass
        from hystmpc.experiments.benches import get_bench

        @dataclass
        class Settings:
            payload: float = 2.5

        def make():
            bench = get_bench("pam")
            return bench.build_plant(bench.configure([f"plant.payload_kg={Settings().payload}"]))
    '''))
    code = main(["run", "pam", "square-10", "--controller", "pi", "--plant", f"{tmp_path / 'dc_rig.py'}:make",
                 "--duration", "1", "--out", str(tmp_path / "o"), "--no-plots", "--quiet"])
    assert code == 0, capsys.readouterr().err


def test_a_plant_that_stops_measuring_fails_the_command(rig, capsys):
    """Runs are written, but a run whose measurements turned NaN has no RMSE and exit is 1."""
    code = main(["run", "pam", "square-10", "--controller", "pi", "--plant", "my_rig:blinding", "--duration", "3",
                 "--out", "x", "--no-plots", "--quiet"])
    err = capsys.readouterr().err
    assert code == 1 and "the plant's measurement was not a finite number in square-10 · pi (129 samples)" in err
    assert (rig / "x" / "results.json").is_file()
