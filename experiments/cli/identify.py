"""``hystmpc identify``: fit a hysteresis model family to a measured record.

It can also run a bench's own identification (reluctance).
"""

from __future__ import annotations

import json
import sys
from pathlib import Path

from hystmpc.experiments.benches import all_bench_names
from hystmpc.experiments.cli.common import FAMILY_NAMES, UsageError, bench_named, configured


def add_parser(sub) -> None:
    """Register ``identify`` on the subcommand parsers ``sub``.

    Parameters
    ----------
    sub : argparse._SubParsersAction
        What ``add_subparsers`` returned for ``hystmpc``.
    """
    p_id = sub.add_parser("identify", help="fit a hysteresis model to measured data (or a bench's own identification)")
    p_id.add_argument("family", metavar="FAMILY",
                      help=f"one of {', '.join(FAMILY_NAMES)}; 'auto' for every family, ranked by validation; or "
                      "'reluctance' for that bench's identification")
    p_id.add_argument("data", nargs="?", metavar="DATA.csv", help="measured record: columns t, u, y")
    p_id.add_argument("--validate", metavar="VAL.csv", help="a second record to report the validation RMSE on")
    p_id.add_argument("--dynamics", default="none", help="linear block after the hysteresis: none (default), "
                      "first-order, second-order (with a dead time)")
    p_id.add_argument("--dynamics-data", metavar="FAST.csv",
                      help="a faster record to fit the dynamics on (default: DATA.csv)")
    p_id.add_argument("--max-delay", type=int, help="largest dead time tried (samples, default 20; with --dynamics)")
    p_id.add_argument("--alignment", default="auto", help="how the rows read: next (y_k measured before u_k acts, a "
                      "sampled loop), same (after it, a loop tracer), auto (default: the better fit)")
    p_id.add_argument("--warm-up", type=int, default=0, metavar="N",
                      help="leading samples simulated but left out of the fit and of --validate's RMSE (default 0)")
    p_id.add_argument("--continue", dest="continue_state", action="store_true",
                      help="the --validate record continues the data record (the model's state carries over)")
    p_id.add_argument("--creep", nargs="?", const=True, default=False, metavar="FORM",
                      help="fit a creep after the hysteresis too: grunwald-letnikov (a fractional integral; not "
                      "for kp or power-function) or kelvin-voigt (first-order elements in the linear block, any "
                      "family, fckp too after its own; the controller generates in C); --creep alone: "
                      "grunwald-letnikov (fckp has its own); with auto, every family is ranked with and without "
                      "it (one that takes no creep of the form: without)")
    p_id.add_argument("--units", default="", help="output units, recorded in the model document (e.g. um)")
    p_id.add_argument("--input-units", default="", help="input units (e.g. V)")
    p_id.add_argument("--data-file", dest="bench_data", metavar="FILE",
                      help="reluctance only: measured major loops, columns t, u (A), y (N), gap_mm")
    p_id.add_argument("--out", help="model document (default results/identify/<timestamp>/model.json; "
                      "reluctance: identified.json)")
    p_id.add_argument("--set", dest="overrides", action="append", default=[], metavar="KEY=VALUE",
                      help="a fit option of the family (e.g. plays=12), or for reluctance a bench parameter "
                      "(rig.core=C)")
    p_id.add_argument("--no-plots", action="store_true", help="skip the figure")
    p_id.add_argument("--quiet", action="store_true", help="print nothing but errors")
    p_id.set_defaults(handler=command)


IDENTIFIABLE = ("reluctance",)
"""Benches with an identification step of their own."""


def command(args) -> int:
    """Run ``identify``; returns the exit code.

    Parameters
    ----------
    args : argparse.Namespace
        The parsed command line.

    Returns
    -------
    int
        0, or 1 when the fit gives no finite result; bad usage or input raises ``UsageError`` (exit 2).
    """
    from hystmpc.models.identification import CREEP_FORMS
    if isinstance(args.creep, str) and args.creep not in CREEP_FORMS:
        raise UsageError(f"--creep {args.creep!r}: not a creep form; allowed: {', '.join(CREEP_FORMS)} (--creep "
                         "alone: grunwald-letnikov; if that was the family or the record, put --creep after them "
                         "or write --creep=FORM)")
    if args.family in IDENTIFIABLE:
        return _identify_bench(args)
    if args.family in all_bench_names():
        raise UsageError(f"bench {args.family!r} has no identification step; benches with one: "
                         f"{', '.join(IDENTIFIABLE)}; model families: {', '.join(FAMILY_NAMES)}")
    if args.family not in (*FAMILY_NAMES, "auto"):
        raise UsageError(f"unknown model family {args.family!r}; allowed: {', '.join(FAMILY_NAMES)}, auto "
                         f"(or a bench with an identification step: {', '.join(IDENTIFIABLE)})")
    if args.data is None:
        raise UsageError(f"identify {args.family} needs a measured record DATA.csv (columns t, u, y)")
    if args.bench_data:
        raise UsageError("--data-file is the reluctance bench's; give a family's record as DATA.csv")
    from hystmpc.experiments.identify import identify_command
    from hystmpc.models.identification import FitError
    try:
        return identify_command(args)
    except ValueError as exc:
        raise UsageError(str(exc)) from None
    except FitError as exc:  # a fit that gave no finite result: exit 1, one line
        print(f"hystmpc: error: {exc}", file=sys.stderr)
        return 1


def _identify_bench(args) -> int:
    for option, value in (("DATA.csv", args.data), ("--validate", args.validate),
                          ("--dynamics-data", args.dynamics_data), ("--max-delay", args.max_delay),
                          ("--units", args.units), ("--input-units", args.input_units),
                          ("--alignment", None if args.alignment == "auto" else args.alignment),
                          ("--warm-up", args.warm_up or None), ("--continue", args.continue_state or None),
                          ("--creep", args.creep or None)):
        if value not in (None, ""):
            raise UsageError(f"{option} is for a model family; 'identify reluctance' takes its loops with "
                             f"--data-file FILE (its units are A and N)")
    if args.dynamics != "none":
        raise UsageError("--dynamics is for a model family; the reluctance bench's model has no linear block")
    bench = bench_named(args.family)
    config = configured(bench, args.overrides)
    from hystmpc.experiments.benches.reluctance_identification import identified_document, measured_loops
    from hystmpc.experiments.report import version
    try:
        loops = measured_loops(args.bench_data) if args.bench_data else None
        doc = identified_document(config, loops)
    except ValueError as exc:
        raise UsageError(str(exc)) from None
    doc["version"] = version()
    doc["overrides"] = list(args.overrides)
    out = Path("identified.json")
    if args.out is not None:
        from hystmpc.experiments.identify import model_path
        try:
            out = model_path(args.out, "identified.json")
        except ValueError as exc:
            raise UsageError(str(exc)) from None
    replaced = out.exists()
    out.parent.mkdir(parents=True, exist_ok=True)
    out.write_text(json.dumps(doc, indent=1) + "\n")
    if not args.quiet:
        truth = (f" (plant {doc['true_p1_A']:.5f})", f" (plant {doc['true_p2_per_A_m']:.5f})") if "true_p1_A" in doc \
            else ("", "")
        print(f"core {doc['core']}: p1 = {doc['p1_A']:.5f} A{truth[0]}, "
              f"p2 = {doc['p2_per_A_m']:.5f} 1/(A m){truth[1]}; written to {out}"
              + (" (replaced the earlier one)" if replaced else ""))
    return 0
