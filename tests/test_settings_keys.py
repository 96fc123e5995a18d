"""Every ``--set`` key of every bench is honoured there or rejected.

Honoured: with the key changed (to a valid value), something that reads its group behaves
differently: the plant's response to a fixed input sequence, or a controller's inputs
for a fixed sequence of measurements and references. Some keys only act when a feature is
on (a solver's settings when that solver runs, the C-core's parameters on the C-core, a
derivative filter with a derivative gain); :data:`ACTIVATE` says which, and both runs get
that change. Rejected: the bench refuses it when configured (its ``fixed`` keys, with the
reason), or the controller refuses a valid value when it is built (a ``ValueError``: exit 2
on the command line).
"""

from __future__ import annotations

import numpy as np
import pytest

from hystmpc.experiments.benches import BENCH_NAMES, get_bench
from hystmpc.experiments.config import OPTION, allowed_keys, get_value

SAMPLES = 12
ACTIVATE = {
    "solver.ipopt.": ["nmpc.solver=ipopt"], "solver.sqp.": ["nmpc.solver=sqp"],
    "solver.rti.": ["nmpc.solver=rti"], "solver.rti.qp_iterations": ["solver.rti.qp=ipm"],
    "solver.gn.": ["nmpc.solver=gn"],
    "ccore.": ["rig.core=C"], "pi.derivative_filter": ["pi.kd=0.05"],
}
"""Key prefix -> the assignments that switch on what reads it (applied to both runs)."""
VALUES = {"max_iter": "1", "tol": "1e-12", "ftol": "0.5", "pressure_delay_s": "0.06", "solver": None,
          "warm_start": "shift", "core": "C", "iterations": "3", "qp_iterations": "12", "dp_limit": "2.0",
          "angle_limit": "0.05", "amplifier_bandwidth": "1.0", "extra_step_tolerance": "1e-12"}
"""Field name -> the changed value, where the generic rule would not act (or is invalid): iteration
limits that bind, input limits inside the test's inputs, an amplifier slower than the slew limit, an extra
RTI step taken on (almost) every sample."""
OTHER_SOLVER = {"pam": "sqp", "compliant": "sqp", "reluctance": "ipopt", "dea": "ipopt"}


def _changed(bench_name: str, key: str, value) -> str:
    field = key.rsplit(".", 1)[-1]
    if field == "solver":
        return OTHER_SOLVER[bench_name]
    if field == "qp":
        return "daqp" if value == "ipm" else "ipm"
    if field == "line_search":
        return "best" if value == "descent" else "descent"
    if field == "inverse_plan":
        return "static" if value == "linear-mpc" else "linear-mpc"
    if VALUES.get(field) is not None and VALUES[field] != str(value):  # else the bench's default: change it
        return VALUES[field]
    if isinstance(value, bool):
        return str(not value).lower()
    if isinstance(value, int):
        return str(value // 2 if value > 3 else value + 1)
    if isinstance(value, float):
        return repr(1.3 * value if value else 0.1)
    if isinstance(value, tuple):
        flat = np.ravel(value)
        return ",".join(repr(1.1 * float(v)) for v in flat)
    raise AssertionError(f"no changed value for {key}={value!r}")


def _activation(key: str) -> list[str]:
    """The assignments that switch on what reads ``key``, and the Python runtime: the probes
    read the Python controller's iterations and RTI step (the generated controller's inputs
    are the same; its own test checks that)."""
    return ["nmpc.runtime=python", *(a for prefix, assignments in ACTIVATE.items() if key.startswith(prefix)
                                     for a in assignments)]


def _fixed_inputs(bench, n: int) -> np.ndarray:
    lo, hi = bench.input_bounds
    mid, half = 0.5 * (lo + hi), 0.3 * (hi - lo)
    return mid + half * np.sin(2 * np.pi * np.arange(n) / n)


def _plant_response(bench, config) -> np.ndarray:
    plant = bench.build_plant(config)
    values = []
    for u in [None, *_fixed_inputs(bench, SAMPLES)]:
        m = plant.reset(0) if u is None else plant.step(u)
        values += [m.y, *m.sensors.values(), *m.truth.values()]
    return np.asarray(values, float)


def _controller_inputs(bench, name: str, config, measurements) -> np.ndarray:
    """The inputs, and for an NMPC what it solved and built (iterations, the RTI step's size)."""
    controller = bench.build_controller(name, config)
    controller.reset()
    scenario = bench.scenarios[bench.default_scenario]
    dt = bench.sample_period
    t = dt * np.arange(int(scenario.duration / dt))
    t0 = t[np.argmax(np.abs(np.diff(scenario.reference(t))))] - dt * SAMPLES / 2  # the reference moves
    inputs = []
    for k, m in enumerate(measurements):
        window = scenario.reference(t0 + dt * np.arange(k, k + controller.horizon + 1))
        inputs.append(controller.step(m, window))
    solved = list(getattr(controller, "iterations", []))
    rti = getattr(getattr(controller, "problem", None), "rti", None)
    size = [sum(_instructions(f) for f in [rti, *rti.find_functions()])] if rti is not None else []
    return np.asarray(inputs + solved + size, float)


def _instructions(function) -> int:
    """Instructions of a CasADi expression Function (a Switch or a QP solver counts 0)."""
    return function.n_instructions() if function.class_name() in ("SXFunction", "MXFunction") else 0


def _closed_loops(bench, config, group: str) -> list[np.ndarray]:
    """The second, slower probe: 1 s of the default scenario in closed loop (an adaptation
    that only acts once its estimates have moved)."""
    out = []
    for name, spec in bench.controllers.items():
        if group in spec.groups:
            run = bench.run(bench.default_scenario, name, config, duration=1.0)
            out.append(np.concatenate((run.input, run.output)))
    return out


def _measurements(bench, config):
    plant = bench.build_plant(config)
    return [plant.reset(0), *(plant.step(u) for u in _fixed_inputs(bench, SAMPLES - 1))]


def _responses(bench, config, group: str) -> list[np.ndarray]:
    out = []
    if group in bench.plant_groups:
        out.append(_plant_response(bench, config))
    measurements = _measurements(bench, config)
    for name, spec in bench.controllers.items():
        if group in spec.groups:
            out.append(_controller_inputs(bench, name, config, measurements))
    return out


def _verdict(bench_name: str, key: str) -> str:
    bench = get_bench(bench_name)
    if key in bench.fixed:
        with pytest.raises(ValueError, match="cannot be changed on this bench"):
            bench.configure([f"{key}=1"])
        return "rejected"
    base = bench.configure(_activation(key))
    changed = _changed(bench_name, key, get_value(base, key))
    other = bench.configure([*_activation(key), f"{key}={changed}"])  # a valid value: must be accepted here
    try:
        after = _responses(bench, other, key.split(".")[0])
    except ValueError:
        return "rejected"
    before = _responses(bench, base, key.split(".")[0])
    assert len(before) == len(after) > 0, f"{bench_name}: nothing reads {key}"
    if _differ(before, after):
        return "honoured"
    group = key.split(".")[0]
    return "honoured" if _differ(_closed_loops(bench, base, group), _closed_loops(bench, other, group)) else "ignored"


def _differ(before, after) -> bool:
    return any(a.shape != b.shape or not np.array_equal(a, b) for a, b in zip(before, after, strict=True))


SAME_INPUTS = {"nmpc.runtime"}
"""Keys that must not change the inputs (where the controller runs: its own test checks that
the generated controller gives the Python one's inputs exactly)."""


def _keys(bench_name: str) -> list[tuple[str, str]]:
    config = get_bench(bench_name).configure()
    return [(bench_name, k) for k in allowed_keys(config) if not k.endswith(OPTION) and k not in SAME_INPUTS]


ALL_KEYS = [case for name in BENCH_NAMES for case in _keys(name)]
QUICK = [("pam", "model.volume_coupling"), ("pam", "smoothing.direction_eps"), ("pam", "model.creep_time"),
         ("compliant", "smoothing.direction_eps"), ("reluctance", "smoothing.direction_eps"),
         ("dea", "nmpc.preview"), ("dea", "nmpc.warm_start"), ("dea", "solver.rti.qp_iterations"),
         ("dea", "solver.rti.condensed"), ("pam", "solver.gn.max_iter")]
"""The keys the earlier versions ignored, in the default suite."""


@pytest.mark.parametrize("bench_name, key", QUICK, ids=[f"{b}:{k}" for b, k in QUICK])
def test_keys_that_used_to_be_ignored_are_honoured_or_rejected(bench_name, key):
    assert _verdict(bench_name, key) in ("honoured", "rejected")


@pytest.mark.slow
@pytest.mark.parametrize("bench_name, key", ALL_KEYS, ids=[f"{b}:{k}" for b, k in ALL_KEYS])
def test_every_key_is_honoured_or_rejected(bench_name, key):
    assert _verdict(bench_name, key) in ("honoured", "rejected")


@pytest.mark.parametrize("bench_name", BENCH_NAMES)
def test_solver_options_pass_through_or_are_rejected(bench_name):
    bench = get_bench(bench_name)
    solver = "ipopt" if bench_name != "reluctance" else "sqp"
    name, value = ("mu_strategy", "adaptive") if solver == "ipopt" else ("hessian_approximation", "limited-memory")
    one_start = "nmpc.multistart=false"  # IPOPT and sqp report no cost to compare
    config = bench.configure([f"nmpc.solver={solver}", one_start, f"solver.{solver}.options.{name}={value}"])
    assert getattr(config["solver"], solver).options == {name: value}
    bench.build_controller("nmpc", config)
    bad = bench.configure([f"nmpc.solver={solver}", one_start, f"solver.{solver}.options.nosuch=1"])
    with pytest.raises(ValueError, match=f"solver.{solver}.options: .*nosuch"):
        bench.build_controller("nmpc", bad)
