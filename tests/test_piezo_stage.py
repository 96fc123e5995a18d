"""A fifth actuator in a few lines of the public API: a 1 kHz piezo stage with Prandtl–Ishlinskii
hysteresis and second-order stage dynamics, none of it known to hystmpc before this file."""

import numpy as np
import pytest

from hystmpc.experiments import PidController, PidGains, inverse_feedforward_pid, simulate
from hystmpc.models import Dynamics, PrandtlIshlinskii, build_prediction_model
from hystmpc.mpc import InputBounds, NmpcController, NmpcSettings
from hystmpc.plants import HysteresisActuator

DT = 1e-3  # s
LIMITS = (0.0, 100.0)  # V


def stage(natural_frequency_hz: float, damping: float) -> Dynamics:
    """Position (um) of a mass-spring stage driven by the hysteresis output (um at rest)."""
    wn = 2 * np.pi * natural_frequency_hz
    return Dynamics(("position", "velocity"), lambda x, u, h, d: [x[1], wn**2 * (h - x[0]) - 2 * damping * wn * x[1]],
                    output=lambda x, h: x[0], steady_input=lambda y: y)


def reference(t):
    """A raised-cosine approach from rest to 2 um, then a 5 Hz sine over 2–13 um."""
    t = np.asarray(t, float)
    return np.where(t < 0.1, 1 - np.cos(np.pi * t / 0.1), 7.5 - 5.5 * np.cos(2 * np.pi * 5 * (t - 0.1)))


@pytest.mark.slow  # 16 s: tunes both baselines on a grid; tests/test_readme_example.py runs the short example
def test_nmpc_beats_pid_and_inverse_feedforward_pid_on_a_piezo_stage():
    nominal = PrandtlIshlinskii(0.09, (10.0, 25.0, 40.0), (0.03, 0.02, 0.01))  # um/V, V
    truth = PrandtlIshlinskii(0.095, (9.5, 24.0, 38.0), (0.0315, 0.021, 0.0105))  # the rig is never the model
    plant = HysteresisActuator(truth, DT, stage(140.0, 0.35), noise=0.005, input_bounds=LIMITS)
    model = build_prediction_model(nominal, DT, dynamics=stage(150.0, 0.3), eps=0.02)
    nmpc = NmpcController(model, InputBounds(*LIMITS), NmpcSettings(horizon=15, r_rate=1e-4), sensor_noise=0.005)
    run = simulate(plant, nmpc, reference, duration=1.1, name="nmpc")

    def rmse(controller):
        return simulate(plant, controller, reference, duration=1.1).metrics["rmse"]
    grid = [PidGains(kp=kp, ki=ki) for kp in (0.0, 2.0, 4.0) for ki in (1000.0, 2000.0, 3000.0, 4000.0)]
    pid = min(rmse(PidController(g, DT, LIMITS)) for g in grid)  # each baseline at its best gains
    ff_pid = min(rmse(inverse_feedforward_pid(nominal, g, DT, LIMITS)) for g in grid)

    assert run.solver["failures"] == 0
    assert np.all((run.input >= LIMITS[0]) & (run.input <= LIMITS[1]))
    assert run.metrics["rmse"] < ff_pid < pid, (run.metrics["rmse"], ff_pid, pid)
