"""Text, rpg / ECD style: one event per line, `t x y p`, t in seconds, space separated.

Written with 6 decimals (whole µs, so t survives the round trip exactly) through Arrow's CSV
writer; read with Arrow's streaming CSV reader. ECD files give t with 9 decimals: it is rounded
to the nearest µs. A first line with two numbers (`width height`, as rpg_e2vid writes) sets the
sensor size.
"""

from __future__ import annotations

from collections.abc import Iterator
from pathlib import Path

import numpy as np
import pyarrow as pa
import pyarrow.compute as pc
import pyarrow.csv as pcsv

from pecs.io._common import EventFileError, Sink, make_batch, numpy_columns


class TextSink(Sink):
    def __init__(self, path: Path) -> None:
        self._file = open(path, "wb")  # noqa: SIM115 (closed in close())
        options = pcsv.WriteOptions(include_header=False, delimiter=" ", quoting_style="none")
        text_schema = pa.schema([(name, pa.string()) for name in ("t", "x", "y", "p")])
        self._writer = pcsv.CSVWriter(self._file, text_schema, write_options=options)

    def write(self, batch: pa.RecordBatch) -> None:
        columns = numpy_columns(batch)
        self._writer.write_table(
            pa.table(
                {
                    "t": _seconds_text(columns["t"]),
                    "x": pc.cast(batch.column("x"), pa.string()),
                    "y": pc.cast(batch.column("y"), pa.string()),
                    "p": pc.cast(batch.column("p"), pa.string()),
                }
            )
        )

    def close(self) -> None:
        self._writer.close()
        self._file.close()

    def abort(self) -> None:
        self._file.close()


def _seconds_text(t_us: np.ndarray) -> pa.Array:
    """Exact decimal seconds: whole seconds, '.', six digits of µs (no float rounding)."""
    if len(t_us) and t_us.min() < 0:
        raise ValueError("text output needs t >= 0")
    seconds = pc.cast(pa.array(t_us // 1_000_000), pa.string())
    micros = pc.utf8_lpad(pc.cast(pa.array(t_us % 1_000_000), pa.string()), 6, "0")
    return pc.binary_join_element_wise(seconds, micros, ".")


def read_batches(path: Path, batch_size: int) -> Iterator[pa.RecordBatch]:
    width, height, skip = _size_line(path)
    names = ["t", "x", "y", "p"]
    convert = pcsv.ConvertOptions(
        column_types={"t": pa.float64(), "x": pa.int64(), "y": pa.int64(), "p": pa.float64()}
    )
    read = pcsv.ReadOptions(
        column_names=names, skip_rows=skip, block_size=max(1 << 16, batch_size * 24)
    )
    parse = pcsv.ParseOptions(delimiter=" ", ignore_empty_lines=True)
    try:
        reader = pcsv.open_csv(
            path, read_options=read, parse_options=parse, convert_options=convert
        )
        for batch in reader:
            yield _to_events(path, batch, width, height)
    except pa.ArrowInvalid as error:
        line, offset = _first_bad_line(path, skip)
        raise EventFileError(path, offset, f"line {line}: not 't x y p' ({error})") from error


def _to_events(
    path: Path, batch: pa.RecordBatch, width: int | None, height: int | None
) -> pa.RecordBatch:
    t = np.rint(batch.column("t").to_numpy(zero_copy_only=False) * 1e6).astype(np.int64)
    x = batch.column("x").to_numpy(zero_copy_only=False)
    y = batch.column("y").to_numpy(zero_copy_only=False)
    p = batch.column("p").to_numpy(zero_copy_only=False)
    if len(x) and (x.min() < 0 or y.min() < 0 or x.max() > 65535 or y.max() > 65535):
        raise ValueError(f"{path}: x or y outside 0..65535")
    return make_batch(
        t, x.astype(np.uint16), y.astype(np.uint16), (p > 0).astype(np.int8), width, height
    )


def _size_line(path: Path) -> tuple[int | None, int | None, int]:
    """rpg_e2vid event files start with a 'width height' line; others start with an event."""
    with open(path, "rb") as file:
        first = file.readline().split()
    if len(first) == 2 and all(part.isdigit() for part in first):
        return int(first[0]), int(first[1]), 1
    return None, None, 0


def _first_bad_line(path: Path, skip: int) -> tuple[int, int]:
    """Line number (1-based) and byte offset of the first line that is not four numbers."""
    offset = 0
    with open(path, "rb") as file:
        for number, line in enumerate(file, start=1):
            if number > skip and line.strip():
                parts = line.split()
                try:
                    ok = len(parts) == 4 and all(float(part) == float(part) for part in parts)
                    int(parts[1]), int(parts[2])
                except ValueError:
                    ok = False
                if not ok:
                    return number, offset
            offset += len(line)
    return number if offset else 0, offset
