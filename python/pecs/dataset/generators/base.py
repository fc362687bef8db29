"""What a scene generator is: named draw ranges checked when a spec is read, a description drawn
from one random generator (numbers only, no files), and the scene files written from it."""

from __future__ import annotations

from abc import ABC, abstractmethod
from dataclasses import dataclass, field
from pathlib import Path
from typing import Any, ClassVar

import numpy as np

from pecs.dataset.generators.ranges import Draws, Parameter, parse_draws

#: A sequence's duration when its spec states none (and the scene file's).
DEFAULT_DURATION_S = 0.5


@dataclass(frozen=True)
class SceneSettings:
    """What the written scene file states besides the scene: so that `pecs simulate FILE` renders
    the sequence again as the dataset did (ground truth and the IMU rate are the command's)."""

    duration_s: float = DEFAULT_DURATION_S
    #: Fixed stepping; None: adaptive between `ADAPTIVE_RATES_HZ` (as the shipped room scene).
    rate_hz: float | None = None
    spp: int = 16
    preset: str = "davis346"
    seed: int = 0
    #: Sensor fields and film size (a dataset's fixed and drawn fields).
    sensor: dict[str, Any] = field(default_factory=dict)


class SceneGenerator(ABC):
    """A family of scenes. Subclasses set `parameters` (the `[scene.draw]` keys, their laws and
    default ranges) and implement `describe` and `write`; `register` makes them nameable."""

    name: ClassVar[str] = ""
    parameters: ClassVar[dict[str, Parameter]] = {}

    def __init__(self, draw: dict[str, Any] | None = None, where: str = "scene.draw") -> None:
        #: Every parameter's range or names (defaults where the spec gives none).
        self.ranges = parse_draws({} if draw is None else draw, self.parameters, where)
        self.check(where)

    def check(self, where: str) -> None:  # noqa: B027 (an optional hook, not abstract)
        """Refuse ranges that cannot make a scene together (ValueError naming the keys)."""

    def draws(self, rng: np.random.Generator) -> Draws:
        return Draws(self.ranges, self.parameters, rng)

    @abstractmethod
    def describe(self, rng: np.random.Generator, duration_s: float) -> dict[str, Any]:
        """Every drawn value of one scene, as JSON-able data; nothing is rendered or written."""

    @abstractmethod
    def write(self, description: dict[str, Any], folder: Path, settings: SceneSettings) -> Path:
        """The scene files of a description in `folder` (scene TOML, Mitsuba XML, meshes,
        textures); the scene TOML's path."""
