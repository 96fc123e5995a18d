"""The models' recursions over a whole record, compiled by numba, for identification.

Identification simulates a candidate model along a record of tens of thousands of samples
hundreds of times; a Python loop over the samples would dominate the fit.
Each function here repeats, sample by sample, the exact ``step`` of a model class (the tests
check them against each other), on plain arrays: nothing here knows about CasADi or states.
"""

from __future__ import annotations

import numpy as np
from numba import njit


@njit(cache=True)
def play_outputs(u, thresholds, z0):
    """Play operators' outputs ``z_k = clip(z_{k-1}, u_k − r, u_k + r)`` for every threshold ``r``.

    Parameters
    ----------
    u : ndarray
        Input at each sample.
    thresholds : ndarray
        Play thresholds ``r``.
    z0 : ndarray
        Play outputs before the first sample, one per threshold.

    Returns
    -------
    ndarray, shape (len(u), len(thresholds))
        One column per threshold.
    """
    n, m = len(u), len(thresholds)
    out = np.empty((n, m))
    z = z0.copy()
    for k in range(n):
        uk = u[k]
        for i in range(m):
            lo, hi = uk - thresholds[i], uk + thresholds[i]
            zi = z[i]
            if zi < lo:
                zi = lo
            elif zi > hi:
                zi = hi
            z[i] = zi
            out[k, i] = zi
    return out


@njit(cache=True)
def kp_kernel_outputs(p, u_last, rho1, rho2, delta, xi0):
    """KP kernels' outputs (wang2025 eq. (6)) along the normalised input ``p``.

    Parameters
    ----------
    p : ndarray
        Normalised input at each sample.
    u_last : float
        Normalised input before the first sample.
    rho1, rho2 : ndarray
        Kernel thresholds.
    delta : float
        Slope parameter δ of eq. (7).
    xi0 : ndarray
        Kernel outputs before the first sample.

    Returns
    -------
    ndarray, shape (len(p), len(rho1))
        The kernel outputs ξ after each sample, one column per kernel.
    """
    n, m = len(p), len(rho1)
    out = np.empty((n, m))
    xi = xi0.copy()
    last = u_last
    for k in range(n):
        pk = p[k]
        if pk > last:
            for i in range(m):
                r = -1.0 + 2.0 * (pk - rho2[i]) / delta
                r = min(max(r, -1.0), 1.0)
                if r > xi[i]:
                    xi[i] = r
        elif pk < last:
            for i in range(m):
                r = -1.0 + 2.0 * (pk - rho1[i]) / delta
                r = min(max(r, -1.0), 1.0)
                if r < xi[i]:
                    xi[i] = r
        last = pk
        out[k, :] = xi
    return out


@njit(cache=True)
def _phi(x):
    """``(1 − e^{−x}) / x``, 1 at 0."""
    if abs(x) < 1e-8:
        return 1.0 - 0.5 * x
    return -np.expm1(-x) / x


@njit(cache=True)
def bouc_wen_advance(z, du, a, beta, gamma):
    """Bouc–Wen's internal variable after the input moves by ``du`` (exact, n = 1).

    ``dz/du = a − β sgn(du) z − γ |z|``, crossing ``z = 0`` within the move if it does.

    Parameters
    ----------
    z : float
        Internal variable before the move.
    du : float
        Input move.
    a : float
        Slope ``dz/du`` at ``z = 0``.
    beta, gamma : float
        β and γ (1 / input unit).

    Returns
    -------
    float
        ``z`` after the move.
    """
    if du == 0.0:
        return z
    s = 1.0 if du > 0 else -1.0
    q = 1.0 if (z > 0 or (z == 0 and s > 0)) else -1.0
    k = beta * s + gamma * q
    if q == -s:  # moving towards zero: it may cross
        x = -k * z / a
        reach = np.log1p(x) / k if abs(k) > 1e-300 else -z / a
        if abs(du) > abs(reach):
            rest = du - reach
            k2 = (beta + gamma) * s
            return a * rest * _phi(k2 * rest)
    return z * np.exp(-k * du) + a * du * _phi(k * du)


@njit(cache=True)
def _exp_ratio(x):
    """``(e^x − 1) / x``, 1 at 0 (the series below 1e-6, as in the CasADi step)."""
    if abs(x) < 1e-6:
        return 1.0 + 0.5 * x + x * x / 6.0
    return np.expm1(x) / x


@njit(cache=True)
def bouc_wen_advance_power(z, du, beta, gamma, n, pieces):
    """Bouc–Wen's unit internal variable after the input moves by ``du``, for an exponent ``n > 1``.

    The move in ``pieces`` equal pieces ``h``, each an exponential Euler step of
    ``dζ/du = f(ζ) = 1 − (β sgn(du) sgn ζ + γ)|ζ|^n``: ``ζ + h·φ1(h·f′(ζ))·f(ζ)`` with
    ``φ1(x) = (e^x − 1)/x``, clipped to ``ζ``'s bound ``±(β + γ)^(−1/n)`` (a piece that starts at
    ``ζ = 0``, where ``f′ = 0``, is a plain Euler step and overshoots on a long move). The
    arithmetic of :class:`~hystmpc.models.bouc_wen.BoucWen`'s step.

    Parameters
    ----------
    z : float
        Internal variable before the move.
    du : float
        Input move.
    beta, gamma : float
        β and γ (1 / input unit^n).
    n : float
        Exponent.
    pieces : int
        Pieces of the move.

    Returns
    -------
    float
        ``ζ`` after the move.
    """
    if du == 0.0:
        return z
    s = 1.0 if du > 0 else -1.0
    h = du / pieces
    bound = (beta + gamma) ** (-1.0 / n)
    for _ in range(pieces):
        side = 1.0 if z > 0 else (-1.0 if z < 0 else 0.0)
        c = beta * s * side + gamma
        m = abs(z)
        w = m ** (n - 1.0)
        rate = 1.0 - c * w * m
        slope = -n * c * w * side
        z = min(max(z + h * _exp_ratio(h * slope) * rate, -bound), bound)
    return z


@njit(cache=True)
def bouc_wen_states(u, a, beta, gamma, z0, exponent=1.0, pieces=8):
    """Bouc–Wen's internal variable after each sample of ``u`` (from ``u[0]`` with ``z0``).

    Parameters
    ----------
    u : ndarray
        Input at each sample.
    a : float
        Slope ``dz/du`` at ``z = 0``.
    beta, gamma : float
        β and γ (1 / input unit; 1 / input unit^n with an exponent).
    z0 : float
        Internal variable at ``u[0]``.
    exponent : float, optional
        Bouc–Wen's ``n`` (1: the closed form; otherwise ``a`` is not used: the unit form).
    pieces : int, optional
        Pieces of each move for ``n != 1`` (:func:`bouc_wen_advance_power`; the model's is
        :data:`hystmpc.models.bouc_wen.SUBSTEPS`).

    Returns
    -------
    ndarray
        ``z`` after each sample.
    """
    n = len(u)
    out = np.empty(n)
    z = z0
    last = u[0]
    for k in range(n):
        if exponent == 1.0:
            z = bouc_wen_advance(z, u[k] - last, a, beta, gamma)
        else:
            z = bouc_wen_advance_power(z, u[k] - last, beta, gamma, exponent, pieces)
        last = u[k]
        out[k] = z
    return out


@njit(cache=True)
def _polyline(x, xs, ys):
    """Piecewise linear through (xs, ys), continued with the end slopes."""
    n = len(xs)
    j = np.searchsorted(xs, x) - 1
    j = min(max(j, 0), n - 2)
    return ys[j] + (ys[j + 1] - ys[j]) / (xs[j + 1] - xs[j]) * (x - xs[j])


@njit(cache=True)
def _exponent(s0, gp, gn, lo, hi):
    g = gp if s0 > 0 else gn
    b = g[0] * s0 * s0 + g[1] * s0 + g[2]
    return min(max(b, lo), hi)


@njit(cache=True)
def power_function_outputs(s, asc_s, asc_t, desc_s, desc_t, k11, k01, k12, k02, gp, gn, lo, hi):
    """zhou2024's power-function torque along ``s`` from the resting state at ``s[0]``.

    The same as :meth:`PowerFunctionHysteresis.step`, sample by sample.

    Parameters
    ----------
    s : ndarray
        Virtual deformation at each sample.
    asc_s, asc_t : ndarray
        Knots and torques of the ascending polyline (torques scaled).
    desc_s, desc_t : ndarray
        Knots and torques of the descending polyline (torques scaled).
    k11, k01 : float
        ``Δs1(s01) = k11·s01 + k01``, eq. (11).
    k12, k02 : float
        ``Δs2(s02) = k12·s02 + k02``, eq. (11).
    gp, gn : ndarray
        ``(g2, g1, g0)`` of the exponent b(s0) for s0 > 0 and otherwise, eq. (18).
    lo, hi : float
        Range b is clamped to.

    Returns
    -------
    ndarray
        The torque after each sample.
    """
    n = len(s)
    out = np.empty(n)
    s_last = s[0]
    up = 1.0
    s01 = s_last
    s02 = s_last - (k11 * s_last + k01)
    tau = _polyline(s_last, asc_s, asc_t)
    tau_r = tau
    for k in range(n):
        sk = s[k]
        if sk > s_last and up < 0.5:
            s02, s01, tau_r, up = s_last, s_last + (k12 * s_last + k02), tau, 1.0
        elif sk < s_last and up >= 0.5:
            s01, s02, tau_r, up = s_last, s_last - (k11 * s_last + k01), tau, 0.0
        if sk != s_last:
            if up >= 0.5:
                if sk >= s01:
                    tau = _polyline(sk, asc_s, asc_t)
                else:
                    x = (max(sk, s02) - s02) / (s01 - s02)
                    tau = tau_r + (_polyline(s01, asc_s, asc_t) - tau_r) * x ** _exponent(s02, gp, gn, lo, hi)
            else:
                if sk <= s02:
                    tau = _polyline(sk, desc_s, desc_t)
                else:
                    y = (s01 - min(sk, s01)) / (s01 - s02)
                    tau = tau_r - (tau_r - _polyline(s02, desc_s, desc_t)) * y ** _exponent(s01, gp, gn, lo, hi)
        s_last = sk
        out[k] = tau
    return out


@njit(cache=True)
def _lambertw(x):
    """Principal-branch Lambert W (x >= −1/e).

    The start of :mod:`hystmpc.models.lambertw`, then Halley steps to convergence.
    """
    if x == 0.0:
        return 0.0
    if x < -0.25:
        p = np.sqrt(max(2.0 * (np.e * x + 1.0), 0.0))
        w = -1.0 + p - p * p / 3.0 + 11.0 / 72.0 * p ** 3
    elif x < 20.0:
        lx = np.log(1.0 + max(x, -0.3))
        w = lx * (1.0 - np.log(1.0 + lx) / (2.0 + lx))
    else:
        l1 = np.log(x)
        l2 = np.log(l1)
        w = l1 - l2 + l2 / l1
    for _ in range(6):
        ew = np.exp(w)
        f = w * ew - x
        wp1 = w + 1.0
        if wp1 == 0.0:
            break
        step = f / (ew * wp1 - (w + 2.0) * f / (2.0 * wp1))
        w -= step
        if abs(step) <= 1e-15 * (1.0 + abs(w)):
            break
    return w


@njit(cache=True)
def parametric_outputs(u, p1, p2):
    """katalenic2013's operator H (eq. (3)) along ``u`` from the demagnetised state at ``u[0]``.

    The same as :meth:`ParametricHysteresis.step`, sample by sample.

    Parameters
    ----------
    u : ndarray
        Input at each sample.
    p1 : float
        Largest half-width of the loop (input units).
    p2 : float
        Rate of approach to the asymptotes (1 / input units).

    Returns
    -------
    ndarray
        The operator's output after each sample.
    """
    n = len(u)
    out = np.empty(n)
    u_last = u[0]
    s = 1.0
    u0 = u_last
    v0 = u_last
    v = u_last
    for k in range(n):
        uk = u[k]
        if uk != u_last:
            direction = 1.0 if uk > u_last else -1.0
            if direction != s:
                u0, v0, s = u_last, v, direction
        m = p1 + s * (v0 - u0)
        v = uk - u0 + v0 + s * (_lambertw(p2 * m * np.exp(p2 * (m - abs(uk - u0)))) / p2 - m)
        u_last = uk
        out[k] = v
    return out
