"""Reading and writing event files, streaming, in every format users read.

Formats come from the file suffix (see `pecs.io.formats.FORMATS`): Parquet (native, metadata
kept), HDF5 (DSEC layout; v2e layout on request), AEDAT4, Prophesee RAW (EVT3; EVT2 on request),
Prophesee DAT, npz (tonic's structured array), text (rpg `t x y p`, t in seconds).

    with pecs.io.EventWriter("out.raw", width=640, height=480) as writer:
        for batch in batches:              # pyarrow RecordBatches, sorted in t
            writer.write(batch)
    for batch in pecs.io.iter_events("out.raw", batch_size=1 << 20):
        ...

Every file is written through `pecs._atomic.atomic_path`: until the writer closes cleanly the
target path is untouched, and a failed write leaves nothing behind. A symlink's file is replaced,
the link kept. `-` is stdout (text unless `format` says otherwise). A pipe, a terminal or another
device (/dev/null) is written to, not replaced: as the events come in every format but HDF5,
which is built in a temporary file and copied there at the end; binary output is refused on a
terminal.

The camera clocks of EVT3, EVT2, DAT and v2e start at 0: absolute (Unix) times, as DV records,
are refused, and `zero_time=True` (`--zero-time`) starts the times at 0.
"""

from __future__ import annotations

import contextlib
import os
from collections.abc import Iterator
from pathlib import Path
from types import TracebackType
from typing import Any

import numpy as np
import pyarrow as pa
import pyarrow.compute as pc

from pecs import events as event_tables
from pecs._atomic import atomic_path, is_terminal, to_descriptor
from pecs.events import schema, sensor_size
from pecs.io._common import DEFAULT_BATCH_SIZE, EventFileError, Sink
from pecs.io._write_errors import os_error_in, write_error
from pecs.io.formats import FORMATS, Format, format_for, supported

__all__ = [
    "FORMATS",
    "EventFileError",
    "EventWriter",
    "format_for",
    "iter_events",
    "read_events",
    "supported",
    "to_table",
    "write_events",
]


class EventWriter:
    """Streaming event file writer; a context manager that takes record batches in t order.

    The sensor size comes from `width`/`height`, else from the first batch's schema metadata;
    AEDAT4, RAW and DAT store it in their header and need it before the first event. Only
    Parquet keeps the `label` column and the schema metadata. `compression` picks one the
    format offers (`Format.compressions`; HDF5: gzip by default, lzf, blosc, none). A failed
    write (disk full...) is an OSError naming `path`, and leaves nothing behind. `path` may be
    `-` (stdout) or a pipe or device (see the module). `zero_time` subtracts the first event's t
    from every t: what a format whose clock starts at 0 (`Format.clock_us`) needs of a
    recording in absolute time.
    """

    def __init__(
        self,
        path: str | os.PathLike[str],
        *,
        width: int | None = None,
        height: int | None = None,
        format: str | None = None,
        compression: str | None = None,
        zero_time: bool = False,
    ) -> None:
        self.path = Path(path)
        self.format: Format = format_for(self.path, format)
        self.zero_time = zero_time
        if (width is None) != (height is None):
            raise ValueError("give both width and height, or neither")
        if compression is not None and compression.lower() not in self.format.compressions:
            offered = ", ".join(self.format.compressions) or "none"
            raise ValueError(
                f"{self.format.name} offers no compression {compression!r} (it offers: {offered})"
            )
        self.compression = compression
        self.width, self.height = width, height
        self._stack: contextlib.ExitStack | None = None
        self._tmp: Path | None = None
        self._sink: Sink | None = None
        self._schema: pa.Schema | None = None
        self._last_t: int | None = None
        self._first_t: int | None = None  # as given, before zero_time
        self.count = 0

    def __enter__(self) -> EventWriter:
        if self.format.name != "text" and is_terminal(self.path):
            where = (
                "stdout is a terminal" if str(self.path) == "-" else f"{self.path} is a terminal"
            )
            raise ValueError(
                f"{where}, where {self.format.name} (binary) would garble the screen: redirect "
                "the output to a file or a pipe, or write text (--format txt)"
            )
        self._stack = contextlib.ExitStack()
        streams = self.format.streams
        output = (
            to_descriptor(1, streams=streams)
            if str(self.path) == "-"
            else atomic_path(self.path, streams=streams)
        )
        # atomic_path names the target in its errors (permission, a file in the way...).
        self._tmp = self._stack.enter_context(output)
        return self

    def __exit__(
        self,
        exc_type: type[BaseException] | None,
        exc: BaseException | None,
        traceback: TracebackType | None,
    ) -> None:
        if exc is None:
            try:
                with self._naming_write_errors():
                    self._finish()
            except BaseException as error:
                self._abort(type(error), error, error.__traceback__)
                raise
            assert self._stack is not None
            with self._naming_write_errors():
                self._stack.__exit__(None, None, None)
        else:
            self._abort(exc_type, exc, traceback)

    @contextlib.contextmanager
    def _naming_write_errors(self) -> Iterator[None]:
        """A failed write (disk full, quota, file too large, I/O error), from Python or from a
        native encoder, becomes an OSError that names the target, not its temporary file."""
        try:
            yield
        except OSError as error:
            raise write_error(self.path, error) from error
        except BaseException as error:
            os_error = os_error_in(error)
            if os_error is None:
                raise
            raise write_error(self.path, os_error) from error

    def _finish(self) -> None:
        if self._sink is None:
            self._open(schema(self.width, self.height))
        assert self._sink is not None
        self._sink.close()

    def _abort(
        self,
        exc_type: type[BaseException] | None,
        exc: BaseException | None,
        traceback: TracebackType | None,
    ) -> None:
        if self._sink is not None:
            # A native encoder may fail again on the way out (even with a Rust panic, a
            # BaseException); the first error is the one to report.
            try:
                self._sink.abort()
            except BaseException as error:
                if not isinstance(error, Exception) and type(error).__name__ != "PanicException":
                    raise
        if self._stack is not None:
            # atomic_path deletes the temporary file; the exception continues to the caller.
            with contextlib.suppress(BaseException):
                self._stack.__exit__(exc_type, exc, traceback)

    def write(self, events: Any) -> None:
        """Append events: a record batch, a table, or anything `pecs.events.to_table` takes."""
        if self._tmp is None:
            raise RuntimeError("EventWriter.write outside its `with` block")
        table = to_table(events)
        if self._sink is None and table.num_rows == 0:
            # No batch to take the sensor size from: the (empty) table's schema gives it.
            with self._naming_write_errors():
                self._open(table.schema)
        for batch in table.to_batches():
            with self._naming_write_errors():
                self._write_batch(batch)

    def _write_batch(self, batch: pa.RecordBatch) -> None:
        if self._sink is None:
            self._open(batch.schema)
        assert self._schema is not None and self._sink is not None
        batch = self._conform(batch)
        if batch.num_rows == 0:
            return
        if self._first_t is None:
            self._first_t = int(batch.column("t")[0].as_py())
        if self.zero_time:
            shifted = pc.subtract(batch.column("t"), pa.scalar(self._first_t, pa.int64()))
            batch = batch.set_column(batch.schema.get_field_index("t"), "t", shifted)
        self._check(batch)
        self._sink.write(batch)
        self._last_t = int(batch.column("t")[-1].as_py())
        self.count += batch.num_rows

    def _open(self, first_schema: pa.Schema) -> None:
        if self.width is None:
            self.width, self.height = sensor_size(first_schema) or (None, None)
        if self.format.needs_size and self.width is None:
            raise ValueError(
                f"{self.path}: {self.format.name} stores the sensor size in its header; "
                "pass width= and height= (the events carry no width/height metadata)"
            )
        meta = {k.decode(): v.decode() for k, v in (first_schema.metadata or {}).items()}
        labels = self.format.keeps_labels and "label" in first_schema.names
        self._schema = schema(self.width, self.height, labels=labels, metadata=meta)
        most = self.format.max_address
        for axis, extent in (("width", self.width), ("height", self.height)):
            if extent is not None and not 0 < extent <= most + 1:
                raise ValueError(
                    f"{self.path}: {self.format.name} stores x and y up to {most}, so a "
                    f"{axis} of 1 to {most + 1}; got {axis} {extent}"
                )
        assert self._tmp is not None
        self._sink = self.format.open_sink(
            self._tmp, self.width, self.height, self._schema, self.compression
        )

    def _conform(self, batch: pa.RecordBatch) -> pa.RecordBatch:
        """Select and cast the columns to the pecs schema; polarity -1 is read as OFF."""
        assert self._schema is not None
        missing = [f.name for f in self._schema if f.name not in batch.schema.names]
        if missing:
            raise ValueError(f"events lack column(s) {missing} (have {batch.schema.names})")
        arrays = []
        for field in self._schema:
            column = batch.column(field.name)
            if field.name == "p":
                column = _polarity(column)
            try:
                arrays.append(column.cast(field.type))
            except pa.ArrowInvalid as error:
                raise ValueError(
                    f"column {field.name!r} does not fit {field.type}: {error}"
                ) from None
        return pa.RecordBatch.from_arrays(arrays, schema=self._schema)

    def _check(self, batch: pa.RecordBatch) -> None:
        t = batch.column("t").to_numpy()
        if len(t) > 1 and np.any(t[1:] < t[:-1]):
            index = int(np.flatnonzero(t[1:] < t[:-1])[0]) + 1
            raise ValueError(
                f"events must be sorted by t: event {self.count + index} has t = {t[index]} "
                f"after t = {t[index - 1]}"
            )
        if self._last_t is not None and t[0] < self._last_t:
            raise ValueError(
                f"batches must be in t order: batch starts at t = {t[0]} after t = {self._last_t}"
            )
        limit = self.format.clock_us
        if limit is not None and (t[0] < 0 or t[-1] >= limit):
            raise self._clock_error(int(t[0]) if t[0] < 0 else int(t[-1]), limit)
        for axis, limit in (("x", self.width), ("y", self.height)):
            top = pc.max(batch.column(axis)).as_py()
            if limit is not None and top >= limit:
                raise ValueError(f"{axis} = {top} outside the sensor ({axis} < {limit})")
            most = self._sink.max_address if self._sink is not None else None
            if most is not None and top > most:
                raise ValueError(
                    f"{axis} = {top} exceeds what {self.format.name} stores ({axis} <= {most})"
                )

    def _clock_error(self, t_us: int, limit_us: int) -> ValueError:
        """Why `t_us` cannot be written, and what will: --zero-time when the span from the first
        event fits the format's clock, another format when not."""
        name = self.format.name
        first_us = t_us if self._first_t is None else self._first_t
        given_us = t_us + first_us if self.zero_time else t_us  # as the events gave it
        span_us = max(0, given_us - first_us)
        problem = f"{name} stores t as {self.format.clock}; t = {t_us} µs does not fit"
        if t_us >= _UNIX_2000_US:
            problem += " (it looks like a Unix time, as DV records)"
        if span_us < limit_us and not self.zero_time:
            return ValueError(
                f"{problem}: start the times at 0 with --zero-time (zero_time in pecs.io), "
                "or write Parquet or HDF5 (.h5), which keep absolute times"
            )
        return ValueError(
            f"{problem}: the events span {span_us} µs, more than {name} holds even from 0 "
            f"(--zero-time); write {self.format.longer}"
        )


#: 2000-01-01 in Unix µs: a t past it is a wall-clock time, not a camera clock's.
_UNIX_2000_US = 946_684_800 * 1_000_000


def _polarity(column: pa.Array) -> pa.Array:
    values = np.asarray(column.to_numpy(zero_copy_only=False))
    if values.dtype == np.bool_:
        return pa.array(values.astype(np.int8))
    bad = (values != 0) & (values != 1) & (values != -1)
    if np.any(bad):
        raise ValueError(
            f"polarity p must be 1 (ON) or 0 (OFF) (-1 is read as OFF); found {values[bad][0]}"
        )
    return pa.array((values > 0).astype(np.int8))


def iter_events(
    path: str | os.PathLike[str],
    *,
    batch_size: int = DEFAULT_BATCH_SIZE,
    format: str | None = None,
) -> Iterator[pa.RecordBatch]:
    """Yield the events of a file as record batches (t, x, y, p; width and height in the schema
    metadata when the file says), at most `batch_size` events each, without loading the file."""
    file = Path(path)
    if not file.is_file():
        raise _not_a_file(file)
    if batch_size <= 0:
        raise ValueError(f"batch_size must be positive, got {batch_size}")
    event_format = format_for(file, format)
    for batch in event_format.read(file, batch_size):
        if batch.num_rows > batch_size:
            # Slice by slice: to_batches would make every slice up front (a million objects,
            # about a gigabyte, for batch_size=1 on a 1 M-event batch).
            for start in range(0, batch.num_rows, batch_size):
                yield batch.slice(start, batch_size)
        else:
            yield batch


def _not_a_file(file: Path) -> OSError | ValueError:
    if not file.exists():
        return FileNotFoundError(f"no such file: {file}")
    if file.is_dir():
        return IsADirectoryError(f"{file} is a folder, not an event file")
    # A pipe or a device: the readers check sizes and seek.
    return ValueError(f"{file} is not a regular file: event files are read from disk")


def to_table(events: Any) -> pa.Table:
    """Any event-like object as an Arrow table with columns t, x, y, p: what
    `pecs.events.to_table` takes, or the path of an event file `read_events` reads."""
    if isinstance(events, (str, os.PathLike)):
        return read_events(events)
    return event_tables.to_table(events)


def read_events(path: str | os.PathLike[str], *, format: str | None = None) -> pa.Table:
    """Read an event file into an Arrow table with columns t, x, y, p (and label if stored)."""
    batches = list(iter_events(path, format=format))
    if not batches:
        return schema().empty_table()
    return pa.Table.from_batches(batches)


def write_events(
    events: Any,
    path: str | os.PathLike[str],
    *,
    width: int | None = None,
    height: int | None = None,
    format: str | None = None,
    compression: str | None = None,
    zero_time: bool = False,
) -> Path:
    """Write events to `path` atomically, in the format of its suffix (or `format`).

    The sensor size is `width`/`height`, else the events' metadata, else the largest address + 1.
    `compression` picks one the format offers (HDF5: gzip (default), lzf, blosc, none).
    `zero_time` starts the times at 0 (the first event's t subtracted from every t).
    """
    table = to_table(events)
    if width is None and height is None and sensor_size(table.schema) is None and table.num_rows:
        width = int(pc.max(table.column("x")).as_py()) + 1
        height = int(pc.max(table.column("y")).as_py()) + 1
    with EventWriter(
        path,
        width=width,
        height=height,
        format=format,
        compression=compression,
        zero_time=zero_time,
    ) as writer:
        writer.write(table)
    return Path(path)
