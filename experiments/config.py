"""Settings into a bench's parameter groups, with their types and clear errors.

One route for every value: ``--set KEY=VALUE`` texts (:func:`apply_overrides`) are parsed to
the type of the field they set, a file's tables and a Python caller's dict
(:func:`apply_values`) keep their own types; both go through the same checks into the frozen
dataclasses, whose own validation then checks ranges.

A configuration is a dict of groups, each a frozen dataclass; a key is ``group.field``,
``group.field.sub`` for a nested dataclass (any depth), or ``group.field.NAME`` for a field
that maps option names to values (solver pass-through options).
"""

from __future__ import annotations

import dataclasses
import difflib
import functools
from typing import Any

import numpy as np

MOVED = {
    "nmpc.eps": "smoothing.eps", "nmpc.direction_eps": "smoothing.direction_eps",
    "nmpc.max_iter": "solver.<solver>.max_iter", "nmpc.tol": "solver.<solver>.tol",
    "nmpc.warm_multipliers": "solver.ipopt.warm_multipliers (or solver.sqp.warm_multipliers)",
    "nmpc.rti_iterations": "solver.rti.iterations", "nmpc.rti_condensed": "solver.rti.condensed",
    "nmpc.rti_qp_iterations": "solver.rti.qp_iterations",
}
"""Keys that moved to their own groups, and where to."""
FOLLOWS = {"lmpc.horizon": "nmpc.horizon"}
"""Keys that take the value of another when only that other is assigned: ``inverse-lmpc``
predicts over the NMPC's horizon unless told otherwise (a fair comparison)."""
OPTION = "<name>"
"""Stands for any option name in :func:`allowed_keys`."""


def _fields(obj) -> dict[str, dataclasses.Field]:
    return {f.name: f for f in dataclasses.fields(obj)}


def _keys(prefix: str, obj) -> list[str]:
    keys = []
    for name in _fields(obj):
        value = getattr(obj, name)
        if dataclasses.is_dataclass(value):
            keys += _keys(f"{prefix}.{name}", value)
        elif isinstance(value, dict):
            keys.append(f"{prefix}.{name}.{OPTION}")
        else:
            keys.append(f"{prefix}.{name}")
    return keys


def allowed_keys(config: dict[str, Any]) -> list[str]:
    """Every settable key (``group.field``, ``group.field.sub``..., ``group.options.<name>``).

    Parameters
    ----------
    config : dict
        The configuration groups.

    Returns
    -------
    list of str
        The keys, group by group; a dict field appears once, ending in :data:`OPTION`.
    """
    keys = []
    for group, obj in config.items():
        keys += _keys(group, obj)
    return keys


def _number(text: str) -> Any:
    """An option value: a bool, an int, a float or the text itself."""
    lowered = text.strip().lower()
    if lowered in ("true", "false"):
        return lowered == "true"
    for kind in (int, float):
        try:
            return kind(text)
        except ValueError:
            pass
    return text.strip()


def _assignment(source: str, key: str, text: str, quoted: bool = False) -> str:
    """How the user wrote an assignment.

    ``--set KEY=VALUE`` (``quoted``: the value as a Python string) or a table's ``KEY = VALUE``
    (the value as written).
    """
    if source != "--set":
        return f"{key} = {text}"
    return f"--set {key}={text!r}" if quoted else f"--set {key}={text}"


def _kind(current: Any, infinite_ok: bool = False) -> str:
    """What a value must be to set a field holding ``current``, in words."""
    if isinstance(current, bool):
        return "true or false"
    if isinstance(current, str):
        return "text"
    if isinstance(current, int):
        return "an integer"
    if isinstance(current, float):
        return "a number or inf" if infinite_ok else "a finite number"
    if not isinstance(current, tuple):
        return "a value the setting accepts"
    if current and isinstance(current[0], tuple):
        return (f"comma-separated numbers, {len(current[0])} per point (x1,y1,x2,y2,...; the default has "
                f"{len(current)} points)")
    return f"{len(current)} comma-separated numbers"


def _real(value: Any, infinite_ok: bool) -> float:
    """``value`` as a float; ``ValueError`` for NaN, -inf and (unless ``infinite_ok``) inf."""
    value = float(value)
    if value != value or value == float("-inf") or (value == float("inf") and not infinite_ok):
        raise ValueError
    return value


def _numbers(values: tuple, current: tuple) -> tuple:
    """A tuple field's new value from a flat sequence of numbers (points regrouped)."""
    if current and isinstance(current[0], tuple):
        width = len(current[0])
        if len(values) % width or not values:
            raise ValueError
        return tuple(values[i: i + width] for i in range(0, len(values), width))
    if len(values) != len(current):
        raise ValueError
    return values


def _parse(text: str, current: Any, infinite_ok: bool = False) -> Any:
    """A ``--set`` text as the type of ``current`` (``ValueError`` when it is not one)."""
    if isinstance(current, bool):
        lowered = text.strip().lower()
        if lowered in ("true", "1", "yes"):
            return True
        if lowered in ("false", "0", "no"):
            return False
        raise ValueError
    if isinstance(current, int):
        return int(text)
    if isinstance(current, float):
        return _real(text, infinite_ok)
    if isinstance(current, tuple):
        return _numbers(tuple(float(v) for v in text.split(",")), current)
    return text


def _typed(value: Any, current: Any, infinite_ok: bool = False) -> Any:
    """A typed value (a TOML table's, a Python caller's) checked against the type of ``current``.

    Nothing is converted but an integer where a number goes (and a NumPy scalar to its Python
    value): ``"20"`` is not a horizon and ``1`` is not true.
    """
    value = _plain(value)
    if not isinstance(current, (bool, str, int, float, tuple)):  # a setting of its own kind (None: unset)
        return value
    if isinstance(current, bool) or isinstance(value, bool):
        if isinstance(current, bool) and isinstance(value, bool):
            return value
        raise ValueError
    if isinstance(current, str):
        if isinstance(value, str):
            return value
        raise ValueError
    if isinstance(current, int):
        if isinstance(value, int):
            return value
        raise ValueError
    if isinstance(current, float):
        if isinstance(value, (int, float)):
            return _real(value, infinite_ok)
        raise ValueError
    if isinstance(current, tuple) and isinstance(value, (list, tuple)):
        points = bool(current) and isinstance(current[0], tuple)
        nested = [isinstance(item, (list, tuple)) for item in value]
        if points and all(nested):  # [[x1, y1], [x2, y2], ...]: each point as wide as the default's
            if any(len(item) != len(current[0]) for item in value):
                raise ValueError
            value = [v for item in value for v in item]
        elif any(nested):
            raise ValueError
        flat = [_plain(v) for v in value]
        if all(isinstance(v, (int, float)) and not isinstance(v, bool) for v in flat):
            return _numbers(tuple(float(v) for v in flat), current)
    raise ValueError


def _plain(value: Any) -> Any:
    """A NumPy scalar as its Python value; anything else as it is."""
    return value.item() if isinstance(value, np.generic) else value


def _option(value: Any) -> Any:
    """A typed pass-through option (solver options): a bool, a number or text (text read as ``--set`` reads it)."""
    value = _plain(value)
    if isinstance(value, str):
        return _number(value)
    if isinstance(value, (bool, int, float)):
        return value
    raise ValueError


def unknown_key(key: str, config: dict[str, Any], source: str = "--set") -> ValueError:
    """The error for a key ``config`` does not have.

    It names the nearest key, or the group's keys.

    Parameters
    ----------
    key : str
        The key the user gave.
    config : dict
        The configuration groups.
    source : str, optional
        How the user gave it: ``--set`` or a file's table.

    Returns
    -------
    ValueError
        The error, not raised: where a moved key (:data:`MOVED`) went, the allowed groups
        for an unknown group, else the nearest key or the group's keys.
    """
    if key in MOVED:
        return ValueError(f"{source} {key} is now {MOVED[key]}")
    group = key.split(".", 1)[0]
    if group not in config:
        return ValueError(f"unknown {source} group {group!r} in {key!r}; allowed groups: {', '.join(config)}")
    fields = [k.split(".", 1)[1] for k in _keys(group, config[group])]
    near = difflib.get_close_matches(key.split(".", 1)[-1], fields, n=1, cutoff=0.6)
    every = "'hystmpc list BENCH' shows every key with its default and units"
    if near:
        return ValueError(f"unknown {source} key {key!r}; did you mean '{group}.{near[0]}'? ({every})")
    if len(fields) <= 12:
        return ValueError(f"unknown {source} key {key!r}; keys of group {group}: {', '.join(fields)}")
    return ValueError(f"unknown {source} key {key!r}; group {group} has {len(fields)} keys: {every}")


@dataclasses.dataclass(frozen=True)
class _Assignment:
    """One key's new value: text to parse (``--set``) or a typed value (a table, Python)."""

    key: str
    value: Any
    text: bool
    source: str

    def written(self, quoted: bool = False) -> str:
        """The assignment as the user wrote it, for an error."""
        if self.text:
            return _assignment(self.source, self.key, self.value, quoted)
        return _assignment(self.source, self.key, repr(self.value) if quoted else _toml(self.value))

    def option(self) -> Any:
        """The value of a pass-through option (``ValueError`` for anything but a bool, a number or text)."""
        if self.text:
            return _number(self.value)
        try:
            return _option(self.value)
        except ValueError:
            raise ValueError(f"{self.written(quoted=True)}: expected true or false, a number or text") from None

    def convert(self, current: Any, infinite_ok: bool) -> Any:
        """The value with the type of ``current`` (``ValueError`` naming the key and what is allowed)."""
        try:
            if self.text:
                return _parse(self.value, current, infinite_ok)
            return _typed(self.value, current, infinite_ok)
        except (ValueError, TypeError, OverflowError):
            expected = _kind(current, infinite_ok)
            if self.text:
                raise ValueError(f"{self.written(quoted=True)}: expected {expected}") from None
            raise ValueError(f"{self.written(quoted=True)}: expected {expected} (the default is {current!r})") from None


def _toml(value: Any) -> str:
    """A typed value as a TOML file would show it."""
    if isinstance(value, bool):
        return "true" if value else "false"
    return repr(value) if isinstance(value, str) else str(value)


def _replace(obj, path: list[str], assignment: _Assignment):
    """``obj`` with the field at ``path`` set (dataclasses rebuilt and re-validated)."""
    name, rest = path[0], path[1:]
    value = getattr(obj, name)
    if isinstance(value, dict):
        new = {**value, ".".join(rest): assignment.option()}
    elif rest:
        new = _replace(value, rest, assignment)
    else:  # inf where the setting's own default is inf (it means "none")
        default = next((f.default for f in dataclasses.fields(obj) if f.name == name), None)
        new = assignment.convert(value, isinstance(default, float) and default == float("inf"))
    try:
        return dataclasses.replace(obj, **{name: new})
    except ValueError as exc:
        raise ValueError(f"{assignment.written()}: {exc}") from None


def _match(key: str, allowed: list[str]) -> bool:
    if key in allowed:
        return True
    return any(a.endswith(OPTION) and key.startswith(a[: -len(OPTION)]) and len(key) > len(a) - len(OPTION)
               for a in allowed)


def apply_overrides(config: dict[str, Any], assignments: list[str], fixed: dict[str, str] | None = None,
                    source: str = "--set") -> dict[str, Any]:
    """Return a new configuration with each ``KEY=VALUE`` text applied (``--set``, conditions).

    The text is parsed to the type of the field it sets; then as :func:`apply_values`.

    Parameters
    ----------
    config : dict
        The configuration groups (not changed).
    assignments : list of str
        ``KEY=VALUE`` texts.
    fixed : dict, optional
        Keys that cannot be set, with the reason.
    source : str, optional
        How the texts were given, for the errors.

    Returns
    -------
    dict
        The new configuration.

    Raises
    ------
    ValueError
        A text without ``=``, or as :func:`apply_values`.
    """
    parsed = []
    for assignment in assignments:
        if "=" not in assignment:
            raise ValueError(f"{source} {assignment!r}: expected KEY=VALUE")
        key, text = assignment.split("=", 1)
        parsed.append(_Assignment(key.strip(), text, True, source))
    return _apply(config, parsed, fixed)


def apply_values(config: dict[str, Any], values, fixed: dict[str, str] | None = None,
                 source: str = "table") -> dict[str, Any]:
    """Return a new configuration with typed values applied: a file's tables, a Python caller's dict.

    Parameters
    ----------
    config : dict
        The configuration groups.
    values : dict or iterable of (key, value)
        Values of the fields' own types (an integer also sets a number; a list of numbers a
        tuple); nothing else is converted.
    fixed : dict, optional
        Keys that cannot be set, with the reason.
    source : str
        How the values were given, for the errors (``table``, ``--set``).

    Returns
    -------
    dict
        A new configuration (``config`` is not changed).

    Raises
    ------
    ValueError
        Naming the bad key (with the nearest allowed one), a key in ``fixed`` (with its
        reason) or the bad value; the dataclasses' own validation then checks ranges.
    """
    pairs = values.items() if isinstance(values, dict) else values
    return _apply(config, [_Assignment(str(k).strip(), v, False, source) for k, v in pairs], fixed)


def _apply(config: dict[str, Any], assignments: list[_Assignment], fixed: dict[str, str] | None) -> dict[str, Any]:
    """The one route every value takes into the configuration's dataclasses."""
    config = dict(config)
    allowed = allowed_keys(config)
    for assignment in assignments:
        key = assignment.key
        if not _match(key, allowed):
            raise unknown_key(key, config, assignment.source)
        if fixed and key in fixed:
            raise ValueError(f"{assignment.source} {key} cannot be changed on this bench: {fixed[key]}")
        group, *path = key.split(".")
        config[group] = _replace(config[group], path, assignment)
    assigned = {assignment.key for assignment in assignments}
    for key, leader in FOLLOWS.items():
        group, field = key.split(".")
        if leader in assigned and key not in assigned and group in config:
            config[group] = dataclasses.replace(config[group], **{field: get_value(config, leader)})
    return config


@functools.cache
def _field_docs(cls) -> dict[str, str]:
    """The attribute docstrings of a dataclass (and its bases): the string after each field."""
    import ast
    import inspect
    import textwrap
    docs: dict[str, str] = {}
    for klass in reversed(cls.__mro__):
        if not dataclasses.is_dataclass(klass):
            continue
        try:
            tree = ast.parse(textwrap.dedent(inspect.getsource(klass)))
        except (OSError, TypeError, SyntaxError):
            continue  # a class made at run time (an actuator file's model) has no source
        body = tree.body[0].body if tree.body and isinstance(tree.body[0], ast.ClassDef) else []
        for node, after in zip(body, body[1:], strict=False):
            if (isinstance(node, ast.AnnAssign) and isinstance(node.target, ast.Name)
                    and isinstance(after, ast.Expr) and isinstance(after.value, ast.Constant)
                    and isinstance(after.value.value, str)):
                docs[node.target.id] = " ".join(after.value.value.split())
    return docs


def key_table(config: dict[str, Any]) -> list[tuple[str, Any, str]]:
    """Every settable key with its current value and its docstring, cut at 100 characters.

    Units are written in the docstring, in parentheses.

    Parameters
    ----------
    config : dict
        The configuration groups.

    Returns
    -------
    list of tuple
        ``(key, value, doc)`` rows; a dict field is one row, its key ending in :data:`OPTION`.
    """
    rows = []

    def walk(prefix: str, obj) -> None:
        docs = _field_docs(type(obj))
        for name in _fields(obj):
            value = getattr(obj, name)
            key = f"{prefix}.{name}"
            if dataclasses.is_dataclass(value):
                walk(key, value)
                continue
            doc = docs.get(name, "").replace(":data:", "").replace("``", "").replace("`", "")
            first = doc if len(doc) <= 100 else doc[:99].rstrip() + "…"
            if isinstance(value, dict):
                rows.append((f"{key}.{OPTION}", value or "{}", first or "a pass-through option"))
            else:
                rows.append((key, value, first))

    for group, obj in config.items():
        walk(group, obj)
    return rows


def describe(config: dict[str, Any]) -> dict[str, Any]:
    """JSON-ready dump of every parameter group (recorded with each result).

    Parameters
    ----------
    config : dict
        The configuration groups.

    Returns
    -------
    dict
        Each group as a dict (:func:`dataclasses.asdict`).
    """
    return {group: dataclasses.asdict(obj) for group, obj in config.items()}


def get_value(config: dict[str, Any], key: str) -> Any:
    """The current value of a key.

    Parameters
    ----------
    config : dict
        The configuration groups.
    key : str
        One of :func:`allowed_keys` (``ValueError`` from :func:`unknown_key` otherwise).

    Returns
    -------
    Any
        The field's value.
    """
    if key not in allowed_keys(config):
        raise unknown_key(key, config)
    group, *path = key.split(".")
    value = config[group]
    for name in path:
        value = getattr(value, name)
    return value
