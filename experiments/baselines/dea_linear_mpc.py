"""wang2025's linear MPC baseline (Section 5.2): OSQP on the linearised mechanics."""

from __future__ import annotations

from dataclasses import dataclass

import numpy as np

from hystmpc.models.fckp import Fckp
from hystmpc.plants.dea import DeaParams


@dataclass(frozen=True)
class DeaLinearMpcSettings:
    """Linear MPC of Section 5.2 (``--set linear_mpc.KEY=VALUE``)."""

    prediction: int = 15
    control: int = 5
    q_output: float = 0.13
    r_rate: float = 0.75
    r_input: float = 0.0

    def __post_init__(self):
        if not 1 <= self.control <= self.prediction:
            raise ValueError(f"need 1 <= control <= prediction, got {self.control}, {self.prediction}")
        for name in ("q_output", "r_rate", "r_input"):
            if not (np.isfinite(getattr(self, name)) and getattr(self, name) >= 0):
                raise ValueError(f"{name} must be finite and >= 0, got {getattr(self, name)}")


class DeaLinearMpc:
    """Linear MPC with OSQP (Section 5.2): the paper's horizons and weights, u ∈ [0, 10] V.

    Model: the nominal mechanics linearised at ``x1 = 1.5 mm`` (mid-range), driven by
    ``W ≈ a u + b`` (a least-squares line through the mean static curve of the nominal FCKP
    model) plus an input disturbance ``d`` (in W units) that a Kalman filter estimates from
    the laser: hysteresis, creep and mismatch all land in ``d``, which makes the tracking
    offset-free. The QP is condensed over the control moves Δu_0..Δu_{Nc−1}; the input is
    held after the control horizon; the reference over the prediction horizon is previewed.

    Parameters
    ----------
    settings : DeaLinearMpcSettings
        Horizons and weights.
    model : DeaParams
        The nominal model (its mechanics, FCKP, sample period and sensor noise).
    """

    def __init__(self, settings: DeaLinearMpcSettings, model: DeaParams):
        import osqp
        from scipy import sparse
        from scipy.linalg import expm

        self.s, self.model = settings, model
        self.horizon = settings.prediction
        dt = model.sample_period
        fckp = Fckp(model.fckp)
        u, w = fckp.mean_static_curve()
        mid = (w > 0.1 * w.max()) & (w < 0.9 * w.max())
        self.a, self.b = np.polyfit(u[mid], w[mid], 1)
        x0, h = 1.5, 1e-6
        k_spring = -(model.f(x0 + h, 0.0) - model.f(x0 - h, 0.0)) / (2 * h)
        c_damp = -(model.f(x0, h) - model.f(x0, -h)) / (2 * h)
        g0 = float(model.g(x0))
        # continuous [x1, x2, d] with input W; the spring is linearised around x0 (f(x0) + g0 W0 = 0)
        Ac = np.array([[0.0, 1.0, 0.0], [-k_spring, -c_damp, g0], [0.0, 0.0, 0.0]])
        Bc = np.array([[0.0], [g0], [0.0]])
        M = expm(np.block([[Ac, Bc], [np.zeros((1, 4))]]) * dt)
        self.A, self.B = M[:3, :3], M[:3, 3:]
        w_eq = (float(model.f(x0, 0.0)) + k_spring * x0) / -g0  # W offset of the affine spring
        self._w_offset = w_eq
        self.C = np.array([[1.0, 0.0, 0.0]])
        Np, Nc = settings.prediction, settings.control
        n = 3
        Phi = np.zeros((Np, n))
        Gamma = np.zeros((Np, Np))  # response of y_{k+1..k+Np} to u_k..u_{k+Np−1}
        Ak = np.eye(n)
        for i in range(Np):
            Ak = self.A @ Ak
            Phi[i] = (self.C @ Ak).ravel()
        for i in range(Np):
            for j in range(i + 1):
                Gamma[i, j] = (self.C @ np.linalg.matrix_power(self.A, i - j) @ self.B).item()
        # u_j = u_prev + Σ_{m<=min(j, Nc−1)} Δu_m
        S = np.tril(np.ones((Np, Nc)))
        self._Phi, self._S = Phi, S
        self._G = Gamma @ S * self.a
        self._Gamma = Gamma
        q, r = settings.q_output, settings.r_rate
        L = np.tril(np.ones((Nc, Nc)))
        P = 2 * (q * self._G.T @ self._G + r * np.eye(Nc) + settings.r_input * S.T @ S)
        self._solver = osqp.OSQP()
        self._solver.setup(P=sparse.csc_matrix(P), q=np.zeros(Nc), A=sparse.csc_matrix(L),
                           l=np.zeros(Nc), u=np.full(Nc, model.fckp.u_max), verbose=False, warm_starting=True,
                           eps_abs=1e-8, eps_rel=1e-8, max_iter=4000, polishing=False)
        # Kalman filter on [x1, x2, d]
        self._Q = np.diag([1e-10, 1e-6, 1e-6])
        self._R = model.noise**2 if model.noise > 0 else 1e-12
        self.reset()

    def reset(self) -> None:
        """At rest, no disturbance estimate."""
        self.x = np.zeros(3)
        self.P = np.diag([1e-6, 1e-4, 1.0])
        self._u = 0.0
        self._started = False
        self.failures = 0
        self.predicted_output = float("nan")

    def _affine(self, u):
        """W of the linear model for voltage u, relative to the spring's linearisation."""
        return self.a * u + self.b - self._w_offset

    def step(self, measurement, ref_window) -> float:
        """Voltage for this sample.

        Parameters
        ----------
        measurement : Measurement
            This sample's measurement (its displacement ``y``, mm).
        ref_window : ndarray
            The references ``r_k..r_{k+Np}`` (mm).

        Returns
        -------
        float
            The voltage (V), within ``[0, u_max]``; the last one held when OSQP fails.
        """
        if self._started:  # time update with the applied input
            self.x = self.A @ self.x + (self.B * self._affine(self._u)).ravel()
            self.P = self.A @ self.P @ self.A.T + self._Q
        self.predicted_output = float(self.x[0])
        S = self.P[0, 0] + self._R
        K = self.P[:, 0] / S
        self.x = self.x + K * (measurement.y - self.x[0])
        self.P = self.P - np.outer(K, self.P[0])
        self._started = True
        s = self.s
        ref = np.asarray(ref_window[1: s.prediction + 1], float)
        free = self._Phi @ self.x + self._Gamma @ np.full(s.prediction, self._affine(self._u))
        q = 2 * s.q_output * self._G.T @ (free - ref) + 2 * s.r_input * self._S.T @ np.full(s.prediction, self._u)
        room = np.ones(s.control)
        self._solver.update(q=q, l=-self._u * room, u=(self.model.fckp.u_max - self._u) * room)
        result = self._solver.solve(raise_error=False)
        if result.info.status_val not in (1, 2) or not np.all(np.isfinite(result.x)):
            self.failures += 1
            u = self._u  # hold the last input
        else:
            u = float(np.clip(self._u + result.x[0], 0.0, self.model.fckp.u_max))
        self._u = u
        return u

    def stats(self) -> dict:
        """OSQP failures (input held).

        Returns
        -------
        dict
            ``name`` (``osqp``), ``failures`` and ``fallbacks`` (the same count).
        """
        return {"name": "osqp", "failures": self.failures, "fallbacks": self.failures}
