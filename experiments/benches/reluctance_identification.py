"""The reluctance bench's identification: the simulated major-loop experiment and the fit.

The controllers of bench ``reluctance`` never see the plant's true parameters: they use the
model identified here from simulated, noisy major-loop measurements (katalenic2013,
Section 3.5, Fig. 9), or from measured loops (``hystmpc identify reluctance --loops``).
"""

from __future__ import annotations

import functools
from dataclasses import dataclass

import numpy as np

from hystmpc.models.reluctance import ReluctanceModel, fit_reluctance_model
from hystmpc.plants.reluctance import ReluctanceParams, major_loop_measurement

CORES = ("E", "C")
FORCE_MAX = {"E": 400.0, "C": 240.0}
"""Identification and ramp force ranges (N), Section 3.5."""


@dataclass(frozen=True)
class RigSettings:
    """Which actuator and air gap (fixed by each named scenario)."""

    core: str = "E"
    """``E`` or ``C`` (Table 1)."""
    gap_mm: float = 1.5
    """Air gap (mm)."""

    def __post_init__(self):
        if self.core not in CORES:
            raise ValueError(f"core {self.core!r} is unknown; allowed: {', '.join(CORES)}")
        if not 1.0 <= self.gap_mm <= 2.0:
            raise ValueError(f"gap_mm must be in [1.0, 2.0], got {self.gap_mm}")


@dataclass(frozen=True)
class IdentificationSettings:
    """The simulated identification experiment (Fig. 9) and its fit."""

    gaps_mm: tuple[float, float, float, float, float] = (1.2, 1.3, 1.5, 1.7, 1.75)
    """Air gaps of the major-loop measurements (mm)."""
    duration: float = 2.0
    """Length of each 0 → max → 0 current run (s)."""
    seed: int = 0
    """Seed of the force-measurement noise."""
    window: int = 10
    """Samples averaged per look-up-table point (1: the paper's plain table). Noise in the
    table goes 1:1 into the linearisation error; 10 samples of the decimated 2.5 kHz record
    (4 ms) cut σ = 0.05 N to about 0.016 N."""
    force_margin: float = 0.03
    """Identify up to this fraction beyond the operating force, so the table covers the peak."""

    def __post_init__(self):
        if sorted(self.gaps_mm) != list(self.gaps_mm) or len(set(self.gaps_mm)) != len(self.gaps_mm):
            raise ValueError(f"gaps_mm must increase strictly, got {self.gaps_mm}")
        if not self.duration > 0 or self.window < 1:
            raise ValueError("duration must be > 0 and window >= 1")


@functools.lru_cache(maxsize=8)
def identify(plant: ReluctanceParams, settings: IdentificationSettings, force_max: float) -> ReluctanceModel:
    """Run the simulated identification experiment on ``plant`` and fit the model (cached).

    Parameters
    ----------
    plant : ReluctanceParams
        The true plant parameters.
    settings : IdentificationSettings
        The experiment and its fit.
    force_max : float
        The operating force range (N); the loops go ``settings.force_margin`` beyond it.

    Returns
    -------
    ReluctanceModel
        The model fitted to one major loop per air gap of ``settings.gaps_mm``.
    """
    loops = {g * 1e-3: major_loop_measurement(plant, g * 1e-3, force_max * (1 + settings.force_margin),
                                              settings.duration, seed=settings.seed + k)
             for k, g in enumerate(settings.gaps_mm)}
    return fit_reluctance_model(loops, window=settings.window)


def rig(config) -> tuple[ReluctanceParams, float, float]:
    """The configured core's plant parameters, air gap (m) and force range (N).

    Parameters
    ----------
    config : dict
        The configuration (groups ``rig``, ``ecore`` and ``ccore``).

    Returns
    -------
    tuple
        ``(ReluctanceParams, gap, force_max)``.
    """
    settings: RigSettings = config["rig"]
    plant = config["ecore"] if settings.core == "E" else config["ccore"]
    return plant, settings.gap_mm * 1e-3, FORCE_MAX[settings.core]


def identified_model(config) -> ReluctanceModel:
    """The controllers' model for the configured core.

    Parameters
    ----------
    config : dict
        The configuration (groups ``rig``, ``ecore``, ``ccore`` and ``identification``).

    Returns
    -------
    ReluctanceModel
        The model :func:`identify` fits.
    """
    plant, _, force_max = rig(config)
    return identify(plant, config["identification"], force_max)


def measured_loops(path) -> dict[float, tuple[np.ndarray, np.ndarray]]:
    """Major loops from a measured file: one 0 → max → 0 run per air gap (Fig. 9).

    Parameters
    ----------
    path : str or Path
        A CSV file with columns ``t``, ``u`` (current, A), ``y`` (force, N) and ``gap_mm``.

    Returns
    -------
    dict
        ``{gap (m): (current, force)}`` per air gap (``ValueError`` naming what is wrong).
    """
    from hystmpc.experiments.reference import read_columns
    data = read_columns(path, ("t", "u", "y", "gap_mm"), "loop file", minimum_rows=20)
    loops = {}
    for gap in np.unique(data[:, 3]):
        rows = data[data[:, 3] == gap]
        if not 1.0 <= gap <= 2.0:
            raise ValueError(f"loop file {path}: gap_mm {gap:g} is outside the rig's [1.0, 2.0] mm")
        if len(rows) < 20 or np.ptp(rows[:, 1]) <= 0:
            raise ValueError(f"loop file {path}: the loop at gap {gap:g} mm needs 20 rows and a varying current")
        loops[float(gap) * 1e-3] = (rows[:, 1], rows[:, 2])
    return loops


def identified_document(config, loops: dict | None = None) -> dict:
    """The identified model of the configured core as a JSON-ready dict (``hystmpc identify``).

    Parameters
    ----------
    config : dict
        The configuration (groups ``rig``, ``ecore``, ``ccore`` and ``identification``).
    loops : dict, optional
        Measured loops (:func:`measured_loops`) to fit instead of the simulated experiment.

    Returns
    -------
    dict
        The identified parameters, tables and polynomial inverse (with the true parameters
        when simulated).
    """
    plant, _, force_max = rig(config)
    if loops is None:
        model = identified_model(config)
        truth = {"true_p1_A": plant.p1, "true_p2_per_A_m": plant.p2}
    else:
        model = fit_reluctance_model(loops, window=config["identification"].window)
        truth = {"source": "measured loops"}
    return {
        "schema": "hystmpc.identified/1", "bench": "reluctance", "core": config["rig"].core,
        "p1_A": model.p1, "p2_per_A_m": model.p2, **truth,
        "gaps_m": list(model.gaps),
        "tables": [{"gap_m": g, "force_N": f.tolist(), "x_A": x.tolist()}
                   for g, (f, x) in zip(model.gaps, model.tables, strict=True)],
        "poly_inverse": {"features": "sqrt(F)^a * (g/1mm)^b, a+b<=4, a outer", "coefficients": model.poly.tolist()},
        "force_max_N": force_max,
    }
