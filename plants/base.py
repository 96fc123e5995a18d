"""What every plant returns each sample."""

from __future__ import annotations

from dataclasses import dataclass, field


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
