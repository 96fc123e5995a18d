"""``--set KEY=VALUE`` overrides of a bench's parameter groups, with clear errors.

A configuration is a dict of groups, each a frozen dataclass; a key is ``group.field``,
``group.field.sub`` for a nested dataclass (any depth), or ``group.field.NAME`` for a field
that maps option names to values (solver pass-through options).
"""

from __future__ import annotations

import dataclasses
import difflib
import functools
from typing import Any

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
    """Every settable key (``group.field``, ``group.field.sub``..., ``group.options.<name>``)."""
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
    (the TOML value as written).
    """
    if source != "--set":
        return f"{key} = {text}"
    return f"--set {key}={text!r}" if quoted else f"--set {key}={text}"


def _parse(text: str, current: Any, key: str, infinite_ok: bool = False, source: str = "--set") -> Any:
    if isinstance(current, bool):
        lowered = text.strip().lower()
        if lowered in ("true", "1", "yes"):
            return True
        if lowered in ("false", "0", "no"):
            return False
        raise ValueError(f"{_assignment(source, key, text, quoted=True)}: expected true or false")
    try:
        if isinstance(current, int):
            return int(text)
        if isinstance(current, float):
            value = float(text)
            if value != value or value == float("-inf") or (value == float("inf") and not infinite_ok):
                raise ValueError
            return value
        if isinstance(current, tuple):
            values = tuple(float(v) for v in text.split(","))
            if current and isinstance(current[0], tuple):  # points: a flat list, regrouped
                width = len(current[0])
                if len(values) % width or not values:
                    raise ValueError
                return tuple(values[i: i + width] for i in range(0, len(values), width))
            if len(values) != len(current):
                raise ValueError
            return values
    except ValueError:
        if isinstance(current, tuple) and current and isinstance(current[0], tuple):
            kind = (f"comma-separated numbers, {len(current[0])} per point (x1,y1,x2,y2,...; the default has "
                    f"{len(current)} points)")
        elif isinstance(current, tuple):
            kind = f"{len(current)} comma-separated numbers"
        else:
            kind = ("an integer" if isinstance(current, int) else "a number or inf" if infinite_ok
                    else "a finite number")
        raise ValueError(f"{_assignment(source, key, text, quoted=True)}: expected {kind}") from None
    return text


def unknown_key(key: str, config: dict[str, Any], source: str = "--set") -> ValueError:
    """The error for a key ``config`` does not have.

    It names the nearest key, or the group's keys (``source``: how the user gave it, ``--set`` or
    a file's table).
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


def _replace(obj, path: list[str], text: str, key: str, source: str = "--set"):
    """``obj`` with the field at ``path`` set from ``text`` (dataclasses rebuilt and re-validated)."""
    name, rest = path[0], path[1:]
    value = getattr(obj, name)
    if isinstance(value, dict):
        new = {**value, ".".join(rest): _number(text)}
    elif rest:
        new = _replace(value, rest, text, key, source)
    else:  # inf where the setting's own default is inf (it means "none")
        default = next((f.default for f in dataclasses.fields(obj) if f.name == name), None)
        new = _parse(text, value, key, isinstance(default, float) and default == float("inf"), source)
    try:
        return dataclasses.replace(obj, **{name: new})
    except ValueError as exc:
        raise ValueError(f"{_assignment(source, key, text)}: {exc}") from None


def _match(key: str, allowed: list[str]) -> bool:
    if key in allowed:
        return True
    return any(a.endswith(OPTION) and key.startswith(a[: -len(OPTION)]) and len(key) > len(a) - len(OPTION)
               for a in allowed)


def apply_overrides(config: dict[str, Any], assignments: list[str], fixed: dict[str, str] | None = None,
                    source: str = "--set") -> dict[str, Any]:
    """Return a new configuration with each ``KEY=VALUE`` applied.

    ``source`` names where they came from in the errors: ``--set``, or ``table`` for a file's
    tables.

    Raises ``ValueError`` naming the bad key (with the nearest allowed one), a key in
    ``fixed`` (with its reason) or the bad value; the dataclasses' own validation then
    checks ranges.
    """
    config = dict(config)
    allowed = allowed_keys(config)
    for assignment in assignments:
        if "=" not in assignment:
            raise ValueError(f"{source} {assignment!r}: expected KEY=VALUE")
        key, text = assignment.split("=", 1)
        key = key.strip()
        if not _match(key, allowed):
            raise unknown_key(key, config, source)
        if fixed and key in fixed:
            raise ValueError(f"{source} {key} cannot be changed on this bench: {fixed[key]}")
        group, *path = key.split(".")
        config[group] = _replace(config[group], path, text, key, source)
    assigned = {assignment.split("=", 1)[0].strip() for assignment in assignments}
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
    """JSON-ready dump of every parameter group (recorded with each result)."""
    return {group: dataclasses.asdict(obj) for group, obj in config.items()}


def get_value(config: dict[str, Any], key: str) -> Any:
    """The current value of a key."""
    if key not in allowed_keys(config):
        raise unknown_key(key, config)
    group, *path = key.split(".")
    value = config[group]
    for name in path:
        value = getattr(value, name)
    return value
