"""Small event files of every format, valid and damaged, generated at test time.

`valid_files(folder)` writes one small valid file per reader (the seeds of the fuzz loop in
fuzz_readers.py); `bad_cases()` lists damaged inputs, each with the error a reader must give.
Nothing here is committed as a binary: every file comes from a few lines of code.
"""

from __future__ import annotations

import io
import zipfile
from collections.abc import Callable
from dataclasses import dataclass
from pathlib import Path

import h5py
import numpy as np
import pecs
import pecs.events
import pyarrow as pa
import pyarrow.parquet as pq

WIDTH, HEIGHT = 64, 48

# name -> (suffix, pecs format): one valid seed file each, every reader covered.
SEEDS = {
    "parquet": (".parquet", "parquet"),
    "dsec": (".h5", "hdf5"),
    "v2e": (".h5", "v2e"),
    "aedat4": (".aedat4", "aedat4"),
    "evt3": (".raw", "evt3"),
    "evt2": (".raw", "evt2"),
    "dat": (".dat", "dat"),
    "npz": (".npz", "npz"),
    "text": (".txt", "text"),
}
SUFFIXES = (".parquet", ".h5", ".aedat4", ".raw", ".dat", ".npz", ".txt")


def small_events(n: int = 300, seed: int = 1) -> pa.Table:
    rng = np.random.default_rng(seed)
    columns = {
        "t": np.sort(rng.integers(0, 50_000, n)),
        "x": rng.integers(0, WIDTH, n),
        "y": rng.integers(0, HEIGHT, n),
        "p": rng.integers(0, 2, n),
    }
    batch = pecs.events.record_batch(columns, pecs.events.schema(WIDTH, HEIGHT))
    return pa.Table.from_batches([batch])


def valid_files(folder: Path) -> dict[str, Path]:
    """One small valid file per seed name, written by pecs."""
    folder.mkdir(parents=True, exist_ok=True)
    events = small_events()
    files = {}
    for name, (suffix, fmt) in SEEDS.items():
        files[name] = pecs.io.write_events(events, folder / f"{name}{suffix}", format=fmt)
    return files


@dataclass(frozen=True)
class BadCase:
    """A damaged file: its name, how to make its bytes from the seeds, what reading must raise
    (None: it must read, as a valid file would), a fragment of the message, and the format
    to read it as (None: from the suffix)."""

    name: str
    suffix: str
    make: Callable[[dict[str, Path]], bytes]
    fragment: str | None
    format: str | None = None


def _h5_bytes(build: Callable[[h5py.File], None]) -> bytes:
    buffer = io.BytesIO()
    with h5py.File(buffer, "w") as file:
        build(file)
    return buffer.getvalue()


def _dsec(lengths: dict[str, int] | None = None, x_dtype: type = np.uint16) -> bytes:
    lengths = lengths or {}

    def build(file: h5py.File) -> None:
        for name, dtype in (("t", np.uint32), ("x", x_dtype), ("y", np.uint16), ("p", np.uint8)):
            file.create_dataset(f"events/{name}", data=np.zeros(lengths.get(name, 3), dtype))

    return _h5_bytes(build)


def _parquet_bytes(table: pa.Table) -> bytes:
    buffer = io.BytesIO()
    pq.write_table(table, buffer)
    return buffer.getvalue()


def _npz_bytes(members: dict[str, bytes | np.ndarray]) -> bytes:
    buffer = io.BytesIO()
    with zipfile.ZipFile(buffer, "w") as archive:
        for name, value in members.items():
            if isinstance(value, np.ndarray):
                member = io.BytesIO()
                np.lib.format.write_array(member, value)
                value = member.getvalue()
            archive.writestr(name, value)
    return buffer.getvalue()


def _npy_header_claiming(count: int) -> bytes:
    """An npy member whose header declares `count` int64 values and holds 8 bytes."""
    member = io.BytesIO()
    header = {"descr": "<i8", "fortran_order": False, "shape": (count,)}
    np.lib.format.write_array_header_1_0(member, header)
    return member.getvalue() + bytes(8)


def _text_cut_mid_line(files: dict[str, Path]) -> bytes:
    data = files["text"].read_bytes()
    middle = data.index(b"\n", len(data) // 2) + 1  # start of a line past the middle
    return data[: data.index(b" ", middle) + 1]  # ... and cut after its first field


def _cut(name: str, fraction: float = 0.5, align: int = 1) -> Callable[[dict[str, Path]], bytes]:
    def make(files: dict[str, Path]) -> bytes:
        data = files[name].read_bytes()
        end = int(len(data) * fraction)
        return data[: end - end % align + (1 if align > 1 else 0)]

    return make


def _aedat4_first_packet_size(size: int) -> Callable[[dict[str, Path]], bytes]:
    """The AEDAT4 seed with its first packet's int32 size replaced: magic (14 bytes), int32
    header size, header, then the packet's int32 stream id and int32 size."""

    def make(files: dict[str, Path]) -> bytes:
        data = bytearray(files["aedat4"].read_bytes())
        first_packet = 18 + int.from_bytes(data[14:18], "little")
        data[first_packet + 4 : first_packet + 8] = size.to_bytes(4, "little", signed=True)
        return bytes(data)

    return make


def _random(files: dict[str, Path]) -> bytes:
    return np.random.default_rng(12).integers(0, 256, 4096, dtype=np.uint8).tobytes()


def _replace_at(name: str, offset_from_header: int, value: bytes) -> Callable[..., bytes]:
    """The seed file with `value` written just after its `%` header lines."""

    def make(files: dict[str, Path]) -> bytes:
        data = bytearray(files[name].read_bytes())
        end = 0
        while data.startswith(b"%", end):
            end = data.index(b"\n", end) + 1
        data[end + offset_from_header : end + offset_from_header + len(value)] = value
        return bytes(data)

    return make


# What a reader says when a file is not its format (the start of "not a/an ... file").
NOT_THIS_FORMAT = {
    ".parquet": "not a Parquet file",
    ".h5": "not an HDF5 file",
    ".aedat4": "not an AEDAT 4.0 file",
    ".dat": "not a Prophesee DAT file",
    ".npz": "not an npz file",
    ".txt": "not a text event file",
    ".raw": "not a Prophesee RAW file",
}
# What `looks_like` recognises in each seed (text has no signature).
LOOKS_LIKE = {
    "parquet": "a Parquet file",
    "dsec": "an HDF5 file",
    "v2e": "an HDF5 file",
    "aedat4": "an AEDAT4 file",
    "evt3": "a Prophesee RAW file",
    "evt2": "a Prophesee RAW file",
    "dat": "a Prophesee DAT or RAW file",
    "npz": "a zip archive",
}


def _renamed(seed: str) -> Callable[[dict[str, Path]], bytes]:
    return lambda files: files[seed].read_bytes()


def _wrong_suffix_cases() -> list[BadCase]:
    cases = []
    for seed, (own_suffix, _) in SEEDS.items():
        for suffix in SUFFIXES:
            if suffix == own_suffix:
                continue
            cases.append(
                BadCase(f"{seed}-as{suffix}", suffix, _renamed(seed), NOT_THIS_FORMAT[suffix])
            )
    return cases


def bad_cases() -> list[BadCase]:
    empty = lambda files: b""  # noqa: E731
    cases = [BadCase(f"zero-bytes{s}", s, empty, NOT_THIS_FORMAT[s]) for s in SUFFIXES]
    # An empty text file is an empty event list; so is a RAW header with no words.
    cases = [c for c in cases if c.suffix != ".txt"] + [
        BadCase("zero-bytes.txt", ".txt", empty, None)
    ]
    cases += [BadCase(f"random{s}", s, _random, NOT_THIS_FORMAT[s]) for s in SUFFIXES]
    cases += [
        BadCase("truncated.parquet", ".parquet", _cut("parquet"), "truncated Parquet file"),
        BadCase("truncated-dsec.h5", ".h5", _cut("dsec"), "truncated or corrupt HDF5 file"),
        BadCase("truncated-v2e.h5", ".h5", _cut("v2e"), "truncated or corrupt HDF5 file"),
        BadCase("truncated.aedat4", ".aedat4", _cut("aedat4", 0.8), "truncated AEDAT4 file"),
        BadCase("truncated.dat", ".dat", _cut("dat", 0.5, 8), "truncated DAT file"),
        BadCase("truncated.npz", ".npz", _cut("npz"), "not an npz file"),
        BadCase("truncated.txt", ".txt", _text_cut_mid_line, "line 152: 2 fields, not 4"),
        BadCase("truncated-evt3.raw", ".raw", _cut("evt3", 0.5, 2), "truncated EVT3 file"),
        BadCase("truncated-evt2.raw", ".raw", _cut("evt2", 0.5, 4), "truncated EVT2 file", "evt2"),
    ]
    cases += _wrong_suffix_cases()
    cases += [
        # Parquet that is not events.
        BadCase(
            "no-t-column.parquet",
            ".parquet",
            lambda f: _parquet_bytes(pa.table({"a": [1, 2], "x": [1, 2]})),
            "holds no events: no column(s) ['t', 'y', 'p']",
        ),
        BadCase(
            "float-t.parquet",
            ".parquet",
            lambda f: _parquet_bytes(pa.table({"t": [0.5], "x": [1], "y": [1], "p": [1]})),
            "column t holds double, not integers",
        ),
        # HDF5 that is not events.
        BadCase(
            "no-events.h5",
            ".h5",
            lambda f: _h5_bytes(lambda file: file.create_dataset("frames", data=[1, 2])),
            "HDF5 file holds no events",
        ),
        BadCase(
            "dsec-without-p.h5",
            ".h5",
            lambda f: _h5_bytes(
                lambda file: file.create_dataset("events/t", data=np.zeros(2, np.uint32))
            ),
            "'events' group lacks ['p', 'x', 'y']",
        ),
        BadCase("dsec-ragged.h5", ".h5", lambda f: _dsec({"x": 2}), "columns differ in length"),
        BadCase(
            "dsec-float-x.h5", ".h5", lambda f: _dsec(x_dtype=np.float32), "column x holds float32"
        ),
        BadCase(
            "v2e-three-columns.h5",
            ".h5",
            lambda f: _h5_bytes(
                lambda file: file.create_dataset("events", data=np.zeros((2, 3), np.uint32))
            ),
            "must be N x 4",
        ),
        # Shapes that declare data the file does not hold (HDF5 reads zeros for it): found by
        # the fuzz loop, a v2e file of 2^31 rows read one event at a time for hours.
        BadCase(
            "v2e-unstored-rows.h5",
            ".h5",
            lambda f: _h5_bytes(
                lambda file: file.create_dataset(
                    "events", shape=(10**9, 4), maxshape=(None, 4), chunks=(1024, 4), dtype="u4"
                )
            ),
            "/events declares shape (1000000000, 4) but stores 0 of its 976563 chunks",
        ),
        BadCase(
            "dsec-unstored-t.h5",
            ".h5",
            lambda f: _h5_bytes(
                lambda file: [
                    file.create_dataset(f"events/{name}", shape=(10**6,), dtype="u2")
                    for name in "txyp"
                ]
            ),
            "/events/t declares 2000000 bytes but stores 0",
        ),
        # AEDAT4 with a header length past the end of the file.
        BadCase(
            "aedat4-header-length.aedat4",
            ".aedat4",
            lambda f: f["aedat4"].read_bytes()[:14] + (10**6).to_bytes(4, "little"),
            "corrupt AEDAT4 header",
        ),
        # AEDAT4 whose XML description is not UTF-8 (faery aborted the process on it).
        BadCase(
            "aedat4-description-not-utf8.aedat4",
            ".aedat4",
            lambda f: f["aedat4"].read_bytes().replace(b"<dv version", b"<dv\xe1version", 1),
            "corrupt AEDAT4 header ('utf-8' codec can't decode byte 0xe1",
        ),
        # AEDAT4 whose first packet declares -2^28 bytes: faery read it as ~4 GB, allocated
        # them, and aborted under a memory limit (a fuzz finding).
        BadCase(
            "aedat4-packet-size.aedat4",
            ".aedat4",
            _aedat4_first_packet_size(-(1 << 28)),
            "corrupt AEDAT4 packet: -268435456 bytes declared",
        ),
        # DAT with a wrong event size or type byte.
        BadCase("dat-event-size.dat", ".dat", _replace_at("dat", 1, b"\x04"), "event size 4"),
        BadCase("dat-event-type.dat", ".dat", _replace_at("dat", 0, b"\x55"), "event type 0x55"),
        # npz that is not events.
        BadCase(
            "npz-no-events.npz",
            ".npz",
            lambda f: _npz_bytes({"a.npy": np.zeros(2), "b.npy": np.zeros(2)}),
            "npz holds no events",
        ),
        BadCase(
            "npz-float-events.npz",
            ".npz",
            lambda f: _npz_bytes({"events.npy": np.zeros(3)}),
            "events.npy is not events",
        ),
        BadCase(
            "npz-huge-shape.npz",
            ".npz",
            lambda f: _npz_bytes({"events.npy": _npy_header_claiming(10**12)}),
            "declares (1000000000000,)",
        ),
        BadCase(
            "npz-ragged.npz",
            ".npz",
            lambda f: _npz_bytes(
                {
                    "t.npy": np.arange(3),
                    "x.npy": np.arange(2),
                    "y.npy": np.arange(3),
                    "p.npy": np.ones(3),
                }
            ),
            "arrays differ in length",
        ),
        # Text that is not events.
        BadCase("csv.txt", ".txt", lambda f: b"t,x,y,p\n0.1,1,2,1\n", "line 1: 1 fields, not 4"),
    ]
    return cases
