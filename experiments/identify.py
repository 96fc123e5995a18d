"""``hystmpc identify FAMILY DATA.csv``: fit a model to a measured record, report and save it."""

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
from hystmpc.models.identification import FAMILIES, identify
from hystmpc.models.linear_dynamics import KINDS


def _options(family: str, assignments: list[str]) -> dict:
    options = {}
    for assignment in assignments:
        if "=" not in assignment:
            raise ValueError(f"--set {assignment!r}: expected NAME=VALUE")
        key, value = (part.strip() for part in assignment.split("=", 1))
        options[key] = value
    from hystmpc.models.identification import fit_options
    fit_options(family, options)  # unknown option or bad value: its own error, before any work
    return options


DEFAULT_MAX_DELAY = 20
"""Largest dead time (samples) the dynamics fit tries unless ``--max-delay`` says."""


def identify_command(args) -> int:
    """Run ``identify`` for a model family (``args`` from the ``hystmpc`` parser); returns the exit code."""
    from hystmpc.experiments.report import version
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
    options = _options(args.family, args.overrides)
    u, y, period = load_record(args.data, "data file")
    validation = load_record(args.validate, "--validate file") if args.validate else None
    fast = load_record(args.dynamics_data, "--dynamics-data file") if args.dynamics_data else None
    for what, record in (("--validate", validation), ("--dynamics-data", fast)):
        if record is not None and abs(record[2] - period) > 1e-6 * period:
            raise ValueError(f"{what} file is sampled every {record[2]:g} s, the data every {period:g} s")
    out = model_path(args.out)
    try:  # before the fit: a path that cannot be written fails now, not after minutes of work
        out.parent.mkdir(parents=True, exist_ok=True)
        with tempfile.TemporaryFile(dir=out.parent):
            pass
    except OSError as exc:
        raise ValueError(f"--out {str(out)!r} cannot be written ({exc.strerror or type(exc).__name__})") from None
    identified = identify(args.family, u, y, period, options, args.dynamics,
                          None if fast is None else fast[:2], max_delay)
    val = None
    if validation is not None:
        predicted = identified.predict(validation[0])
        val = {"rmse": float(np.sqrt(np.mean((predicted - validation[1]) ** 2))), "n_samples": len(validation[0]),
               "file": str(args.validate)}
    doc = model_document(identified, {"u": args.input_units, "y": args.units}, val, version(),
                         source={"data": str(args.data), **({"dynamics_data": str(args.dynamics_data)}
                                                            if args.dynamics_data else {})})
    replaced = out.exists()
    out.parent.mkdir(parents=True, exist_ok=True)
    out.write_text(json.dumps(doc, indent=1) + "\n")
    figure = None
    if not args.no_plots:
        figure = identification_figure(identified, (u, y), None if validation is None else validation[:2],
                                       out.with_suffix(".png"), args.units, args.input_units)
    if not args.quiet:
        print(summary(doc))
        print(f"model: {out}" + (" (replaced the earlier one)" if replaced else "")
              + (f"; figure: {figure}" if figure else ""))
    spread = float(np.std(y))
    if identified.rmse > POOR_FIT * spread:  # a warning: shown even with --quiet
        logging.getLogger("hystmpc").warning(
            f"poor fit: RMSE {identified.rmse:.4g} is {identified.rmse / spread:.0%} of the output's standard "
            f"deviation ({spread:.4g}); check the family (maxwell-slip saturates), that the record starts at rest "
            "with output 0 at input 0 (remove a sensor offset), and the input's sign")
    return 0


POOR_FIT = 0.1
"""``identify`` warns when the fit RMSE exceeds this share of the output's standard deviation
(the model then explains less than 99 % of its variance; the piezo example fits to 0.9 %)."""


def model_path(out: str | None, default_name: str = "model.json") -> Path:
    """``--out``'s model document file (``ValueError`` for a folder; default under
    ``results/identify/<timestamp>/``)."""
    if out is None:
        return Path("results") / "identify" / dt.datetime.now(dt.UTC).strftime("%Y%m%dT%H%M%SZ") / default_name
    path = Path(out)
    if out.endswith(("/", os.sep)) or path.is_dir():
        raise ValueError(f"--out {out!r} is a folder; name the model document's file (e.g. {path / default_name})")
    return path


def summary(doc: dict) -> str:
    """The parameters and fit of a model document, for the terminal."""
    units = doc["units"].get("y", "")
    lines = [f"{doc['family']} ({FAMILIES[doc['family']].description})"]
    for name, value in doc["parameters"].items():
        if isinstance(value, list):
            flat = np.asarray(value, float).ravel()
            text = ", ".join(f"{v:.5g}" for v in flat[:12]) + (" ..." if len(flat) > 12 else "")
            lines.append(f"  {name}: [{text}]")
        else:
            lines.append(f"  {name}: {value:.6g}" if isinstance(value, float) else f"  {name}: {value}")
    dyn = doc["dynamics"]
    lines.append("  dynamics: " + ", ".join(f"{k} = {v:.5g}" if isinstance(v, float) else f"{k} = {v}"
                                            for k, v in dyn.items()))
    units = f" {units}" if units else ""
    lines.append(f"fit RMSE {doc['fit']['rmse']:.4g}{units} on {doc['fit']['n_samples']} samples"
                 + (f"; validation RMSE {doc['validation']['rmse']:.4g}{units} on "
                    f"{doc['validation']['n_samples']} samples" if "validation" in doc else ""))
    return "\n".join(lines)


def identification_figure(identified, fit: tuple, validation: tuple | None, path: Path, units: str,
                          input_units: str) -> Path:
    """Measured against modelled output over time, and the loops (output against input)."""
    import matplotlib
    matplotlib.use("Agg")
    import matplotlib.pyplot as plt

    records = [("fit", *fit)] + ([("validation", *validation)] if validation is not None else [])
    fig, axes = plt.subplots(len(records), 2, figsize=(11, 3.4 * len(records)), squeeze=False)
    for row, (label, u, y) in zip(axes, records, strict=True):
        model = identified.predict(u)
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
