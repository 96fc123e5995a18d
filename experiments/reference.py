"""User CSV files: reference trajectories and measured records for identification.

They are described in interface.md: "Reference CSV" for the trajectories, "Identification"
for the records.
"""

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

    Parameters
    ----------
    path : str or Path
        The CSV file, with a header.
    bench : Bench
        The bench the reference is for (its output name, range and units).

    Returns
    -------
    Scenario
        Named after the file's stem, lasting until the last ``t``, the reference linearly
        interpolated between the rows.
    """
    path = Path(path)
    header = _header(path, "reference file")
    column = bench.output_name if bench.output_name in header else "ref"
    if "t" in header and column not in header:
        raise ValueError(f"reference file {str(path)!r} lacks column {bench.output_name!r}; "
                         f"needs 't' and {bench.output_name!r} (or 'ref'), has {header}")
    data = read_columns(path, ("t", column), "reference file", minimum_rows=2)
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


def _header(path: Path, what: str) -> list[str]:
    try:
        with path.open(newline="", encoding="utf-8-sig") as fh:
            first = next(csv.reader(fh), None)
    except FileNotFoundError:
        raise ValueError(f"{what} {str(path)!r} does not exist") from None
    except (OSError, UnicodeDecodeError) as exc:
        raise ValueError(f"{what} {str(path)!r} cannot be read as CSV text ({type(exc).__name__})") from None
    if first is None:
        raise ValueError(f"{what} {str(path)!r} is empty")
    return [h.strip() for h in first]


def read_columns(path: str | Path, columns: tuple[str, ...], what: str, minimum_rows: int = 2) -> np.ndarray:
    """The named columns of a CSV file with a header, as a float array (rows: samples).

    ``ValueError`` naming the file (as ``what``) for a missing or unreadable file or
    column, a row whose field count differs from the header's, a non-numeric or missing
    value (with its line), NaN or infinite values, or fewer than ``minimum_rows``. Blank rows
    are skipped.

    Parameters
    ----------
    path : str or Path
        The CSV file.
    columns : tuple of str
        Names of the columns to read, in the array's order.
    what : str
        What the file is, for the error messages.
    minimum_rows : int, optional
        Fewest data rows accepted.

    Returns
    -------
    ndarray
        Shape ``(rows, len(columns))``.
    """
    path = Path(path)
    header = _header(path, what)
    missing = [c for c in columns if c not in header]
    if missing:
        raise ValueError(f"{what} {str(path)!r} lacks column {missing[0]!r}; needs {', '.join(columns)}, "
                         f"has {header}")
    index = [header.index(c) for c in columns]
    try:
        with path.open(newline="", encoding="utf-8-sig") as fh:
            rows = list(csv.reader(fh))[1:]
    except (OSError, UnicodeDecodeError, csv.Error) as exc:
        raise ValueError(f"{what} {str(path)!r} cannot be read as CSV text ({type(exc).__name__})") from None
    values = []
    for line, row in enumerate(rows, start=2):
        if not any(c.strip() for c in row):
            continue
        if len(row) != len(header):
            raise ValueError(f"{what} {str(path)!r}, line {line}: {len(row)} fields, the header has "
                             f"{len(header)}")
        try:
            values.append([float(row[i]) for i in index])
        except ValueError:
            bad = next(row[i] for i in index if not _is_number(row[i])).strip()
            problem = f"{bad!r} is not a number" if bad else "a value is missing"
            raise ValueError(f"{what} {str(path)!r}, line {line}: {problem}") from None
    data = np.array(values, float).reshape(len(values), len(columns))
    if len(data) < minimum_rows:
        raise ValueError(f"{what} {str(path)!r} needs at least {minimum_rows} rows, has {len(data)}")
    if not np.all(np.isfinite(data)):
        bad = int(np.flatnonzero(~np.all(np.isfinite(data), axis=1))[0]) + 2
        raise ValueError(f"{what} {str(path)!r} has NaN or infinite values (line {bad})")
    return data.reshape(len(data), len(columns))


def _is_number(text: str) -> bool:
    try:
        float(text)
    except ValueError:
        return False
    return True


def load_record(path: str | Path, what: str = "data file") -> tuple[np.ndarray, np.ndarray, float]:
    """A measured record for identification: columns ``t``, ``u``, ``y``; returns ``(u, y, sample_period)``.

    ``ValueError`` as :func:`read_columns`, and for a time column that is not strictly
    increasing or not uniformly sampled (to 1e-6 of the period), fewer than
    :data:`~hystmpc.models.identification.MIN_SAMPLES` rows or a constant input.

    Parameters
    ----------
    path : str or Path
        The CSV file.
    what : str, optional
        What the file is, for the error messages.

    Returns
    -------
    u, y : ndarray
        Input and output samples, as checked by ``hystmpc.models.identification.check_data``.
    sample_period : float
        The median step of ``t`` (s).
    """
    from hystmpc.models.identification import MIN_SAMPLES, check_data
    data = read_columns(path, ("t", "u", "y"), what, minimum_rows=MIN_SAMPLES)
    t = data[:, 0]
    steps = np.diff(t)
    if np.any(steps <= 0):
        bad = int(np.flatnonzero(steps <= 0)[0]) + 3
        raise ValueError(f"{what} {str(path)!r}: t must be strictly increasing (line {bad})")
    period = float(np.median(steps))
    if np.max(np.abs(steps - period)) > 1e-6 * period + 1e-12 * abs(t[-1]):
        bad = int(np.argmax(np.abs(steps - period))) + 3
        raise ValueError(f"{what} {str(path)!r}: t must be uniformly sampled; the step at line {bad} is "
                         f"{steps[bad - 3]:g} s against {period:g} s")
    u, y = check_data(data[:, 1], data[:, 2], period, f"{what} {str(path)!r}")
    return u, y, period
