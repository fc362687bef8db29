"""Pieces shared by the format modules: the sink interface, errors, column conversion."""

from __future__ import annotations

import abc
import os
from pathlib import Path

import numpy as np
import pyarrow as pa

from pecs.events import record_batch, schema

DEFAULT_BATCH_SIZE = 1 << 20


class EventFileError(ValueError):
    """A truncated or corrupt event file; names the file and the byte offset of the problem."""

    def __init__(self, path: str | os.PathLike[str], offset: int | None, problem: str) -> None:
        self.path = Path(path)
        self.offset = offset
        where = f" at byte offset {offset}" if offset is not None else ""
        super().__init__(f"{self.path}{where}: {problem}")


class Sink(abc.ABC):
    """One open output file of one format. `EventWriter` validates batches before `write`."""

    #: the largest x and y address the format stores, or None when unbounded (uint16 anyway)
    max_address: int | None = None

    @abc.abstractmethod
    def write(self, batch: pa.RecordBatch) -> None:
        """Append a validated, t-sorted batch (t never below the previous batch's last t)."""

    @abc.abstractmethod
    def close(self) -> None:
        """Finish the file (footers, indexes); called once after the last batch."""

    def abort(self) -> None:
        """Release resources after a failure; the partial file is deleted by the caller."""
        try:
            self.close()
        except Exception:
            pass


def numpy_columns(batch: pa.RecordBatch) -> dict[str, np.ndarray]:
    """The batch's columns as numpy arrays (zero copy where Arrow allows)."""
    return {name: batch.column(name).to_numpy(zero_copy_only=False) for name in batch.schema.names}


def make_batch(
    t: np.ndarray,
    x: np.ndarray,
    y: np.ndarray,
    p: np.ndarray,
    width: int | None,
    height: int | None,
    metadata: dict[str, str] | None = None,
) -> pa.RecordBatch:
    """A pecs record batch from decoded columns."""
    event_schema = schema(width, height, metadata=metadata)
    return record_batch({"t": t, "x": x, "y": y, "p": p}, event_schema)


def header_lines_end(data: bytes, marker: bytes = b"%") -> int:
    """Byte offset after the ASCII header: the run of lines that start with `marker`."""
    offset = 0
    while data.startswith(marker, offset):
        newline = data.find(b"\n", offset)
        if newline < 0:
            return len(data)
        offset = newline + 1
    return offset


def read_head(path: Path, size: int = 1 << 16) -> bytes:
    with open(path, "rb") as file:
        return file.read(size)


def header_size(header: str) -> tuple[int, int] | None:
    """Sensor size from a Prophesee `% ` header: `width=W;height=H` (EVT3 format line),
    `% geometry WxH`, or `% Width W` / `% Height H` (DAT); None when it does not say."""
    import re

    text = header.lower()
    width = re.search(r"width[=\s]+(\d+)", text)
    height = re.search(r"height[=\s]+(\d+)", text)
    if width and height:
        return int(width.group(1)), int(height.group(1))
    geometry = re.search(r"geometry\s+(\d+)x(\d+)", text)
    if geometry:
        return int(geometry.group(1)), int(geometry.group(2))
    return None


# Signatures of the formats pecs reads, to say what a misnamed file looks like.
_SIGNATURES = (
    (b"#!AER-DAT4.0", "an AEDAT4 file"),
    (b"#!AER-DAT", "an AEDAT file"),
    (b"\x89HDF\r\n\x1a\n", "an HDF5 file"),
    (b"PAR1", "a Parquet file"),
    (b"PK\x03\x04", "a zip archive (npz)"),
    (b"PK\x05\x06", "a zip archive (npz)"),
    (b"\x93NUMPY", "a numpy .npy file"),
    (b"% evt", "a Prophesee RAW file"),
    (b"% Data file containing", "a Prophesee DAT file"),
)


def looks_like(path: Path) -> str:
    """' (it looks like an HDF5 file)' when the file's first bytes name a known format, else ''."""
    try:
        head = read_head(path, 64)
    except OSError:
        return ""
    for signature, name in _SIGNATURES:
        if head.startswith(signature):
            return f" (it looks like {name})"
    if head.startswith(b"%") and b"evt" in read_head(path, 4096).lower():
        return " (it looks like a Prophesee RAW file)"
    if head.startswith(b"%"):
        return " (it looks like a Prophesee DAT or RAW file)"
    return ""


def checked_batch(
    path: Path,
    columns: dict[str, np.ndarray],
    width: int | None,
    height: int | None,
    metadata: dict[str, str] | None = None,
) -> pa.RecordBatch:
    """A pecs batch from decoded integer columns t, x, y and p (> 0 is ON), refusing what the
    schema cannot hold (x, y in 0..65535, integer t) rather than wrapping it around."""
    for name in ("t", "x", "y", "p"):
        if columns[name].dtype.kind not in "iub":
            raise EventFileError(
                path, None, f"column {name} holds {columns[name].dtype}, not integers"
            )
    for name in ("x", "y"):
        values = columns[name]
        if len(values) and (values.min() < 0 or values.max() > 65535):
            bad = values[(values < 0) | (values > 65535)][0]
            raise EventFileError(path, None, f"{name} = {bad} outside 0..65535")
    t = columns["t"]
    if t.dtype == np.uint64 and len(t) and t.max() > np.iinfo(np.int64).max:
        raise EventFileError(path, None, f"t = {t.max()} µs does not fit int64")
    return make_batch(
        t.astype(np.int64),
        columns["x"].astype(np.uint16),
        columns["y"].astype(np.uint16),
        (columns["p"] > 0).astype(np.int8),
        width,
        height,
        metadata,
    )


def empty_batch(
    width: int | None, height: int | None, metadata: dict[str, str] | None = None
) -> pa.RecordBatch:
    """No events, with the sensor size the file states: what a reader yields for an empty file."""
    empty = {name: np.zeros(0, np.int64) for name in ("t", "x", "y", "p")}
    return make_batch(empty["t"], empty["x"], empty["y"], empty["p"], width, height, metadata)
