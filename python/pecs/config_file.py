"""Sensor configuration files: a `SensorConfig` as a flat TOML file of `field = value` lines.

    # pecs sensor configuration
    preset_name = "davis346"
    theta_on = 0.1336...

Every key is a `SensorConfig` field (TOML 1.0: strings, integers, floats, booleans), but for an
optional `[biases]` table: the sensor's biases (`sensor = "davis346"` or `"imx636"` and its
biases), mapped to fields by `pecs.biases`; the file's own fields win over mapped ones. A field
left out takes the value of the preset the file names (`preset_name`); a file that names none
must give every field, and an empty file is refused (`SensorConfig.from_file`). A field that is
None (`lin_log_knee`, `preset_name`) is left out, TOML having no null. Floats are written with Python's repr, which
reads back to the same float, so a file round-trips exactly. Written atomically.
"""

from __future__ import annotations

import math
import os
import sys
from collections.abc import Callable, Collection, Mapping
from pathlib import Path
from typing import Any, TypeVar

from pecs._atomic import atomic_path

if sys.version_info >= (3, 11):
    import tomllib
else:  # pragma: no cover (Python 3.10)
    import tomli as tomllib

__all__ = ["read_config", "write_config"]

T = TypeVar("T")
#: The table of a sensor's biases (`sensor = "davis346"` and its biases), mapped to fields.
BIASES_TABLE = "biases"
HEADER = "# pecs sensor configuration (SensorConfig fields; see docs/pixel-model.md in pecs)\n"


def read_config(
    path: str | os.PathLike[str],
    known: Collection[str],
    build: Callable[[dict[str, Any]], T],
) -> T:
    """`build` of the values in a TOML file whose keys are all in `known` (`SensorConfig.from_file`
    passes its fields and `from_dict`); a ValueError names the file and the offending key."""
    file = Path(path)
    if not file.is_file():
        raise FileNotFoundError(f"no such file: {file} (the sensor config, --config)")
    try:
        with open(file, "rb") as stream:
            values = tomllib.load(stream)
    except (tomllib.TOMLDecodeError, UnicodeDecodeError) as error:
        raise ValueError(f"{file}: not a valid TOML file ({error})") from error
    for key, value in values.items():
        if key == BIASES_TABLE and isinstance(value, dict):
            continue  # the sensor's biases, mapped by `build` (pecs.biases)
        if key not in known:
            raise ValueError(
                f"{file}: unknown sensor field {key!r}; known fields: {', '.join(sorted(known))}"
            )
        if isinstance(value, (dict, list)):
            raise ValueError(f"{file}: {key} must be a single value, got {type(value).__name__}")
    try:
        return build(values)
    except (TypeError, ValueError) as error:
        raise ValueError(f"{file}: {error}") from error


def write_config(values: Mapping[str, Any], path: str | os.PathLike[str]) -> Path:
    """Write `values` (a configuration's fields; None left out) to a TOML file (atomically);
    returns the path."""
    target = Path(path)
    lines = [HEADER]
    for key, value in values.items():
        if value is not None:
            lines.append(f"{key} = {toml_value(value)}\n")
    with atomic_path(target) as tmp:
        tmp.write_text("".join(lines), encoding="utf-8")
    return target


def toml_value(value: Any) -> str:
    """One TOML value: booleans before integers (bool is an int in Python), floats by repr."""
    if isinstance(value, bool):
        return "true" if value else "false"
    if isinstance(value, int):
        return str(value)
    if isinstance(value, float):
        if not math.isfinite(value):
            raise ValueError(f"cannot write a non-finite number ({value}) to a sensor file")
        return repr(value)
    if isinstance(value, str):
        escaped = value.replace("\\", "\\\\").replace('"', '\\"')
        return f'"{escaped}"'
    raise ValueError(f"cannot write a {type(value).__name__} to a sensor file")
