"""Extended Kalman filter on the model state augmented with a constant disturbance."""

from __future__ import annotations

import casadi as ca
import numpy as np

from hystmpc.models.prediction import PredictionModel


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
        self.time_update, self.measurement_update = self._update_functions()
        self.x = np.zeros(nx)
        self.d = np.zeros(nd)
        self.P = np.eye(nx + nd)

    def _update_functions(self) -> tuple[ca.Function, ca.Function]:
        """The time and measurement updates as CasADi Functions (matrix products as loops).

        The Python filter and the generated controller (:mod:`hystmpc.mpc.embedded`) call the
        same ones, so they round alike. ``Q`` and ``R`` are arguments: an observer may change them.
        """
        nx, nd, nz = self.model.nx, self.model.nd, self.model.nz
        x, u, d = ca.MX.sym("x", nx), ca.MX.sym("u", self.model.nu), ca.MX.sym("d", nd)
        P, Q = ca.MX.sym("P", nx + nd, nx + nd), ca.MX.sym("Q", nx + nd, nx + nd)
        xd_next, A = self._predict(x, u, d)
        time_update = ca.Function("ekf_time_update", [x, u, d, P, Q], [xd_next, A @ P @ A.T + Q],
                                  ["x", "u", "d", "P", "Q"], ["xd_next", "P_next"])
        z, R = ca.MX.sym("z", nz), ca.MX.sym("R", nz, nz)
        xd, P_next = ca.vertcat(x, d), P
        if nz:
            z_pred, C = self._measure(x, d)
            K = ca.solve(C @ P @ C.T + R, C @ P, "qr").T
            xd = xd + K @ (z - z_pred)
            I_KC = ca.DM.eye(nx + nd) - K @ C
            P_next = I_KC @ P @ I_KC.T + K @ R @ K.T  # Joseph form: stays symmetric PSD
        measurement_update = ca.Function("ekf_measurement_update", [x, d, P, z, R], [xd, P_next],
                                         ["x", "d", "P", "z", "R"], ["xd_next", "P_next"])
        return time_update, measurement_update

    def reset(self, x0, d0, P0) -> None:
        """Set the estimate and its covariance (diagonal ``P0``).

        Parameters
        ----------
        x0 : array_like, shape (nx,)
            State estimate.
        d0 : array_like, shape (nd,)
            Disturbance estimate.
        P0 : array_like, shape (nx + nd,)
            Diagonal of the covariance of ``[x; d]``.
        """
        self.x = np.asarray(x0, float).copy()
        self.d = np.asarray(d0, float).copy()
        self.P = np.diag(np.asarray(P0, float))

    def predict(self, u) -> None:
        """Time update with the applied input ``u``.

        Parameters
        ----------
        u : array_like, shape (nu,)
            The input applied over the sample.
        """
        z_next, P = self.time_update(self.x, u, self.d, self.P, self.Q)
        z_next = np.asarray(z_next).ravel()
        self.x, self.d, self.P = z_next[: self.model.nx], z_next[self.model.nx:], np.asarray(P)

    def update(self, z_meas) -> None:
        """Measurement update with the sensor vector ``z_meas``.

        Parameters
        ----------
        z_meas : array_like, shape (nz,)
            The sensor vector.
        """
        z, P = self.measurement_update(self.x, self.d, self.P, np.asarray(z_meas, float), self.R)
        z = np.asarray(z).ravel()
        self.x, self.d, self.P = z[: self.model.nx], z[self.model.nx:], np.asarray(P)

    @classmethod
    def from_sensor_noise(cls, model: PredictionModel, sensor_noise,
                          disturbance_walk: float | None = None) -> tuple[DisturbanceEKF, np.ndarray]:
        """An EKF tuned from the sensors' noise, and its initial covariance.

        With ``σ`` the smallest sensor noise standard deviation: measurement noise ``σ_i²``;
        the disturbance a random walk of ``disturbance_walk`` per sample (default ``σ``: it
        follows a model mismatch that changes over tens of samples); the states' process noise
        ``(0.01 σ)²`` (the model is trusted, its errors land in ``d``); initial covariance
        ``(10 σ)²`` on the states and ``(1000 σ)²`` on ``d``.

        Parameters
        ----------
        model : PredictionModel
            The model the EKF runs.
        sensor_noise : float or array_like
            Standard deviation of each sensor (one value: every sensor), > 0; unused (None)
            for a model without sensors.
        disturbance_walk : float, optional
            Standard deviation of the disturbance's step per sample, > 0 (how fast the model's
            error drifts; default ``σ``).

        Returns
        -------
        ekf : DisturbanceEKF
            The tuned EKF.
        initial_covariance : ndarray, shape (nx + nd,)
            Diagonal of its initial covariance.
        """
        noise = np.broadcast_to(np.asarray(1.0 if sensor_noise is None else sensor_noise, float), (model.nz,)).copy()
        if not np.all(np.isfinite(noise)) or np.any(noise <= 0):
            raise ValueError(f"sensor_noise must be finite and > 0, got {sensor_noise}")
        sigma = float(noise.min()) if model.nz else 1.0  # without sensors the EKF only predicts
        walk = sigma if disturbance_walk is None else float(disturbance_walk)
        if not np.isfinite(walk) or walk <= 0:
            raise ValueError(f"disturbance_walk must be finite and > 0, got {disturbance_walk}")
        process = [(0.01 * sigma) ** 2] * model.nx + [walk**2] * model.nd
        initial = [(10 * sigma) ** 2] * model.nx + [(1000 * sigma) ** 2] * model.nd
        return cls(model, process, noise**2), np.asarray(initial)

