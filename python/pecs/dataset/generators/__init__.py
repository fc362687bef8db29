"""Scene generators: families of scenes a dataset spec names and draws, a scene per sequence.

```toml
[scene]
generator = "objects"
[scene.draw]
object_count = [2, 6]
illuminance_lux = [100, 10000]
```

Generators are registered by name, as Mitsuba registers plugins: `register("objects",
ObjectsGenerator)`; a spec's `generator = NAME` picks one. A sequence's scene is drawn from
`numpy.random.default_rng([dataset seed, index, SCENE_STREAM])` alone (its own stream, so the
sensor draws do not move it), so the same spec and index give the same scene, bit for bit, on any
worker. `describe_scene` draws the numbers (fast, no files); `write_scene` writes the scene file,
Mitsuba XML, meshes and textures, which the dataset keeps in `runs/NAME/scene/`.
"""

from __future__ import annotations

import hashlib
import json
from pathlib import Path
from typing import TYPE_CHECKING, Any

import numpy as np

from pecs.dataset.generators.base import DEFAULT_DURATION_S, SceneGenerator, SceneSettings
from pecs.dataset.generators.driving import DrivingGenerator
from pecs.dataset.generators.objects import ObjectsGenerator

if TYPE_CHECKING:
    from pecs.dataset.spec import SequenceTask

#: Appended to (dataset seed, index): the scene's random stream, apart from the sensor draws'.
SCENE_STREAM = 1
#: The folder of a sequence's scene files, in its run folder.
SCENE_FOLDER = "scene"
_REGISTRY: dict[str, type[SceneGenerator]] = {}


def register(name: str, generator: type[SceneGenerator]) -> None:
    """Make `generator` the one a spec's `generator = name` picks."""
    if not isinstance(generator, type) or not issubclass(generator, SceneGenerator):
        raise TypeError(f"{name}: a scene generator must subclass SceneGenerator")
    if not name.isidentifier():
        raise ValueError(f"{name!r}: a generator name is letters, digits and '_'")
    _REGISTRY[name] = generator


def names() -> list[str]:
    """The registered generators' names."""
    return sorted(_REGISTRY)


def make_generator(
    name: str, draw: dict[str, Any] | None = None, where: str = "scene"
) -> SceneGenerator:
    """The generator `name` with its `[scene.draw]` ranges checked (errors name `where`)."""
    if name not in _REGISTRY:
        raise ValueError(
            f"{where}.generator: unknown scene generator {name!r} (known: {', '.join(names())})"
        )
    return _REGISTRY[name](draw, f"{where}.draw")


def scene_rng(dataset_seed: int, index: int) -> np.random.Generator:
    """The random generator of sequence `index`'s scene."""
    return np.random.default_rng([dataset_seed, index, SCENE_STREAM])


def describe_scene(
    generator: str,
    draw: dict[str, Any],
    dataset_seed: int,
    index: int,
    duration_s: float = DEFAULT_DURATION_S,
) -> dict[str, Any]:
    """The drawn description of sequence `index`'s scene (no files)."""
    return make_generator(generator, draw).describe(scene_rng(dataset_seed, index), duration_s)


def description_hash(description: dict[str, Any]) -> str:
    """SHA-256 of a description's canonical JSON: equal hashes, equal scenes."""
    text = json.dumps(description, sort_keys=True, separators=(",", ":"))
    return hashlib.sha256(text.encode()).hexdigest()


def task_settings(task: SequenceTask) -> SceneSettings:
    """The settings a dataset simulates a sequence with, for its scene file."""
    settings = task.settings
    return SceneSettings(
        duration_s=float(settings.get("duration_s", DEFAULT_DURATION_S)),
        rate_hz=settings.get("rate_hz"),
        spp=int(settings.get("spp", SceneSettings.spp)),
        preset=str(settings.get("preset", SceneSettings.preset)),
        seed=task.seed,
        sensor={**task.sensor, **task.drawn},
    )


def describe_task_scene(task: SequenceTask) -> dict[str, Any]:
    """The drawn description of a generated sequence's scene."""
    duration_s = task_settings(task).duration_s
    return describe_scene(
        task.generator, task.scene_draw, task.dataset_seed, task.index, duration_s
    )


def write_task_scene(task: SequenceTask, folder: Path) -> Path:
    """Write a generated sequence's scene files into `folder`; the scene TOML's path."""
    generator = make_generator(task.generator, task.scene_draw)
    settings = task_settings(task)
    description = generator.describe(scene_rng(task.dataset_seed, task.index), settings.duration_s)
    return generator.write(description, folder, settings)


register("objects", ObjectsGenerator)
register("driving", DrivingGenerator)

__all__ = [
    "SCENE_FOLDER",
    "DrivingGenerator",
    "ObjectsGenerator",
    "SceneGenerator",
    "SceneSettings",
    "describe_scene",
    "describe_task_scene",
    "description_hash",
    "make_generator",
    "names",
    "register",
    "scene_rng",
    "write_task_scene",
]
