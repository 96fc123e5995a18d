"""Property: whatever the reference (jumps, ramps, values outside the bench's range) and however
wrong the plant and the model (up to six parameters scaled by 0.5..1.5; in half the loops the
input limits widened by up to 1.5):

* the NMPC itself asks only for numbers within the bounds and rate it was given, and, unless
  it was told of a wider input range, within the actuator's (the inputs it *asks for*, before
  the plant's guard);
* where it asks for more, the guard clips it, and every such sample is counted in the result;
* no plant ever receives a non-finite or out-of-bound input;
* every estimate the NMPC loses counts as a failure.

The quick form draws a few closed loops per bench; the slow form many more.
"""

from __future__ import annotations

import numpy as np
import pytest
from hypothesis import HealthCheck, given, reject, settings
from hypothesis import strategies as st

from hystmpc.experiments.benches import BENCH_NAMES, get_bench
from hystmpc.experiments.config import key_table
from hystmpc.experiments.runner import simulate
from hystmpc.experiments.sweep import scaled_assignments

SAMPLES = 30
"""Length of each closed loop."""
QUICK_EXAMPLES = {"pam": 2, "compliant": 2, "reluctance": 1, "dea": 2}
"""Closed loops per bench in the default suite (a reluctance example identifies its model: ~10 s)."""
SLOW_EXAMPLES = 25
TOLERANCE = 1e-6
"""How far (a fraction of the input span) a request may pass a bound and still count as within
it: a QP solver's feasibility tolerance, far below anything an actuator would notice."""
BASE = {"reluctance": ["identification.duration=0.5"], "pam": ["nmpc.solver=rti"], "compliant": ["nmpc.solver=rti"]}
"""Settings under every example: the reluctance model is identified from shorter simulated
loops (a quarter of the default), which keeps an example to seconds. pam and compliant run
their RTI step in-process: every perturbed model would otherwise compile its own C step
(seconds each), and the compiled step is the same function (test_realtime's round trip)."""


class RecordingPlant:
    """A plant that keeps every input it receives."""

    def __init__(self, plant):
        self.plant, self.inputs = plant, []

    def __getattr__(self, name):
        return getattr(self.plant, name)

    def reset(self, seed=0):
        self.inputs = []
        return self.plant.reset(seed)

    def step(self, u):
        self.inputs.append(u)
        return self.plant.step(u)


class RecordingController:
    """A controller that keeps every input it asks for."""

    def __init__(self, controller):
        self.controller, self.requests = controller, []

    def __getattr__(self, name):
        return getattr(self.controller, name)

    def reset(self):
        self.requests = []
        return self.controller.reset()

    def step(self, measurement, reference):
        u = self.controller.step(measurement, reference)
        self.requests.append(float(u))
        return u


def _perturbable(bench) -> list[str]:
    """Real-valued keys of the plant's and the model's groups that no scenario fixes."""
    groups = {*bench.plant_groups, "model"}
    conditions = {c.split("=", 1)[0] for s in bench.scenarios.values() for c in s.conditions}
    keys = []
    for key, value, _ in key_table(bench.configure()):
        real = isinstance(value, float) or (isinstance(value, tuple) and value and all(
            isinstance(v, float) for v in value))
        if (key.split(".")[0] in groups and real and key not in bench.fixed and key not in conditions
                and not key.endswith(("sample_period", "substeps"))):
            keys.append(key)
    return keys


def _limits(bench) -> list[str]:
    """The keys that say how far the input may go (``dp_limit``, ``u_max``, ``current_limit``...)."""
    return [k for k in _perturbable(bench) if "limit" in k.rsplit(".", 1)[-1] or k.endswith("u_max")]


@st.composite
def closed_loops(draw, bench):
    keys = draw(st.lists(st.sampled_from(_perturbable(bench)), min_size=1, max_size=6, unique=True))
    factors = {k: draw(st.floats(0.5, 1.5)) for k in keys}
    if draw(st.booleans()):  # half the loops: a model (or plant) that believes in a wider input range
        factors.update({k: draw(st.floats(1.0, 1.5)) for k in _limits(bench)})
    lo, hi = bench.output_range
    span = hi - lo
    level = st.floats(lo - 0.5 * span, hi + 0.5 * span)
    reference = np.empty(SAMPLES)
    k = 0
    while k < SAMPLES:  # segments: a jump to a level and a hold, or a ramp to a level
        n = draw(st.integers(3, 12))
        start = reference[k - 1] if k else draw(level)
        end = draw(level)
        shape = np.linspace(start, end, n) if draw(st.booleans()) else np.full(n, end)
        reference[k: k + n] = shape[: SAMPLES - k]
        k += n
    noise = draw(st.sampled_from([1.0, 1.0, 10.0, 100.0]))
    return factors, reference, noise, draw(st.integers(0, 2**16))


def _check(bench, factors, reference, noise, seed):
    base = bench.configure(BASE.get(bench.name, []))
    noise_keys = [k for k, v, _ in key_table(base) if k.startswith("plant.") and "noise" in k and isinstance(v, float)]
    assignments = scaled_assignments(base, {**factors, **{k: noise for k in noise_keys}})
    try:
        config = bench.configure(BASE.get(bench.name, []) + assignments)
        prepared = bench.prepare(bench.default_scenario, "nmpc", config)
    except ValueError:
        reject()  # a parameter set the bench refuses (with a clear error): not a closed loop
    plant, controller = RecordingPlant(prepared.plant), RecordingController(prepared.controller)
    run = simulate(plant, controller, reference, seed=seed, name="nmpc", guard=bench.guard)
    lo, hi = bench.input_bounds
    asked = np.asarray(controller.requests)
    assert np.all(np.isfinite(asked)), f"the NMPC asked for {asked[~np.isfinite(asked)][0]}"
    slack = TOLERANCE * (hi - lo)
    own = prepared.controller.bounds  # what the NMPC was told, widened or not
    assert np.all((asked >= own.lower - slack) & (asked <= own.upper + slack)), (asked.min(), asked.max(), own)
    if np.isfinite(own.rate):
        assert np.all(np.abs(np.diff(asked)) <= own.rate + slack), np.abs(np.diff(asked)).max()
    if not any(factors.get(k, 1.0) > 1.0 for k in _limits(bench)):
        assert np.all((asked >= lo - slack) & (asked <= hi + slack)), (asked.min(), asked.max(), lo, hi)
        if np.isfinite(bench.input_rate):
            assert np.all(np.abs(np.diff(asked)) <= bench.input_rate + slack), np.abs(np.diff(asked)).max()
    changed = np.abs(run.input - asked) > 1e-12 * np.maximum(1.0, np.abs(asked))
    assert run.guard["clips"] == int(np.count_nonzero(changed)), (run.guard["clips"], np.count_nonzero(changed))
    inputs = np.asarray(plant.inputs)
    assert np.all(np.isfinite(inputs)), inputs
    assert np.all((inputs >= lo) & (inputs <= hi)), (inputs.min(), inputs.max())
    if np.isfinite(bench.input_rate):
        assert np.all(np.abs(np.diff(inputs)) <= bench.input_rate * (1 + 1e-9))
    stats = run.solver
    lost = stats["estimator_resets"]
    assert stats["statuses"].get("Non_Finite_Estimate", 0) == lost
    assert stats["failures"] >= lost


def _property(name: str, examples: int):
    bench = get_bench(name)

    @settings(max_examples=examples, deadline=None, derandomize=True, database=None,
              suppress_health_check=[HealthCheck.too_slow, HealthCheck.filter_too_much])
    @given(closed_loops(bench))
    def check(loop):
        _check(bench, *loop)

    check()


@pytest.mark.filterwarnings("ignore::RuntimeWarning")  # plants driven far out of range overflow, by design
@pytest.mark.parametrize("name", BENCH_NAMES)
def test_no_plant_receives_a_bad_input(name):
    _property(name, QUICK_EXAMPLES[name])


@pytest.mark.slow
@pytest.mark.filterwarnings("ignore::RuntimeWarning")
@pytest.mark.parametrize("name", BENCH_NAMES)
def test_no_plant_receives_a_bad_input_long(name):
    _property(name, SLOW_EXAMPLES)
