"""Registry of benches: the four built in, plugins and actuator files.

:func:`get_bench` takes a built-in name (``pam``, ``compliant``, ``reluctance``, ``dea``), the
name of a bench another package registers through the ``hystmpc.benches`` entry point (the
entry point gives a :class:`~hystmpc.experiments.bench.Bench` or a function returning one),
or the path of an actuator file (``*.toml``, :mod:`hystmpc.experiments.actuator_file`).
"""

from __future__ import annotations

from importlib.metadata import entry_points
from pathlib import Path

from hystmpc.experiments.bench import Bench

ENTRY_POINT_GROUP = "hystmpc.benches"


def _pam() -> Bench:
    from hystmpc.experiments.benches.pam import BENCH
    return BENCH


def _compliant() -> Bench:
    from hystmpc.experiments.benches.compliant import BENCH
    return BENCH


def _reluctance() -> Bench:
    from hystmpc.experiments.benches.reluctance import BENCH
    return BENCH


def _dea() -> Bench:
    from hystmpc.experiments.benches.dea import BENCH
    return BENCH


_FACTORIES = {"pam": _pam, "compliant": _compliant, "reluctance": _reluctance, "dea": _dea}
BENCH_NAMES = tuple(_FACTORIES)
"""The built-in benches."""
DEFAULT_BENCH = "pam"


def plugin_names() -> tuple[str, ...]:
    """Names of the benches other installed packages register (``hystmpc.benches`` entry points).

    Returns
    -------
    tuple of str
        The names, sorted, without the built-in ones.
    """
    return tuple(sorted({ep.name for ep in entry_points(group=ENTRY_POINT_GROUP)} - set(BENCH_NAMES)))


def all_bench_names() -> tuple[str, ...]:
    """Built-in benches, then plugins.

    Returns
    -------
    tuple of str
        :data:`BENCH_NAMES`, then :func:`plugin_names`.
    """
    return BENCH_NAMES + plugin_names()


def _plugin(name: str) -> Bench:
    (ep,) = [ep for ep in entry_points(group=ENTRY_POINT_GROUP) if ep.name == name][:1]
    try:
        obj = ep.load()
        bench = obj() if callable(obj) and not isinstance(obj, Bench) else obj
    except Exception as exc:  # noqa: BLE001 - a broken plugin: name it, whatever it raised
        raise ValueError(f"bench plugin {name!r} ({ep.value}) failed to load: {type(exc).__name__}: {exc}") from None
    if not isinstance(bench, Bench):
        raise ValueError(f"bench plugin {name!r} ({ep.value}) gave a {type(bench).__name__}, not a Bench")
    return bench


def is_actuator_file(name: str) -> bool:
    """Whether ``name`` names an actuator file rather than a bench.

    Parameters
    ----------
    name : str
        A bench name or a path.

    Returns
    -------
    bool
        True for a name ending in ``.toml``, or a path with ``/`` that exists.
    """
    return name.endswith(".toml") or ("/" in name and Path(name).exists())


def get_bench(name: str) -> Bench:
    """The bench called ``name`` (or in the actuator file ``name``).

    Parameters
    ----------
    name : str
        A built-in bench, a plugin's name or an actuator file's path.

    Returns
    -------
    Bench
        The bench (``ValueError`` naming the allowed ones otherwise).
    """
    if name in _FACTORIES:
        return _FACTORIES[name]()
    if is_actuator_file(name):
        from hystmpc.experiments.actuator_file import load_actuator
        return load_actuator(name)
    if name in plugin_names():
        return _plugin(name)
    raise ValueError(f"unknown bench {name!r}; allowed: {', '.join(all_bench_names())}, or an actuator file "
                     f"(*.toml)")
