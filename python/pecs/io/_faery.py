"""Conversion between pecs batches and faery's event arrays (faery.EVENTS_DTYPE)."""

from __future__ import annotations

from collections.abc import Iterable, Iterator

import numpy as np
import pyarrow as pa

from pecs.io._common import make_batch, numpy_columns

# faery.EVENTS_DTYPE: t u8, x u2, y u2, on bool (field named p with title "on").
FAERY_DTYPE = np.dtype([("t", "<u8"), ("x", "<u2"), ("y", "<u2"), (("p", "on"), "?")])


def to_faery(batch: pa.RecordBatch) -> np.ndarray:
    columns = numpy_columns(batch)
    if len(columns["t"]) and columns["t"][0] < 0:
        raise ValueError(f"negative timestamp {columns['t'][0]} µs: this format stores t unsigned")
    events = np.empty(len(columns["t"]), dtype=FAERY_DTYPE)
    events["t"] = columns["t"]
    events["x"] = columns["x"]
    events["y"] = columns["y"]
    events["on"] = columns["p"] > 0
    return events


def from_faery(
    events: np.ndarray, width: int | None, height: int | None, metadata: dict[str, str] | None
) -> pa.RecordBatch:
    return make_batch(
        events["t"].astype(np.int64),
        np.ascontiguousarray(events["x"]),
        np.ascontiguousarray(events["y"]),
        events["on"].astype(np.int8),
        width,
        height,
        metadata,
    )


def is_decoder_failure(error: BaseException) -> bool:
    """Whether faery gave up on the data: it raises RuntimeError, or, on some malformed input,
    a Rust panic that pyo3 turns into PanicException, a BaseException that `except Exception`
    misses. Either becomes an EventFileError naming the file."""
    return isinstance(error, RuntimeError) or type(error).__name__ == "PanicException"


def rebatched(packets: Iterable[np.ndarray], batch_size: int) -> Iterator[np.ndarray]:
    """A decoder's packets of faery events joined into arrays of at least `batch_size` events
    (the last may be shorter); empty packets are skipped."""
    buffer: list[np.ndarray] = []
    buffered = 0
    for packet in packets:
        if len(packet) == 0:
            continue
        buffer.append(packet)
        buffered += len(packet)
        if buffered >= batch_size:
            yield np.concatenate(buffer)
            buffer, buffered = [], 0
    if buffered:
        yield np.concatenate(buffer)
