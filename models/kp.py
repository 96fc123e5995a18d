"""Krasnoselskii–Pokrovskii (KP) hysteresis, wang2025 eqs. (5)–(7).

A KP kernel with thresholds ρ1 < ρ2 and slope δ follows the ridge function (eq. (7))
``φ(τ) = −1 (τ ≤ 0), −1 + 2τ/δ (0 < τ < δ), 1 (τ ≥ δ)``: while the input rises its output
is ``max(ξ, φ(u − ρ2))``, while it falls ``min(ξ, φ(u − ρ1))``, where ξ is its last output
(eq. (6)). So it switches up over [ρ2, ρ2 + δ] and down over [ρ1, ρ1 + δ], and stays in
[−1, 1]. The KP model is the density-weighted sum over a threshold grid (eq. (5)).

State: ``[u_last, ξ_1, …, ξ_n]``.
"""

from __future__ import annotations

from dataclasses import dataclass

import casadi as ca
import numpy as np

from hystmpc.models.base import SteppedModel, builtin_max, builtin_min, check_smoothing, clip, smooth_function, symbolic
from hystmpc.models.smooth import smooth_clip, smooth_max, smooth_min


def ridge(tau, delta: float):
    """Ridge function φ_R of eq. (7) (NumPy).

    Parameters
    ----------
    tau : float or array_like
        Distance of the input above the threshold.
    delta : float
        Slope parameter δ > 0.

    Returns
    -------
    ndarray
        φ(τ), in [−1, 1].
    """
    # np.clip's own operations (max, then min; NaN kept) without its Python wrappers: ~3 × faster
    return np.minimum(np.maximum(-1.0 + 2.0 * np.asarray(tau, float) / delta, -1.0), 1.0)


def paper_density(rho1, rho2, c: float = 2.0, sigma: float = 1.0, scale: float = 0.004):
    """The density given with Fig. 3: ``scale / ([1 + ((ρ1 − c)/(cσ))²] [1 + ((ρ2 + c)/(cσ))²])``.

    Read from the garbled text as the usual product of two Cauchy factors; it is positive
    and largest for kernels with a high ρ1 and a low ρ2 (narrow loops).

    Parameters
    ----------
    rho1, rho2 : array_like
        Kernel thresholds.
    c : float, optional
        Centre parameter ``c``.
    sigma : float, optional
        Width parameter ``σ``.
    scale : float, optional
        Peak value.

    Returns
    -------
    ndarray
        The density at each kernel.
    """
    rho1, rho2 = np.asarray(rho1, float), np.asarray(rho2, float)
    return scale / ((1 + ((rho1 - c) / (c * sigma)) ** 2) * (1 + ((rho2 + c) / (c * sigma)) ** 2))


def threshold_grid(levels: int, delta: float, max_span: int | None = None, low: float = -1.0,
                   high: float = 1.0):
    """Pairs (ρ1, ρ2), ρ1 < ρ2, on ``levels`` thresholds in [low, high − δ].

    Parameters
    ----------
    levels : int
        Number of thresholds, >= 2.
    delta : float
        Slope parameter δ, in (0, high − low).
    max_span : int, optional
        Keep only pairs at most that many grid steps apart (narrower loops, fewer kernels);
        None keeps every pair.
    low, high : float, optional
        Ends of the input range.

    Returns
    -------
    rho1, rho2 : ndarray
        Thresholds of each pair.
    """
    if levels < 2:
        raise ValueError(f"levels must be >= 2, got {levels}")
    if not 0 < delta < high - low:
        raise ValueError(f"delta must be in (0, {high - low}), got {delta}")
    if max_span is not None and max_span < 1:
        raise ValueError(f"max_span must be >= 1 or None, got {max_span}")
    t = np.linspace(low, high - delta, levels)
    i, j = np.triu_indices(levels, k=1)
    if max_span is not None:
        keep = j - i <= max_span
        i, j = i[keep], j[keep]
    return t[i], t[j]


@dataclass(frozen=True)
class KrasnoselskiiPokrovskii(SteppedModel):
    """KP model: ``κ[u] = Σ μ_i κ_i[u]`` over kernels with thresholds ``(rho1_i, rho2_i)``.

    Parameters
    ----------
    rho1, rho2 : array_like
        Kernel thresholds, ``rho2 >= rho1 + delta`` for each kernel.
    weights : array_like
        Density μ at each kernel (times the grid cell area), ``>= 0``.
    delta : float
        Slope parameter δ > 0 of eq. (7).
    """

    rho1: np.ndarray
    rho2: np.ndarray
    weights: np.ndarray
    delta: float

    def __post_init__(self):
        for name in ("rho1", "rho2", "weights"):
            object.__setattr__(self, name, np.asarray(getattr(self, name), float).ravel())
        n = len(self.rho1)
        if not (len(self.rho2) == n == len(self.weights)) or n == 0:
            raise ValueError("rho1, rho2 and weights must have the same, non-zero length")
        if not self.delta > 0:
            raise ValueError(f"delta must be > 0, got {self.delta}")
        if np.any(self.weights < 0) or not np.all(np.isfinite(self.weights)):
            raise ValueError("weights must be finite and >= 0")
        if np.any(self.rho2 < self.rho1 + self.delta - 1e-12):
            raise ValueError("each kernel needs rho2 >= rho1 + delta")

    @property
    def n_kernels(self) -> int:
        """Number of kernels."""
        return len(self.rho1)

    @property
    def state_names(self) -> tuple[str, ...]:
        """``u_last`` and the kernel outputs ``ξ_1..ξ_n``."""
        return ("u_last", *(f"kernel_{i + 1}" for i in range(self.n_kernels)))

    @property
    def total_weight(self) -> float:
        """Σ μ: the output spans [−Σμ, Σμ]."""
        return float(self.weights.sum())

    def initial_state(self, u0: float) -> np.ndarray:
        """State after a monotone rise to ``u0`` from below every threshold.

        All kernels are at −1 when ``u0`` is below every ρ2.

        Parameters
        ----------
        u0 : float
            Input the state rests at.

        Returns
        -------
        ndarray
            ``[u0, ξ_1, …, ξ_n]``.
        """
        u0 = float(u0)
        return np.concatenate(([u0], ridge(u0 - self.rho2, self.delta)))

    def kernels_step(self, state, u: float) -> np.ndarray:
        """Kernel outputs ξ after moving the input to ``u`` (eq. (6)); also on CasADi expressions.

        Parameters
        ----------
        state : ndarray or CasADi expression
            State before the move.
        u : float or CasADi expression
            New input.

        Returns
        -------
        ndarray or CasADi expression
            ξ_1..ξ_n after the move.
        """
        if symbolic(state) or symbolic(u):
            u_last, xi = state[0], state[1:]
            rising = builtin_max(xi, clip(-1.0 + 2.0 * (u - ca.DM(self.rho2)) / self.delta, -1.0, 1.0))
            falling = builtin_min(xi, clip(-1.0 + 2.0 * (u - ca.DM(self.rho1)) / self.delta, -1.0, 1.0))
            return ca.if_else(u > u_last, rising, ca.if_else(u < u_last, falling, xi))
        return self._kernels_after(float(state[0]), np.asarray(state[1:], float), u)

    def _kernels_after(self, u_last: float, xi: np.ndarray, u: float) -> np.ndarray:
        """ξ after the input moves from ``u_last`` to ``u`` (NumPy; ``xi`` is not changed)."""
        if u > u_last:
            return np.maximum(xi, ridge(u - self.rho2, self.delta))
        if u < u_last:
            return np.minimum(xi, ridge(u - self.rho1, self.delta))
        return xi.copy()

    def step(self, state, u: float, weights=None) -> tuple[np.ndarray, float]:
        """Exact step to input ``u``; returns ``(state, κ)``.

        Also on CasADi expressions (without ``weights``).

        Parameters
        ----------
        state : ndarray or CasADi expression
            State before the step.
        u : float or CasADi expression
            New input (finite).
        weights : array_like, optional
            Replaces the density (for adaptive estimates of it); NumPy states only.

        Returns
        -------
        state : ndarray or CasADi expression
            State after the step.
        y : float or CasADi expression
            Output κ after the step.
        """
        if symbolic(state) or symbolic(u):
            if weights is not None:
                raise ValueError("weights applies to NumPy states only")
            xi = self.kernels_step(state, u)
            return ca.vertcat(u, xi), ca.dot(ca.DM(self.weights), xi)
        if not np.isfinite(u):
            raise ValueError(f"u must be finite, got {u}")
        xi = self.kernels_step(state, u)
        return np.concatenate(([u], xi)), float((self.weights if weights is None else weights) @ xi)

    def output(self, state):
        """κ of a state (NumPy or CasADi).

        Parameters
        ----------
        state : ndarray or CasADi expression
            A state.

        Returns
        -------
        float or CasADi expression
            κ with the model's own weights.
        """
        if symbolic(state):
            return ca.dot(ca.DM(self.weights), state[1:])
        return float(self.weights @ np.asarray(state[1:], float))

    def smooth_kernels(self, u_last, xi, u, eps: float, direction_eps: float):
        """Smooth kernel update (CasADi or NumPy): smoothed ridge, max/min and direction.

        The direction is ``s = tanh(Δu / direction_eps)``; the rising and falling updates are
        blended by ``(1 ± s)/2``, so a standing input keeps the average of both, which equals
        ξ away from the ridges.

        Parameters
        ----------
        u_last : float or CasADi expression
            Last input.
        xi : ndarray or CasADi expression
            Kernel outputs before the move.
        u : float or CasADi expression
            New input.
        eps : float
            Width of the smoothed ridge and max/min.
        direction_eps : float
            Width of the direction detection.

        Returns
        -------
        ndarray or CasADi expression
            Smoothed kernel outputs after the move.
        """
        s = ca.tanh((u - u_last) / direction_eps)
        up = smooth_max(xi, smooth_clip(-1.0 + 2.0 * (u - self.rho2) / self.delta, 1.0, eps), eps)
        down = smooth_min(xi, smooth_clip(-1.0 + 2.0 * (u - self.rho1) / self.delta, 1.0, eps), eps)
        return 0.5 * (1 + s) * up + 0.5 * (1 - s) * down

    def smooth_step(self, eps: float, direction_eps: float | None = None) -> ca.Function:
        """Smooth step ``(state, u) -> (state_next, κ)`` as a CasADi Function.

        Ridge, max/min and direction smoothed (:meth:`smooth_kernels`). The output error is
        O(eps) on a reversing input.

        Parameters
        ----------
        eps : float
            Width of the smoothed ridge and max/min, > 0.
        direction_eps : float, optional
            Width of the direction detection (default: ``eps``).

        Returns
        -------
        casadi.Function
            ``(state, u) -> (state_next, y)``.
        """
        check_smoothing(eps, direction_eps)
        direction_eps = direction_eps or eps
        weights = ca.DM(self.weights)

        def expressions(x, u):
            xi = self.smooth_kernels(x[0], x[1:], u, eps, direction_eps)
            return ca.vertcat(u, xi), ca.dot(weights, xi)
        return smooth_function("kp_smooth", self.n_kernels + 1, expressions)

    def inverse_step(self, state, y_target: float, u_min: float = -1.0, u_max: float = 1.0,
                     step: float = 0.01, weights=None) -> tuple[np.ndarray, float]:
        """Implicit inverse (Section 3.2): search from the last input in steps of ζ = ``step``.

        Moves the input up (or down) from ``u_last`` in steps of ``step`` until the model
        output reaches ``y_target``, then refines within the last step by bisection; returns
        the bound when the target is beyond what the range can reach. On CasADi expressions (a
        generated controller) :meth:`bisection_inverse`, with the model's own weights.

        Parameters
        ----------
        state : ndarray or CasADi expression
            State to move from.
        y_target : float or CasADi expression
            Output to reach (finite).
        u_min, u_max : float, optional
            Input range.
        step : float, optional
            Search step ζ (NumPy only).
        weights : array_like, optional
            Replaces the density, as in :meth:`step` (NumPy only).

        Returns
        -------
        state : ndarray or CasADi expression
            State after the move.
        u : float or CasADi expression
            The input.
        """
        if symbolic(state) or symbolic(y_target):
            if weights is not None:
                raise ValueError("the symbolic inverse uses the model's own weights; weights must stay None")
            return self.bisection_inverse(state, y_target, u_min, u_max)
        if not np.isfinite(y_target):
            raise ValueError(f"y_target must be finite, got {y_target}")
        if not (np.isfinite(u_min) and np.isfinite(u_max) and np.isfinite(step) and step > 0):
            raise ValueError(f"u_min, u_max and step must be finite (step > 0), got {u_min}, {u_max}, {step}")
        u_min, u_max = float(u_min), float(u_max)
        # The outputs of step(state, u, weights), without building a state for every trial input
        start, xi = float(state[0]), np.asarray(state[1:], float)
        density = self.weights if weights is None else weights

        def output(u: float) -> float:
            return float(density @ self._kernels_after(start, xi, u))
        u_last = min(max(start, u_min), u_max)  # np.clip of a float
        if not np.isfinite(u_last):
            raise ValueError(f"u must be finite, got {u_last}")
        y_now = output(u_last)
        sign = 1.0 if y_target > y_now else -1.0
        bound = u_max if sign > 0 else u_min
        reached = (lambda y: y >= y_target) if sign > 0 else (lambda y: y <= y_target)
        lo = u_last
        u = u_last
        while True:
            u = min(max(u + sign * step, u_min), u_max)
            if reached(output(u)):
                break
            lo = u
            if u == bound:
                return self.step(state, u)[0], u
        hi = u
        for _ in range(30):  # bisection within the last ζ step
            mid = 0.5 * (lo + hi)
            if reached(output(mid)):
                hi = mid
            else:
                lo = mid
        return self.step(state, hi)[0], hi

    def bisection_inverse(self, state, y_target, u_min: float = -1.0, u_max: float = 1.0,
                          iterations: int = 44):
        """An input that reaches ``y_target`` from ``state`` by bisection, and the state after it.

        On CasADi expressions (the same arithmetic as the generated C).

        The output moves monotonically with the input in the direction of the target, so
        ``iterations`` halvings of ``[u_last, bound]`` (width at most 2) find the input where the
        target is first reached to ``2^-iterations`` of that width (44: about 1e-13); a target
        beyond the bound gives the bound, as :meth:`inverse_step` does. The halvings run as a
        CasADi fold: generated C keeps one loop, not ``iterations`` copies.

        Parameters
        ----------
        state : ndarray or CasADi expression
            State to move from.
        y_target : float or CasADi expression
            Output to reach.
        u_min, u_max : float, optional
            Input range.
        iterations : int, optional
            Number of halvings.

        Returns
        -------
        state : casadi.DM or CasADi expression
            State after the move.
        u : casadi.DM or CasADi expression
            The input.
        """
        n = self.n_kernels + 1
        x, target, up = ca.SX.sym("state", n), ca.SX.sym("target"), ca.SX.sym("up")
        lo, hi = ca.SX.sym("lo"), ca.SX.sym("hi")

        def reached(u):
            y = self.step(x, u)[1]
            return ca.if_else(up, y >= target, y <= target)
        mid = 0.5 * (lo + hi)
        halve = ca.Function("kp_bisect", [ca.vertcat(lo, hi), ca.vertcat(x, target, up)],
                            [ca.if_else(reached(mid), ca.vertcat(lo, mid), ca.vertcat(mid, hi))])
        x, target = ca.MX.sym("state", n), ca.MX.sym("target")  # MX: the fold stays a call
        u_last = clip(x[0], u_min, u_max)
        rising = target > self.step(x, u_last)[1]
        bound = ca.if_else(rising, u_max, u_min)
        start = ca.vertcat(u_last, bound)
        bracket = halve.fold(iterations)(start, ca.vertcat(x, target, rising))
        u = ca.if_else(ca.if_else(rising, self.step(x, bound)[1] >= target, self.step(x, bound)[1] <= target),
                       bracket[1], bound)
        inverse = ca.Function("kp_inverse", [x, target], [self.step(x, u)[0], u], {"never_inline": True})
        return inverse(state, y_target)
