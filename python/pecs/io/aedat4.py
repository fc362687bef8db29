"""AEDAT 4.0 (iniVation DV), encoded and decoded by faery.

Layout: magic `#!AER-DAT4.0\\r\\n`, int32 header size, FlatBuffers IOHeader (with the stream
description: sizeX, sizeY), then packets, each an 8-byte header (int32 stream id, int32 size)
and a (LZ4 or ZSTD compressed) FlatBuffers EventPacket of {int64 t µs, int16 x, int16 y, bool
on}, then an optional FileDataTable. A truncated file is reported at the packet that runs past
the end.
"""

from __future__ import annotations

import struct
from collections.abc import Iterator
from pathlib import Path

import pyarrow as pa

from pecs.io._common import EventFileError, Sink, empty_batch, looks_like
from pecs.io._faery import from_faery, is_decoder_failure, rebatched, to_faery

_MAGIC = b"#!AER-DAT4.0\r\n"


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

    with open(path, "rb") as file:
        magic = file.read(len(_MAGIC))
        header_bytes = int.from_bytes(file.read(4).ljust(4, b"\0"), "little")
    if magic != _MAGIC:
        raise EventFileError(
            path, 0, f"not an AEDAT 4.0 file (starts with {magic!r}){looks_like(path)}"
        )
    if header_bytes == 0 or len(_MAGIC) + 4 + header_bytes > path.stat().st_size:
        raise EventFileError(
            path, len(_MAGIC), f"corrupt AEDAT4 header ({header_bytes} bytes declared)"
        )
    data_table = _check_description(path, header_bytes)
    _check_packets(path, len(_MAGIC) + 4 + header_bytes, data_table)
    try:
        decoder = faery.aedat.Decoder(path)
        tracks = decoder.tracks()
    except BaseException as error:
        if not is_decoder_failure(error):
            raise
        raise EventFileError(path, _first_bad_packet(path), f"corrupt AEDAT4 ({error})") from error
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
            offset = _first_bad_packet(path)
            raise EventFileError(path, offset, f"corrupt AEDAT4 packet ({error})") from error


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
    """Every packet (int32 stream id, int32 size, data) must end before the data table or the
    end of the file: faery allocates a packet's declared size before reading it, so a damaged
    size field of ~2^31 cost it seconds and, under a memory limit, aborted the process."""
    size = path.stat().st_size
    end = data_table if first_packet <= data_table <= size else size
    offset = first_packet
    with open(path, "rb") as file:
        while offset < end:
            file.seek(offset)
            head = file.read(8)
            if len(head) < 8 or offset + 8 > end:
                raise EventFileError(path, offset, "truncated AEDAT4 packet header")
            packet_bytes = struct.unpack("<ii", head)[1]
            if packet_bytes < 0 or offset + 8 + packet_bytes > end:
                raise EventFileError(
                    path,
                    offset,
                    f"corrupt AEDAT4 packet: {packet_bytes} bytes declared, "
                    f"{end - offset - 8} left before the end of the packets",
                )
            offset += 8 + packet_bytes


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
