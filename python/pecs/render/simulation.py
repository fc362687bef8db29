"""`pecs.Simulation`: an animated scene in, the events of a sensor out, streamed frame by frame.

Frames (photocurrent in pA per pixel) go straight into `EventSensor`; nothing grows with the
duration except the ground-truth pose table (a few numbers per frame).
"""

from __future__ import annotations

import dataclasses
import json
import os
import re
import time
from collections.abc import Callable, Iterable, Iterator
from dataclasses import dataclass
from pathlib import Path
from typing import TYPE_CHECKING, Any

import numpy as np
import pyarrow as pa
import pyarrow.parquet as pq

from pecs._atomic import atomic_dir, atomic_path
from pecs.config import SensorConfig
from pecs.filters import EventFilter, FilterSettings
from pecs.ground_truth import layout as gt_layout
from pecs.ground_truth.imu_noise import ImuModel
from pecs.render import limits
from pecs.render.animation import Track, quaternion_from_matrix
from pecs.render.flicker import SAMPLES_PER_PERIOD
from pecs.render.limits import SettingError
from pecs.render.pixel_geometry import PixelGeometry, pixel_geometry
from pecs.render.quantum_efficiency import QuantumEfficiency, load_qe, preset_qe
from pecs.render.scene_file import SENSOR_PRESETS, SceneSpec, TimeStepping, resolve_scene
from pecs.render.time_stepping import (
    US_PER_S,
    AdaptiveStepper,
    common_change,
    fixed_times_us,
    log_intensity,
)
from pecs.sensor import EventSensor

if TYPE_CHECKING:
    from pecs.ground_truth.writer import GroundTruthWriter

# What `Simulation.run` writes in its folder: these files, and EXR images in the frames folder.
_OUTPUT_FILES = {
    "events": "events.parquet",
    "ground_truth": "ground_truth.parquet",
    "preview": "preview.png",
}
_FRAMES_FOLDER = "frames"
_FRAME_IMAGE = re.compile(r"(photocurrent|depth)_\d+\.exr")
_GROUND_TRUTH_FRAME = re.compile(rf"({'|'.join(gt_layout.FRAME_KINDS.values())})_\d+\.npy")
_GROUND_TRUTH_TABLES = {
    gt_layout.CAMERAS,
    gt_layout.SHAPES,
    gt_layout.OBJECT_POSES,
    gt_layout.INTRINSICS,
    gt_layout.IMU,
    gt_layout.ANIMATION,
}
#: IMU samples per second unless asked otherwise (ESIM's default).
DEFAULT_IMU_RATE_HZ = 1000.0

# Sensor overrides that describe the film (resolution, pixel size), not the pixel circuit.
_GEOMETRY_KEYS = ("width", "height", "pixel_pitch_um", "fill_factor")


@dataclass(frozen=True)
class Frame:
    """One rendered time step."""

    index: int
    t_us: int
    #: Photocurrent per pixel in picoamperes, float32 (height, width).
    photocurrent_pa: np.ndarray
    #: Camera to world, 4x4 (Mitsuba's convention: +z looks forward, +y up).
    camera_to_world: np.ndarray


@dataclass(frozen=True)
class RunSummary:
    """What `Simulation.run` wrote."""

    out_dir: Path
    files: dict[str, Path]
    frames: int
    events: int
    simulated_s: float
    wall_s: float


class Simulation:
    """A scene file (or built-in scene name) rendered over time and fed to an event sensor.

    `scene` is a TOML path, a built-in name, a `SceneSpec`, or the TOML's settings as a dict.
    Keyword arguments override the scene file: `duration_s`, `spp`, `preset`, `seed` (render
    and sensor), `rate_hz` (fixed stepping), `sensor` (sensor fields and film size, or a whole
    `SensorConfig`, e.g. `SensorConfig.from_file("sensor.toml")`, its preset's film), `write_frames` / `write_depth` (EXR per frame in `run`),
    `scene_dict` (a Mitsuba scene in Mitsuba's dict format, in place of the XML; pecs replaces its
    sensor's film, sampler and filter and its integrator), `camera` / `objects` (`Track`s, e.g.
    `read_trajectory("cam.tum")`, in place of the file's camera and per object id).
    `ground_truth` ("all", "depth,flow", or a list of `pecs.ground_truth.KINDS`) makes `run`
    write ground truth (docs/ground-truth.md), the IMU at `imu_rate_hz`; `imu_model` (a named
    IMU, "mpu6500" or "bmi160", a dict like the scene file's `[imu]`, or an `ImuModel`; in place
    of the file's `[imu]`) adds what that real IMU reads, its noise seeded by `seed` unless it
    has its own.
    """

    def __init__(
        self,
        scene: str | os.PathLike[str] | SceneSpec | dict[str, Any],
        *,
        scene_dict: dict[str, Any] | None = None,
        camera: Track | None = None,
        objects: dict[str, Track] | None = None,
        duration_s: float | None = None,
        spp: int | None = None,
        preset: str | None = None,
        seed: int | None = None,
        rate_hz: float | None = None,
        sensor: dict[str, Any] | SensorConfig | None = None,
        write_frames: bool | None = None,
        write_depth: bool | None = None,
        ground_truth: str | Iterable[str] | None = None,
        imu_rate_hz: float = DEFAULT_IMU_RATE_HZ,
        imu_model: str | dict[str, Any] | ImuModel | None = None,
        filters: FilterSettings | None = None,
    ) -> None:
        self.ground_truth = gt_layout.parse_kinds(ground_truth)
        # The chip's on-chip filters (anti-flicker, STC/trail, a rate controller) after the
        # sensor, on every batch as the chip would (pecs.filters); None: none.
        self.filters = filters
        if isinstance(imu_rate_hz, bool) or not isinstance(imu_rate_hz, (int, float)):
            raise SettingError(
                "imu_rate_hz", imu_rate_hz, f"must be a number of Hz, got {imu_rate_hz!r}"
            )
        _refuse("imu_rate_hz", imu_rate_hz, limits.rate_problem(float(imu_rate_hz)))
        self.imu_rate_hz = float(imu_rate_hz)
        spec = resolve_scene(scene, scene_dict, camera, objects)
        if isinstance(sensor, SensorConfig):  # e.g. from a config file (`pecs calibrate`)
            preset = preset if preset is not None else sensor.known_preset
            sensor = config_overrides(sensor)
            if seed is not None:  # the simulation's seed is the sensor's too
                sensor.pop("seed", None)
        self.spec = _overridden(spec, duration_s, spp, preset, seed, rate_hz, sensor)
        given = {
            name
            for name, value in (("duration_s", duration_s), ("rate_hz", rate_hz), ("spp", spp))
            if value is not None
        }
        if write_frames is not None or write_depth is not None:
            self.spec = dataclasses.replace(
                self.spec,
                write_frames=self.spec.write_frames if write_frames is None else write_frames,
                write_depth=self.spec.write_depth if write_depth is None else write_depth,
            )
        try:
            self.geometry, self.sensor_config = _sensor(self.spec, self.spec.sensor_overrides)
        except (ValueError, TypeError) as error:
            raise _sensor_error(error, self.spec, spec.sensor_overrides, sensor or {}) from error
        self._check_counts(given)
        self._check_flicker_rate(given)
        self._check_tracks(camera is not None, set(objects or {}))
        self.imu_model = self._imu_model(imu_model)
        self.qe: QuantumEfficiency = (
            load_qe(self.spec.qe) if self.spec.qe else preset_qe(self.spec.preset)
        )
        self._renderer: Any = None

    def _check_counts(self, given: set[str]) -> None:
        """Refuse more frames, IMU samples or samples per frame than a run can take
        (`pecs.render.limits`), naming the caller's setting if it gave one, else the file's."""
        spec, stepping = self.spec, self.spec.time
        duration_s = stepping.duration_s
        rate_hz = stepping.min_rate_hz if stepping.adaptive else stepping.rate_hz
        assert rate_hz is not None
        reason = limits.frames_problem(duration_s, rate_hz, stepping.adaptive)
        if reason is not None:
            rate_key = "time.min_rate_hz" if stepping.adaptive else "time.rate_hz"
            blamed = [("duration_s", duration_s), ("rate_hz", rate_hz)]
            raise _blame(
                spec, given, blamed, {"duration_s": "time.duration_s", "rate_hz": rate_key}, reason
            )
        pixels = self.geometry.width * self.geometry.height
        reason = limits.spp_problem(spec.spp, pixels)
        if reason is not None:
            raise _blame(spec, given, [("spp", spec.spp)], {"spp": "render.spp"}, reason)
        if "imu" in self.ground_truth:
            reason = limits.imu_samples_problem(duration_s, self.imu_rate_hz)
            _refuse("imu_rate_hz", self.imu_rate_hz, reason)

    @property
    def flicker_hz(self) -> float | None:
        """The fastest flicker of the scene's lights (`flicker` in `[light]` or `[[lights]]`,
        depth above 0), or None: the frames must sample it (`pecs.render.flicker`)."""
        spec = self.spec
        flickers = [level.flicker for level in spec.lights]
        flickers.append(spec.light.flicker if spec.light is not None else None)
        rates = [f.frequency_hz for f in flickers if f is not None and f.depth > 0]
        return max(rates) if rates else None

    def _check_flicker_rate(self, given: set[str]) -> None:
        """Refuse frame rates that cannot follow a flickering light: fixed steps below, or
        adaptive steps whose finest is below, SAMPLES_PER_PERIOD frames a flicker period."""
        flicker_hz = self.flicker_hz
        stepping = self.spec.time
        rate_hz = stepping.max_rate_hz if stepping.adaptive else stepping.rate_hz
        if flicker_hz is None or rate_hz is None:
            return
        needed_hz = SAMPLES_PER_PERIOD * flicker_hz
        if rate_hz >= needed_hz - 1e-9:
            return
        reason = (
            f"{rate_hz:g} frames a second cannot follow the {flicker_hz:g} Hz flicker of the "
            f"scene's lights; it needs {SAMPLES_PER_PERIOD} a period, at least {needed_hz:g} Hz"
        )
        key = "time.max_rate_hz" if stepping.adaptive else "time.rate_hz"
        raise _blame(self.spec, given, [("rate_hz", rate_hz)], {"rate_hz": key}, reason)

    def _imu_model(self, given: str | dict[str, Any] | ImuModel | None) -> ImuModel | None:
        """The caller's real IMU, else the scene file's `[imu]`; seeded by the simulation's seed
        unless it has its own. None: the ideal IMU alone."""
        model = self.spec.imu
        if given is not None:
            try:
                model = _as_imu_model(given)
            except ValueError as error:
                raise SettingError("imu_model", given, str(error).removeprefix("model: ")) from None
            if "imu" not in self.ground_truth:
                reason = "a real IMU needs the IMU ground truth (kind imu, or all)"
                raise SettingError("imu_model", given, reason)
        return None if model is None else model.with_seed(self.spec.seed)

    def _check_tracks(self, camera_given: bool, objects_given: set[str]) -> None:
        """Recorded trajectories must cover the run; the IMU needs a camera path with an
        acceleration (no velocity jump inside the run)."""
        from pecs.ground_truth.imu import check_imu_path
        from pecs.render.trajectory_file import check_covers

        spec, duration_s = self.spec, self.spec.time.duration_s
        in_file = f"{spec.path}: "
        if spec.camera is not None:
            camera_name = "camera" if camera_given else f"{in_file}camera"
            check_covers(spec.camera, duration_s, camera_name)
            if "imu" in self.ground_truth:
                check_imu_path(spec.camera, duration_s, camera_name, in_scene_file=not camera_given)
        for object_id, track in spec.objects.items():
            where = "" if object_id in objects_given else in_file
            check_covers(track, duration_s, f"{where}object {object_id}")

    @property
    def renderer(self) -> Any:
        """The Mitsuba renderer, built on first use (imports Mitsuba, compiles the kernel)."""
        if self._renderer is None:
            from pecs.render.renderer import Renderer

            self._renderer = Renderer(
                self.spec, self.geometry, self.qe, self.sensor_config.cfa_array()
            )
        return self._renderer

    @property
    def duration_us(self) -> int:
        """The simulated duration, whole microseconds."""
        return round(self.spec.time.duration_s * US_PER_S)

    def frames(self) -> Iterator[Frame]:
        """Rendered frames in time order (fixed rate, or adaptive steps)."""
        if self.spec.time.adaptive:
            yield from self._adaptive_frames(exact_motion=self.spec.time.motion == "exact")
            return
        assert self.spec.time.rate_hz is not None
        for index, t_us in enumerate(
            fixed_times_us(self.spec.time.duration_s, self.spec.time.rate_hz)
        ):
            yield self._render(index, int(t_us))

    def event_batches(self) -> Iterator[pa.RecordBatch]:
        """Event batches in time order: one per frame after the first, then the latency tail."""
        for _, batch in self._frames_and_events():
            yield batch

    def run(
        self,
        out_dir: str | os.PathLike[str],
        progress: Callable[[Frame, int], None] | None = None,
    ) -> RunSummary:
        """Write events.parquet, ground_truth.parquet, preview.png (and EXR frames if asked).

        The folder is built beside `out_dir` (hidden, same parent) and renamed to it when
        complete, so an interrupted run leaves no half-filled folder. An existing `out_dir` is
        replaced if it holds only what a run writes (a rerun); anything else in it is a
        ValueError before any rendering, since replacing it would delete the user's files.
        `progress(frame, events_so_far)` is called after every frame.
        """
        out = Path(out_dir)
        _check_replaceable(out)
        started = time.perf_counter()
        _ = self.renderer  # load the scene first: the metadata records the variant and light scale
        with atomic_dir(out) as building:
            frame_count, events = self._write_outputs(building, progress)
            _check_replaceable(out)  # again: files may have appeared there while it rendered
        files = {name: out / file for name, file in _OUTPUT_FILES.items()}
        if self.spec.write_frames or self.spec.write_depth:
            files["frames"] = out / _FRAMES_FOLDER
        if self.ground_truth:
            files["ground_truth_dir"] = out / gt_layout.FOLDER
        return RunSummary(
            out,
            files,
            frame_count,
            events,
            self.spec.time.duration_s,
            time.perf_counter() - started,
        )

    def _write_outputs(
        self, out: Path, progress: Callable[[Frame, int], None] | None
    ) -> tuple[int, int]:
        """Render, simulate and write every output into `out`; (frames, events)."""
        from pecs.io import EventWriter
        from pecs.viz import event_frame, save_image

        width, height = self.geometry.width, self.geometry.height
        last_polarity = np.full(width * height, -1, dtype=np.int8)
        poses: list[tuple[float, ...]] = []
        frame_count = 0
        metadata = self.metadata()
        truth = self._ground_truth_writer(out)
        with EventWriter(out / _OUTPUT_FILES["events"], width=width, height=height) as writer:
            for frame, batch in self._frames_and_events():
                if frame is not None:
                    frame_count += 1
                    poses.append(_pose_row(frame))
                    self._write_frame_images(out, frame)
                    if truth is not None:
                        self._add_ground_truth(truth, frame)
                if batch.num_rows:
                    writer.write(_with_metadata(batch, metadata))
                    _remember_polarity(batch, last_polarity, width)
                if progress is not None and frame is not None:
                    progress(frame, writer.count)
        _write_poses(out / _OUTPUT_FILES["ground_truth"], poses, metadata)
        if truth is not None:
            truth.finish(
                self.renderer.camera_pose,
                self.spec.time.duration_s,
                self.imu_rate_hz,
                imu_model=self.imu_model,
            )
            if "events" in self.ground_truth:
                _add_event_ground_truth(out, np.array([row[0] for row in poses], np.int64))
        preview = event_frame(_latest_events(last_polarity, width, height))
        save_image(preview, out / _OUTPUT_FILES["preview"])
        return frame_count, writer.count

    def metadata(self) -> dict[str, str]:
        """What produced the events: scene, sensor, optics, render settings, seed (JSON strings)."""
        spec = self.spec
        render = {
            "spp": spec.spp,
            "max_depth": spec.max_depth,
            "seed": spec.seed,
            "photocurrent_unit": "pA",
            "qe": self.qe.name,
            "qe_source": self.qe.source,
            "pixel_pitch_um": self.geometry.pitch_um,
            "fill_factor": self.geometry.fill_factor,
            "time": dataclasses.asdict(spec.time),
        }
        if self._renderer is not None:
            render["mitsuba_variant"] = self._renderer.mi.variant()
            render["light_scale"] = self._renderer.light_scale
            render["emitter_scales"] = self._renderer.emitter_scales
            if self._renderer.flickering:
                lamps = self._renderer.flickering
                render["flicker"] = {lamp.name: lamp.flicker.as_dict() for lamp in lamps}
        return {
            "pecs.scene": json.dumps({"file": str(spec.path.name), "mitsuba": spec.mitsuba_name}),
            "pecs.optics": json.dumps(spec.optics.as_dict()),
            "pecs.render": json.dumps(render),
            "pecs.sensor": self.sensor_config.to_json(),
            **({"pecs.filters": json.dumps([self.filters.to_dict()])} if self.filters else {}),
        }

    # -- internals -------------------------------------------------------------------------

    def _add_ground_truth(self, truth: GroundTruthWriter, frame: Frame) -> None:
        surface = self.renderer.surface(frame.t_us / US_PER_S) if truth.needs_surface else None
        truth.add(frame.index, frame.t_us, frame.camera_to_world, surface)

    def _ground_truth_writer(self, out: Path) -> GroundTruthWriter | None:
        """The writer of the ground truth asked for, or None."""
        if not self.ground_truth:
            return None
        from pecs.ground_truth.tracks import animation_dict
        from pecs.ground_truth.writer import GroundTruthWriter, SceneFacts

        renderer, spec = self.renderer, self.spec
        objects = {name: track.pose for name, track in spec.objects.items()}
        facts = SceneFacts(
            animation_dict(spec.camera, spec.objects), renderer.shape_boxes(), spec.classes
        )
        return GroundTruthWriter(
            out, self.ground_truth, renderer.shape_ids(), objects, renderer.camera_model(), facts
        )

    def _render(self, index: int, t_us: int) -> Frame:
        renderer = self.renderer
        t_s = t_us / US_PER_S
        photocurrent = renderer.render(t_s)
        return Frame(index, t_us, photocurrent, renderer.camera_pose(t_s))

    def _adaptive_frames(
        self,
        change_of: Callable[[np.ndarray, np.ndarray], float] | None = None,
        *,
        exact_motion: bool = False,
    ) -> Iterator[Frame]:
        """Frames at adaptive steps; `change_of(L_previous, L_next)` is the step's log change
        (default `AdaptiveStepper.change`; benches/bench_adaptive.py passes ESIM's maximum).
        `exact_motion`: steps from the image motion the animation gives (`exact_step`), the
        frames measuring only the change common to the whole image."""
        stepper = AdaptiveStepper(
            self.spec.time,
            min(self.sensor_config.theta_on, self.sensor_config.theta_off),
            periodic_hz=self.flicker_hz,
        )
        if exact_motion:
            change_of = change_of or (lambda a, b: abs(common_change(a, b)))
        change_of = change_of or stepper.change
        dark = self.sensor_config.dark_current
        end_us = self.duration_us
        frame = self._render(0, 0)
        yield frame
        log_previous = log_intensity(frame.photocurrent_pa, dark)
        step_us = stepper.first_step_us()
        if exact_motion:
            step_us = stepper.exact_step(self._motion_px_over(0))
        while frame.t_us < end_us:
            step_us = min(step_us, end_us - frame.t_us)
            candidate = self._render(frame.index + 1, frame.t_us + step_us)
            log_candidate = log_intensity(candidate.photocurrent_pa, dark)
            change = change_of(log_previous, log_candidate)
            if not stepper.accept(change, step_us):
                step_us = stepper.shorter(step_us)
                continue
            frame, log_previous = candidate, log_candidate
            yield frame
            if exact_motion and frame.t_us < end_us:
                exact_us = stepper.exact_step(self._motion_px_over(frame.t_us))
                step_us = stepper.exact_next_step_us(change, step_us, exact_us)
            else:
                step_us = stepper.next_step_us(change, step_us)

    def _motion_px_over(self, t_us: int) -> Callable[[int], float]:
        """step_us -> the largest image motion (px) of the surface points seen at t_us over a
        step from t_us: each moved with its object's track and projected by the camera then
        (`motion_field_px`, the ground truth's flow). Points that end behind the camera do not
        count; none seen, no motion."""
        from pecs.ground_truth.surface import motion_field_px

        renderer = self.renderer
        t0_s = t_us / US_PER_S
        hits = renderer.surface(t0_s)
        shape_ids, model = renderer.shape_ids(), renderer.camera_model()
        tracks = self.spec.objects

        def largest_px(step_us: int) -> float:
            t1_s = (t_us + step_us) / US_PER_S

            def shape_motion(index: int) -> np.ndarray | None:
                track = tracks.get(shape_ids[index])
                return None if track is None else track.pose(t1_s) @ np.linalg.inv(track.pose(t0_s))

            flow = motion_field_px(hits, renderer.camera_pose(t1_s), shape_motion, model)
            moved = np.hypot(flow[..., 0], flow[..., 1])
            moved = moved[np.isfinite(moved)]
            return float(moved.max()) if moved.size else 0.0

        return largest_px

    def _frames_and_events(self) -> Iterator[tuple[Frame | None, pa.RecordBatch]]:
        sensor = EventSensor(self.sensor_config)
        chip = EventFilter(self.filters) if self.filters is not None else None
        for frame in self.frames():
            batch = sensor.feed(frame.photocurrent_pa, frame.t_us)
            yield frame, chip.apply(batch) if chip is not None else batch
        tail = sensor.flush()
        if chip is None:
            yield None, tail
            return
        yield None, chip.apply(tail)
        yield None, chip.flush()  # what the filters held for a later verdict

    def _write_frame_images(self, out: Path, frame: Frame) -> None:
        if not (self.spec.write_frames or self.spec.write_depth):
            return
        folder = out / _FRAMES_FOLDER
        folder.mkdir(exist_ok=True)
        if self.spec.write_frames:
            _write_exr(folder / f"photocurrent_{frame.index:06d}.exr", frame.photocurrent_pa)
        if self.spec.write_depth:
            depth = self.renderer.depth(frame.t_us / US_PER_S)
            _write_exr(folder / f"depth_{frame.index:06d}.exr", depth)


def _sensor(spec: SceneSpec, overrides: dict[str, Any]) -> tuple[PixelGeometry, SensorConfig]:
    """The film and the sensor configuration of the scene's preset with `overrides`."""
    geometry = pixel_geometry(spec.preset, overrides)
    circuit = {k: v for k, v in overrides.items() if k not in _GEOMETRY_KEYS}
    circuit.setdefault("seed", spec.seed)
    config = SensorConfig.preset(
        spec.preset, width=geometry.width, height=geometry.height, **circuit
    )
    return geometry, config


def _sensor_error(
    error: Exception, spec: SceneSpec, in_file: dict[str, Any], given: dict[str, Any]
) -> ValueError:
    """Blame a sensor value that cannot be simulated on whoever gave it: the caller's `sensor`
    (a `SettingError` naming the field, which the CLI and the dataset runner name in their own
    words) or the scene file's overrides."""
    # SensorConfig's and pixel_geometry's messages start with the field: "theta_on: must ...".
    name = str(error).split(":", 1)[0]
    if name in given:
        return SettingError("sensor", given[name], str(error), field=name)
    if given and _builds(spec, in_file):  # the file's values alone pass: the caller's do not
        return SettingError("sensor", None, str(error))
    return ValueError(f"{spec.path}: sensor.overrides: {error}")


def _builds(spec: SceneSpec, overrides: dict[str, Any]) -> bool:
    try:
        _sensor(spec, overrides)
    except (ValueError, TypeError):
        return False
    return True


def _as_imu_model(value: str | dict[str, Any] | ImuModel) -> ImuModel:
    """A named IMU, the settings of an `[imu]` table, or a model as it is."""
    if isinstance(value, ImuModel):
        return value
    if isinstance(value, str):
        return ImuModel.preset(value)
    if isinstance(value, dict):
        return ImuModel.from_settings(value)
    raise ValueError(f"expected an IMU model's name, settings or ImuModel, got {value!r}")


def _refuse(setting: str, value: object, reason: str | None) -> None:
    """A SettingError for the caller's `setting` when `reason` says what is wrong with it."""
    if reason is not None:
        raise SettingError(setting, value, reason)


def _blame(
    spec: SceneSpec,
    given: set[str],
    settings: list[tuple[str, object]],
    file_keys: dict[str, str],
    reason: str,
) -> SettingError:
    """The error for a combination of settings: on the first the caller gave, else on the
    scene file's key of the first."""
    for setting, value in settings:
        if setting in given:
            return SettingError(setting, value, reason)
    setting, value = settings[0]
    return SettingError(file_keys[setting], value, reason, source=str(spec.path))


def config_overrides(config: SensorConfig) -> dict[str, Any]:
    """A whole sensor configuration as a scene's sensor overrides (its preset aside)."""
    return {name: value for name, value in config.to_dict().items() if name != "preset_name"}


def _overridden(
    spec: SceneSpec,
    duration_s: float | None,
    spp: int | None,
    preset: str | None,
    seed: int | None,
    rate_hz: float | None,
    sensor: dict[str, Any] | None,
) -> SceneSpec:
    """The scene with the caller's values in place of the file's, each checked like the file's."""
    changes: dict[str, Any] = {}
    stepping: TimeStepping = spec.time
    if duration_s is not None:
        _refuse("duration_s", duration_s, _number_problem(duration_s, limits.duration_problem))
        stepping = dataclasses.replace(stepping, duration_s=float(duration_s))
    if rate_hz is not None:
        _refuse("rate_hz", rate_hz, _number_problem(rate_hz, limits.rate_problem))
        stepping = TimeStepping(stepping.duration_s, rate_hz=float(rate_hz))
    changes["time"] = stepping
    if spp is not None:
        _refuse("spp", spp, limits.spp_problem(spp))
        changes["spp"] = spp
    if preset is not None:
        if preset not in SENSOR_PRESETS:
            raise ValueError(
                f"preset: unknown sensor preset {preset!r}; known: {list(SENSOR_PRESETS)}"
            )
        changes["preset"] = preset
    if seed is not None:
        if isinstance(seed, bool) or not isinstance(seed, int) or seed < 0:
            raise ValueError(f"seed: must be a non-negative integer, got {seed!r}")
        changes["seed"] = seed
    if sensor:
        changes["sensor_overrides"] = {**spec.sensor_overrides, **sensor}
    return dataclasses.replace(spec, **changes)


def _number_problem(value: object, problem: Callable[[float], str | None]) -> str | None:
    """`problem(value)` for a real number; what is wrong with anything else."""
    if isinstance(value, bool) or not isinstance(value, (int, float)):
        return f"must be a number, got {value!r}"
    return problem(float(value))


def _check_replaceable(out: Path) -> None:
    """Refuse an output folder that holds anything a run does not write (or is not a folder):
    the finished run replaces the folder whole."""
    if not out.exists() and not out.is_symlink():
        return
    if not out.is_dir() or out.is_symlink():
        raise ValueError(f"{out}: exists and is not a folder; choose another output folder")
    foreign = [entry.name for entry in out.iterdir() if not _is_run_output(entry)]
    if foreign:
        shown = ", ".join(sorted(foreign)[:5]) + (", ..." if len(foreign) > 5 else "")
        raise ValueError(
            f"{out}: holds files a simulation does not write ({shown}); it would be replaced "
            "whole, so choose another output folder or empty it"
        )


def _is_run_output(entry: Path) -> bool:
    if entry.is_symlink():
        return False
    if entry.name == _FRAMES_FOLDER and entry.is_dir():
        return all(_FRAME_IMAGE.fullmatch(image.name) for image in entry.iterdir())
    if entry.name == gt_layout.FOLDER and entry.is_dir():
        return all(_is_ground_truth_output(item) for item in entry.iterdir())
    return entry.name in _OUTPUT_FILES.values() and entry.is_file()


def _is_ground_truth_output(entry: Path) -> bool:
    if entry.is_symlink():
        return False
    if entry.name == gt_layout.FRAMES and entry.is_dir():
        return all(_GROUND_TRUTH_FRAME.fullmatch(item.name) for item in entry.iterdir())
    return entry.name in _GROUND_TRUTH_TABLES and entry.is_file()


def _add_event_ground_truth(out: Path, frame_times_us: np.ndarray) -> None:
    """Append each event's frame, flow and instance (pecs.ground_truth.event_truth) to its file."""
    from pecs.ground_truth.event_truth import add_event_columns

    frames = out / gt_layout.FOLDER / gt_layout.FRAMES

    def load(prefix: str) -> Callable[[int], np.ndarray]:
        return lambda index: np.load(frames / gt_layout.frame_file(prefix, index))

    add_event_columns(out / _OUTPUT_FILES["events"], frame_times_us, load("flow"), load("instance"))


def _pose_row(frame: Frame) -> tuple[float, ...]:
    rotation = frame.camera_to_world[:3, :3]
    # Normalise the columns: a scaled camera transform still has a well-defined orientation.
    unit = rotation / np.linalg.norm(rotation, axis=0, keepdims=True)
    q = quaternion_from_matrix(unit)
    return (frame.t_us, frame.index, *frame.camera_to_world[:3, 3], *q)


def _write_poses(path: Path, rows: list[tuple[float, ...]], metadata: dict[str, str]) -> None:
    """Camera pose per rendered frame: t_us, frame, position (m), quaternion (w, x, y, z)."""
    columns = list(zip(*rows, strict=True)) if rows else [[] for _ in range(9)]
    names = ("position_x_m", "position_y_m", "position_z_m", "qw", "qx", "qy", "qz")
    arrays = [pa.array(columns[0], pa.int64()), pa.array(columns[1], pa.uint32())]
    arrays += [pa.array(c, pa.float64()) for c in columns[2:]]
    table = pa.Table.from_arrays(arrays, names=["t_us", "frame", *names])
    table = table.replace_schema_metadata(metadata)
    with atomic_path(path) as tmp:
        pq.write_table(table, tmp)


def _with_metadata(batch: pa.RecordBatch, metadata: dict[str, str]) -> pa.RecordBatch:
    merged = {**{k.decode(): v.decode() for k, v in (batch.schema.metadata or {}).items()}}
    merged.update(metadata)
    return batch.replace_schema_metadata(merged)


def _remember_polarity(batch: pa.RecordBatch, last: np.ndarray, width: int) -> None:
    """Keep each pixel's latest polarity (the preview), in O(pixels) memory."""
    x = batch.column("x").to_numpy().astype(np.int64)
    y = batch.column("y").to_numpy().astype(np.int64)
    p = batch.column("p").to_numpy()
    # Latest event per pixel: its first occurrence in the reversed batch (events sorted by t).
    pixel, first = np.unique((y * width + x)[::-1], return_index=True)
    last[pixel] = p[::-1][first]


def _latest_events(last: np.ndarray, width: int, height: int) -> pa.Table:
    """One event per pixel that fired, with its latest polarity, for `pecs.viz.event_frame`."""
    from pecs.events import record_batch, schema

    pixel = np.flatnonzero(last >= 0)
    columns = {
        "t": np.zeros(pixel.size, dtype=np.int64),
        "x": (pixel % width).astype(np.uint16),
        "y": (pixel // width).astype(np.uint16),
        "p": last[pixel].astype(np.int8),
    }
    return pa.Table.from_batches([record_batch(columns, schema(width, height))])


def _write_exr(path: Path, image: np.ndarray) -> None:
    """A single-channel float32 OpenEXR file, written atomically."""
    from pecs._mitsuba import mitsuba

    mi = mitsuba()
    bitmap = mi.Bitmap(np.ascontiguousarray(image[..., None], dtype=np.float32))
    with atomic_path(path) as tmp:
        bitmap.write(str(tmp), mi.Bitmap.FileFormat.OpenEXR)
