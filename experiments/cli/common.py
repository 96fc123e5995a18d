"""What every ``hystmpc`` command shares.

The usage error (exit 2), the checks of common options, output folders and JSON targets, the
solver log.
"""

from __future__ import annotations

import argparse
import contextlib
import dataclasses
import datetime as dt
import json
import logging
import shutil
import sys
import tempfile
from pathlib import Path

from hystmpc.experiments.bench import Bench
from hystmpc.experiments.benches import BENCH_NAMES, get_bench
from hystmpc.experiments.limits import check_horizons, check_run_samples, run_samples
from hystmpc.experiments.reference import load_reference
from hystmpc.experiments.report import write_json
from hystmpc.models.identification import FAMILIES

FAMILY_NAMES = tuple(FAMILIES)
BENCH_HELP = f"one of {', '.join(BENCH_NAMES)}, a plugin bench, or an actuator file (*.toml)"


class UsageError(Exception):
    """Bad usage or bad input: exit code 2."""


class Parser(argparse.ArgumentParser):
    """An argument parser whose errors are one line and exit 2 (a :class:`UsageError`)."""

    def error(self, message):
        """Raise a :class:`UsageError` (argparse prints usage and exits otherwise).

        Parameters
        ----------
        message : str
            argparse's description of the problem.
        """
        raise UsageError(message)


FORCE_HELP = "run beyond the work limits (horizon 200, 1,000,000 samples per run; interface.md)"
JSON_HELP = "also write the {} to this file ('-': standard output, instead of the table)"


def timestamped(folder: Path, prefix: str = "") -> Path:
    """A new folder name under ``folder``: ``<prefix><UTC timestamp>``, suffixed if taken.

    Parameters
    ----------
    folder : Path
        The parent folder.
    prefix : str, optional
        Text before the timestamp.

    Returns
    -------
    Path
        A path that does not exist yet (the folder is not created).
    """
    stamp = prefix + dt.datetime.now(dt.UTC).strftime("%Y%m%dT%H%M%SZ")
    path, n = folder / stamp, 1
    while path.exists():
        n += 1
        path = folder / f"{stamp}-{n}"
    return path


def output_folder(path: Path, option: str = "--out", overwrite: bool = True) -> bool:
    """Create ``path`` (or check it) before any work; returns whether it was created.

    ``UsageError`` for a file, a folder that cannot be written, or (unless ``overwrite``)
    a folder that already holds files.

    Parameters
    ----------
    path : Path
        The output folder.
    option : str, optional
        The option that named it, for the messages.
    overwrite : bool, optional
        Accept a folder that already holds files.

    Returns
    -------
    bool
        Whether this call created the folder.
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


def checked_json_target(value: str | None) -> Path | str | None:
    """``--json``'s file, checked (its folder created) before any work; ``'-'`` is standard output.

    Parameters
    ----------
    value : str or None
        The ``--json`` value.

    Returns
    -------
    Path, str or None
        The file, ``'-'``, or None without ``--json``.
    """
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


def write_json_target(doc: dict, target: Path | str | None) -> None:
    """Write ``doc`` to ``--json``'s target: a file, standard output (``'-'``), or nowhere (None).

    Parameters
    ----------
    doc : dict
        The document (strict JSON).
    target : Path, str or None
        What :func:`checked_json_target` returned.
    """
    if target == "-":
        json.dump(doc, sys.stdout, indent=2, allow_nan=False)
        sys.stdout.write("\n")
    elif target is not None:
        write_json(doc, target)


@contextlib.contextmanager
def cleanup_on_error(folder: Path, created: bool):
    """Remove ``folder`` if the work in it fails and this command created it: nothing half-written stays.

    Parameters
    ----------
    folder : Path
        The output folder.
    created : bool
        Whether this command created it (:func:`output_folder`).

    Yields
    ------
    None
        Control to the work; its exception is raised again after the cleanup.
    """
    try:
        yield
    except BaseException:
        if created:
            shutil.rmtree(folder, ignore_errors=True)
        raise


@contextlib.contextmanager
def solver_log(path: Path):
    """Solver and CasADi warnings (written to Python's stderr) go to ``path``, not the terminal.

    Parameters
    ----------
    path : Path
        The log file, appended to.

    Yields
    ------
    None
        Control to the work, with ``sys.stderr`` redirected.
    """
    with open(path, "a") as log, contextlib.redirect_stderr(log):
        yield


def report_solver_log(path: Path, quiet: bool) -> None:
    """Say how many lines of solver warnings went to ``path``; remove it when empty.

    Parameters
    ----------
    path : Path
        The log file (nothing happens if it does not exist).
    quiet : bool
        Say nothing (an empty file is still removed).
    """
    if not path.exists():
        return
    with path.open() as log:
        lines = sum(1 for _ in log)
    if not lines:
        path.unlink()
    elif not quiet:
        logging.getLogger("hystmpc").info(f"{lines} lines of solver warnings written to {path}")


def check_seed(value: int) -> int:
    """``--seed``, checked (an integer >= 0).

    Parameters
    ----------
    value : int
        The ``--seed`` value.

    Returns
    -------
    int
        ``value``; a negative one raises ``UsageError``.
    """
    if value < 0:
        raise UsageError(f"--seed must be an integer >= 0, got {value}")
    return value


def checked_samples(duration: float, sample_period: float, what: str, force: bool) -> int:
    """The samples ``duration`` takes, within the work limits (``--force`` lifts them).

    Parameters
    ----------
    duration : float
        Length of the run (s).
    sample_period : float
        Sample period (s).
    what : str
        What sets the duration (``--duration`` or ``scenario NAME``), for the messages.
    force : bool
        Lift the ceiling on samples per run.

    Returns
    -------
    int
        The samples; ``UsageError`` for a bad duration or one above the limit.
    """
    try:
        n = run_samples(duration, sample_period, what)
        check_run_samples(n, what if what != "--duration" else f"--duration {duration:g}", force)
    except ValueError as exc:
        raise UsageError(str(exc)) from None
    return n


def check_duration(value) -> None:
    """``UsageError`` unless ``--duration`` is absent or a finite number of seconds > 0.

    Parameters
    ----------
    value : float or None
        The ``--duration`` value (s).
    """
    if value is not None and not (value > 0 and value != float("inf")):
        raise UsageError(f"--duration must be a finite number of seconds > 0, got {value}")


def work_config(bench: Bench, overrides: list[str], force: bool, tuned: bool = True):
    """The bench's configuration with ``--set`` applied, its horizons within the work limits.

    Parameters
    ----------
    bench : Bench
        The bench.
    overrides : list of str
        The ``--set KEY=VALUE`` assignments.
    force : bool
        Lift the ceiling on horizons.
    tuned : bool, optional
        False: the untuned defaults where the bench has them (the baselines are not tuned).

    Returns
    -------
    dict
        The parameter groups; ``UsageError`` for a bad key or value or a horizon above the limit.
    """
    config = configured(bench, overrides, tuned)
    try:
        check_horizons(config, force)
    except ValueError as exc:
        raise UsageError(str(exc)) from None
    return config


def sets_key(overrides: list[str], key: str) -> bool:
    """Whether one of the ``--set KEY=VALUE`` assignments is ``key``'s.

    Parameters
    ----------
    overrides : list of str or None
        The assignments.
    key : str
        The key, e.g. ``nmpc.horizon``.

    Returns
    -------
    bool
        Whether an assignment sets it.
    """
    return any(item.split("=", 1)[0].strip() == key for item in overrides or ())


def checked_codegen_settings(bench: Bench, config) -> None:
    """``UsageError`` for an NMPC setting that ``codegen`` and ``speed`` do not read.

    Parameters
    ----------
    bench : Bench
        The bench.
    config : dict
        Its parameter groups.
    """
    from hystmpc.experiments.realtime import check_codegen_settings
    try:
        check_codegen_settings(bench, config)
    except ValueError as exc:
        raise UsageError(str(exc)) from None


def bench_named(name: str) -> Bench:
    """The bench ``name`` (a built-in, a plugin or an actuator file), or a ``UsageError``.

    Parameters
    ----------
    name : str
        A bench name or an actuator file's path.

    Returns
    -------
    Bench
        The bench.
    """
    try:
        return get_bench(name)
    except ValueError as exc:
        raise UsageError(str(exc)) from None


def check_names(kind: str, names: list[str], allowed) -> None:
    """``UsageError`` naming the first of ``names`` that is not in ``allowed``.

    Parameters
    ----------
    kind : str
        What the names are (``scenario``, ``controller``), for the message.
    names : list of str
        The names given.
    allowed : iterable of str
        The names allowed.
    """
    for name in names:
        if name not in allowed:
            raise UsageError(f"unknown {kind} {name!r}; allowed: {', '.join(allowed)}")


def configured(bench: Bench, overrides: list[str], tuned: bool = True):
    """The bench's configuration with ``--set`` applied, or a ``UsageError`` naming the bad key.

    Parameters
    ----------
    bench : Bench
        The bench.
    overrides : list of str
        The ``--set KEY=VALUE`` assignments.
    tuned : bool, optional
        False: the untuned defaults where the bench has them (the baselines are not tuned).

    Returns
    -------
    dict
        The parameter groups.
    """
    try:
        return bench.configure(overrides, tuned)
    except ValueError as exc:
        raise UsageError(str(exc)) from None


def scenario_to_run(bench: Bench, name: str | None, reference: str | None):
    """Scenario ``name``, or the ``reference`` file's trajectory.

    The trajectory runs under the conditions of scenario ``name``, if one is named.

    Parameters
    ----------
    bench : Bench
        The bench.
    name : str or None
        One of its scenarios (checked before), or None with ``reference``.
    reference : str or None
        A reference CSV (``--reference``), or None.

    Returns
    -------
    Scenario
        The scenario to run; ``UsageError`` for a reference file that cannot be read.
    """
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
