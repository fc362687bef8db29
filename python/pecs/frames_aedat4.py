"""The APS frames of an AEDAT 4.0 recording (iniVation DV, DAVIS cameras) as a frame source.

A DAVIS records grey-level APS frames beside its events, from the same pixels. Each AEDAT4
frame packet carries `timestamp`, the exposure midpoint (faery's `Frame.t`; dv-processing's
`Frame.timestamp` is the exposure start instead, tests/data/davis346_excerpt/README.md), and
8-bit pixels. The DAVIS APS readout is linear in light (no gamma is applied by the camera or DV),
so a frame becomes photocurrent as DN / 255 with no decoding: 1.0 is a full-scale pixel.
"""

from __future__ import annotations

from collections.abc import Iterator
from dataclasses import dataclass
from pathlib import Path
from typing import Any

import numpy as np

from pecs.frames import FrameSource, lift_black, to_luminance
from pecs.io import EventFileError
from pecs.io._faery import is_decoder_failure

AEDAT4_SUFFIXES = (".aedat4",)

# Full scale of each AEDAT4 frame format (faery's names): pixel values divide by it.
_FULL_SCALE = {"L": 255.0, "I;16": 65535.0, "RGB": 255.0, "RGBA": 255.0}


@dataclass
class Aedat4FrameSource(FrameSource):
    """The APS frames of one AEDAT4 file, as (exposure-midpoint t_us, float32 (H, W)) pairs."""

    track_id: int = 0

    def __iter__(self) -> Iterator[tuple[int, np.ndarray]]:
        previous_us: int | None = None
        for frame in self._packets():
            t_us = int(frame.t)
            if previous_us is not None and t_us <= previous_us:
                raise ValueError(
                    f"{self.path}: APS frame times must increase; {t_us} us follows {previous_us} us"
                )
            previous_us = t_us
            yield t_us, self._photocurrent(frame)

    def _packets(self) -> Iterator[Any]:
        decoder = _decoder(self.path)
        with decoder:
            try:
                for track, packet in decoder:
                    if track.id == self.track_id:
                        yield packet
            except BaseException as error:
                if not is_decoder_failure(error):
                    raise
                raise EventFileError(self.path, 0, f"corrupt AEDAT4 packet ({error})") from error

    def _photocurrent(self, frame: Any) -> np.ndarray:
        """DN / full scale: the APS is linear, so no gamma to undo; 0 DN lifted to half a DN
        (`lift_black`)."""
        if frame.format not in _FULL_SCALE:
            raise ValueError(f"{self.path}: unsupported AEDAT4 frame format {frame.format!r}")
        pixels = np.asarray(frame.pixels)
        linear = to_luminance(pixels.astype(np.float32) / np.float32(_FULL_SCALE[frame.format]))
        if linear.shape != (self.height, self.width) or (frame.offset_x, frame.offset_y) != (0, 0):
            raise ValueError(
                f"{self.path}: APS frame is {linear.shape[1]} x {linear.shape[0]} at offset "
                f"({frame.offset_x}, {frame.offset_y}); only full {self.width} x {self.height} "
                "frames are supported"
            )
        full_scale = _FULL_SCALE[frame.format]
        return np.ascontiguousarray(lift_black(linear, full_scale), dtype=np.float32)


def open_aedat4_frames(
    path: Path, *, fps: float | None = None, timestamps: Any = None
) -> FrameSource:
    """The first frame stream of an AEDAT4 file; its times and size come from the file."""
    if fps is not None or timestamps is not None:
        raise ValueError(
            f"{path}: an AEDAT4 recording carries its own frame times; do not give fps or timestamps"
        )
    decoder = _decoder(path)
    with decoder:
        tracks = [track for track in decoder.tracks() if track.data_type == "frame"]
        if not tracks:
            raise ValueError(f"{path}: AEDAT4 file has no frame stream (no APS frames recorded)")
        track = tracks[0]
        count = _frame_count(decoder, track.id)
    width, height = track.dimensions
    return Aedat4FrameSource(path, "aedat4", width, height, None, None, count, track_id=track.id)


def _decoder(path: Path) -> Any:
    import faery

    try:
        return faery.aedat.Decoder(path)
    except BaseException as error:
        if not is_decoder_failure(error):
            raise
        raise EventFileError(path, 0, f"not a readable AEDAT4 file ({error})") from error


def _frame_count(decoder: Any, track_id: int) -> int | None:
    """Frames in the stream, from the file's data table when it has one (else unknown)."""
    try:
        table = decoder.file_data_definitions()
    except BaseException as error:
        if not is_decoder_failure(error):
            raise
        return None
    if not table:
        return None
    return sum(entry.elements_count for entry in table if entry.track_id == track_id)
