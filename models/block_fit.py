"""The linear block and dead time that map a hysteresis output onto a record.

Once a family's static fit gives a hysteresis output, :func:`fit_block` finds the block
(``none``, a first-order lag, or a second-order resonance) and the dead time by a grid search
over them, the gain and offset projected, then polishes the best by least squares.
"""

from __future__ import annotations

from collections.abc import Sequence
from dataclasses import replace

import numpy as np

from hystmpc.models.block_parameters import block_of
from hystmpc.models.linear_dynamics import LinearDynamics
from hystmpc.models.record_fit import Problem, Record, refine, respond


def _grid(kind: str, record: Record) -> list[np.ndarray]:
    """Block parameters (:func:`block_theta`) the dead-time search tries.

    Lags from a tenth of a sample to a tenth of the record, resonances from 10 cycles per record
    to Nyquist.
    """
    T, duration = record.sample_period, record.sample_period * len(record.u)
    if kind == "first-order":
        return [np.log([tau]) for tau in np.geomspace(0.1 * T, max(0.1 * duration, T), 24)]
    if kind == "second-order":
        return [np.log([f, zeta]) for f in np.geomspace(min(10.0 / duration, 0.04 / T), 0.45 / T, 18)
                for zeta in (0.05, 0.15, 0.35, 0.7, 1.2)]
    return [np.zeros(0)]


def fit_block(h: np.ndarray, record: Record, kind: str, delays: Sequence[int],
              creep: tuple = ()) -> tuple[LinearDynamics, float]:
    """The block ``kind`` and dead time that best map one hysteresis output ``h`` onto the record.

    The gain and offset are projected. A grid search (each dead time with every grid block; for
    a second-order block, the dead times within 2 samples of the best lag's), then a
    least-squares polish of the best.

    Parameters
    ----------
    h : ndarray
        One hysteresis output, one value per sample.
    record : Record
        The record.
    kind : str
        Block kind (``"none"``, ``"first-order"``, ``"second-order"``).
    delays : sequence of int
        Dead times to try (samples).
    creep : tuple, optional
        Creep elements the blocks carry (:attr:`LinearDynamics.creep`); the polish moves their shares.

    Returns
    -------
    tuple
        ``(block, rmse)``: the best block with its dead time, and its RMSE after the warm-up.
    """
    rows = record.rows()
    y = record.y[rows]

    def cost(block):
        f = respond(h, block, record)[rows]
        fc, yc = f - f.mean(), y - y.mean()
        gain = float(fc @ yc) / max(float(fc @ fc), 1e-300)
        return float(np.mean((yc - gain * fc) ** 2))

    def search(kind, delays):
        return min(((cost(replace(block_of(kind, z, d), creep=creep)), d, tuple(z)) for d in delays
                    for z in _grid(kind, record)), key=lambda item: item[0])
    if kind == "second-order":
        _, lag_delay, _ = search("first-order", delays)
        _, delay, z = search(kind, [d for d in delays if abs(d - lag_delay) <= 2] or list(delays))
    else:
        _, delay, z = search(kind, delays)
    problem = Problem([(np.zeros(0, int), lambda _: h[:, None])], np.zeros(0), np.zeros(0), np.zeros(0),
                      np.array([False]), lambda theta, w: {})
    fit = refine(problem, record, replace(block_of(kind, np.asarray(z), delay), creep=creep), iterations=15)
    return fit.block, fit.rmse
