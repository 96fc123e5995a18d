"""hystmpc's hysteresis families: how each is built from its named parameters and fitted.

:data:`FAMILIES` maps each public name (``hystmpc identify FAMILY``) to a :class:`Family`:
its model's builder, its fit problem (:mod:`hystmpc.models.fit_plays`,
:mod:`hystmpc.models.fit_operators`), its fit options and the parameters a simulated plant
perturbs. :func:`build_hysteresis` adds what every family takes besides its own parameters
(offsets, and a creep order); :func:`hysteresis_output` runs a built model along a record,
through the compiled recursions of :mod:`hystmpc.models.compiled` where there is one.
"""

from __future__ import annotations

from collections.abc import Callable
from dataclasses import dataclass
from typing import Any

import numpy as np

from hystmpc.models.bouc_wen import SUBSTEPS, BoucWen
from hystmpc.models.fckp import Fckp, FckpParams
from hystmpc.models.fit_operators import (
    bouc_wen_problem,
    kp_problem,
    parametric_problem,
    power_function_outputs_of,
    power_function_problem,
)
from hystmpc.models.fit_plays import (
    generalised_pi_problem,
    maxwell_slip_problem,
    prandtl_ishlinskii_problem,
    preisach_problem,
)
from hystmpc.models.fractional import creep_integral
from hystmpc.models.generalised_pi import GeneralisedPI
from hystmpc.models.maxwell_slip import MaxwellSlip
from hystmpc.models.parametric import ParametricHysteresis
from hystmpc.models.power_function import PowerFunctionHysteresis
from hystmpc.models.prandtl_ishlinskii import PrandtlIshlinskii
from hystmpc.models.preisach import Preisach
from hystmpc.models.scaled import Offset, Scaled

OFFSET_KEYS = ("input_offset", "output_offset")
"""Parameters every family takes besides its own (:func:`build_hysteresis`)."""


@dataclass(frozen=True)
class Family:
    """A hysteresis family: how to build it from named parameters and how to fit it."""

    name: str
    description: str
    build: Callable[[dict, float], tuple[Any, float]]
    """``(parameters, sample_period) -> (hysteresis model, creep order)``."""
    problem: Callable[..., Any]
    """``(record, **options) -> Problem`` (:mod:`hystmpc.models.record_fit`)."""
    options: dict[str, Any]
    """Fit options and their defaults (``hystmpc identify ... --set NAME=VALUE``)."""
    mismatch: tuple[str, ...]
    """Parameters a simulated plant perturbs (the others are structure: grids, ranges)."""


def build_hysteresis(name: str, parameters: dict, sample_period: float):
    """``(hysteresis model, creep order)`` of family ``name`` from its parameters.

    With ``input_offset`` and ``output_offset`` (0 when absent) around the model, and a
    ``creep_order`` (fitted with ``creep=True``) for families without a creep of their own.

    Parameters
    ----------
    name : str
        Family name, a key of :data:`FAMILIES`.
    parameters : dict
        The family's parameters, with the optional offsets and ``creep_order``.
    sample_period : float
        Sample period (s).

    Returns
    -------
    tuple
        ``(model, creep_order)``: the model (in an ``Offset`` when an offset is not 0) and its
        creep order (0 without creep).
    """
    own = {k: v for k, v in parameters.items() if k not in OFFSET_KEYS}
    creep = own.pop("creep_order", None) if name != "fckp" else None
    if creep is not None and not (isinstance(creep, int | float) and 0 <= creep < 1):
        raise ValueError(f"creep_order must be in [0, 1), got {creep!r}")
    model, creep_order = family(name).build(own, sample_period)
    creep_order = float(creep) if creep is not None else creep_order
    shift = {k: float(parameters.get(k, 0.0)) for k in OFFSET_KEYS}
    if shift["input_offset"] or shift["output_offset"]:
        model = Offset(model, **shift)
    return model, creep_order


def hysteresis_output(model, creep_order: float, u, sample_period: float) -> np.ndarray:
    """Exact hysteresis (and creep) output along ``u`` from the relaxed state at ``u[0]``.

    Parameters
    ----------
    model : object
        A hysteresis model from :func:`build_hysteresis`.
    creep_order : float
        Fractional creep order (0: no creep).
    u : array_like
        Input record.
    sample_period : float
        Sample period (s).

    Returns
    -------
    ndarray
        The output, one value per sample of ``u``.
    """
    u = np.asarray(u, float)
    inner, (shift_in, shift_out) = ((model.inner, (model.input_offset, model.output_offset))
                                    if isinstance(model, Offset) else (model, (0.0, 0.0)))
    w = compiled_response(inner, u - shift_in)
    w = model.simulate(u)[0] if w is None else w + shift_out
    return creep_integral(w, creep_order, sample_period)


def compiled_response(model, u) -> np.ndarray | None:
    """The exact response of ``model`` along ``u`` from ``initial_state(u[0])``.

    Computed by the compiled recursions of :mod:`hystmpc.models.compiled`.

    Parameters
    ----------
    model : object
        A hysteresis model (without offsets).
    u : ndarray
        Input record.

    Returns
    -------
    ndarray or None
        The output, one value per sample of ``u``; None for a model without a compiled recursion.
    """
    from hystmpc.models.compiled import bouc_wen_states, kp_kernel_outputs, parametric_outputs, play_outputs
    from hystmpc.models.kp import ridge

    def plays(r):
        r = np.asarray(r, float)
        return play_outputs(u, r, np.full(len(r), u[0]))
    if isinstance(model, Scaled) and isinstance(model.inner, ParametricHysteresis):
        return model.gain * parametric_outputs(u, model.inner.p1, model.inner.p2)
    if isinstance(model, PowerFunctionHysteresis):
        return power_function_outputs_of(model, u)
    if isinstance(model, PrandtlIshlinskii):
        return model.linear_gain * u + (plays(model.thresholds) @ np.asarray(model.weights) if model.weights else 0.0)
    if isinstance(model, MaxwellSlip):
        k = np.asarray(model.k)
        return (u[:, None] - plays(np.asarray(model.w) / k)) @ k
    if isinstance(model, GeneralisedPI):
        return model.curve(compiled_response(model.inner, u))
    if isinstance(model, Preisach):
        return model.outputs(np.column_stack((u, plays(model.thresholds))))
    if isinstance(model, BoucWen):
        zeta = bouc_wen_states(u, 1.0, model.beta, model.gamma, 0.0, model.exponent, SUBSTEPS)
        return model.linear_gain * u + model.a * zeta
    if isinstance(model, Fckp):
        kp, p = model.kp, model.normalise(u)
        xi = kp_kernel_outputs(p, p[0], kp.rho1, kp.rho2, kp.delta, ridge(p[0] - kp.rho2, kp.delta))
        return model.static(xi @ kp.weights)
    return None


# ----- building each family from its parameters -----------------------------------------------------

def _build_prandtl_ishlinskii(p: dict, sample_period: float):
    return PrandtlIshlinskii(float(p["linear_gain"]), tuple(p["thresholds"]), tuple(p["weights"])), 0.0


def _build_maxwell_slip(p: dict, sample_period: float):
    return MaxwellSlip(tuple(float(v) for v in p["stiffness"]), tuple(float(v) for v in p["breakaway"])), 0.0


def _build_preisach(p: dict, sample_period: float):
    return Preisach(tuple(p["thresholds"]), tuple(p["knots"]), tuple(tuple(row) for row in p["density"])), 0.0


def _build_generalised_pi(p: dict, sample_period: float):
    return GeneralisedPI(float(p["linear_gain"]), tuple(p["thresholds"]), tuple(p["weights"]),
                         tuple(p["output_knots"]), tuple(p["output_values"])), 0.0


def _build_bouc_wen(p: dict, sample_period: float):
    return BoucWen(float(p["linear_gain"]), float(p["a"]), float(p["beta"]), float(p["gamma"]),
                   float(p.get("exponent", 1.0))), 0.0


def _build_parametric(p: dict, sample_period: float):
    return Scaled(ParametricHysteresis(float(p["p1"]), float(p["p2"])), float(p["gain"])), 0.0


def _fckp_params(p: dict, sample_period: float, creep_order: float) -> FckpParams:
    return FckpParams(levels=int(p["levels"]), max_span=int(p["max_span"]), delta=float(p["delta"]),
                      density_c=float(p["density_c"]), density_sigma=float(p["density_sigma"]),
                      creep_order=creep_order, stroke=float(p["stroke"]), u_max=float(p["u_max"]),
                      sample_period=sample_period, u_min=float(p.get("u_min", 0.0)))


def _build_kp(p: dict, sample_period: float):
    return Fckp(_fckp_params(p, sample_period, 0.0)), 0.0


def _build_fckp(p: dict, sample_period: float):
    alpha = float(p["creep_order"])
    return Fckp(_fckp_params(p, sample_period, alpha)), alpha


def _build_power_function(p: dict, sample_period: float):
    return PowerFunctionHysteresis(tuple(tuple(map(float, q)) for q in p["ascending"]),
                                   tuple(tuple(map(float, q)) for q in p["descending"]),
                                   k11=float(p["k11"]), k01=float(p["k01"]), k12=float(p["k12"]),
                                   k02=float(p["k02"]), exponent_positive=tuple(map(float, p["exponent_positive"])),
                                   exponent_negative=tuple(map(float, p["exponent_negative"]))), 0.0


_KP_OPTIONS = {"levels": 12, "max_span": 2, "delta": 0.15, "u_max": 0.0, "u_min": float("nan")}
FAMILIES: dict[str, Family] = {f.name: f for f in (
    Family("prandtl-ishlinskii", "linear term + weighted play operators", _build_prandtl_ishlinskii,
           prandtl_ishlinskii_problem, {"plays": 10}, ("linear_gain", "thresholds", "weights")),
    Family("maxwell-slip", "parallel elasto-slide elements", _build_maxwell_slip, maxwell_slip_problem,
           {"elements": 10}, ("stiffness", "breakaway")),
    Family("preisach", "Preisach density on play thresholds × relay centres", _build_preisach, preisach_problem,
           {"plays": 8, "cells": 8, "smoothing": 1e-6}, ("thresholds",)),
    Family("generalised-pi", "Prandtl–Ishlinskii behind a monotone output curve (asymmetric, saturating)",
           _build_generalised_pi, generalised_pi_problem, {"plays": 8, "cells": 6},
           ("linear_gain", "thresholds", "weights", "output_values")),
    Family("bouc-wen", "Bouc–Wen differential model (exponent n >= 1 fitted)", _build_bouc_wen,
           bouc_wen_problem, {}, ("linear_gain", "a", "beta", "gamma")),
    Family("power-function", "zhou2024 polylines and power-function transitions", _build_power_function,
           power_function_problem, {"knots": 10, "ascending_s": (), "descending_s": ()},
           ("k11", "k01", "k12", "k02", "exponent_positive", "exponent_negative")),
    Family("parametric", "katalenic2013 Lambert-W operator, times a gain", _build_parametric, parametric_problem, {},
           ("p1", "p2", "gain")),
    Family("kp", "wang2025 Krasnoselskii–Pokrovskii model (no creep)", _build_kp,
           lambda record, **o: kp_problem(record, False, **o), dict(_KP_OPTIONS),
           ("density_c", "density_sigma", "stroke")),
    Family("fckp", "wang2025 KP model with fractional-order creep", _build_fckp,
           lambda record, **o: kp_problem(record, True, **o), dict(_KP_OPTIONS),
           ("density_c", "density_sigma", "stroke", "creep_order")),
)}
"""Every hysteresis family hystmpc identifies, by public name."""


def family(name: str) -> Family:
    """The family called ``name``; ``ValueError`` naming the allowed ones otherwise.

    Parameters
    ----------
    name : str
        Public family name.

    Returns
    -------
    Family
        Its entry of :data:`FAMILIES`.
    """
    if name not in FAMILIES:
        raise ValueError(f"unknown model family {name!r}; allowed: {', '.join(FAMILIES)}")
    return FAMILIES[name]


def fit_options(name: str, assignments: dict[str, Any]) -> dict[str, Any]:
    """The family's fit options with ``assignments`` (text or values) applied.

    Raises ``ValueError`` naming an unknown option or a bad value.

    Parameters
    ----------
    name : str
        Public family name.
    assignments : dict
        Option values by name, as text (``"1,2"`` for a tuple) or values, converted to the type of the default.

    Returns
    -------
    dict
        Every option of the family: the defaults with ``assignments`` applied.
    """
    fam = family(name)
    options = dict(fam.options)
    for key, value in assignments.items():
        if key not in options:
            allowed = ", ".join(options) or "none"
            raise ValueError(f"unknown option {key!r} for family {name}; its options: {allowed}")
        default = options[key]
        try:
            if isinstance(default, tuple):
                value = tuple(float(v) for v in (value.split(",") if isinstance(value, str) else value))
            elif isinstance(default, int):
                value = int(value)
            else:
                value = float(value)
        except (TypeError, ValueError):
            raise ValueError(f"option {key}={value!r} for family {name}: expected "
                             f"{'numbers' if isinstance(default, tuple) else type(default).__name__}") from None
        options[key] = value
    return options
