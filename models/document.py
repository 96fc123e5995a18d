"""Model documents (``hystmpc.model/1``): an identified hysteresis model as JSON.

``hystmpc identify`` writes them; actuator files name them. Layout (interface.md,
"Identification")::

    {"schema": "hystmpc.model/1", "family": "prandtl-ishlinskii", "created": ..., "version": ...,
     "sample_period_s": 0.001, "parameters": {...}, "offsets": {"input": 0.0, "output": ...},
     "alignment": "next", "dynamics": {"kind": "none", ...}, "units": {"u": "V", "y": "um"},
     "fit": {"rmse": ..., "n_samples": ...}, "validation": {...}, "candidates": [...]}
"""

from __future__ import annotations

import dataclasses
import datetime as dt
import json
from pathlib import Path

import numpy as np

from hystmpc.models.identification import FAMILIES, Identified
from hystmpc.models.linear_dynamics import KIND_KEYS, KINDS, LinearDynamics

SCHEMA = "hystmpc.model/1"


def _plain(value):
    if isinstance(value, dict):
        return {k: _plain(v) for k, v in value.items()}
    if isinstance(value, (list, tuple, np.ndarray)):
        return [_plain(v) for v in value]
    if isinstance(value, np.generic):
        return value.item()
    return value


def model_document(identified: Identified, units: dict | None = None, validation: dict | None = None,
                   version: str = "", source: dict | None = None) -> dict:
    """The JSON-ready document of an identified model.

    Parameters
    ----------
    identified : Identified
        The identified model.
    units : dict, optional
        Units of ``"u"`` and ``"y"`` (default: both empty).
    validation : dict, optional
        Validation results, stored under ``"validation"`` when given.
    version : str, optional
        hystmpc version that wrote the document.
    source : dict, optional
        Where the data came from, stored under ``"source"`` when not empty.

    Returns
    -------
    dict
        The document, of plain JSON types.
    """
    doc = {"schema": SCHEMA, "family": identified.family,
           "created": dt.datetime.now(dt.UTC).strftime("%Y-%m-%dT%H:%M:%SZ"), "version": version,
           "sample_period_s": identified.sample_period, "parameters": _plain(identified.parameters),
           "offsets": {"input": float(identified.offsets.get("input", 0.0)),
                       "output": float(identified.offsets.get("output", 0.0))},
           "alignment": identified.alignment,
           "dynamics": _plain(identified.dynamics.parameters()), "units": dict(units or {"u": "", "y": ""}),
           "fit": {"rmse": identified.rmse, "n_samples": identified.n_samples,
                   "options": _plain(identified.options)}}
    if "dynamics" in identified.notes:
        doc["dynamics_fit"] = _plain(identified.notes["dynamics"])
    if identified.notes.get("at_bounds"):
        doc["fit"]["at_bounds"] = list(identified.notes["at_bounds"])
    if validation is not None:
        doc["validation"] = validation
    if source:
        doc["source"] = source
    return doc


def dynamics_from(spec: dict, where: str) -> LinearDynamics:
    """A :class:`LinearDynamics` from a ``dynamics`` table (model document or actuator file).

    Parameters
    ----------
    spec : dict
        The table: ``kind``, that kind's keys and optionally ``delay_samples`` and ``creep``.
    where : str
        Where the table is, prefixed to every error message.

    Returns
    -------
    LinearDynamics
        The dynamics; ``ValueError`` for a missing, unknown or mistyped key.
    """
    if not isinstance(spec, dict):
        raise ValueError(f"{where}: dynamics must be a table, got {spec!r}")
    if "kind" not in spec and spec:  # a table of parameters without its kind
        raise ValueError(f"{where}: dynamics.kind is missing: the table describes the whole block (it replaces "
                         f"the model document's), so give its kind; allowed: {', '.join(KINDS)}")
    kind = spec.get("kind", "none")
    if kind not in KINDS:
        raise ValueError(f"{where}: dynamics.kind = {kind!r}; allowed: {', '.join(KINDS)}")
    allowed = {f.name for f in dataclasses.fields(LinearDynamics)}
    unknown = sorted(set(spec) - allowed)
    if unknown:
        raise ValueError(f"{where}: unknown dynamics key {unknown[0]!r}; allowed: {', '.join(sorted(allowed))}")
    own = ("kind", *KIND_KEYS[kind], "delay_samples")
    for key in allowed - {*own, "creep"}:
        if key in spec:  # a key of another kind would be ignored
            raise ValueError(f"{where}: dynamics key {key!r} does not apply to kind {kind!r}; its keys: "
                             f"{', '.join(own)}, creep")
    for key in KIND_KEYS[kind]:
        if key not in spec:  # no silent default for what describes the actuator
            raise ValueError(f"{where}: dynamics kind {kind!r} needs {key!r}; its keys: {', '.join(own)}")
    for key in own[1:]:
        value = spec.get(key, 0)
        if isinstance(value, bool) or not isinstance(value, int | float) or \
                (key == "delay_samples" and not isinstance(value, int)):
            kind_of = "an integer" if key == "delay_samples" else "a number"
            raise ValueError(f"{where}: dynamics.{key} must be {kind_of}, got {value!r}")
    creep = spec.get("creep", [])
    if not isinstance(creep, list) or not all(
            isinstance(pair, list) and len(pair) == 2 and all(isinstance(v, int | float) and not isinstance(v, bool)
                                                               for v in pair) for pair in creep):
        raise ValueError(f"{where}: dynamics.creep must be a list of [share, time_constant] pairs, got {creep!r}")
    try:
        return LinearDynamics(**spec)
    except (TypeError, ValueError) as exc:
        raise ValueError(f"{where}: dynamics: {exc}") from None


def read_model_document(source: str | Path | dict, sample_period: float | None = None) -> Identified:
    """The model of a document (a path or the parsed dict); ``ValueError`` naming what is wrong.

    Parameters
    ----------
    source : str, Path or dict
        Path of the JSON document, or the parsed document.
    sample_period : float, optional
        Replaces the document's (s); a creep model is discretised there.

    Returns
    -------
    Identified
        The model, with its fit RMSE, sample count, offsets and alignment.
    """
    where = "model document"
    if not isinstance(source, dict):
        where = f"model file {source}"
        try:
            source = json.loads(Path(source).read_text())
        except FileNotFoundError:
            raise ValueError(f"{where}: no such file") from None
        except (OSError, UnicodeDecodeError, json.JSONDecodeError) as exc:
            raise ValueError(f"{where}: not a readable JSON document ({exc})") from None
    if not isinstance(source, dict) or source.get("schema") != SCHEMA:
        found = source.get("schema") if isinstance(source, dict) else type(source).__name__
        raise ValueError(f"{where}: schema is {found!r}, expected {SCHEMA!r}")
    family = source.get("family")
    if family not in FAMILIES:
        raise ValueError(f"{where}: family {family!r}; allowed: {', '.join(FAMILIES)}")
    parameters = source.get("parameters")
    if not isinstance(parameters, dict):
        raise ValueError(f"{where}: 'parameters' must be a table of the family's parameters")
    period = sample_period if sample_period is not None else source.get("sample_period_s", 1.0)
    identified = Identified(family, parameters, dynamics_from(source.get("dynamics", {"kind": "none"}), where),
                            float(period))
    try:
        identified.hysteresis()
    except KeyError as exc:
        raise ValueError(f"{where}: parameter {exc.args[0]!r} of family {family} is missing") from None
    except (TypeError, ValueError) as exc:
        raise ValueError(f"{where}: bad {family} parameters: {exc}") from None
    fit = source.get("fit", {})
    identified.rmse, identified.n_samples = fit.get("rmse", float("nan")), fit.get("n_samples", 0)
    offsets = source.get("offsets", {})
    if not isinstance(offsets, dict) or set(offsets) - {"input", "output"} or not all(
            isinstance(v, int | float) and not isinstance(v, bool) and np.isfinite(v) for v in offsets.values()):
        raise ValueError(f"{where}: offsets must be a table of finite numbers 'input' and 'output', got {offsets!r}")
    identified.offsets = {"input": float(offsets.get("input", 0.0)), "output": float(offsets.get("output", 0.0))}
    alignment = source.get("alignment", "next")
    if alignment not in ("next", "same"):
        raise ValueError(f"{where}: alignment {alignment!r}; allowed: next, same")
    identified.alignment = alignment
    try:
        identified.hysteresis()
    except (TypeError, ValueError) as exc:
        raise ValueError(f"{where}: bad offsets: {exc}") from None
    return identified
