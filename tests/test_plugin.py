"""A bench written in another package registers itself through the ``hystmpc.benches`` entry
point, then shows in ``hystmpc list`` and runs like a built-in one."""

import json
import os
import subprocess
import sys
import textwrap

import pytest

PYPROJECT = """\
[build-system]
requires = ["setuptools>=68"]
build-backend = "setuptools.build_meta"

[project]
name = "hystmpc-demo-bench"
version = "0.1.0"

[project.entry-points."hystmpc.benches"]
demo = "demo_bench:make_bench"

[tool.setuptools]
py-modules = ["demo_bench"]
"""

MODULE = '''\
"""A 100 Hz actuator with Maxwell-slip hysteresis and a first-order lag, as a plugin bench."""
import numpy as np

from hystmpc.experiments import Bench, ControllerSpec, PidController, PidGains, Scenario
from hystmpc.models import MaxwellSlip, build_prediction_model
from hystmpc.models.linear_dynamics import LinearDynamics
from hystmpc.mpc import InputBounds, NmpcController, NmpcSettings
from hystmpc.plants import HysteresisActuator

DT = 0.01
NOMINAL = MaxwellSlip((1.0, 0.5), (0.2, 0.3))
LAG = LinearDynamics("first-order", time_constant=0.03)


def make_bench():
    def nmpc(config):
        model = build_prediction_model(NOMINAL, DT, dynamics=LAG.discrete(DT), eps=1e-3)
        return NmpcController(model, InputBounds(-2.0, 2.0), config["nmpc"], sensor_noise=0.001)

    sine = Scenario("sine", "0.5 Hz sine", 2.0, lambda t: 0.8 * np.sin(np.pi * np.asarray(t, float)))
    return Bench(
        name="demo", description="plugin demo: Maxwell-slip + lag", paper="", output_name="position",
        units="mm", input_units="V", sample_period=DT, scenarios={"sine": sine},
        controllers={"pid": ControllerSpec("pid", "PI", lambda c: PidController(c["pid"], DT, (-2.0, 2.0)),
                                           ("pid",)),
                     "nmpc": ControllerSpec("nmpc", "NMPC", nmpc, ("nmpc",))},
        defaults=lambda: {"pid": PidGains(kp=0.5, ki=20.0), "nmpc": NmpcSettings(horizon=10)},
        make_plant=lambda c: HysteresisActuator(MaxwellSlip((1.05, 0.5), (0.2, 0.32)), DT, LAG.discrete(DT),
                                                noise=0.001, input_bounds=(-2.0, 2.0)),
        plant_groups=(), output_range=(-1.0, 1.0), input_bounds=(-2.0, 2.0), default_scenario="sine")
'''


@pytest.fixture(scope="module")
def site(tmp_path_factory):
    """The plugin package, installed (pip, no network) into a folder put on PYTHONPATH."""
    root = tmp_path_factory.mktemp("plugin")
    (root / "src").mkdir()
    (root / "src" / "pyproject.toml").write_text(PYPROJECT)
    (root / "src" / "demo_bench.py").write_text(textwrap.dedent(MODULE))
    target = root / "site"
    subprocess.run([sys.executable, "-m", "pip", "install", "-q", "--no-deps", "--no-build-isolation",
                    "--target", str(target), str(root / "src")], check=True, capture_output=True)
    return target


def hystmpc(site, *args, cwd):
    env = dict(os.environ, PYTHONPATH=str(site))
    return subprocess.run([sys.executable, "-m", "hystmpc.experiments", *args], capture_output=True, text=True,
                          env=env, cwd=cwd)


def test_a_plugin_bench_is_listed_and_runs(site, tmp_path):
    listed = hystmpc(site, "list", "--json", cwd=tmp_path)
    assert listed.returncode == 0, listed.stderr
    benches = json.loads(listed.stdout)["benches"]
    assert "demo" in benches and benches["demo"]["controllers"] == ["pid", "nmpc"]
    run = hystmpc(site, "compare", "demo", "--duration", "1", "--out", str(tmp_path / "out"), "--no-plots",
                  "--quiet", cwd=tmp_path)
    assert run.returncode == 0, run.stderr
    runs = json.loads((tmp_path / "out" / "results.json").read_text())["runs"]
    rmse = {r["controller"]: r["metrics"]["rmse"] for r in runs}
    assert rmse["nmpc"] < rmse["pid"], rmse
    unknown = hystmpc(site, "run", "demo", "nope", "--controller", "pid", cwd=tmp_path)
    assert unknown.returncode == 2 and "unknown scenario 'nope'" in unknown.stderr
