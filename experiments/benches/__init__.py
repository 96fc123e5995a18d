"""Registry of benches by public name."""

from __future__ import annotations

from hystmpc.experiments.bench import Bench


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
DEFAULT_BENCH = "pam"


def get_bench(name: str) -> Bench:
    """The bench called ``name``; ``ValueError`` naming the allowed ones otherwise."""
    if name not in _FACTORIES:
        raise ValueError(f"unknown bench {name!r}; allowed: {', '.join(BENCH_NAMES)}")
    return _FACTORIES[name]()
