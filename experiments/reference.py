"""User reference trajectories from CSV (interface.md, "Reference CSV")."""

from __future__ import annotations

import csv
from pathlib import Path

import numpy as np

from hystmpc.experiments.bench import Bench, Scenario


def load_reference(path: str | Path, bench: Bench) -> Scenario:
    """Read ``t`` and the bench's reference column (or ``ref``) into a scenario.

    Raises ``ValueError`` for a missing file or column, non-numeric, NaN or infinite values,
    a time column that does not start at 0 or is not strictly increasing, fewer than two
    rows, or values outside the bench's output range.
    """
    path = Path(path)
    if not path.is_file():
        raise ValueError(f"reference file {str(path)!r} does not exist")
    with path.open(newline="") as fh:
        rows = list(csv.reader(fh))
    if not rows:
        raise ValueError(f"reference file {str(path)!r} is empty")
    header = [h.strip() for h in rows[0]]
    column = bench.output_name if bench.output_name in header else "ref"
    missing = [c for c in ("t", column) if c not in header]
    if missing:
        name = bench.output_name if missing[0] == "ref" else missing[0]
        raise ValueError(f"reference file {str(path)!r} lacks column {name!r}; "
                         f"needs 't' and {bench.output_name!r} (or 'ref'), has {header}")
    it, ir = header.index("t"), header.index(column)
    try:
        data = np.array([[float(r[it]), float(r[ir])] for r in rows[1:] if any(c.strip() for c in r)])
    except (ValueError, IndexError):
        raise ValueError(f"reference file {str(path)!r} has a non-numeric or missing value") from None
    if len(data) < 2:
        raise ValueError(f"reference file {str(path)!r} needs at least two rows, has {len(data)}")
    if not np.all(np.isfinite(data)):
        bad = int(np.flatnonzero(~np.all(np.isfinite(data), axis=1))[0]) + 2
        raise ValueError(f"reference file {str(path)!r} has NaN or infinite values (line {bad})")
    t, r = data[:, 0], data[:, 1]
    if t[0] != 0:
        raise ValueError(f"reference file {str(path)!r}: t must start at 0, starts at {t[0]}")
    if np.any(np.diff(t) <= 0):
        bad = int(np.flatnonzero(np.diff(t) <= 0)[0]) + 3
        raise ValueError(f"reference file {str(path)!r}: t must be strictly increasing (line {bad})")
    lo, hi = bench.output_range
    if r.min() < lo or r.max() > hi:
        raise ValueError(f"reference file {str(path)!r}: {column} must lie in [{lo}, {hi}] "
                         f"{bench.units}, spans [{r.min():g}, {r.max():g}]")
    return Scenario(name=path.stem, description=f"reference from {path.name}", duration=float(t[-1]),
                    reference=lambda tq: np.interp(tq, t, r))
