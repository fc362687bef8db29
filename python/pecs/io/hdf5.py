"""HDF5 in two layouts: DSEC (default) and v2e.

DSEC (Gehrig et al. 2021, RA-L): `/events/{x,y,t,p}` columns, t in µs relative to `/t_offset`,
`/ms_to_idx[k]` = index of the first event with t >= 1000 k. v2e (Hu et al. 2021): one `events`
dataset, N x 4 uint32 rows [t_us, x, y, p]. Both stream: datasets are chunked and grow as batches
arrive. Compression is gzip (level 1, byte shuffle) by default: every HDF5 build decodes it. Blosc
(what DSEC ships) only on request (`compression="blosc"`), as it needs hdf5plugin to read back.
"""

from __future__ import annotations

import contextlib
import math
from collections.abc import Iterator
from pathlib import Path
from typing import Any

import numpy as np
import pyarrow as pa

from pecs.io._common import (
    EventFileError,
    Sink,
    checked_batch,
    empty_batch,
    looks_like,
    numpy_columns,
)
from pecs.io._guarded_file import GuardedFile

_CHUNK = 1 << 16  # events per HDF5 chunk
_SIGNATURE = b"\x89HDF\r\n\x1a\n"
COMPRESSIONS = ("gzip", "lzf", "blosc", "none")
_BLOSC_FILTER = 32001  # the HDF5 filter id registered for Blosc
#: DSEC's ms_to_idx has one entry per millisecond of the recording: 24 h is 86.4 M entries
#: (691 MB before compression). Longer spans are refused rather than written for hours.
MAX_DSEC_SPAN_US = 24 * 3600 * 1_000_000


def _compression(name: str | None) -> dict[str, Any]:
    """h5py dataset options for a compression name; gzip when None (portable)."""
    name = "gzip" if name is None else name.lower()
    if name == "gzip":
        return {"compression": "gzip", "compression_opts": 1, "shuffle": True}
    if name == "lzf":
        return {"compression": "lzf", "shuffle": True}
    if name == "none":
        return {}
    if name == "blosc":
        try:
            import hdf5plugin
        except ImportError:
            raise ValueError(
                "compression='blosc' needs hdf5plugin (pip install hdf5plugin)"
            ) from None
        return dict(hdf5plugin.Blosc(cname="lz4", clevel=5, shuffle=hdf5plugin.Blosc.SHUFFLE))
    raise ValueError(f"unknown HDF5 compression {name!r}; choose one of {', '.join(COMPRESSIONS)}")


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


class _GuardedH5:
    """An h5py file written through `GuardedFile`, so a full disk is an OSError, not a crash."""

    def __init__(self, path: Path) -> None:
        import h5py

        self._guard = GuardedFile(path)
        self.file = h5py.File(self._guard, "w")

    def check(self) -> None:
        self._guard.raise_if_failed()

    def close(self) -> None:
        self.file.close()
        self._guard.close()
        self._guard.raise_if_failed()


class DsecSink(Sink):
    """DSEC layout. t is stored as uint32 µs after t_offset (71 minutes) and widened to int64 if
    a recording runs longer; ms_to_idx grows with the data (bounded memory)."""

    max_address = (1 << 16) - 1  # uint16 addresses

    def __init__(
        self, path: Path, width: int | None, height: int | None, compression: str | None = None
    ) -> None:
        self._compression = _compression(compression)
        self._h5 = _GuardedH5(path)
        self._file = self._h5.file
        group = self._file.create_group("events")
        self._columns = {
            name: self._dataset(group, name, dtype)
            for name, dtype in (("x", np.uint16), ("y", np.uint16), ("p", np.uint8))
        }
        self._t = self._dataset(group, "t", np.uint32)
        self._ms_to_idx = self._dataset(self._file, "ms_to_idx", np.uint64)
        if width is not None and height is not None:
            self._file.attrs["width"] = width
            self._file.attrs["height"] = height
        self._t_offset: int | None = None
        self._count = 0
        self._next_ms = 0

    def _dataset(self, parent: Any, name: str, dtype: type) -> Any:
        return parent.create_dataset(
            name,
            shape=(0,),
            maxshape=(None,),
            dtype=dtype,
            chunks=(_CHUNK,),
            **self._compression,
        )

    def write(self, batch: pa.RecordBatch) -> None:
        columns = numpy_columns(batch)
        t = columns["t"]
        if len(t) == 0:
            return
        if self._t_offset is None:
            self._t_offset = int(t[0])
        relative = t - self._t_offset
        if relative[-1] > MAX_DSEC_SPAN_US:
            raise ValueError(
                f"DSEC HDF5 indexes every millisecond (ms_to_idx): t spans {int(relative[-1])} µs "
                f"from the first event, over its limit of {MAX_DSEC_SPAN_US} µs (24 h); "
                "use Parquet for longer recordings"
            )
        if relative[-1] > np.iinfo(np.uint32).max and self._t.dtype != np.int64:
            self._widen_t()
        _append(self._t, relative.astype(self._t.dtype))
        _append(self._columns["x"], columns["x"])
        _append(self._columns["y"], columns["y"])
        _append(self._columns["p"], columns["p"].astype(np.uint8))
        self._index_milliseconds(relative)
        self._count += len(t)
        self._h5.check()

    def _index_milliseconds(self, relative: np.ndarray) -> None:
        """ms_to_idx[k]: index of the first event with relative t >= 1000 k; written in pieces
        so that a long gap between two events costs bounded memory."""
        last_ms = int(relative[-1]) // 1000
        piece = 1 << 20
        for first in range(self._next_ms, last_ms + 1, piece):
            ms = np.arange(first, min(first + piece, last_ms + 1), dtype=np.int64)
            index = self._count + np.searchsorted(relative, ms * 1000, "left")
            _append(self._ms_to_idx, index.astype(np.uint64))
        self._next_ms = max(self._next_ms, last_ms + 1)

    def _widen_t(self) -> None:
        """Past 2^32 µs: move t to an int64 dataset, copying chunk by chunk (bounded memory)."""
        group = self._file["events"]
        old = self._t
        wide = self._dataset(group, "t_int64", np.int64)
        wide.resize(old.shape[0], axis=0)
        for start in range(0, old.shape[0], 16 * _CHUNK):
            wide[start : start + 16 * _CHUNK] = old[start : start + 16 * _CHUNK]
        del group["t"]
        group.move("t_int64", "t")
        self._t = group["t"]

    def close(self) -> None:
        self._file.create_dataset("t_offset", data=np.int64(self._t_offset or 0))
        self._h5.close()

    def abort(self) -> None:
        with contextlib.suppress(Exception):
            self._h5.close()


class V2eSink(Sink):
    """v2e layout: `events` N x 4 uint32 [t_us, x, y, p]."""

    def __init__(
        self, path: Path, width: int | None, height: int | None, compression: str | None = None
    ) -> None:
        self._h5 = _GuardedH5(path)
        self._file = self._h5.file
        self._events = self._file.create_dataset(
            "events",
            shape=(0, 4),
            maxshape=(None, 4),
            dtype=np.uint32,
            chunks=(_CHUNK, 4),
            **_compression(compression),
        )
        if width is not None and height is not None:
            self._file.attrs["width"] = width
            self._file.attrs["height"] = height

    def write(self, batch: pa.RecordBatch) -> None:
        columns = numpy_columns(batch)
        t = columns["t"]  # in uint32: EventWriter refused the rest (Format.clock_us)
        rows = np.empty((len(t), 4), dtype=np.uint32)
        rows[:, 0], rows[:, 1], rows[:, 2], rows[:, 3] = t, columns["x"], columns["y"], columns["p"]
        _append(self._events, rows)
        self._h5.check()

    def close(self) -> None:
        self._h5.close()

    def abort(self) -> None:
        with contextlib.suppress(Exception):
            self._h5.close()


def read_batches(path: Path, batch_size: int) -> Iterator[pa.RecordBatch]:
    import h5py

    _register_filters()
    with open(path, "rb") as raw:
        if raw.read(8) != _SIGNATURE:
            raise EventFileError(path, 0, f"not an HDF5 file (no HDF5 signature){looks_like(path)}")
    try:
        file = h5py.File(path, "r")
    except OSError as error:
        size = path.stat().st_size
        raise EventFileError(path, size, f"truncated or corrupt HDF5 file ({error})") from error
    with file:
        try:
            yield from _read_layout(path, file, batch_size)
        except (OSError, KeyError, RuntimeError, TypeError) as error:
            # h5py raises these on damaged object headers, links and attributes.
            raise EventFileError(path, None, f"corrupt HDF5 structure ({error})") from error


def _read_layout(path: Path, file: Any, batch_size: int) -> Iterator[pa.RecordBatch]:
    import h5py

    size = _stored_size(path, file)
    events = file.get("events")
    if isinstance(events, h5py.Group):
        batches = _read_dsec(path, file, size, batch_size)
    elif isinstance(events, h5py.Dataset):
        batches = _read_v2e(path, file, size, batch_size)
    else:
        raise EventFileError(
            path,
            None,
            "HDF5 file holds no events: no 'events' group (DSEC) or dataset (v2e); "
            f"top-level keys: {sorted(file.keys())}",
        )
    yielded = False
    for batch in batches:
        yielded = True
        yield batch
    if not yielded:
        yield empty_batch(*size)


def _stored_size(path: Path, file: Any) -> tuple[int | None, int | None]:
    if "width" not in file.attrs or "height" not in file.attrs:
        return None, None
    try:
        width, height = int(file.attrs["width"]), int(file.attrs["height"])
    except (TypeError, ValueError) as error:
        raise EventFileError(
            path, None, f"width/height attributes are not integers ({error})"
        ) from error
    if not (0 < width <= 65536 and 0 < height <= 65536):
        raise EventFileError(path, None, f"sensor size {width} x {height} outside 1..65536")
    return width, height


def _check_filters(path: Path, dataset: Any) -> None:
    """A dataset whose compression filter this HDF5 lacks (Blosc without hdf5plugin) is named
    before reading, instead of HDF5's "can't open directory" of its plugin folder."""
    import h5py

    plist = dataset.id.get_create_plist()
    for index in range(plist.get_nfilters()):
        filter_id, _, _, name = plist.get_filter(index)
        if not h5py.h5z.filter_avail(filter_id):
            hint = "install hdf5plugin (pip install hdf5plugin)"
            label = "Blosc" if filter_id == _BLOSC_FILTER else name.decode(errors="replace")
            raise EventFileError(
                path,
                None,
                f"{dataset.name} is compressed with {label} (HDF5 filter {filter_id}), "
                f"which this HDF5 cannot decode: {hint}",
            )


def _check_storage(path: Path, dataset: Any) -> None:
    """A damaged shape can declare billions of events that the file does not hold (HDF5 would
    read its fill value, zeros, for every missing chunk): every chunk must be stored."""
    if dataset.chunks is not None:
        needed = math.prod(
            -(-extent // chunk) for extent, chunk in zip(dataset.shape, dataset.chunks, strict=True)
        )
        stored = dataset.id.get_num_chunks()
        if stored < needed:
            raise EventFileError(
                path,
                None,
                f"{dataset.name} declares shape {dataset.shape} but stores {stored} of its "
                f"{needed} chunks",
            )
    elif dataset.id.get_storage_size() < dataset.nbytes:
        raise EventFileError(
            path,
            None,
            f"{dataset.name} declares {dataset.nbytes} bytes but stores "
            f"{dataset.id.get_storage_size()}",
        )


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
    import h5py

    events = file["events"]
    missing = {"x", "y", "t", "p"} - set(events.keys())
    if missing:
        raise EventFileError(path, None, f"DSEC HDF5 'events' group lacks {sorted(missing)}")
    columns = {name: events[name] for name in ("t", "x", "y", "p")}
    for name, dataset in columns.items():
        if not isinstance(dataset, h5py.Dataset) or dataset.ndim != 1:
            raise EventFileError(path, None, f"DSEC events/{name} is not a 1-D dataset")
        _check_filters(path, dataset)
        _check_storage(path, dataset)
    counts = {name: dataset.shape[0] for name, dataset in columns.items()}
    if len(set(counts.values())) != 1:
        raise EventFileError(path, None, f"DSEC event columns differ in length: {counts}")
    t_offset = _t_offset(path, file)
    count = counts["t"]
    for start in range(0, count, batch_size):
        stop = min(count, start + batch_size)
        chunk = {name: _read_chunk(path, columns[name], start, stop) for name in columns}
        if chunk["t"].dtype.kind in "iu":
            chunk["t"] = chunk["t"].astype(np.int64) + t_offset
        yield checked_batch(path, chunk, *size)


def _t_offset(path: Path, file: Any) -> int:
    if "t_offset" not in file:
        return 0
    value = np.asarray(file["t_offset"][()])
    if value.size != 1 or value.dtype.kind not in "iu":
        raise EventFileError(path, None, f"t_offset is not one integer ({value.dtype})")
    return int(value.reshape(-1)[0])


def _read_v2e(
    path: Path, file: Any, size: tuple[int | None, int | None], batch_size: int
) -> Iterator[pa.RecordBatch]:
    events = file["events"]
    if events.ndim != 2 or events.shape[1] != 4:
        raise EventFileError(
            path, None, f"v2e 'events' must be N x 4 [t, x, y, p], got {events.shape}"
        )
    _check_filters(path, events)
    _check_storage(path, events)
    for start in range(0, events.shape[0], batch_size):
        rows = _read_chunk(path, events, start, min(events.shape[0], start + batch_size))
        # v2e stores p as 1/0 (some versions -1/1 in signed files): ON is positive.
        columns = {"t": rows[:, 0], "x": rows[:, 1], "y": rows[:, 2], "p": rows[:, 3]}
        yield checked_batch(path, columns, *size)
