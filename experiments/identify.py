"""``hystmpc identify FAMILY|auto DATA.csv``: fit a model to a measured record, report and save it."""

from __future__ import annotations

import datetime as dt
import json
import logging
import os
import tempfile
from pathlib import Path

import numpy as np

from hystmpc.experiments.reference import load_record
from hystmpc.models.document import model_document
from hystmpc.models.identification import FAMILIES, check_alignment, identify
from hystmpc.models.identify_auto import identify_auto, validation_rmse
from hystmpc.models.linear_dynamics import KINDS

LOG = logging.getLogger("hystmpc")
DEFAULT_MAX_DELAY = 20
"""Largest dead time (samples) the dynamics fit tries unless ``--max-delay`` says."""
POOR_FIT = 0.1
"""``identify`` warns when the fit RMSE exceeds this share of the output's standard deviation
(the model then explains less than 99 % of its variance)."""
OVERFIT = 2.0
"""``identify`` warns when the validation RMSE exceeds the fit's by this factor."""


def _options(family: str, assignments: list[str]) -> dict:
    """The fit options of ``--set NAME=VALUE``, checked before any work.

    For ``auto`` the keys are ``FAMILY.NAME=VALUE`` and the options a table per family.
    """
    from hystmpc.models.identification import fit_options
    options: dict = {}
    for assignment in assignments:
        if "=" not in assignment:
            raise ValueError(f"--set {assignment!r}: expected NAME=VALUE")
        key, value = (part.strip() for part in assignment.split("=", 1))
        if family == "auto":
            name, _, key = key.rpartition(".")
            if name not in FAMILIES:
                raise ValueError(f"--set {assignment!r}: with auto, name the family: FAMILY.OPTION=VALUE, FAMILY one "
                                 f"of {', '.join(FAMILIES)}")
            options.setdefault(name, {})[key] = value
        else:
            options[key] = value
    for name, table in (options.items() if family == "auto" else [(family, options)]):
        fit_options(name, table)  # unknown option or bad value: its own error
    return options


def _check(args) -> int:
    """The option combinations ``identify`` refuses; returns the dead-time bound."""
    if args.dynamics not in KINDS:
        raise ValueError(f"--dynamics {args.dynamics!r}; allowed: {', '.join(KINDS)}")
    if args.dynamics_data and args.dynamics == "none":
        raise ValueError(f"--dynamics-data {args.dynamics_data} fits the dynamics, but --dynamics is none; "
                         "allowed with it: --dynamics first-order or second-order")
    if args.max_delay is not None and args.dynamics == "none":
        raise ValueError(f"--max-delay {args.max_delay} bounds the dynamics' dead time, but --dynamics is none; "
                         "allowed with it: --dynamics first-order or second-order")
    max_delay = DEFAULT_MAX_DELAY if args.max_delay is None else args.max_delay
    if not 0 <= max_delay <= 1000:
        raise ValueError(f"--max-delay must be in [0, 1000] samples, got {max_delay}")
    check_alignment(args.alignment)
    if args.warm_up < 0:
        raise ValueError(f"--warm-up must be >= 0 samples, got {args.warm_up}")
    if args.continue_state and not args.validate:
        raise ValueError("--continue says the validation record continues the data record; give it with "
                         "--validate VAL.csv")
    return max_delay


def identify_command(args) -> int:
    """Run ``identify`` for a model family or ``auto`` (``args`` from the ``hystmpc`` parser); returns the exit code.

    Writes the model document to ``--out`` and, unless ``--no-plots``, its figures beside it.

    Parameters
    ----------
    args : argparse.Namespace
        The parsed ``identify`` command line.

    Returns
    -------
    int
        0 (a problem raises instead, e.g. ``ValueError`` for bad options or files).
    """
    from hystmpc.experiments.report import version
    max_delay = _check(args)
    options = _options(args.family, args.overrides)
    u, y, period = load_record(args.data, "data file")
    validation = load_record(args.validate, "--validate file") if args.validate else None
    fast = load_record(args.dynamics_data, "--dynamics-data file") if args.dynamics_data else None
    for what, record in (("--validate", validation), ("--dynamics-data", fast)):
        if record is not None and abs(record[2] - period) > 1e-6 * period:
            raise ValueError(f"{what} file is sampled every {record[2]:g} s, the data every {period:g} s")
    if args.warm_up >= len(u) - 10:
        raise ValueError(f"--warm-up {args.warm_up} leaves fewer than 10 of the data's {len(u)} samples to fit")
    out = model_path(args.out)
    try:  # before the fit: a path that cannot be written fails now, not after minutes of work
        out.parent.mkdir(parents=True, exist_ok=True)
        with tempfile.TemporaryFile(dir=out.parent):
            pass
    except OSError as exc:
        raise ValueError(f"--out {str(out)!r} cannot be written ({exc.strerror or type(exc).__name__})") from None
    common = {"dynamics": args.dynamics, "dynamics_data": None if fast is None else fast[:2], "max_delay": max_delay,
              "alignment": args.alignment, "warm_up": args.warm_up, "creep": args.creep}
    units = {"u": args.input_units, "y": args.units}
    if args.family == "auto":
        ranking = identify_auto(u, y, period, None if validation is None else validation[:2], args.continue_state,
                                options=options, workers=min(2, os.cpu_count() or 1), **common)
        best = ranking.best
        identified, fit_u = best.identified, u[: ranking.fit_samples]
        val = {"rmse": best.validation_rmse, "n_samples": len(u) - len(fit_u) if validation is None else
               len(validation[0]), "how": ranking.validation}
        if validation is not None:
            val["file"] = str(args.validate)
        doc = model_document(identified, units, val, version(), source=_source(args))
        doc["candidates"] = [_candidate(c, units) for c in ranking.candidates]
        doc["reference"] = _candidate(ranking.naive)
    else:
        identified = identify(args.family, u, y, period, options, **common)
        fit_u, val = u, None
        if validation is not None:
            val = {"rmse": validation_rmse(identified, u, validation[:2], args.continue_state, args.warm_up),
                   "n_samples": len(validation[0]), "file": str(args.validate)}
            if not np.isfinite(val["rmse"]):
                from hystmpc.models.identification import FitError
                raise FitError(f"{args.family}: the validation RMSE is not finite (the model diverges on "
                               f"{args.validate})")
        doc = model_document(identified, units, val, version(), source=_source(args))
    replaced = out.exists()
    out.write_text(json.dumps(doc, indent=1) + "\n")
    figures = []
    if not args.no_plots:
        held = None if validation is not None or args.family != "auto" else (u[len(fit_u):], y[len(fit_u):])
        figures.append(identification_figure(identified, (fit_u, y[: len(fit_u)]),
                                             validation[:2] if validation is not None else held,
                                             args.continue_state or held is not None, out.with_suffix(".png"),
                                             args.units, args.input_units))
        if args.dynamics != "none":
            record = fast[:2] if fast is not None else (fit_u, y[: len(fit_u)])
            figures.append(dynamics_figure(identified, record, out.with_name(out.stem + "_dynamics.png"), args.units))
    if not args.quiet:
        if args.family == "auto":
            print(ranking_table(ranking, args.units))
        print(summary(doc))
        print(f"model: {out}" + (" (replaced the earlier one)" if replaced else "")
              + (f"; figures: {', '.join(str(f) for f in figures)}" if figures else ""))
    _warn(doc, y)
    return 0


def _source(args) -> dict:
    return {"data": str(args.data), **({"dynamics_data": str(args.dynamics_data)} if args.dynamics_data else {}),
            **({"warm_up": args.warm_up} if args.warm_up else {})}


def _candidate(c, units: dict | None = None) -> dict:
    """A row of the ranking.

    With ``units``, it holds the candidate's own model document under ``"model"`` (an actuator
    file's simulated plant may be the runner-up).
    """
    row = {"family": c.family, **({"creep": c.creep} if c.creep else {}), "fit_rmse": c.fit_rmse,
           "validation_rmse": c.validation_rmse,
           "seconds": round(c.seconds, 2)}
    if c.identified is not None:
        row["alignment"] = c.identified.alignment
        row["dynamics"] = c.identified.dynamics.parameters()
        row["distance_to_best"] = c.distance_to_best
    if c.error:
        row["error"] = c.error
    row = {k: (None if isinstance(v, float) and not np.isfinite(v) else v) for k, v in row.items()}
    if units is not None and c.identified is not None and np.isfinite(c.validation_rmse):
        row["model"] = model_document(c.identified, units, {"rmse": c.validation_rmse})
    return row


def _warn(doc: dict, y) -> None:
    """The one-line warnings (shown even with ``--quiet``)."""
    family, fit = doc["family"], doc["fit"]["rmse"]
    spread = float(np.std(y))
    if fit > POOR_FIT * spread:
        LOG.warning(f"poor fit: RMSE {fit:.4g} is {fit / spread:.0%} of the output's standard deviation "
                    f"({spread:.4g}); check the family (maxwell-slip saturates), the input's sign, and that the "
                    "record starts at rest (--warm-up N leaves an unsettled start out)")
    val = doc.get("validation", {}).get("rmse")
    if val is not None and val > OVERFIT * fit:
        LOG.warning(f"{family}: validation RMSE {val:.4g} is {val / fit:.1f} × the fit's {fit:.4g}: the model does not "
                    "carry over (too many parameters for the record, another operating point, drift, or a validation "
                    "record that does not start at rest: --continue or --warm-up)")
    bounds = doc["fit"].get("at_bounds")
    if bounds:
        LOG.warning(f"{family}: {', '.join(bounds)} at a bound of the search: the record may not determine "
                    f"{'it' if len(bounds) == 1 else 'them'}, or the family does not suit it")
    reference = doc.get("reference")
    if reference and reference.get("validation_rmse") and val is not None and val >= reference["validation_rmse"]:
        LOG.warning(f"no family beats a straight line through a first-order lag on validation ({val:.4g} against "
                    f"{reference['validation_rmse']:.4g}): a hysteresis model does not pay on this record")


def ranking_table(ranking, units: str) -> str:
    """The ``auto`` ranking as a table for the terminal.

    Parameters
    ----------
    ranking : Ranking
        The result of :func:`hystmpc.models.identify_auto.identify_auto`; its naive model is the
        last row and the validation RMSEs' yardstick.
    units : str
        Units of the output (may be empty).

    Returns
    -------
    str
        The table, one line per candidate.
    """
    unit = f" [{units}]" if units else ""
    naive = ranking.naive.validation_rmse
    width = max(len(c.label) for c in [*ranking.candidates, ranking.naive]) + 1
    lines = [f"validation on {ranking.validation}",
             f"{'family':{width}s} {'fit RMSE' + unit:>16s} {'validation' + unit:>16s} {'vs linear+lag':>14s} "
             f"{'time':>7s}"]
    for c in [*ranking.candidates, ranking.naive]:
        if c.error:
            lines.append(f"{c.label:{width}s} {'failed: ' + c.error}")
            continue
        ratio = c.validation_rmse / naive if naive > 0 else float("nan")
        lines.append(f"{c.label:{width}s} {c.fit_rmse:16.4g} {c.validation_rmse:16.4g} {ratio:14.3f} {c.seconds:6.1f}s")
    return "\n".join(lines)


def model_path(out: str | None, default_name: str = "model.json") -> Path:
    """``--out``'s model document file.

    ``ValueError`` for a folder.

    Parameters
    ----------
    out : str or None
        The ``--out`` value; None for the default, under ``results/identify/<timestamp>/``.
    default_name : str, optional
        File name of the default, and of the suggestion when ``out`` is a folder.

    Returns
    -------
    Path
        The file to write (not created here).
    """
    if out is None:
        return Path("results") / "identify" / dt.datetime.now(dt.UTC).strftime("%Y%m%dT%H%M%SZ") / default_name
    path = Path(out)
    if out.endswith(("/", os.sep)) or path.is_dir():
        raise ValueError(f"--out {out!r} is a folder; name the model document's file (e.g. {path / default_name})")
    return path


def summary(doc: dict) -> str:
    """The parameters and fit of a model document, for the terminal.

    Parameters
    ----------
    doc : dict
        A model document.

    Returns
    -------
    str
        Several lines: family, parameters, offsets, dynamics and the fit (and validation) RMSE.
    """
    units = doc["units"].get("y", "")
    lines = [f"{doc['family']} ({FAMILIES[doc['family']].description})"]
    for name, value in doc["parameters"].items():
        if isinstance(value, list):
            flat = np.asarray(value, float).ravel()
            text = ", ".join(f"{v:.5g}" for v in flat[:12]) + (" ..." if len(flat) > 12 else "")
            lines.append(f"  {name}: [{text}]")
        else:
            lines.append(f"  {name}: {value:.6g}" if isinstance(value, float) else f"  {name}: {value}")
    offsets = doc.get("offsets", {})
    lines.append(f"  offsets: input {offsets.get('input', 0.0):.5g}, output {offsets.get('output', 0.0):.5g}; rows "
                 f"read as '{doc.get('alignment', 'next')}'")
    dyn = doc["dynamics"]
    def shown(value):
        if isinstance(value, float):
            return f"{value:.5g}"
        if isinstance(value, list):  # the creep's [share, time constant] pairs
            return "[" + ", ".join(shown(v) for v in value) + "]"
        return f"{value}"
    lines.append("  dynamics: " + ", ".join(f"{k} = {shown(v)}" for k, v in dyn.items()))
    units = f" {units}" if units else ""
    lines.append(f"fit RMSE {doc['fit']['rmse']:.4g}{units} on {doc['fit']['n_samples']} samples"
                 + (f"; validation RMSE {doc['validation']['rmse']:.4g}{units} on "
                    f"{doc['validation']['n_samples']} samples" if "validation" in doc else ""))
    if "dynamics_fit" in doc:
        lines.append(f"dynamics fit RMSE {doc['dynamics_fit']['rmse']:.4g}{units} on the "
                     f"{doc['dynamics_fit']['record']} record")
    return "\n".join(lines)


def _plt():
    import matplotlib
    matplotlib.use("Agg")
    import matplotlib.pyplot as plt
    return plt


def identification_figure(identified, fit: tuple, validation: tuple | None, continued: bool, path: Path, units: str,
                          input_units: str) -> Path:
    """Measured against modelled output over time, and the loops (output against input).

    Parameters
    ----------
    identified : Identified
        The identified model.
    fit : tuple of ndarray
        The ``(u, y)`` record it was fitted on.
    validation : tuple of ndarray or None
        A validation record ``(u, y)``, drawn in a second row.
    continued : bool
        The validation record continues the fit record (the model runs through the fit first).
    path : Path
        The PNG file to write.
    units, input_units : str
        Units of the output and of the input.

    Returns
    -------
    Path
        ``path``.
    """
    plt = _plt()
    records = [("fit", *fit, identified.predict(fit[0]))]
    if validation is not None:
        u_val = np.asarray(validation[0], float)
        model = (identified.predict(np.concatenate((fit[0], u_val)))[len(fit[0]):] if continued
                 else identified.predict(u_val))
        records.append(("validation", *validation, model))
    fig, axes = plt.subplots(len(records), 2, figsize=(11, 3.4 * len(records)), squeeze=False)
    for row, (label, u, y, model) in zip(axes, records, strict=True):
        t = np.arange(len(u)) * identified.sample_period
        row[0].plot(t, y, lw=0.8, label="measured")
        row[0].plot(t, model, lw=0.8, label="model")
        rmse = float(np.sqrt(np.mean((model - y) ** 2)))
        row[0].set(xlabel="t [s]", ylabel=f"y [{units}]", title=f"{label}: RMSE {rmse:.3g} {units}")
        row[0].legend(fontsize=8)
        row[1].plot(u, y, lw=0.6, label="measured")
        row[1].plot(u, model, lw=0.6, label="model")
        row[1].set(xlabel=f"u [{input_units}]", ylabel=f"y [{units}]", title=f"{label}: loops")
    fig.suptitle(f"identified {identified.family} model")
    fig.tight_layout()
    fig.savefig(path, dpi=110)
    plt.close(fig)
    return path


def dynamics_figure(identified, record: tuple, path: Path, units: str) -> Path:
    """The dynamics' own fit: measured against modelled output on the record they were fitted on.

    The record is shown whole and around its fastest input change.

    Parameters
    ----------
    identified : Identified
        The identified model.
    record : tuple of ndarray
        The ``(u, y)`` record the dynamics were fitted on.
    path : Path
        The PNG file to write.
    units : str
        Units of the output.

    Returns
    -------
    Path
        ``path``.
    """
    plt = _plt()
    u, y = (np.asarray(v, float) for v in record)
    model = identified.predict(u)
    t = np.arange(len(u)) * identified.sample_period
    k = int(np.argmax(np.abs(np.diff(u))))
    window = slice(max(k - 40, 0), min(k + 160, len(u)))
    fig, axes = plt.subplots(1, 2, figsize=(11, 3.4))
    panels = ((axes[0], slice(None), "whole record"), (axes[1], window, "around the fastest input change"))
    for ax, part, title in panels:
        ax.plot(t[part], y[part], lw=0.8, label="measured")
        ax.plot(t[part], model[part], lw=0.8, label="model")
        ax.set(xlabel="t [s]", ylabel=f"y [{units}]", title=title)
    rmse = float(np.sqrt(np.mean((model - y) ** 2)))
    axes[0].legend(fontsize=8)
    fig.suptitle(f"dynamics: {identified.dynamics.parameters()} — RMSE {rmse:.3g} {units}", fontsize=9)
    fig.tight_layout()
    fig.savefig(path, dpi=110)
    plt.close(fig)
    return path
