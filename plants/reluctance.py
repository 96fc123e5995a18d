"""Current-driven reluctance actuators, E-core and C-core (katalenic2013).

First principles (eq. (1) with a linear core, and Maxwell's stress for two gaps), with
the core hysteresis translated into the current as in eq. (11):

    i_eff = H_{p1, p2/g}[i]                                    (parametric operator)
    Φ_lin = μ0 A N i_eff / (2g + l_m/μr)
    Φ     = Φ_lin / (1 + (Φ_lin/Φ_sat)^4)^(1/4)                (core saturation, B_sat)
    F     = (1 − λ g/1 mm)² Φ² / (μ0 A)                         (leakage grows with the gap)

The nominal model knows none of the last two lines: it only sees them through the
identified look-up table (Section 3.5). The amplifier (6 kHz current source) is a
first-order lag with a slew limit; 5 kHz sampling.
"""

from __future__ import annotations

import math
from dataclasses import dataclass, field

import numpy as np

from hystmpc.models.parametric import ParametricHysteresis
from hystmpc.plants.base import Measurement, ParametrisedPlant

MU0 = 4e-7 * np.pi


@dataclass(frozen=True)
class ReluctanceParams:
    """A reluctance actuator; defaults: the E-core of Table 1 with our plant choices."""

    area: float = 338e-6
    """Side-tooth cross-section A (m²), Table 1."""
    path_length: float = 0.108
    """Mean magnetic path l_m (m), Table 1."""
    turns: int = 3 * 152
    """Total coil turns N (3 coils × 152), Table 1."""
    p1: float = 0.0074
    """True hysteresis width (A); Table 2 identified 0.0071 on the real E-core."""
    p2: float = 0.0013
    """True p2 (1/(A m)), p2(g) = p2/g; Table 2: 0.0014."""
    mu_r: float = 5000.0
    """Relative permeability of the Co–Fe core (our choice)."""
    b_sat: float = 2.35
    """Saturation flux density of Co–Fe (T)."""
    leakage: float = 0.03
    """λ: relative flux lost to leakage per mm of air gap (our choice)."""
    amplifier_bandwidth: float = 6000.0
    """Current-source bandwidth (Hz), Section 2.1."""
    slew_limit: float = 1000.0
    """Largest current rate (A/s): 164 V over the coil inductance at small gaps."""
    current_limit: float = 23.0
    """Supply current limit (A)."""
    force_noise: float = 0.05
    """Force-measurement noise (N, standard deviation); identification only."""
    sample_period: float = 2e-4
    """5 kHz."""
    substeps: int = 4
    """Plant integration substeps per sample."""

    def __post_init__(self):
        for name in ("area", "path_length", "p1", "p2", "mu_r", "b_sat", "amplifier_bandwidth",
                     "slew_limit", "current_limit", "sample_period"):
            value = getattr(self, name)
            if not (np.isfinite(value) and value > 0):
                raise ValueError(f"{name} must be finite and > 0, got {value}")
        if self.turns < 1 or self.substeps < 1 or not (0 <= self.leakage < 0.5):
            raise ValueError("turns and substeps must be >= 1, leakage in [0, 0.5)")


C_CORE = ReluctanceParams(area=256e-6, path_length=0.150, turns=2 * 210, p1=0.0079, p2=0.0024)
"""Table 1's C-core; true hysteresis near Table 2's 0.0076 A and 0.0025."""


def static_force(p: ReluctanceParams, i_eff, gap: float):
    """F(i_eff, g) of the module docstring (N).

    Parameters
    ----------
    p : ReluctanceParams
        The actuator parameters.
    i_eff : float or array_like
        Effective current, the hysteresis output (A).
    gap : float
        Air gap (m).

    Returns
    -------
    float or ndarray
        Force (N): a float for a float ``i_eff``, else of the shape of ``i_eff``.
    """
    if isinstance(i_eff, float):  # one sample: Python floats, the same operations
        phi_lin = MU0 * p.area * p.turns * float(i_eff) / (2 * gap + p.path_length / p.mu_r)
        try:
            phi = phi_lin / (1 + (phi_lin / (p.b_sat * p.area)) ** 4) ** 0.25
            return (1 - p.leakage * gap / 1e-3) ** 2 * phi**2 / (MU0 * p.area)  # pow, as NumPy's float64 does
        except OverflowError:  # |i_eff| beyond 1e77: NumPy's inf and 0, below
            pass
    phi_lin = MU0 * p.area * p.turns * np.asarray(i_eff, float) / (2 * gap + p.path_length / p.mu_r)
    phi_sat = p.b_sat * p.area
    phi = phi_lin / (1 + (phi_lin / phi_sat) ** 4) ** 0.25
    return (1 - p.leakage * gap / 1e-3) ** 2 * phi**2 / (MU0 * p.area)


@dataclass
class ReluctanceActuator(ParametrisedPlant):
    """Simulated actuator at a fixed air gap; input: current reference (A); output: force (N)."""

    params: ReluctanceParams = field(default_factory=ReluctanceParams)
    gap: float = 1.5e-3
    """Air gap (m), held by the test rig's position loops."""
    noisy: bool = False
    """Add the force-measurement noise (identification runs); off in operation, where force
    is not measured and the metrics use the true force."""

    def __post_init__(self):
        if not 0.5e-3 <= self.gap <= 3e-3:
            raise ValueError(f"gap must be in [0.5, 3] mm, got {self.gap * 1e3:g} mm")
        self.hysteresis = ParametricHysteresis(self.params.p1, self.params.p2 / self.gap)
        super().__post_init__()

    def reset(self, seed: int) -> Measurement:
        """Demagnetised at zero current; seed the force noise.

        Parameters
        ----------
        seed : int
            Seed of the force-measurement noise (drawn only when ``noisy``).

        Returns
        -------
        Measurement
            The first measurement, at rest.
        """
        self._rng = np.random.default_rng(seed)
        self._current = 0.0
        self._hys = self.hysteresis.initial_state(0.0)
        return self._measure()

    def step(self, current_ref: float) -> Measurement:
        """Apply a current reference (A) for one sample.

        Parameters
        ----------
        current_ref : float
            Current reference (A), clipped to ±``current_limit``.

        Returns
        -------
        Measurement
            The measurement at the end of the sample; the sensor is the current.
        """
        if not np.isfinite(current_ref):
            raise ValueError(f"plant input must be finite, got {current_ref}")
        p = self.params
        ref = min(max(float(current_ref), -p.current_limit), p.current_limit)  # np.clip of a float, faster
        h = p.sample_period / p.substeps
        # Exact first-order step (explicit Euler would overshoot: ω h = 1.9 here, and every
        # overshoot is a reversal that resets the hysteresis memory), then the slew limit.
        approach = 1.0 - math.exp(-2 * np.pi * p.amplifier_bandwidth * h)
        for _ in range(p.substeps):
            delta = (ref - self._current) * approach
            self._current += min(max(delta, -p.slew_limit * h), p.slew_limit * h)
            self._hys, _ = self.hysteresis.step(self._hys, self._current)
        return self._measure()

    def _measure(self) -> Measurement:
        force = float(static_force(self.params, self.hysteresis.output(self._hys), self.gap))
        noise = self.params.force_noise * float(self._rng.standard_normal()) if self.noisy else 0.0
        return Measurement(t=0.0, y=force + noise,
                           sensors={"current": self._current},
                           truth={"force": force, "current": self._current})


def major_loop_measurement(p: ReluctanceParams, gap: float, force_max: float, duration: float = 2.0,
                           seed: int = 0, decimate: int = 5) -> tuple[np.ndarray, np.ndarray]:
    """Simulated identification run (Fig. 9): current 0 → i_max → 0, measured force.

    Parameters
    ----------
    p : ReluctanceParams
        The true actuator.
    gap : float
        Air gap (m).
    force_max : float
        Force (N) that ``i_max`` reaches on the static map without hysteresis.
    duration : float, optional
        Length of the run, up and down (s).
    seed : int, optional
        Seed of the force noise.
    decimate : int, optional
        Keep every ``decimate``-th sample.

    Returns
    -------
    current : ndarray
        The current (A), decimated.
    force : ndarray
        The noisy force (N), decimated.
    """
    grid = np.linspace(0.0, p.current_limit, 20001)
    i_max = float(np.interp(force_max, static_force(p, grid, gap), grid))
    n = int(round(duration / p.sample_period)) // 2
    current = np.concatenate((np.linspace(0.0, i_max, n + 1), np.linspace(i_max, 0.0, n + 1)[1:]))
    plant = ReluctanceActuator(p, gap, noisy=True)
    plant.reset(seed)
    forces = []
    for i in current:  # slow ramps: the amplifier follows exactly
        plant._current = float(i)
        plant._hys, _ = plant.hysteresis.step(plant._hys, float(i))
        forces.append(plant._measure().y)
    return current[::decimate], np.asarray(forces)[::decimate]
