"""Sensor biases mapped to the pixel model's parameters: DAVIS346 coarse/fine biases (libcaer)
and Sony IMX636 / Prophesee EVK4 bias offsets (OpenEB), each mapped to theta_on, theta_off,
cutoff_hz and refractory_us with the range the mapping's constants allow. The relations, their
constants and sources are in docs/biases.md.

    >>> mapping = map_biases("davis346", {"OnBn": "5/255"})
    >>> config = config_from_biases("imx636", {"bias_diff_on": 20})
"""

from __future__ import annotations

import os
from collections.abc import Mapping
from pathlib import Path
from typing import TYPE_CHECKING, Any

from pecs._atomic import atomic_path
from pecs.biases._mapping import BiasMapping, Estimate
from pecs.biases.davis import DAVIS346_DEFAULTS, coarse_fine_current_pa, davis346_mapping
from pecs.biases.imx636 import IMX636_DEFAULTS, IMX636_RANGES, imx636_mapping
from pecs.config_file import BIASES_TABLE, HEADER, toml_value

if TYPE_CHECKING:
    from pecs.config import SensorConfig

__all__ = [
    "BIAS_SENSORS",
    "DAVIS346_DEFAULTS",
    "IMX636_DEFAULTS",
    "IMX636_RANGES",
    "BiasMapping",
    "Estimate",
    "coarse_fine_current_pa",
    "config_from_biases",
    "map_biases",
    "write_bias_file",
]

_MAPPINGS = {"davis346": davis346_mapping, "imx636": imx636_mapping}
#: The sensors whose biases pecs maps (each is also a preset of that name).
BIAS_SENSORS = tuple(_MAPPINGS)


def map_biases(sensor: str, biases: Mapping[str, Any]) -> BiasMapping:
    """The biases of `sensor` ("davis346": {"OnBn": "5/255", ...}; "imx636": {"bias_diff_on": 20,
    ...}) mapped to SensorConfig fields with their ranges; biases not given take the sensor's
    defaults. A ValueError names a bias that is unknown or out of its range."""
    from pecs.config import SensorConfig

    if sensor not in _MAPPINGS:
        raise ValueError(f"sensor {sensor!r}: pecs maps the biases of {', '.join(BIAS_SENSORS)}")
    mapping = _MAPPINGS[sensor](biases)
    try:  # the model's own ranges, checked where the biases are named
        SensorConfig.preset(sensor, **mapping.fields)
    except ValueError as error:
        raise ValueError(_out_of_model(mapping, str(error))) from error
    return mapping


def _out_of_model(mapping: BiasMapping, error: str) -> str:
    """The model's range error, with the biases that set the field named."""
    field = error.partition(":")[0]
    estimate = mapping.parameters.get(field)
    if estimate is None:
        return f"the biases map outside the pixel model's range: {error}"
    settings = ", ".join(f"{b} {mapping.biases[b]}" for b in estimate.set_by.split(", "))
    return f"{settings} give {field} = {estimate.value:.4g}, outside the model's range ({error})"


def config_from_biases(sensor: str, biases: Mapping[str, Any], **overrides: Any) -> SensorConfig:
    """The `sensor` preset with the fields its biases map to, and `overrides` over both."""
    from pecs.config import SensorConfig

    return SensorConfig.preset(sensor, **{**map_biases(sensor, biases).fields, **overrides})


def write_bias_file(mapping: BiasMapping, path: str | os.PathLike[str]) -> Path:
    """A sensor file (`SensorConfig.from_file` reads it) of the mapping's biases: the preset and a
    `[biases]` table, with the mapped fields and their ranges as comments. Written atomically."""
    lines = [HEADER, "# Biases mapped by pecs.biases (docs/biases.md); each field, its range:\n"]
    for name, e in mapping.parameters.items():
        lines.append(f"#   {name} = {e.value:.4g} ({e.low:.4g} to {e.high:.4g})\n")
    for name, why in mapping.unmapped.items():
        lines.append(f"#   {name}: not mapped: {why}\n")
    lines.append(f"preset_name = {toml_value(mapping.sensor)}\n\n[{BIASES_TABLE}]\n")
    lines.append(f"sensor = {toml_value(mapping.sensor)}\n")
    lines += [f"{name} = {toml_value(value)}\n" for name, value in mapping.biases.items()]
    target = Path(path)
    with atomic_path(target) as tmp:
        tmp.write_text("".join(lines), encoding="utf-8")
    return target
