"""``hystmpc`` command line (interface.md): list, run, compare, sweep, identify, codegen, speed.

Exit codes: 0 success; 2 bad usage or bad input, with one line naming what is wrong and
what is allowed; 1 anything else.
"""

from __future__ import annotations

import argparse
import contextlib
import dataclasses
import datetime as dt
import json
import logging
import os
import shutil
import sys
import tempfile
from pathlib import Path

import numpy as np

from hystmpc.experiments.bench import MULTIPLE_SHOOTING, Bench
from hystmpc.experiments.benches import BENCH_NAMES, DEFAULT_BENCH, all_bench_names, get_bench
from hystmpc.experiments.limits import check_horizons, check_run_samples, run_samples
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


FORCE_HELP = "run beyond the work limits (horizon 200, 1,000,000 samples per run; interface.md)"
JSON_HELP = "also write the {} to this file ('-': standard output, instead of the table)"


def _add_run_options(p: argparse.ArgumentParser) -> None:
    p.add_argument("--out", help="results folder (default results/<bench>/<timestamp>); an existing, non-empty "
                   "one is refused unless --overwrite")
    p.add_argument("--overwrite", action="store_true", help="write into an --out folder that already holds files")
    p.add_argument("--json", dest="json_file", help=JSON_HELP.format("result document"))
    p.add_argument("--force", action="store_true", help=FORCE_HELP)
    p.add_argument("--reference", help="CSV with columns t and the bench's reference (or 'ref')")
    p.add_argument("--duration", type=float, help="run length in seconds (default: the scenario's)")
    p.add_argument("--set", dest="overrides", action="append", default=[], metavar="KEY=VALUE",
                   help="parameter override, repeatable (e.g. nmpc.horizon=30); 'hystmpc list' names the groups")
    p.add_argument("--seed", type=int, default=0, help="seed of the sensor noise (default 0)")
    p.add_argument("--plant", metavar="MODULE:CALLABLE", help="your own plant (a rig, your own simulator) instead "
                   "of the bench's: CALLABLE() from MODULE (a module name or a .py file) returns it (interface.md)")
    p.add_argument("--no-plots", action="store_true", help="skip the figures")
    p.add_argument("--quiet", action="store_true", help="print nothing but errors")


def build_parser() -> argparse.ArgumentParser:
    """The argument parser of ``hystmpc``."""
    parser = _Parser(prog="hystmpc", description="NMPC for actuators with hysteresis: benches from four papers.")
    from hystmpc.experiments.report import version
    parser.add_argument("--version", action="version", version=f"hystmpc {version()}")
    sub = parser.add_subparsers(dest="command", required=True, parser_class=_Parser)
    p_list = sub.add_parser("list", help="benches, scenarios, controllers, solver variants")
    p_list.add_argument("bench", nargs="?", help="only this bench (a name, plugin or actuator file)")
    p_list.add_argument("--json", action="store_true", help="machine-readable output")
    p_run = sub.add_parser("run", help="one closed-loop run")
    p_run.add_argument("bench", help=BENCH_HELP)
    p_run.add_argument("scenario", nargs="?", help="one of the bench's scenarios (optional with --reference)")
    p_run.add_argument("--controller", required=True, help="one of the bench's controllers ('hystmpc list BENCH')")
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
    p_id.add_argument("--creep", action="store_true", help="fit a fractional-order (Grünwald–Letnikov) creep after "
                      "the hysteresis too (fckp has its own; kp and power-function take none)")
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
    parser.commands = tuple(sub.choices)
    return parser


IDENTIFIABLE = ("reluctance",)
"""Benches with an identification step of their own."""


def _identify(args) -> int:
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


CODEGEN_SOLVERS = ("rti",)
CODEGEN_TARGETS = ("cortex-m7",)


def _timestamped(folder: Path, prefix: str = "") -> Path:
    """A new folder name under ``folder``: ``<prefix><UTC timestamp>``, suffixed if taken."""
    stamp = prefix + dt.datetime.now(dt.UTC).strftime("%Y%m%dT%H%M%SZ")
    path, n = folder / stamp, 1
    while path.exists():
        n += 1
        path = folder / f"{stamp}-{n}"
    return path


def _output_folder(path: Path, option: str = "--out", overwrite: bool = True) -> bool:
    """Create ``path`` (or check it) before any work; returns whether it was created.

    ``UsageError`` for a file, a folder that cannot be written, or (unless ``overwrite``)
    a folder that already holds files.
    """
    if path.exists() and not path.is_dir():
        raise UsageError(f"{option} {str(path)!r} is a file; give a folder")
    if not overwrite and path.is_dir() and any(path.iterdir()):
        raise UsageError(f"{option} {str(path)!r} already holds files; pass --overwrite to write into it, or "
                         "choose another folder")
    created = not path.exists()
    try:
        path.mkdir(parents=True, exist_ok=True)
        with tempfile.TemporaryFile(dir=path):
            pass
    except OSError as exc:
        raise UsageError(f"{option} {str(path)!r} cannot be written ({exc.strerror or type(exc).__name__})") from None
    return created


def _json_target(value: str | None) -> Path | str | None:
    """``--json``'s file, checked (its folder created) before any work; ``'-'`` is standard output."""
    if value is None or value == "-":
        return value
    path = Path(value)
    if path.is_dir():
        raise UsageError(f"--json {value!r} is a folder; give a file name (or '-' for standard output)")
    try:
        path.parent.mkdir(parents=True, exist_ok=True)
        with tempfile.TemporaryFile(dir=path.parent):
            pass
    except OSError as exc:
        raise UsageError(f"--json {value!r} cannot be written ({exc.strerror or type(exc).__name__})") from None
    return path


def _write_json_target(doc: dict, target: Path | str | None) -> None:
    if target == "-":
        json.dump(doc, sys.stdout, indent=2, allow_nan=False)
        sys.stdout.write("\n")
    elif target is not None:
        write_json(doc, target)


@contextlib.contextmanager
def _cleanup_on_error(folder: Path, created: bool):
    """Remove ``folder`` if the work in it fails and this command created it: nothing half-written stays."""
    try:
        yield
    except BaseException:
        if created:
            shutil.rmtree(folder, ignore_errors=True)
        raise


@contextlib.contextmanager
def _solver_log(path: Path):
    """Solver and CasADi warnings (written to Python's stderr) go to ``path``, not the terminal."""
    with open(path, "a") as log, contextlib.redirect_stderr(log):
        yield


def _report_solver_log(path: Path, quiet: bool) -> None:
    if not path.exists():
        return
    with path.open() as log:
        lines = sum(1 for _ in log)
    if not lines:
        path.unlink()
    elif not quiet:
        logging.getLogger("hystmpc").info(f"{lines} lines of solver warnings written to {path}")


def _seed(value: int) -> int:
    if value < 0:
        raise UsageError(f"--seed must be an integer >= 0, got {value}")
    return value


def _samples(duration: float, sample_period: float, what: str, force: bool) -> int:
    try:
        n = run_samples(duration, sample_period, what)
        check_run_samples(n, what if what != "--duration" else f"--duration {duration:g}", force)
    except ValueError as exc:
        raise UsageError(str(exc)) from None
    return n


def _positive_duration(value) -> None:
    if value is not None and not (value > 0 and value != float("inf")):
        raise UsageError(f"--duration must be a finite number of seconds > 0, got {value}")


def _work_config(bench: Bench, overrides: list[str], force: bool, tuned: bool = True):
    config = _config(bench, overrides, tuned)
    try:
        check_horizons(config, force)
    except ValueError as exc:
        raise UsageError(str(exc)) from None
    return config


def _sets(overrides: list[str], key: str) -> bool:
    """Whether one of the ``--set KEY=VALUE`` assignments is ``key``'s."""
    return any(item.split("=", 1)[0].strip() == key for item in overrides or ())


def _check_codegen_settings(bench: Bench, config) -> None:
    from hystmpc.experiments.realtime import check_codegen_settings
    try:
        check_codegen_settings(bench, config)
    except ValueError as exc:
        raise UsageError(str(exc)) from None


def _codegen(args) -> int:
    from hystmpc.experiments.realtime import codegen
    bench = _bench(args.bench)
    if args.solver not in CODEGEN_SOLVERS:
        raise UsageError(f"--solver {args.solver!r} cannot be code-generated yet; "
                         f"allowed: {', '.join(CODEGEN_SOLVERS)}")
    _positive_duration(args.duration)
    if args.duration is not None and not args.verify:
        raise UsageError(f"--duration {args.duration:g} sets the length of the --verify run; add --verify, or drop "
                         "--duration")
    if args.target not in (None, *CODEGEN_TARGETS):
        raise UsageError(f"--target {args.target!r} is unknown; allowed: {', '.join(CODEGEN_TARGETS)}")
    config = _work_config(bench, args.overrides, args.force, tuned=False)  # the NMPC alone
    _check_codegen_settings(bench, config)
    if args.target is not None and not _sets(args.overrides, "solver.rti.sensitivity_block"):
        from hystmpc.experiments.firmware import firmware_config
        try:
            config = firmware_config(bench, config)  # RAM before speed
        except ValueError as exc:
            raise UsageError(str(exc)) from None
    if args.duration is not None:
        _samples(args.duration, bench.sample_period, "--duration", args.force)
    out = Path(args.out) if args.out else Path("codegen") / bench.name
    json_target = _json_target(args.json_file)
    created = _output_folder(out)  # a build folder: its files are replaced
    with _cleanup_on_error(out, created):
        try:
            report = codegen(bench, config, out, args.verify, args.duration, args.target)
        except ValueError as exc:
            raise UsageError(str(exc)) from None
    _write_json_target(report, json_target)
    if not args.quiet and json_target != "-":
        print(f"C solver written and built in {out}: {', '.join(report['files'])}")
        ctrl = report["controller"]
        if "skipped" in ctrl:
            print(f"whole controller not generated: {ctrl['skipped']}")
        else:
            print(f"whole controller (estimator, warm start, solver, fallback) in {ctrl['folder']}: {ctrl['name']}.h "
                  f"documents the interface; example loop {ctrl['name']}_main")
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


def _speed(args) -> int:
    from hystmpc.experiments.realtime import speed, speed_table
    from hystmpc.experiments.report import version
    bench = _bench(args.bench)
    _positive_duration(args.duration)
    config = _work_config(bench, args.overrides, args.force, tuned=False)  # the NMPC alone
    _check_codegen_settings(bench, config)
    if args.variants:
        variants = args.variants.split(",")
        _check_names("solver variant", variants, SOLVERS)
    else:
        own = config["nmpc"].solver if "nmpc" in config else "ipopt"
        variants = list(dict.fromkeys([own, "ipopt", "sqp", "rti", "rti-c"]))
    scenario = bench.scenario(bench.default_scenario) if bench.default_scenario else None
    if scenario is not None:
        _samples(args.duration or scenario.duration, bench.sample_period, "--duration", args.force)
    out = Path(args.out) if args.out else _timestamped(Path("results") / bench.name, "speed-")
    created = _output_folder(out, overwrite=args.overwrite)
    with _cleanup_on_error(out, created):
        try:
            with _solver_log(out / "solver.log"):
                result = speed(bench, config, variants, args.duration, out / "codegen")
        except ValueError as exc:
            raise UsageError(str(exc)) from None
    result.update({"schema": "hystmpc.speed/1", "version": version(), "overrides": list(args.overrides)})
    (out / "speed.json").write_text(json.dumps(result, indent=1) + "\n")
    table = speed_table(result)
    (out / "speed.md").write_text(table + "\n")
    _report_solver_log(out / "solver.log", args.quiet)
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
    if args.retry_failed and not args.resume:
        raise UsageError("--retry-failed redoes the failed runs of a sweep: use it with --resume and --out DIR")
    json_target = _json_target(args.json_file)
    try:
        spec = load_spec(args.spec, args.overrides, args.duration, force=args.force)
        out = Path(args.out) if args.out else _timestamped(Path("results") / _bench(spec.bench).name, "sweep-")
        outcome = run_sweep(spec, out, workers=args.workers, executor=args.executor, scheduler=args.scheduler,
                            resume=args.resume, plots=not args.no_plots, quiet=args.quiet,
                            spec_text=Path(args.spec).read_text(), retry_failed=args.retry_failed)
    except SpecError as exc:
        raise UsageError(str(exc)) from None
    _write_json_target(outcome.summary, json_target)
    _report_solver_log(out / "solver.log", args.quiet)
    summary = outcome.summary
    if not args.quiet and json_target != "-":
        print(summary_table(summary, _bench(spec.bench).units))
        print(f"\n{outcome.ran} runs done in {outcome.wall_s:.1f} s ({outcome.skipped} already recorded), "
              f"{summary['runs_failed']} failed in all; results: {out / 'summary.json'}")
        if outcome.figures:
            print("figures: " + ", ".join(str(f) for f in outcome.figures))
    if summary["runs_recorded"] and summary["runs_failed"] == summary["runs_recorded"]:
        print(f"hystmpc: error: every run of the sweep failed ({summary['runs_failed']}); the causes are in "
              f"{out / 'records'}", file=sys.stderr)
        return 1
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


def _config(bench: Bench, overrides: list[str], tuned: bool = True):
    try:
        return bench.configure(overrides, tuned)
    except ValueError as exc:
        raise UsageError(str(exc)) from None


def _scenario(bench: Bench, name: str | None, reference: str | None):
    """Scenario ``name``, or the ``reference`` file's trajectory (under the conditions of
    scenario ``name``, if one is named)."""
    if reference is None:
        return bench.scenarios[name]
    try:
        loaded = load_reference(reference, bench)
    except ValueError as exc:
        raise UsageError(str(exc)) from None
    if name is None:
        return loaded
    named = bench.scenarios[name]
    return dataclasses.replace(loaded, description=f"{loaded.description}, conditions of {name}",
                               conditions=named.conditions)


def _execute(args, bench: Bench, scenario_names: list[str], controllers: list[str]) -> int:
    _positive_duration(args.duration)
    _seed(args.seed)
    if args.reference is not None and len(scenario_names) > 1:
        raise UsageError("--reference replaces one scenario's reference: name one scenario at most")
    # checked before the baselines are tuned (an actuator file's first run tunes them for seconds to minutes)
    config = _work_config(bench, args.overrides, args.force, tuned=False)
    if "nmpc" in controllers and "nmpc" in config:
        from hystmpc.experiments.firmware import check_runtime
        try:
            config["nmpc"].check_combination(config.get("solver"))  # before any baseline runs
            check_runtime(config)
        except ValueError as exc:
            raise UsageError(str(exc)) from None
    if args.reference is not None and not scenario_names:
        scenarios = [_scenario(bench, None, args.reference)]
    else:
        scenarios = [_scenario(bench, s, args.reference) for s in scenario_names]
    user_keys = {o.split("=", 1)[0].strip() for o in args.overrides}
    for scenario in scenarios:
        for condition in scenario.conditions:
            key = condition.split("=", 1)[0]
            if key in user_keys and args.reference is not None:
                raise UsageError(f"--set {key} conflicts with scenario {scenario_names[0]!r}, whose condition "
                                 f"{condition} the reference file runs under; drop the scenario name to run the file "
                                 "under other conditions")
            if key in user_keys:
                raise UsageError(f"--set {key} conflicts with scenario {scenario.name!r}, which fixes "
                                 f"{condition}; use --reference for other conditions")
        if args.reference is not None and args.duration is not None and \
                args.duration > scenario.duration + 0.5 * bench.sample_period:
            raise UsageError(f"--duration {args.duration:g} s is longer than the reference file {args.reference!r} "
                             f"({scenario.duration:g} s); allowed: up to {scenario.duration:g} s")
    total = sum(_samples(args.duration or s.duration, bench.sample_period,
                         "--duration" if args.duration else f"scenario {s.name}", args.force)
                for s in scenarios) * len(controllers)
    json_target = _json_target(args.json_file)
    out = Path(args.out) if args.out else _timestamped(Path("results") / bench.name)
    created = _output_folder(out, overwrite=args.overwrite)
    with _cleanup_on_error(out, created):
        own_plant = _own_plant(args, bench, config)  # last of the checks: it may open hardware
        if any(c != "nmpc" for c in controllers):
            config = _config(bench, args.overrides)
        runs = _run_all(args, bench, config, scenarios, controllers, out, total, own_plant)
    doc = results_document(bench.name, runs, command=sys.argv[1:] if sys.argv else None)
    write_json(doc, out / "results.json")
    _write_json_target(doc, json_target)
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
    _report_solver_log(out / "solver.log", args.quiet)
    clipped = [r for r in runs if r.guard and r.guard["clips"]]
    if clipped:  # a warning: shown even with --quiet
        lo, hi = bench.input_bounds
        logging.getLogger("hystmpc").warning(
            f"the plant guard clipped {sum(r.guard['clips'] for r in clipped)} inputs of "
            f"{', '.join(sorted({r.controller for r in clipped}))} to the bench's input range [{lo:g}, {hi:g}] "
            f"{bench.input_units}" + (f" and rate {bench.input_rate:g} per sample" if bench.input_rate < float("inf")
                                      else "") + " (guard clips in the table)")
    for r in runs:  # warnings: shown even with --quiet
        if r.solver and not r.timing["real_time"]:
            logging.getLogger("hystmpc").warning(f"not real time on this machine: {r.real_time_verdict()}")
    oscillating = [f"{r.scenario} · {r.controller} ({r.metrics['oscillation_cycles']:g} cycles at "
                   f"{r.metrics['oscillation_hz']:.2g} Hz)" for r in runs if r.metrics.get("oscillating")]
    if oscillating:
        logging.getLogger("hystmpc").warning("the output oscillates while the reference keeps its direction: "
                                             + ", ".join(oscillating))
    if not args.quiet and json_target != "-":
        print(table)
        if own_plant is not None:
            print(f"\nplant: {runs[0].parameters['plant']['own_plant']} (--plant {args.plant}); the controllers "
                  "are the bench's, tuned as for compare")
        print(f"\nresults: {out / 'results.json'}" + (f" and {args.json_file}" if args.json_file else ""))
        if figures:
            print("figures: " + ", ".join(str(f) for f in figures))
        if bench.source.endswith(".toml"):
            tuned = [f"{g}: kp {config[g].kp:.4g}, ki {config[g].ki:.4g}, kd {config[g].kd:.4g}"
                     + (f", preview {config[g].preview}" if hasattr(config[g], "preview") else "")
                     for g in ("pid", "inverse_ff_pid") if any(c.replace("-", "_") == g for c in controllers)]
            if "inverse-lmpc" in controllers and "lmpc" in config:
                tuned.append(f"inverse-lmpc: r_rate {config['lmpc'].r_rate:.4g}")
            if tuned:
                print("baseline gains (tuned on the tuning ensemble unless set): " + "; ".join(tuned))
        nmpc_runs = [r for r in runs if r.solver]
        for r in nmpc_runs:
            print("real time: " + r.real_time_verdict())
        if nmpc_runs and any(r.solver["failures"] for r in nmpc_runs):
            print("note: some NMPC solves failed; the fallback input was applied (see solver.failures)")
    blind = [f"{r.scenario} · {r.controller} ({int(np.sum(~np.isfinite(r.output)))} samples)"
             for r in runs if not np.all(np.isfinite(r.output))]
    if blind:  # a plant (a rig, most likely) that measured nothing: the runs are written, the command failed
        print(f"hystmpc: error: the plant's measurement was not a finite number in {', '.join(blind)}; those "
              f"runs have no RMSE (results: {out / 'results.json'})", file=sys.stderr)
        return 1
    return 0


def _own_plant(args, bench: Bench, config):
    """The plant ``--plant`` names, checked against the bench (exit 2 otherwise); None without it."""
    if args.plant is None:
        return None
    plant_only = bench.plant_only_groups()
    ignored = [o.split("=", 1)[0].strip() for o in args.overrides if o.split(".", 1)[0].strip() in plant_only]
    if ignored:
        raise UsageError(f"--set {ignored[0]} sets the bench's simulated plant, which --plant replaces; drop it "
                         "(your plant takes its own settings)")
    from hystmpc.experiments.own_plant import check_plant, load_plant
    try:
        plant = load_plant(args.plant)
        check_plant(plant, bench.sample_period, bench.sensors(config), who=f"--plant {args.plant}")
    except ValueError as exc:
        raise UsageError(str(exc)) from None
    return plant


@contextlib.contextmanager
def _naming_own_plant(plant, spec: str | None, scenario, controller: str):
    """An error inside a run on ``--plant``'s plant names the plant and the run (one line, exit 1)."""
    if plant is None:
        yield
        return
    try:
        yield
    except Exception as exc:  # noqa: BLE001 - the user's rig code: any failure, named
        raise RuntimeError(f"during {scenario.name} · {controller} on --plant {spec}: {type(exc).__name__}: "
                           f"{exc}") from exc


def _run_all(args, bench: Bench, config, scenarios, controllers, out: Path, total: int,
             own_plant=None) -> list[RunResult]:
    runs: list[RunResult] = []
    from tqdm import tqdm
    with tqdm(total=total, unit="step", disable=True if args.quiet else None, leave=False,
              dynamic_ncols=True) as bar:
        for scenario in scenarios:
            for controller in controllers:
                bar.set_description(f"{scenario.name} · {controller}")
                try:
                    prepared = bench.prepare(scenario, controller, config, own_plant)
                except ValueError as exc:  # a setting the controller or plant cannot take
                    raise UsageError(str(exc)) from None
                with _solver_log(out / "solver.log"), _naming_own_plant(own_plant, args.plant, scenario, controller):
                    run = bench.run(scenario, controller, seed=args.seed, duration=args.duration,
                                    progress=bar.update, prepared=prepared)
                runs.append(run)
                write_run_csv(run, out)
    return runs


TUNED_GROUPS = ("pid", "inverse_ff_pid", "lmpc")
"""An actuator file's groups that its first run tunes (``list`` shows them untuned)."""


def _list(args) -> int:
    from hystmpc.experiments.config import key_table
    info, solvers = {}, SOLVERS
    for name in [args.bench] if args.bench else all_bench_names():
        bench = _bench(name)
        if args.bench and MULTIPLE_SHOOTING.keys() <= bench.fixed.keys():  # gn: single-shooting NMPCs only
            solvers = tuple(s for s in SOLVERS if s != "gn")
        info[bench.name if args.bench else name] = {
            "description": bench.description, "paper": bench.paper, "units": bench.units,
            "input_units": bench.input_units, "sample_period_s": bench.sample_period,
            "input_bounds": list(bench.input_bounds), "scenarios": list(bench.scenarios),
            "controllers": list(bench.controllers), "parameter_groups": list(bench.configure(tuned=False))} | (
            {"source": bench.source} if bench.source else {})
        if args.bench:  # untuned: listing never waits for an actuator file's tuning
            info[bench.name]["keys"] = [{"key": k, "default": v, "doc": d}
                                        for k, v, d in key_table(bench.configure(tuned=False))]
            if bench.untuned_defaults is not None:
                info[bench.name]["tuned_at_first_run"] = TUNED_GROUPS
    if args.json:
        from hystmpc.experiments.report import json_safe
        print(json.dumps(json_safe({"benches": info, "solvers": list(solvers), "families": list(FAMILY_NAMES)}),
                         indent=2, default=str))
        return 0
    for name, b in info.items():
        lo, hi = b["input_bounds"]
        print(f"{name}: {b['description']} [{b['units']}, {1 / b['sample_period_s']:g} Hz, input "
              f"{lo:g}..{hi:g} {b['input_units']}]" + (f" ({b['source']})" if "source" in b else ""))
        print(f"  scenarios:   {', '.join(b['scenarios'])}")
        print(f"  controllers: {', '.join(b['controllers'])}")
        if "keys" not in b:
            print(f"  --set groups: {', '.join(b['parameter_groups'])}")
            continue
        print("  --set keys (default, long ones cut: --json has them whole; meaning and units):")
        width = max(len(k["key"]) for k in b["keys"])
        for k in b["keys"]:
            print(f"    {k['key']:<{width}}  {_show(k['default'])}" + (f"  — {k['doc']}" if k["doc"] else ""))
        if "tuned_at_first_run" in b:
            print(f"  {', '.join(g + '.*' for g in b['tuned_at_first_run'])}: the values before tuning; the first "
                  "run or compare tunes the baselines on the nominal model (what you --set stays)")
    print(f"solvers (--set nmpc.solver=...): {', '.join(solvers)}")
    print(f"model families (hystmpc identify FAMILY DATA.csv): {', '.join(FAMILY_NAMES)}")
    if not args.bench:
        print("'hystmpc list BENCH' shows every --set key of a bench with its default and units")
    return 0


def _show(value) -> str:
    """A default as ``--set`` takes it (tuples comma-separated)."""
    if isinstance(value, tuple):
        flat = [v for item in value for v in (item if isinstance(item, tuple) else (item,))]
        text = ",".join(f"{v:g}" if isinstance(v, float) else str(v) for v in flat)
        return text if len(text) <= 60 else text[:57] + "..."
    if isinstance(value, float):
        return f"{value:g}"
    return str(value)


class _NoticeHandler(logging.StreamHandler):
    """Writes to the standard error of the last ``main()`` call (not to a run's solver.log);
    once that stream is closed (a caller that captured it is gone), to the current one."""

    def emit(self, record):
        if getattr(self.stream, "closed", False):
            self.stream = sys.stderr
        super().emit(record)


def _log_notices(show: bool) -> None:
    """Notices of long steps (tuning, ...) on stderr as ``hystmpc: ...`` lines, unless ``--quiet``."""
    log = logging.getLogger("hystmpc")
    for handler in log.handlers:
        if getattr(handler, "hystmpc", False):
            handler.stream = sys.stderr  # whatever it is now (setStream would flush the old one: maybe closed)
    if not any(getattr(h, "hystmpc", False) for h in log.handlers):
        handler = _NoticeHandler()
        handler.hystmpc = True
        handler.setFormatter(logging.Formatter("hystmpc: %(message)s"))
        log.addHandler(handler)
        log.propagate = False
    log.setLevel(logging.INFO if show else logging.WARNING)


def _parse(argv: list[str]) -> argparse.Namespace:
    """The command line, with scenario names also accepted after options
    (``compare pam --no-plots sine-30``)."""
    parser = build_parser()
    if not argv:
        raise UsageError(f"name a command: {', '.join(parser.commands)} ('hystmpc COMMAND --help' describes each)")
    args, extra = parser.parse_known_args(argv)
    names = [e for e in extra if not e.startswith("-")]
    if extra and len(names) == len(extra) and args.command == "compare":
        args.scenarios = [*args.scenarios, *names]
    elif extra and len(names) == len(extra) == 1 and args.command == "run" and args.scenario is None:
        args.scenario = names[0]
    elif extra and len(names) == len(extra) == 1 and args.command == "identify" and args.data is None:
        args.data = names[0]
    elif extra:
        options = [e for e in extra if e.startswith("-")]
        raise UsageError(f"unrecognized arguments: {' '.join(options or extra)}")
    return args


def _one_blas_thread() -> None:
    """BLAS on one thread, unless the user chose otherwise: every matrix here is small, and
    on a loaded machine BLAS threads wait for each other (``identify`` on the piezo example
    with two busy cores took 12.6 s, on one thread 4.6 s). Sweep workers inherit the setting."""
    if "OPENBLAS_NUM_THREADS" in os.environ or "MKL_NUM_THREADS" in os.environ:
        return
    os.environ["OPENBLAS_NUM_THREADS"] = os.environ["MKL_NUM_THREADS"] = "1"
    from threadpoolctl import threadpool_limits
    threadpool_limits(1, user_api="blas")


def main(argv: list[str] | None = None) -> int:
    """Entry point; returns the exit code."""
    _one_blas_thread()
    try:
        args = _parse(sys.argv[1:] if argv is None else argv)
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
        if args.controllers is not None and not [c for c in args.controllers.split(",") if c.strip()]:
            raise UsageError("--controllers is empty; allowed: a comma-separated list of "
                             f"{', '.join(bench.controllers)} (or leave the option out for all of them)")
        controllers = args.controllers.split(",") if args.controllers else list(bench.controllers)
        _check_names("controller", controllers, bench.controllers)
        return _execute(args, bench, scenarios, controllers)
    except UsageError as exc:
        print(f"hystmpc: error: {exc}", file=sys.stderr)
        return 2
    except KeyboardInterrupt:
        print("hystmpc: interrupted", file=sys.stderr)
        return 130
    except BrokenPipeError:  # the reader went away (``hystmpc list pam | head``): stop quietly
        os.dup2(os.open(os.devnull, os.O_WRONLY), sys.stdout.fileno())
        return 141
    except Exception as exc:  # noqa: BLE001 - anything unexpected: one line, exit 1
        if os.environ.get("HYSTMPC_DEBUG"):
            raise
        print(f"hystmpc: error: {type(exc).__name__}: {exc} (set HYSTMPC_DEBUG=1 for a traceback)",
              file=sys.stderr)
        return 1


def entry_point() -> None:
    """Console-script wrapper."""
    sys.exit(main())
