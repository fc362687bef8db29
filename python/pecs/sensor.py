"""The streaming event sensor: photocurrent frames in, Arrow record batches of events out."""

from __future__ import annotations

import json
import math
import numbers
import os
from collections.abc import Iterable, Iterator, Sequence
from typing import TYPE_CHECKING, Any

import numpy as np
import pyarrow as pa

from pecs import _core, events
from pecs.config import REFERENCE_WHITE_LUX, SensorConfig
from pecs.filters import EventFilter, FilterSettings, filter_events
from pecs.footage.exposure import check_exposure, exposure_deconvolved, source_exposure_us
from pecs.footage.flow_interpolation import flow_subframes
from pecs.footage.frame_interpolation import INTERPOLATIONS, transition_subframes
from pecs.footage.frames import FrameSource, decode_footage, decode_image, open_frames, times_us
from pecs.footage.input_noise import (
    InputNoise,
    check_deadband_sigmas,
    is_camera_footage,
    suppress_input_noise,
)

if TYPE_CHECKING:  # pecs.render imports this module: its flicker is imported where it is used
    from pecs.render.flicker import Flicker


class EventSensor:
    """A DVS sensor with per-pixel state, fed frames of linear photocurrent in time order.

    `feed(frame, t_us)` returns the events in (t_prev, t_us]; the first frame only initialises
    the pixels. `flush()` returns what latency still holds back; `reset()` starts over.

    Frames are float32/float64 linear photocurrent, or uint8/uint16 images, decoded as 8/16-bit
    image files are (sRGB to linear [0, 1]); other integer frames are refused (their scale is
    unknown: divide them to float). One call may give at most 5e7 events (about 3 GB while they
    are simulated). A gap between frames whose noise would be more is refused at once with a
    ValueError that says how far apart frames may be, and the sensor is unchanged. A frame whose
    light changed by more than the thresholds can follow (3e38 after a dark frame gives about
    9,600 events a pixel at theta 0.01) is stopped mid-call once its events pass the limit, with
    a ValueError; its pixels are then partly stepped, so the sensor refuses `feed` and `flush`
    until `reset()`.

    A sensor is one stream in time order. Calls from several threads take turns (a lock in the
    core, taken with the GIL released), so they never corrupt it, but each must still feed
    times later than the last one fed by any thread.
    """

    def __init__(self, config: SensorConfig | None = None) -> None:
        self.config = config if config is not None else SensorConfig()
        if not isinstance(self.config, SensorConfig):
            raise TypeError(f"config must be a pecs.SensorConfig, got {type(config).__name__}")
        self._core = _core.EventSensor(self.config.core_params(), labels=self.config.labels)
        self._shape = (self.config.height, self.config.width)
        self._cfa = self.config.cfa_array()  # colour frames go through it (`feed`)
        # What the core exports; the readout delays, when asked for, are a column added here.
        self._core_schema = events.schema(
            self.config.width,
            self.config.height,
            labels=self.config.labels,
            metadata={"pecs.sensor": self.config.to_json()},
        )
        self._delays = self.config.readout_delays
        self.schema = self._core_schema.append(DELAY_FIELD) if self._delays else self._core_schema

    @property
    def last_time_us(self) -> int | None:
        """Time of the last frame fed, or None before the first."""
        return self._core.last_time_us

    def feed(self, frame: np.ndarray, t_us: int) -> pa.RecordBatch:
        """Feed one frame (height, width) of photocurrent >= 0 at integer time `t_us`."""
        # The usual frame (float32, C-contiguous, right shape) and time (an int) are recognised
        # in a few attribute reads: at 2,000 frames a second the full checks cost 5 % of a frame.
        if not (
            type(frame) is np.ndarray
            and frame.dtype is _FLOAT32
            and frame.flags.c_contiguous
            and frame.shape == self._shape
        ):
            frame = self._checked_frame(frame)
        if type(t_us) is not int:
            t_us = _checked_time(t_us)
        try:
            return self._batch(self._core.feed(frame, t_us))
        except OverflowError:
            raise ValueError(f"t_us must be within +-2^53 us (285 years), got {t_us}") from None

    def flush(self) -> pa.RecordBatch:
        """Events still held back by latency and jitter."""
        return self._batch(self._core.flush())

    def reset(self) -> None:
        """Forget all state; the next frame initialises the sensor again."""
        self._core.reset()

    @property
    def readout_counts(self) -> dict[str, int] | None:
        """What became of the events through the readout since the start (or `reset`), or None
        when the configuration has no readout: events_in = events_out + dropped (a full readout
        queue) + erc_dropped (the rate controller) + held (still inside); delayed, delay_total_us
        and delay_max_us (events stamped in a later microsecond than they were made);
        same_timestamp (events out stamped as the one before them)."""
        return self._core.readout_counts()

    def _batch(self, exported: _core.ExportedBatch) -> pa.RecordBatch:
        # The Arrow C data interface moves the columns out of Rust without a copy; importing
        # against the schema held here skips parsing one per batch.
        batch = pa.RecordBatch._import_from_c(exported.address, self._core_schema)
        if not self._delays:
            return batch
        delays = self._core.delays_us()
        if len(delays) != batch.num_rows:  # the readout is off: no event waits
            delays = np.zeros(batch.num_rows, np.int64)
        return pa.RecordBatch.from_arrays([*batch.columns, pa.array(delays)], schema=self.schema)

    def _checked_frame(self, frame: np.ndarray) -> np.ndarray:
        if not isinstance(frame, np.ndarray):
            raise ValueError(f"frame must be a numpy array, got {type(frame).__name__}")
        if frame.ndim == 3 and self._cfa is not None:
            frame = _colour_through(self._cfa, frame)
        if frame.dtype in _IMAGE_DTYPES and frame.ndim == 2:
            frame = decode_image(frame.astype(frame.dtype.newbyteorder("=")))
        if frame.dtype.kind != "f" or frame.dtype.itemsize not in (4, 8):
            raise ValueError(
                f"frame dtype is {frame.dtype}; expected float32 or float64 linear photocurrent "
                "(or a uint8/uint16 image)"
            )
        if frame.size == 0:
            raise ValueError(f"frame is empty (shape {frame.shape})")
        expected = self._shape
        if frame.shape != expected:
            raise ValueError(
                f"frame shape {frame.shape} does not match the sensor's (height, width) = {expected}"
            )
        if frame.dtype.itemsize == 8:
            return _as_float32(frame)
        # Taken without a copy when already float32 and C-contiguous.
        return np.ascontiguousarray(frame, dtype=np.float32)


def _colour_through(cfa: Any, frame: np.ndarray) -> np.ndarray:
    """A colour frame (height, width, 3: linear RGB floats, or an sRGB uint8/uint16 image in RGB
    order) through the colour filter array: each pixel takes its own filter's channel."""
    if frame.shape[-1] not in (3, 4):
        raise ValueError(
            f"colour frame shape {frame.shape}: a colour sensor (cfa {cfa.pattern}) takes "
            "(height, width) or (height, width, 3) RGB frames"
        )
    if frame.dtype in _IMAGE_DTYPES:  # decode_image takes OpenCV's BGR order
        native = frame.astype(frame.dtype.newbyteorder("="))
        return decode_image(native[..., [2, 1, 0]], cfa=cfa)
    return cfa.mosaic_rgb(frame)


def _as_float32(frame: np.ndarray) -> np.ndarray:
    """A float64 frame as float32; a finite value past float32's range is refused for what it
    is (the cast made it inf, which the sensor reported as non-finite), without numpy's
    overflow warning."""
    with np.errstate(over="ignore"):
        cast = np.ascontiguousarray(frame, dtype=np.float32)
    overflowed = np.isinf(cast) & np.isfinite(frame)
    if overflowed.any():
        y, x = (int(i[0]) for i in np.nonzero(overflowed))
        raise ValueError(
            f"frame has a value ({frame[y, x]:g}) at x={x}, y={y} past float32's range "
            f"(+-{np.finfo(np.float32).max:.3g}), the sensor's input type"
        )
    return cast


_FLOAT32 = np.dtype(np.float32)
#: The optional column of each event's readout delay (us), `SensorConfig.readout_delays`.
DELAY_FIELD = pa.field("delay_us", pa.int64(), nullable=False)
#: Schema metadata key of a run's readout counts (`EventSensor.readout_counts`), JSON.
READOUT_METADATA_KEY = "pecs.readout"
_IMAGE_DTYPES = tuple(np.dtype(t) for t in ("u1", "<u2", ">u2"))


def _checked_time(t_us: int) -> int:
    """An integer, or a float holding a whole number, of microseconds, as a Python int."""
    if isinstance(t_us, bool) or not isinstance(t_us, numbers.Real):
        raise ValueError(f"t_us must be an integer number of microseconds, got {t_us!r}")
    if isinstance(t_us, numbers.Integral):
        return int(t_us)
    if not (math.isfinite(t_us) and float(t_us).is_integer()):
        raise ValueError(f"t_us must be a whole number of microseconds, got {t_us!r}")
    return int(t_us)


def frames_to_events(
    frames: Iterable[np.ndarray] | np.ndarray,
    t_us: Sequence[int] | np.ndarray,
    config: SensorConfig | None = None,
    *,
    camera_footage: bool = False,
    input_noise: InputNoise | bool | None = None,
    deadband_sigmas: float | None = None,
    interpolation: str = "auto",
    filters: FilterSettings | None = None,
    flicker: Flicker | None = None,
    exposure_us: float | Sequence[float] | np.ndarray | None = None,
) -> pa.Table:
    """Events of a whole frame sequence in memory: frames (N, H, W) with N timestamps in
    microseconds (integers, or floats holding whole numbers).

    `camera_footage`: the frames come from a real camera (read and shot noise, 25 Hz changes),
    as AEDAT4 APS frames do; 8- and 16-bit frames then have their black lifted to half a code
    (`pecs.footage.frames.lift_black`), and `input_noise` and `interpolation` default to what
    `frames_to_file` (and `pecs frames2events`) use for such footage: noise held back,
    transitions between frames. For arrays (rendered, by default) both are off / linear.
    `input_noise`, `deadband_sigmas`, `interpolation`, `filters` and `flicker` as in
    `frames_to_file`. `exposure_us`: each frame is the light averaged over an exposure this
    long (one number, or one per frame) centred on its time; the light at the frame times is
    recovered from them (`pecs.footage.exposure`) before the sensor sees it. None or 0: the
    frames are the light at their times (the events unchanged, bit for bit)."""
    times = times_us(t_us, "us", "t_us")
    config = config if config is not None else SensorConfig()
    pairs: Iterable[tuple[int, np.ndarray]] = _paired(frames, times)
    works_on_light = input_noise or deadband_sigmas is not None or flicker is not None
    exposed = _exposed(exposure_us)
    if camera_footage or works_on_light or exposed or interpolation not in ("auto", "linear"):
        pairs = ((t, _decoded(frame, camera_footage)) for t, frame in pairs)
    pairs = _with_input_noise(camera_footage, pairs, input_noise, deadband_sigmas)
    if exposed:
        check_exposure(exposure_us, times)  # type: ignore[arg-type]
        pairs = exposure_deconvolved(pairs, exposure_us)
    pairs = _with_interpolation(camera_footage, pairs, config, interpolation)
    pairs = _with_flicker(pairs, config, flicker)
    sensor = EventSensor(config)
    batches = [sensor.feed(frame, t) for t, frame in pairs]
    batches.append(sensor.flush())
    table = pa.Table.from_batches(batches, schema=sensor.schema)
    table = with_readout_counts(table, sensor.readout_counts)
    return table if filters is None else filter_events(table, filters)


def with_readout_counts(table: pa.Table, counts: dict[str, int] | None) -> pa.Table:
    """The table with a run's readout counts in its schema metadata (`pecs.readout`, JSON),
    where the sensor had a readout."""
    if counts is None:
        return table
    metadata = {**(table.schema.metadata or {}), READOUT_METADATA_KEY.encode(): json.dumps(counts)}
    return table.replace_schema_metadata(metadata)


def _paired(
    frames: Iterable[np.ndarray] | np.ndarray, times: np.ndarray
) -> Iterator[tuple[int, np.ndarray]]:
    """(t_us, frame) pairs; a ValueError where there are more or fewer frames than times."""
    remaining = iter(frames)
    for count, t in enumerate(times):
        frame = next(remaining, None)
        if frame is None:
            raise ValueError(f"got {count} frames for {len(times)} timestamps")
        yield int(t), frame
    if next(remaining, None) is not None:
        raise ValueError(f"got more frames than the {len(times)} timestamps")


def _exposed(exposure_us: object) -> bool:
    """Whether frames were exposed for a time to undo (not None, not 0); bad values are
    refused by `pecs.footage.exposure.check_exposure` when the frames are read."""
    if exposure_us is None:
        return False
    if isinstance(exposure_us, (str, bytes)):
        raise TypeError(
            f"exposure_us: a number of microseconds or one per frame, got {exposure_us!r}"
        )
    return np.ndim(exposure_us) > 0 or float(exposure_us) != 0.0  # type: ignore[arg-type]


def _decoded(frame: np.ndarray, camera_footage: bool) -> np.ndarray:
    """A uint8/uint16 image as linear photocurrent (as `EventSensor.feed` decodes it), before the
    input stages, which work on light; from camera footage with its black lifted to half a code
    (`lift_black`), as the video and AEDAT4 readers give it. Anything else as given (the sensor
    checks it)."""
    if isinstance(frame, np.ndarray) and frame.dtype in _IMAGE_DTYPES and frame.ndim == 2:
        native = frame.astype(frame.dtype.newbyteorder("="))
        return decode_footage(native) if camera_footage else decode_image(native)
    return frame


def frames_to_file(
    frames: FrameSource | str | os.PathLike[str],
    output: str | os.PathLike[str],
    config: SensorConfig,
    *,
    fps: float | None = None,
    format: str | None = None,
    progress: bool = False,
    input_noise: InputNoise | bool | None = None,
    deadband_sigmas: float | None = None,
    interpolation: str = "auto",
    zero_time: bool = False,
    filters: FilterSettings | None = None,
    flicker: Flicker | None = None,
    exposure_us: float | str | Sequence[float] | np.ndarray | None = None,
) -> dict[str, int]:
    """Simulate the sensor on frames on disk and stream its events to an event file (any format
    `pecs.write_events` knows, by suffix). Memory does not grow with the sequence; the file
    appears at `output` only when complete. Returns counts of frames and events.

    `input_noise`: the frames' own noise held back (`pecs.footage.input_noise`): an `InputNoise`, True
    (estimated from the frames), False (off), or None: on for camera footage (AEDAT4 APS frames,
    videos), off for images, EXR and arrays, which may be rendered. `deadband_sigmas`: how many
    sigma of the estimated noise a pixel's input must move before it follows (default
    `pecs.footage.input_noise.DEFAULT_DEADBAND_SIGMAS`); stating it turns input noise on where None, and
    a stated `InputNoise` carries its own. `interpolation`: the light
    between frames, "linear" in log (ESIM's rule, exact for rendered ramps), "transition" (each
    pixel's change a short transition at a random time of the interval,
    `pecs.footage.frame_interpolation`), "flow" (sub-frames warped along the optical flow, so a moving
    edge reaches each pixel when its motion says; `pecs.footage.flow_interpolation`), or "auto":
    transition for camera footage, linear otherwise. `zero_time`: the events' times start at 0
    (the first event's t subtracted), as EVT3, EVT2, DAT and v2e need of a recording in Unix
    time (AEDAT4). `filters`: the on-chip filters (`pecs.filters.FilterSettings`) run on the
    sensor's events as they stream out; the counts then tell what each dropped. `flicker`: the
    frames' light is modulated by a mains flicker (`pecs.render.flicker.Flicker`), fed as
    sub-frames at 20 a flicker period (2000 frames a second at 100 Hz) between the frames.
    `exposure_us`: what each frame's exposure averaged the light over, undone before the
    sensor sees it (`pecs.footage.exposure`): a number of us, "auto" (an AEDAT4 recording's
    own exposures; nothing for other sources), or None / "none" (the frames are the light at
    their times)."""
    from pecs.io import EventWriter

    source = (
        frames if isinstance(frames, FrameSource) else open_frames(frames, fps=fps, cfa=config.cfa)
    )
    if (source.width, source.height) != (config.width, config.height):
        config = config.replace(width=source.width, height=source.height)
    frame_times: list[int] = []  # the source's frames as they are read (sub-frames aside)
    footage = is_camera_footage(source.kind)
    pairs = _with_input_noise(
        footage, _noting_times(source, frame_times), input_noise, deadband_sigmas
    )
    exposure = source_exposure_us(source, exposure_us)
    if _exposed(exposure):
        pairs = exposure_deconvolved(pairs, exposure)
    pairs = _with_interpolation(footage, pairs, config, interpolation)
    pairs = _with_flicker(pairs, config, flicker)
    sensor = EventSensor(config)
    on_chip = (
        None if filters is None else EventFilter(filters, width=config.width, height=config.height)
    )
    bar = _progress_bar(progress, len(source) or None)
    with EventWriter(
        output, width=config.width, height=config.height, format=format, zero_time=zero_time
    ) as writer:
        for t_us, frame in pairs:
            batch = sensor.feed(frame, t_us)
            writer.write(batch if on_chip is None else on_chip.apply(batch))
            if bar is not None and frame_times and t_us == frame_times[-1]:
                bar.update(len(frame_times) - bar.n)
                bar.set_postfix(t=f"{t_us / 1e6:.3f}s", events=str(writer.count))
        writer.write(sensor.flush() if on_chip is None else on_chip.apply(sensor.flush()))
        if on_chip is not None:
            writer.write(on_chip.flush())
    if bar is not None:
        bar.close()
    counts = {"frames": len(frame_times), "events": writer.count}
    if on_chip is not None:
        dropped = on_chip.counts
        counts.update(
            {key: dropped[key] for key in ("afk_dropped", "trail_dropped", "erc_dropped")}
        )
    readout = sensor.readout_counts
    if readout is not None:
        counts.update({f"readout_{key}": value for key, value in readout.items()})
    return counts


def _noting_times(
    pairs: Iterable[tuple[int, np.ndarray]], times: list[int]
) -> Iterator[tuple[int, np.ndarray]]:
    """The pairs as they come, each one's time appended to `times`."""
    for t_us, frame in pairs:
        times.append(t_us)
        yield t_us, frame


def _with_input_noise(
    camera_footage: bool,
    pairs: Iterable[tuple[int, np.ndarray]],
    input_noise: InputNoise | bool | None,
    deadband_sigmas: float | None = None,
) -> Iterable[tuple[int, np.ndarray]]:
    """The (t_us, frame) pairs, with the frames' input noise held back where asked (None: where
    they are camera footage, or a deadband is stated); a deadband stated where it cannot apply
    is refused before any frame is read."""
    if deadband_sigmas is not None:
        if input_noise is False:
            raise ValueError(
                f"deadband_sigmas={deadband_sigmas} holds back the frames' noise; it cannot go "
                "with input_noise=False"
            )
        if isinstance(input_noise, InputNoise):
            raise ValueError(
                "deadband_sigmas is for an estimated noise; a stated InputNoise carries its own "
                f"(deadband_sigmas={input_noise.deadband_sigmas})"
            )
        check_deadband_sigmas("deadband_sigmas", deadband_sigmas)
    stated = deadband_sigmas is not None
    wanted = (camera_footage or stated) if input_noise is None else input_noise is not False
    if not wanted:
        return pairs
    given = input_noise if isinstance(input_noise, InputNoise) else None
    return suppress_input_noise(pairs, given, deadband_sigmas=deadband_sigmas)


def _with_interpolation(
    camera_footage: bool,
    pairs: Iterable[tuple[int, np.ndarray]],
    config: SensorConfig,
    interpolation: str,
) -> Iterable[tuple[int, np.ndarray]]:
    """The pairs with sub-frames between them where the light is not to be linear in log."""
    if interpolation not in (*INTERPOLATIONS, "auto"):
        raise ValueError(
            f"interpolation: must be 'auto' or one of {INTERPOLATIONS}, got {interpolation!r}"
        )
    if interpolation == "auto":
        interpolation = "transition" if camera_footage else "linear"
    if interpolation == "linear":
        return pairs
    if interpolation == "flow":
        return flow_subframes(pairs)
    # ln(v * white_lux / 1000 + dark) = const + ln(v + dark * 1000 / white_lux).
    offset = config.dark_current * REFERENCE_WHITE_LUX / config.white_lux
    return transition_subframes(pairs, offset, seed=config.seed)


def _with_flicker(
    pairs: Iterable[tuple[int, np.ndarray]], config: SensorConfig, flicker: Flicker | None
) -> Iterable[tuple[int, np.ndarray]]:
    """The pairs lit by a mains flicker, with sub-frames that sample it (pecs.render.flicker)."""
    if flicker is None:
        return pairs
    from pecs.render.flicker import Flicker, flickered

    if not isinstance(flicker, Flicker):
        raise TypeError(f"flicker must be a pecs.render.flicker.Flicker, got {flicker!r}")
    # The sensor interpolates ln(frame * white_lux / 1000 + dark): the same, up to a constant,
    # as ln(frame + offset).
    offset = config.dark_current * REFERENCE_WHITE_LUX / config.white_lux
    return flickered(pairs, flicker, offset)


def _progress_bar(enabled: bool, total: int | None):  # noqa: ANN202 (a tqdm bar or None)
    if not enabled:
        return None
    from tqdm import tqdm

    return tqdm(total=total, unit="frame", dynamic_ncols=True)
