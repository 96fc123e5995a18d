"""Whether a record shows a resonance: a second-order block is fitted only where it does.

A slowly varying record cannot tell a resonance from a lag: a second-order block fitted to it
returns some mode the record does not determine (a 7 Hz one on a stage that has 350 Hz). The
test fits both blocks behind one quick Prandtl–Ishlinskii start and asks the second-order one
to win by 2 %.
"""

from __future__ import annotations

import numpy as np

from hystmpc.models.block_fit import fit_block
from hystmpc.models.fit_plays import prandtl_ishlinskii_problem
from hystmpc.models.linear_dynamics import LinearDynamics
from hystmpc.models.record_fit import Record, refine


def shows_resonance(u, y, sample_period: float, alignment: str, delays, warm_up: int = 0) -> tuple[bool, str]:
    """Whether a record shows a second-order block's resonance: ``(shows, why)``.

    The second-order fit must beat the first-order one by 2 % in RMSE (on a Prandtl–Ishlinskii
    start).

    Parameters
    ----------
    u, y : array_like
        The record.
    sample_period : float
        Sample period (s).
    alignment : str
        ``next`` or ``same``.
    delays : sequence of int
        Dead times tried (samples).
    warm_up : int, optional
        Leading samples left out of the fits.

    Returns
    -------
    shows : bool
        Whether the second-order block wins.
    why : str
        Both blocks' RMSE and the second-order one's frequency and damping, for a message.
    """
    record = Record(np.asarray(u, float), np.asarray(y, float), sample_period, alignment, warm_up)
    problem = prandtl_ishlinskii_problem(record, 10)
    fit = refine(problem, record, LinearDynamics(), move_block=False, iterations=10)
    h = problem.columns(fit.theta) @ fit.weights
    second, rmse2 = fit_block(h, record, "second-order", delays)
    _, rmse1 = fit_block(h, record, "first-order", delays)
    why = (f"a second-order block ({second.natural_frequency_hz:.4g} Hz, damping {second.damping:.3g}) fits it to "
           f"{rmse2:.4g} against {rmse1:.4g} for a first-order lag")
    return rmse2 < 0.98 * rmse1, why


def require_resonance(u, y, sample_period: float, alignment: str, delays, warm_up: int = 0,
                      fast: tuple | None = None) -> None:
    """``ValueError`` unless the record shows a second-order block's resonance.

    The test is :func:`shows_resonance`.

    Parameters
    ----------
    u, y : array_like
        The record.
    sample_period : float
        Sample period (s).
    alignment : str
        ``next`` or ``same``.
    delays : sequence of int
        Dead times tried (samples).
    warm_up : int, optional
        Leading samples of ``(u, y)`` left out (not applied to ``fast``).
    fast : tuple of array_like, optional
        ``(u, y)`` of the dynamics record: checked instead of ``(u, y)`` when given.
    """
    shows, why = shows_resonance(*(fast or (u, y)), sample_period, alignment, delays, 0 if fast else warm_up)
    if not shows:
        raise ValueError(f"the {'dynamics ' if fast else ''}record is too slow to show a resonance: {why}; fit "
                         "--dynamics second-order on a record that excites it (--dynamics-data FAST.csv: steps or a "
                         "chirp up to the resonance), or use --dynamics first-order")
