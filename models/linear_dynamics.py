"""The linear block after a hysteresis: none, first or second order, a dead time, a creep.

Unity static gain (the hysteresis carries the gain), so the output at rest equals the
hysteresis output. The creep (:attr:`LinearDynamics.creep`) is a chain of first-order
elements in parallel between the hysteresis and the block: the output answers a held
hysteresis output ``h`` at once with ``(1 − Σ s_i) h`` and creeps the rest of the way, each
element's share ``s_i`` with its time constant ``τ_i``. It is a finite state, so a model with it
generates its whole controller in C.

:meth:`LinearDynamics.discrete` gives the :class:`~hystmpc.models.prediction.Dynamics` both
the prediction model and the simulated plant are built from, and
:meth:`LinearDynamics.response` the same model as a filter, which identification fits: exact
under a zero-order hold of ``h``. With creep, the main block is driven over each sample by the
elements' values at its end, held, which is within one sample's creep of the continuous
:meth:`LinearDynamics.dynamics`.
"""

from __future__ import annotations

from dataclasses import dataclass

import numpy as np

from hystmpc.models.prediction import Dynamics, PredictionModel

KINDS = ("none", "first-order", "second-order")
KIND_KEYS = {"none": (), "first-order": ("time_constant",), "second-order": ("natural_frequency_hz", "damping")}
"""The parameters each kind needs (``delay_samples``, 0 by default, applies to all)."""


@dataclass(frozen=True)
class LinearDynamics:
    """``y = G(s) h`` delayed by ``delay_samples`` samples of the input."""

    kind: str = "none"
    """One of :data:`KINDS`."""
    time_constant: float = 0.01
    """First order: τ (s) of ``τ y' = h − y``."""
    natural_frequency_hz: float = 100.0
    """Second order: f_n (Hz) of ``y'' = ω_n² (h − y) − 2 ζ ω_n y'``."""
    damping: float = 0.5
    """Second order: ζ."""
    delay_samples: int = 0
    """Dead time between the input and the hysteresis (samples)."""
    creep: tuple[tuple[float, float], ...] = ()
    """Kelvin–Voigt creep elements ``(share, time_constant)``: shares >= 0 summing below 1, time
    constants (s) > 0 (the module docstring); empty: no creep."""

    def __post_init__(self):
        if self.kind not in KINDS:
            raise ValueError(f"dynamics kind {self.kind!r} is not one of {', '.join(KINDS)}")
        for name in ("time_constant", "natural_frequency_hz", "damping"):
            value = getattr(self, name)
            if not (np.isfinite(value) and value > 0):
                raise ValueError(f"{name} must be finite and > 0, got {value}")
        if not (isinstance(self.delay_samples, int) and 0 <= self.delay_samples <= 1000):
            raise ValueError(f"delay_samples must be an integer in [0, 1000], got {self.delay_samples}")
        try:
            if any(isinstance(element, str | bytes) for element in self.creep):
                raise TypeError
            creep = tuple((float(share), float(tau)) for share, tau in self.creep)
        except (TypeError, ValueError):
            raise ValueError(f"creep must be a list of [share, time_constant] pairs, got {self.creep!r}") from None
        for share, tau in creep:
            if not (np.isfinite(share) and share >= 0 and np.isfinite(tau) and tau > 0):
                raise ValueError(f"creep element [{share}, {tau}]: the share must be >= 0 and the time constant > 0")
        if sum(share for share, _ in creep) >= 1:
            raise ValueError(f"creep shares sum to {sum(share for share, _ in creep):.4g}; they must sum below 1")
        object.__setattr__(self, "creep", creep)

    def parameters(self) -> dict:
        """The named parameters of this kind (for model and result documents).

        Returns
        -------
        dict
            ``kind``, the kind's keys (:data:`KIND_KEYS`) and ``delay_samples``.
        """
        kind = {"none": {}, "first-order": {"time_constant": self.time_constant},
                "second-order": {"natural_frequency_hz": self.natural_frequency_hz, "damping": self.damping}}
        creep = {"creep": [list(element) for element in self.creep]} if self.creep else {}
        return {"kind": self.kind, **kind[self.kind], "delay_samples": self.delay_samples, **creep}

    @property
    def creep_times(self) -> tuple[float, ...]:
        """The creep elements' time constants (s)."""
        return tuple(tau for _, tau in self.creep)

    def _creep_poles(self, sample_period: float) -> tuple[np.ndarray, np.ndarray]:
        """``(shares, e^{−T/τ_i})`` of the creep elements."""
        shares = np.array([share for share, _ in self.creep])
        return shares, np.exp(-sample_period / np.array(self.creep_times))

    def creep_response(self, h, sample_period: float) -> np.ndarray:
        """The creep's output for ``h_k`` held over each sample, from rest at zero.

        Element ``i`` moves to ``x_i ← a_i x_i + (1 − a_i) h_k`` over sample ``k`` (``a_i =
        e^{−T/τ_i}``, exact under the hold); what the block sees over that sample is
        ``(1 − Σ s_i) h_k + Σ s_i x_i``, the elements at the sample's end.

        Parameters
        ----------
        h : array_like
            Hysteresis output at each sample; may hold one signal per column.
        sample_period : float
            Sample period (s).

        Returns
        -------
        ndarray
            The creep's output, of the shape of ``h`` (``h`` itself without creep).
        """
        h = np.asarray(h, float)
        if not self.creep:
            return h
        shares = [share for share, _ in self.creep]
        out = (1.0 - sum(shares)) * h
        for share, element in zip(shares, self.creep_elements(h, sample_period), strict=True):
            out = out + share * element
        return out

    def creep_elements(self, h, sample_period: float) -> list[np.ndarray]:
        """Each creep element's state at the end of each sample, ``h_k`` held over it, from zero.

        Parameters
        ----------
        h : array_like
            Hysteresis output at each sample; may hold one signal per column.
        sample_period : float
            Sample period (s).

        Returns
        -------
        list of ndarray
            One array of the shape of ``h`` per element (:attr:`creep` order).
        """
        from scipy.signal import lfilter

        h = np.asarray(h, float)
        return [lfilter([1.0 - a], [1.0, -a], h, axis=0) for a in self._creep_poles(sample_period)[1]]

    def rest_state(self, h) -> list:
        """The block's states at rest with the hysteresis output ``h`` (NumPy or CasADi).

        Parameters
        ----------
        h : float or CasADi expression
            The hysteresis output held.

        Returns
        -------
        list
            One entry per state of :meth:`discrete`: ``h`` for the output and each creep element,
            0 for the rate.
        """
        main = {"none": [h], "first-order": [h], "second-order": [h, 0.0]}[self.kind]
        return main + [h] * len(self.creep)

    def state_space(self) -> tuple[np.ndarray, np.ndarray]:
        """Continuous ``(A, B)`` with state ``[y]`` or ``[y, y']`` and input ``h``.

        Returns
        -------
        A : ndarray
            State matrix, ``(n, n)``.
        B : ndarray
            Input vector, ``(n,)``.
        """
        if self.kind == "first-order":
            return np.array([[-1.0 / self.time_constant]]), np.array([1.0 / self.time_constant])
        wn, zeta = 2 * np.pi * self.natural_frequency_hz, self.damping
        return np.array([[0.0, 1.0], [-wn**2, -2 * zeta * wn]]), np.array([0.0, wn**2])

    def discrete(self, sample_period: float, hold: bool = False) -> Dynamics | None:
        """The block as discrete :class:`Dynamics`, exact for ``h`` held over each sample.

        That is a zero-order hold, which is what an input-driven hysteresis gives.

        Parameters
        ----------
        sample_period : float
            Sample period (s).
        hold : bool, optional
            For ``none``, one state that holds ``h`` until the next sample (the same output; a
            creep model needs its output to be a state).

        Returns
        -------
        Dynamics or None
            The discrete block; None for ``none`` without ``hold``.
        """
        if self.creep:
            return self._discrete_with_creep(sample_period)
        if self.kind == "none":
            if not hold:
                return None
            return Dynamics(("output",), lambda x, u, h, d: [h], output=lambda x, h: x[0],
                            steady_input=lambda y: y, discrete=True)
        ad, bd = self._zoh(sample_period)
        n = len(bd)
        names = ("output",) if n == 1 else ("output", "rate")
        return Dynamics(names, lambda x, u, h, d: [sum(ad[i, j] * x[j] for j in range(n)) + bd[i] * h
                                                   for i in range(n)],
                        output=lambda x, h: x[0], steady_input=lambda y: y, discrete=True)

    def _zoh(self, sample_period: float) -> tuple[np.ndarray, np.ndarray]:
        """The main block's ``(A_d, B_d)`` under a zero-order hold (a held output for ``none``)."""
        from scipy.linalg import expm

        if self.kind == "none":
            return np.zeros((1, 1)), np.ones(1)
        a, b = self.state_space()
        n = len(b)
        block = np.zeros((n + 1, n + 1))
        block[:n, :n], block[:n, n] = a * sample_period, b * sample_period
        phi = expm(block)
        return phi[:n, :n], phi[:n, n]

    def _discrete_with_creep(self, sample_period: float) -> Dynamics:
        """The creep elements after the main block's states; the output is always a state."""
        ad, bd = self._zoh(sample_period)
        n = len(bd)
        shares, poles = self._creep_poles(sample_period)
        kept = 1.0 - float(shares.sum())

        def rhs(x, u, h, d):
            elements = [poles[i] * x[n + i] + (1.0 - poles[i]) * h for i in range(len(poles))]
            seen = kept * h + sum(shares[i] * elements[i] for i in range(len(poles)))
            return [sum(ad[i, j] * x[j] for j in range(n)) + bd[i] * seen for i in range(n)] + elements

        names = ("output",) if n == 1 else ("output", "rate")
        return Dynamics((*names, *(f"creep_{i + 1}" for i in range(len(poles)))), rhs,
                        output=lambda x, h: x[0], steady_input=lambda y: y, discrete=True,
                        rest_state=self.rest_state)

    def dynamics(self) -> Dynamics | None:
        """The block as continuous :class:`Dynamics` (None for ``none`` without creep).

        Returns
        -------
        Dynamics or None
            The block, states ``output`` (and ``rate`` for second order, ``creep_i`` for the creep
            elements), or None for ``none`` without creep.
        """
        if self.kind == "none" and not self.creep:
            return None
        taus = self.creep_times
        m = len(taus)
        kept = 1.0 - sum(share for share, _ in self.creep)

        def seen(x, h, n):  # what the main block is driven by: the creep's output
            return kept * h + sum(self.creep[i][0] * x[n + i] for i in range(m))

        def elements(x, h, n):
            return [(h - x[n + i]) / taus[i] for i in range(m)]

        creep_names = tuple(f"creep_{i + 1}" for i in range(m))
        rest = self.rest_state if self.creep else None
        if self.kind == "none":
            return Dynamics(creep_names, lambda x, u, h, d: elements(x, h, 0), output=lambda x, h: seen(x, h, 0),
                            steady_input=lambda y: y, rest_state=lambda h: [h] * m)
        if self.kind == "first-order":
            tau = self.time_constant
            return Dynamics(("output", *creep_names), lambda x, u, h, d: [(seen(x, h, 1) - x[0]) / tau,
                                                                           *elements(x, h, 1)],
                            output=lambda x, h: x[0], steady_input=lambda y: y, rest_state=rest)
        wn, zeta = 2 * np.pi * self.natural_frequency_hz, self.damping
        return Dynamics(("output", "rate", *creep_names),
                        lambda x, u, h, d: [x[1], wn**2 * (seen(x, h, 2) - x[0]) - 2 * zeta * wn * x[1],
                                            *elements(x, h, 2)],
                        output=lambda x, h: x[0], steady_input=lambda y: y, rest_state=rest)

    def virtual_input_model(self, sample_period: float) -> PredictionModel:
        """The block driven by a virtual input ``v`` plus an input disturbance ``d``, after the dead time.

        ``v`` is the hysteresis output asked for; the dead time is a queue of ``v``. This is what is
        left between an inverse hysteresis compensation and the output, for a linear MPC. States:
        the block's (``output`` for ``none``: the output follows ``h`` one sample later) and
        ``delay_1..delay_D``; sensor: the output.

        Parameters
        ----------
        sample_period : float
            Sample period (s).

        Returns
        -------
        PredictionModel
            Step ``(x, u, d) -> x_next`` with ``u`` the virtual input ``v``; output and sensor ``x[0]``.
        """
        import casadi as ca

        block = self.discrete(sample_period, hold=True)
        n, D = len(block.state_names), self.delay_samples
        x, v, d = ca.SX.sym("x", n + D), ca.SX.sym("v"), ca.SX.sym("d")
        v_in = x[n] if D else v
        x_next = ca.vertcat(*block.rhs(x[:n], v_in, v_in + d, 0.0), *[x[n + i] for i in range(1, D)],
                            *([v] if D else []))
        return PredictionModel(
            step=ca.Function("virtual_step", [x, v, d], [x_next], ["x", "u", "d"], ["x_next"]),
            output=ca.Function("virtual_output", [x, d], [x[0]], ["x", "d"], ["y"]),
            measure=ca.Function("virtual_measure", [x, d], [x[0]], ["x", "d"], ["z"]),
            sample_period=sample_period,
            state_names=(*block.state_names, *(f"delay_{i + 1}" for i in range(D))))

    def lag(self) -> float:
        """Low-frequency group delay (s) of the block, dead time and creep not included (a feed-forward's preview).

        Returns
        -------
        float
            0, τ, or ``2ζ/ω_n`` (s).
        """
        return {"none": 0.0, "first-order": self.time_constant,
                 "second-order": 2 * self.damping / (2 * np.pi * self.natural_frequency_hz)}[self.kind]

    def response(self, h, sample_period: float, from_steady_state: bool = False) -> np.ndarray:
        """Output measured at each sample for the hysteresis output ``h_k`` held from that sample on.

        The hold is a zero-order hold, so ``y_k`` depends on ``h_{k-1}`` and earlier. The output
        comes after the dead time and the creep, from rest at zero, or with ``from_steady_state`` at rest at ``h_0``
        (a record that starts with the actuator settled).

        Parameters
        ----------
        h : array_like
            Hysteresis output at each sample; may hold one signal per column.
        sample_period : float
            Sample period (s).
        from_steady_state : bool, optional
            Start at rest at ``h_0``.

        Returns
        -------
        ndarray
            The output at each sample, of the shape of ``h``.
        """
        from scipy.signal import lfilter

        h = np.asarray(h, float)
        start = h[:1] if from_steady_state else None
        if start is not None:
            h = h - start
        if self.delay_samples:
            lead = np.zeros((self.delay_samples, *h.shape[1:])) if start is not None else \
                np.full((self.delay_samples, *h.shape[1:]), h[0] if len(h) else 0.0)
            h = np.concatenate((lead, h))[: len(h)]
        h = self.creep_response(h, sample_period)
        if self.kind == "none":
            out = np.concatenate((h[:1], h[:-1]))
        else:
            out = lfilter(*self.zoh_filter(sample_period), h, axis=0)
        return out if start is None else out + start

    def zoh_filter(self, sample_period: float) -> tuple[np.ndarray, np.ndarray]:
        """``(b, a)`` of the block under a zero-order hold, in closed form.

        A first-order lag's pole ``e^{−T/τ}``; a second-order block's partial fractions over its two
        poles, exact to about ``1e-16 / |ζ − 1|`` relative, a double pole's own form at ``ζ = 1``.

        Parameters
        ----------
        sample_period : float
            Sample period (s).

        Returns
        -------
        b : ndarray
            Numerator coefficients (no feed-through: ``b[0] = 0``).
        a : ndarray
            Denominator coefficients, ``a[0] = 1``.
        """
        if self.kind == "first-order":
            pole = np.exp(-sample_period / self.time_constant)
            return np.array([0.0, 1.0 - pole]), np.array([1.0, -pole])
        wn, zeta = 2 * np.pi * self.natural_frequency_hz, self.damping
        if abs(zeta - 1.0) < 1e-7:  # a double pole: G(s)/s = 1/s − 1/(s+ω) − ω/(s+ω)²
            e, wt = np.exp(-wn * sample_period), wn * sample_period
            return np.array([0.0, 1.0 - e - wt * e, e * e - e + wt * e]), np.array([1.0, -2.0 * e, e * e])
        root = np.sqrt(complex(zeta * zeta - 1.0))
        p1, p2 = wn * (-zeta + root), wn * (-zeta - root)
        r1, r2 = wn**2 / (p1 * (p1 - p2)), wn**2 / (p2 * (p2 - p1))  # G(s)/s = 1/s + r1/(s-p1) + r2/(s-p2)
        z1, z2 = np.exp(p1 * sample_period), np.exp(p2 * sample_period)
        # (1 - q)·[1/(1-q) + r1/(1-z1 q) + r2/(1-z2 q)] over (1-z1 q)(1-z2 q), q the delay operator
        a = np.array([1.0, -(z1 + z2), z1 * z2])
        b = np.real(a + np.convolve([1.0, -1.0], r1 * np.array([1.0, -z2]) + r2 * np.array([1.0, -z1])))
        b[0] = 0.0  # no feed-through under a hold (rounding leaves ~1e-13 near ζ = 1)
        return b, np.real(a)
