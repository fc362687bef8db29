"""`--set FIELD=VALUE`: sensor fields overridden from the command line, each value parsed as the
field's type (so `labels=true` is a bool and `seed=1` an int), with errors that name the field."""

from __future__ import annotations

import dataclasses
from typing import Any

from pecs.config import SensorConfig

_TRUE = ("true", "yes", "on", "1")
_FALSE = ("false", "no", "off", "0")
_NONE = ("none", "null", "")


def sensor_field_types(**extra: str) -> dict[str, str]:
    """Field name -> type as written in SensorConfig ("float", "bool", "float | None", ...)."""
    types = {f.name: str(f.type) for f in dataclasses.fields(SensorConfig) if f.init}
    types.pop("preset_name", None)
    return {**types, **extra}


def parse_overrides(items: list[str], types: dict[str, str]) -> dict[str, Any]:
    """FIELD=VALUE pairs as a dict; an unknown field or a value of the wrong kind is a
    ValueError that names it."""
    overrides: dict[str, Any] = {}
    for item in items:
        field, sep, text = item.partition("=")
        field, text = field.strip(), text.strip()
        if not sep or not field:
            raise ValueError(f"--set {item}: expected FIELD=VALUE, e.g. theta_on=0.3")
        if field not in types:
            known = ", ".join(sorted(types))
            raise ValueError(f"--set {field}: unknown sensor field; known fields: {known}")
        overrides[field] = parse_value(field, text, types[field])
    return overrides


def parse_value(field: str, text: str, kind: str) -> Any:
    optional = kind.endswith("| None")
    base = kind.removesuffix("| None").strip()
    if optional and text.lower() in _NONE:
        return None
    if base == "bool":
        if text.lower() in _TRUE:
            return True
        if text.lower() in _FALSE:
            return False
        raise ValueError(f"--set {field}={text}: {field} takes true or false (or yes/no, 1/0)")
    if base == "int":
        return _integer(field, text)
    if base == "float":
        try:
            return float(text)
        except ValueError:
            raise ValueError(f"--set {field}={text}: {field} takes a number") from None
    return text


def _integer(field: str, text: str) -> int:
    try:
        return int(text)
    except ValueError:
        pass
    try:
        value = float(text)  # 1e3 is a whole number too
    except ValueError:
        value = float("nan")
    if not value.is_integer():
        raise ValueError(f"--set {field}={text}: {field} takes a whole number")
    return int(value)
