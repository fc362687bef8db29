"""Scene files (TOML): a Mitsuba scene plus animation, time stepping, sensor, optics, light.

Every error names the file and the key (`[time] duration_s`, `objects[1].keyframes[0].t_s`).
Lengths are metres in the scene, millimetres in the optics (`efl_mm`), times seconds (`t_s`).
"""

from __future__ import annotations

import dataclasses
import math
import os
import sys
from collections.abc import Callable
from dataclasses import dataclass, field
from pathlib import Path
from typing import Any
from xml.etree import ElementTree

import numpy as np

from pecs._data import scenes_dir
from pecs.ground_truth.imu_noise import ImuModel
from pecs.render import limits
from pecs.render.animation import (
    INTERPOLATIONS,
    Keyframe,
    Track,
    look_at_rotation,
    quaternion_from_axis_angle,
)
from pecs.render.flicker import LAMPS, WAVEFORMS, Flicker, depth_problem, frequency_problem
from pecs.render.trajectory_file import read_trajectory

if sys.version_info >= (3, 11):
    import tomllib
else:  # pragma: no cover - Python 3.10
    import tomli as tomllib

SENSOR_PRESETS = ("ideal", "esim", "davis346", "color_davis346", "dvxplorer", "imx636")
OPTICS_MODELS = ("pinhole", "thinlens")


@dataclass(frozen=True)
class TimeStepping:
    """Fixed rate, or adaptive between min and max rates (ESIM's rule)."""

    duration_s: float
    rate_hz: float | None = None
    min_rate_hz: float | None = None
    max_rate_hz: float | None = None
    threshold_fraction: float = 0.5
    #: What bounds an adaptive step: "measured" (the log change the frames show, ESIM's rule)
    #: or "exact" (the image motion the animation gives: no visible surface point moves more
    #: than threshold_fraction px a step; pecs.render.time_stepping.exact_step_us).
    motion: str = "measured"

    @property
    def adaptive(self) -> bool:
        return self.rate_hz is None


# What may bound an adaptive step (TimeStepping.motion).
STEP_MOTIONS = ("measured", "exact")


@dataclass(frozen=True)
class Optics:
    """Camera optics: `pinhole`, `thinlens`, or a realistic `lens` prescription by name.

    `f_number`: 2.0 unless given for pinhole (its radiometry) and thin lens; a lens left without
    one is wide open (its prescription's stop), not stopped to 2.0 or clamped from it."""

    model: str
    efl_mm: float | None = None
    fov_deg: float | None = None
    f_number: float | None = 2.0
    focus_m: float | None = None
    lens: str | None = None
    #: Lens ghosts (`ghosts = true` or a table of settings, pecs.render.lens_ghosts); None: off.
    ghosts: dict[str, Any] | None = None

    def as_dict(self) -> dict[str, Any]:
        return {k: v for k, v in self.__dict__.items() if v is not None}


@dataclass(frozen=True)
class Light:
    """Emitter spectrum (blackbody or file), scaled to an illuminance at a point."""

    illuminance_lux: float
    at: tuple[float, float, float]
    normal: tuple[float, float, float]
    temperature_k: float | None = None
    spectrum_file: Path | None = None
    #: Mains flicker of these lamps (`flicker = {...}`); None: steady.
    flicker: Flicker | None = None


@dataclass(frozen=True)
class EmitterLevel:
    """One emitter's level (`[[lights]]`): scaled to an illuminance at a point, or by a factor.

    `emitter_id` is the emitter's id, or for an area light the id of its shape."""

    emitter_id: str
    illuminance_lux: float | None = None
    at: tuple[float, float, float] | None = None
    normal: tuple[float, float, float] | None = None
    scale: float | None = None
    #: Mains flicker of this emitter (`flicker = {...}`); None: steady.
    flicker: Flicker | None = None


@dataclass(frozen=True)
class SceneSpec:
    """A validated scene file.

    The Mitsuba scene is `mitsuba_xml` (a file), or `mitsuba_dict` (Mitsuba's dict format, built
    in Python; `mitsuba_xml` is then None). Either way pecs brings its own sensor (film, sampler,
    reconstruction filter) and integrator: those of the scene are not used, except that the
    scene's first sensor gives the default camera pose and field of view.
    """

    path: Path
    mitsuba_xml: Path | None
    time: TimeStepping
    preset: str
    sensor_overrides: dict[str, Any]
    qe: str | None
    optics: Optics
    spp: int
    max_depth: int
    seed: int
    light: Light | None
    camera: Track | None
    objects: dict[str, Track] = field(default_factory=dict)
    write_frames: bool = False
    write_depth: bool = False
    lights: tuple[EmitterLevel, ...] = ()
    mitsuba_dict: dict[str, Any] | None = None
    #: The real IMU of `[imu]` (docs/ground-truth.md): what the IMU ground truth also reads.
    imu: ImuModel | None = None
    #: `[classes]`: shape id -> the class its ground truth names (pecs.ground_truth).
    classes: dict[str, str] = field(default_factory=dict)

    @property
    def name(self) -> str:
        return self.path.stem

    @property
    def mitsuba_name(self) -> str:
        """The Mitsuba scene's file name, or "scene dict" (for messages and metadata)."""
        return self.mitsuba_xml.name if self.mitsuba_xml is not None else "scene dict"


def builtin_scenes() -> list[str]:
    """Names of the scenes shipped in `pecs/scenes/` (`pecs simulate checkerboard` works)."""
    return sorted(p.stem for p in scenes_dir().glob("*.toml"))


def resolve_scene_path(scene: str | os.PathLike[str]) -> Path:
    """A scene file path, or the name of a built-in scene."""
    path = Path(scene)
    if path.is_file():
        return path
    builtin = scenes_dir() / f"{scene}.toml"
    if path.suffix == "" and builtin.is_file():
        return builtin
    raise FileNotFoundError(
        f"scene file not found: {scene} (built-in scenes: {', '.join(builtin_scenes())})"
    )


# The `path` of a scene given as a Python dict of settings (relative files resolve from the
# working directory).
SETTINGS_PATH = Path("settings")


def load_scene(
    scene: str | os.PathLike[str] | dict[str, Any],
    scene_dict: dict[str, Any] | None = None,
) -> SceneSpec:
    """Read and validate a scene file (or built-in scene name, or the same settings as a dict:
    `{"time": {"duration_s": 0.1, "rate_hz": 500}, "sensor": {...}, ...}`).

    `scene_dict`, a Mitsuba scene in Mitsuba's dict format, takes the place of `[scene] mitsuba`
    (which may then be left out); animated `[[objects]]` ids are keys of the dict.
    """
    if isinstance(scene, dict):
        path, doc = SETTINGS_PATH, scene
    else:
        path = resolve_scene_path(scene)
        try:
            doc = tomllib.loads(path.read_text())
        except tomllib.TOMLDecodeError as error:
            raise ValueError(f"{path}: not valid TOML ({error})") from error
    root = _Table(doc, f"{path}: ", "")
    spec = _parse(root, path, scene_dict is not None)
    root.reject_unknown()
    return spec if scene_dict is None else with_scene_dict(spec, scene_dict)


def resolve_scene(
    scene: str | os.PathLike[str] | SceneSpec | dict[str, Any],
    scene_dict: dict[str, Any] | None = None,
    camera: Track | None = None,
    objects: dict[str, Track] | None = None,
) -> SceneSpec:
    """A scene (file, built-in name, settings dict or SceneSpec) with the caller's Mitsuba dict and
    tracks in place of the file's; the animated ids are checked against the dict."""
    if not isinstance(scene, SceneSpec):
        scene = load_scene(scene, scene_dict)
    if camera is not None or objects:
        for name, track in [("camera", camera), *(objects or {}).items()]:
            if track is not None and not isinstance(track, Track):
                raise TypeError(f"{name}: expected a pecs Track, got {type(track).__name__}")
        scene = dataclasses.replace(
            scene,
            camera=camera if camera is not None else scene.camera,
            objects={**scene.objects, **(objects or {})},
        )
    scene_dict = scene_dict if scene_dict is not None else scene.mitsuba_dict
    return scene if scene_dict is None else with_scene_dict(scene, scene_dict)  # ids checked


def with_scene_dict(spec: SceneSpec, scene_dict: dict[str, Any]) -> SceneSpec:
    """`spec` with a Mitsuba scene dict in place of its XML, checked against the animation."""
    where = f"{spec.path}: scene_dict"
    if not isinstance(scene_dict, dict) or scene_dict.get("type") != "scene":
        raise ValueError(f'{where}: expected a Mitsuba scene dict ({{"type": "scene", ...}})')
    for key, value in scene_dict.items():
        if key != "type" and not _is_plugin(value):
            raise ValueError(
                f"{where}[{key!r}]: expected a plugin dict ({{'type': ...}}) or a Mitsuba object, "
                f"got {type(value).__name__}"
            )
    keys = sorted(k for k in scene_dict if k != "type")
    for object_id in spec.objects:
        if object_id not in scene_dict:
            raise ValueError(
                f"{spec.path}: objects id {object_id!r} is not a key of the scene dict (keys: {keys})"
            )
    return dataclasses.replace(spec, mitsuba_xml=None, mitsuba_dict=scene_dict)


def _is_plugin(value: Any) -> bool:
    """A nested plugin description, or an object Mitsuba made (a loaded shape, a bitmap)."""
    if isinstance(value, dict):
        return isinstance(value.get("type"), str)
    return type(value).__module__.startswith(("mitsuba", "drjit"))


class _Table:
    """A TOML table that remembers its name for error messages and which keys were read."""

    def __init__(self, data: dict[str, Any], prefix: str, name: str) -> None:
        self.data, self.prefix, self.name, self.read = data, prefix, name, set()

    def where(self, key: str) -> str:
        return f"{self.prefix}{self.name + '.' if self.name else ''}{key}"

    def has(self, key: str) -> bool:
        return key in self.data

    def get(self, key: str, kind: type | tuple[type, ...], default: Any = ...) -> Any:
        self.read.add(key)
        if key not in self.data:
            if default is ...:
                raise ValueError(f"{self.where(key)}: missing required key")
            return default
        value = self.data[key]
        kinds = kind if isinstance(kind, tuple) else (kind,)
        if float in kinds and isinstance(value, int) and not isinstance(value, bool):
            value = float(value)
        if not isinstance(value, kinds) or (isinstance(value, bool) and bool not in kinds):
            names = " or ".join(k.__name__ for k in kinds)
            raise ValueError(f"{self.where(key)}: expected {names}, got {value!r}")
        return value

    def positive(self, key: str, default: Any = ...) -> Any:
        value = self.get(key, float, default)
        if value is not None and value is not default and not (math.isfinite(value) and value > 0):
            raise ValueError(f"{self.where(key)}: must be a positive number, got {value}")
        return value

    def vector(self, key: str, default: Any = ...) -> Any:
        value = self.get(key, list, default)
        if value is default:
            return value
        if len(value) != 3 or not all(isinstance(v, (int, float)) for v in value):
            raise ValueError(f"{self.where(key)}: expected three numbers, got {value!r}")
        return tuple(float(v) for v in value)

    def table(self, key: str, required: bool = False) -> _Table | None:
        if key not in self.data and not required:
            self.read.add(key)
            return None
        return _Table(self.get(key, dict), self.prefix, self.where(key)[len(self.prefix) :])

    def tables(self, key: str) -> list[_Table]:
        items = self.get(key, list, [])
        out = []
        for i, item in enumerate(items):
            if not isinstance(item, dict):
                raise ValueError(f"{self.where(key)}[{i}]: expected a table, got {item!r}")
            out.append(_Table(item, self.prefix, f"{self.where(key)[len(self.prefix) :]}[{i}]"))
        return out

    def reject_unknown(self) -> None:
        unknown = sorted(set(self.data) - self.read)
        if unknown:
            raise ValueError(f"{self.where(unknown[0])}: unknown key (known: {sorted(self.read)})")


def _parse(root: _Table, path: Path, has_scene_dict: bool = False) -> SceneSpec:
    xml = _parse_mitsuba_xml(root, path, has_scene_dict)
    time = _parse_time(root.table("time", required=True))
    sensor = root.table("sensor", required=True)
    preset = sensor.get("preset", str)
    if preset not in SENSOR_PRESETS:
        raise ValueError(
            f"{sensor.where('preset')}: unknown sensor preset {preset!r}; known: {list(SENSOR_PRESETS)}"
        )
    overrides = dict(sensor.get("overrides", dict, {}))
    qe = sensor.get("qe", str, None)
    if qe is not None and qe.endswith(".csv"):
        qe = str(path.parent / qe)
    sensor.reject_unknown()
    render = root.table("render") or _Table({}, root.prefix, "render")
    spp = render.get("spp", int, 16)
    max_depth = render.get("max_depth", int, 4)
    seed = render.get("seed", int, 0)
    if spp < 1 or max_depth < 1:
        raise ValueError(
            f"{render.where('spp')}/max_depth: must be at least 1, got {spp}/{max_depth}"
        )
    reason = limits.spp_problem(spp)  # with the film's size: in Simulation
    if reason is not None:
        raise ValueError(f"{render.where('spp')}: {reason}")
    render.reject_unknown()
    output = root.table("output") or _Table({}, root.prefix, "output")
    write_frames, write_depth = output.get("frames", bool, False), output.get("depth", bool, False)
    output.reject_unknown()
    camera_table = root.table("camera")
    camera = None
    if camera_table is not None:
        camera = _parse_track(camera_table, allow_look_at=True, base=path.parent)
        camera_table.reject_unknown()
    objects: dict[str, Track] = {}
    for obj in root.tables("objects"):
        object_id = obj.get("id", str)
        if object_id in objects:
            raise ValueError(f"{obj.where('id')}: object {object_id!r} animated twice")
        objects[object_id] = _parse_track(
            obj, allow_look_at=False, base=path.parent, pivot=obj.vector("pivot", (0.0, 0.0, 0.0))
        )
        obj.reject_unknown()
    return SceneSpec(
        path=path,
        mitsuba_xml=xml,
        time=time,
        preset=preset,
        sensor_overrides=overrides,
        qe=qe,
        optics=_parse_optics(root.table("optics", required=True)),
        spp=spp,
        max_depth=max_depth,
        seed=seed,
        light=_parse_light(root.table("light"), path),
        camera=camera,
        objects=objects,
        write_frames=write_frames,
        write_depth=write_depth,
        lights=_parse_lights(root.tables("lights")),
        imu=_parse_imu(root.table("imu")),
        classes=_parse_classes(root),
    )


def _parse_classes(root: _Table) -> dict[str, str]:
    """`[classes]`: shape id = "class name" (ground truth; ids are checked against the scene's
    shapes when it loads)."""
    classes = root.get("classes", dict, {})
    for shape_id, name in classes.items():
        if not isinstance(name, str) or not name:
            raise ValueError(
                f"{root.where('classes')}.{shape_id}: expected a class name, got {name!r}"
            )
    return dict(classes)


def _parse_imu(table: _Table | None) -> ImuModel | None:
    """`[imu]`: `model` (a named IMU) and overrides of its fields (pecs.ground_truth.imu_noise)."""
    if table is None:
        return None
    model = ImuModel.from_settings(table.data, where=table.where(""))
    table.read.update(table.data)
    return model


def _parse_mitsuba_xml(root: _Table, path: Path, has_scene_dict: bool) -> Path | None:
    """`[scene] mitsuba`: required, unless a scene dict takes its place."""
    scene = root.table("scene", required=not has_scene_dict)
    if scene is None or (has_scene_dict and not scene.has("mitsuba")):
        if scene is not None:
            scene.reject_unknown()
        return None
    name = scene.get("mitsuba", str)
    scene.reject_unknown()
    if has_scene_dict:
        return None  # the dict replaces the file's Mitsuba scene
    xml = path.parent / name
    if not xml.is_file():
        raise FileNotFoundError(f"{scene.where('mitsuba')}: Mitsuba scene file not found: {xml}")
    _check_xml(xml, scene.where("mitsuba"))
    return xml


def _check_xml(xml: Path, where: str) -> None:
    """Fail at load time, naming the file, when the Mitsuba scene is not well-formed XML."""
    try:
        ElementTree.parse(xml)
    except (ElementTree.ParseError, OSError) as error:
        raise ValueError(f"{where}: {xml} is not a readable XML file ({error})") from error


def _parse_time(time: _Table) -> TimeStepping:
    duration_s = _within(time, "duration_s", limits.duration_problem)
    adaptive = time.get("adaptive", bool, False)
    if adaptive:
        min_rate = _within(time, "min_rate_hz", limits.rate_problem)
        max_rate = _within(time, "max_rate_hz", limits.rate_problem)
        if min_rate > max_rate:
            raise ValueError(
                f"{time.where('min_rate_hz')}: {min_rate} exceeds max_rate_hz {max_rate}"
            )
        fraction = time.positive("threshold_fraction", 0.5)
        motion = time.get("motion", str, "measured")
        if motion not in STEP_MOTIONS:
            raise ValueError(
                f"{time.where('motion')}: {motion!r}: choose one of {', '.join(STEP_MOTIONS)}"
            )
        time.reject_unknown()
        return TimeStepping(duration_s, None, min_rate, max_rate, fraction, motion)
    rate = _within(time, "rate_hz", limits.rate_problem)
    time.reject_unknown()
    return TimeStepping(duration_s, rate_hz=rate)


def _within(table: _Table, key: str, problem: Callable[[float], str | None]) -> float:
    """A required number that `problem` (pecs.render.limits) finds nothing wrong with."""
    value = table.positive(key)
    reason = problem(value)
    if reason is not None:
        raise ValueError(f"{table.where(key)}: {reason}")
    return value


def _parse_optics(optics: _Table) -> Optics:
    lens = optics.get("lens", str, None)
    model = "lens" if lens is not None else optics.get("model", str)
    if lens is None and model not in OPTICS_MODELS:
        raise ValueError(
            f"{optics.where('model')}: unknown optics model {model!r}; known: {list(OPTICS_MODELS)} or lens = NAME"
        )
    efl_mm = optics.positive("efl_mm", None)
    fov_deg = optics.positive("fov_deg", None)
    f_number = optics.positive("f_number", None if model == "lens" else 2.0)
    focus_m = optics.positive("focus_m", None)
    if efl_mm is not None and fov_deg is not None:
        raise ValueError(f"{optics.where('fov_deg')}: give efl_mm or fov_deg, not both")
    if model != "pinhole" and efl_mm is None:
        raise ValueError(f"{optics.where('efl_mm')}: missing required key for {model}")
    if model != "pinhole" and focus_m is None:
        raise ValueError(f"{optics.where('focus_m')}: missing required key for {model}")
    ghosts = _parse_ghosts(optics, model, lens, efl_mm, f_number, focus_m)
    optics.reject_unknown()
    return Optics(model, efl_mm, fov_deg, f_number, focus_m, lens, ghosts)


def _parse_ghosts(
    optics: _Table,
    model: str,
    lens: str | None,
    efl_mm: float | None,
    f_number: float | None,
    focus_m: float | None,
) -> dict[str, Any] | None:
    """`ghosts = true` or a table of settings: checked now against the lens it will use."""
    value = optics.get("ghosts", (bool, dict), False)
    if value is False:
        return None
    if model != "lens" or lens is None:
        raise ValueError(
            f"{optics.where('ghosts')}: lens ghosts need a realistic lens (lens = NAME), "
            f"not the {model} model"
        )
    settings = {} if value is True else dict(value)
    from pecs.render.lens_ghosts import ghost_settings, realistic_lens

    try:
        traced = realistic_lens(lens, efl_mm, f_number, focus_m)
    except (FileNotFoundError, ValueError):
        return settings  # the lens itself is reported where the sensor is built
    ghost_settings(settings, traced, optics.where("ghosts"))
    return settings


def _parse_light(light: _Table | None, path: Path) -> Light | None:
    if light is None:
        return None
    temperature_k = light.positive("temperature_k", None)
    spectrum = light.get("spectrum", str, None)
    if (temperature_k is None) == (spectrum is None):
        raise ValueError(
            f"{light.where('temperature_k')}: give exactly one of temperature_k and spectrum"
        )
    spectrum_file = None
    if spectrum is not None:
        spectrum_file = path.parent / spectrum
        if not spectrum_file.is_file():
            raise FileNotFoundError(
                f"{light.where('spectrum')}: spectrum file not found: {spectrum_file}"
            )
    normal = light.vector("normal")
    if np.linalg.norm(normal) == 0:
        raise ValueError(f"{light.where('normal')}: must not be the zero vector")
    result = Light(
        light.positive("illuminance_lux"),
        light.vector("at"),
        normal,
        temperature_k,
        spectrum_file,
        _parse_flicker(light.table("flicker")),
    )
    light.reject_unknown()
    return result


def _parse_lights(tables: list[_Table]) -> tuple[EmitterLevel, ...]:
    """`[[lights]]`: per emitter, `illuminance_lux` at `at` (facing `normal`), or a `scale`."""
    levels: list[EmitterLevel] = []
    for table in tables:
        emitter_id = table.get("id", str)
        if any(level.emitter_id == emitter_id for level in levels):
            raise ValueError(f"{table.where('id')}: emitter {emitter_id!r} given twice")
        lux, scale = table.positive("illuminance_lux", None), table.positive("scale", None)
        if (lux is None) == (scale is None):
            raise ValueError(
                f"{table.where('illuminance_lux')}: give exactly one of illuminance_lux and scale"
            )
        at = normal = None
        if lux is not None:
            at, normal = table.vector("at"), table.vector("normal")
            if np.linalg.norm(normal) == 0:
                raise ValueError(f"{table.where('normal')}: must not be the zero vector")
        flicker = _parse_flicker(table.table("flicker"))
        table.reject_unknown()
        levels.append(EmitterLevel(emitter_id, lux, at, normal, scale, flicker))
    return tuple(levels)


def _parse_flicker(table: _Table | None) -> Flicker | None:
    """`flicker = { frequency_hz = 100, lamp = "fluorescent_magnetic" }` or `{ frequency_hz =
    100, depth = 0.3, waveform = "sine" }` (pecs.render.flicker), `phase_deg` optional."""
    if table is None:
        return None
    frequency_hz = table.get("frequency_hz", float)
    _refuse_at(table, "frequency_hz", frequency_problem(frequency_hz))
    phase_deg = table.get("phase_deg", float, 0.0)
    _refuse_at(table, "phase_deg", None if math.isfinite(phase_deg) else "must be finite")
    lamp = table.get("lamp", str, None)
    if lamp is not None:
        for key in ("depth", "waveform"):
            if table.has(key):
                raise ValueError(f"{table.where(key)}: give lamp or {key}, not both")
        if lamp not in LAMPS:
            raise ValueError(f"{table.where('lamp')}: unknown lamp {lamp!r}; known: {list(LAMPS)}")
        table.reject_unknown()
        return Flicker.lamp(lamp, frequency_hz, phase_deg)
    depth = table.get("depth", float)
    _refuse_at(table, "depth", depth_problem(depth))
    waveform = table.get("waveform", str, "sine")
    if waveform not in WAVEFORMS:
        raise ValueError(
            f"{table.where('waveform')}: expected one of {list(WAVEFORMS)}, got {waveform!r}"
        )
    table.reject_unknown()
    return Flicker(frequency_hz, depth, waveform, phase_deg)


def _refuse_at(table: _Table, key: str, reason: str | None) -> None:
    if reason is not None:
        raise ValueError(f"{table.where(key)}: {reason}")


def _parse_track(
    table: _Table,
    allow_look_at: bool,
    base: Path,
    pivot: tuple[float, ...] = (0.0, 0.0, 0.0),
) -> Track:
    if table.has("trajectory"):
        return _parse_trajectory(table, allow_look_at, base, pivot)
    interpolation = _interpolation(table, "linear")
    keyframes = []
    for key in table.tables("keyframes"):
        keyframes.append(_parse_keyframe(key, allow_look_at))
        key.reject_unknown()
    if not keyframes:
        raise ValueError(
            f"{table.where('keyframes')}: missing required key (at least one keyframe, "
            "or a trajectory file)"
        )
    try:
        return Track(keyframes, pivot, interpolation)
    except ValueError as error:
        raise ValueError(f"{table.where('keyframes')}: {error}") from error


def _interpolation(table: _Table, default: str) -> str:
    interpolation = table.get("interpolation", str, default)
    if interpolation not in INTERPOLATIONS:
        raise ValueError(
            f"{table.where('interpolation')}: expected one of {list(INTERPOLATIONS)}, "
            f"got {interpolation!r}"
        )
    return interpolation


def _parse_trajectory(
    table: _Table, is_camera: bool, base: Path, pivot: tuple[float, ...]
) -> Track:
    """`trajectory = "file.tum"` (relative to the scene file), spline-interpolated by default."""
    if table.has("keyframes"):
        raise ValueError(f"{table.where('keyframes')}: give keyframes or a trajectory, not both")
    path = base / table.get("trajectory", str)
    offset = table.get("time_offset_s", (float, str), 0.0)
    if isinstance(offset, str) and offset != "first":
        raise ValueError(
            f'{table.where("time_offset_s")}: expected seconds or "first", got {offset!r}'
        )
    scale = table.positive("time_scale", 1.0)
    axes = table.get("axes", str, "mitsuba") if is_camera else "mitsuba"
    interpolation = _interpolation(table, "spline")
    try:
        return read_trajectory(
            path,
            time_offset_s=offset,
            time_scale=scale,
            axes=axes,
            pivot=(pivot[0], pivot[1], pivot[2]),
            interpolation=interpolation,
        )
    except (ValueError, FileNotFoundError) as error:
        raise type(error)(f"{table.where('trajectory')}: {error}") from error


def _parse_keyframe(key: _Table, allow_look_at: bool) -> Keyframe:
    t_s = key.get("t_s", float)
    if t_s < 0:
        raise ValueError(f"{key.where('t_s')}: must not be negative, got {t_s}")
    position = np.array(key.vector("position", (0.0, 0.0, 0.0)))
    look_at = key.vector("look_at", None) if allow_look_at else None
    axis = key.vector("axis", None)
    quaternion = key.get("quaternion", list, None)
    given = [
        name
        for name, v in (("look_at", look_at), ("axis", axis), ("quaternion", quaternion))
        if v is not None
    ]
    if len(given) > 1:
        raise ValueError(f"{key.where(given[1])}: give one orientation, not {' and '.join(given)}")
    try:
        if look_at is not None:
            rotation = look_at_rotation(position, look_at, key.vector("up", (0.0, 1.0, 0.0)))
        elif axis is not None:
            rotation = quaternion_from_axis_angle(axis, key.get("angle_deg", float))
        elif quaternion is not None:
            q = np.asarray(quaternion, dtype=np.float64)
            if q.shape != (4,) or np.linalg.norm(q) == 0:
                raise ValueError("quaternion must be four numbers (w, x, y, z), not all zero")
            rotation = q / np.linalg.norm(q)
        else:
            rotation = np.array([1.0, 0.0, 0.0, 0.0])
    except ValueError as error:
        raise ValueError(f"{key.where(given[0] if given else 'position')}: {error}") from error
    return Keyframe(t_s, position, rotation)
