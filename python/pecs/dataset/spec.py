"""Dataset specs (TOML): sequences of scenes, each with settings and sensor parameters drawn
from stated distributions, expanded into one `SequenceTask` per sequence.

Layout: `[dataset]` (name, seed, retries), `[defaults]` (Simulation settings for every sequence:
duration_s, rate_hz, spp, preset, `config`: a sensor file (`SensorConfig.from_file`, relative to
the spec) whose fields are the base of the sensor and whose preset is the preset unless one is
stated, and a `sensor` table of fixed sensor fields and film size, which override the file's),
`[draw]` (sensor fields drawn per sequence, `pecs.dataset.distributions`), `[scene]` (a scene
generator and its `[scene.draw]` ranges, `pecs.dataset.generators`: the scene of every sequence
that names none), and `[[sequences]]` (scene: a scene file, a built-in name or a generator
table; optional name, count, its own settings, `sensor` and `draw`). `pecs dataset example`
prints a commented one. Every error names the file and the key.
"""

from __future__ import annotations

import dataclasses
import math
import os
import re
import sys
from dataclasses import dataclass
from pathlib import Path
from typing import Any

import numpy as np

from pecs.config import SensorConfig
from pecs.dataset import generators
from pecs.dataset.distributions import Distribution, parse_distribution
from pecs.ground_truth.imu_noise import IMU_MODELS
from pecs.ground_truth.layout import parse_kinds
from pecs.render import limits
from pecs.render.scene_file import builtin_scenes
from pecs.render.simulation import config_overrides

if sys.version_info >= (3, 11):
    import tomllib
else:  # pragma: no cover - Python 3.10
    import tomli as tomllib

_EXAMPLE = Path(__file__).with_name("example.toml")
# A sequence name is a folder name in the output (`sequence=NAME`): no separators, no `=`.
_NAME = re.compile(r"[A-Za-z0-9][A-Za-z0-9_.-]*")
_SETTINGS = {
    "duration_s": float,
    "rate_hz": float,
    "spp": int,
    "preset": str,
    # pecs.Simulation's ground truth ("all" or "depth,flow,..."; pecs.read_ground_truth reads
    # it from runs/NAME), and the IMU's rate.
    "ground_truth": str,
    "imu_rate_hz": float,
    # A real IMU's readings next to the ideal IMU (a named model, pecs.ground_truth.imu_noise;
    # its noise seeded by the sequence's seed): "mpu6500" (DAVIS346), "bmi160" (DVXplorer).
    "imu_model": str,
}
_FILM_KEYS = ("width", "height", "pixel_pitch_um", "fill_factor")
# The seed of each sequence is drawn, not set: it must differ between sequences.
_SENSOR_KEYS = tuple(
    sorted(
        {f.name for f in dataclasses.fields(SensorConfig)} - {"preset_name", "seed"}
        | set(_FILM_KEYS)
    )
)
_MAX_SEED = 2**31
_RANGES = {
    "duration_s": limits.duration_problem,
    "rate_hz": limits.rate_problem,
    "imu_rate_hz": limits.rate_problem,
    "spp": limits.spp_problem,
}


@dataclass(frozen=True)
class SequenceTask:
    """Everything one sequence needs, drawn already: picklable, sent to a worker as it is."""

    name: str
    index: int
    #: A built-in scene name or an absolute scene file path ("generator:NAME" for a drawn scene).
    scene: str
    #: Render and sensor seed, drawn from the dataset seed and `index`.
    seed: int
    #: Simulation keyword arguments (duration_s, rate_hz, spp, preset) set for this sequence.
    settings: dict[str, Any]
    #: Fixed sensor fields and film size.
    sensor: dict[str, Any]
    #: Sensor fields drawn for this sequence.
    drawn: dict[str, Any]
    #: The scene as the spec names it (a path relative to the spec's folder, or a built-in).
    scene_in_spec: str = ""
    #: Where in the spec each setting and sensor field came from ("spec.toml: draw.theta_on"),
    #: so that a value the simulation refuses is blamed on the spec's key that produced it.
    origins: dict[str, str] = dataclasses.field(default_factory=dict)
    #: The scene generator that draws this sequence's scene (`pecs.dataset.generators`), or "".
    generator: str = ""
    #: Its `[scene.draw]` ranges, checked and completed with its defaults.
    scene_draw: dict[str, Any] = dataclasses.field(default_factory=dict)
    #: The dataset's seed: a generated scene is drawn from (dataset seed, index) alone.
    dataset_seed: int = 0

    def record(self) -> dict[str, Any]:
        """What identifies the sequence's output: a rerun with another record must not reuse
        it. The scene as the spec names it, so that a moved project folder still resumes; a
        generated one by its generator and ranges (with the index and dataset seed, its draw)."""
        scene: Any = self.scene_in_spec or self.scene
        if self.generator:
            scene = {"generator": self.generator, "draw": self.scene_draw}
        return {
            "name": self.name,
            "index": self.index,
            "scene": scene,
            "seed": self.seed,
            "settings": self.settings,
            "sensor": self.sensor,
            "drawn": self.drawn,
        }


@dataclass(frozen=True)
class DatasetSpec:
    """A read dataset spec: its text (kept in the manifest) and its sequences, drawn."""

    name: str
    seed: int
    retries: int
    text: str
    path: Path | None
    sequences: tuple[SequenceTask, ...]


def example_spec_text() -> str:
    """The commented example spec that `pecs dataset example` prints."""
    return _EXAMPLE.read_text()


def load_spec(
    path: str | os.PathLike[str], sensor_config: SensorConfig | None = None
) -> DatasetSpec:
    """Read a spec file; scene and sensor-file paths in it are relative to its folder.
    `sensor_config` (`pecs dataset run --config`) replaces every `config` key of the spec."""
    file = Path(path)
    if not file.is_file():
        raise FileNotFoundError(f"dataset spec not found: {file}")
    return parse_spec(file.read_text(), file, sensor_config)


def parse_spec(
    text: str, path: Path | None = None, sensor_config: SensorConfig | None = None
) -> DatasetSpec:
    """A spec from its TOML text; `path` names it in errors and anchors relative scene and
    sensor-file paths. `sensor_config`, when given, is every sequence's base sensor in place of
    the spec's `config` keys (its `sensor` tables and draws still apply over it)."""
    where = f"{path}: " if path else "dataset spec: "
    try:
        doc = tomllib.loads(text)
    except tomllib.TOMLDecodeError as error:
        raise ValueError(f"{where}not valid TOML ({error})") from error
    _reject_unknown(doc, ("dataset", "defaults", "draw", "scene", "sequences"), where)
    head = _table(doc, "dataset", where)
    _reject_unknown(head, ("name", "seed", "retries"), f"{where}dataset.")
    name = _get(head, "name", str, f"{where}dataset.", "dataset")
    seed = _count(head, "seed", f"{where}dataset.", default=0)
    retries = _count(head, "retries", f"{where}dataset.", default=1)
    base = path.parent if path else Path.cwd()
    defaults_table = _table(doc, "defaults", where)
    if sensor_config is not None:  # in place of the spec's own file, which is not read
        defaults_table = {k: v for k, v in defaults_table.items() if k != "config"}
    defaults = _settings(defaults_table, f"{where}defaults.", base)
    if sensor_config is not None:
        defaults["config"] = sensor_config
        # The sensor chosen on the command line sets the film's pixel pitch too; a sequence's
        # own `preset` still wins.
        if sensor_config.known_preset is not None:
            defaults["preset"] = sensor_config.known_preset
    draws = _draws(_table(doc, "draw", where), f"{where}draw.")
    # The generated scene of every sequence that names no scene of its own.
    default_scene = _generated(doc["scene"], f"{where}scene") if "scene" in doc else None
    entries = doc.get("sequences")
    if not isinstance(entries, list) or not entries:
        raise ValueError(f"{where}sequences: give at least one [[sequences]] table")
    tasks: list[SequenceTask] = []
    for i, entry in enumerate(entries):
        if sensor_config is not None and isinstance(entry, dict):
            entry = {k: v for k, v in entry.items() if k != "config"}
        tasks += _expand(
            entry,
            f"{where}sequences[{i}].",
            where,
            defaults,
            draws,
            base,
            seed,
            len(tasks),
            default_scene,
        )
    _check_unique([t.name for t in tasks], f"{where}sequences")
    return DatasetSpec(name, seed, retries, text, path, tuple(tasks))


def _expand(
    entry: Any,
    where: str,
    root: str,
    defaults: dict[str, Any],
    draws: dict[str, Distribution],
    base: Path,
    dataset_seed: int,
    first_index: int,
    default_scene: generators.SceneGenerator | None = None,
) -> list[SequenceTask]:
    """One `[[sequences]]` entry as `count` tasks, numbered on from `first_index`; an entry
    without a scene has `default_scene` (the spec's `[scene]` generator)."""
    if not isinstance(entry, dict):
        raise ValueError(f"{where[:-1]}: expected a table, got {entry!r}")
    _reject_unknown(
        entry, ("scene", "name", "count", "draw", "sensor", "config", *_SETTINGS), where
    )
    generator = _sequence_generator(entry, where, default_scene)
    if generator is None:
        scene_in_spec = _get(entry, "scene", str, where)
        scene = _scene(scene_in_spec, base, f"{where}scene")
        name = _get(entry, "name", str, where, Path(scene).stem)
    else:
        scene_in_spec, scene = "", f"generator:{generator.name}"
        name = _get(entry, "name", str, where, generator.name)
    count = _count(entry, "count", where, default=1)
    if count < 1:
        raise ValueError(f"{where}count: must be at least 1, got {count}")
    own = _settings(
        {k: v for k, v in entry.items() if k in (*_SETTINGS, "sensor", "config")}, where, base
    )
    settings = {**defaults, **own}
    # A sequence's own sensor file replaces the defaults' file; the sensor tables go over it.
    file_config = settings.pop("config", None)
    from_file = sensor_fields(file_config) if file_config is not None else {}
    if file_config is not None and "preset" not in settings and file_config.known_preset:
        # The file's preset sets what the fields do not (the film's pixel pitch), as in
        # `pecs simulate --config`; a stated `preset` wins, as --preset does there.
        settings["preset"] = file_config.known_preset
    sensor = {**from_file, **defaults.get("sensor", {}), **own.get("sensor", {})}
    settings.pop("sensor", None)
    own_draws = _draws(entry.get("draw", {}), f"{where}draw.")
    all_draws = {**draws, **own_draws}
    origins = _origins(root, where, defaults, own, own_draws)
    origins.update({key: f"{root}draw.{key}" for key in draws.keys() - own_draws.keys()})
    names = [name] if count == 1 else [f"{name}-{k}" for k in range(count)]
    for sequence_name in names:
        if not _NAME.fullmatch(sequence_name):
            raise ValueError(
                f"{where}name: {sequence_name!r} is not a usable folder name "
                "(letters, digits, '_', '.', '-'; starting with a letter or digit)"
            )
    return [
        dataclasses.replace(
            _drawn_task(n, first_index + k, scene, settings, sensor, all_draws, dataset_seed),
            scene_in_spec=scene_in_spec,
            origins=origins,
            generator=generator.name if generator is not None else "",
            scene_draw=generator.ranges if generator is not None else {},
            dataset_seed=dataset_seed,
        )
        for k, n in enumerate(names)
    ]


def _sequence_generator(
    entry: dict[str, Any], where: str, default: generators.SceneGenerator | None
) -> generators.SceneGenerator | None:
    """The generator of an entry's scene: its own `scene` table, else the spec's `[scene]` when
    it names no scene; None for a scene file or built-in scene."""
    if "scene" not in entry:
        if default is None:
            raise ValueError(f"{where}scene: missing required key (or give a [scene] generator)")
        return default
    if isinstance(entry["scene"], dict):
        return _generated(entry["scene"], f"{where}scene")
    return None


def _generated(table: Any, where: str) -> generators.SceneGenerator:
    """A `scene` table: `generator = NAME` and its `draw` ranges, checked."""
    if not isinstance(table, dict):
        raise ValueError(f"{where}: expected a table (generator = ..., draw = ...), got {table!r}")
    _reject_unknown(table, ("generator", "draw"), f"{where}.")
    name = _get(table, "generator", str, f"{where}.")
    return generators.make_generator(name, table.get("draw", {}), where)


def _origins(
    root: str,
    where: str,
    defaults: dict[str, Any],
    own: dict[str, Any],
    own_draws: dict[str, Distribution],
) -> dict[str, str]:
    """The spec key of each setting and sensor field of a sequence, in `_expand`'s order of
    precedence: the sensor file (its own or the defaults'), then defaults.sensor, own sensor,
    and the draws (those of `[draw]` are added by the caller)."""
    origins: dict[str, str] = {}
    for table, at in ((defaults, f"{root}defaults."), (own, where)):
        origins.update({key: f"{at}{key}" for key in table if key in _SETTINGS})
    config_at = where if "config" in own else f"{root}defaults."
    config = own.get("config", defaults.get("config"))
    if config is not None:
        origins.update({key: f"{config_at}config" for key in sensor_fields(config)})
    for table, at in ((defaults, f"{root}defaults."), (own, where)):
        origins.update({key: f"{at}sensor.{key}" for key in table.get("sensor", {})})
    origins.update({key: f"{where}draw.{key}" for key in own_draws})
    return origins


def _drawn_task(
    name: str,
    index: int,
    scene: str,
    settings: dict[str, Any],
    sensor: dict[str, Any],
    draws: dict[str, Distribution],
    dataset_seed: int,
) -> SequenceTask:
    """The sequence's seed and draws, from a generator of (dataset seed, index) alone: the same
    whichever worker runs it, in whichever order. Draws go in name order, not file order."""
    rng = np.random.default_rng([dataset_seed, index])
    seed = int(rng.integers(0, _MAX_SEED))
    drawn = {key: draws[key].draw(rng) for key in sorted(draws)}
    return SequenceTask(name, index, scene, seed, dict(settings), dict(sensor), drawn)


def _scene(scene: str, base: Path, where: str) -> str:
    """A built-in scene name as it is; a file as its absolute path (workers run elsewhere)."""
    candidate = base / scene
    if candidate.is_file():
        return str(candidate.resolve())
    if scene in builtin_scenes():
        return scene
    raise ValueError(
        f"{where}: no scene file {candidate} and no built-in scene {scene!r} "
        f"(built-in: {', '.join(builtin_scenes())})"
    )


def sensor_fields(config: SensorConfig) -> dict[str, Any]:
    """A sensor file's configuration as a sequence's fixed sensor fields: all but its seed
    (each sequence's is drawn) and its preset name (a record, not a field to simulate)."""
    return {name: value for name, value in config_overrides(config).items() if name != "seed"}


def _sensor_file(table: dict[str, Any], base: Path, where: str) -> SensorConfig:
    """The sensor file that `config` names (relative to the spec's folder)."""
    file = base / _get(table, "config", str, where)
    try:
        return SensorConfig.from_file(file)
    except (OSError, ValueError) as error:
        raise ValueError(f"{where}config: cannot use sensor file {file}: {error}") from None


def _settings(table: dict[str, Any], where: str, base: Path) -> dict[str, Any]:
    _reject_unknown(table, (*_SETTINGS, "sensor", "config"), where)
    settings: dict[str, Any] = {}
    for key, kind in _SETTINGS.items():
        if key in table:
            settings[key] = _get(table, key, kind, where)
    if settings.get("preset", SensorConfig.PRESETS[0]) not in SensorConfig.PRESETS:
        raise ValueError(
            f"{where}preset: unknown sensor preset {settings['preset']!r}; "
            f"choose one of {', '.join(SensorConfig.PRESETS)}"
        )
    if "ground_truth" in settings:
        try:
            parse_kinds(settings["ground_truth"])
        except ValueError as error:
            raise ValueError(f"{where}{error}") from None
    if settings.get("imu_model", next(iter(IMU_MODELS))) not in IMU_MODELS:
        raise ValueError(
            f"{where}imu_model: unknown IMU model {settings['imu_model']!r}; "
            f"choose one of {', '.join(IMU_MODELS)}"
        )
    for key, problem in _RANGES.items():
        if key not in settings:
            continue
        if not settings[key] > 0:
            raise ValueError(f"{where}{key}: must be positive, got {settings[key]}")
        reason = problem(settings[key])  # the ranges of pecs.Simulation, before any sequence
        if reason is not None:
            raise ValueError(f"{where}{key}: {reason}")
    if "sensor" in table:
        sensor = table["sensor"]
        if not isinstance(sensor, dict):
            raise ValueError(f"{where}sensor: expected a table, got {sensor!r}")
        _reject_unknown(sensor, _SENSOR_KEYS, f"{where}sensor.")
        settings["sensor"] = dict(sensor)
    if "config" in table:
        settings["config"] = _sensor_file(table, base, where)
    return settings


def _draws(table: Any, where: str) -> dict[str, Distribution]:
    if not isinstance(table, dict):
        raise ValueError(f"{where[:-1]}: expected a table, got {table!r}")
    _reject_unknown(table, _SENSOR_KEYS, where)
    return {key: parse_distribution(value, f"{where}{key}") for key, value in table.items()}


def _table(doc: dict[str, Any], key: str, where: str) -> dict[str, Any]:
    value = doc.get(key, {})
    if not isinstance(value, dict):
        raise ValueError(f"{where}{key}: expected a table, got {value!r}")
    return value


def _get(table: dict[str, Any], key: str, kind: type, where: str, default: Any = ...) -> Any:
    if key not in table:
        if default is ...:
            raise ValueError(f"{where}{key}: missing required key")
        return default
    value = table[key]
    if kind is float and isinstance(value, int) and not isinstance(value, bool):
        value = float(value)
    if isinstance(value, bool) or not isinstance(value, kind):
        raise ValueError(f"{where}{key}: expected {kind.__name__}, got {value!r}")
    if isinstance(value, float) and not math.isfinite(value):
        raise ValueError(f"{where}{key}: must be finite, got {value}")
    return value


def _count(table: dict[str, Any], key: str, where: str, default: int) -> int:
    value = _get(table, key, int, where, default)
    if value < 0:
        raise ValueError(f"{where}{key}: must be >= 0, got {value}")
    return value


def _reject_unknown(table: dict[str, Any], known: tuple[str, ...], where: str) -> None:
    unknown = sorted(set(table) - set(known))
    if unknown:
        raise ValueError(f"{where}{unknown[0]}: unknown key (known: {', '.join(sorted(known))})")


def _check_unique(names: list[str], where: str) -> None:
    seen: set[str] = set()
    for name in names:
        if name in seen:
            raise ValueError(f"{where}: two sequences are named {name!r}; give them names")
        seen.add(name)
