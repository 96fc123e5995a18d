"""``hystmpc`` command line (interface.md): list, run, compare, sweep, identify, codegen, speed.

One module per command (``run`` and ``compare`` share one): each registers its parser and its
handler; :mod:`~hystmpc.experiments.cli.common` holds what they share. Exit codes: 0
success; 2 bad usage or bad input, with one line naming what is wrong and what is allowed;
1 anything else.
"""

from __future__ import annotations

import argparse
import logging
import os
import sys

from hystmpc.experiments.cli import codegen, identify, listing, run, speed, sweep
from hystmpc.experiments.cli.common import Parser, UsageError

__all__ = ["UsageError", "build_parser", "entry_point", "main"]


def build_parser() -> argparse.ArgumentParser:
    """The argument parser of ``hystmpc``.

    Returns
    -------
    argparse.ArgumentParser
        A :class:`~hystmpc.experiments.cli.common.Parser` with every command's subparser.
    """
    parser = Parser(prog="hystmpc", description="NMPC for actuators with hysteresis: benches from four papers.")
    from hystmpc.experiments.report import version
    parser.add_argument("--version", action="version", version=f"hystmpc {version()}")
    sub = parser.add_subparsers(dest="command", required=True, parser_class=Parser)
    listing.add_parser(sub)
    run.add_parsers(sub)
    sweep.add_parser(sub)
    codegen.add_parser(sub)
    speed.add_parser(sub)
    identify.add_parser(sub)
    parser.commands = tuple(sub.choices)
    return parser


class _NoticeHandler(logging.StreamHandler):
    """Writes to the standard error of the last ``main()`` call (not to a run's solver.log).

    Once that stream is closed (a caller that captured it is gone), it writes to the current one.
    """

    def emit(self, record):
        if getattr(self.stream, "closed", False):
            self.stream = sys.stderr
        from tqdm import tqdm
        with tqdm.external_write_mode(file=self.stream):  # a progress bar is cleared, then redrawn below
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
    """The command line, with scenario names also accepted after options (``compare pam --no-plots sine-30``)."""
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
    """BLAS on one thread, unless the user chose otherwise.

    Every matrix here is small, and on a loaded machine BLAS threads wait for each other
    (``identify`` runs faster on one thread there). Sweep workers inherit the setting.
    """
    if "OPENBLAS_NUM_THREADS" in os.environ or "MKL_NUM_THREADS" in os.environ:
        return
    os.environ["OPENBLAS_NUM_THREADS"] = os.environ["MKL_NUM_THREADS"] = "1"
    from threadpoolctl import threadpool_limits
    threadpool_limits(1, user_api="blas")


def main(argv: list[str] | None = None) -> int:
    """Entry point; returns the exit code.

    Parameters
    ----------
    argv : list of str, optional
        The arguments after ``hystmpc`` (default: ``sys.argv[1:]``).

    Returns
    -------
    int
        The command's own (0 on success); 2 bad usage or input, 1 any other error, 130
        interrupted, 141 the output's reader went away.
    """
    _one_blas_thread()
    try:
        args = _parse(sys.argv[1:] if argv is None else argv)
        _log_notices(not getattr(args, "quiet", False))
        return args.handler(args)
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
