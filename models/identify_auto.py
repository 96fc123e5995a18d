"""``identify auto``: every family fitted to one record, ranked by validation, against a naive model.

The ranking is only as honest as its validation. With a separate validation record it is
used (from rest, or continuing the fit record's state with ``continue_state``); without one
the last ``HOLD_OUT`` of the record is held out and the families are fitted on the rest,
the held-out part continuing the fit part's state. Every family is measured against the
model an engineer would try first: a straight line through a first-order lag and a dead time
(:func:`naive_model`), fitted to the same samples.

The families run in parallel processes (``workers``), each as :func:`hystmpc.models.identification.identify`.
Asked for a creep, each family is fitted with and without it and both are ranked: a creep is a
choice the validation makes, as the family is (on a record whose drift is not creep, a creep
fitted to it costs more on validation than it gains on the fit).
"""

from __future__ import annotations

import time
from concurrent.futures import ProcessPoolExecutor
from dataclasses import dataclass, field

import numpy as np

from hystmpc.models.block_fit import fit_block
from hystmpc.models.block_parameters import FASTEST_CREEP
from hystmpc.models.identification import (
    FAMILIES,
    FitError,
    Identified,
    check_data,
    choose_alignment,
    creep_form,
    identify,
    takes_creep,
)
from hystmpc.models.linear_dynamics import LinearDynamics
from hystmpc.models.record_fit import Record, refine, respond
from hystmpc.models.resonance import require_resonance

HOLD_OUT = 0.3
"""Share of the record held out for validation when no validation record is given."""
COST = {"preisach": 5, "generalised-pi": 4, "power-function": 3, "prandtl-ishlinskii": 3, "fckp": 2, "kp": 1}
"""Rough relative fitting times, so that the slowest families start first."""


@dataclass
class Candidate:
    """One family's result in the ranking, fitted with a creep or without."""

    family: str
    identified: Identified | None
    fit_rmse: float
    validation_rmse: float
    seconds: float
    error: str = ""
    """Why the family gave no model (empty when it did)."""
    model: object = None
    """The naive reference's model (:class:`NaiveModel`), for the naive row only."""
    distance_to_best: float = float("nan")
    """RMS difference of its validation prediction from the best candidate's (output units):
    how far apart two models of the same record are."""
    creep: str = ""
    """The creep form fitted with the family (empty: none)."""

    @property
    def label(self) -> str:
        """The family, and its creep form where it has one (``preisach + kelvin-voigt``)."""
        return f"{self.family} + {self.creep}" if self.creep else self.family


@dataclass
class Ranking:
    """Every candidate, best first by validation RMSE, and the naive model's figures."""

    candidates: list[Candidate]
    naive: Candidate
    validation: str
    """How the validation RMSE was measured (for the report)."""
    fit_samples: int
    """Leading samples of the record the families were fitted on."""
    warnings: list[str] = field(default_factory=list)

    @property
    def best(self) -> Candidate:
        """The candidate with the least validation RMSE."""
        return self.candidates[0]


def validation_prediction(identified, fit_u, u_val, continue_state: bool, warm_up: int) -> np.ndarray:
    """The model's output on the validation inputs.

    Parameters
    ----------
    identified : Identified or NaiveModel
        The model (anything with ``predict(u)``).
    fit_u : array_like
        Inputs of the fit record.
    u_val : array_like
        Validation inputs.
    continue_state : bool
        Continue the fit record's state; otherwise start from rest at the first validation input.
    warm_up : int
        Leading validation samples left out when starting from rest.

    Returns
    -------
    ndarray
        The modelled output on the validation inputs (after the warm-up when from rest).
    """
    u_val = np.asarray(u_val, float)
    if continue_state:
        return identified.predict(np.concatenate((fit_u, u_val)))[len(fit_u):]
    return identified.predict(u_val)[warm_up:]


def validation_rmse(identified, fit_u, validation: tuple, continue_state: bool, warm_up: int) -> float:
    """RMSE on the validation record ``(u, y)`` (:func:`validation_prediction`).

    Parameters
    ----------
    identified : Identified or NaiveModel
        The model (anything with ``predict(u)``).
    fit_u : array_like
        Inputs of the fit record.
    validation : tuple of array_like
        ``(u, y)`` of the validation record.
    continue_state : bool
        Continue the fit record's state; otherwise start from rest.
    warm_up : int
        Leading validation samples left out when starting from rest.

    Returns
    -------
    float
        The RMSE (output units).
    """
    predicted = validation_prediction(identified, fit_u, validation[0], continue_state, warm_up)
    y_val = np.asarray(validation[1], float)[len(validation[1]) - len(predicted):]
    return float(np.sqrt(np.mean((predicted - y_val) ** 2)))


@dataclass
class NaiveModel:
    """``y = gain·u + offset`` through a first-order lag and a dead time: the model to beat."""

    gain: float
    offset: float
    dynamics: LinearDynamics
    sample_period: float
    alignment: str
    rmse: float = float("nan")

    def predict(self, u) -> np.ndarray:
        """Modelled output for ``u`` from rest at ``u[0]``.

        Parameters
        ----------
        u : array_like
            Input at each sample.

        Returns
        -------
        ndarray
            The modelled output at each sample.
        """
        u = np.asarray(u, float)
        return respond(self.gain * u + self.offset, self.dynamics,
                       Record(u, u, self.sample_period, self.alignment))


def naive_model(u, y, sample_period: float, alignment: str = "next", max_delay: int = 20, warm_up: int = 0
                ) -> NaiveModel:
    """The :class:`NaiveModel` fitted to the record, by the same least squares as the families.

    Its parameters: a gain of either sign, a lag, a dead time and an offset.

    Parameters
    ----------
    u, y : array_like
        The record.
    sample_period : float
        Sample period (s).
    alignment : str, optional
        ``next`` or ``same``.
    max_delay : int, optional
        Largest dead time tried (samples).
    warm_up : int, optional
        Leading samples left out of the fit.

    Returns
    -------
    NaiveModel
        The fitted model, with its RMSE after the warm-up.
    """
    from hystmpc.models.fit_plays import linear_problem
    record = Record(np.asarray(u, float), np.asarray(y, float), sample_period, alignment, warm_up)
    block, _ = fit_block(record.u, record, "first-order", range(max_delay + 1))
    fit = refine(linear_problem(record), record, block)
    return NaiveModel(float(fit.weights[0]), fit.offset, fit.block, sample_period, alignment, fit.rmse)


def _one_blas_thread() -> None:
    """BLAS on one thread in a worker.

    The matrices are small, and threads of two workers on two cores wait for each other.
    """
    from threadpoolctl import threadpool_limits
    threadpool_limits(1, user_api="blas")


def _one(job) -> Candidate:
    name, u, y, sample_period, options, kw, validation, continue_state, warm_up = job
    creep = kw["creep"] or ""
    start = time.perf_counter()
    try:
        identified = identify(name, u, y, sample_period, options, **kw)
        val = validation_rmse(identified, u, validation, continue_state, warm_up)
        if not np.isfinite(val):
            raise FitError(f"{name}: the validation RMSE is not finite (the model diverges on the validation record)")
        return Candidate(name, identified, identified.rmse, val, time.perf_counter() - start, creep=creep)
    except (FitError, ValueError) as exc:
        return Candidate(name, None, float("nan"), float("nan"), time.perf_counter() - start, str(exc), creep=creep)
    except Exception as exc:  # noqa: BLE001 - one family's failure must not end the ranking of the others
        return Candidate(name, None, float("nan"), float("nan"), time.perf_counter() - start,
                         f"{name}: {type(exc).__name__}: {exc}", creep=creep)


def identify_auto(u, y, sample_period: float, validation: tuple | None = None, continue_state: bool = False,
                  families: list[str] | None = None, options: dict | None = None, dynamics: str = "none",
                  dynamics_data: tuple | None = None, max_delay: int = 20, alignment: str = "auto",
                  warm_up: int = 0, creep: bool = False, workers: int = 2) -> Ranking:
    """Fit every family (or ``families``) and rank them by validation RMSE.

    Parameters
    ----------
    u, y, sample_period
        The record, as for :func:`hystmpc.models.identification.identify`.
    validation : tuple of array_like, optional
        ``(u, y)`` of a validation record; default: the record's last ``HOLD_OUT``.
    continue_state : bool, optional
        The validation record continues the fit record (the model's state carries over).
    families : list of str, optional
        Families to fit (default: every one of :data:`FAMILIES`).
    options : dict, optional
        Fit options per family name.
    dynamics, dynamics_data, max_delay, alignment, warm_up, creep
        As for :func:`hystmpc.models.identification.identify` (the resonance check runs once).
        With a creep, every family is fitted with it and without it (one candidate each; a family
        that takes no creep of the form, and fckp with its own Grünwald–Letnikov creep, once).
    workers : int, optional
        Families fitted at once, each in its own process.

    Returns
    -------
    Ranking
        The candidates, best first (those without a model last), and the naive model's row.

    Raises
    ------
    FitError
        When no family gives a model.
    """
    u, y = check_data(u, y, sample_period)
    how = "the validation record" + (", continuing the fit record's state" if continue_state else "")
    if validation is None:
        cut = int(round((1 - HOLD_OUT) * len(u)))
        validation, u, y, continue_state = (u[cut:], y[cut:]), u[:cut], y[:cut], True
        how = f"the record's last {HOLD_OUT:.0%} ({len(validation[0])} samples), continuing the fit part's state"
        check_data(u, y, sample_period, "the record's fit part")
    if dynamics == "second-order":  # refused once, here, rather than once per family
        probe = choose_alignment(u, y, sample_period, warm_up) if alignment == "auto" else alignment
        fast = None if dynamics_data is None else check_data(*dynamics_data, sample_period, "dynamics data")
        require_resonance(u, y, sample_period, probe, range(max_delay + 1), warm_up, fast)
    names = sorted(families or FAMILIES, key=lambda name: -COST.get(name, 0))  # the longest first
    form = creep_form(creep)
    kw = {"dynamics": dynamics, "dynamics_data": dynamics_data, "max_delay": max_delay, "alignment": alignment,
          "warm_up": warm_up, "check_resonance": False}
    if form == "kelvin-voigt" and len(u) < FASTEST_CREEP:  # refused once, here, as identify refuses it
        raise ValueError(f"a Kelvin–Voigt creep needs a fit record of at least {FASTEST_CREEP} samples (its elements "
                         f"are slower than that); the record's fit part has {len(u)}")
    creeps = [form, None] if form else [None]  # the slower fits first

    def fitted(name, c):  # fckp fits its own Grünwald–Letnikov creep either way: once
        return c is None or (takes_creep(name, c) and (name, c) != ("fckp", "grunwald-letnikov"))
    jobs = [(name, u, y, sample_period, (options or {}).get(name, {}), kw | {"creep": c}, validation,
             continue_state, warm_up)
            for c in creeps for name in names if fitted(name, c)]
    if workers > 1 and len(jobs) > 1:
        with ProcessPoolExecutor(max_workers=min(workers, len(jobs)), initializer=_one_blas_thread) as pool:
            candidates = list(pool.map(_one, jobs))
    else:
        candidates = [_one(job) for job in jobs]
    start = time.perf_counter()
    naive = naive_model(u, y, sample_period, "next" if alignment == "auto" else alignment, max_delay, warm_up)
    reference = Candidate("linear + first-order lag", None, naive.rmse,
                          validation_rmse(naive, u, validation, continue_state, warm_up), time.perf_counter() - start,
                          model=naive)
    ranked = sorted(candidates, key=lambda c: (c.identified is None, c.validation_rmse))
    ranking = Ranking(ranked, reference, how, len(u))
    if ranked[0].identified is None:
        raise FitError("no family gave a model: " + "; ".join(c.error for c in ranked))
    best = validation_prediction(ranked[0].identified, u, validation[0], continue_state, warm_up)
    for candidate in ranked:
        if candidate.identified is not None:
            other = validation_prediction(candidate.identified, u, validation[0], continue_state, warm_up)
            candidate.distance_to_best = float(np.sqrt(np.mean((other - best) ** 2)))
    return ranking
