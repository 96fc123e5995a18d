"""What every plant is and returns: :class:`Plant` and :class:`Measurement`."""

from __future__ import annotations

from dataclasses import dataclass, field
from typing import Protocol, runtime_checkable


@dataclass
class Measurement:
    """One sample of a plant's sensors plus, for reports only, a few true signals."""

    t: float
    """Time of the sample (s)."""
    y: float
    """Measured controlled output (the one the metrics use)."""
    sensors: dict[str, float] = field(default_factory=dict)
    """Other measured signals a controller may use (e.g. ``pressure``)."""
    truth: dict[str, float] = field(default_factory=dict)
    """True internal signals for plots and diagnostics; controllers must not read these."""


@runtime_checkable
class Plant(Protocol):
    """A simulated actuator (the truth): reset, then one input per sample."""

    @property
    def sample_period(self) -> float:
        """Sample period (s)."""

    def reset(self, seed: int) -> Measurement:
        """Back to rest, sensor noise seeded with ``seed``; the first measurement.

        The measurement is read before any input is applied (a rig holds its rest input,
        settles, then reads its sensors).

        Parameters
        ----------
        seed : int
            Seed of the sensor noise.

        Returns
        -------
        Measurement
            The first measurement, at rest.
        """

    def step(self, u: float) -> Measurement:
        """Apply ``u`` for one sample; the measurement at the end of it.

        Parameters
        ----------
        u : float
            The input, held over the sample.

        Returns
        -------
        Measurement
            The measurement at the end of the sample.
        """


class ParametrisedPlant:
    """Mixin for a plant dataclass whose ``params`` hold its ``sample_period``: built at rest."""

    def __post_init__(self):
        self.reset(0)

    @property
    def sample_period(self) -> float:
        """Control sample period (s)."""
        return self.params.sample_period
