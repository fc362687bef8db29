"""Frame sequences from files: image folders, videos, EXR sequences and numpy arrays, as linear
photocurrent frames with integer-microsecond timestamps, streamed one frame at a time."""

from __future__ import annotations

import math
import os
import re
from collections.abc import Callable, Iterator
from dataclasses import dataclass
from pathlib import Path
from typing import Any

import numpy as np

IMAGE_SUFFIXES = (".png", ".jpg", ".jpeg", ".tif", ".tiff", ".bmp", ".webp", ".pgm", ".ppm")
EXR_SUFFIXES = (".exr",)
VIDEO_SUFFIXES = (".mp4", ".avi", ".mov", ".mkv", ".webm", ".m4v", ".mpg", ".mpeg", ".wmv")
ARRAY_SUFFIXES = (".npy",)
TIME_UNITS_US = {"us": 1.0, "ms": 1e3, "s": 1e6}
#: Times are f64 seconds in the core, exact to the microsecond up to 2^53 us (285 years).
MAX_ABS_TIME_US = 2**53
#: Frames closer than 1 us would share a timestamp: pecs's time resolution is 1 us.
MAX_FPS = 1e6

# Rec. 709 / sRGB luminance weights of linear R, G, B.
_LUMINANCE_RGB = np.array([0.2126, 0.7152, 0.0722], np.float32)


def srgb_to_linear(encoded: np.ndarray) -> np.ndarray:
    """IEC 61966-2-1: v / 12.92 below 0.04045, ((v + 0.055) / 1.055)^2.4 above; v in [0, 1]."""
    v = np.asarray(encoded, np.float32)
    return np.where(v <= 0.04045, v / 12.92, ((v + 0.055) / 1.055) ** 2.4).astype(np.float32)


def to_luminance(image: np.ndarray) -> np.ndarray:
    """Linear luminance of a linear image: grey as is, RGB(A) by Rec. 709 weights."""
    if image.ndim == 2:
        return image
    return np.tensordot(image[..., :3], _LUMINANCE_RGB, axes=([-1], [0])).astype(np.float32)


def lift_black(linear: np.ndarray, full_scale: float, encoding: str = "linear") -> np.ndarray:
    """Camera footage: a pixel read as code 0 had light below one code, not none, so it gets the
    centre of that interval, half a code (as linear light). Taken as 0 the DVS pixel behind it
    would see its dark current alone, and the shot noise of darkness (10 Hz for davis346) where
    a daylight scene has shadows. Rendered frames keep their zeros (this is not applied).
    `linear` (float32, a frame of its own) is lifted in place, without a second frame."""
    half_code = np.float32(0.5 / full_scale)
    floor = srgb_to_linear(half_code) if encoding == "srgb" else half_code
    return np.maximum(linear, floor, out=linear)


def decode_image(raw: np.ndarray, encoding: str = "srgb", cfa: Any = None) -> np.ndarray:
    """An 8- or 16-bit image (as OpenCV reads it, BGR order) as linear luminance in [0, 1]; with
    a colour filter array (`pecs.render.cfa.ColourFilterArray`), a colour image goes through its
    pattern instead: each pixel takes its own filter's channel (`mosaic_rgb`)."""
    if raw.dtype == np.uint8:
        scaled = raw.astype(np.float32) / 255.0
    elif raw.dtype == np.uint16:
        scaled = raw.astype(np.float32) / 65535.0
    elif raw.dtype == np.float32:
        scaled = raw
    else:
        raise ValueError(f"unsupported image sample type {raw.dtype}; expected 8- or 16-bit")
    if scaled.ndim == 3:
        scaled = scaled[..., [2, 1, 0]] if scaled.shape[-1] >= 3 else scaled[..., 0]
    linear = srgb_to_linear(scaled) if encoding == "srgb" else scaled
    if cfa is not None and linear.ndim == 3:
        return cfa.mosaic_rgb(linear)
    return to_luminance(linear)


def decode_footage(raw: np.ndarray, encoding: str = "srgb", cfa: Any = None) -> np.ndarray:
    """A camera's 8- or 16-bit image as linear luminance (through `cfa`, where given), its black
    lifted (`lift_black`)."""
    full_scale = 65535.0 if raw.dtype == np.uint16 else 255.0
    return lift_black(decode_image(raw, encoding, cfa), full_scale, encoding)


@dataclass
class FrameSource:
    """A sequence of frames on disk; iterate for (t_us, frame) pairs, frames float32 (H, W)."""

    path: Path
    kind: str
    width: int
    height: int
    timestamps_us: np.ndarray | None
    fps: float | None
    count: int | None
    channel: str | None = None
    encoding: str = "srgb"
    _files: tuple[Path, ...] = ()
    #: Colour filter array colour frames go through (`pecs.render.cfa`); None: luminance.
    cfa: Any = None

    def __len__(self) -> int:
        return self.count or 0

    def __iter__(self) -> Iterator[tuple[int, np.ndarray]]:
        frames = {
            "images": self._images,
            "exr": self._exrs,
            "video": self._video,
            "array": self._array,
        }[self.kind]()
        for index, frame in enumerate(frames):
            yield self._time_us(index), frame

    def _time_us(self, index: int) -> int:
        if self.timestamps_us is not None:
            if index >= len(self.timestamps_us):
                raise ValueError(
                    f"{self.path}: more frames than timestamps ({len(self.timestamps_us)})"
                )
            return int(self.timestamps_us[index])
        assert self.fps is not None
        return round(index * 1e6 / self.fps)

    def _images(self) -> Iterator[np.ndarray]:
        for file in self._files:
            yield self._checked(file, read_image(file, self.encoding, self.cfa))

    def _exrs(self) -> Iterator[np.ndarray]:
        for file in self._files:
            yield self._checked(file, read_exr(file, self.channel))

    def _video(self) -> Iterator[np.ndarray]:
        capture = _open_video(self.path)
        try:
            while True:
                ok, raw = capture.read()
                if not ok:
                    return
                yield decode_footage(raw, self.encoding, self.cfa)
        finally:
            capture.release()

    def _array(self) -> Iterator[np.ndarray]:
        for frame in np.load(self.path, mmap_mode="r"):
            # 8/16-bit frames are images, decoded as image files are; floats are photocurrent.
            yield decode_image(frame, self.encoding) if frame.dtype.kind == "u" else frame

    def _checked(self, file: Path, frame: np.ndarray) -> np.ndarray:
        if frame.shape != (self.height, self.width):
            raise ValueError(
                f"{file}: frame is {frame.shape[1]} x {frame.shape[0]}, the sequence is {self.width} x {self.height}"
            )
        return frame


def open_frames(
    path: str | os.PathLike[str],
    *,
    fps: float | None = None,
    timestamps: str | os.PathLike[str] | np.ndarray | None = None,
    timestamp_unit: str = "us",
    channel: str | None = None,
    encoding: str = "srgb",
    cfa: str | None = None,
) -> FrameSource:
    """Open a folder of images or EXR files, a video, a .npy array (N, H, W) of frames, or the
    APS frames of an AEDAT4 recording (times and size from the file; `pecs.footage.aedat4_frames`).

    Timestamps come from `timestamps` (an array, or a text file with one number per line, first
    column, in `timestamp_unit`), else from `fps`, else from the video's own frame rate.
    `encoding` is how 8/16-bit images are stored: "srgb" (decoded to linear) or "linear".
    `cfa` (a colour filter pattern, "RGBG"; `pecs.render.cfa`): colour images and video go through
    it, each pixel taking its filter's channel, as a colour event sensor sees them; grey stays grey.
    """
    source = Path(path)
    if not source.exists():
        raise FileNotFoundError(f"no such file or folder: {source}")
    if source.suffix.lower() == ".aedat4":  # the APS frames of a DAVIS recording
        from pecs.footage.aedat4_frames import open_aedat4_frames

        return open_aedat4_frames(source, fps=fps, timestamps=timestamps)
    if encoding not in ("srgb", "linear"):
        raise ValueError(f"encoding: must be 'srgb' or 'linear', got {encoding!r}")
    if fps is not None:
        _check_fps(fps)
    times = _timestamps(timestamps, timestamp_unit) if timestamps is not None else None
    if source.is_dir():
        frames = _folder(source, channel, encoding)
    elif source.suffix.lower() in ARRAY_SUFFIXES:
        frames = _npy(source, encoding)
    elif source.suffix.lower() in VIDEO_SUFFIXES:
        frames = _video_source(source, encoding)
    else:
        known = ", ".join(VIDEO_SUFFIXES + ARRAY_SUFFIXES)
        raise ValueError(f"{source}: not a folder of frames nor a known video or array ({known})")
    frames.timestamps_us = times
    frames.fps = fps or frames.fps
    if cfa is not None:
        from pecs.render.cfa import load_cfa

        frames.cfa = load_cfa(cfa)
    if times is None and frames.fps is None:
        raise ValueError(f"{source}: give a frame rate (fps) or a timestamps file")
    if times is not None and frames.count is not None and len(times) < frames.count:
        raise ValueError(f"{source}: {frames.count} frames but only {len(times)} timestamps")
    return frames


def _folder(folder: Path, channel: str | None, encoding: str) -> FrameSource:
    files = sorted((f for f in folder.iterdir() if f.is_file()), key=_natural_key)
    exrs = tuple(f for f in files if f.suffix.lower() in EXR_SUFFIXES)
    images = tuple(f for f in files if f.suffix.lower() in IMAGE_SUFFIXES)
    if exrs and images:
        raise ValueError(f"{folder}: mixes EXR and other images; keep one kind per folder")
    chosen = exrs or images
    if not chosen:
        raise ValueError(
            f"{folder}: no frames (looked for {', '.join(IMAGE_SUFFIXES + EXR_SUFFIXES)})"
        )
    first = read_exr(chosen[0], channel) if exrs else read_image(chosen[0], encoding)
    height, width = first.shape
    kind = "exr" if exrs else "images"
    return FrameSource(
        folder, kind, width, height, None, None, len(chosen), channel, encoding, chosen
    )


def read_image(file: Path, encoding: str = "srgb", cfa: Any = None) -> np.ndarray:
    """One 8/16-bit image file as linear luminance in [0, 1] (through `cfa`, where given)."""
    import cv2

    raw = cv2.imread(str(file), cv2.IMREAD_UNCHANGED)
    if raw is None:
        raise ValueError(f"{file}: not a readable image")
    return decode_image(raw, encoding, cfa)


def read_exr(file: Path, channel: str | None = None) -> np.ndarray:
    """One channel of an EXR file (default Y, else the luminance of R, G, B), read in Rust."""
    from pecs._core import read_exr as _read_exr

    frame, _ = _read_exr(str(file), channel)
    return frame


def _npy(file: Path, encoding: str) -> FrameSource:
    try:
        array = np.load(file, mmap_mode="r")
    except ValueError as error:
        raise ValueError(f"{file}: not a readable .npy array ({error})") from error
    if array.ndim != 3:
        raise ValueError(f"{file}: expected an array of frames (N, H, W), got shape {array.shape}")
    if array.dtype not in _ARRAY_DTYPES:
        raise ValueError(
            f"{file}: frames of dtype {array.dtype}; expected float32/float64 photocurrent or "
            "uint8/uint16 images"
        )
    height, width = array.shape[1:]
    return FrameSource(file, "array", width, height, None, None, array.shape[0], None, encoding)


_ARRAY_DTYPES = tuple(np.dtype(t) for t in ("<f4", ">f4", "<f8", ">f8", "u1", "<u2", ">u2"))


def _open_video(file: Path):  # noqa: ANN202 (cv2.VideoCapture)
    import cv2

    capture = cv2.VideoCapture(str(file))
    if not capture.isOpened():
        raise ValueError(f"{file}: not a readable video")
    return capture


def _video_source(file: Path, encoding: str) -> FrameSource:
    import cv2

    capture = _open_video(file)
    try:
        width = int(capture.get(cv2.CAP_PROP_FRAME_WIDTH))
        height = int(capture.get(cv2.CAP_PROP_FRAME_HEIGHT))
        fps = capture.get(cv2.CAP_PROP_FPS) or None
        count = int(capture.get(cv2.CAP_PROP_FRAME_COUNT)) or None
    finally:
        capture.release()
    return FrameSource(file, "video", width, height, None, fps, count, None, encoding)


def _check_fps(fps: float) -> None:
    if isinstance(fps, bool) or not isinstance(fps, (int, float, np.integer, np.floating)):
        raise ValueError(f"fps: must be a number, got {fps!r}")
    if not (math.isfinite(fps) and fps > 0):
        raise ValueError(f"fps: must be > 0, got {fps!r}")
    if fps > MAX_FPS:
        raise ValueError(
            f"fps: {fps:g} frames per second puts frames {1e6 / fps:.3g} us apart, but pecs's "
            f"times are whole microseconds: fps must be at most {MAX_FPS:g}"
        )


def _timestamps(timestamps: str | os.PathLike[str] | np.ndarray, unit: str) -> np.ndarray:
    if unit not in TIME_UNITS_US:
        raise ValueError(f"timestamp_unit: must be one of {', '.join(TIME_UNITS_US)}, got {unit!r}")
    if isinstance(timestamps, np.ndarray):
        return times_us(timestamps, unit, "timestamps")
    file = Path(timestamps)
    if not file.is_file():
        raise FileNotFoundError(f"no such file: {file} (the timestamps, --timestamps)")
    try:
        values = np.loadtxt(file, usecols=0, ndmin=1, comments="#", dtype=np.float64)
    except ValueError as error:
        raise ValueError(f"{file}: not a column of numbers ({error})") from error
    return times_us(values, unit, str(file), line_numbers=True)


def times_us(
    values: object, unit: str = "us", where: str = "t_us", *, line_numbers: bool = False
) -> np.ndarray:
    """Timestamps in `unit` as strictly increasing int64 microseconds. Integer or float values;
    in us they must be whole, in ms or s they are rounded to the microsecond. A ValueError names
    the first bad value (by line number for a file) and, where the values look like seconds
    given as microseconds, says so."""
    array = np.asarray(values)
    if array.ndim != 1:
        raise ValueError(f"{where}: must be a 1-D sequence of times, got shape {array.shape}")
    if array.dtype.kind not in "iuf" or array.dtype == np.bool_:
        raise ValueError(f"{where}: must be numbers of {unit}, got dtype {array.dtype}")
    name = (lambda i: f"{where}: line {i + 1}") if line_numbers else (lambda i: f"{where}[{i}]")
    raw = array.astype(np.float64)
    if array.dtype.kind in "iu":
        return _increasing(_in_range(raw, array, unit, where, name), array, unit, where, name)
    bad = np.flatnonzero(~np.isfinite(raw))
    if bad.size:
        raise ValueError(f"{name(int(bad[0]))} is {raw[bad[0]]}; times must be finite")
    scaled = _in_range(raw, array, unit, where, name)
    rounded = np.round(scaled)
    if unit == "us":
        fractional = np.flatnonzero(rounded != scaled)
        if fractional.size:
            i = int(fractional[0])
            raise ValueError(
                f"{name(i)} = {raw[i].item()!r} is not a whole number of microseconds"
                + _seconds_hint(raw, unit)
            )
    return _increasing(rounded, raw, unit, where, name)


def _in_range(
    raw: np.ndarray, given: np.ndarray, unit: str, where: str, name: Callable[[int], str]
) -> np.ndarray:
    """The times (`raw`, `given` as float64) in microseconds, each checked to be within
    +-2^53 us before it is scaled."""
    far = np.flatnonzero(np.abs(raw) > MAX_ABS_TIME_US / TIME_UNITS_US[unit])
    if far.size:
        i = int(far[0])
        raise ValueError(
            f"{name(i)} = {given[i].item()!r} is out of range: times must be within +-2^53 us "
            "(285 years)"
        )
    return raw * TIME_UNITS_US[unit]


def _increasing(
    t_us: np.ndarray, raw: np.ndarray, unit: str, where: str, name: Callable[[int], str]
) -> np.ndarray:
    t_us = t_us.astype(np.int64)
    bad = np.flatnonzero(np.diff(t_us) <= 0)
    if bad.size:
        i = int(bad[0]) + 1
        collided = raw[i] > raw[i - 1]  # distinct values that fall on the same microsecond
        raise ValueError(
            f"timestamps must increase: {name(i)} = {raw[i].item()!r} follows "
            f"{raw[i - 1].item()!r}"
            + (" at the same microsecond" + _seconds_hint(raw, unit) if collided else "")
        )
    return t_us


def _seconds_hint(raw: np.ndarray, unit: str) -> str:
    """Why times in us would be fractional or collide: seconds read as microseconds, which
    step by less than 1 from frame to frame (any frame rate above 1 Hz)."""
    if unit != "us" or len(raw) < 2 or not np.all(np.abs(np.diff(raw)) < 1):
        return ""
    return (
        "; these timestamps look like seconds: give their unit as s "
        "(timestamp_unit, --timestamp-unit)"
    )


def _natural_key(path: Path) -> list[object]:
    """frame2.png before frame10.png."""
    return [int(part) if part.isdigit() else part for part in re.split(r"(\d+)", path.name)]
