"""``hystmpc codegen``: write, build and check a bench's NMPC as C.

The C is the RTI step, and the whole controller where it can be generated; optionally
cross-compiled for a microcontroller.
"""

from __future__ import annotations

from pathlib import Path

from hystmpc.experiments.cli.common import (
    BENCH_HELP,
    FORCE_HELP,
    JSON_HELP,
    UsageError,
    bench_named,
    check_duration,
    checked_codegen_settings,
    checked_json_target,
    checked_samples,
    cleanup_on_error,
    output_folder,
    sets_key,
    work_config,
    write_json_target,
)


def add_parser(sub) -> None:
    """Register ``codegen`` on the subcommand parsers ``sub``.

    Parameters
    ----------
    sub : argparse._SubParsersAction
        What ``add_subparsers`` returned for ``hystmpc``.
    """
    p_cg = sub.add_parser("codegen", help="write, build and load the C solver of a bench's NMPC")
    p_cg.add_argument("bench", help=BENCH_HELP)
    p_cg.add_argument("--solver", default="rti", help="rti (the only code-generated variant so far)")
    p_cg.add_argument("--out", help="folder for the C files (default codegen/<bench>)")
    p_cg.add_argument("--verify", action="store_true",
                      help="replay the default scenario with the in-process and the compiled solver")
    p_cg.add_argument("--duration", type=float, help="length of the verification run (s)")
    p_cg.add_argument("--target", help="also cross-compile the whole controller for a microcontroller and "
                      "report its size: cortex-m7 (needs arm-none-eabi-gcc)")
    p_cg.add_argument("--set", dest="overrides", action="append", default=[], metavar="KEY=VALUE",
                      help="parameter override, repeatable (e.g. solver.rti.iterations=2)")
    p_cg.add_argument("--json", dest="json_file", help=JSON_HELP.format("report"))
    p_cg.add_argument("--force", action="store_true", help=FORCE_HELP)
    p_cg.add_argument("--quiet", action="store_true", help="print nothing but errors")
    p_cg.set_defaults(handler=command)


CODEGEN_SOLVERS = ("rti",)
CODEGEN_TARGETS = ("cortex-m7",)


def command(args) -> int:
    """Run ``codegen``; returns the exit code.

    Parameters
    ----------
    args : argparse.Namespace
        The parsed command line.

    Returns
    -------
    int
        0; bad usage or input raises ``UsageError`` (exit 2).
    """
    from hystmpc.experiments.realtime import codegen
    bench = bench_named(args.bench)
    if args.solver not in CODEGEN_SOLVERS:
        raise UsageError(f"--solver {args.solver!r} cannot be code-generated yet; "
                         f"allowed: {', '.join(CODEGEN_SOLVERS)}")
    check_duration(args.duration)
    if args.duration is not None and not args.verify:
        raise UsageError(f"--duration {args.duration:g} sets the length of the --verify run; add --verify, or drop "
                         "--duration")
    if args.target not in (None, *CODEGEN_TARGETS):
        raise UsageError(f"--target {args.target!r} is unknown; allowed: {', '.join(CODEGEN_TARGETS)}")
    checked_codegen_settings(bench, work_config(bench, args.overrides, args.force, tuned=False))  # before tuning
    # an actuator file's NMPC walk is tuned (once, cached), unless --set gives it
    config = work_config(bench, args.overrides, args.force, tuned=not sets_key(args.overrides, "estimator.disturbance"))
    if args.target is not None and not sets_key(args.overrides, "solver.rti.sensitivity_block"):
        from hystmpc.experiments.firmware import firmware_config
        try:
            config = firmware_config(bench, config)  # RAM before speed
        except ValueError as exc:
            raise UsageError(str(exc)) from None
    if args.duration is not None:
        checked_samples(args.duration, bench.sample_period, "--duration", args.force)
    out = Path(args.out) if args.out else Path("codegen") / bench.name
    json_target = checked_json_target(args.json_file)
    created = output_folder(out)  # a build folder: its files are replaced
    with cleanup_on_error(out, created):
        try:
            report = codegen(bench, config, out, args.verify, args.duration, args.target)
        except ValueError as exc:
            raise UsageError(str(exc)) from None
    write_json_target(report, json_target)
    if not args.quiet and json_target != "-":
        print(f"C solver written and built in {out}: {', '.join(report['files'])}")
        ctrl = report["controller"]
        if "skipped" in ctrl:
            print(f"whole controller not generated: {ctrl['skipped']}")
        else:
            print(f"whole controller (estimator, warm start, solver, fallback) in {ctrl['folder']}: {ctrl['name']}.h "
                  f"documents the interface; example loop {ctrl['name']}_main")
            if ctrl.get("generated_with"):
                print(f"  built with {', '.join(ctrl['generated_with'])}: what the generated controller needs "
                      "(docs/realtime.md)")
        if args.target in ctrl:
            m7 = ctrl[args.target]
            if ctrl["sensitivity_block"]:
                print(f"sensitivities padded in blocks of {ctrl['sensitivity_block']} for less RAM, the same "
                      "numbers (solver.rti.sensitivity_block; set 0 for the fastest step)")
            print(f"{args.target} build ({m7['qp']} QP): text {m7['text']:,} B, data {m7['data']:,} B, "
                  f"bss {m7['bss']:,} B: {m7['elf']}")
        if args.verify and "verify" in ctrl:
            v = ctrl["verify"]
            loop = v["example_loop"]
            print(f"controller verify on {v['scenario']}: largest input difference Python vs C controller "
                  f"{v['max_input_difference']:.3g}; example loop: feedback {loop['step_median_us']:.0f} µs median, "
                  f"{loop['step_p95_us']:.0f} µs p95, prepare {loop['prepare_median_us']:.0f} µs median")
        if args.verify:
            c = report["standalone"]
            print(f"verify on {report['scenario']} ({report['samples']} samples): largest input difference "
                  f"in-process vs compiled {report['max_input_difference']:.3g}; standalone program: "
                  f"output difference {c['max_output_difference_first_200']:.3g}, "
                  f"{c['median_us']:.0f} µs median, {c['p95_us']:.0f} µs p95 per call")
    return 0
