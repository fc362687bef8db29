"""HDF5 in two layouts: DSEC (default) and v2e.

DSEC (Gehrig et al. 2021, RA-L): `/events/{x,y,t,p}` columns, t in µs relative to `/t_offset`,
`/ms_to_idx[k]` = index of the first event with t >= 1000 k. Blosc (LZ4) through hdf5plugin when
it is installed, gzip otherwise. v2e (Hu et al. 2021): one `events` dataset, N x 4 uint32 rows
[t_us, x, y, p], gzip. Both stream: datasets are chunked and grow as batches arrive.
"""

from __future__ import annotations

from collections.abc import Iterator
from pathlib import Path
from typing import Any

import numpy as np
import pyarrow as pa

from pecs.io._common import EventFileError, Sink, make_batch, numpy_columns

_CHUNK = 1 << 16  # events per HDF5 chunk
_SIGNATURE = b"\x89HDF\r\n\x1a\n"


def _compression() -> dict[str, Any]:
    """Blosc/LZ4 with byte shuffle when hdf5plugin is installed (what DSEC ships), else gzip."""
    try:
        import hdf5plugin
    except ImportError:
        return {"compression": "gzip", "compression_opts": 1, "shuffle": True}
    return dict(hdf5plugin.Blosc(cname="lz4", clevel=5, shuffle=hdf5plugin.Blosc.SHUFFLE))


def _register_filters() -> None:
    """Reading Blosc-compressed files (DSEC) needs hdf5plugin's filters registered."""
    try:
        import hdf5plugin  # noqa: F401
    except ImportError:
        pass


def _append(dataset: Any, values: np.ndarray) -> None:
    start = dataset.shape[0]
    dataset.resize(start + len(values), axis=0)
    dataset[start:] = values


class DsecSink(Sink):
    """DSEC layout. t is stored as uint32 µs after t_offset (71 minutes) and widened to int64 if
    a recording runs longer."""

    def __init__(self, path: Path, width: int | None, height: int | None) -> None:
        import h5py

        self._file = h5py.File(path, "w")
        self._compression = _compression()
        group = self._file.create_group("events")
        self._columns = {
            name: group.create_dataset(
                name,
                shape=(0,),
                maxshape=(None,),
                dtype=dtype,
                chunks=(_CHUNK,),
                **self._compression,
            )
            for name, dtype in (("x", np.uint16), ("y", np.uint16), ("p", np.uint8))
        }
        self._t = group.create_dataset(
            "t",
            shape=(0,),
            maxshape=(None,),
            dtype=np.uint32,
            chunks=(_CHUNK,),
            **self._compression,
        )
        if width is not None and height is not None:
            self._file.attrs["width"] = width
            self._file.attrs["height"] = height
        self._t_offset: int | None = None
        self._count = 0
        self._ms_to_idx: list[np.ndarray] = []
        self._next_ms = 0

    def write(self, batch: pa.RecordBatch) -> None:
        columns = numpy_columns(batch)
        t = columns["t"]
        if len(t) == 0:
            return
        if self._t_offset is None:
            self._t_offset = int(t[0])
        relative = t - self._t_offset
        if relative[-1] > np.iinfo(np.uint32).max and self._t.dtype != np.int64:
            self._widen_t()
        _append(self._t, relative.astype(self._t.dtype))
        _append(self._columns["x"], columns["x"])
        _append(self._columns["y"], columns["y"])
        _append(self._columns["p"], columns["p"].astype(np.uint8))
        # ms_to_idx[k]: index of the first event with relative t >= 1000 k.
        last_ms = int(relative[-1]) // 1000
        if last_ms >= self._next_ms:
            ms = np.arange(self._next_ms, last_ms + 1, dtype=np.int64)
            self._ms_to_idx.append(self._count + np.searchsorted(relative, ms * 1000, "left"))
            self._next_ms = last_ms + 1
        self._count += len(t)

    def _widen_t(self) -> None:
        """Past 2^32 µs: move t to an int64 dataset, copying chunk by chunk (bounded memory)."""
        group = self._file["events"]
        old = self._t
        wide = group.create_dataset(
            "t_int64",
            shape=old.shape,
            maxshape=(None,),
            dtype=np.int64,
            chunks=(_CHUNK,),
            **self._compression,
        )
        for start in range(0, old.shape[0], 16 * _CHUNK):
            wide[start : start + 16 * _CHUNK] = old[start : start + 16 * _CHUNK]
        del group["t"]
        group.move("t_int64", "t")
        self._t = group["t"]

    def close(self) -> None:
        ms_to_idx = (
            np.concatenate(self._ms_to_idx) if self._ms_to_idx else np.zeros(0, dtype=np.uint64)
        )
        self._file.create_dataset("ms_to_idx", data=ms_to_idx.astype(np.uint64))
        self._file.create_dataset("t_offset", data=np.int64(self._t_offset or 0))
        self._file.close()


class V2eSink(Sink):
    """v2e layout: `events` N x 4 uint32 [t_us, x, y, p], gzip."""

    def __init__(self, path: Path, width: int | None, height: int | None) -> None:
        import h5py

        self._file = h5py.File(path, "w")
        self._events = self._file.create_dataset(
            "events",
            shape=(0, 4),
            maxshape=(None, 4),
            dtype=np.uint32,
            chunks=(_CHUNK, 4),
            compression="gzip",
            compression_opts=1,
        )
        if width is not None and height is not None:
            self._file.attrs["width"] = width
            self._file.attrs["height"] = height

    def write(self, batch: pa.RecordBatch) -> None:
        columns = numpy_columns(batch)
        t = columns["t"]
        if len(t) and (t[0] < 0 or t[-1] > np.iinfo(np.uint32).max):
            raise ValueError(
                f"v2e HDF5 stores t as uint32 µs; t from {t[0]} to {t[-1]} does not fit "
                "(use the DSEC layout or Parquet)"
            )
        rows = np.empty((len(t), 4), dtype=np.uint32)
        rows[:, 0], rows[:, 1], rows[:, 2], rows[:, 3] = t, columns["x"], columns["y"], columns["p"]
        _append(self._events, rows)

    def close(self) -> None:
        self._file.close()


def read_batches(path: Path, batch_size: int) -> Iterator[pa.RecordBatch]:
    import h5py

    _register_filters()
    with open(path, "rb") as raw:
        if raw.read(8) != _SIGNATURE:
            raise EventFileError(path, 0, "not an HDF5 file (no HDF5 signature)")
    try:
        file = h5py.File(path, "r")
    except OSError as error:
        size = path.stat().st_size
        raise EventFileError(path, size, f"truncated or corrupt HDF5 file ({error})") from error
    with file:
        size = _stored_size(file)
        if isinstance(file.get("events"), h5py.Group):
            yield from _read_dsec(path, file, size, batch_size)
        elif isinstance(file.get("events"), h5py.Dataset):
            yield from _read_v2e(path, file, size, batch_size)
        else:
            raise ValueError(
                f"{path}: HDF5 file has no 'events' group (DSEC) or dataset (v2e); "
                f"top-level keys: {sorted(file.keys())}"
            )


def _stored_size(file: Any) -> tuple[int | None, int | None]:
    if "width" in file.attrs and "height" in file.attrs:
        return int(file.attrs["width"]), int(file.attrs["height"])
    return None, None


def _read_chunk(path: Path, dataset: Any, start: int, stop: int) -> np.ndarray:
    try:
        return dataset[start:stop]
    except OSError as error:
        offset = dataset.id.get_offset()
        raise EventFileError(
            path, offset, f"corrupt HDF5 data in {dataset.name}[{start}:{stop}] ({error})"
        ) from error


def _read_dsec(
    path: Path, file: Any, size: tuple[int | None, int | None], batch_size: int
) -> Iterator[pa.RecordBatch]:
    events = file["events"]
    missing = {"x", "y", "t", "p"} - set(events.keys())
    if missing:
        raise ValueError(f"{path}: DSEC HDF5 'events' group lacks {sorted(missing)}")
    t_offset = int(file["t_offset"][()]) if "t_offset" in file else 0
    count = events["t"].shape[0]
    for start in range(0, count, batch_size):
        stop = min(count, start + batch_size)
        t = _read_chunk(path, events["t"], start, stop).astype(np.int64) + t_offset
        x = _read_chunk(path, events["x"], start, stop)
        y = _read_chunk(path, events["y"], start, stop)
        p = (_read_chunk(path, events["p"], start, stop) > 0).astype(np.int8)
        yield make_batch(t, x, y, p, *size)


def _read_v2e(
    path: Path, file: Any, size: tuple[int | None, int | None], batch_size: int
) -> Iterator[pa.RecordBatch]:
    events = file["events"]
    if events.ndim != 2 or events.shape[1] != 4:
        raise ValueError(f"{path}: v2e 'events' must be N x 4 [t, x, y, p], got {events.shape}")
    for start in range(0, events.shape[0], batch_size):
        rows = _read_chunk(path, events, start, min(events.shape[0], start + batch_size))
        t = rows[:, 0].astype(np.int64)
        # v2e stores p as 1/0 (some versions -1/1 in signed files): ON is positive.
        p = (rows[:, 3].astype(np.int64) > 0).astype(np.int8)
        yield make_batch(t, rows[:, 1], rows[:, 2], p, *size)
