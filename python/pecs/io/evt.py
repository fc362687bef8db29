"""Prophesee RAW (Metavision): EVT 3.0, the default for .raw, and EVT 2.0 (and EVT 2.1 read).

A RAW file is a text header of lines starting with `% `, ended by `% end` (or by the first line
that does not start with `%`), then the event words. pecs accepts a file as RAW only when its
header names the encoding: a `% format EVT3;height=H;width=W` line (also EVT2, EVT21; it wins)
or a `% evt 3.0` line (also 2.0, 2.1), as Metavision 2.x and later write them. Anything else (no
header, random bytes, another format renamed .raw, a header naming no encoding) is refused with
an EventFileError. The sensor size comes from the header (`width=`/`height=`, `% geometry WxH`).

EVT3 is encoded and decoded by pecs's own codec (`pecs._core.Evt3Encoder`/`Evt3Decoder`, from
the EVT 3.0 specification): the writer writes what a camera writes, a TIME_HIGH word at every
4096 µs step of the clock from t = 0 (the camera's clock starts at 0 too; times are absolute
µs and must stay below 2^36 µs, 19.1 h), so a decoder that counts TIME_HIGH wraps reconstructs
time after any gap. The reader counts those wraps (+2^24 µs each) as the specification says.
EVT2 and EVT2.1 go through faery. The formats have no end marker: a file cut at a word boundary
reads as a shorter recording; one cut inside a word is reported with its offset.
"""

from __future__ import annotations

import re
from collections.abc import Iterator
from pathlib import Path

import numpy as np
import pyarrow as pa

from pecs import _core
from pecs.events import schema
from pecs.io._common import EventFileError, Sink, header_size, numpy_columns, read_head
from pecs.io._faery import from_faery, is_decoder_failure, rebatched, to_faery

VERSIONS = ("evt3", "evt2")
#: The clock of both encodings starts at 0 (the camera's start). EVT3's writer carries a
#: TIME_HIGH word every 4096 µs from 0 (33 MB at this limit); EVT2's one every 2^26 µs, but
#: a Unix time (1.6e15 µs) cost it 95 MB of them, so both refuse times from 2^36 µs on.
MAX_T_US = 1 << 36
CLOCK = "µs from the camera's start (0 <= t < 2^36 µs, 19.1 hours)"
_WORD_BYTES = {"evt3": 2, "evt2": 4, "evt2.1": 8}
#: Addresses are 11 bits in every EVT encoding.
_MAX_SIZE = 2048
#: `% format EVT3;...` (OpenEB) and `% evt 3.0` (Metavision) header lines, and their versions.
_FORMAT_LINE = re.compile(r"^%\s*format\s+(evt\w*)", re.IGNORECASE | re.MULTILINE)
_EVT_LINE = re.compile(r"^%\s*evt\s+([\d.]+)\s*$", re.IGNORECASE | re.MULTILINE)
_BY_FORMAT = {"evt3": "evt3", "evt2": "evt2", "evt21": "evt2.1"}
_BY_EVT = {"3.0": "evt3", "2.0": "evt2", "2.1": "evt2.1"}


def evt3_header(width: int, height: int) -> bytes:
    """The header Metavision writes for EVT3, reduced to what readers use."""
    return (
        f"% evt 3.0\n% format EVT3;height={height};width={width}\n"
        f"% geometry {width}x{height}\n% end\n"
    ).encode("ascii")


class EvtSink(Sink):
    """A RAW file: EVT3 through pecs's codec, EVT2 through faery."""

    max_address = _MAX_SIZE - 1

    def __init__(self, path: Path, version: str, width: int, height: int) -> None:
        _check_size(width, height)
        self._writer: Sink = (
            _Evt3Writer(path, width, height)
            if version == "evt3"
            else _FaeryWriter(path, version, width, height)
        )

    def write(self, batch: pa.RecordBatch) -> None:
        self._writer.write(batch)

    def close(self) -> None:
        self._writer.close()


class _Evt3Writer(Sink):
    def __init__(self, path: Path, width: int, height: int) -> None:
        self._encoder = _core.Evt3Encoder(width, height)
        self._file = open(path, "wb")  # noqa: SIM115 (closed by close, or abort)
        self._file.write(evt3_header(width, height))

    def write(self, batch: pa.RecordBatch) -> None:
        columns = numpy_columns(batch)
        t, x, y, p = (np.ascontiguousarray(columns[n], dtype=d) for n, d in _COLUMN_DTYPES)
        self._file.write(self._encoder.encode(t, x, y, p))

    def close(self) -> None:
        self._file.close()


_COLUMN_DTYPES = (("t", np.int64), ("x", np.uint16), ("y", np.uint16), ("p", np.int8))


class _FaeryWriter(Sink):
    def __init__(self, path: Path, version: str, width: int, height: int) -> None:
        import faery

        self._encoder = faery.evt.Encoder(
            path=path,
            version=version,
            zero_t0=False,  # keep absolute µs so every reader sees the same t
            dimensions=(width, height),
            enforce_monotonic=True,
        )
        self._encoder.__enter__()

    def write(self, batch: pa.RecordBatch) -> None:
        self._encoder.write({"events": to_faery(batch)})

    def close(self) -> None:
        self._encoder.__exit__(None, None, None)


def _check_size(width: int, height: int) -> None:
    if not (1 <= width <= _MAX_SIZE and 1 <= height <= _MAX_SIZE):
        raise ValueError(
            f"Prophesee RAW addresses 1 to {_MAX_SIZE} columns and rows (11 bits); "
            f"the sensor is {width} x {height}"
        )


def read_batches(path: Path, batch_size: int) -> Iterator[pa.RecordBatch]:
    head = read_head(path)
    data_start = _header_end(head)
    header = head[:data_start].decode("ascii", errors="replace")
    version = _version_from_header(path, header)
    _check_word_alignment(path, data_start, _WORD_BYTES[version], version)
    size = header_size(header)
    if size is not None and not all(1 <= side <= _MAX_SIZE for side in size):
        raise EventFileError(
            path, 0, f"header gives a {size[0]} x {size[1]} sensor; RAW addresses are 11 bits"
        )
    if version == "evt3":
        batches = _read_evt3(path, data_start, size, batch_size)
    else:
        batches = _read_with_faery(path, data_start, version, size, batch_size)
    empty = True
    for batch in batches:
        empty = False
        yield batch
    if empty:  # the header still gives the sensor size
        width, height = size or (None, None)
        event_schema = schema(width, height, metadata={"format": version})
        yield pa.RecordBatch.from_pylist([], schema=event_schema)


def _read_evt3(
    path: Path, data_start: int, size: tuple[int, int] | None, batch_size: int
) -> Iterator[pa.RecordBatch]:
    # Without a size in the header, decode with the largest the addresses allow (11 bits) and
    # leave width/height out of the metadata.
    width, height = size or (None, None)
    decoder = _core.Evt3Decoder(width or _MAX_SIZE, height or _MAX_SIZE, data_start)
    event_schema = schema(width, height, metadata={"format": "evt3"})
    # Chunks of several batches' worth of words (about 2 bytes an event), bounded in memory.
    chunk_bytes = min(max(1 << 22, 4 * batch_size), 1 << 26)
    with open(path, "rb") as file:
        file.seek(data_start)
        try:
            while chunk := file.read(chunk_bytes):
                data = np.frombuffer(chunk, dtype=np.uint8)
                while len(data):
                    exported, used = decoder.decode(data, batch_size)
                    data = data[used:]
                    batch = pa.RecordBatch._import_from_c(exported.address, event_schema)
                    if batch.num_rows:
                        yield batch
            decoder.finish()
        except _core.Evt3DataError as error:
            offset, problem = error.args
            raise EventFileError(path, offset, f"corrupt EVT3 data: {problem}") from None


def _read_with_faery(
    path: Path, data_start: int, version: str, size: tuple[int, int] | None, batch_size: int
) -> Iterator[pa.RecordBatch]:
    import faery

    try:
        decoder = faery.evt.Decoder(path, size or (_MAX_SIZE, _MAX_SIZE), version)
    except BaseException as error:
        if not (isinstance(error, Exception) or is_decoder_failure(error)):
            raise
        raise EventFileError(path, 0, f"unreadable {version.upper()} header ({error})") from error
    width, height = size or (None, None)
    check_width, check_height = decoder.dimensions
    metadata = {"format": version}
    packets = (packet["events"] for packet in decoder if packet.get("events") is not None)
    with decoder:
        try:
            for events in rebatched(packets, batch_size):
                yield from_faery(events, width, height, metadata)
        except BaseException as error:
            if not is_decoder_failure(error):
                raise
            offset = _first_bad_evt2_word(path, data_start, check_width, check_height)
            raise EventFileError(
                path, offset, f"corrupt {version.upper()} data ({error})"
            ) from error


def _header_end(head: bytes) -> int:
    """Byte offset after the header: its `%` lines, up to and with `% end` when there is one
    (data after it may start with the byte of `%`)."""
    offset = 0
    while head.startswith(b"%", offset):
        newline = head.find(b"\n", offset)
        if newline < 0:
            return len(head)
        line = head[offset:newline].strip()
        offset = newline + 1
        if line == b"% end":
            break
    return offset


def _version_from_header(path: Path, header: str) -> str:
    """The encoding the header names (`% format EVT3;...` first, else `% evt 3.0`), or an
    EventFileError that says why this is not a RAW file pecs reads."""
    if not header:
        raise EventFileError(
            path,
            0,
            "not a Prophesee RAW file: no '% ' text header (a Metavision RAW file starts with "
            "lines such as '% evt 3.0' and '% format EVT3;height=720;width=1280')",
        )
    named = _FORMAT_LINE.search(header)
    if named:
        version = _BY_FORMAT.get(named.group(1).lower())
        what = f"'% format {named.group(1)}'"
    else:
        named = _EVT_LINE.search(header)
        version = _BY_EVT.get(named.group(1)) if named else None
        what = f"'% evt {named.group(1)}'" if named else None
    if what is None:
        raise EventFileError(
            path,
            0,
            "not a Prophesee RAW file pecs can read: its header names no encoding "
            "(no '% format EVT3;...' or '% evt 3.0' line)",
        )
    if version is None:
        raise EventFileError(
            path, 0, f"unsupported RAW encoding {what} (pecs reads EVT 2.0, 2.1 and 3.0)"
        )
    return version


def _check_word_alignment(path: Path, data_start: int, word_bytes: int, version: str) -> None:
    size = path.stat().st_size
    tail = (size - data_start) % word_bytes
    if tail:
        raise EventFileError(
            path,
            size - tail,
            f"truncated {version.upper()} file: {tail} byte(s) of an incomplete "
            f"{word_bytes}-byte word at the end",
        )


def _first_bad_evt2_word(path: Path, data_start: int, width: int, height: int) -> int:
    """Offset of the first EVT2 word whose address is outside the sensor or whose type is
    unknown."""
    words = np.memmap(path, dtype="<u4", mode="r", offset=data_start)
    kind = words >> 28
    x, y = (words >> 11) & 0x7FF, words & 0x7FF
    known = np.isin(kind, [0x0, 0x1, 0x8, 0xA, 0xE, 0xF])
    bad = ~known | ((kind <= 1) & ((x >= width) | (y >= height)))
    index = np.flatnonzero(bad)
    return data_start + int(index[0]) * 4 if len(index) else data_start
