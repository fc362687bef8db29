"""Prophesee RAW: EVT 3.0 (default for .raw) and EVT 2.0, encoded and decoded by faery.

EVT3: ASCII `% ` header, then 16-bit little-endian words, type in the top 4 bits (ADDR_Y 0x0,
ADDR_X 0x2, VECT_BASE_X 0x3, VECT_12 0x4, VECT_8 0x5, TIME_LOW 0x6, TIME_HIGH 0x8, EXT_TRIGGER
0xA, OTHERS 0xE, CONTINUED 0xF); time is TIME_HIGH:TIME_LOW (24 bits), wrapping every 2^24 µs.
EVT2: 32-bit words, CD_OFF 0x0 / CD_ON 0x1 with 6-bit time LSB, 11-bit x, 11-bit y; TIME_HIGH
0x8 carries the upper 28 bits. Both formats have no end marker: a file cut at a word boundary
reads as a shorter recording; one cut inside a word is reported with its offset.
"""

from __future__ import annotations

from collections.abc import Iterator
from pathlib import Path

import numpy as np
import pyarrow as pa

from pecs.io._common import EventFileError, Sink, header_lines_end, header_size, read_head
from pecs.io._faery import from_faery, is_decoder_failure, rebatched, to_faery

VERSIONS = ("evt3", "evt2")
_WORD_BYTES = {"evt3": 2, "evt2": 4, "evt2.1": 8}


class EvtSink(Sink):
    max_address = 2047  # 11-bit addresses

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


def read_batches(path: Path, batch_size: int) -> Iterator[pa.RecordBatch]:
    import faery

    head = read_head(path)
    data_start = header_lines_end(head)
    header = head[:data_start].decode("ascii", errors="replace")
    version = _version_from_header(header)
    _check_word_alignment(path, data_start, _WORD_BYTES[version], version)
    # Without a size in the header, decode with the largest the addresses allow (11 bits) and
    # leave width/height out of the metadata.
    size = header_size(header)
    try:
        decoder = faery.evt.Decoder(path, size or (2048, 2048), version)
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
            offset = _first_bad_word(path, data_start, version, check_width, check_height)
            raise EventFileError(
                path, offset, f"corrupt {version.upper()} data ({error})"
            ) from error


def _version_from_header(header: str) -> str:
    """`% evt 3.0` / `% format EVT3;...` (OpenEB), else EVT3 as Metavision assumes."""
    text = header.lower()
    if "evt 2.1" in text or "format evt21" in text:
        return "evt2.1"
    if "evt 2.0" in text or "format evt2" in text:
        return "evt2"
    return "evt3"


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


def _first_bad_word(path: Path, data_start: int, version: str, width: int, height: int) -> int:
    """Offset of the first word whose address is outside the sensor or whose type is unknown."""
    if version == "evt3":
        words = np.memmap(path, dtype="<u2", mode="r", offset=data_start)
        kind = words >> 12
        value = words & 0x7FF
        known = np.isin(kind, [0x0, 0x2, 0x3, 0x4, 0x5, 0x6, 0x8, 0xA, 0xE, 0xF])
        bad = ~known | ((kind == 0x0) & (value >= height)) | ((kind == 0x2) & (value >= width))
    else:
        words = np.memmap(path, dtype="<u4", mode="r", offset=data_start)
        kind = words >> 28
        x, y = (words >> 11) & 0x7FF, words & 0x7FF
        known = np.isin(kind, [0x0, 0x1, 0x8, 0xA, 0xE, 0xF])
        bad = ~known | ((kind <= 1) & ((x >= width) | (y >= height)))
    index = np.flatnonzero(bad)
    word_bytes = words.dtype.itemsize
    return data_start + int(index[0]) * word_bytes if len(index) else data_start
