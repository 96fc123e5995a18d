"""``hystmpc run`` and ``hystmpc compare``: closed loops on a bench's plant or on your own.

``hystmpc run`` runs one controller on one scenario, ``hystmpc compare`` every controller on
every scenario: closed loops on the bench's simulated plant or on your own (``--plant``), with
the result document, per-run CSVs, the table and the figures.
"""

from __future__ import annotations

import argparse
import contextlib
import logging
import sys
from pathlib import Path

import numpy as np

from hystmpc.experiments.bench import Bench
from hystmpc.experiments.benches import DEFAULT_BENCH
from hystmpc.experiments.cli.common import (
    BENCH_HELP,
    FORCE_HELP,
    JSON_HELP,
    UsageError,
    bench_named,
    check_duration,
    check_names,
    check_seed,
    checked_json_target,
    checked_samples,
    cleanup_on_error,
    configured,
    output_folder,
    report_solver_log,
    scenario_to_run,
    solver_log,
    timestamped,
    work_config,
    write_json_target,
)
from hystmpc.experiments.limits import run_samples
from hystmpc.experiments.report import comparison_table, results_document, write_json, write_run_csv
from hystmpc.experiments.runner import RunResult


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


def add_parsers(sub) -> None:
    """Register ``run`` and ``compare`` on the subcommand parsers ``sub``.

    Parameters
    ----------
    sub : argparse._SubParsersAction
        What ``add_subparsers`` returned for ``hystmpc``.
    """
    p_run = sub.add_parser("run", help="one closed-loop run")
    p_run.add_argument("bench", help=BENCH_HELP)
    p_run.add_argument("scenario", nargs="?", help="one of the bench's scenarios (optional with --reference)")
    p_run.add_argument("--controller", required=True, help="one of the bench's controllers ('hystmpc list BENCH')")
    _add_run_options(p_run)
    p_run.set_defaults(handler=run_command)
    p_cmp = sub.add_parser("compare", help="every controller on every scenario, table and figures")
    p_cmp.add_argument("bench", nargs="?", default=DEFAULT_BENCH, help=BENCH_HELP)
    p_cmp.add_argument("scenarios", nargs="*", help="default: all of the bench's scenarios")
    p_cmp.add_argument("--controllers", help="comma-separated (default: all of the bench's)")
    p_cmp.add_argument("--workers", type=int, help="processes running the runs at once (default: one per core, "
                       "fewer for short work; 1 with --plant)")
    _add_run_options(p_cmp)
    p_cmp.set_defaults(handler=compare_command)


def run_command(args) -> int:
    """Run ``run``; returns the exit code.

    Parameters
    ----------
    args : argparse.Namespace
        The parsed command line.

    Returns
    -------
    int
        0, or 1 when the plant's measurement was not finite in the run (its result is written);
        bad usage or input raises ``UsageError`` (exit 2).
    """
    bench = bench_named(args.bench)
    if args.scenario is None and args.reference is None:
        raise UsageError(f"name a scenario ({', '.join(bench.scenarios)}) or give --reference FILE.csv")
    scenario = [] if args.scenario is None else [args.scenario]
    check_names("scenario", scenario, bench.scenarios)
    check_names("controller", [args.controller], bench.controllers)
    return _execute(args, bench, scenario, [args.controller])


def compare_command(args) -> int:
    """Run ``compare``; returns the exit code.

    Parameters
    ----------
    args : argparse.Namespace
        The parsed command line.

    Returns
    -------
    int
        0, or 1 when the plant's measurement was not finite in some run (the results are written);
        bad usage or input raises ``UsageError`` (exit 2).
    """
    bench = bench_named(args.bench)
    scenarios = args.scenarios or ([] if args.reference else list(bench.scenarios))
    check_names("scenario", scenarios, bench.scenarios)
    if args.controllers is not None and not [c for c in args.controllers.split(",") if c.strip()]:
        raise UsageError("--controllers is empty; allowed: a comma-separated list of "
                         f"{', '.join(bench.controllers)} (or leave the option out for all of them)")
    controllers = args.controllers.split(",") if args.controllers else list(bench.controllers)
    check_names("controller", controllers, bench.controllers)
    return _execute(args, bench, scenarios, controllers)


def _execute(args, bench: Bench, scenario_names: list[str], controllers: list[str]) -> int:
    check_duration(args.duration)
    check_seed(args.seed)
    workers = getattr(args, "workers", None)
    if workers is not None and workers < 1:
        raise UsageError(f"--workers must be >= 1, got {workers}")
    if workers is not None and workers > 1 and args.plant is not None:
        raise UsageError(f"--workers {workers} runs copies of the bench's plant at once; --plant's plant is "
                         "one (a rig, your simulator): drop --workers")
    if args.reference is not None and len(scenario_names) > 1:
        raise UsageError("--reference replaces one scenario's reference: name one scenario at most")
    # checked before the baselines are tuned (an actuator file's first run tunes them for seconds to minutes)
    config = work_config(bench, args.overrides, args.force, tuned=False)
    try:
        bench.validate(config, controllers)  # before any baseline runs
    except ValueError as exc:
        raise UsageError(str(exc)) from None
    if args.reference is not None and not scenario_names:
        scenarios = [scenario_to_run(bench, None, args.reference)]
    else:
        scenarios = [scenario_to_run(bench, s, args.reference) for s in scenario_names]
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
    total = sum(checked_samples(args.duration or s.duration, bench.sample_period,
                         "--duration" if args.duration else f"scenario {s.name}", args.force)
                for s in scenarios) * len(controllers)
    json_target = checked_json_target(args.json_file)
    out = Path(args.out) if args.out else timestamped(Path("results") / bench.name)
    created = output_folder(out, overwrite=args.overwrite)
    with cleanup_on_error(out, created):
        own_plant = _own_plant(args, bench, config)  # last of the checks: it may open hardware
        if any(c != "nmpc" for c in controllers) or bench.untuned_defaults is not None:
            config = configured(bench, args.overrides)  # an actuator file's NMPC has a tuned walk too
        runs = _run_all(args, bench, config, scenarios, controllers, out, total, own_plant, scenario_names)
    doc = results_document(bench.name, runs, command=sys.argv[1:] if sys.argv else None)
    write_json(doc, out / "results.json")
    write_json_target(doc, json_target)
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
    report_solver_log(out / "solver.log", args.quiet)
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
    late = [r for r in runs if r.controller == "nmpc" and r.solver and r.timing["p95_share_of_period"] > 1]
    if late and "nmpc" in config:
        logging.getLogger("hystmpc").warning(_shorter_step_hint(config["nmpc"], args.bench, late))
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
                tuned.append(f"inverse-lmpc: r_rate {config['lmpc'].r_rate:.4g}, disturbance walk "
                             f"{config['lmpc_estimator'].disturbance:.3g}")
            if "nmpc" in controllers and "estimator" in config:
                tuned.append(f"nmpc: disturbance walk {config['estimator'].disturbance:.3g}")
            if tuned:
                print("gains and walks (tuned on the tuning ensemble unless set): " + "; ".join(tuned))
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


def _shorter_step_hint(nmpc, bench_name: str, late: list) -> str:
    """What shortens the NMPC's step, for runs whose p95 step exceeds the period."""
    levers = [f"a shorter nmpc.horizon (now {nmpc.horizon})"]
    if nmpc.solver not in ("rti", "rti-c"):
        levers.insert(0, f"nmpc.solver=rti-c (now {nmpc.solver})")
    if nmpc.multistart:
        levers.append(f"a larger nmpc.second_start_error (now {nmpc.second_start_error:.4g}: the second start on "
                      "fewer samples)")
        levers.append("nmpc.multistart=false (one start per sample)")
    worst = max(r.timing["p95_share_of_period"] for r in late)
    return (f"nmpc: its p95 step is up to {worst:.0%} of the period; {', or '.join(levers)} shortens it "
            f"('hystmpc speed {bench_name}' with the same --set options times it alone)")


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
             own_plant=None, scenario_names=()) -> list[RunResult]:
    from tqdm import tqdm

    from hystmpc.experiments.cli.workers import CompareRun, default_workers, run_in_parallel
    workers = getattr(args, "workers", None)
    if workers is None:
        workers = 1 if own_plant is not None else default_workers(total, len(scenarios) * len(controllers))
    runs: list[RunResult] = []
    with tqdm(total=total, unit="step", disable=True if args.quiet else None, leave=False,
              dynamic_ncols=True) as bar:
        if workers > 1:
            bar.set_description(f"{len(scenarios) * len(controllers)} runs on {workers} processes")
            level = logging.getLogger("hystmpc").getEffectiveLevel()
            tasks = [CompareRun(args.bench, tuple(args.overrides), any(c != "nmpc" for c in controllers), name,
                                args.reference, controller, args.seed, args.duration, level)
                     for name in (scenario_names or [None]) for controller in controllers]

            def done(run: RunResult, printed: str) -> None:
                if printed:
                    with open(out / "solver.log", "a") as log:
                        log.write(printed)
                write_run_csv(run, out)
                bar.update(len(run.t))
            # Longest first: the scenarios with the most samples, and on each the controllers listed
            # last (a bench lists its baselines first and the NMPC last) before those listed first
            samples = [run_samples(args.duration or s.duration, bench.sample_period, s.name) for s in scenarios]
            first = sorted(range(len(tasks)), key=lambda i: (-samples[i // len(controllers)], -(i % len(controllers))))
            return run_in_parallel(tasks, workers, done, first)
        for scenario in scenarios:
            for controller in controllers:
                bar.set_description(f"{scenario.name} · {controller}")
                try:
                    prepared = bench.prepare(scenario, controller, config, own_plant)
                except ValueError as exc:  # a setting the controller or plant cannot take
                    raise UsageError(str(exc)) from None
                with solver_log(out / "solver.log"), _naming_own_plant(own_plant, args.plant, scenario, controller):
                    run = bench.run(scenario, controller, seed=args.seed, duration=args.duration,
                                    progress=bar.update, prepared=prepared)
                runs.append(run)
                write_run_csv(run, out)
    return runs
