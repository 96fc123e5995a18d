"""Extended Kalman filter on the model state augmented with a constant disturbance."""

from __future__ import annotations

import casadi as ca
import numpy as np

from mpc.model import PredictionModel


class DisturbanceEKF:
    """EKF on ``[x; d]`` with ``d+ = d`` (random walk): offset-free estimates for the NMPC.

    Parameters
    ----------
    model : PredictionModel
        Nominal model; its Jacobians are generated once with CasADi.
    process_noise : array_like, shape (nx + nd,)
        Diagonal of the process-noise covariance of ``[x; d]``.
    measurement_noise : array_like, shape (nz,)
        Diagonal of the measurement-noise covariance.
    """

    def __init__(self, model: PredictionModel, process_noise, measurement_noise):
        self.model = model
        nx, nd = model.nx, model.nd
        self.Q = np.diag(np.asarray(process_noise, float))
        self.R = np.diag(np.asarray(measurement_noise, float))
        if self.Q.shape != (nx + nd, nx + nd):
            raise ValueError(f"process_noise needs {nx + nd} entries, got {len(process_noise)}")
        if self.R.shape != (model.nz, model.nz):
            raise ValueError(f"measurement_noise needs {model.nz} entries, got {len(measurement_noise)}")
        x = ca.SX.sym("x", nx)
        u = ca.SX.sym("u", model.nu)
        d = ca.SX.sym("d", nd)
        z = ca.vertcat(x, d)
        z_next = ca.vertcat(model.step(x, u, d), d)
        self._predict = ca.Function("ekf_predict", [x, u, d], [z_next, ca.jacobian(z_next, z)])
        meas = model.measure(x, d)
        self._measure = ca.Function("ekf_measure", [x, d], [meas, ca.jacobian(meas, z)])
        self.x = np.zeros(nx)
        self.d = np.zeros(nd)
        self.P = np.eye(nx + nd)

    def reset(self, x0, d0, P0) -> None:
        """Set the estimate and its covariance (diagonal ``P0``)."""
        self.x = np.asarray(x0, float).copy()
        self.d = np.asarray(d0, float).copy()
        self.P = np.diag(np.asarray(P0, float))

    def predict(self, u) -> None:
        """Time update with the applied input ``u``."""
        z_next, A = self._predict(self.x, u, self.d)
        z_next = np.asarray(z_next).ravel()
        A = np.asarray(A)
        self.x, self.d = z_next[: self.model.nx], z_next[self.model.nx:]
        self.P = A @ self.P @ A.T + self.Q

    def update(self, z_meas) -> None:
        """Measurement update with the sensor vector ``z_meas``."""
        z_pred, C = self._measure(self.x, self.d)
        C = np.asarray(C)
        innovation = np.asarray(z_meas, float) - np.asarray(z_pred).ravel()
        S = C @ self.P @ C.T + self.R
        K = np.linalg.solve(S, C @ self.P).T
        z = np.concatenate((self.x, self.d)) + K @ innovation
        I_KC = np.eye(len(z)) - K @ C
        self.P = I_KC @ self.P @ I_KC.T + K @ self.R @ K.T  # Joseph form: stays symmetric PSD
        self.x, self.d = z[: self.model.nx], z[self.model.nx:]


class OpenLoopEstimator:
    """For feed-forward control (no sensor): the state follows a model under the applied inputs.

    Parameters
    ----------
    step : callable
        ``(x, u) -> x_next``, typically the *exact* model, so the NMPC re-anchors its smooth
        prediction on the exact memory every sample.
    nd : int
        Size of the (always zero) disturbance vector the NMPC expects.
    """

    def __init__(self, step, nd: int = 1):
        self._step = step
        self.x = np.zeros(0)
        self.d = np.zeros(nd)

    def reset(self, x0, d0, P0=None) -> None:
        """Set the state; the disturbance stays zero (nothing measures it)."""
        self.x = np.asarray(x0, float).copy()
        self.d = np.zeros_like(np.asarray(d0, float))

    def predict(self, u) -> None:
        """Propagate with the applied input."""
        self.x = np.asarray(self._step(self.x, float(np.ravel(u)[0])), float)

    def update(self, z) -> None:
        """No measurement: nothing to do."""
