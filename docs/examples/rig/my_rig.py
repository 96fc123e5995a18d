"""A rig adapter for ``hystmpc run/compare piezo.toml --plant my_rig:connect``.

Replace the two ``_Driver`` methods with your hardware's calls (a DAQ card, a serial link, a
UDP socket to a real-time target). As shipped it drives a simulated stand-in, so the file
runs as is: the piezo example's plant with its own parameter draw.

hystmpc calls ``reset(seed)`` before each run, and when it checks the plant (bring the
actuator to rest, then read the sensors: that first measurement is taken before any input is
applied), and ``step(u)`` once per sample. Every ``u`` has passed the plant guard: finite,
inside the actuator file's ``input_bounds``, and after the first one within ``input_rate``
of the one before. Pacing (waiting for the next sample tick) is yours;
here ``step`` returns as soon as the stand-in has answered.
"""

from hystmpc.plants.base import Measurement

SAMPLE_PERIOD = 0.001  # s: must equal the actuator file's sample_period
REST_INPUT = 0.0  # V: what the amplifier holds between runs


class _Driver:
    """Stand-in for the hardware: the piezo example's simulated stage, another draw."""

    def __init__(self):
        from pathlib import Path

        from hystmpc.experiments.benches import get_bench

        bench = get_bench(str(Path(__file__).parents[1] / "piezo" / "piezo.toml"))
        self._stage = bench.build_plant(bench.configure(["plant.seed=11"], tuned=False))

    def write_volts(self, volts: float) -> float:
        """Apply ``volts`` for one sample; the displacement (µm) read at its end."""
        return self._stage.step(volts).y

    def settle_at_rest(self) -> float:
        """Hold the rest input until the stage settles; the displacement (µm) read then."""
        return self._stage.reset(0).y


class PiezoRig:
    """The Plant protocol over a driver: ``sample_period``, ``reset``, ``step``."""

    sample_period = SAMPLE_PERIOD
    description = "piezo rig (simulated stand-in)"

    def __init__(self, driver):
        self.driver = driver
        self.k = 0

    def reset(self, seed: int) -> Measurement:
        """Back to rest; the first measurement (``seed`` matters only to simulators)."""
        self.k = 0
        return Measurement(0.0, self.driver.settle_at_rest())

    def step(self, u: float) -> Measurement:
        """Apply ``u`` (V) for one sample; the measurement at its end."""
        self.k += 1
        return Measurement(self.k * SAMPLE_PERIOD, self.driver.write_volts(u))


def connect() -> PiezoRig:
    """What ``--plant my_rig:connect`` calls: open the hardware, return the plant."""
    return PiezoRig(_Driver())
