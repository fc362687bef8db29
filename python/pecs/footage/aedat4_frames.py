"""The APS frames of an AEDAT 4.0 recording (iniVation DV, DAVIS cameras) as a frame source.

A DAVIS records grey-level APS frames beside its events, from the same pixels. Each AEDAT4
frame packet carries its exposure start and end (timestampStartOfExposure/EndOfExposure), a
`timestamp` (faery's `Frame.t`) and 8-bit pixels. A frame is timed at its exposure midpoint, the
mean of its exposure start and end, since `timestamp` is not always that midpoint: DV wrote the
midpoint in tests/data/davis346_excerpt but the exposure start in
tests/data/davis346_emlb_excerpt, whose frames it would time half an exposure (10 ms) early.
Only a file that records no exposure times is timed by `timestamp`; the source's `frame_times`
says which was used. (dv-processing's `Frame.timestamp` is the exposure start in both.)

The DAVIS APS readout is linear in light (no gamma is applied by the camera or DV), so a frame
becomes photocurrent as DN / 255 with no decoding: 1.0 is a full-scale pixel.
"""

from __future__ import annotations

from collections.abc import Generator, Iterator
from contextlib import closing
from dataclasses import dataclass, field
from pathlib import Path
from typing import Any

import numpy as np

from pecs.footage.frames import FrameSource, lift_black, to_luminance
from pecs.io import EventFileError
from pecs.io._faery import is_decoder_failure

AEDAT4_SUFFIXES = (".aedat4",)

# Full scale of each AEDAT4 frame format (faery's names): pixel values divide by it.
_FULL_SCALE = {"L": 255.0, "I;16": 65535.0, "RGB": 255.0, "RGBA": 255.0}


#: `Aedat4FrameSource.frame_times` of a file whose frames record their exposure start and end.
EXPOSURE_MIDPOINT = "exposure midpoint from exposure start/end"
#: ... and of a file whose frames do not (their `timestamp` taken as the exposure midpoint).
TIMESTAMP = "timestamp (no exposure start/end recorded)"


def has_exposure_times(frame: Any) -> bool:
    """Whether an AEDAT4 frame packet records its exposure: AEDAT4 leaves absent times at 0, and
    an exposure that ends before it starts is no time to trust."""
    start_us, end_us = int(frame.exposure_start_t), int(frame.exposure_end_t)
    return start_us > 0 and end_us >= start_us


def frame_time_us(frame: Any) -> int:
    """A frame packet's exposure midpoint (to the microsecond below), else its `timestamp`."""
    if has_exposure_times(frame):
        return (int(frame.exposure_start_t) + int(frame.exposure_end_t)) // 2
    return int(frame.t)


@dataclass
class Aedat4FrameSource(FrameSource):
    """The APS frames of one AEDAT4 file, as (exposure-midpoint t_us, float32 (H, W)) pairs.
    `frame_times` says where the times come from: `EXPOSURE_MIDPOINT` or `TIMESTAMP`."""

    frame_times: str = EXPOSURE_MIDPOINT
    track_id: int = 0
    #: Each frame's exposure (end - start, us) as the frames are read, where the file records
    #: it (`frame_times` is EXPOSURE_MIDPOINT); empty otherwise. `pecs.footage.exposure` reads
    #: it for `exposure_us="auto"`.
    exposures_us: list[int] = field(default_factory=list)

    def __iter__(self) -> Iterator[tuple[int, np.ndarray]]:
        previous_us: int | None = None
        self.exposures_us.clear()
        for index, frame in enumerate(self._packets()):
            t_us = self._time_us_of(index, frame)
            if self.frame_times == EXPOSURE_MIDPOINT:
                self.exposures_us.append(int(frame.exposure_end_t) - int(frame.exposure_start_t))
            if previous_us is not None and t_us <= previous_us:
                raise ValueError(
                    f"{self.path}: APS frame times must increase; {t_us} us follows {previous_us} us"
                )
            previous_us = t_us
            yield t_us, self._photocurrent(frame)

    def _time_us_of(self, index: int, frame: Any) -> int:
        """The frame's time by the file's rule: one rule for every frame, since mixing them
        would shift some frames by half an exposure against the others."""
        recorded = has_exposure_times(frame)
        if recorded != (self.frame_times == EXPOSURE_MIDPOINT):
            where = "has exposure times where" if recorded else "has no exposure times where"
            first = "has none" if recorded else "has them"
            raise ValueError(
                f"{self.path}: APS frame {index} {where} the first frame {first}; "
                "cannot time the frames consistently"
            )
        return frame_time_us(frame)

    def _packets(self) -> Generator[Any, None, None]:
        decoder = _decoder(self.path)
        with decoder:
            try:
                for track, packet in decoder:
                    if track.id == self.track_id:
                        yield packet
            except BaseException as error:
                if not is_decoder_failure(error):
                    raise
                # The structure checked out (_decoder): damage inside a packet, place unknown.
                raise EventFileError(self.path, None, f"corrupt AEDAT4 packet ({error})") from error

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
    source = Aedat4FrameSource(path, "aedat4", width, height, None, None, count, track_id=track.id)
    with closing(source._packets()) as packets:  # closing: the decoder with it
        first = next(packets, None)
    if first is not None and not has_exposure_times(first):
        source.frame_times = TIMESTAMP
    return source


def _decoder(path: Path) -> Any:
    import faery

    from pecs.io.aedat4 import check_structure

    check_structure(path)  # a cut or damaged file named as such, and where, before faery reads it
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
