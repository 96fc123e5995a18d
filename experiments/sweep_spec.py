"""A sweep's spec (interface.md, "Sweeps").

The TOML file read and checked into a :class:`SweepSpec`, and the id of each of its runs.
"""

from __future__ import annotations

import math
import tomllib
from collections.abc import Iterable
from dataclasses import asdict, dataclass, field
from pathlib import Path
from typing import Any

SPEC_KEYS = ("bench", "scenarios", "controllers", "seeds", "perturb", "duration", "set", "perturb_seed")
METRICS = ("rmse", "mae", "max_abs_error", "input_tv", "oscillation_cycles")
CHALLENGER = "nmpc"
"""The controller whose wins against the others the summary counts."""


class SpecError(ValueError):
    """A sweep spec (or its combination with the command line) that cannot be run."""


@dataclass(frozen=True)
class SweepSpec:
    """What to run: the full factorial of scenarios, controllers, seeds and perturbation samples."""

    bench: str
    scenarios: tuple[str, ...]
    controllers: tuple[str, ...]
    seeds: tuple[int, ...] = (0,)
    perturb: dict[str, float] = field(default_factory=dict)
    """Relative amplitude per parameter key: each sample scales the value by U(1 − a, 1 + a)."""
    samples: int = 1
    """Perturbed plants per (scenario, seed); the same plants for every controller."""
    duration: float | None = None
    overrides: tuple[str, ...] = ()
    """``KEY=VALUE`` assignments applied to every run before the perturbation."""
    perturb_seed: int = 0

    @property
    def n_runs(self) -> int:
        """Number of runs in the sweep."""
        return len(self.scenarios) * len(self.controllers) * len(self.seeds) * self.samples

    def as_dict(self) -> dict[str, Any]:
        """JSON-ready form (stored beside the records, compared on resume).

        Returns
        -------
        dict
            The fields, tuples as lists.
        """
        d = asdict(self)
        for key in ("scenarios", "controllers", "seeds", "overrides"):
            d[key] = list(d[key])
        return d


def _fail(path, message: str):
    raise SpecError(f"{path}: {message}")


def _string_list(path, raw: dict, key: str, allowed: Iterable[str], default: list[str]) -> tuple[str, ...]:
    value = raw.get(key, default)
    if isinstance(value, str):
        value = [value]
    if not isinstance(value, list) or not value or not all(isinstance(v, str) for v in value):
        _fail(path, f"{key} must be a non-empty list of names")
    allowed = list(allowed)
    for name in value:
        if name not in allowed:
            _fail(path, f"unknown {key[:-1]} {name!r}; allowed: {', '.join(allowed)}")
    if len(set(value)) != len(value):
        _fail(path, f"{key} names a {key[:-1]} twice: {value}")
    return tuple(value)


def load_spec(path: str | Path, extra_overrides: Iterable[str] = (), duration: float | None = None,
              force: bool = False) -> SweepSpec:
    """Read and check a sweep spec.

    Parameters
    ----------
    path : str or Path
        TOML file (format in interface.md).
    extra_overrides : iterable of str, optional
        ``KEY=VALUE`` assignments from the command line, applied after the spec's ``set``.
    duration : float, optional
        Run length (s) from the command line; replaces the spec's ``duration``.
    force : bool, optional
        Lift the work ceilings of :mod:`hystmpc.experiments.limits` (horizon, samples per
        run, runs and samples per sweep).

    Returns
    -------
    SweepSpec
        The checked spec; an actuator file as ``bench`` is made absolute.

    Raises
    ------
    SpecError
        Naming the file, the bad entry and what is allowed.
    """
    from hystmpc.experiments.benches import get_bench, is_actuator_file
    from hystmpc.experiments.config import allowed_keys, get_value, unknown_key

    path = Path(path)
    try:
        raw = tomllib.loads(path.read_text())
    except FileNotFoundError:
        raise SpecError(f"sweep spec {str(path)!r} not found") from None
    except (OSError, UnicodeDecodeError) as exc:
        raise SpecError(f"sweep spec {str(path)!r} cannot be read: {exc}") from None
    except tomllib.TOMLDecodeError as exc:
        raise SpecError(f"{path}: not valid TOML: {exc}") from None
    unknown = sorted(set(raw) - set(SPEC_KEYS))
    if unknown:
        _fail(path, f"unknown key {unknown[0]!r}; allowed: {', '.join(SPEC_KEYS)}")
    if not isinstance(raw.get("bench"), str):
        _fail(path, f"bench = {raw.get('bench')!r}; a bench name or an actuator file (relative to the spec)")
    if is_actuator_file(raw["bench"]):  # workers find it by its absolute path
        raw["bench"] = str((path.parent / raw["bench"]).resolve())
    try:
        bench = get_bench(raw["bench"])
    except ValueError as exc:
        _fail(path, f"bench: {exc}")
    scenarios = _string_list(path, raw, "scenarios", bench.scenarios, [bench.default_scenario])
    controllers = _string_list(path, raw, "controllers", bench.controllers, list(bench.controllers))
    seeds = raw.get("seeds", [0])
    if (not isinstance(seeds, list) or not seeds or not all(isinstance(s, int) and s >= 0 for s in seeds)
            or len(set(seeds)) != len(seeds)):
        _fail(path, f"seeds must be a non-empty list of distinct integers >= 0, got {seeds!r}")
    perturb_seed = raw.get("perturb_seed", 0)
    if not isinstance(perturb_seed, int) or perturb_seed < 0:
        _fail(path, f"perturb_seed must be an integer >= 0, got {perturb_seed!r}")
    if duration is None:
        duration = raw.get("duration")
    if duration is not None and (isinstance(duration, bool) or not isinstance(duration, (int, float))
                                 or not math.isfinite(duration) or not duration > 0):
        _fail(path, f"duration must be a finite number of seconds > 0, got {duration!r}")
    overrides = raw.get("set", [])
    if not isinstance(overrides, list) or not all(isinstance(o, str) for o in overrides):
        _fail(path, "set must be a list of 'KEY=VALUE' strings")
    overrides = tuple(overrides) + tuple(extra_overrides)
    try:
        config = bench.configure(overrides)
    except ValueError as exc:
        _fail(path, str(exc))

    if not isinstance(raw.get("perturb", {}), dict):
        _fail(path, f"perturb must be a table of KEY = relative amplitude, plus samples = N; got "
                    f"{raw['perturb']!r}")
    perturb = dict(raw.get("perturb", {}))
    samples = perturb.pop("samples", 10 if perturb else 1)
    if isinstance(samples, bool) or not isinstance(samples, int) or samples < 1:
        _fail(path, f"perturb.samples must be an integer >= 1, got {samples!r}")
    allowed = allowed_keys(config)
    fixed = {c.split("=", 1)[0] for name in scenarios for c in bench.scenarios[name].conditions}
    for key, amplitude in perturb.items():
        if key not in allowed:
            _fail(path, str(unknown_key(key, config)).replace("--set key", "perturb key"))
        if key in fixed:
            _fail(path, f"perturb key {key!r} is fixed by the scenarios; perturb another parameter")
        value = get_value(config, key)
        real = isinstance(value, float) or (isinstance(value, tuple) and all(isinstance(v, float) for v in value))
        if not real:
            _fail(path, f"perturb key {key!r} is not a real-valued parameter (it is {value!r})")
        if isinstance(amplitude, bool) or not isinstance(amplitude, (int, float)) or not 0 < amplitude < 1:
            _fail(path, f"perturb amplitude of {key!r} must be a number in (0, 1), got {amplitude!r}")
    spec = SweepSpec(bench=raw["bench"], scenarios=scenarios, controllers=controllers, seeds=tuple(seeds),
                     perturb={k: float(v) for k, v in sorted(perturb.items())}, samples=samples,
                     duration=None if duration is None else float(duration), overrides=overrides,
                     perturb_seed=perturb_seed)
    from hystmpc.experiments.limits import check_horizons, check_run_samples, check_sweep, run_samples
    try:
        per_scenario = {name: run_samples(spec.duration or bench.scenarios[name].duration, bench.sample_period,
                                          "duration") for name in scenarios}
        for name, n in per_scenario.items():
            check_run_samples(n, f"a run of {name}", force)
        check_horizons(config, force)
        bench.validate(config, controllers)
        check_sweep(spec.n_runs, sum(per_scenario.values()) * spec.n_runs // len(scenarios), force)
    except ValueError as exc:
        _fail(path, str(exc))
    return spec


def run_id(scenario: str, controller: str, seed: int, sample: int) -> str:
    """Name of a run's record: ``<scenario>__<controller>__s<seed>__p<sample>``.

    Parameters
    ----------
    scenario, controller : str
        Names of the scenario and the controller.
    seed : int
        Seed of the run.
    sample : int
        Index of the perturbed plant.

    Returns
    -------
    str
        The id, ``<sample>`` zero-padded to four digits.
    """
    return f"{scenario}__{controller}__s{seed}__p{sample:04d}"
