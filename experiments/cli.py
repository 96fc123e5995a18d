"""``hystmpc`` command line (interface.md): list, run, compare, sweep, identify, codegen, speed.

Exit codes: 0 success; 2 bad usage or bad input, with one line naming what is wrong and
what is allowed; 1 anything else.
"""

from __future__ import annotations

import argparse
import datetime as dt
import json
import logging
import os
import sys
from pathlib import Path

from hystmpc.experiments.bench import Bench
from hystmpc.experiments.benches import BENCH_NAMES, DEFAULT_BENCH, all_bench_names, get_bench
from hystmpc.experiments.reference import load_reference
from hystmpc.experiments.report import comparison_table, results_document, write_json, write_run_csv
from hystmpc.experiments.runner import RunResult
from hystmpc.models.identification import FAMILIES
from hystmpc.mpc.settings import SOLVERS

FAMILY_NAMES = tuple(FAMILIES)
BENCH_HELP = f"one of {', '.join(BENCH_NAMES)}, a plugin bench, or an actuator file (*.toml)"


class UsageError(Exception):
    """Bad usage or bad input: exit code 2."""


class _Parser(argparse.ArgumentParser):
    def error(self, message):  # one line, exit 2 (argparse prints usage + message otherwise)
        raise UsageError(message)


def _add_run_options(p: argparse.ArgumentParser) -> None:
    p.add_argument("--out", help="results folder (default results/<bench>/<timestamp>)")
    p.add_argument("--json", dest="json_file", help="also write the result document to this file")
    p.add_argument("--reference", help="CSV with columns t and the bench's reference (or 'ref')")
    p.add_argument("--duration", type=float, help="run length in seconds (default: the scenario's)")
    p.add_argument("--set", dest="overrides", action="append", default=[], metavar="KEY=VALUE",
                   help="parameter override, repeatable (e.g. nmpc.horizon=30); 'hystmpc list' names the groups")
    p.add_argument("--seed", type=int, default=0, help="seed of the sensor noise (default 0)")
    p.add_argument("--no-plots", action="store_true", help="skip the figures")
    p.add_argument("--quiet", action="store_true", help="print nothing but errors")


def build_parser() -> argparse.ArgumentParser:
    """The argument parser of ``hystmpc``."""
    parser = _Parser(prog="hystmpc", description="NMPC for actuators with hysteresis: benches from four papers.")
    sub = parser.add_subparsers(dest="command", required=True, parser_class=_Parser)
    p_list = sub.add_parser("list", help="benches, scenarios, controllers, solver variants")
    p_list.add_argument("bench", nargs="?", help="only this bench (a name, plugin or actuator file)")
    p_list.add_argument("--json", action="store_true", help="machine-readable output")
    p_run = sub.add_parser("run", help="one closed-loop run")
    p_run.add_argument("bench", help=BENCH_HELP)
    p_run.add_argument("scenario", nargs="?", help="one of the bench's scenarios (optional with --reference)")
    p_run.add_argument("--controller", required=True)
    _add_run_options(p_run)
    p_cmp = sub.add_parser("compare", help="every controller on every scenario, table and figures")
    p_cmp.add_argument("bench", nargs="?", default=DEFAULT_BENCH, help=BENCH_HELP)
    p_cmp.add_argument("scenarios", nargs="*", help="default: all of the bench's scenarios")
    p_cmp.add_argument("--controllers", help="comma-separated (default: all of the bench's)")
    _add_run_options(p_cmp)
    p_sw = sub.add_parser("sweep", help="many runs: scenarios × controllers × seeds × plant perturbations")
    p_sw.add_argument("spec", metavar="SPEC.toml", help="sweep spec (interface.md)")
    p_sw.add_argument("--workers", type=int, help=f"worker processes (default: the core count, {os.cpu_count()})")
    p_sw.add_argument("--executor", default="local", help="local (process pool, default) or dask")
    p_sw.add_argument("--scheduler", metavar="ADDR", help="address of a running Dask scheduler (with --executor dask)")
    p_sw.add_argument("--resume", action="store_true", help="finish the sweep in --out, skipping recorded runs")
    p_sw.add_argument("--out", help="results folder (default results/<bench>/sweep-<timestamp>)")
    p_sw.add_argument("--json", dest="json_file", help="also write the summary to this file")
    p_sw.add_argument("--duration", type=float, help="run length in seconds (default: the spec's, else the scenario's)")
    p_sw.add_argument("--set", dest="overrides", action="append", default=[], metavar="KEY=VALUE",
                      help="parameter override for every run, after the spec's own 'set'")
    p_sw.add_argument("--no-plots", action="store_true", help="skip the figures")
    p_sw.add_argument("--quiet", action="store_true", help="print nothing but errors")
    p_cg = sub.add_parser("codegen", help="write, build and load the C solver of a bench's NMPC")
    p_cg.add_argument("bench", help=BENCH_HELP)
    p_cg.add_argument("--solver", default="rti", help="rti (the only code-generated variant so far)")
    p_cg.add_argument("--out", help="folder for the C files (default codegen/<bench>)")
    p_cg.add_argument("--verify", action="store_true",
                      help="replay the default scenario with the in-process and the compiled solver")
    p_cg.add_argument("--duration", type=float, help="length of the verification run (s)")
    p_cg.add_argument("--set", dest="overrides", action="append", default=[], metavar="KEY=VALUE")
    p_cg.add_argument("--json", dest="json_file", help="also write the report to this file")
    p_cg.add_argument("--quiet", action="store_true", help="print nothing but errors")
    p_sp = sub.add_parser("speed", help="per-step compute of every solver variant on the default scenario")
    p_sp.add_argument("bench", help=BENCH_HELP)
    p_sp.add_argument("--variants", help="comma-separated solver variants (default: the bench's own solver, "
                      "then ipopt, sqp, rti, rti-c)")
    p_sp.add_argument("--duration", type=float, help="run length (s, default: the scenario's)")
    p_sp.add_argument("--out", help="results folder (default results/<bench>/speed-<timestamp>)")
    p_sp.add_argument("--set", dest="overrides", action="append", default=[], metavar="KEY=VALUE")
    p_sp.add_argument("--quiet", action="store_true", help="print nothing but errors")
    p_id = sub.add_parser("identify", help="fit a hysteresis model to measured data (or a bench's own identification)")
    p_id.add_argument("family", metavar="FAMILY",
                      help=f"one of {', '.join(FAMILY_NAMES)}; or 'reluctance' for that bench's identification")
    p_id.add_argument("data", nargs="?", metavar="DATA.csv", help="measured record: columns t, u, y")
    p_id.add_argument("--validate", metavar="VAL.csv", help="a second record to report the validation RMSE on")
    p_id.add_argument("--dynamics", default="none", help="linear block after the hysteresis: none (default), "
                      "first-order, second-order (with a dead time)")
    p_id.add_argument("--dynamics-data", metavar="FAST.csv",
                      help="a faster record to fit the dynamics on (default: DATA.csv)")
    p_id.add_argument("--max-delay", type=int, default=20, help="largest dead time tried (samples, default 20)")
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
    return parser


IDENTIFIABLE = ("reluctance",)
"""Benches with an identification step of their own."""


def _identify(args) -> int:
    if args.family in IDENTIFIABLE:
        return _identify_bench(args)
    if args.family in all_bench_names():
        raise UsageError(f"bench {args.family!r} has no identification step; benches with one: "
                         f"{', '.join(IDENTIFIABLE)}; model families: {', '.join(FAMILY_NAMES)}")
    if args.family not in FAMILY_NAMES:
        raise UsageError(f"unknown model family {args.family!r}; allowed: {', '.join(FAMILY_NAMES)} "
                         f"(or a bench with an identification step: {', '.join(IDENTIFIABLE)})")
    if args.data is None:
        raise UsageError(f"identify {args.family} needs a measured record DATA.csv (columns t, u, y)")
    if args.bench_data:
        raise UsageError("--data-file is the reluctance bench's; give a family's record as DATA.csv")
    from hystmpc.experiments.identify import identify_command
    try:
        return identify_command(args)
    except ValueError as exc:
        raise UsageError(str(exc)) from None


def _identify_bench(args) -> int:
    for option, value in (("DATA.csv", args.data), ("--validate", args.validate),
                          ("--dynamics-data", args.dynamics_data)):
        if value:
            raise UsageError(f"{option} is for a model family; 'identify reluctance' takes its loops with "
                             f"--data-file FILE")
    if args.dynamics != "none":
        raise UsageError("--dynamics is for a model family; the reluctance bench's model has no linear block")
    bench = _bench(args.family)
    config = _config(bench, args.overrides)
    from hystmpc.experiments.benches.reluctance import identified_document, measured_loops
    from hystmpc.experiments.report import version
    try:
        loops = measured_loops(args.bench_data) if args.bench_data else None
        doc = identified_document(config, loops)
    except ValueError as exc:
        raise UsageError(str(exc)) from None
    doc["version"] = version()
    doc["overrides"] = list(args.overrides)
    out = Path(args.out or "identified.json")
    out.parent.mkdir(parents=True, exist_ok=True)
    out.write_text(json.dumps(doc, indent=1) + "\n")
    if not args.quiet:
        truth = (f" (plant {doc['true_p1_A']:.5f})", f" (plant {doc['true_p2_per_A_m']:.5f})") if "true_p1_A" in doc \
            else ("", "")
        print(f"core {doc['core']}: p1 = {doc['p1_A']:.5f} A{truth[0]}, "
              f"p2 = {doc['p2_per_A_m']:.5f} 1/(A m){truth[1]}; written to {out}")
    return 0


CODEGEN_SOLVERS = ("rti",)


def _positive_duration(value) -> None:
    if value is not None and not value > 0:
        raise UsageError(f"--duration must be > 0 seconds, got {value}")


def _codegen(args) -> int:
    from hystmpc.experiments.realtime import codegen
    bench = _bench(args.bench)
    if args.solver not in CODEGEN_SOLVERS:
        raise UsageError(f"--solver {args.solver!r} cannot be code-generated yet; "
                         f"allowed: {', '.join(CODEGEN_SOLVERS)}")
    _positive_duration(args.duration)
    config = _config(bench, args.overrides)
    out = Path(args.out) if args.out else Path("codegen") / bench.name
    try:
        report = codegen(bench, config, out, args.verify, args.duration)
    except ValueError as exc:
        raise UsageError(str(exc)) from None
    if args.json_file:
        Path(args.json_file).write_text(json.dumps(report, indent=1) + "\n")
    if not args.quiet:
        print(f"C solver written and built in {out}: {', '.join(report['files'])}")
        if args.verify:
            c = report["standalone"]
            print(f"verify on {report['scenario']} ({report['samples']} samples): largest input difference "
                  f"in-process vs compiled {report['max_input_difference']:.3g}; standalone program: "
                  f"output difference {c['max_output_difference_first_200']:.3g}, "
                  f"{c['median_us']:.0f} µs median, {c['p95_us']:.0f} µs p95 per call")
    return 0


def _speed(args) -> int:
    from hystmpc.experiments.realtime import speed, speed_table
    from hystmpc.experiments.report import version
    bench = _bench(args.bench)
    _positive_duration(args.duration)
    config = _config(bench, args.overrides)
    if args.variants:
        variants = args.variants.split(",")
        _check_names("solver variant", variants, SOLVERS)
    else:
        own = config["nmpc"].solver if "nmpc" in config else "ipopt"
        variants = list(dict.fromkeys([own, "ipopt", "sqp", "rti", "rti-c"]))
    out = Path(args.out) if args.out else Path("results") / bench.name / ("speed-" + dt.datetime.now(
        dt.UTC).strftime("%Y%m%dT%H%M%SZ"))
    try:
        result = speed(bench, config, variants, args.duration, out / "codegen")
    except ValueError as exc:
        raise UsageError(str(exc)) from None
    result.update({"schema": "hystmpc.speed/1", "version": version(), "overrides": list(args.overrides)})
    out.mkdir(parents=True, exist_ok=True)
    (out / "speed.json").write_text(json.dumps(result, indent=1) + "\n")
    table = speed_table(result)
    (out / "speed.md").write_text(table + "\n")
    if not args.quiet:
        print(table)
        print(f"\nresults: {out / 'speed.json'}")
    return 0


EXECUTORS = ("local", "dask")


def _sweep(args) -> int:
    from hystmpc.experiments.sweep import SpecError, load_spec, run_sweep, summary_table
    _positive_duration(args.duration)
    if args.executor not in EXECUTORS:
        raise UsageError(f"unknown executor {args.executor!r}; allowed: {', '.join(EXECUTORS)}")
    if args.workers is not None and args.workers < 1:
        raise UsageError(f"--workers must be >= 1, got {args.workers}")
    if args.resume and not args.out:
        raise UsageError("--resume needs --out DIR: the folder of the sweep to finish")
    try:
        spec = load_spec(args.spec, args.overrides, args.duration)
        out = Path(args.out) if args.out else Path("results") / _bench(spec.bench).name / ("sweep-" + dt.datetime.now(
            dt.UTC).strftime("%Y%m%dT%H%M%SZ"))
        outcome = run_sweep(spec, out, workers=args.workers, executor=args.executor, scheduler=args.scheduler,
                            resume=args.resume, plots=not args.no_plots, quiet=args.quiet,
                            spec_text=Path(args.spec).read_text())
    except SpecError as exc:
        raise UsageError(str(exc)) from None
    if args.json_file:
        Path(args.json_file).write_text(json.dumps(outcome.summary, indent=1) + "\n")
    if not args.quiet:
        print(summary_table(outcome.summary, _bench(spec.bench).units))
        print(f"\n{outcome.ran} runs done in {outcome.wall_s:.1f} s ({outcome.skipped} already recorded), "
              f"{outcome.summary['runs_failed']} failed in all; results: {out / 'summary.json'}")
        if outcome.figures:
            print("figures: " + ", ".join(str(f) for f in outcome.figures))
    return 0


def _bench(name: str) -> Bench:
    try:
        return get_bench(name)
    except ValueError as exc:
        raise UsageError(str(exc)) from None


def _check_names(kind: str, names: list[str], allowed) -> None:
    for name in names:
        if name not in allowed:
            raise UsageError(f"unknown {kind} {name!r}; allowed: {', '.join(allowed)}")


def _config(bench: Bench, overrides: list[str]):
    try:
        return bench.configure(overrides)
    except ValueError as exc:
        raise UsageError(str(exc)) from None


def _scenario(bench: Bench, name: str, reference: str | None):
    if reference is None:
        return bench.scenarios[name]
    try:
        return load_reference(reference, bench)
    except ValueError as exc:
        raise UsageError(str(exc)) from None


def _execute(args, bench: Bench, scenario_names: list[str], controllers: list[str]) -> int:
    if args.duration is not None and not args.duration > 0:
        raise UsageError(f"--duration must be > 0 seconds, got {args.duration}")
    if args.reference is not None and len(scenario_names) > 1:
        raise UsageError("--reference replaces one scenario's reference: name one scenario at most")
    config = _config(bench, args.overrides)
    if args.reference is not None and not scenario_names:
        scenarios = [_scenario(bench, None, args.reference)]
    else:
        scenarios = [_scenario(bench, s, args.reference) for s in scenario_names]
    user_keys = {o.split("=", 1)[0].strip() for o in args.overrides}
    for scenario in scenarios:
        for condition in scenario.conditions:
            key = condition.split("=", 1)[0]
            if key in user_keys:
                raise UsageError(f"--set {key} conflicts with scenario {scenario.name!r}, which fixes "
                                 f"{condition}; use --reference for other conditions")
    out = Path(args.out) if args.out else Path("results") / bench.name / dt.datetime.now(
        dt.UTC).strftime("%Y%m%dT%H%M%SZ")
    total = sum(int(round((args.duration or s.duration) / bench.sample_period)) for s in scenarios) * len(controllers)
    runs: list[RunResult] = []
    from tqdm import tqdm
    with tqdm(total=total, unit="step", disable=True if args.quiet else None, leave=False,
              dynamic_ncols=True) as bar:
        for scenario in scenarios:
            for controller in controllers:
                bar.set_description(f"{scenario.name} · {controller}")
                try:
                    prepared = bench.prepare(scenario, controller, config)
                except ValueError as exc:  # a setting the controller or plant cannot take
                    raise UsageError(str(exc)) from None
                run = bench.run(scenario, controller, seed=args.seed, duration=args.duration, progress=bar.update,
                                prepared=prepared)
                runs.append(run)
                write_run_csv(run, out)
    doc = results_document(bench.name, runs, command=sys.argv[1:] if sys.argv else None)
    write_json(doc, out / "results.json")
    if args.json_file:
        write_json(doc, args.json_file)
    table = comparison_table(runs)
    (out / "table.md").write_text(table + "\n")
    figures = []
    if not args.no_plots:
        from hystmpc.experiments.plots import error_vs_reference_figure, rmse_figure, scenario_figure
        for scenario in scenarios:
            subset = [r for r in runs if r.scenario == scenario.name]
            figures.append(scenario_figure(subset, out / f"{scenario.name}.png"))
            if bench.error_vs_reference:
                figures.append(error_vs_reference_figure(subset, out / f"{scenario.name}_error.png"))
        if len(runs) > 1:
            figures.append(rmse_figure(runs, out / "rmse.png"))
    if not args.quiet:
        print(table)
        print(f"\nresults: {out / 'results.json'}" + (f" and {args.json_file}" if args.json_file else ""))
        if figures:
            print("figures: " + ", ".join(str(f) for f in figures))
        if bench.source.endswith(".toml"):
            tuned = [f"{g}: kp {config[g].kp:.4g}, ki {config[g].ki:.4g}, kd {config[g].kd:.4g}"
                     + (f", preview {config[g].preview}" if hasattr(config[g], "preview") else "")
                     for g in ("pid", "inverse_ff_pid") if any(c.replace("-", "_") == g for c in controllers)]
            if tuned:
                print("PID gains (tuned on the nominal model unless set): " + "; ".join(tuned))
        nmpc_runs = [r for r in runs if r.solver]
        if nmpc_runs and any(r.solver["failures"] for r in nmpc_runs):
            print("note: some NMPC solves failed; the fallback input was applied (see solver.failures)")
    return 0


def _list(args) -> int:
    info = {}
    for name in [args.bench] if args.bench else all_bench_names():
        bench = _bench(name)
        info[bench.name if args.bench else name] = {
            "description": bench.description, "paper": bench.paper, "units": bench.units,
            "sample_period_s": bench.sample_period, "scenarios": list(bench.scenarios),
            "controllers": list(bench.controllers), "parameter_groups": list(bench.defaults())} | (
            {"source": bench.source} if bench.source else {})
    if args.json:
        print(json.dumps({"benches": info, "solvers": list(SOLVERS), "families": list(FAMILY_NAMES)}, indent=2))
        return 0
    for name, b in info.items():
        print(f"{name}: {b['description']} [{b['units']}, {1 / b['sample_period_s']:g} Hz]"
              + (f" ({b['source']})" if "source" in b else ""))
        print(f"  scenarios:   {', '.join(b['scenarios'])}")
        print(f"  controllers: {', '.join(b['controllers'])}")
        print(f"  --set groups: {', '.join(b['parameter_groups'])}")
    print(f"solvers (--set nmpc.solver=...): {', '.join(SOLVERS)}")
    print(f"model families (hystmpc identify FAMILY DATA.csv): {', '.join(FAMILY_NAMES)}")
    return 0


def _log_notices(show: bool) -> None:
    """Notices of long steps (tuning, ...) on stderr as ``hystmpc: ...`` lines, unless ``--quiet``."""
    log = logging.getLogger("hystmpc")
    if not any(getattr(h, "hystmpc", False) for h in log.handlers):
        handler = logging.StreamHandler()
        handler.hystmpc = True
        handler.setFormatter(logging.Formatter("hystmpc: %(message)s"))
        log.addHandler(handler)
        log.propagate = False
    log.setLevel(logging.INFO if show else logging.WARNING)


def main(argv: list[str] | None = None) -> int:
    """Entry point; returns the exit code."""
    try:
        args = build_parser().parse_args(argv)
        _log_notices(not getattr(args, "quiet", False))
        if args.command == "list":
            return _list(args)
        if args.command == "identify":
            return _identify(args)
        if args.command == "codegen":
            return _codegen(args)
        if args.command == "speed":
            return _speed(args)
        if args.command == "sweep":
            return _sweep(args)
        bench = _bench(args.bench)
        if args.command == "run":
            if args.scenario is None and args.reference is None:
                raise UsageError(f"name a scenario ({', '.join(bench.scenarios)}) or give --reference FILE.csv")
            scenario = [] if args.scenario is None else [args.scenario]
            _check_names("scenario", scenario, bench.scenarios)
            _check_names("controller", [args.controller], bench.controllers)
            return _execute(args, bench, scenario, [args.controller])
        scenarios = args.scenarios or ([] if args.reference else list(bench.scenarios))
        _check_names("scenario", scenarios, bench.scenarios)
        controllers = args.controllers.split(",") if args.controllers else list(bench.controllers)
        _check_names("controller", controllers, bench.controllers)
        return _execute(args, bench, scenarios, controllers)
    except UsageError as exc:
        print(f"hystmpc: error: {exc}", file=sys.stderr)
        return 2
    except KeyboardInterrupt:
        print("hystmpc: interrupted", file=sys.stderr)
        return 130
    except Exception as exc:  # noqa: BLE001 - anything unexpected: one line, exit 1
        if os.environ.get("HYSTMPC_DEBUG"):
            raise
        print(f"hystmpc: error: {type(exc).__name__}: {exc} (set HYSTMPC_DEBUG=1 for a traceback)",
              file=sys.stderr)
        return 1


def entry_point() -> None:
    """Console-script wrapper."""
    sys.exit(main())
