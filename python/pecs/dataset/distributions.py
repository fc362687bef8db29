"""Distributions of the per-sequence parameter draws of a dataset spec (`[draw]` tables).

Each is a one-key TOML table: `{ uniform = [min, max] }`, `{ log_uniform = [min, max] }` (uniform
in the logarithm: every decade equally likely), `{ normal = [mean, std] }`, `{ choice = [...] }`.
"""

from __future__ import annotations

import math
from dataclasses import dataclass
from typing import Any

import numpy as np

KINDS = ("uniform", "log_uniform", "normal", "choice")


@dataclass(frozen=True)
class Distribution:
    """One parameter's distribution, checked when the spec is read."""

    kind: str
    arguments: tuple[Any, ...]

    def draw(self, rng: np.random.Generator) -> Any:
        """One value, as a plain Python number (or the chosen item)."""
        if self.kind == "uniform":
            low, high = self.arguments
            return float(rng.uniform(low, high))
        if self.kind == "log_uniform":
            low, high = self.arguments
            return float(math.exp(rng.uniform(math.log(low), math.log(high))))
        if self.kind == "normal":
            mean, std = self.arguments
            return float(rng.normal(mean, std))
        return self.arguments[int(rng.integers(len(self.arguments)))]

    def as_dict(self) -> dict[str, list[Any]]:
        return {self.kind: list(self.arguments)}


def parse_distribution(value: Any, where: str) -> Distribution:
    """A `[draw]` entry as a Distribution; a ValueError naming `where` for anything else."""
    if not isinstance(value, dict) or len(value) != 1:
        raise ValueError(
            f"{where}: expected a table with one of {', '.join(KINDS)}, e.g. "
            f"{{ uniform = [0.1, 0.3] }}, got {value!r}"
        )
    ((kind, arguments),) = value.items()
    if kind not in KINDS:
        raise ValueError(f"{where}: unknown distribution {kind!r}; known: {', '.join(KINDS)}")
    if not isinstance(arguments, list):
        raise ValueError(f"{where}.{kind}: expected a list, got {arguments!r}")
    if kind == "choice":
        if not arguments:
            raise ValueError(f"{where}.choice: needs at least one value")
        return Distribution(kind, tuple(arguments))
    numbers = _two_numbers(arguments, f"{where}.{kind}")
    _check_range(kind, numbers, f"{where}.{kind}")
    return Distribution(kind, numbers)


def _two_numbers(arguments: list[Any], where: str) -> tuple[float, float]:
    if len(arguments) != 2 or not all(
        isinstance(a, (int, float)) and not isinstance(a, bool) and math.isfinite(a)
        for a in arguments
    ):
        raise ValueError(f"{where}: expected two finite numbers, got {arguments!r}")
    return float(arguments[0]), float(arguments[1])


def _check_range(kind: str, numbers: tuple[float, float], where: str) -> None:
    first, second = numbers
    if kind == "normal":
        if second < 0:
            raise ValueError(f"{where}: the standard deviation must be >= 0, got {second}")
        return
    if first > second:
        raise ValueError(f"{where}: min {first} is above max {second}")
    if kind == "log_uniform" and first <= 0:
        raise ValueError(f"{where}: the bounds must be positive, got {first}")
