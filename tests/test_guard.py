"""The plant guard: every input passes the bench's physical bounds and rate before the plant
sees it; a lost estimate or a non-finite cost is a counted failure, never a success."""

from __future__ import annotations

import numpy as np
import pytest

from hystmpc.experiments.benches import get_bench
from hystmpc.experiments.report import comparison_table
from hystmpc.experiments.runner import InputGuard, simulate


class Constant:
    """A controller that asks for fixed inputs, one per sample."""

    horizon = 0

    def __init__(self, *inputs):
        self.inputs = list(inputs)

    def reset(self):
        self.k = 0

    def step(self, measurement, ref_window):
        u = self.inputs[min(self.k, len(self.inputs) - 1)]
        self.k += 1
        return u


def test_guard_clips_counts_and_holds_on_nan():
    guard = InputGuard(-1.0, 1.0, rate=0.5)
    assert guard.apply(float("nan"), None) == (0.0, True, True)  # the rest input, inside the bounds
    assert guard.apply(3.0, 0.0) == (0.5, True, False)  # the rate first, then the bounds
    assert guard.apply(3.0, 0.9) == (1.0, True, False)
    assert guard.apply(float("inf"), 0.7) == (0.7, True, True)
    assert guard.apply(0.2, -0.3) == (0.2, False, False)
    assert guard.apply(1.0 + 1e-15, 0.9) == (1.0, False, False)  # rounding: applied inside, not counted
    with pytest.raises(ValueError, match="lower < upper"):
        InputGuard(1.0, 1.0)


def test_every_input_a_bench_plant_receives_is_inside_its_bounds():
    bench = get_bench("pam")
    plant = bench.build_plant(bench.configure())
    received = []
    step = plant.step
    plant.step = lambda u: received.append(u) or step(u)
    run = simulate(plant, Constant(100.0, -100.0, float("nan"), 2.0), np.zeros(6), name="constant",
                   guard=bench.guard)
    assert received == [6.0, -6.0, -6.0, 2.0, 2.0]
    assert list(run.input) == [6.0, -6.0, -6.0, 2.0, 2.0, 2.0]
    assert run.guard == {"lower": -6.0, "upper": 6.0, "rate": np.inf, "clips": 3, "non_finite": 1}
    assert "guard clips" in comparison_table([run])
    assert run.to_json()["guard"]["clips"] == 3


def test_model_settings_cannot_widen_the_guard():
    bench = get_bench("pam")
    config = bench.configure(["model.dp_limit=100"])
    prepared = bench.prepare("square-20", "pi", config)
    run = bench.run("square-20", "pi", config, duration=0.1, prepared=prepared)
    assert run.guard["lower"] == -6.0 and run.guard["upper"] == 6.0


def test_a_lost_estimate_is_a_counted_failure_with_the_fallback():
    bench = get_bench("dea")
    # the model's EKF diverges (the static inverse: the linear MPC of the default second start
    # cannot even be set up on this model, a clear error of its own)
    config = bench.configure(["model.natural_frequency=5000", "nmpc.inverse_plan=static"])
    run = bench.run("square", "nmpc", config, duration=0.3)
    s = run.solver
    assert s["estimator_resets"] > 0
    assert s["statuses"]["Non_Finite_Estimate"] == s["estimator_resets"]
    assert s["failures"] == sum(s["statuses"].values()) - s["statuses"].get("Solve_Succeeded", 0)
    assert np.all(np.isfinite(run.input)) and run.guard["clips"] == 0
    assert "Solve_Succeeded" not in s["statuses"]  # every sample's estimate or cost was lost
    with pytest.raises(ValueError, match="the linear MPC's QP over 15 samples cannot be set up"):
        bench.build_controller("nmpc", bench.configure(["model.natural_frequency=5000"]))
