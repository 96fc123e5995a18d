"""``hystmpc list``: what the benches and the package offer.

It lists benches, scenarios, controllers, every ``--set`` key of a bench, solver variants and
model families.
"""

from __future__ import annotations

import json

from hystmpc.experiments.bench import MULTIPLE_SHOOTING
from hystmpc.experiments.benches import all_bench_names
from hystmpc.experiments.cli.common import FAMILY_NAMES, bench_named
from hystmpc.mpc.settings import SOLVERS


def add_parser(sub) -> None:
    """Register ``list`` on the subcommand parsers ``sub``.

    Parameters
    ----------
    sub : argparse._SubParsersAction
        What ``add_subparsers`` returned for ``hystmpc``.
    """
    p_list = sub.add_parser("list", help="benches, scenarios, controllers, solver variants")
    p_list.add_argument("bench", nargs="?", help="only this bench (a name, plugin or actuator file)")
    p_list.add_argument("--json", action="store_true", help="machine-readable output")
    p_list.set_defaults(handler=command)


TUNED_GROUPS = ("pid", "inverse_ff_pid", "lmpc", "lmpc_estimator", "estimator")
"""An actuator file's groups that its first run tunes (``list`` shows them untuned)."""


def command(args) -> int:
    """Run ``list``; returns the exit code.

    Parameters
    ----------
    args : argparse.Namespace
        The parsed command line.

    Returns
    -------
    int
        0.
    """
    from hystmpc.experiments.config import key_table
    info, solvers = {}, SOLVERS
    for name in [args.bench] if args.bench else all_bench_names():
        bench = bench_named(name)
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
