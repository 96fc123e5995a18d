"""Fractional-order creep KP (FCKP) model, wang2025 eq. (9): ``W[u] = D^(−α) w[u]``.

``w[u]`` is the KP model (eq. (5)) of the normalised input ``p = 2(u − u_min)/(u_max − u_min) − 1``, shifted and
scaled to a displacement: ``w = stroke (κ/Σμ + 1)/2``, so zero volts on a demagnetised
actuator gives zero (the shift is a constant kernel, which eq. (5) allows). The creep is
the GL fractional *integral* of order α on ``w`` (a constant input rises ∝ t^α, benches.md).

The KP memory is a state vector (``[p_last, ξ_1..ξ_n]``); the creep memory is the whole
past of ``w`` and lives in a :class:`hystmpc.models.fractional.GrunwaldLetnikov` object.
"""

from __future__ import annotations

from dataclasses import dataclass

import casadi as ca
import numpy as np

from hystmpc.models.base import SteppedModel, smooth_function, symbolic
from hystmpc.models.fractional import GrunwaldLetnikov
from hystmpc.models.kp import KrasnoselskiiPokrovskii, paper_density, threshold_grid


@dataclass(frozen=True)
class FckpParams:
    """Parameters of an FCKP model on a threshold grid with the density of Fig. 3."""

    levels: int = 12
    """Thresholds on the grid's axis."""
    max_span: int = 2
    """Kernels only for threshold pairs at most this many grid steps apart (loops of at
    most 2 × 0.17 of the normalised range 2): a DEA's loop is narrow, and the NLP smaller."""
    delta: float = 0.15
    """Slope parameter δ of eq. (7), in normalised input units (input range 2)."""
    density_c: float = 2.0
    """c of the density under Fig. 3."""
    density_sigma: float = 1.0
    """σ of the density under Fig. 3."""
    creep_order: float = 0.02
    """α (Section 5.1 identifies 0.02)."""
    stroke: float = 4.0
    """Creep-free output at full input (mm)."""
    u_max: float = 10.0
    """Input range [0, u_max] (V into the 1000 V/V amplifier)."""
    sample_period: float = 0.01
    """GL step h (s): the input is held between samples."""
    u_min: float = 0.0
    """Lower end of the input range [u_min, u_max] (a bipolar input: below zero)."""

    def __post_init__(self):
        if self.levels < 2 or self.max_span < 1:
            raise ValueError(f"levels must be >= 2 and max_span >= 1, got {self.levels}, {self.max_span}")
        for name in ("delta", "density_c", "density_sigma", "stroke", "u_max", "sample_period"):
            value = getattr(self, name)
            if not (np.isfinite(value) and value > 0):
                raise ValueError(f"{name} must be finite and > 0, got {value}")
        if not (np.isfinite(self.u_min) and self.u_min < self.u_max):
            raise ValueError(f"u_min must be finite and below u_max = {self.u_max}, got {self.u_min}")
        if not (np.isfinite(self.creep_order) and 0 <= self.creep_order < 1):
            raise ValueError(f"creep_order must be in [0, 1), got {self.creep_order}")


class Fckp(SteppedModel):
    """FCKP model: KP on the normalised input, then the GL creep integral.

    As a :class:`hystmpc.models.base.HysteresisModel` it is the creep-free part, volts to
    millimetres (``step``, ``smooth_step``, ``inverse_step``); its state is the KP state, whose
    first entry is the last input in normalised units ``p``. The creep memory is a separate
    :class:`GrunwaldLetnikov` object (:meth:`creep`), stepped with :meth:`creep_step`.

    Parameters
    ----------
    params : FckpParams
        Grid, density, creep order, scaling.
    """

    def __init__(self, params: FckpParams = FckpParams()):
        self.params = params
        rho1, rho2 = threshold_grid(params.levels, params.delta, params.max_span)
        weights = paper_density(rho1, rho2, params.density_c, params.density_sigma)
        self.kp = KrasnoselskiiPokrovskii(rho1, rho2, weights, params.delta)

    @property
    def state_names(self) -> tuple[str, ...]:
        """The KP state: ``u_last`` (normalised) and the kernel outputs."""
        return self.kp.state_names

    @property
    def creep_order(self) -> float:
        """α of ``D^(−α)``."""
        return self.params.creep_order

    def normalise(self, u):
        """Input voltage to the KP input p ∈ [−1, 1].

        Parameters
        ----------
        u : float, ndarray or CasADi expression
            Input (V).

        Returns
        -------
        float, ndarray or CasADi expression
            p, −1 at ``u_min`` and 1 at ``u_max``.
        """
        lo = self.params.u_min
        if lo == 0:  # the paper's range [0, u_max], in its own arithmetic
            return 2.0 * u / self.params.u_max - 1.0
        return 2.0 * (u - lo) / (self.params.u_max - lo) - 1.0

    def denormalise(self, p):
        """KP input back to volts.

        Parameters
        ----------
        p : float, ndarray or CasADi expression
            Normalised input.

        Returns
        -------
        float, ndarray or CasADi expression
            Input (V).
        """
        lo = self.params.u_min
        if lo == 0:
            return 0.5 * (p + 1.0) * self.params.u_max
        return 0.5 * (p + 1.0) * (self.params.u_max - lo) + lo

    def static(self, kappa):
        """KP output κ to the creep-free displacement w (mm).

        Parameters
        ----------
        kappa : float, ndarray or CasADi expression
            KP output κ.

        Returns
        -------
        float, ndarray or CasADi expression
            w = stroke (κ/Σμ + 1)/2 (mm).
        """
        return self.params.stroke * 0.5 * (kappa / self.kp.total_weight + 1.0)

    def kappa_of(self, w):
        """Inverse of :meth:`static`.

        Parameters
        ----------
        w : float, ndarray or CasADi expression
            Creep-free displacement (mm).

        Returns
        -------
        float, ndarray or CasADi expression
            KP output κ.
        """
        return (2.0 * w / self.params.stroke - 1.0) * self.kp.total_weight

    def initial_state(self, u0: float = 0.0) -> np.ndarray:
        """Demagnetised at ``u0`` volts (every kernel at −1 at ``u_min``, the default zero).

        Parameters
        ----------
        u0 : float, optional
            Input the state rests at (V).

        Returns
        -------
        ndarray
            The KP state.
        """
        return self.kp.initial_state(float(self.normalise(u0)))

    def output(self, state):
        """Creep-free displacement w (mm) of a state (NumPy or CasADi).

        Parameters
        ----------
        state : ndarray or CasADi expression
            A KP state.

        Returns
        -------
        float or CasADi expression
            w (mm).
        """
        w = self.static(self.kp.output(state))
        return w if symbolic(w) else float(w)

    def mean_static_curve(self, n: int = 401) -> tuple[np.ndarray, np.ndarray]:
        """Mean of the rising and falling major-loop branches of w(u): ``(u, w)`` on ``n`` voltages.

        Parameters
        ----------
        n : int, optional
            Number of voltages, evenly spaced over ``[u_min, u_max]``.

        Returns
        -------
        u : ndarray
            The voltages (V).
        w : ndarray
            The mean creep-free displacement at each (mm).
        """
        u = np.linspace(self.params.u_min, self.params.u_max, n)
        state = self.initial_state()
        up = np.empty(n)
        for i, v in enumerate(u):
            state, up[i] = self.step(state, v)
        down = np.empty(n)
        for i, v in enumerate(u[::-1]):
            state, down[i] = self.step(state, v)
        return u, 0.5 * (up + down[::-1])

    def creep(self, window: int | None = None) -> GrunwaldLetnikov:
        """A fresh creep memory: ``D^(−α)`` at step h with memory window ``window``.

        Parameters
        ----------
        window : int, optional
            Memory window (samples); None: the full memory.

        Returns
        -------
        GrunwaldLetnikov
            The empty memory.
        """
        return GrunwaldLetnikov(-self.params.creep_order, self.params.sample_period, window)

    def creep_inverse(self, window: int | None = None) -> GrunwaldLetnikov:
        """A fresh creep-inverse memory: ``D^(+α)``, Section 2.3.

        The exact inverse of :meth:`creep` for the same h and full memory, since the GL weights of
        ±α convolve to 1.

        Parameters
        ----------
        window : int, optional
            Memory window (samples); None: the full memory.

        Returns
        -------
        GrunwaldLetnikov
            The empty memory.
        """
        return GrunwaldLetnikov(self.params.creep_order, self.params.sample_period, window)

    def step(self, state, u: float) -> tuple[np.ndarray, float]:
        """Exact KP step to voltage ``u``; returns ``(state, w)`` (creep-free, mm).

        Also on CasADi expressions.

        Parameters
        ----------
        state : ndarray or CasADi expression
            KP state before the step.
        u : float or CasADi expression
            New input (V).

        Returns
        -------
        state : ndarray or CasADi expression
            KP state after the step.
        w : float or CasADi expression
            Creep-free displacement after the step (mm).
        """
        if symbolic(state) or symbolic(u):
            state, kappa = self.kp.step(state, self.normalise(u))
            return state, self.static(kappa)
        state, kappa = self.kp.step(state, float(self.normalise(u)))
        return state, float(self.static(kappa))

    def creep_step(self, state, creep: GrunwaldLetnikov, u: float) -> tuple[np.ndarray, float]:
        """Exact FCKP step: KP, then push w into the creep memory; returns ``(state, W)``.

        Parameters
        ----------
        state : ndarray
            KP state before the step.
        creep : GrunwaldLetnikov
            Creep memory (from :meth:`creep`), updated in place.
        u : float
            New input (V).

        Returns
        -------
        state : ndarray
            KP state after the step.
        W : float
            Displacement with creep (mm).
        """
        state, w = self.step(state, u)
        return state, creep.push(w)

    def smooth_step(self, eps: float, direction_eps: float | None = None) -> ca.Function:
        """Smooth KP step in volts ``(state, u) -> (state_next, w)`` (CasADi).

        See :meth:`KrasnoselskiiPokrovskii.smooth_step` for the error.

        Parameters
        ----------
        eps : float
            Width of the smoothed ridge and max/min, > 0.
        direction_eps : float, optional
            Width of the direction detection (default: ``eps``).

        Returns
        -------
        casadi.Function
            ``(state, u) -> (state_next, y)``, ``y`` the creep-free displacement w (mm).
        """
        inner = self.kp.smooth_step(eps, direction_eps)

        def expressions(x, u):
            x_next, kappa = inner(x, self.normalise(u))
            return x_next, self.static(kappa)
        return smooth_function("fckp_smooth", self.kp.n_kernels + 1, expressions)

    def inverse_step(self, state, w_target: float, zeta: float = 0.01) -> tuple[np.ndarray, float]:
        """Section 3.2: the voltage whose KP output reaches ``w_target``; returns ``(state, u)``.

        Searched from the last input in steps of ζ. On CasADi expressions (a generated
        controller) it bisects instead (:meth:`KrasnoselskiiPokrovskii.bisection_inverse`; ``zeta``
        does not apply); both find the same input (docs/dea.md).

        Parameters
        ----------
        state : ndarray or CasADi expression
            KP state to move from.
        w_target : float or CasADi expression
            Creep-free displacement to reach (mm).
        zeta : float, optional
            Search step ζ (V).

        Returns
        -------
        state : ndarray or CasADi expression
            KP state after the move.
        u : float or CasADi expression
            The input (V), within ``[u_min, u_max]``.
        """
        if symbolic(state) or symbolic(w_target):
            p_state, p = self.kp.bisection_inverse(state, self.kappa_of(w_target))
            return p_state, self.denormalise(p)
        p_state, p = self.kp.inverse_step(state, float(self.kappa_of(w_target)), -1.0, 1.0,
                                          step=2.0 * zeta / (self.params.u_max - self.params.u_min))
        return p_state, float(self.denormalise(p))
