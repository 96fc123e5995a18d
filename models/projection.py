"""The weights of a fit's columns for given nonlinear parameters: constrained linear least squares.

For fixed thresholds and block, a family's prediction is linear in its weights (and the output
offset); :func:`project` finds them, non-negative where the family says, with an optional
smoothness penalty, and :func:`project_normal` does the same from the normal equations (which a
fit keeps per group of columns, so that a step of one parameter rebuilds one block of them).
"""

from __future__ import annotations

import numpy as np


def project(F: np.ndarray, y: np.ndarray, nonneg: np.ndarray, penalty: np.ndarray | None = None,
            intercept: bool = True) -> tuple[np.ndarray, float]:
    """Weights ``w`` and offset ``c`` minimising ``|y − F w − c|² + |penalty w|²``.

    Parameters
    ----------
    F : ndarray
        Columns, ``(n_rows, p)``.
    y : ndarray
        Target, one value per row.
    nonneg : ndarray
        Per column (bool): its weight is constrained to >= 0.
    penalty : ndarray, optional
        Penalty rows, ``(m, p)``, or None.
    intercept : bool, optional
        Fit the offset ``c``; ``c = 0`` without it.

    Returns
    -------
    tuple
        ``(w, c)``: the weights (ndarray) and the offset (float).
    """
    return project_normal(F.T @ F, F.T @ y, F.sum(axis=0), float(np.sum(y)), len(y), nonneg, penalty, intercept)


def project_normal(FtF, Fty, sum_f, sum_y: float, n: int, nonneg: np.ndarray, penalty: np.ndarray | None = None,
                   intercept: bool = True) -> tuple[np.ndarray, float]:
    """:func:`project` from the normal equations' pieces.

    The refinement keeps these pieces per group of columns.

    Parameters
    ----------
    FtF : ndarray
        ``FᵀF``.
    Fty : ndarray
        ``Fᵀy``.
    sum_f : ndarray
        ``Σ_rows F``, one sum per column.
    sum_y : float
        ``Σ y``.
    n : int
        Number of rows.
    nonneg : ndarray
        Per column (bool): its weight is constrained to >= 0.
    penalty : ndarray, optional
        Penalty rows, ``(m, p)``, or None.
    intercept : bool, optional
        Fit the offset ``c``; ``c = 0`` without it.

    Returns
    -------
    tuple
        ``(w, c)``: the weights (ndarray) and the offset (float), as :func:`project` gives them.
    """
    from scipy.linalg import cho_solve, solve_triangular
    from scipy.optimize import nnls

    if len(Fty) == 0:
        return np.zeros(0), sum_y / n if intercept else 0.0
    mean_f, mean_y = (sum_f / n, sum_y / n) if intercept else (np.zeros(len(Fty)), 0.0)
    G = FtF - n * np.outer(mean_f, mean_f)
    b = Fty - n * mean_f * mean_y
    norm = np.sqrt(np.maximum(np.diag(G), 0.0))
    top = max(float(np.max(norm)), 1e-300)
    scale = np.where(norm > 1e-7 * top, norm, top)  # a column the record leaves constant: left to the penalty
    G = G / np.outer(scale, scale)
    b = b / scale
    if penalty is not None and len(penalty):
        P = penalty / scale
        G = G + P.T @ P
    factor = _factor(G)
    if not np.any(nonneg):
        v = cho_solve(factor, b)
    else:
        R = np.triu(factor[0])
        target = solve_triangular(R, b, trans="T")
        free = ~nonneg
        if np.any(free):  # free weights: two non-negative halves
            R2 = np.hstack((R, -R[:, free]))
            v2 = nnls(R2, target, maxiter=50 * R2.shape[1])[0]
            v = v2[: len(b)].copy()
            v[free] -= v2[len(b):]
        else:
            v = nnls(R, target, maxiter=50 * R.shape[1])[0]
    w = v / scale
    return w, mean_y - float(mean_f @ w)


def _factor(G: np.ndarray) -> tuple:
    """Cholesky factor (upper) of the scaled normal matrix ``G`` with a small ridge.

    The ridge starts at 1e-10 of the mean diagonal and grows a hundredfold while rounding
    (nearly collinear columns, the mean removed by subtraction) leaves ``G`` indefinite.
    """
    from scipy.linalg import LinAlgError, cho_factor

    trace = max(float(np.trace(G)), 1e-300)
    for ridge in (1e-10, 1e-8, 1e-6, 1e-4):
        ridged = G.copy()
        ridged[np.diag_indices_from(ridged)] += ridge * trace / len(G)
        try:
            return cho_factor(ridged, lower=False)
        except LinAlgError:
            continue
    ridged[np.diag_indices_from(ridged)] += 1e-2 * trace / len(G)
    return cho_factor(ridged, lower=False)
