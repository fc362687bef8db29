"""Pictures of event streams: event frames, time surfaces, and videos of the stream.

Every function returns numpy images, uint8 RGB, H x W x 3, origin top-left (row = y, column = x),
so they go straight into matplotlib, OpenCV (after RGB -> BGR) or `save_image`.
"""

from __future__ import annotations

import json
import os
from collections.abc import Iterable, Iterator
from pathlib import Path
from typing import Any

import numpy as np
import pyarrow as pa

from pecs._atomic import atomic_path
from pecs.events import sensor_size
from pecs.io import to_table

__all__ = [
    "event_frame",
    "event_frames",
    "save_image",
    "save_video",
    "time_surface",
    "time_surface_image",
]

# Colours (RGB) per background: ON blue, OFF red, the usual pairing in DV and Metavision viewers;
# lighter tones on black so both stay visible.
_PALETTES = {
    "white": {"background": (255, 255, 255), "on": (33, 102, 172), "off": (214, 39, 40)},
    "black": {"background": (0, 0, 0), "on": (86, 180, 233), "off": (255, 80, 60)},
}


def _palette(background: str) -> dict[str, tuple[int, int, int]]:
    if background not in _PALETTES:
        raise ValueError(f"background must be one of {sorted(_PALETTES)}, got {background!r}")
    return _PALETTES[background]


def _columns(events: Any) -> tuple[pa.Schema, np.ndarray, np.ndarray, np.ndarray, np.ndarray]:
    """(schema, t, x, y, p) as numpy arrays from anything `pecs.io.to_table` accepts."""
    table = to_table(events)
    for name in ("t", "x", "y", "p"):
        if name not in table.column_names:
            raise ValueError(f"events have no column {name!r} (columns: {table.column_names})")

    def column(name: str) -> np.ndarray:
        return table.column(name).to_numpy()

    return table.schema, column("t"), column("x"), column("y"), column("p")


def _resolve_size(
    schema: pa.Schema,
    x: np.ndarray,
    y: np.ndarray,
    width: int | None,
    height: int | None,
) -> tuple[int, int]:
    """Sensor size: the arguments, else the schema metadata, else the largest address + 1."""
    size = sensor_size(schema)
    if width is None:
        width = size[0] if size else (int(x.max()) + 1 if len(x) else None)
    if height is None:
        height = size[1] if size else (int(y.max()) + 1 if len(y) else None)
    if width is None or height is None:
        raise ValueError("sensor size unknown: no events and no width/height given or stored")
    if width <= 0 or height <= 0:
        raise ValueError(f"sensor size must be positive, got {width} x {height}")
    return int(width), int(height)


def _window(t: np.ndarray, t_start_us: int | None, t_end_us: int | None) -> tuple[int, int] | None:
    """Index range [i, j) of the events with t_start_us <= t < t_end_us (t sorted)."""
    i = 0 if t_start_us is None else int(np.searchsorted(t, t_start_us, side="left"))
    j = len(t) if t_end_us is None else int(np.searchsorted(t, t_end_us, side="left"))
    return i, max(i, j)


def _paint(
    x: np.ndarray,
    y: np.ndarray,
    p: np.ndarray,
    width: int,
    height: int,
    background: str,
    cfa: str | None = None,
) -> np.ndarray:
    """Frame where each pixel shows the polarity of its latest event (events in time order);
    under a colour filter array (`cfa`), its channel's colour: full for ON, halfway to the
    background for OFF."""
    colours = _palette(background)
    image = np.empty((height, width, 3), dtype=np.uint8)
    image[:] = colours["background"]
    if len(x) == 0:
        return image
    if int(x.max()) >= width or int(y.max()) >= height:
        raise ValueError(
            f"event address outside the {width} x {height} sensor "
            f"(max x {int(x.max())}, max y {int(y.max())})"
        )
    pixel = y.astype(np.int64) * width + x.astype(np.int64)
    # Latest event per pixel: first occurrence in the reversed stream.
    reversed_pixel = pixel[::-1]
    unique_pixel, first_in_reversed = np.unique(reversed_pixel, return_index=True)
    latest_on = p[::-1][first_in_reversed] > 0
    flat = image.reshape(-1, 3)
    if cfa is not None:
        flat[unique_pixel] = _channel_colours(cfa, unique_pixel, width, latest_on, background)
        return image
    flat[unique_pixel[latest_on]] = colours["on"]
    flat[unique_pixel[~latest_on]] = colours["off"]
    return image


def _channel_colours(
    pattern: str, pixel: np.ndarray, width: int, on: np.ndarray, background: str
) -> np.ndarray:
    """RGB of events at flat pixel indices: their filter's colour, OFF halfway to the background."""
    from pecs.render.cfa import CHANNEL_COLOURS_RGB, load_cfa

    cfa = load_cfa(pattern)
    palette = np.array([CHANNEL_COLOURS_RGB[c] for c in cfa.channels], dtype=np.float32)
    colour = palette[cfa.channel_of(pixel % width, pixel // width)]
    back = np.asarray(_palette(background)["background"], dtype=np.float32)
    colour = np.where(on[:, None], colour, 0.5 * (colour + back))
    return np.round(colour).astype(np.uint8)


def sensor_cfa(schema: pa.Schema | None) -> str | None:
    """The colour filter pattern of the sensor that made the events (the `cfa` field of the
    `pecs.sensor` schema metadata), None for a monochrome sensor or unknown."""
    metadata = (schema.metadata if schema is not None else None) or {}
    try:
        cfa = json.loads(metadata.get(b"pecs.sensor", b"{}")).get("cfa")
    except (ValueError, AttributeError):
        return None
    return cfa if isinstance(cfa, str) else None


def event_frame(
    events: Any,
    width: int | None = None,
    height: int | None = None,
    *,
    t_start_us: int | None = None,
    t_end_us: int | None = None,
    background: str = "white",
) -> np.ndarray:
    """Event frame (uint8, H x W x 3): the events in [t_start_us, t_end_us) accumulated.

    A pixel takes the ON colour (blue) or OFF colour (red) of its most recent event in the window
    and the background colour ("white" or "black") where it has none. Events of a colour sensor
    (a `cfa` in the `pecs.sensor` metadata) take their pixel's filter colour instead (R, G, B,
    white), full for ON and halfway to the background for OFF. Size: the arguments, else the
    schema metadata, else the largest address + 1.
    """
    schema, t, x, y, p = _columns(events)
    width, height = _resolve_size(schema, x, y, width, height)
    if len(t) > 1 and np.any(np.diff(t) < 0):
        order = np.argsort(t, kind="stable")
        t, x, y, p = t[order], x[order], y[order], p[order]
    i, j = _window(t, t_start_us, t_end_us)
    return _paint(x[i:j], y[i:j], p[i:j], width, height, background, sensor_cfa(schema))


def time_surface(
    events: Any,
    width: int | None = None,
    height: int | None = None,
    *,
    t_us: int | None = None,
    tau_us: float = 50_000.0,
) -> np.ndarray:
    """Exponential time surface (float32, 2 x H x W; channel 0 OFF, 1 ON) at time `t_us`.

    Lagorce et al. 2017 (HOTS): S_p(x, y) = exp(-(t - t_last_p(x, y)) / tau); 0 where the pixel
    has no event of polarity p at or before t. `t_us` defaults to the last event's time.
    """
    if tau_us <= 0:
        raise ValueError(f"tau_us must be positive, got {tau_us}")
    schema, t, x, y, p = _columns(events)
    width, height = _resolve_size(schema, x, y, width, height)
    surface = np.zeros((2, height, width), dtype=np.float32)
    if len(t) == 0:
        return surface
    t_now = int(t.max()) if t_us is None else int(t_us)
    keep = t <= t_now
    t, x, y, p = t[keep], x[keep], y[keep], p[keep]
    if len(t) and (int(x.max()) >= width or int(y.max()) >= height):
        raise ValueError(f"event address outside the {width} x {height} sensor")
    last = np.full((2, height, width), np.iinfo(np.int64).min, dtype=np.int64)
    np.maximum.at(last, ((p > 0).astype(np.intp), y.astype(np.intp), x.astype(np.intp)), t)
    seen = last != np.iinfo(np.int64).min
    age_us = (t_now - last[seen]).astype(np.float64)
    surface[seen] = np.exp(-age_us / tau_us).astype(np.float32)
    return surface


def time_surface_image(
    events: Any,
    width: int | None = None,
    height: int | None = None,
    *,
    t_us: int | None = None,
    tau_us: float = 50_000.0,
    background: str = "white",
) -> np.ndarray:
    """Time surface as an RGB image: each pixel blends from the background towards the colour of
    its most recent polarity by that polarity's surface value (recent = saturated)."""
    surface = time_surface(events, width, height, t_us=t_us, tau_us=tau_us)
    colours = _palette(background)
    back = np.asarray(colours["background"], dtype=np.float32)
    on_wins = surface[1] >= surface[0]
    strength = np.where(on_wins, surface[1], surface[0])[..., None]
    colour = np.where(
        on_wins[..., None],
        np.asarray(colours["on"], dtype=np.float32),
        np.asarray(colours["off"], dtype=np.float32),
    )
    image = back + strength * (colour - back)
    return np.clip(np.rint(image), 0, 255).astype(np.uint8)


def event_frames(
    events: Any,
    width: int | None = None,
    height: int | None = None,
    *,
    window_us: int = 33_333,
    t_start_us: int | None = None,
    t_end_us: int | None = None,
    background: str = "white",
) -> Iterator[np.ndarray]:
    """Event frames over consecutive windows of `window_us`, streaming.

    `events` may be an iterable of record batches (sorted in t across batches, as `iter_events`
    yields them) so a long recording never sits in memory; then width and height come from the
    arguments or the first batch's schema metadata.
    """
    if window_us <= 0:
        raise ValueError(f"window_us must be positive, got {window_us}")
    batches = _batches(events)
    pending: list[tuple[np.ndarray, ...]] = []
    window_start = t_start_us
    size: tuple[int, int] | None = None
    cfa: str | None = None
    for batch in batches:
        schema, t, x, y, p = _columns(batch)
        if size is None:
            size = _batch_size(schema, x, y, width, height)
            cfa = sensor_cfa(schema)
        if t_end_us is not None:
            keep = t < t_end_us
            t, x, y, p = t[keep], x[keep], y[keep], p[keep]
        if t_start_us is not None:
            keep = t >= t_start_us
            t, x, y, p = t[keep], x[keep], y[keep], p[keep]
        if len(t) == 0:
            continue
        if window_start is None:
            window_start = int(t[0])
        pending.append((t, x, y, p))
        # Emit every window that ends before this batch's last event: later batches cannot add to it.
        while window_start + window_us <= int(t[-1]):
            yield _frame_from_pending(pending, window_start, window_us, size, background, cfa)
            window_start += window_us
            pending = _drop_before(pending, window_start)
    if size is None or window_start is None:
        return
    end = t_end_us if t_end_us is not None else window_start + window_us
    while window_start < end:
        yield _frame_from_pending(pending, window_start, window_us, size, background, cfa)
        window_start += window_us
        pending = _drop_before(pending, window_start)


def _batches(events: Any) -> Iterable[pa.RecordBatch | pa.Table]:
    if isinstance(events, (pa.Table, pa.RecordBatch, str, os.PathLike, np.ndarray)):
        return [to_table(events)]
    if isinstance(events, Iterable):
        return events
    return [to_table(events)]


def _batch_size(
    schema: pa.Schema, x: np.ndarray, y: np.ndarray, width: int | None, height: int | None
) -> tuple[int, int]:
    if (width is None or height is None) and sensor_size(schema) is None:
        raise ValueError("event_frames on a stream needs width and height (or schema metadata)")
    return _resolve_size(schema, x, y, width, height)


def _frame_from_pending(
    pending: list[tuple[np.ndarray, ...]],
    window_start: int,
    window_us: int,
    size: tuple[int, int],
    background: str,
    cfa: str | None = None,
) -> np.ndarray:
    parts = [_slice(chunk, window_start, window_start + window_us) for chunk in pending]
    x = np.concatenate([part[1] for part in parts]) if parts else np.zeros(0, np.uint16)
    y = np.concatenate([part[2] for part in parts]) if parts else np.zeros(0, np.uint16)
    p = np.concatenate([part[3] for part in parts]) if parts else np.zeros(0, np.int8)
    return _paint(x, y, p, size[0], size[1], background, cfa)


def _slice(chunk: tuple[np.ndarray, ...], start: int, end: int) -> tuple[np.ndarray, ...]:
    t = chunk[0]
    i, j = np.searchsorted(t, start, side="left"), np.searchsorted(t, end, side="left")
    return tuple(column[i:j] for column in chunk)


def _drop_before(pending: list[tuple[np.ndarray, ...]], start: int) -> list[tuple[np.ndarray, ...]]:
    kept = []
    for chunk in pending:
        i = int(np.searchsorted(chunk[0], start, side="left"))
        if i < len(chunk[0]):
            kept.append(tuple(column[i:] for column in chunk))
    return kept


def save_image(image: np.ndarray, path: str | os.PathLike[str]) -> Path:
    """Write an RGB (H x W x 3) or grey (H x W) uint8 image as PNG, atomically."""
    import cv2

    array = _as_uint8_image(image)
    bgr = array[..., ::-1] if array.ndim == 3 else array
    ok, encoded = cv2.imencode(".png", np.ascontiguousarray(bgr))
    if not ok:
        raise ValueError(f"{path}: OpenCV could not encode a {array.shape} image as PNG")
    file = Path(path)
    with atomic_path(file) as tmp:
        tmp.write_bytes(encoded.tobytes())
    return file


def _as_uint8_image(image: np.ndarray) -> np.ndarray:
    array = np.asarray(image)
    if array.dtype != np.uint8:
        raise TypeError(f"image must be uint8, got {array.dtype}")
    if array.ndim == 3 and array.shape[2] == 3 or array.ndim == 2:
        return array
    raise ValueError(f"image must be H x W x 3 (RGB) or H x W, got shape {array.shape}")


def save_video(
    frames: Iterable[np.ndarray],
    path: str | os.PathLike[str],
    *,
    fps: float = 30.0,
) -> Path:
    """Write RGB frames as a video, atomically: `.mp4` (OpenCV, mp4v) or `.gif` (Pillow)."""
    if fps <= 0:
        raise ValueError(f"fps must be positive, got {fps}")
    file = Path(path)
    suffix = file.suffix.lower()
    if suffix not in (".mp4", ".gif"):
        raise ValueError(f"{file}: video format {suffix!r} not supported; use .mp4 or .gif")
    with atomic_path(file) as tmp:
        count = _write_mp4(frames, tmp, fps) if suffix == ".mp4" else _write_gif(frames, tmp, fps)
    if count == 0:
        file.unlink()
        raise ValueError(f"{file}: no frames to write")
    return file


def _write_mp4(frames: Iterable[np.ndarray], tmp: Path, fps: float) -> int:
    import cv2

    # OpenCV chooses the container from the file name, so encode under a .mp4 name first.
    video_tmp = tmp.with_name(tmp.name + ".mp4")
    writer = None
    count = 0
    try:
        for frame in frames:
            array = _as_uint8_image(frame)
            rgb = np.repeat(array[..., None], 3, axis=2) if array.ndim == 2 else array
            if writer is None:
                fourcc = cv2.VideoWriter_fourcc(*"mp4v")
                size = (rgb.shape[1], rgb.shape[0])
                writer = cv2.VideoWriter(str(video_tmp), fourcc, float(fps), size)
                if not writer.isOpened():
                    raise ValueError(f"OpenCV cannot open an mp4v video writer for {size}")
            writer.write(np.ascontiguousarray(rgb[..., ::-1]))
            count += 1
        if writer is not None:
            writer.release()
            writer = None
            os.replace(video_tmp, tmp)
    finally:
        if writer is not None:
            writer.release()
        video_tmp.unlink(missing_ok=True)
    return count


def _write_gif(frames: Iterable[np.ndarray], tmp: Path, fps: float) -> int:
    """Frames written as they come: Pillow's save_all keeps every frame until the end (a 1 us
    window on a 2.3 s recording filled 23 GB), here one or two frames are held at a time."""
    duration_ms = max(20, round(1000.0 / fps))  # browsers clamp faster GIF frames
    count = 0
    with open(tmp, "wb") as file:
        stream = _GifStream(file, duration_ms)
        for frame in frames:
            array = _as_uint8_image(frame)
            stream.add(np.repeat(array[..., None], 3, axis=2) if array.ndim == 2 else array)
            count += 1
        stream.close()
    return count


# A GIF frame's delay is 16 bits of centiseconds.
_GIF_MAX_DELAY_MS = 655_350


class _GifStream:
    """An animated GIF, looping, written frame by frame. As Pillow's writer does, a frame equal
    to the one before lengthens it instead of being stored, and a frame is stored as the box in
    which it differs from the one before (left in place under it: disposal 0), each with its own
    palette. The frame waits until the next one is known, since its delay may still grow."""

    def __init__(self, file: Any, duration_ms: int) -> None:
        self.file = file
        self.duration_ms = duration_ms
        self.shown: np.ndarray | None = None  # the last frame, as the viewer will show it
        self.pending: tuple[np.ndarray, tuple[int, int]] | None = None
        self.pending_ms = 0
        self.started = False

    def add(self, rgb: np.ndarray) -> None:
        if self.shown is not None and rgb.shape != self.shown.shape:
            raise ValueError(
                f"GIF frames must all have one size: {rgb.shape[1]} x {rgb.shape[0]} after "
                f"{self.shown.shape[1]} x {self.shown.shape[0]}"
            )
        box = None if self.shown is None else _changed_box(self.shown, rgb)
        same = box == ((0, 0), (0, 0))
        if same and self.pending_ms + self.duration_ms <= _GIF_MAX_DELAY_MS:
            self.pending_ms += self.duration_ms
            return
        self._write_pending()
        if box is None or same:
            self.pending = (rgb.copy(), (0, 0))
        else:
            (y0, y1), (x0, x1) = box
            self.pending = (rgb[y0:y1, x0:x1].copy(), (x0, y0))
        self.pending_ms = self.duration_ms
        self.shown = rgb.copy()

    def close(self) -> None:
        self._write_pending()
        if self.started:
            self.file.write(b";")  # the GIF trailer

    def _write_pending(self) -> None:
        if self.pending is None:
            return
        from PIL import GifImagePlugin, Image

        pixels, offset = self.pending
        image = Image.fromarray(pixels).convert("P", palette=Image.Palette.ADAPTIVE)
        # The first frame's palette is the global one; each later frame carries its own.
        params: dict[str, Any] = {"duration": self.pending_ms, "include_color_table": self.started}
        if not self.started:
            header, _ = GifImagePlugin.getheader(image, info={"loop": 0, **params})
            self.file.write(b"".join(header))
            self.started = True
        self.file.write(b"".join(GifImagePlugin.getdata(image, offset, **params)))
        self.pending = None


def _changed_box(before: np.ndarray, after: np.ndarray) -> tuple[tuple[int, int], ...]:
    """((y0, y1), (x0, x1)): the smallest box holding every pixel that differs; ((0, 0), (0, 0))
    where none does. (Indices of the changed bytes: a reduction over the colour axis took
    longer than encoding the frame.)"""
    changed = np.flatnonzero(before.reshape(-1) != after.reshape(-1)) // 3
    if not len(changed):
        return (0, 0), (0, 0)
    width = before.shape[1]
    rows, columns = changed // width, changed % width
    return (int(rows[0]), int(rows[-1]) + 1), (int(columns.min()), int(columns.max()) + 1)
