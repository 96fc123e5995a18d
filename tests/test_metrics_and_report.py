"""Metrics on closed forms; overrides; result-document validation."""

import numpy as np
import pytest

from hystmpc.experiments.benches.pam import BENCH
from hystmpc.experiments.config import allowed_keys, apply_overrides
from hystmpc.experiments.metrics import step_metrics, tracking_metrics
from hystmpc.experiments.report import SCHEMA, validate_document


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
