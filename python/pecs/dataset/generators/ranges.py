"""The `[scene.draw]` ranges of a scene generator: checked when the spec is read, drawn per
sequence.

Each parameter has a fixed law, so that a spec states only its range: `[min, max]` for numbers
(uniform, uniform in the logarithm for scale-like quantities, or whole numbers) and a list of
names for choices (each equally likely). The law is the generator's documentation, not the
spec's: `illuminance_lux = [1, 100000]` is log-uniform (every decade equally likely).
"""

from __future__ import annotations

import math
from dataclasses import dataclass
from typing import Any

import numpy as np

LAWS = ("uniform", "log_uniform", "integer", "choice")


@dataclass(frozen=True)
class Parameter:
    """One drawn parameter: its law, default range (or names) and the values it may take."""

    law: str
    default: tuple[Any, ...]
    #: Inclusive bounds of any range a spec may give (numbers), or the known names (choice).
    lowest: float = -math.inf
    highest: float = math.inf
    names: tuple[str, ...] = ()
    #: One line for the documentation and error messages: what the value is.
    meaning: str = ""


def parse_draws(table: Any, parameters: dict[str, Parameter], where: str) -> dict[str, list[Any]]:
    """The spec's `[scene.draw]` table checked against `parameters`, over their defaults: every
    parameter's range (`[min, max]`) or names, as plain lists (they go into the manifest)."""
    if not isinstance(table, dict):
        raise ValueError(f"{where}: expected a table of ranges, got {table!r}")
    unknown = sorted(set(table) - set(parameters))
    if unknown:
        raise ValueError(
            f"{where}.{unknown[0]}: unknown key (known: {', '.join(sorted(parameters))})"
        )
    ranges = {}
    for key, parameter in parameters.items():
        value = table.get(key, list(parameter.default))
        ranges[key] = _checked(value, parameter, f"{where}.{key}")
    return ranges


def _checked(value: Any, parameter: Parameter, where: str) -> list[Any]:
    if parameter.law == "choice":
        return _names(value, parameter, where)
    if (
        not isinstance(value, list)
        or len(value) != 2
        or not all(_is_number(v) and math.isfinite(v) for v in value)
    ):
        raise ValueError(f"{where}: expected [min, max], two finite numbers, got {value!r}")
    low, high = value
    if parameter.law == "integer":
        if not all(isinstance(v, int) or float(v).is_integer() for v in value):
            raise ValueError(f"{where}: expected two whole numbers [min, max], got {value!r}")
        low, high = int(low), int(high)
    else:
        low, high = float(low), float(high)
    if low > high:
        raise ValueError(f"{where}: min {low} is above max {high}")
    if low < parameter.lowest or high > parameter.highest:
        raise ValueError(
            f"{where}: {parameter.meaning or 'the range'} must lie within "
            f"[{_shown(parameter.lowest)}, {_shown(parameter.highest)}], got [{low}, {high}]"
        )
    return [low, high]


def _names(value: Any, parameter: Parameter, where: str) -> list[str]:
    if not isinstance(value, list) or not value or not all(isinstance(v, str) for v in value):
        raise ValueError(f"{where}: expected a list of names, e.g. {list(parameter.default)}")
    for name in value:
        if name not in parameter.names:
            raise ValueError(
                f"{where}: unknown name {name!r} (known: {', '.join(parameter.names)})"
            )
    return list(value)


def _is_number(value: Any) -> bool:
    return isinstance(value, (int, float)) and not isinstance(value, bool)


def _shown(bound: float) -> str:
    return f"{bound:g}"


class Draws:
    """Values drawn from checked ranges with one generator, in the order the caller asks."""

    def __init__(
        self,
        ranges: dict[str, list[Any]],
        parameters: dict[str, Parameter],
        rng: np.random.Generator,
    ) -> None:
        self.ranges, self.parameters, self.rng = ranges, parameters, rng

    def value(self, key: str) -> float:
        """A number of a `uniform` or `log_uniform` parameter."""
        low, high = self.ranges[key]
        if self.parameters[key].law == "log_uniform":
            return float(math.exp(self.rng.uniform(math.log(low), math.log(high))))
        return float(self.rng.uniform(low, high))

    def integer(self, key: str) -> int:
        """A whole number of an `integer` parameter, min and max included."""
        low, high = self.ranges[key]
        return int(self.rng.integers(low, high, endpoint=True))

    def pick(self, key: str) -> str:
        """One of a `choice` parameter's names."""
        names = self.ranges[key]
        return str(names[int(self.rng.integers(len(names)))])
