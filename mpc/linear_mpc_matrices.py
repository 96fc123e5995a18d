"""The linear MPC's matrices, built once from its model.

:func:`linearise` linearises the model at the origin; :func:`condense` gives the Kalman filter
on the state and integrating disturbance, and the QP condensed onto the virtual inputs
(:class:`~hystmpc.mpc.linear_mpc.InverseLinearMpc` solves it; the generated planner,
:mod:`hystmpc.mpc.embedded_planner`, reads the same matrices).
"""

from __future__ import annotations

from dataclasses import dataclass
from typing import TYPE_CHECKING

import casadi as ca
import numpy as np

from hystmpc.models.prediction import PredictionModel

if TYPE_CHECKING:  # linear_mpc, where the settings live, imports this module
    from hystmpc.mpc.linear_mpc import LinearMpcSettings


def linearise(model: PredictionModel) -> dict[str, np.ndarray]:
    """``x+ = A x + B v + Bd d + f0``, ``y = Cy x + Dy d + y0``, ``z = Cz x + Dz d + z0`` at the origin.

    Parameters
    ----------
    model : PredictionModel
        The model to linearise.

    Returns
    -------
    dict
        ``A``, ``B``, ``Bd``, ``Cy``, ``Dy``, ``Cz``, ``Dz`` (matrices) and ``f0``, ``y0``, ``z0``
        (vectors), as ndarrays.
    """
    x, u, d = ca.SX.sym("x", model.nx), ca.SX.sym("u", model.nu), ca.SX.sym("d", model.nd)
    nxt, y, z = model.step(x, u, d), model.output(x, d), model.measure(x, d)
    parts = ca.Function("linearised", [x, u, d],
                        [ca.jacobian(nxt, x), ca.jacobian(nxt, u), ca.jacobian(nxt, d), nxt,
                         ca.jacobian(y, x), ca.jacobian(y, d), y, ca.jacobian(z, x), ca.jacobian(z, d), z])
    values = [np.asarray(v, float) for v in parts(np.zeros(model.nx), np.zeros(model.nu), np.zeros(model.nd))]
    names = ("A", "B", "Bd", "f0", "Cy", "Dy", "y0", "Cz", "Dz", "z0")
    out = dict(zip(names, values, strict=True))
    out["f0"], out["y0"], out["z0"] = out["f0"].ravel(), out["y0"].ravel(), out["z0"].ravel()
    return out


@dataclass(frozen=True)
class CondensedLinearMpc:
    """The linear MPC's Kalman filter on ``[x; d]`` and its QP condensed onto the virtual inputs.

    Filter: ``s+ = A s + B v + f``, sensors ``z = C s + z0``, output ``y = Cy s + y0``.
    Prediction over the horizon: ``y_{k+1..k+N} = Phi s + G v + offset``. QP:
    ``min ½ vᵀ hessian v + gᵀ v`` with ``g = 2 (q Gᵀ(Phi s + offset − r) − r_rate Dᵀ e0)``,
    ``e0 = [v_prev, 0, …]``, bounds on ``v`` and on ``D v`` (the changes).
    """

    A: np.ndarray
    B: np.ndarray
    f: np.ndarray
    C: np.ndarray
    z0: np.ndarray
    Q: np.ndarray
    R: np.ndarray
    Cy: np.ndarray
    y0: float
    Phi: np.ndarray
    G: np.ndarray
    offset: np.ndarray
    D: np.ndarray
    hessian: np.ndarray
    initial_covariance: np.ndarray


def condense(model: PredictionModel, settings: LinearMpcSettings, process_noise, measurement_noise,
             initial_covariance) -> CondensedLinearMpc:
    """The Kalman filter and the condensed QP of a linear MPC on ``model`` (linearised at the origin).

    Parameters
    ----------
    model : PredictionModel
        The linear remainder, input ``v``.
    settings : LinearMpcSettings
        Horizon and weights.
    process_noise, measurement_noise, initial_covariance : array_like
        Diagonals of the filter's covariances (``[x; d]``, sensors, ``[x; d]`` at the start).

    Returns
    -------
    CondensedLinearMpc
        The matrices.
    """
    nx, nd, N = model.nx, model.nd, settings.horizon
    for name, values, length in (("process_noise", process_noise, nx + nd),
                                 ("measurement_noise", measurement_noise, model.nz),
                                 ("initial_covariance", initial_covariance, nx + nd)):
        if np.size(values) != length:
            raise ValueError(f"{name} needs {length} entries, got {np.size(values)}")
    lin = linearise(model)
    A = np.block([[lin["A"], lin["Bd"]], [np.zeros((nd, nx)), np.eye(nd)]])
    B = np.vstack((lin["B"], np.zeros((nd, 1)))).ravel()
    f = np.concatenate((lin["f0"], np.zeros(nd)))
    Cy = np.hstack((lin["Cy"], lin["Dy"])).ravel()
    # y_{k+j} = Cy (A^j z + Σ_{i<j} A^{j−1−i} (B v_i + f)) + y0, j = 1..N
    Phi, G, offset = np.empty((N, nx + nd)), np.zeros((N, N)), np.empty(N)
    power = np.eye(nx + nd)
    drift = np.zeros(nx + nd)
    markov = []
    for j in range(N):
        markov.append(Cy @ power @ B)
        drift = A @ drift + f
        power = A @ power
        Phi[j] = Cy @ power
        offset[j] = Cy @ drift + lin["y0"][0]
    for j in range(N):
        G[j, : j + 1] = markov[j::-1]
    D = np.eye(N) - np.eye(N, k=-1)  # Δv_j = v_j − v_{j−1}
    hessian = 2 * (settings.q_output * G.T @ G + settings.r_rate * D.T @ D)
    # the filter on [x; d] (d+ = d): the NMPC's disturbance model, exact on a linear model
    return CondensedLinearMpc(
        A=A, B=B, f=f, C=np.hstack((lin["Cz"], lin["Dz"])).reshape(model.nz, nx + nd), z0=lin["z0"],
        Q=np.diag(np.asarray(process_noise, float)),
        R=np.diag(np.asarray(measurement_noise, float)).reshape(model.nz, model.nz), Cy=Cy, y0=float(lin["y0"][0]),
        Phi=Phi, G=G, offset=offset, D=D, hessian=hessian,
        initial_covariance=np.diag(np.asarray(initial_covariance, float)))
