"""Where an NMPC runs and where its inverse-model inputs come from, as its settings ask.

:func:`assemble_nmpc` turns one way of building the Python controller into the controller
the settings ask for:

* ``nmpc.runtime``: ``python``; ``c``, the whole generated controller
  (:mod:`hystmpc.mpc.codegen`), written, built once per distinct source into the cache and
  driven through ``ctypes``; ``auto``, ``c`` where it can run, else ``python`` after a
  one-line notice;
* ``nmpc.inverse_plan``: ``static`` (the inverse models at rest), or ``linear-mpc``, the plan
  of a linear MPC that the caller builds (a bench's ``inverse-lmpc``; generated with the
  controller, :mod:`hystmpc.mpc.embedded_planner`).

:func:`validate_nmpc` is the check of these settings that runs before any work.
"""

from __future__ import annotations

import tempfile
from collections.abc import Callable
from dataclasses import dataclass, replace
from pathlib import Path

from hystmpc.mpc.codegen import CompiledController, Signals, build_cached, c_compiler, cache_dir, write_controller
from hystmpc.mpc.codegen.toolchain import LOG, no_compiler_reason
from hystmpc.mpc.embedded import NotGeneratable, controller_code
from hystmpc.mpc.settings import NmpcSettings, SolverSettings

RTI_SOLVERS = ("rti", "rti-c")
"""The solvers the generated controller has (its RTI step)."""


@dataclass(frozen=True)
class CodeLabels:
    """What the generated controller's header says about where it runs."""

    signals: Signals
    """Names and units of the signals."""
    sample_period: float
    """Seconds per sample."""
    origin: str
    """Where the controller comes from (a bench's name)."""
    version: str
    """The hystmpc version that wrote it."""
    changes: tuple[str, ...] = ()
    """Settings the generated controller is built with where they differ from those asked for
    (``memory.window=200``: what C needs), said once before it runs."""


def generated_settings(settings: NmpcSettings) -> NmpcSettings:
    """``settings`` of the Python controller that is generated: the RTI step, run in Python.

    Parameters
    ----------
    settings : NmpcSettings
        The settings asked for.

    Returns
    -------
    NmpcSettings
        A copy with ``solver="rti"`` and ``runtime="python"``.
    """
    return replace(settings, solver="rti", runtime="python")


def runs_generated(settings: NmpcSettings) -> bool:
    """Whether the controller runs as its generated C: ``runtime=c``, or ``auto`` with an RTI solver.

    Parameters
    ----------
    settings : NmpcSettings
        The settings asked for.

    Returns
    -------
    bool
        True for ``runtime=c``, and for ``auto`` with an RTI solver.
    """
    return settings.runtime == "c" or (settings.runtime == "auto" and settings.solver in RTI_SOLVERS)


def validate_nmpc(settings: NmpcSettings, solvers: SolverSettings | None = None) -> None:
    """``ValueError`` for NMPC settings that cannot go together or cannot run here.

    Cheap (no code is generated): the combinations of :meth:`NmpcSettings.check_combination`,
    and ``runtime=c`` with a solver the generated controller lacks or no C compiler.

    Parameters
    ----------
    settings : NmpcSettings
        The settings to check.
    solvers : SolverSettings, optional
        The solver settings they go with (the configuration's ``solver`` group).
    """
    settings.check_combination(solvers)
    if settings.runtime != "c":
        return
    if settings.solver not in RTI_SOLVERS:
        raise ValueError(f"nmpc.runtime=c runs the generated controller, whose solver is the RTI step; nmpc.solver is "
                         f"{settings.solver!r} (allowed with it: {', '.join(RTI_SOLVERS)}; or set nmpc.runtime=python "
                         "or auto)")
    if c_compiler() is None:
        raise ValueError(f"nmpc.runtime=c needs a C compiler ({no_compiler_reason()}); set nmpc.runtime=python or auto")


_SAID: set[str] = set()


def _say_once(notice: str) -> None:
    """A notice of ``nmpc.runtime=auto``, once per process (not once per scenario)."""
    if notice not in _SAID:
        _SAID.add(notice)
        LOG.warning(notice)


def assemble_nmpc(build: Callable[..., object], settings: NmpcSettings, labels: CodeLabels,
                  planner: Callable[..., object] | None = None):
    """The NMPC as ``settings`` ask: in Python or as generated C, with or without a planner.

    Parameters
    ----------
    build : callable
        ``build(settings)`` builds the Python controller from NMPC settings (the other
        settings fixed); ``build(settings, True)``, for the generated controller only: the
        one it is made from (a bench's
        :meth:`~hystmpc.experiments.bench.Bench.generated_config`).
    settings : NmpcSettings
        The settings asked for.
    labels : CodeLabels
        For the generated controller's header.
    planner : callable, optional
        ``planner()`` builds the linear MPC whose plan ``inverse_plan=linear-mpc`` takes
        (``planner(True)``: the generated controller's); ``ValueError`` names its reason when
        it cannot.

    Raises
    ------
    ValueError
        Settings :func:`validate_nmpc` refuses, a controller ``runtime=c`` cannot generate,
        or ``inverse_plan=linear-mpc`` without a ``planner``.

    Returns
    -------
    Controller
        The Python controller (with its planner attached for ``inverse_plan=linear-mpc``),
        or a :class:`~hystmpc.mpc.codegen.CompiledController` around the generated C.
    """
    validate_nmpc(settings)
    if runs_generated(settings):
        return _compiled(build, settings, labels, planner)
    return _with_planner(build, settings, planner, False)


def _with_planner(build, settings: NmpcSettings, planner, for_code: bool):
    """The Python controller, with its planner attached for ``inverse_plan=linear-mpc``."""
    if settings.inverse_plan != "linear-mpc":
        return build(settings, True) if for_code else build(settings)
    if planner is None:
        raise ValueError("nmpc.inverse_plan=linear-mpc takes the plan of a linear MPC, and there is none here; "
                         "set nmpc.inverse_plan=static")
    plan = planner(True) if for_code else planner()  # first: its checks come before the NMPC's build
    plan.prepare_plan()
    controller = build(settings, True) if for_code else build(settings)
    controller.planner = plan
    return controller


def _compiled(build, settings: NmpcSettings, labels: CodeLabels, planner):
    """The whole generated controller, built once per distinct source into ``<cache>/controllers/``.

    With ``runtime=auto``, no C compiler or a model that cannot be generated gives the
    controller in Python instead, after a one-line notice.
    """
    def in_python():  # the user's solver, in Python
        return _with_planner(build, replace(settings, runtime="python"), planner, False)
    if c_compiler() is None:  # runtime=auto: validate_nmpc refuses runtime=c without a compiler
        _say_once(f"no C compiler ({no_compiler_reason()}): nmpc.runtime=auto runs the controller in Python, slower")
        return in_python()
    python = _with_planner(build, generated_settings(settings), planner, True)
    if labels.changes:
        _say_once(f"nmpc.runtime={settings.runtime}: the generated controller is built with "
                  f"{', '.join(labels.changes)} (what C needs; docs/realtime.md)")
    name = "controller"
    with tempfile.TemporaryDirectory(prefix="hystmpc-controller-") as scratch:  # a cache hit writes nothing there
        written = Path(scratch) / "c"
        try:
            code = controller_code(python, f"{name}_nmpc")
        except NotGeneratable as exc:
            if settings.runtime == "auto":
                _say_once(f"{exc}: nmpc.runtime=auto runs the controller in Python")
                return in_python()
            raise ValueError(f"nmpc.runtime=c: {exc}; or set nmpc.runtime=python or auto") from None
        write_controller(code, written, name, labels.signals, labels.sample_period, labels.origin, labels.version,
                         build=False)
        library = build_cached(written, name, cache_dir() / "controllers", f"nmpc.runtime={settings.runtime}")
    return CompiledController(library, name, python)
