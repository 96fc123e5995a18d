"""``hystmpc speed``: per-step compute of each solver variant of a bench's NMPC.

It runs on the bench's default scenario (with the compiled C solver and controller where
``rti-c`` is among them).
"""

from __future__ import annotations

import json
from pathlib import Path

from hystmpc.experiments.cli.common import (
    BENCH_HELP,
    FORCE_HELP,
    UsageError,
    bench_named,
    check_duration,
    check_names,
    checked_codegen_settings,
    checked_samples,
    cleanup_on_error,
    output_folder,
    report_solver_log,
    sets_key,
    solver_log,
    timestamped,
    work_config,
)
from hystmpc.mpc.settings import SOLVERS


def add_parser(sub) -> None:
    """Register ``speed`` on the subcommand parsers ``sub``.

    Parameters
    ----------
    sub : argparse._SubParsersAction
        What ``add_subparsers`` returned for ``hystmpc``.
    """
    p_sp = sub.add_parser("speed", help="per-step compute of every solver variant on the default scenario")
    p_sp.add_argument("bench", help=BENCH_HELP)
    p_sp.add_argument("--variants", help="comma-separated solver variants (default: the bench's own solver, "
                      "then ipopt, sqp, rti, rti-c)")
    p_sp.add_argument("--duration", type=float, help="run length (s, default: the scenario's)")
    p_sp.add_argument("--out", help="results folder (default results/<bench>/speed-<timestamp>); an existing, "
                      "non-empty one is refused unless --overwrite")
    p_sp.add_argument("--overwrite", action="store_true", help="write into an --out folder that already holds files")
    p_sp.add_argument("--force", action="store_true", help=FORCE_HELP)
    p_sp.add_argument("--set", dest="overrides", action="append", default=[], metavar="KEY=VALUE",
                      help="parameter override, repeatable (e.g. nmpc.horizon=30)")
    p_sp.add_argument("--quiet", action="store_true", help="print nothing but errors")
    p_sp.set_defaults(handler=command)


def command(args) -> int:
    """Run ``speed``; returns the exit code.

    Parameters
    ----------
    args : argparse.Namespace
        The parsed command line.

    Returns
    -------
    int
        0; bad usage or input raises ``UsageError`` (exit 2).
    """
    from hystmpc.experiments.realtime import speed, speed_table
    from hystmpc.experiments.report import version
    bench = bench_named(args.bench)
    check_duration(args.duration)
    checked_codegen_settings(bench, work_config(bench, args.overrides, args.force, tuned=False))  # before tuning
    # an actuator file's NMPC walk is tuned (once, cached), unless --set gives it
    config = work_config(bench, args.overrides, args.force, tuned=not sets_key(args.overrides, "estimator.disturbance"))
    if args.variants:
        variants = args.variants.split(",")
        check_names("solver variant", variants, SOLVERS)
    else:
        own = config["nmpc"].solver if "nmpc" in config else "ipopt"
        variants = list(dict.fromkeys([own, "ipopt", "sqp", "rti", "rti-c"]))
    scenario = bench.scenario(bench.default_scenario) if bench.default_scenario else None
    if scenario is not None:
        checked_samples(args.duration or scenario.duration, bench.sample_period, "--duration", args.force)
    out = Path(args.out) if args.out else timestamped(Path("results") / bench.name, "speed-")
    created = output_folder(out, overwrite=args.overwrite)
    with cleanup_on_error(out, created):
        try:
            with solver_log(out / "solver.log"):
                result = speed(bench, config, variants, args.duration, out / "codegen")
        except ValueError as exc:
            raise UsageError(str(exc)) from None
    result.update({"schema": "hystmpc.speed/1", "version": version(), "overrides": list(args.overrides)})
    (out / "speed.json").write_text(json.dumps(result, indent=1) + "\n")
    table = speed_table(result)
    (out / "speed.md").write_text(table + "\n")
    report_solver_log(out / "solver.log", args.quiet)
    if not args.quiet:
        print(table)
        print(f"\nresults: {out / 'speed.json'}")
    return 0
