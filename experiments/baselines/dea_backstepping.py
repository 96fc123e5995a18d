"""wang2025's adaptive backstepping (Section 3.1), with and without the paper's compensation.

The compensation is ``bic``: creep inverse and implicit inverse through an adaptive KP density.
"""

from __future__ import annotations

from dataclasses import dataclass

import numpy as np

from hystmpc.models.fckp import Fckp
from hystmpc.plants.dea import DeaParams


@dataclass(frozen=True)
class BicSettings:
    """Backstepping implicit-inverse adaptive control, Section 5.2 (``--set bic.KEY=VALUE``)."""

    k1: float = 20.0
    """Outer-loop gain (1/s). The paper's 3.5 tracks ``single-sine`` worse here; 20 is
    the middle of the stable region of a scan over k1, λ and the velocity filter (docs/dea.md)."""
    k2: float = 3.5
    """Inner-loop gain, applied as λ·k2 (see :class:`Backstepping`)."""
    gamma_theta: float = 2.0
    """Γ11 = diag{gamma_theta}."""
    gamma_delta: float = 2.0
    """Γ12 = diag{gamma_delta}."""
    sigma1: float = 0.2
    r1: float = 0.2
    r2: float = 10.0
    gamma_mu: float = 0.1
    rbf_nodes: int = 11
    """RBF centres evenly spaced in [−1, 1] (η = 1)."""
    zeta: float = 0.01
    """Implicit-inverse search step (V)."""
    creep_inverse: bool = True
    """Compensate the creep by the GL derivative of order α (Section 2.3)."""
    velocity_filter: float = 0.05
    """Time constant of the filter on the differenced displacement (s)."""
    unit_scale: float = 0.025
    """λ: k2, Γ11 and Γ12 act as λ·k2, λ·Γ11, λ·Γ12 in our units (see :class:`Backstepping`)."""

    def __post_init__(self):
        for name in ("k1", "k2", "gamma_theta", "gamma_delta", "sigma1", "r1", "r2", "gamma_mu", "zeta",
                     "velocity_filter", "unit_scale"):
            value = getattr(self, name)
            if not (np.isfinite(value) and value >= 0):
                raise ValueError(f"{name} must be finite and >= 0, got {value}")
        if self.rbf_nodes < 2 or self.zeta <= 0:
            raise ValueError("rbf_nodes must be >= 2 and zeta > 0")


class ReferenceDerivatives:
    """ẋd and ẍd from the sampled reference by central differences (one sample of preview).

    Parameters
    ----------
    dt : float
        Sample period (s).
    """

    def __init__(self, dt: float):
        self.dt = dt
        self.reset()

    def reset(self) -> None:
        """Forget the last reference."""
        self._last = None

    def __call__(self, ref_window) -> tuple[float, float, float]:
        """The reference and its first two derivatives now (central differences)."""
        r0, r1 = float(ref_window[0]), float(ref_window[1])
        rm = r0 if self._last is None else self._last
        self._last = r0
        return r0, (r1 - rm) / (2 * self.dt), (r1 - 2 * r0 + rm) / self.dt**2


class VelocityFilter:
    """x2 from the laser displacement: differenced, then a first-order low-pass.

    Parameters
    ----------
    dt : float
        Sample period (s).
    tau : float
        Time constant of the low-pass (s); 0: none.
    """

    def __init__(self, dt: float, tau: float):
        self.dt, self.alpha = dt, dt / (tau + dt) if tau > 0 else 1.0
        self.reset()

    def reset(self) -> None:
        """Forget the last measurement; the velocity starts at zero."""
        self._last, self.value = None, 0.0

    def __call__(self, y: float) -> float:
        """The filtered velocity after measurement ``y``."""
        if self._last is not None:
            self.value += self.alpha * ((y - self._last) / self.dt - self.value)
        self._last = y
        return self.value


class Backstepping:
    """Adaptive backstepping of Section 3.1, with or without the paper's compensation.

    ``e1 = x1 − xd``, ``x2d = −k1 e1 + ẋd``, ``e2 = x2 − x2d`` and the temporary control
    (eq. (20)) ``W = −θ̂ᵀξ(x1) + δ̂ᵀη(x1) (ẋ2d − k2 e2)``, where θ̂ᵀξ ≈ g⁻¹f and δ̂ᵀη ≈ g⁻¹
    (eq. (18)) and the updates are eq. (25).

    Our units (mm, V, s; W a displacement, g ≈ ω² ≈ 1400 s⁻²) need these decisions:

    * λ (``unit_scale``) scales k2, Γ11 and Γ12. Literally, ``− k2 e2`` makes e2 decay at
      g·k2 ≈ 5000 /s, which a 100 Hz loop cannot realise: the input chatters 0 ↔ 10 V.
    * δ̂ ≈ g⁻¹ adapts 1/ω² slower still and is projected onto [0, 2/ω²]; unscaled it grew
      far beyond g⁻¹.
    * The RBFs see x1 mapped from [0, 4] mm onto the centres' [−1, 1].
    * x2 is the differenced laser signal through a first-order low-pass (``velocity_filter``).
    * k1 = 20 instead of 3.5 (see :class:`BicSettings`). θ̂ and δ̂ start from zero, as printed.

    Without compensation (``backstepping``) the voltage is W over the mean static slope.
    With it (``bic``), W goes through the creep inverse D^α (Section 2.3, on the history of
    W commands) and then the implicit inverse (Section 3.2) of the KP model with the
    adaptive density μ̂ (eq. (26)): ``μ̂' = γμ (e2 κ_ρ − r2 (μ̂ − μ̂0))``, μ̂ ≥ 0, where μ̂0 is
    the nominal density (a leak towards zero, as printed, would empty the model the inverse
    searches).

    Parameters
    ----------
    settings : BicSettings
        Gains, adaptation rates and the decisions above.
    model : DeaParams
        The nominal model (its FCKP, sample period and natural frequency).
    creep_window : int or None
        Memory window of the creep inverse (past samples); None: the full memory.
    compensate : bool
        ``bic`` (True) or ``backstepping`` (False).
    """

    horizon = 1

    def __init__(self, settings: BicSettings, model: DeaParams, creep_window: int | None, compensate: bool):
        self.s, self.model, self.compensate = settings, model, compensate
        self.fckp = Fckp(model.fckp)
        self.dt = model.sample_period
        self.centres = np.linspace(-1.0, 1.0, settings.rbf_nodes)
        u, w = self.fckp.mean_static_curve()
        self._slope = (w[-1] - w[0]) / (u[-1] - u[0])
        kp = self.fckp.kp
        self._mu0 = self.fckp.params.stroke * 0.5 * kp.weights / kp.total_weight  # mm per kernel
        self._creep_window = creep_window
        self._rate = 1.0 / model.natural_frequency**2
        self.reset()

    def reset(self) -> None:
        """Initial estimates of Section 5.2 (θ̂ = δ̂ = 0, μ̂ = μ̂0); empty memories."""
        self.theta = np.zeros(self.s.rbf_nodes)
        self.delta = np.zeros(self.s.rbf_nodes)
        self.mu = self._mu0.copy()
        self._kp_state = self.fckp.initial_state()
        self._creep_inv = self.fckp.creep_inverse(self._creep_window)
        self._refs = ReferenceDerivatives(self.dt)
        self._velocity = VelocityFilter(self.dt, self.s.velocity_filter)
        self.predicted_output = float("nan")

    def _rbf(self, x1):
        """Gaussian RBFs (η = 1) of the displacement mapped from [0, 4] mm onto the centres' [−1, 1]."""
        return np.exp(-(((x1 - 2.0) / 2.0 - self.centres) ** 2) / 2.0)

    def step(self, measurement, ref_window) -> float:
        """Voltage for this sample.

        Parameters
        ----------
        measurement : Measurement
            This sample's measurement (its displacement ``y``, mm).
        ref_window : ndarray
            The references from this sample on (mm); the first two are used.

        Returns
        -------
        float
            The voltage (V), within ``[0, u_max]``.
        """
        s, dt = self.s, self.dt
        x1 = measurement.y
        x2 = self._velocity(x1)
        xd, xd_dot, xd_ddot = self._refs(ref_window)
        e1 = x1 - xd
        e2 = x2 - (-s.k1 * e1 + xd_dot)
        x2d_dot = -s.k1 * (x2 - xd_dot) + xd_ddot
        xi = self._rbf(x1)
        lam = s.unit_scale
        W = -self.theta @ xi + (self.delta @ xi) * x2d_dot - lam * s.k2 * e2
        self.theta += dt * lam * s.gamma_theta * (e2 * xi - s.sigma1 * self.theta)
        self.delta += dt * lam * self._rate * s.gamma_delta * (-e2 * xi * x2d_dot - s.r1 * self.delta)
        self.delta = np.clip(self.delta, 0.0, 2 * self._rate)  # projection: 0 < g⁻¹ < 2/ω²
        if not self.compensate:
            u = W / self._slope
        else:
            w_target = self._creep_inv.push(W) if s.creep_inverse else W
            kernels = self._kp_state[1:]
            self.mu = np.maximum(self.mu + dt * s.gamma_mu * (e2 * kernels - s.r2 * (self.mu - self._mu0)), 0.0)
            kappa_target = w_target - self.fckp.params.stroke * 0.5  # w = Σ μ̂ ξ + stroke/2
            _, p = self.fckp.kp.inverse_step(self._kp_state, kappa_target, -1.0, 1.0,
                                             step=2 * s.zeta / self.fckp.params.u_max, weights=self.mu)
            u = float(self.fckp.denormalise(p))
        u = float(np.clip(u, 0.0, self.fckp.params.u_max))
        if self.compensate:
            self._kp_state, _ = self.fckp.kp.step(self._kp_state, float(self.fckp.normalise(u)))
        return u

    def stats(self) -> None:
        """None: nothing is solved."""
        return None
