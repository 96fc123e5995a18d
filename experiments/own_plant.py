"""Your own plant (a rig, or your own simulator) in place of a bench's simulated one.

``--plant MODULE:CALLABLE`` on ``run`` and ``compare``; in Python, pass the object as
``Bench.run(..., plant=...)``. The controllers stay those the bench or actuator file builds
(tuned on its nominal model); the plant guard still sits between them and your plant.
"""

from __future__ import annotations

import importlib
import importlib.util
import math
import numbers
import sys
from pathlib import Path
from typing import Any

from hystmpc.plants.base import Measurement


def load_plant(spec: str) -> Any:
    """The plant ``CALLABLE()`` returns, for ``spec`` = ``"MODULE:CALLABLE"``.

    ``ValueError`` naming what is wrong otherwise (also when ``CALLABLE()`` raises).

    Parameters
    ----------
    spec : str
        ``MODULE:CALLABLE``; ``MODULE`` is a dotted name, imported with the working directory on
        the path, or a ``.py`` file's path.

    Returns
    -------
    object
        What ``CALLABLE()`` returned (not checked here: :func:`check_plant`).
    """
    module_name, sep, attribute = spec.rpartition(":")
    if not sep or not module_name or not attribute:
        raise ValueError(f"--plant {spec!r} is not MODULE:CALLABLE (e.g. my_rig:make_plant)")
    try:
        module = _module(module_name)
    except ImportError as exc:
        raise ValueError(f"--plant {spec!r}: cannot import {module_name!r} ({exc})") from None
    factory = getattr(module, attribute, None)
    if not callable(factory):
        raise ValueError(f"--plant {spec!r}: module {module_name!r} ({getattr(module, '__file__', '?')}) has no "
                         f"callable {attribute!r}")
    try:
        return factory()
    except Exception as exc:  # the user's code (opening hardware): one line naming it, not a traceback
        raise ValueError(f"--plant {spec!r}: {attribute}() raised {type(exc).__name__}: {exc}") from None


def _module(name: str):
    """Module ``name``, or the ``.py`` file ``name`` loaded as a module of its own.

    The file's folder goes on the path, for its own imports.
    """
    if not name.endswith(".py"):
        if str(Path.cwd()) not in sys.path and "" not in sys.path:
            sys.path.insert(0, str(Path.cwd()))
        return importlib.import_module(name)
    path = Path(name).resolve()
    if not path.is_file():
        raise ImportError(f"no file {name!r}")
    if str(path.parent) not in sys.path:
        sys.path.insert(0, str(path.parent))
    spec = importlib.util.spec_from_file_location(f"hystmpc_own_plant_{path.stem}", path)
    module = importlib.util.module_from_spec(spec)
    sys.modules[spec.name] = module  # dataclasses and pickling look their module up there
    try:
        spec.loader.exec_module(module)
    except BaseException:
        del sys.modules[spec.name]
        raise
    return module


def check_plant(plant: Any, sample_period: float, expected_sensors=(), who: str = "the plant") -> None:
    """``ValueError`` unless ``plant`` has the Plant protocol and a usable first measurement.

    Resets the plant once (seed 0); the first measurement must be a ``Measurement`` with a finite ``y``.

    Parameters
    ----------
    plant : object
        The plant to check.
    sample_period : float
        The bench's sample period (s); the plant's must equal it.
    expected_sensors : iterable of str, optional
        Sensors the first measurement must carry (the ones the bench's controllers may read).
    who : str, optional
        How the error messages name the plant.
    """
    missing = [m for m in ("sample_period", "reset", "step") if not hasattr(plant, m)]
    if missing:
        raise ValueError(f"{who} lacks {', '.join(missing)} of the Plant protocol (sample_period, "
                         "reset(seed) -> Measurement, step(u) -> Measurement)")
    period = plant.sample_period
    if not isinstance(period, numbers.Real) or not math.isclose(float(period), sample_period, rel_tol=1e-9):
        raise ValueError(f"{who}'s sample_period {period!r} s differs from the bench's {sample_period:g} s; "
                         "allowed: the bench's")
    try:
        first = plant.reset(0)
    except Exception as exc:  # the user's code
        raise ValueError(f"{who}'s reset(0) raised {type(exc).__name__}: {exc}") from None
    if not isinstance(first, Measurement):
        raise ValueError(f"{who}'s reset(seed) returned {type(first).__name__}; allowed: "
                         "hystmpc.plants.base.Measurement")
    if not isinstance(first.y, numbers.Real) or not math.isfinite(first.y):
        raise ValueError(f"{who}'s first measurement y is {first.y}; allowed: a finite number")
    lacking = [s for s in expected_sensors if s not in first.sensors]
    if lacking:
        raise ValueError(f"{who}'s measurement lacks sensor(s) {', '.join(map(repr, lacking))}, which the bench's "
                         f"controllers may read; it gives: {', '.join(map(repr, first.sensors)) or 'none'}")


def describe_plant(plant: Any) -> str:
    """How a result names a plant that is not the bench's: its ``description`` if it has one, else its class.

    Parameters
    ----------
    plant : object
        The plant.

    Returns
    -------
    str
        The description, or the class's ``module.qualname``.
    """
    return getattr(plant, "description", None) or f"{type(plant).__module__}.{type(plant).__qualname__}"
