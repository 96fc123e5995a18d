"""``compare``'s runs on several processes: each (scenario, controller) run is independent.

A run is seeded and builds its own plant and controller, so it gives the same result on any
process; the runs come back in the command's order. Each worker rebuilds the bench from the
name or file the command was given and applies the same ``--set`` assignments (an actuator
file's tuned gains come from the tuning cache the command filled before). What a worker logs
(notices, warnings) is handed to the command's logger; what the solvers print goes to ``solver.log``.
"""

from __future__ import annotations

import contextlib
import io
import logging
import multiprocessing
import os
import sys
from concurrent.futures import ProcessPoolExecutor
from dataclasses import dataclass

from hystmpc.experiments.runner import RunResult

MIN_SAMPLES_PER_WORKER = 5_000
"""Short work stays on one process: starting another takes 2–3 s (importing CasADi and
hystmpc, building the bench), what a few thousand samples of most controllers take."""


@dataclass(frozen=True)
class CompareRun:
    """One run of ``compare``, in terms a fresh process can rebuild."""

    bench: str
    """The bench's name or actuator file, as given on the command line."""
    overrides: tuple[str, ...]
    tuned: bool
    """Whether the configuration has the tuned baselines (as the command's has)."""
    scenario: str | None
    reference: str | None
    controller: str
    seed: int
    duration: float | None
    log_level: int = logging.WARNING
    """The command's logger level (``--quiet``: warnings only; else notices too)."""


def default_workers(samples: int, runs: int) -> int:
    """The number of processes ``compare`` uses unless told.

    One per core, one per run at most, and one per :data:`MIN_SAMPLES_PER_WORKER` samples of work.

    Parameters
    ----------
    samples : int
        Samples of every run together.
    runs : int
        Number of runs.

    Returns
    -------
    int
        At least 1.
    """
    return max(1, min(usable_cores(), runs, samples // MIN_SAMPLES_PER_WORKER))


def usable_cores() -> int:
    """Cores this process may run on (its affinity, which a container's CPU limit sets), else all.

    Returns
    -------
    int
        At least 1.
    """
    try:
        return max(1, len(os.sched_getaffinity(0)))
    except AttributeError:  # no affinity on this platform (macOS, Windows)
        return os.cpu_count() or 1


def _run_task(task: CompareRun) -> tuple[RunResult, str, list[logging.LogRecord]]:
    """Run ``task`` in this process: the result, what the solvers printed, the warnings logged."""
    from hystmpc.experiments.cli.common import UsageError, bench_named, configured, scenario_to_run

    records: list[logging.LogRecord] = []

    class Keep(logging.Handler):
        def emit(self, record: logging.LogRecord) -> None:
            if getattr(record, "live", False):  # news during the run (a slow run's estimate): now, not after it
                print(f"hystmpc: {record.getMessage()}", file=sys.__stderr__, flush=True)
            else:
                records.append(record)

    logger = logging.getLogger("hystmpc")
    logger.handlers[:] = [Keep()]
    logger.propagate = False
    logger.setLevel(task.log_level)
    printed = io.StringIO()
    bench = bench_named(task.bench)
    config = configured(bench, list(task.overrides), task.tuned)
    scenario = scenario_to_run(bench, task.scenario, task.reference)
    try:
        prepared = bench.prepare(scenario, task.controller, config)
    except ValueError as exc:  # a setting the controller or plant cannot take (as without workers)
        raise UsageError(str(exc)) from None
    with contextlib.redirect_stderr(printed):  # as solver_log does on one process
        run = bench.run(scenario, task.controller, seed=task.seed, duration=task.duration, prepared=prepared)
    for record in records:  # a record's arguments may not pickle: keep the text only
        record.msg, record.args, record.exc_info = record.getMessage(), None, None
    return run, printed.getvalue(), records


def run_in_parallel(tasks: list[CompareRun], workers: int, on_done, first=None) -> list[RunResult]:
    """Run ``tasks`` on ``workers`` processes; results in the order of ``tasks``.

    Parameters
    ----------
    tasks : list of CompareRun
        The runs.
    workers : int
        Processes (spawned: CasADi and BLAS threads are not safe in a forked child).
    first : list of int, optional
        The order in which the runs start (indices into ``tasks``; default: theirs). Starting
        the longest first keeps a process from finishing a long run alone at the end.
    on_done : callable
        Called as ``on_done(run, printed)`` in the order of ``tasks``, as each result arrives in
        that order; ``printed`` is what the solvers wrote.

    Returns
    -------
    list of RunResult
        The runs' results.
    """
    logger = logging.getLogger("hystmpc")
    results = []
    pool = ProcessPoolExecutor(max_workers=workers, mp_context=multiprocessing.get_context("spawn"))
    try:
        futures: list = [None] * len(tasks)
        for i in (range(len(tasks)) if first is None else first):
            futures[i] = pool.submit(_run_task, tasks[i])
        for future in futures:
            run, printed, records = future.result()
            for record in records:
                logger.handle(record)
            on_done(run, printed)
            results.append(run)
    except BaseException:  # a failed run or Ctrl-C: no new run starts (the running ones end with the command)
        pool.shutdown(wait=False, cancel_futures=True)
        raise
    pool.shutdown()
    return results
