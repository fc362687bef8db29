"""Text, rpg / ECD style: one event per line, `t x y p`, t in seconds, space separated.

Written with 6 decimals (whole µs, so t survives the round trip exactly) through Arrow's CSV
writer, after a comment line `# width W height H` when the size is known (numpy's loadtxt skips
it); read with Arrow's streaming CSV reader. ECD files give t with 9 decimals: it is rounded to
the nearest µs. A first line with two numbers (`width height`, as rpg_e2vid writes) also sets the
sensor size. A line that is not `t x y p` (t >= 0 seconds, x and y in 0..65535, p 1, 0 or -1) is
an EventFileError naming the line.
"""

from __future__ import annotations

import math
import re
from collections.abc import Iterator
from pathlib import Path

import numpy as np
import pyarrow as pa
import pyarrow.compute as pc
import pyarrow.csv as pcsv

from pecs.io._common import (
    EventFileError,
    Sink,
    empty_batch,
    looks_like,
    make_batch,
    numpy_columns,
    read_head,
)

#: t is read back as float64 seconds: below 2^31 s (68 years) every µs survives exactly
#: (checked by brute force in the tests; above 2^33 s some do not).
MAX_T_US = (1 << 31) * 1_000_000
_SIZE_COMMENT = re.compile(rb"#\s*width\s+(\d+)\s+height\s+(\d+)", re.IGNORECASE)


class TextSink(Sink):
    def __init__(self, path: Path, width: int | None, height: int | None) -> None:
        self._file = open(path, "wb")  # noqa: SIM115 (closed in close())
        if width is not None and height is not None:
            self._file.write(f"# width {width} height {height}\n".encode())
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
    if len(t_us) and (t_us.min() < 0 or t_us.max() >= MAX_T_US):
        raise ValueError(
            f"text stores t as seconds read back in float64: t must be 0 <= t < {MAX_T_US} µs "
            f"(2^31 s) to survive exactly; got t from {t_us.min()} to {t_us.max()} µs"
        )
    seconds = pc.cast(pa.array(t_us // 1_000_000), pa.string())
    micros = pc.utf8_lpad(pc.cast(pa.array(t_us % 1_000_000), pa.string()), 6, "0")
    return pc.binary_join_element_wise(seconds, micros, ".")


def read_batches(path: Path, batch_size: int) -> Iterator[pa.RecordBatch]:
    _check_is_text(path)
    width, height, skip = _header(path)
    names = ["t", "x", "y", "p"]
    convert = pcsv.ConvertOptions(
        column_types={"t": pa.float64(), "x": pa.int64(), "y": pa.int64(), "p": pa.float64()}
    )
    read = pcsv.ReadOptions(
        column_names=names, skip_rows=skip, block_size=max(1 << 16, batch_size * 24)
    )
    parse = pcsv.ParseOptions(delimiter=" ", ignore_empty_lines=True)
    yielded = False
    try:
        reader = pcsv.open_csv(
            path, read_options=read, parse_options=parse, convert_options=convert
        )
        for batch in reader:
            events = _to_events(batch, width, height)
            if events is None:
                raise pa.ArrowInvalid("a value outside its range")
            yielded = True
            yield events
    except pa.ArrowInvalid as error:
        if "Empty CSV file" in str(error):
            yield empty_batch(width, height)
            return
        raise _bad_line_error(path, skip, error) from error
    if not yielded:
        yield empty_batch(width, height)


def _check_is_text(path: Path) -> None:
    head = read_head(path, 4096)
    try:
        head.decode("utf-8")
    except UnicodeDecodeError as error:
        # A multi-byte character cut at the end of the 4 KiB head is still text.
        if error.start < len(head) - 4:
            binary = True
        else:
            binary = b"\0" in head
    else:
        binary = b"\0" in head
    if binary:
        raise EventFileError(path, 0, f"not a text event file (binary data){looks_like(path)}")


def _to_events(
    batch: pa.RecordBatch, width: int | None, height: int | None
) -> pa.RecordBatch | None:
    """The batch as events, or None when a value is out of range (the caller finds its line)."""
    t_s = batch.column("t").to_numpy(zero_copy_only=False)
    x = batch.column("x").to_numpy(zero_copy_only=False)
    y = batch.column("y").to_numpy(zero_copy_only=False)
    p = batch.column("p").to_numpy(zero_copy_only=False)
    if len(t_s) and not (
        np.all(np.isfinite(t_s) & (t_s >= 0) & (t_s * 1e6 < 2.0**63))
        and x.min() >= 0
        and y.min() >= 0
        and x.max() <= 65535
        and y.max() <= 65535
        and np.all((p == 0) | (p == 1) | (p == -1))
    ):
        return None
    t = np.rint(t_s * 1e6).astype(np.int64)
    return make_batch(
        t, x.astype(np.uint16), y.astype(np.uint16), (p > 0).astype(np.int8), width, height
    )


def _header(path: Path) -> tuple[int | None, int | None, int]:
    """Sensor size and the number of header lines: `# ...` comments (pecs writes
    `# width W height H`), or the `W H` line rpg_e2vid event files start with."""
    width = height = None
    skip = 0
    with open(path, "rb") as file:
        for line in file:
            if line.startswith(b"#"):
                found = _SIZE_COMMENT.match(line)
                if found:
                    width, height = int(found.group(1)), int(found.group(2))
                skip += 1
                continue
            parts = line.split()
            if skip == 0 and len(parts) == 2 and all(part.isdigit() for part in parts):
                width, height, skip = int(parts[0]), int(parts[1]), 1
            break
    return width, height, skip


def _bad_line_error(path: Path, skip: int, error: Exception) -> EventFileError:
    found = _first_bad_line(path, skip)
    if found is None:
        return EventFileError(path, None, f"not 't x y p' text events ({error})")
    number, offset, problem = found
    return EventFileError(path, offset, f"line {number}: {problem}; expected 't x y p'")


def _first_bad_line(path: Path, skip: int) -> tuple[int, int, str] | None:
    """Line number (1-based), byte offset and problem of the first line that is not an event."""
    offset = 0
    with open(path, "rb") as file:
        for number, line in enumerate(file, start=1):
            if number > skip and line.strip():
                problem = _line_problem(line)
                if problem is not None:
                    return number, offset, problem
            offset += len(line)
    return None


def _line_problem(line: bytes) -> str | None:
    """What is wrong with one `t x y p` line, or None when it is a valid event."""
    parts = line.split(b" ")
    parts[-1] = parts[-1].rstrip(b"\r\n")
    if len(parts) != 4:
        return f"{len(parts)} fields, not 4 ({_shown(line)})"
    t_text, x_text, y_text, p_text = (part.decode("utf-8", "replace") for part in parts)
    try:
        t_s = float(t_text)
    except ValueError:
        return f"t {t_text!r} is not a number"
    if not (math.isfinite(t_s) and 0 <= t_s and t_s * 1e6 < 2.0**63):
        return f"t {t_text!r} is not a time >= 0 s"
    for name, text in (("x", x_text), ("y", y_text)):
        if not text.isdigit() or int(text) > 65535:
            return f"{name} {text!r} is not an integer in 0..65535"
    try:
        p = float(p_text)
    except ValueError:
        return f"p {p_text!r} is not a number"
    if p not in (0, 1, -1):
        return f"p {p_text!r} is not 1, 0 or -1"
    return None


def _shown(line: bytes) -> str:
    text = line.decode("utf-8", "replace").rstrip("\r\n")
    return repr(text if len(text) <= 60 else text[:60] + "...")
