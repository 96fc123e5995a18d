"""``hystmpc sweep``: many runs from a spec, in worker processes or on a Dask cluster, resumable.

The runs are scenarios × controllers × seeds × plant perturbations.
"""

from __future__ import annotations

import os
import sys
from pathlib import Path

from hystmpc.experiments.cli.common import (
    JSON_HELP,
    UsageError,
    bench_named,
    check_duration,
    checked_json_target,
    report_solver_log,
    timestamped,
    write_json_target,
)


def add_parser(sub) -> None:
    """Register ``sweep`` on the subcommand parsers ``sub``.

    Parameters
    ----------
    sub : argparse._SubParsersAction
        What ``add_subparsers`` returned for ``hystmpc``.
    """
    p_sw = sub.add_parser("sweep", help="many runs: scenarios × controllers × seeds × plant perturbations")
    p_sw.add_argument("spec", metavar="SPEC.toml", help="sweep spec (interface.md)")
    p_sw.add_argument("--workers", type=int, help=f"worker processes (default: the core count, {os.cpu_count()})")
    p_sw.add_argument("--executor", default="local", help="local (process pool, default) or dask")
    p_sw.add_argument("--scheduler", metavar="ADDR", help="address of a running Dask scheduler (with --executor dask)")
    p_sw.add_argument("--resume", action="store_true", help="finish the sweep in --out, skipping recorded runs")
    p_sw.add_argument("--retry-failed", action="store_true", help="with --resume: also redo the runs that failed")
    p_sw.add_argument("--out", help="results folder (default results/<bench>/sweep-<timestamp>); must be new or "
                      "empty, or hold the sweep to --resume")
    p_sw.add_argument("--json", dest="json_file", help=JSON_HELP.format("summary"))
    p_sw.add_argument("--force", action="store_true", help="run beyond the work limits (horizon 200, 1,000,000 "
                      "samples per run, 10,000 runs and 20,000,000 samples per sweep)")
    p_sw.add_argument("--duration", type=float, help="run length in seconds (default: the spec's, else the scenario's)")
    p_sw.add_argument("--set", dest="overrides", action="append", default=[], metavar="KEY=VALUE",
                      help="parameter override for every run, after the spec's own 'set'")
    p_sw.add_argument("--no-plots", action="store_true", help="skip the figures")
    p_sw.add_argument("--quiet", action="store_true", help="print nothing but errors")
    p_sw.set_defaults(handler=command)


EXECUTORS = ("local", "dask")


def command(args) -> int:
    """Run ``sweep``; returns the exit code.

    Parameters
    ----------
    args : argparse.Namespace
        The parsed command line.

    Returns
    -------
    int
        0, or 1 when every recorded run failed; bad usage or input raises ``UsageError`` (exit 2).
    """
    from hystmpc.experiments.sweep import run_sweep
    from hystmpc.experiments.sweep_spec import SpecError, load_spec
    from hystmpc.experiments.sweep_summary import summary_table
    check_duration(args.duration)
    if args.executor not in EXECUTORS:
        raise UsageError(f"unknown executor {args.executor!r}; allowed: {', '.join(EXECUTORS)}")
    if args.workers is not None and args.workers < 1:
        raise UsageError(f"--workers must be >= 1, got {args.workers}")
    if args.resume and not args.out:
        raise UsageError("--resume needs --out DIR: the folder of the sweep to finish")
    if args.retry_failed and not args.resume:
        raise UsageError("--retry-failed redoes the failed runs of a sweep: use it with --resume and --out DIR")
    json_target = checked_json_target(args.json_file)
    try:
        spec = load_spec(args.spec, args.overrides, args.duration, force=args.force)
        out = Path(args.out) if args.out else timestamped(Path("results") / bench_named(spec.bench).name, "sweep-")
        outcome = run_sweep(spec, out, workers=args.workers, executor=args.executor, scheduler=args.scheduler,
                            resume=args.resume, plots=not args.no_plots, quiet=args.quiet,
                            spec_text=Path(args.spec).read_text(), retry_failed=args.retry_failed)
    except SpecError as exc:
        raise UsageError(str(exc)) from None
    write_json_target(outcome.summary, json_target)
    report_solver_log(out / "solver.log", args.quiet)
    summary = outcome.summary
    if not args.quiet and json_target != "-":
        print(summary_table(summary, bench_named(spec.bench).units))
        print(f"\n{outcome.ran} runs done in {outcome.wall_s:.1f} s ({outcome.skipped} already recorded), "
              f"{summary['runs_failed']} failed in all; results: {out / 'summary.json'}")
        if outcome.figures:
            print("figures: " + ", ".join(str(f) for f in outcome.figures))
    if summary["runs_recorded"] and summary["runs_failed"] == summary["runs_recorded"]:
        print(f"hystmpc: error: every run of the sweep failed ({summary['runs_failed']}); the causes are in "
              f"{out / 'records'}", file=sys.stderr)
        return 1
    return 0
