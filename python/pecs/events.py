"""The event schema shared by every part of pecs, and conversion of anything event-like to Arrow.

Schema: t int64 (microseconds), x uint16, y uint16, p int8 (1 = ON, 0 = OFF), optional label
uint8 (0 signal, 1 leak, 2 shot, 3 hot pixel). Origin top-left, x right, y down. The schema
metadata carries `width` and `height` (decimal strings) and, when known, `pecs.sensor`: the JSON
of the sensor configuration that produced the events.
"""

from __future__ import annotations

import json
import os
from collections.abc import Mapping
from typing import Any

import numpy as np
import pyarrow as pa

LABELS = {0: "signal", 1: "leak", 2: "shot", 3: "hot"}

_BASE_FIELDS = [
    pa.field("t", pa.int64(), nullable=False),
    pa.field("x", pa.uint16(), nullable=False),
    pa.field("y", pa.uint16(), nullable=False),
    pa.field("p", pa.int8(), nullable=False),
]
_LABEL_FIELD = pa.field("label", pa.uint8(), nullable=False)
_NUMPY_DTYPES = {"t": np.int64, "x": np.uint16, "y": np.uint16, "p": np.int8, "label": np.uint8}


def schema(
    width: int | None = None,
    height: int | None = None,
    *,
    labels: bool = False,
    metadata: Mapping[str, str] | None = None,
) -> pa.Schema:
    """The Arrow schema of a pecs event table, with the sensor size in its metadata."""
    meta: dict[str, str] = dict(metadata or {})
    if width is not None:
        meta["width"] = str(int(width))
    if height is not None:
        meta["height"] = str(int(height))
    fields = _BASE_FIELDS + ([_LABEL_FIELD] if labels else [])
    return pa.schema(fields, metadata=meta or None)


def record_batch(columns: Mapping[str, np.ndarray], event_schema: pa.Schema) -> pa.RecordBatch:
    """Wrap numpy columns (t, x, y, p[, label]) as a record batch without copying them."""
    arrays = [_wrap(columns[f.name], f) for f in event_schema]
    return pa.RecordBatch.from_arrays(arrays, schema=event_schema)


def _wrap(values: np.ndarray, field: pa.Field) -> pa.Array:
    # Arrow over the numpy buffer itself: pa.array() would take a slower, inferring path.
    data = np.ascontiguousarray(values, dtype=_NUMPY_DTYPES[field.name])
    return pa.Array.from_buffers(field.type, len(data), [None, pa.py_buffer(data)])


def sensor_size(table_schema: pa.Schema) -> tuple[int, int] | None:
    """(width, height) from a pecs schema's metadata, or None when it does not say."""
    meta = table_schema.metadata or {}
    if b"width" in meta and b"height" in meta:
        return int(meta[b"width"]), int(meta[b"height"])
    return None


def sensor_config_json(table_schema: pa.Schema) -> dict[str, Any] | None:
    """The sensor configuration stored with the events, if any."""
    raw = (table_schema.metadata or {}).get(b"pecs.sensor")
    return None if raw is None else json.loads(raw)


def to_table(events: Any) -> pa.Table:
    """Any in-memory event-like object as an Arrow table with columns t, x, y, p.

    Accepts Arrow tables and record batches (anything with `__arrow_c_stream__` or
    `__arrow_c_array__`) and numpy structured arrays with fields t, x, y, p (or `on` for p).
    Event files are read by `pecs.io` (`pecs.io.to_table` takes paths too): this module knows
    nothing of file formats.
    """
    if isinstance(events, pa.Table):
        return events
    if isinstance(events, pa.RecordBatch):
        return pa.Table.from_batches([events])
    if isinstance(events, (str, os.PathLike)):
        raise TypeError(
            f"{os.fspath(events)!r} is a path: read it with pecs.read_events, or pass it to "
            "pecs.io.to_table"
        )
    if isinstance(events, np.ndarray) and events.dtype.names:
        return _table_from_structured(events)
    if hasattr(events, "__arrow_c_stream__"):
        return pa.RecordBatchReader.from_stream(events).read_all()
    if hasattr(events, "__arrow_c_array__"):
        return pa.Table.from_batches([pa.record_batch(events)])
    raise TypeError(
        f"cannot read events from {type(events).__name__}: expected an Arrow table or record "
        "batch, a numpy structured array with t, x, y, p, or a path to an event file"
    )


def _table_from_structured(array: np.ndarray) -> pa.Table:
    names = set(array.dtype.names or ())
    polarity = "p" if "p" in names else "on" if "on" in names else None
    missing = {"t", "x", "y"} - names
    if missing or polarity is None:
        raise ValueError(
            f"structured array needs fields t, x, y and p (or on); missing {sorted(missing | ({'p'} if polarity is None else set()))}"
        )
    columns = {
        "t": array["t"],
        "x": array["x"],
        "y": array["y"],
        "p": array[polarity].astype(np.int8),
    }
    return pa.Table.from_batches([record_batch(columns, schema())])


# tonic's event dtype (tonic.io / its datasets' `dtype`) and its sensor size order (W, H, P).
TONIC_DTYPE = np.dtype([("x", "<i2"), ("y", "<i2"), ("t", "<i8"), ("p", "?")])


def to_tonic(events: Any) -> tuple[np.ndarray, tuple[int, int, int]]:
    """Events as tonic takes them: (structured array of TONIC_DTYPE, sensor_size (W, H, 2)).

    `tonic.transforms.ToFrame(sensor_size=size, ...)(array)` and the other transforms run on it.
    Width and height come from the schema metadata, else the largest address + 1.
    """
    table = to_table(events)
    array = np.empty(table.num_rows, dtype=TONIC_DTYPE)
    x = table.column("x").to_numpy()
    y = table.column("y").to_numpy()
    if len(x) and (x.max() > np.iinfo(np.int16).max or y.max() > np.iinfo(np.int16).max):
        raise ValueError("tonic stores x and y as int16; addresses above 32767 do not fit")
    array["x"], array["y"] = x, y
    array["t"] = table.column("t").to_numpy()
    array["p"] = table.column("p").to_numpy() > 0
    size = sensor_size(table.schema)
    if size is None:
        size = (int(x.max()) + 1 if len(x) else 0, int(y.max()) + 1 if len(y) else 0)
    return array, (size[0], size[1], 2)
