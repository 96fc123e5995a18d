"""Metrics on closed forms; overrides; result-document validation."""

import numpy as np
import pytest

from hystmpc.experiments.benches.pam import BENCH
from hystmpc.experiments.config import allowed_keys, apply_overrides, apply_values
from hystmpc.experiments.metrics import (
    OSCILLATING_CYCLES,
    input_metrics,
    noise_level,
    oscillation_metrics,
    reversals,
    step_metrics,
    tracking_metrics,
)
from hystmpc.experiments.report import SCHEMA, results_document, validate_document


def test_tracking_metrics_closed_form():
    m = tracking_metrics([1, 1, 1, 1], [0, 2, 1, 1])
    assert m == {"rmse": pytest.approx(np.sqrt(0.5)), "mae": 0.5, "max_abs_error": 1.0, "n_samples": 4}


def test_step_metrics_first_order_response():
    dt, tau = 0.001, 0.1  # judged over the first 80 % of 2 s: settles at 0.39 s
    t = np.arange(0, 2, dt)
    r = np.ones_like(t)
    y = 1 - np.exp(-t / tau)
    y[0] = 0.0
    m = step_metrics(t, r, y, min_step=0.5)
    assert m["overshoot_pct"] == 0.0
    assert m["settling_time_s"] == pytest.approx(tau * np.log(50), abs=2 * dt)  # e^{-t/τ} = 2 %
    assert m["steady_state_error"] <= np.exp(-1.4 / tau)  # window starts at 7/8 of 1.6 s
    assert m["n_steps"] == 1


def _square_response(t, ring_decay: float, seed: int = 0):
    """A ±10 square wave at 0.1 Hz and a response ringing at 3.5 Hz after each step (decay
    rate ``ring_decay`` 1/s; 0: a limit cycle), with sensor noise below the threshold."""
    r = np.where(np.mod(t, 10.0) < 5.0, 10.0, -10.0)
    since = np.mod(t, 5.0)
    y = r - 2.0 * np.sign(r) * np.exp(-ring_decay * since) * np.cos(2 * np.pi * 3.5 * since)
    return r, y + 0.05 * np.random.default_rng(seed).standard_normal(len(t))


def test_reversals_ignore_swings_below_the_threshold():
    x = np.array([0, 1, 0.9, 2, 1.5, 3, 0, 0.05, -1, 2])
    assert list(reversals(x, 0.3)) == [4, 5, 6, 9]
    assert list(reversals(x, 1.0)) == [6, 9]
    assert len(reversals(np.zeros(10), 0.1)) == 0


def test_oscillation_flags_a_limit_cycle_and_not_a_damped_ring():
    t = 0.02 * np.arange(1000)
    r, cycle = _square_response(t, 0.0)
    m = oscillation_metrics(t, r, cycle)
    assert m["oscillating"] == 1.0 and m["oscillation_cycles"] >= OSCILLATING_CYCLES
    assert m["oscillation_hz"] == pytest.approx(3.5, rel=0.05)
    r, ring = _square_response(t, 6.0)  # 2 % of the span after about 0.6 s: two periods
    m = oscillation_metrics(t, r, ring)
    assert m["oscillating"] == 0.0 and 0 < m["oscillation_cycles"] < OSCILLATING_CYCLES
    smooth = 10 * np.sin(2 * np.pi * 0.1 * t)
    assert oscillation_metrics(t, smooth, smooth)["oscillation_cycles"] == 0.0


def test_noise_on_a_held_reference_is_not_an_oscillation_but_a_cycle_is():
    t = 0.01 * np.arange(4000)
    held = np.full_like(t, 1.0)
    noisy = held + 5e-4 * np.random.default_rng(3).standard_normal(len(t))
    assert noise_level(noisy) == pytest.approx(5e-4, rel=0.1)
    assert oscillation_metrics(t, held, noisy)["oscillation_cycles"] < 1.0
    encoder = np.round(noisy / 2e-3) * 2e-3  # mostly one count, now and then the next
    assert oscillation_metrics(t, held, encoder)["oscillation_cycles"] < 1.0
    cycle = noisy + 4e-3 * np.sin(2 * np.pi * 3.0 * t)  # 8 noise σ peak to peak: a real limit cycle
    m = oscillation_metrics(t, held, cycle)
    assert m["oscillating"] == 1.0 and m["oscillation_hz"] == pytest.approx(3.0, rel=0.05)


def test_input_total_variation():
    assert input_metrics([0.0, 1.0, -1.0, -1.0, 2.0])["input_tv"] == pytest.approx(6.0)


def test_overrides_nested_and_typed():
    config = apply_overrides(BENCH.configure(), ["plant.hysteresis.k=0.05,0.02,0.003,0.003",
                                                "nmpc.preview=false", "model.payload_kg=1.5"])
    assert config["plant"].hysteresis.k == (0.05, 0.02, 0.003, 0.003)
    assert config["nmpc"].preview is False
    assert config["model"].payload_kg == 1.5
    assert "plant.hysteresis.w" in allowed_keys(config)


@pytest.mark.parametrize("assignment, match", [
    ("plant.hysteresis.k=0.05,0.02", "expected 4 comma-separated numbers"),
    ("nmpc.preview=maybe", "expected true or false"),
    ("plant.payload_kg=nan", "expected a finite number"),
    ("plant.payload_kg=-1", "payload_kg must be finite and >= 0"),
])
def test_bad_overrides(assignment, match):
    with pytest.raises(ValueError, match=match):
        apply_overrides(BENCH.configure(), [assignment])


def test_typed_values_take_the_same_route_as_texts():
    """A dict of typed values (a file's tables, a Python caller) sets what the same texts set,
    follows the same leaders (lmpc.horizon), and is refused where its type is not the field's."""
    texts = BENCH.configure(["plant.hysteresis.k=0.05,0.02,0.003,0.003", "nmpc.preview=false",
                             "model.payload_kg=1.5", "nmpc.horizon=25", "solver.ipopt.options.print_level=0"])
    typed = BENCH.configure({"plant.hysteresis.k": [0.05, 0.02, 0.003, 0.003], "nmpc.preview": False,
                             "model.payload_kg": 1.5, "nmpc.horizon": 25, "solver.ipopt.options.print_level": 0})
    assert typed == texts and typed["lmpc"].horizon == 25
    assert apply_values(BENCH.configure(), {"model.payload_kg": 2})["model"].payload_kg == 2.0  # an integer is a number
    numpy = BENCH.configure({"nmpc.horizon": np.int64(25), "nmpc.preview": np.bool_(False),
                             "model.payload_kg": np.float32(1.5)})
    assert numpy == BENCH.configure({"nmpc.horizon": 25, "nmpc.preview": False, "model.payload_kg": 1.5})
    assert BENCH.configure({"solver.ipopt.options.max_cpu_time": "5"})["solver"].ipopt.options["max_cpu_time"] == 5


@pytest.mark.parametrize("values, match", [
    ({"nmpc.horizon": "25"}, r"nmpc.horizon = '25': expected an integer \(the default is 20\)"),
    ({"nmpc.horizon": 25.0}, "nmpc.horizon = 25.0: expected an integer"),
    ({"nmpc.preview": 1}, "nmpc.preview = 1: expected true or false"),
    ({"model.payload_kg": True}, "model.payload_kg = True: expected a finite number"),
    ({"plant.hysteresis.k": [0.05, "x"]}, "expected 4 comma-separated numbers"),
    ({"nmpc.horizon": 1}, "nmpc.horizon = 1: horizon must be >= 2"),
    ({"nmpc.horizn": 3}, "unknown table key 'nmpc.horizn'; did you mean 'nmpc.horizon'"),
    ({"nmpc.q_output": 10**400}, "nmpc.q_output = 1000.*: expected a finite number"),
    ({"plant.hysteresis.k": [[0.05, 0.02], 0.003, 0.003]}, "expected 4 comma-separated numbers"),
    ({"solver.ipopt.options.when": __import__("datetime").date(1979, 5, 27)},
     "solver.ipopt.options.when = datetime.date.*: expected true or false, a number or text"),
])
def test_bad_typed_values(values, match):
    with pytest.raises(ValueError, match=match):
        apply_values(BENCH.configure(), values)


def _doc():
    return {"schema": SCHEMA, "bench": "pam", "created": "x", "version": "0.1.0", "runs": [{
        "scenario": "s", "controller": "c", "seed": 0, "units": "deg", "sample_period_s": 0.02,
        "metrics": {"rmse": 1.0, "mae": 1.0, "max_abs_error": 1.0, "n_samples": 3},
        "timing": {"step_ms_median": 1.0, "step_ms_p95": 1.0, "step_ms_max": 1.0}}]}


def test_validate_document_accepts_and_rejects():
    validate_document(_doc())
    bad = _doc()
    bad["runs"][0]["metrics"]["rmse"] = float("nan")
    with pytest.raises(ValueError, match="rmse is not a finite number"):
        validate_document(bad)
    bad = _doc()
    bad["schema"] = "other/1"
    with pytest.raises(ValueError, match="schema"):
        validate_document(bad)


def test_result_documents_name_the_libraries_that_made_them():
    import casadi

    env = results_document("pam", [])["environment"]
    assert env["casadi"] == casadi.__version__ and env["numpy"] == np.__version__
    assert set(env) >= {"python", "machine", "scipy", "osqp"}
