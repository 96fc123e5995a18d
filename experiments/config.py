"""``--set KEY=VALUE`` overrides of a bench's parameter groups, with clear errors."""

from __future__ import annotations

import dataclasses
from typing import Any


def _fields(obj) -> dict[str, dataclasses.Field]:
    return {f.name: f for f in dataclasses.fields(obj)}


def allowed_keys(config: dict[str, Any]) -> list[str]:
    """Every settable ``group.field`` (and ``group.field.sub`` for nested dataclasses)."""
    keys = []
    for group, obj in config.items():
        for name in _fields(obj):
            value = getattr(obj, name)
            if dataclasses.is_dataclass(value):
                keys += [f"{group}.{name}.{sub}" for sub in _fields(value)]
            else:
                keys.append(f"{group}.{name}")
    return keys


def _parse(text: str, current: Any, key: str) -> Any:
    if isinstance(current, bool):
        lowered = text.strip().lower()
        if lowered in ("true", "1", "yes"):
            return True
        if lowered in ("false", "0", "no"):
            return False
        raise ValueError(f"--set {key}={text!r}: expected true or false")
    try:
        if isinstance(current, int):
            return int(text)
        if isinstance(current, float):
            value = float(text)
            if value != value or value in (float("inf"), float("-inf")):
                raise ValueError
            return value
        if isinstance(current, tuple):
            values = tuple(float(v) for v in text.split(","))
            if len(values) != len(current):
                raise ValueError
            return values
    except ValueError:
        if isinstance(current, tuple):
            kind = f"{len(current)} comma-separated numbers"
        else:
            kind = "an integer" if isinstance(current, int) else "a finite number"
        raise ValueError(f"--set {key}={text!r}: expected {kind}") from None
    return text


def apply_overrides(config: dict[str, Any], assignments: list[str]) -> dict[str, Any]:
    """Return a new configuration with each ``KEY=VALUE`` applied.

    Raises ``ValueError`` naming the bad key (and the allowed ones) or the bad value; the
    dataclasses' own validation then checks ranges.
    """
    config = dict(config)
    allowed = allowed_keys(config)
    for assignment in assignments:
        if "=" not in assignment:
            raise ValueError(f"--set {assignment!r}: expected KEY=VALUE")
        key, text = assignment.split("=", 1)
        key = key.strip()
        if key not in allowed:
            raise ValueError(f"unknown --set key {key!r}; allowed: {', '.join(allowed)}")
        group, *path = key.split(".")
        obj = config[group]
        if len(path) == 1:
            new = _parse(text, getattr(obj, path[0]), key)
            config[group] = dataclasses.replace(obj, **{path[0]: new})
        else:
            inner = getattr(obj, path[0])
            new = _parse(text, getattr(inner, path[1]), key)
            config[group] = dataclasses.replace(obj, **{path[0]: dataclasses.replace(inner, **{path[1]: new})})
    return config


def describe(config: dict[str, Any]) -> dict[str, Any]:
    """JSON-ready dump of every parameter group (recorded with each result)."""
    return {group: dataclasses.asdict(obj) for group, obj in config.items()}


def get_value(config: dict[str, Any], key: str) -> Any:
    """The current value of a ``group.field`` (or ``group.field.sub``) key."""
    if key not in allowed_keys(config):
        raise ValueError(f"unknown key {key!r}; allowed: {', '.join(allowed_keys(config))}")
    group, *path = key.split(".")
    value = config[group]
    for name in path:
        value = getattr(value, name)
    return value
