"""Reading and writing event files. Parquet is the native format (schema metadata kept)."""

from __future__ import annotations

import os
from pathlib import Path
from typing import Any

import pyarrow as pa
import pyarrow.parquet as pq

from pecs._atomic import atomic_path
from pecs.events import schema, sensor_size, to_table

__all__ = ["read_events", "write_events"]


def read_events(path: str | os.PathLike[str]) -> pa.Table:
    """Read an event file into an Arrow table with columns t, x, y, p (and label if present)."""
    file = Path(path)
    if not file.is_file():
        raise FileNotFoundError(f"no event file at {file}")
    if file.suffix.lower() != ".parquet":
        raise ValueError(f"{file}: unsupported event format {file.suffix!r}; supported: .parquet")
    try:
        return pq.read_table(file)
    except (pa.ArrowInvalid, OSError) as error:
        raise ValueError(f"{file}: not a readable Parquet event file ({error})") from error


def write_events(
    events: Any,
    path: str | os.PathLike[str],
    *,
    width: int | None = None,
    height: int | None = None,
) -> Path:
    """Write events to `path` atomically (nothing is left at `path` if writing fails)."""
    table = to_table(events)
    size = sensor_size(table.schema)
    width, height = (width, height) if width is not None else (size or (None, None))
    meta = {k.decode(): v.decode() for k, v in (table.schema.metadata or {}).items()}
    labels = "label" in table.column_names
    target_schema = schema(width, height, labels=labels, metadata=meta)
    table = table.select([f.name for f in target_schema]).cast(target_schema)
    file = Path(path)
    if file.suffix.lower() != ".parquet":
        raise ValueError(f"{file}: unsupported event format {file.suffix!r}; supported: .parquet")
    with atomic_path(file) as tmp:
        pq.write_table(table, tmp)
    return file
