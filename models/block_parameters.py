"""The linear block as a fit moves it: its parameter vector, the vector's bounds, and its creep.

The refinement (:func:`hystmpc.models.record_fit.refine`) moves a block's lag or resonance as
logarithms and its Kelvin–Voigt creep elements as shares and log time constants; these
functions map a :class:`~hystmpc.models.linear_dynamics.LinearDynamics` to that vector and
back, bound it, lay out the creep elements a fit starts from, and tidy those it ends with.
"""

from __future__ import annotations

from typing import TYPE_CHECKING

import numpy as np

from hystmpc.models.linear_dynamics import LinearDynamics

if TYPE_CHECKING:  # only its length and sample period are read
    from hystmpc.models.record_fit import Record

MOST_CREEP = 0.95
"""Largest share of the output a fitted creep may take, all elements together."""
FASTEST_CREEP = 100
"""Shortest time constant of a fitted creep element (samples): a creep is slow; a faster
element would take a share of the block's lag or dead time."""


def block_theta(block: LinearDynamics) -> np.ndarray:
    """The block's parameters as the refinement moves them.

    Parameters
    ----------
    block : LinearDynamics
        The linear block.

    Returns
    -------
    ndarray
        ``[log time_constant]`` (first-order), ``[log natural_frequency_hz, log damping]``
        (second-order) or empty, then the creep elements' shares and the logarithms of their
        time constants.
    """
    creep = [share for share, _ in block.creep] + [np.log(tau) for tau in block.creep_times]
    if block.kind == "first-order":
        return np.array([np.log(block.time_constant), *creep])
    if block.kind == "second-order":
        return np.array([np.log(block.natural_frequency_hz), np.log(block.damping), *creep])
    return np.array(creep, float)


def block_bounds(kind: str, sample_period: float, creep_elements: int = 0) -> tuple[list[float], list[float]]:
    """Search bounds of :func:`block_theta`.

    A lag between a tenth of a sample and 1e4 s; a resonance below Nyquist with a damping from
    0.007 to 7; each creep share from 0 to :data:`MOST_CREEP` (:func:`block_of` scales them
    down together where they sum beyond it), each creep time constant from :data:`FASTEST_CREEP`
    samples (faster is the block's business) to 1e4 s.

    Parameters
    ----------
    kind : str
        Block kind (``"none"``, ``"first-order"``, ``"second-order"``).
    sample_period : float
        Sample period (s).
    creep_elements : int, optional
        Number of creep elements.

    Returns
    -------
    tuple of list
        ``(lower, upper)``, one entry per parameter of :func:`block_theta`.
    """
    m = creep_elements
    fastest = np.log(FASTEST_CREEP * sample_period)
    lower_c, upper_c = [0.0] * m + [fastest] * m, [MOST_CREEP] * m + [np.log(1e4)] * m
    if kind == "first-order":
        return [np.log(sample_period / 10), *lower_c], [np.log(1e4), *upper_c]
    if kind == "second-order":
        return [np.log(1e-3), -5.0, *lower_c], [np.log(0.5 / sample_period), 2.0, *upper_c]
    return lower_c, upper_c


def block_of(kind: str, theta, delay: int, creep_elements: int = 0) -> LinearDynamics:
    """The block of :func:`block_theta` values.

    Parameters
    ----------
    kind : str
        Block kind (``"none"``, ``"first-order"``, ``"second-order"``).
    theta : array_like
        Its parameters as :func:`block_theta` gives them.
    delay : int
        Dead time (samples).
    creep_elements : int, optional
        Number of creep elements: their shares (scaled down together where they sum beyond
        :data:`MOST_CREEP`) and log time constants are the last entries of ``theta``.

    Returns
    -------
    LinearDynamics
        The block.
    """
    m = creep_elements
    theta = np.asarray(theta, float)
    main, shares, log_taus = theta[:len(theta) - 2 * m], theta[len(theta) - 2 * m:len(theta) - m], \
        theta[len(theta) - m:]
    if m and np.sum(shares) > MOST_CREEP:
        shares = shares * (MOST_CREEP / np.sum(shares))
    creep = tuple((float(share), float(np.exp(log_tau))) for share, log_tau in zip(shares, log_taus, strict=True))
    if kind == "first-order":
        return LinearDynamics("first-order", time_constant=float(np.exp(main[0])), delay_samples=delay, creep=creep)
    if kind == "second-order":
        return LinearDynamics("second-order", natural_frequency_hz=float(np.exp(main[0])),
                              damping=float(np.exp(main[1])), delay_samples=delay, creep=creep)
    return LinearDynamics("none", delay_samples=delay, creep=creep)


def creep_start(record: Record, elements: int = 8) -> tuple[tuple[float, float], ...]:
    """Kelvin–Voigt creep elements to start a fit from.

    Time constants from the record's length down by a factor √10 each, no shorter than
    :data:`FASTEST_CREEP` samples, at most ``elements``; shares 0.01.

    Parameters
    ----------
    record : Record
        The record (its length and sample period).
    elements : int, optional
        Most elements.

    Returns
    -------
    tuple
        ``((share, time_constant), ...)``, the longest first.
    """
    duration = record.sample_period * len(record.u)
    taus = [duration / np.sqrt(10.0) ** k for k in range(elements)]
    return tuple((0.01, float(tau)) for tau in taus if tau >= FASTEST_CREEP * record.sample_period)


def tidy_creep(creep, least_share: float = 1e-6, ratio: float = 1.25) -> tuple[tuple[float, float], ...]:
    """Fitted creep elements without those the record did not need, and with near twins merged.

    An element with a share below ``least_share`` is left out; elements whose time constants
    lie within ``ratio`` of each other become one, with their shares summed and the
    share-weighted geometric mean of their time constants (one state instead of several).

    Parameters
    ----------
    creep : sequence of (float, float)
        ``(share, time_constant)`` pairs.
    least_share : float, optional
        Smallest share kept.
    ratio : float, optional
        Time constants closer than this factor merge.

    Returns
    -------
    tuple
        The elements, the shortest time constant first.
    """
    kept = sorted(((float(s), float(t)) for s, t in creep if s >= least_share), key=lambda e: e[1])
    merged: list[tuple[float, float]] = []
    for share, tau in kept:
        if merged and tau < ratio * merged[-1][1]:
            s0, t0 = merged[-1]
            merged[-1] = (s0 + share, float(np.exp((s0 * np.log(t0) + share * np.log(tau)) / (s0 + share))))
        else:
            merged.append((share, tau))
    return tuple(merged)
