"""Prophesee DAT (version 2, CD events), encoded and decoded by faery.

Layout: `% ` ASCII header (Width, Height, Version 2), one byte event type (0x0C for CD), one byte
event size (8), then 8-byte events: uint32 t µs, uint32 with x in bits 0-13, y in 14-27 and
polarity in 28-31. t is 32-bit: recordings up to 2^32 µs (71.6 minutes).
"""

from __future__ import annotations

from collections.abc import Iterator
from pathlib import Path

import numpy as np
import pyarrow as pa

from pecs.io._common import (
    EventFileError,
    Sink,
    empty_batch,
    header_lines_end,
    header_size,
    looks_like,
    read_head,
)
from pecs.io._faery import from_faery, is_decoder_failure, rebatched, to_faery

_EVENT_BYTES = 8
_EVENT_TYPES = (0x0C, 0x00)  # CD events; "2D" events, same layout (older ATIS recordings)


class DatSink(Sink):
    max_address = (1 << 14) - 1

    def __init__(self, path: Path, width: int, height: int) -> None:
        import faery

        self._encoder = faery.dat.Encoder(
            path=path, version="dat2", event_type="cd", zero_t0=False, dimensions=(width, height)
        )
        self._encoder.__enter__()

    def write(self, batch: pa.RecordBatch) -> None:
        # EventWriter refused any t outside uint32 (Format.clock_us), naming --zero-time.
        events = to_faery(batch)
        packed = events.astype(
            np.dtype([("t", "<u8"), ("x", "<u2"), ("y", "<u2"), ("payload", "u1")]),
            casting="unsafe",
        )
        self._encoder.write(packed)

    def close(self) -> None:
        self._encoder.__exit__(None, None, None)


def read_batches(path: Path, batch_size: int) -> Iterator[pa.RecordBatch]:
    import faery

    head = read_head(path)
    header_end = header_lines_end(head)
    if header_end == 0:
        raise EventFileError(
            path, 0, f"not a Prophesee DAT file (no '% ' header lines){looks_like(path)}"
        )
    if b"evt" in head[:header_end].lower():
        raise EventFileError(
            path, 0, f"not a Prophesee DAT file (its header names EVT){looks_like(path)}"
        )
    data_start = header_end + 2  # event type byte, event size byte
    if len(head) < data_start:
        raise EventFileError(path, len(head), "truncated DAT file: no event type/size bytes")
    event_type, event_size = head[header_end], head[header_end + 1]
    if event_type not in _EVENT_TYPES:
        raise EventFileError(
            path, header_end, f"DAT event type {event_type:#x} is not CD (0x0c) or 2D (0x00)"
        )
    if event_size != _EVENT_BYTES:
        raise EventFileError(
            path, header_end + 1, f"DAT event size {event_size}, expected {_EVENT_BYTES}"
        )
    size = path.stat().st_size
    tail = (size - data_start) % _EVENT_BYTES
    if tail:
        raise EventFileError(
            path, size - tail, f"truncated DAT file: {tail} byte(s) of an incomplete 8-byte event"
        )
    # Without a size in the header, decode with the largest the addresses allow (14 bits) and
    # leave width/height out of the metadata.
    size = header_size(head[:header_end].decode("ascii", errors="replace"))
    try:
        decoder = faery.dat.Decoder(path, size or (1 << 14, 1 << 14), None)
    except BaseException as error:
        if not (isinstance(error, Exception) or is_decoder_failure(error)):
            raise
        raise EventFileError(path, 0, f"unreadable DAT header ({error})") from error
    # 0x0C: CD events; 0x00: "2D" events, the same 8-byte layout (older ATIS recordings, expelliarmus)
    if decoder.event_type not in ("cd", "2d"):
        raise EventFileError(
            path, header_end, f"DAT event type {event_type:#x} holds no change-detection events"
        )
    width, height = size or (None, None)
    check_width, check_height = decoder.dimensions or (1 << 14, 1 << 14)
    metadata = {"format": "dat"}
    with decoder:
        try:
            yielded = False
            for events in rebatched(decoder, batch_size):
                yielded = True
                yield _batch(events, width, height, metadata)
            if not yielded:
                yield empty_batch(width, height, metadata)
        except BaseException as error:
            if not is_decoder_failure(error):
                raise
            offset = _first_bad_event(path, data_start, check_width, check_height)
            raise EventFileError(path, offset, f"corrupt DAT data ({error})") from error


def _batch(
    events: np.ndarray, width: int | None, height: int | None, metadata: dict[str, str]
) -> pa.RecordBatch:
    converted = np.empty(len(events), dtype=[("t", "<u8"), ("x", "<u2"), ("y", "<u2"), ("on", "?")])
    converted["t"], converted["x"], converted["y"] = events["t"], events["x"], events["y"]
    converted["on"] = events["payload"] > 0
    return from_faery(converted, width, height, metadata)


def _first_bad_event(path: Path, data_start: int, width: int, height: int) -> int:
    if path.stat().st_size <= data_start:
        return data_start
    words = np.memmap(path, dtype="<u4", mode="r", offset=data_start).reshape(-1, 2)
    x, y = words[:, 1] & 0x3FFF, (words[:, 1] >> 14) & 0x3FFF
    t = words[:, 0].astype(np.int64)
    bad = (x >= width) | (y >= height) | np.concatenate([[False], np.diff(t) < 0])
    index = np.flatnonzero(bad)
    return data_start + int(index[0]) * _EVENT_BYTES if len(index) else data_start
