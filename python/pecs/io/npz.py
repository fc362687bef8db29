"""numpy .npz with tonic's structured event array.

Written: `events` = structured array [("x", i2), ("y", i2), ("t", i8), ("p", bool)] (what
tonic's transforms take) and `sensor_size` = [width, height, 2] (tonic's order), so
`np.load(path)["events"]` goes straight into tonic. Read: that, faery's dtype (t, x, y, on), or
rpg_vid2e's separate arrays `np.savez(x=, y=, t=, p=)` (esim_torch: int64 t in ns, p -1/1),
rounded to the nearest µs. The writer streams: events go to a spool
file, and the .npy member is written once the count (needed by its header) is known.
"""

from __future__ import annotations

import math
import shutil
import tempfile
import zipfile
import zlib
from collections.abc import Iterator
from pathlib import Path
from typing import IO

import numpy as np
import pyarrow as pa

from pecs.events import TONIC_DTYPE
from pecs.io._common import (
    EventFileError,
    Sink,
    checked_batch,
    empty_batch,
    looks_like,
    numpy_columns,
)


class NpzSink(Sink):
    max_address = 32767  # int16 in tonic's dtype

    def __init__(self, path: Path, width: int | None, height: int | None) -> None:
        self._path = path
        self._size = (width, height)
        # Beside the output (its disk has room for it), or for a pipe or device (`-`, a FIFO),
        # in the temporary folder.
        spool_dir = path.parent if path.is_file() else None
        self._spool = tempfile.TemporaryFile(dir=spool_dir, prefix=".pecs-npz-")
        self._count = 0

    def write(self, batch: pa.RecordBatch) -> None:
        columns = numpy_columns(batch)
        events = np.empty(batch.num_rows, dtype=TONIC_DTYPE)
        events["x"], events["y"], events["t"] = columns["x"], columns["y"], columns["t"]
        events["p"] = columns["p"] > 0
        self._spool.write(events.tobytes())
        self._count += len(events)

    def close(self) -> None:
        with zipfile.ZipFile(self._path, "w", zipfile.ZIP_STORED, allowZip64=True) as archive:
            with archive.open("events.npy", "w", force_zip64=True) as member:
                header = {"descr": TONIC_DTYPE.descr, "fortran_order": False}
                np.lib.format.write_array_header_2_0(member, {**header, "shape": (self._count,)})
                self._spool.seek(0)
                shutil.copyfileobj(self._spool, member, 1 << 22)
            width, height = self._size
            if width is not None and height is not None:
                with archive.open("sensor_size.npy", "w") as member:
                    np.lib.format.write_array(member, np.array([width, height, 2], np.int64))
        self._spool.close()

    def abort(self) -> None:
        self._spool.close()


# What a damaged zip member raises on reading: bad CRC or header (BadZipFile), a cut stream
# (EOFError), bad deflate data (zlib.error), an unknown method (NotImplementedError), a password
# (RuntimeError), a bad npy header (ValueError).
_MEMBER_ERRORS = (
    zipfile.BadZipFile,
    OSError,
    EOFError,
    zlib.error,
    NotImplementedError,
    RuntimeError,
    ValueError,
)
_MAX_EVENT_BYTES = 64  # a structured event record larger than this is not events


def read_batches(path: Path, batch_size: int) -> Iterator[pa.RecordBatch]:
    try:
        archive = zipfile.ZipFile(path)
    except (zipfile.BadZipFile, OSError, EOFError, ValueError) as error:
        size = path.stat().st_size
        raise EventFileError(
            path, size, f"not an npz file (zip): {error}{looks_like(path)}"
        ) from error
    with archive:
        names = set(archive.namelist())
        size = _sensor_size(path, archive) if "sensor_size.npy" in names else (None, None)
        if "events.npy" in names:
            batches = _read_structured(path, archive, "events.npy", size, batch_size)
        elif {"x.npy", "y.npy", "t.npy", "p.npy"} <= names:
            batches = iter([_read_separate(path, archive, size)])
        else:
            structured = [name for name in sorted(names) if name.endswith(".npy")]
            if len(structured) != 1:
                raise EventFileError(
                    path,
                    None,
                    "npz holds no events: it needs 'events' (a structured array) or x, y, t, p "
                    f"arrays; found {sorted(names)}",
                )
            batches = _read_structured(path, archive, structured[0], size, batch_size)
        yielded = False
        for batch in batches:
            yielded = True
            yield batch
        if not yielded:
            yield empty_batch(*size)


def _sensor_size(path: Path, archive: zipfile.ZipFile) -> tuple[int | None, int | None]:
    try:
        member, shape, dtype = _open_npy(path, archive, "sensor_size.npy")
        with member:
            values = np.frombuffer(member.read(), dtype=dtype)
    except _MEMBER_ERRORS as error:
        raise EventFileError(path, None, f"corrupt sensor_size.npy ({error})") from error
    if (
        dtype.kind not in "iu"
        or len(values) < 2
        or not (0 < values[0] <= 65536)
        or not (0 < values[1] <= 65536)
    ):
        raise EventFileError(path, None, f"sensor_size.npy is not a width and height: {values}")
    return int(values[0]), int(values[1])


def _open_npy(path: Path, archive: zipfile.ZipFile, name: str) -> tuple[IO[bytes], tuple, np.dtype]:
    """The member positioned after its npy header, its shape and dtype; the declared data must
    fit in the member (a corrupt shape must not allocate terabytes)."""
    info = archive.getinfo(name)
    try:
        member = archive.open(name)
    except _MEMBER_ERRORS as error:
        raise EventFileError(path, info.header_offset, f"corrupt {name}: {error}") from error
    try:
        version = np.lib.format.read_magic(member)
        read_header = (
            np.lib.format.read_array_header_1_0
            if version == (1, 0)
            else np.lib.format.read_array_header_2_0
        )
        shape, fortran, dtype = read_header(member)
    except _MEMBER_ERRORS as error:
        member.close()
        raise EventFileError(
            path, info.header_offset, f"corrupt npy header in {name}: {error}"
        ) from error
    declared = math.prod(shape) * dtype.itemsize
    if dtype.hasobject or declared > info.file_size:
        member.close()
        raise EventFileError(
            path,
            info.header_offset,
            f"{name} declares {shape} x {dtype} ({declared} bytes) in {info.file_size} bytes",
        )
    if fortran and len(shape) > 1:
        member.close()
        raise EventFileError(path, None, f"{name} is Fortran-ordered; expected a 1-D event array")
    return member, shape, dtype


def _read_structured(
    path: Path,
    archive: zipfile.ZipFile,
    name: str,
    size: tuple[int | None, int | None],
    batch_size: int,
) -> Iterator[pa.RecordBatch]:
    member, shape, dtype = _open_npy(path, archive, name)
    fields = set(dtype.names or ())
    polarity = "p" if "p" in fields else "on" if "on" in fields else None
    scalar = all(dtype[field].shape == () for field in fields)
    if (
        not {"t", "x", "y"} <= fields
        or polarity is None
        or len(shape) != 1
        or not scalar
        or dtype.itemsize > _MAX_EVENT_BYTES
    ):
        member.close()
        raise EventFileError(
            path,
            None,
            f"{name} is not events: it must be a 1-D structured array with t, x, y, p (or on); "
            f"got dtype {dtype} shape {shape}",
        )
    info = archive.getinfo(name)
    with member:
        remaining = shape[0]
        while remaining:
            count = min(batch_size, remaining)
            try:
                raw = member.read(count * dtype.itemsize)
            except _MEMBER_ERRORS as error:
                raise EventFileError(
                    path, info.header_offset, f"corrupt {name}: {error}"
                ) from error
            if len(raw) != count * dtype.itemsize:
                done = shape[0] - remaining
                raise EventFileError(
                    path,
                    info.header_offset + done * dtype.itemsize,
                    f"truncated {name}: {shape[0]} events declared, data ends after "
                    f"{done + len(raw) // dtype.itemsize}",
                )
            events = np.frombuffer(raw, dtype=dtype)
            columns = {"t": events["t"], "x": events["x"], "y": events["y"], "p": events[polarity]}
            yield checked_batch(path, columns, *size)
            remaining -= count


def _read_separate(
    path: Path, archive: zipfile.ZipFile, size: tuple[int | None, int | None]
) -> pa.RecordBatch:
    columns = {}
    for name in ("t", "x", "y", "p"):
        member, shape, dtype = _open_npy(path, archive, f"{name}.npy")
        try:
            with member:
                raw = member.read()
        except _MEMBER_ERRORS as error:
            offset = archive.getinfo(f"{name}.npy").header_offset
            raise EventFileError(path, offset, f"corrupt {name}.npy: {error}") from error
        count = math.prod(shape)
        if len(shape) != 1 or dtype.names is not None or len(raw) < count * dtype.itemsize:
            raise EventFileError(path, None, f"{name}.npy is not a whole 1-D array of numbers")
        columns[name] = np.frombuffer(raw, dtype=dtype, count=count)
    lengths = {name: len(values) for name, values in columns.items()}
    if len(set(lengths.values())) != 1:
        raise EventFileError(path, None, f"x, y, t, p arrays differ in length: {lengths}")
    t = columns["t"]
    # rpg_vid2e's esim_torch saves int64 nanoseconds; float t is taken as seconds (esim_py).
    if t.dtype.kind == "f":
        if not np.all(np.isfinite(t) & (np.abs(t) < 9e12)):
            raise EventFileError(path, None, "t.npy holds times that are not finite seconds")
        columns["t"] = np.rint(t * 1e6).astype(np.int64)
    elif t.dtype.kind in "iu":
        columns["t"] = (t.astype(np.int64) + 500) // 1000
    return checked_batch(path, columns, *size)
