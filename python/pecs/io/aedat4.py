"""AEDAT 4.0 (iniVation DV), encoded and decoded by faery.

Layout: magic `#!AER-DAT4.0\\r\\n`, int32 header size, FlatBuffers IOHeader (with the stream
description: sizeX, sizeY), then packets, each an 8-byte header (int32 stream id, int32 size)
and a (LZ4 or ZSTD compressed) FlatBuffers EventPacket of {int64 t µs, int16 x, int16 y, bool
on}, then an optional FileDataTable. The structure is checked before faery reads the file
(`check_structure`): a file that ends inside its header or a packet, or before the data table
its header places, is reported as truncated, where it ends and what was expected there; a size
field that contradicts the rest as corrupt.
"""

from __future__ import annotations

import struct
from collections.abc import Iterator
from pathlib import Path

import pyarrow as pa

from pecs.io._common import EventFileError, Sink, empty_batch, looks_like
from pecs.io._faery import from_faery, is_decoder_failure, rebatched, to_faery

_MAGIC = b"#!AER-DAT4.0\r\n"
_HEADER_START = len(_MAGIC) + 4  # after the magic line and the int32 header size
#: IOHeaders are a few KiB (the XML description of the streams); a larger declared size is a
#: damaged field rather than a header cut short.
_MAX_HEADER_BYTES = 1 << 16


class Aedat4Sink(Sink):
    max_address = 32767  # int16 addresses

    def __init__(self, path: Path, width: int, height: int) -> None:
        import faery

        aedat = faery.aedat

        def attribute(kind: str, value: str | int) -> object:
            return aedat.DescriptionAttribute(attribute_type=kind, value=value)

        info = aedat.DescriptionNode(
            name="info",
            path="/mainloop/Recorder/outInfo/0/info/",
            attributes={
                "sizeX": attribute("int", width),
                "sizeY": attribute("int", height),
                "source": attribute("string", "pecs"),
            },
            nodes=[],
        )
        stream = aedat.DescriptionNode(
            name="0",
            path="/mainloop/Recorder/outInfo/0/",
            attributes={
                "compression": attribute("string", "LZ4"),
                "originalOutputName": attribute("string", "events"),
                "typeIdentifier": attribute("string", "EVTS"),
            },
            nodes=[info],
        )
        out_info = aedat.DescriptionNode(
            name="outInfo", path="/mainloop/Recorder/outInfo/", attributes={}, nodes=[stream]
        )
        self._encoder = aedat.Encoder(
            path=path, description=[out_info], compression=aedat.LZ4_DEFAULT
        )
        self._encoder.__enter__()

    def write(self, batch: pa.RecordBatch) -> None:
        if batch.num_rows:
            self._encoder.write(0, to_faery(batch))

    def close(self) -> None:
        self._encoder.__exit__(None, None, None)


def read_batches(path: Path, batch_size: int) -> Iterator[pa.RecordBatch]:
    import faery

    data_table = check_structure(path)
    try:
        decoder = faery.aedat.Decoder(path)
        tracks = decoder.tracks()
    except BaseException as error:
        if not is_decoder_failure(error):
            raise
        raise _decoder_error(path, data_table, "", error) from error
    event_tracks = [track for track in tracks if track.data_type == "events"]
    if not event_tracks:
        raise EventFileError(path, None, "AEDAT4 file has no event stream")
    track = event_tracks[0]
    width, height = track.dimensions
    metadata = {"format": "aedat4"}
    packets = (packet for packet_track, packet in decoder if packet_track.id == track.id)
    with decoder:
        try:
            yielded = False
            for events in rebatched(packets, batch_size):
                yielded = True
                yield from_faery(events, width, height, metadata)
            if not yielded:
                yield empty_batch(width, height, metadata)
        except BaseException as error:
            if not is_decoder_failure(error):
                raise
            raise _decoder_error(path, data_table, " packet", error) from error


def check_structure(path: Path) -> int:
    """Check what faery trusts before reading: the magic line, the header and its description,
    and that the packets tile the file up to its data table. Returns the data table's offset
    (-1: none). A file cut short is an EventFileError saying "truncated", where the file ends
    and what it was in the middle of; faery, given one, reported a corrupt packet at byte 0."""
    size = path.stat().st_size
    with open(path, "rb") as file:
        magic = file.read(len(_MAGIC))
        size_field = file.read(4)
    if magic != _MAGIC:
        if magic and _MAGIC.startswith(magic):
            raise _truncated(path, 0, size, f"inside its first line {_MAGIC!r}")
        raise EventFileError(
            path, 0, f"not an AEDAT 4.0 file (starts with {magic!r}){looks_like(path)}"
        )
    if len(size_field) < 4:
        raise _truncated(path, len(_MAGIC), size, "inside the int32 size of its header")
    header_bytes = int.from_bytes(size_field, "little", signed=True)
    if not 0 < header_bytes <= _MAX_HEADER_BYTES:
        raise EventFileError(
            path, len(_MAGIC), f"corrupt AEDAT4 header ({header_bytes} bytes declared)"
        )
    if _HEADER_START + header_bytes > size:
        header_end = _HEADER_START + header_bytes
        where = f"inside its {header_bytes}-byte header (bytes {_HEADER_START} to {header_end})"
        raise _truncated(path, len(_MAGIC), size, where)
    data_table = _check_description(path, header_bytes)
    _check_packets(path, _HEADER_START + header_bytes, data_table)
    return data_table


def _truncated(path: Path, offset: int, size: int, where: str) -> EventFileError:
    return EventFileError(path, offset, f"truncated AEDAT4 file: it ends at byte {size}, {where}")


def _decoder_error(path: Path, data_table: int, what: str, error: BaseException) -> EventFileError:
    """faery's failure on a file whose structure checked out: damage inside a packet, or in the
    data table at the end (which has no size field: a cut there is only seen by decoding it)."""
    offset = _first_bad_packet(path)
    if 0 <= data_table <= offset:
        return EventFileError(
            path, data_table, f"corrupt or truncated AEDAT4 file data table ({error})"
        )
    return EventFileError(path, offset, f"corrupt AEDAT4{what} ({error})")


def _check_description(path: Path, header_bytes: int) -> int:
    """The IOHeader's infoNode (its XML description) must be a UTF-8 string inside the header.
    faery's decoder aborts the process (a panic in a destructor) on one that is not, so it is
    checked here first. FlatBuffers: u32 root table offset; the table's i32 vtable offset; the
    vtable's u16 field offsets; infoNode is field 2 (compression, dataTablePosition, infoNode),
    a u32 offset to a u32 length and the bytes. Returns dataTablePosition (field 1, an int64;
    -1 when the file has no data table)."""
    start = len(_MAGIC) + 4
    with open(path, "rb") as file:
        file.seek(start)
        header = file.read(header_bytes)
    try:
        table = struct.unpack_from("<I", header, 0)[0]
        vtable = table - struct.unpack_from("<i", header, table)[0]
        vtable_bytes = struct.unpack_from("<H", header, vtable)[0]
        field = struct.unpack_from("<H", header, vtable + 8)[0] if vtable_bytes >= 10 else 0
        if field == 0:
            raise EventFileError(path, start, "AEDAT4 header has no description (infoNode)")
        where = table + field
        text_at = where + struct.unpack_from("<I", header, where)[0]
        length = struct.unpack_from("<I", header, text_at)[0]
        if vtable < 0 or text_at + 4 + length > len(header):
            raise struct.error("description runs past the header")
        header[text_at + 4 : text_at + 4 + length].decode("utf-8")
        table_field = struct.unpack_from("<H", header, vtable + 6)[0] if vtable_bytes >= 8 else 0
        return struct.unpack_from("<q", header, table + table_field)[0] if table_field else -1
    except (struct.error, UnicodeDecodeError) as error:
        raise EventFileError(path, start, f"corrupt AEDAT4 header ({error})") from error


def _check_packets(path: Path, first_packet: int, data_table: int) -> None:
    """Every packet (int32 stream id, int32 size, data) must end before the data table, else
    before the end of the file: faery allocates a packet's declared size before reading it, so
    a damaged size field of ~2^31 cost it seconds and, under a memory limit, aborted the
    process. A packet that stays short of the data table but runs past the end of the file,
    and a file that ends between packets before its data table, were cut short."""
    size = path.stat().st_size
    # Where the packets end: the data table the header places (maybe past a cut), or the end.
    end = data_table if data_table >= first_packet else size
    offset = first_packet
    with open(path, "rb") as file:
        while offset < min(end, size):
            file.seek(offset)
            head = file.read(8)
            if offset + 8 > end:
                raise EventFileError(
                    path, offset, "corrupt AEDAT4 packet header: it runs into the data table"
                )
            if len(head) < 8:
                raise _truncated(
                    path, offset, size, f"inside the header of the packet at byte {offset}"
                )
            packet_bytes = struct.unpack("<ii", head)[1]
            if packet_bytes < 0 or offset + 8 + packet_bytes > end:
                raise EventFileError(
                    path,
                    offset,
                    f"corrupt AEDAT4 packet: {packet_bytes} bytes declared, "
                    f"{end - offset - 8} left before the end of the packets",
                )
            if offset + 8 + packet_bytes > size:
                raise _truncated(
                    path,
                    offset,
                    size,
                    f"inside the packet at byte {offset} ({packet_bytes} bytes declared, "
                    f"{size - offset - 8} present)",
                )
            offset += 8 + packet_bytes
    if end > size:
        raise _truncated(
            path, size, size, f"before the data table its header places at byte {data_table}"
        )


def _first_bad_packet(path: Path) -> int:
    """Walk the packet headers; the offset of the first one that runs past the end of file."""
    size = path.stat().st_size
    with open(path, "rb") as file:
        file.seek(len(_MAGIC))
        raw = file.read(4)
        if len(raw) < 4:
            return len(_MAGIC)
        offset = len(_MAGIC) + 4 + struct.unpack("<i", raw)[0]
        if offset > size:
            return len(_MAGIC)
        while offset + 8 <= size:
            file.seek(offset)
            _, packet_size = struct.unpack("<ii", file.read(8))
            if packet_size < 0 or offset + 8 + packet_size > size:
                return offset
            offset += 8 + packet_size
    return offset
