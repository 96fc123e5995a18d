"""Every ``--set`` key of every bench is honoured there or rejected.

Honoured: with the key changed (to a valid value), something that reads its group behaves
differently: the plant's response to a fixed input sequence, or a controller's inputs for a
fixed sequence of measurements and references, or, failing both, a closed loop's inputs and
outputs. Iteration counts and the size of a built function are not evidence: an option that
only moves them has not reached what the actuator sees; the few keys that only change how
the RTI step is built (:data:`STRUCTURE_ONLY`) must build another step with the same inputs.
Some keys only act when a feature is
on (a solver's settings when that solver runs, the C-core's parameters on the C-core, a
derivative filter with a derivative gain, the warm start when no second start can overrule
it); :data:`ACTIVATE` says which, and both runs get
that change. Rejected: the bench refuses it when configured (its ``fixed`` keys, with the
reason), or the controller refuses a valid value when it is built, with a ``ValueError`` that
names the key (or its last part) and says why (exit 2 on the command line). Any other error
fails the test.
"""

from __future__ import annotations

import re
from functools import cache

import numpy as np
import pytest

from hystmpc.experiments.benches import BENCH_NAMES, get_bench
from hystmpc.experiments.config import OPTION, allowed_keys, get_value

SAMPLES = 12
ACTIVATE = {
    "solver.ipopt.": ["nmpc.solver=ipopt", "nmpc.multistart=false"],
    "solver.sqp.": ["nmpc.solver=sqp", "nmpc.multistart=false"],
    "solver.rti.": ["nmpc.solver=rti"], "solver.rti.qp_iterations": ["solver.rti.qp=ipm"],
    "solver.gn.": ["nmpc.solver=gn"],
    "ccore.": ["rig.core=C"], "pi.derivative_filter": ["pi.kd=0.05"],
    "nmpc.warm_start": ["nmpc.multistart=false"], "nmpc.second_start_error": ["nmpc.multistart=true"],
    "nmpc.second_start_pause": ["nmpc.multistart=true", "nmpc.second_start_error=1e-9"],
}
"""Key prefix -> the assignments that switch on what reads it (applied to both runs)."""
VALUES = {"max_iter": "1", "tol": "1e-12", "ftol": "0.5", "pressure_delay_s": "0.06", "solver": None,
          "warm_start": "shift", "core": "C", "iterations": "3", "qp_iterations": "12", "dp_limit": "2.0",
          "angle_limit": "0.05", "amplifier_bandwidth": "1.0", "extra_step_tolerance": "1e-12",
          "second_start_error": "1e6", "second_start_pause": "1000"}
"""Field name -> the changed value, where the generic rule would not act (or is invalid): iteration
limits that bind, input limits inside the test's inputs, an amplifier slower than the slew limit, an extra
RTI step taken on (almost) every sample, a second start on no sample (and none after the first
that lost, where every plan is off)."""
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
    """The inputs a controller asks for along ``measurements`` while the reference moves."""
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
    return np.asarray(inputs, float)


CLOSED_LOOP_SAMPLES = 500
"""Length of the closed-loop probe: 1 s of the default scenario, or this many samples if fewer
(reluctance's 5 kHz would take minutes with IPOPT)."""


def _closed_loops(bench, config, group: str) -> list[np.ndarray]:
    """The second, slower probe: the default scenario in closed loop (an adaptation that only
    acts once its estimates have moved)."""
    out = []
    duration = min(1.0, CLOSED_LOOP_SAMPLES * bench.sample_period)
    for name, spec in bench.controllers.items():
        if group in spec.groups:
            run = bench.run(bench.default_scenario, name, config, duration=duration)
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


REASONS = re.compile(r"\b(must|allowed|only|not|cannot|needs|requires|unsupported|unknown|differs)\b")
"""Words that say why a value is refused."""


def _check_rejection(key: str, error: ValueError, reason: str | None = None) -> None:
    """A refusal names the key (whole, or its last part as a word) and gives a reason (``reason``
    itself where the bench states one)."""
    message = str(error)
    field = key.rsplit(".", 1)[-1]
    named = key in message or re.search(rf"(?<![\w.]){re.escape(field)}\b", message)
    assert named, f"{key} refused without naming it: {message}"
    if reason is not None:
        assert reason in message, f"{key} refused without the bench's reason ({reason}): {message}"
    assert REASONS.search(message), f"{key} refused without a reason: {message}"


@cache
def _base_responses(bench_name: str, activation: tuple[str, ...], group: str, closed: bool) -> list[np.ndarray]:
    """What the unchanged configuration gives (shared by every key with the same activation)."""
    bench = get_bench(bench_name)
    config = bench.configure(list(activation))
    return _closed_loops(bench, config, group) if closed else _responses(bench, config, group)


def _verdict(bench_name: str, key: str) -> str:
    bench = get_bench(bench_name)
    if key in bench.fixed:
        with pytest.raises(ValueError, match="cannot be changed on this bench") as refused:
            bench.configure([f"{key}=1"])
        _check_rejection(key, refused.value, bench.fixed[key])
        return "rejected"
    activation = tuple(_activation(key))
    changed = _changed(bench_name, key, get_value(bench.configure(list(activation)), key))
    other = bench.configure([*activation, f"{key}={changed}"])  # a valid value: must be accepted here
    group = key.split(".")[0]
    try:
        after = _responses(bench, other, group)
    except ValueError as refused:
        _check_rejection(key, refused)
        return "rejected"
    before = _base_responses(bench_name, activation, group, False)
    assert len(before) == len(after) > 0, f"{bench_name}: nothing reads {key}"
    if _differ(before, after):
        return "honoured"
    closed_before = _base_responses(bench_name, activation, group, True)
    if _differ(closed_before, _closed_loops(bench, other, group)):
        return "honoured"
    return _structure_verdict(bench_name, key) if _structure_only(bench_name, key) else "ignored"


def _differ(before, after) -> bool:
    return any(a.shape != b.shape or not np.array_equal(a, b) for a, b in zip(before, after, strict=True))


SAME_INPUTS = {"nmpc.runtime"}
"""Keys that must not change the inputs (where the controller runs: its own test checks that
the generated controller gives the Python one's inputs exactly)."""
STRUCTURE_ONLY = {
    "solver.rti.sensitivity_block": "computes the same numbers in another layout (less RAM)",
    "pam:solver.rti.line_search": "on pam the full step is always the lowest-cost one: `descent` and `best` "
                                  "pick the same step (measured: 0 of square-20's 1000 samples differ)",
}
"""Keys (``group.field``, or ``bench:group.field`` on one bench) that may change how the RTI step
is built but, by design or on that bench, not its answer: where the inputs do not move, honoured
when the built step differs and the inputs stay the same to the last bit."""


def _structure_only(bench_name: str, key: str) -> bool:
    return key in STRUCTURE_ONLY or f"{bench_name}:{key}" in STRUCTURE_ONLY


def _keys(bench_name: str) -> list[tuple[str, str]]:
    config = get_bench(bench_name).configure()
    return [(bench_name, k) for k in allowed_keys(config) if not k.endswith(OPTION) and k not in SAME_INPUTS]


def _rti_size(bench, config) -> int:
    """Instructions of the NMPC's RTI step and the Functions it calls (a QP solver counts 0)."""
    rti = bench.build_controller("nmpc", config).problem.rti
    return sum(f.n_instructions() for f in [rti, *rti.find_functions()]
               if f.class_name() in ("SXFunction", "MXFunction"))


def _structure_verdict(bench_name: str, key: str) -> str:
    """``honoured`` when the changed key builds another RTI step that gives the same inputs."""
    bench = get_bench(bench_name)
    activation = ["nmpc.runtime=python", "nmpc.solver=rti"]
    base = bench.configure(activation)
    other = bench.configure([*activation, f"{key}={_changed(bench_name, key, get_value(base, key))}"])
    measurements = _measurements(bench, base)
    same = np.array_equal(_controller_inputs(bench, "nmpc", base, measurements),
                          _controller_inputs(bench, "nmpc", other, measurements))
    assert same, f"{bench_name}: {key} is listed as changing the step's layout only, but the inputs moved"
    return "honoured" if _rti_size(bench, base) != _rti_size(bench, other) else "ignored"


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
