"""Identify a hysteresis model, and the linear block after it, from a measured record.

The record is ``(u_k, y_k)`` sampled every ``sample_period`` seconds. Its rows are read as a
rig's (``alignment = "next"``: ``y_k`` measured before ``u_k`` acts) or as a loop tracer's
(``"same"``: ``y_k`` after it); ``"auto"`` fits the family under the one a quick, flexible
static Preisach fit prefers (:func:`choose_alignment`), tries the other from there and keeps
the better. The actuator is taken to be at rest at ``u_0`` (leave an unsettled start out of the
fit with ``warm_up``).

Every family is fitted the same way (:mod:`hystmpc.models.record_fit`): its own start
(:mod:`hystmpc.models.fit_plays`, :mod:`hystmpc.models.fit_operators`), a static refinement,
then, with a linear block, the block and its dead time on the static model's output, and a
joint refinement of every parameter (hysteresis, block, output offset) by simulation-error
least squares on the record. Input offsets are absorbed by every family here (the plays,
Bouc–Wen and the parametric operator move with a shifted input, the others' grids and knots
are fitted on the data), so ``offsets.input`` is 0 unless set by hand.
"""

from __future__ import annotations

from dataclasses import dataclass, field, replace

import numpy as np

from hystmpc.models.block_fit import fit_block
from hystmpc.models.block_parameters import FASTEST_CREEP, creep_start, tidy_creep
from hystmpc.models.families import (
    FAMILIES,
    OFFSET_KEYS,
    Family,
    build_hysteresis,
    compiled_response,
    family,
    fit_options,
    hysteresis_output,
)
from hystmpc.models.fit_plays import preisach_problem
from hystmpc.models.linear_dynamics import LinearDynamics
from hystmpc.models.record_fit import ALIGNMENTS, Record, evaluate, refine, respond, with_creep
from hystmpc.models.resonance import require_resonance

__all__ = ["CREEP_FORMS", "DEFAULT_CREEP", "FAMILIES", "MIN_SAMPLES", "OFFSET_KEYS", "Family", "FitError",
           "Identified", "build_hysteresis", "check_alignment", "check_data", "choose_alignment", "compiled_response",
           "creep_form", "family", "fit_options", "hysteresis_output", "identify", "takes_creep"]

MIN_SAMPLES = 50
"""Fewer samples than this are refused: no family can be told from noise on less."""


@dataclass
class Identified:
    """A fitted model: hysteresis (with creep), offsets and linear block, and how well it fits."""

    family: str
    parameters: dict
    dynamics: LinearDynamics
    sample_period: float
    rmse: float = float("nan")
    n_samples: int = 0
    options: dict = field(default_factory=dict)
    offsets: dict = field(default_factory=lambda: {"input": 0.0, "output": 0.0})
    """``{"input": ..., "output": ...}``: ``y = H[u − input] + output``."""
    alignment: str = "next"
    """How the record's rows were read (:mod:`hystmpc.models.record_fit`)."""
    notes: dict = field(default_factory=dict)
    """What the fit found out along the way (parameters at a search bound, the dynamics' own fit)."""

    def hysteresis(self):
        """``(hysteresis model, creep order)``, offsets included.

        Returns
        -------
        model : object
            The hysteresis model (:func:`build_hysteresis`).
        creep_order : float
            Its creep order (0 without creep).
        """
        return build_hysteresis(self.family, {**self.parameters, "input_offset": self.offsets.get("input", 0.0),
                                              "output_offset": self.offsets.get("output", 0.0)},
                                self.sample_period)

    def predict(self, u, alignment: str | None = None) -> np.ndarray:
        """Modelled output for the inputs ``u`` from rest at ``u[0]``, rows read as the fit record's.

        Parameters
        ----------
        u : array_like
            Input at each sample.
        alignment : str, optional
            ``next`` or ``same`` instead of the fit's :attr:`alignment`.

        Returns
        -------
        ndarray
            The modelled output at each sample, through the linear block and its dead time.
        """
        model, creep_order = self.hysteresis()
        h = hysteresis_output(model, creep_order, u, self.sample_period)
        return respond(h, self.dynamics, Record(np.asarray(u, float), h, self.sample_period,
                                                alignment or self.alignment))


def check_data(u, y, sample_period: float, what: str = "data") -> tuple[np.ndarray, np.ndarray]:
    """``ValueError`` naming what is wrong with an identification record.

    Parameters
    ----------
    u, y : array_like
        Input and output, 1-D of the same length, at least :data:`MIN_SAMPLES`, finite, ``u`` not constant.
    sample_period : float
        Sample period (s), > 0.
    what : str, optional
        Name of the record in the messages.

    Returns
    -------
    u, y : ndarray
        The record as float arrays.
    """
    u, y = np.asarray(u, float), np.asarray(y, float)
    if u.shape != y.shape or u.ndim != 1:
        raise ValueError(f"{what}: u and y must be columns of the same length")
    if len(u) < MIN_SAMPLES:
        raise ValueError(f"{what}: {len(u)} samples; identification needs at least {MIN_SAMPLES}")
    if not (np.all(np.isfinite(u)) and np.all(np.isfinite(y))):
        raise ValueError(f"{what}: NaN or infinite values in u or y")
    if np.ptp(u) == 0:
        raise ValueError(f"{what}: the input u is constant ({u[0]:g}); a hysteresis needs a varying input")
    if not (np.isfinite(sample_period) and sample_period > 0):
        raise ValueError(f"{what}: sample period must be > 0, got {sample_period}")
    return u, y


def check_alignment(alignment: str) -> None:
    """``ValueError`` unless ``alignment`` is ``next``, ``same`` or ``auto``.

    Parameters
    ----------
    alignment : str
        The alignment to check.
    """
    if alignment not in (*ALIGNMENTS, "auto"):
        raise ValueError(f"alignment {alignment!r}; allowed: next, same, auto")


CREEP_FORMS = ("grunwald-letnikov", "kelvin-voigt")
"""What ``creep`` may name: a fractional integral ``D^(−α)`` after the hysteresis, or
first-order (Kelvin–Voigt) elements in the linear block."""
DEFAULT_CREEP = "grunwald-letnikov"
"""The form ``creep=True`` (``--creep`` alone) fits."""


def takes_creep(name: str, form: str) -> bool:
    """Whether family ``name`` can be fitted with the creep form ``form``.

    kp and power-function take no Grünwald–Letnikov creep (fckp is kp with it); every family
    takes a Kelvin–Voigt one.

    Parameters
    ----------
    name : str
        The family.
    form : str
        One of :data:`CREEP_FORMS`.

    Returns
    -------
    bool
        True when :func:`identify` fits it.
    """
    return not (form == "grunwald-letnikov" and name in ("kp", "power-function"))


def creep_form(creep: bool | str | None) -> str | None:
    """The creep form ``creep`` asks for: None (no creep) or one of :data:`CREEP_FORMS`.

    Parameters
    ----------
    creep : bool, str or None
        False or None (none), True (:data:`DEFAULT_CREEP`) or a form's name.

    Returns
    -------
    str or None
        The form.
    """
    if creep is None or creep is False:
        return None
    if creep is True:
        return DEFAULT_CREEP
    if creep not in CREEP_FORMS:
        raise ValueError(f"creep {creep!r}; allowed: {', '.join(CREEP_FORMS)}")
    return creep


class FitError(RuntimeError):
    """A fit that gave no finite result (the command line's exit code 1)."""


def choose_alignment(u, y, sample_period: float, warm_up: int = 0) -> str:
    """``next`` or ``same``: whichever reads the record better.

    Judged by a static Preisach fit on an even grid of 12 thresholds × 12 cells (constrained
    least squares, no refinement), flexible enough to fit every family here closely.

    Parameters
    ----------
    u, y : array_like
        The record.
    sample_period : float
        Sample period (s).
    warm_up : int, optional
        Leading samples left out of the comparison.

    Returns
    -------
    str
        ``next`` or ``same``, the one with the lower RMSE.
    """
    rmse = {}
    for alignment in ALIGNMENTS:
        record = Record(np.asarray(u, float), np.asarray(y, float), sample_period, alignment, warm_up)
        problem = preisach_problem(record, 12, 12)
        rmse[alignment] = evaluate(problem, problem.theta, LinearDynamics(), record).rmse
    return min(rmse, key=rmse.get)


def _static_fit(fam: Family, record: Record, options: dict, other: str | None, creep: str | None = None):
    """``(problem, record, fit)`` of the static refinement (with a creep of the form ``creep``).

    A Kelvin–Voigt creep rides in the fit's block (a ``none`` block with creep elements, their
    shares moved). With ``other``, the other row alignment gets a short refinement from the fit
    and replaces it if it does better.
    """
    problem = fam.problem(record, **options)
    if creep == "grunwald-letnikov":
        problem = with_creep(problem, record)
    block = LinearDynamics(creep=creep_start(record)) if creep == "kelvin-voigt" else LinearDynamics()
    moving = bool(block.creep)
    fit = refine(problem, record, block, move_block=moving)
    if other is None:
        return problem, record, fit
    start = problem.theta
    problem.theta = fit.theta
    trial_record = replace(record, alignment=other)
    trial = refine(problem, trial_record, fit.block, move_block=moving, iterations=6)
    if trial.rmse < fit.rmse:
        problem.theta = trial.theta
        return problem, trial_record, refine(problem, trial_record, trial.block, move_block=moving)
    problem.theta = start
    return problem, record, fit


def _joint(problem, record: Record, fit, kind: str, delays, fast: Record | None, name: str):
    """From the static ``fit``: the block's fit and the joint refinement.

    Returns the fit and the dynamics' own RMSE on the record they were fitted on (None without a
    block).
    """
    if kind == "none":
        return fit, None
    if fast is None:
        for _ in range(2):  # the dead time again on the refined hysteresis, once
            h = problem.columns(fit.theta) @ fit.weights
            block, _ = fit_block(h, record, kind, delays, fit.block.creep)
            if fit.block.kind == kind and block.delay_samples == fit.block.delay_samples:
                break
            fit = refine(problem, record, block, hold=problem.joint_hold)
        for delay in (fit.block.delay_samples - 1, fit.block.delay_samples + 1):
            if delay in delays:
                trial = evaluate(problem, fit.theta, replace(fit.block, delay_samples=delay), record)
                if trial.rmse < fit.rmse:
                    fit = refine(problem, record, trial.block, hold=problem.joint_hold)
        return fit, fit.rmse
    static = Identified(name, {k: v for k, v in problem.parameters(fit.theta, fit.weights).items()
                               if k != "output_offset"}, LinearDynamics(), record.sample_period)
    model, creep_order = static.hysteresis()
    block, rmse = fit_block(hysteresis_output(model, creep_order, fast.u, fast.sample_period), fast, kind, delays)
    return refine(problem, record, replace(block, creep=fit.block.creep), move_block=False), rmse  # the creep: slow


def identify(name: str, u, y, sample_period: float, options: dict | None = None, dynamics: str = "none",
             dynamics_data: tuple | None = None, max_delay: int = 20, alignment: str = "auto",
             warm_up: int = 0, check_resonance: bool = True, creep: bool | str = False) -> Identified:
    """Fit family ``name`` to the record ``(u, y)``, with the linear block ``dynamics``.

    Parameters
    ----------
    name : str
        One of :data:`FAMILIES`.
    u, y : array_like
        Input applied from each sample on, output measured at each sample.
    sample_period : float
        Sample period of the record (s).
    options : dict, optional
        The family's fit options (:attr:`Family.options`).
    dynamics : str, optional
        ``none``, ``first-order`` or ``second-order``: the block after the hysteresis.
    dynamics_data : tuple of array_like, optional
        ``(u, y)`` of a faster record for the block (default: the same record).
    max_delay : int, optional
        Largest dead time tried (samples).
    alignment : str, optional
        ``next``, ``same`` or ``auto`` (the module docstring).
    warm_up : int, optional
        Leading samples simulated but left out of the fit.
    check_resonance : bool, optional
        With ``second-order``, refuse (``ValueError``) a record that does not show a resonance.
    creep : bool or str, optional
        Fit a creep after the hysteresis too: ``"grunwald-letnikov"`` (``D^(−α)``; not for kp or
        power-function) or ``"kelvin-voigt"`` (first-order elements in the linear block, any
        family, fckp too, after its own); True is :data:`DEFAULT_CREEP`.

    Returns
    -------
    Identified
        The model, with its RMSE and sample count after the warm-up, the alignment it was read
        with and notes (parameters at a search bound, the dynamics' own fit).

    Raises
    ------
    FitError
        When the fit gives no model (every weight zero) or its RMSE is not finite.
    """
    from hystmpc.models.linear_dynamics import KINDS
    fam = family(name)
    creep = creep_form(creep)
    if creep and not takes_creep(name, creep):
        raise ValueError(f"{name} takes no Grünwald–Letnikov creep; "
                         f"{'fckp is kp with it' if name == 'kp' else 'fit it without'}, or --creep kelvin-voigt")
    u, y = check_data(u, y, sample_period)
    if creep == "kelvin-voigt" and len(u) < FASTEST_CREEP:
        raise ValueError(f"a Kelvin–Voigt creep needs a record of at least {FASTEST_CREEP} samples (its elements are "
                         f"slower than that); the record has {len(u)}")
    check_alignment(alignment)
    if dynamics not in KINDS:
        raise ValueError(f"dynamics {dynamics!r} is not one of {', '.join(KINDS)}")
    Record(u, y, sample_period, "next", warm_up)  # the warm-up checked before any work
    other = None
    if alignment == "auto":
        alignment = choose_alignment(u, y, sample_period, warm_up)
        other = ALIGNMENTS[1 - ALIGNMENTS.index(alignment)]
    fast = None
    if dynamics_data is not None:
        fast = check_data(*dynamics_data, sample_period, "dynamics data")
    delays = range(max_delay + 1)
    if dynamics == "second-order" and check_resonance:
        require_resonance(u, y, sample_period, alignment, delays, warm_up, fast)
    problem, record, fit = _static_fit(fam, Record(u, y, sample_period, alignment, warm_up),
                                       fit_options(name, options or {}), other,
                                       None if name == "fckp" and creep == "grunwald-letnikov" else creep)
    alignment = record.alignment
    fast = None if fast is None else Record(*fast, sample_period, alignment)
    fit, dynamics_rmse = _joint(problem, record, fit, dynamics, delays, fast, name)
    if fit.block.creep:  # an element the record did not need is not kept as a state, nor twins
        fit.block = replace(fit.block, creep=tidy_creep(fit.block.creep))
    try:
        parameters = problem.parameters(fit.theta, fit.weights)
        offset = parameters.pop("output_offset", fit.offset)
        identified = Identified(name, parameters, fit.block, sample_period, options=dict(options or {}),
                                offsets={"input": 0.0, "output": float(offset)}, alignment=alignment)
        identified.hysteresis()
    except ValueError as exc:
        raise FitError(f"{name}: the fit gave no model ({exc}); if the output falls as the input rises, flip the "
                       "sign of u or y") from None
    error = identified.predict(u)[warm_up:] - y[warm_up:]
    identified.rmse = float(np.sqrt(np.mean(error**2)))
    identified.n_samples = len(u) - warm_up
    if not np.isfinite(identified.rmse):
        raise FitError(f"{name}: the fit's RMSE is not finite (the model diverges on this record); try another "
                       "family or check the record")
    identified.notes = {"at_bounds": list(fit.at_bounds)}
    if dynamics_rmse is not None:
        identified.notes["dynamics"] = {"rmse": float(dynamics_rmse), "record": "dynamics data" if fast else "data"}
    return identified
