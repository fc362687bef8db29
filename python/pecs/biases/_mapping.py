"""What a bias mapping returns: each model parameter with the range the mapping's constants
allow, and the biases that map to no parameter of the model, with why."""

from __future__ import annotations

from dataclasses import dataclass, field
from typing import Any


@dataclass(frozen=True)
class Estimate:
    """One model parameter mapped from biases: the value, and the low and high ends of what the
    spread of the mapping's constants allows (not a confidence interval: a stated range)."""

    value: float
    low: float
    high: float
    #: The relation and its constants, in a line (sources in docs/biases.md).
    relation: str
    #: The biases the value follows, as a user names them ("RefrBp", "bias_diff_on, bias_diff").
    set_by: str = ""

    def __post_init__(self) -> None:
        if not self.low <= self.value <= self.high:
            raise ValueError(f"estimate {self.value} outside its own range {self.low}-{self.high}")


@dataclass(frozen=True)
class BiasMapping:
    """Biases of one sensor mapped to `SensorConfig` fields."""

    #: The pecs preset of the sensor ("davis346", "imx636"): the fields not mapped come from it.
    sensor: str
    #: Every bias, the ones not given at their defaults, as a user writes them.
    biases: dict[str, Any]
    #: Mapped fields by SensorConfig field name.
    parameters: dict[str, Estimate]
    #: Biases (or effects) with no field in the model, and why.
    unmapped: dict[str, str] = field(default_factory=dict)

    @property
    def fields(self) -> dict[str, float]:
        """The mapped values by field name, as `SensorConfig.preset(sensor, **fields)` takes them."""
        return {name: estimate.value for name, estimate in self.parameters.items()}

    def to_dict(self) -> dict[str, Any]:
        """Plain data (for JSON): the biases, each field with its range and relation, the
        unmapped biases."""
        return {
            "sensor": self.sensor,
            "biases": dict(self.biases),
            "parameters": {
                name: {
                    "value": e.value,
                    "low": e.low,
                    "high": e.high,
                    "relation": e.relation,
                    "set_by": e.set_by,
                }
                for name, e in self.parameters.items()
            },
            "unmapped": dict(self.unmapped),
        }


def spread(value: float, factor_low: float, factor_high: float) -> tuple[float, float]:
    """The range value x [factor_low, factor_high]."""
    return value * factor_low, value * factor_high
