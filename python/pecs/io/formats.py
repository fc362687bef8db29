"""The registry of event file formats: name, file suffixes, reader and writer of each."""

from __future__ import annotations

from collections.abc import Callable, Iterator
from dataclasses import dataclass
from pathlib import Path

import pyarrow as pa

from pecs.io import aedat4, dat, evt, hdf5, npz, parquet, text
from pecs.io._common import Sink


@dataclass(frozen=True)
class Format:
    name: str
    suffixes: tuple[str, ...]
    description: str
    #: (path, batch_size) -> record batches
    read: Callable[[Path, int], Iterator[pa.RecordBatch]]
    #: (path, width, height, schema, compression) -> sink; width and height are None when unknown
    open_sink: Callable[[Path, int | None, int | None, pa.Schema, str | None], Sink]
    #: the format's header stores the sensor size, so it must be known before the first event
    needs_size: bool = False
    #: the format stores the optional `label` column
    keeps_labels: bool = False
    #: the largest x and y the format stores (uint16 in the pecs schema)
    max_address: int = (1 << 16) - 1
    #: the compressions the writer offers (`compression=`); the first is the default
    compressions: tuple[str, ...] = ()
    #: the writer writes front to back, never seeking back: a pipe or device can take it as
    #: it is written (else it is built in a temporary file and copied there at the end)
    streams: bool = True
    #: a camera clock: t must be 0 <= t < clock_us (None: any int64 t)
    clock_us: int | None = None
    #: how the format stores t, and what holds a longer recording, for the refusal's message
    clock: str = ""
    longer: str = ""


def _sized(make: Callable[[Path, int, int], Sink]) -> Callable[..., Sink]:
    def open_sink(
        path: Path, width: int | None, height: int | None, _: pa.Schema, __: str | None
    ) -> Sink:
        assert width is not None and height is not None  # EventWriter checks needs_size
        return make(path, width, height)

    return open_sink


FORMATS: dict[str, Format] = {
    f.name: f
    for f in (
        Format(
            "parquet",
            (".parquet", ".pq"),
            "Apache Parquet, pecs schema and metadata (default)",
            parquet.read_batches,
            lambda path, w, h, schema, _: parquet.ParquetSink(path, schema),
            keeps_labels=True,
        ),
        Format(
            "hdf5",
            (".h5", ".hdf5"),
            "HDF5, DSEC layout (events/x,y,t,p, ms_to_idx, t_offset)",
            hdf5.read_batches,
            lambda path, w, h, schema, compression: hdf5.DsecSink(path, w, h, compression),
            compressions=hdf5.COMPRESSIONS,
            streams=False,
        ),
        Format(
            "v2e",
            (),
            "HDF5, v2e layout (events: N x 4 uint32 [t, x, y, p]); ask for it with format='v2e'",
            hdf5.read_batches,
            lambda path, w, h, schema, compression: hdf5.V2eSink(path, w, h, compression),
            compressions=hdf5.COMPRESSIONS,
            streams=False,
            clock_us=1 << 32,
            clock="uint32 µs (0 to 4294967295), 71.6 minutes",
            longer="the DSEC layout (.h5) or Parquet",
        ),
        Format(
            "aedat4",
            (".aedat4",),
            "AEDAT 4.0 (iniVation DV)",
            aedat4.read_batches,
            _sized(aedat4.Aedat4Sink),
            max_address=aedat4.Aedat4Sink.max_address,
            needs_size=True,
        ),
        Format(
            "evt3",
            (".raw",),
            "Prophesee RAW EVT 3.0 (default for .raw)",
            evt.read_batches,
            _sized(lambda path, w, h: evt.EvtSink(path, "evt3", w, h)),
            max_address=evt.EvtSink.max_address,
            needs_size=True,
            clock_us=evt.MAX_T_US,
            clock=evt.CLOCK,
            longer="HDF5 (.h5) or Parquet",
        ),
        Format(
            "evt2",
            (),
            "Prophesee RAW EVT 2.0; ask for it with format='evt2'",
            evt.read_batches,
            _sized(lambda path, w, h: evt.EvtSink(path, "evt2", w, h)),
            max_address=evt.EvtSink.max_address,
            needs_size=True,
            clock_us=evt.MAX_T_US,
            clock=evt.CLOCK,
            longer="HDF5 (.h5) or Parquet",
        ),
        Format(
            "dat",
            (".dat",),
            "Prophesee DAT (CD events, version 2)",
            dat.read_batches,
            _sized(dat.DatSink),
            max_address=dat.DatSink.max_address,
            needs_size=True,
            clock_us=1 << 32,
            clock="uint32 µs (0 to 4294967295), 71.6 minutes",
            longer="EVT3 (.raw, 19.1 hours), HDF5 (.h5) or Parquet",
        ),
        Format(
            "npz",
            (".npz",),
            "numpy npz, tonic structured array 'events' + 'sensor_size'",
            npz.read_batches,
            lambda path, w, h, schema, _: npz.NpzSink(path, w, h),
            max_address=npz.NpzSink.max_address,
        ),
        Format(
            "text",
            (".txt",),
            "text, rpg/ECD 't x y p' lines, t in seconds",
            text.read_batches,
            lambda path, w, h, schema, _: text.TextSink(path, w, h),
        ),
    )
}

_BY_SUFFIX = {suffix: f for f in FORMATS.values() for suffix in f.suffixes}


def supported() -> str:
    """One line listing the formats and their suffixes, for error messages and --help."""
    parts = []
    for f in FORMATS.values():
        where = ", ".join(f.suffixes) if f.suffixes else f"format={f.name!r}"
        parts.append(f"{f.name} ({where})")
    return "; ".join(parts)


def format_for(path: str | Path, name: str | None = None) -> Format:
    """The format named `name`, else the one registered for the path's suffix; text for `-`
    (stdout), which has none."""
    if name is None and str(path) == "-":
        return FORMATS["text"]
    if name is not None:
        key = name.lower().replace(".", "").replace("-", "")
        key = {"raw": "evt3", "h5": "hdf5", "dsec": "hdf5", "txt": "text", "pq": "parquet"}.get(
            key, key
        )
        if key not in FORMATS:
            raise ValueError(f"unknown event format {name!r}; supported: {supported()}")
        return FORMATS[key]
    suffix = Path(path).suffix.lower()
    if suffix not in _BY_SUFFIX:
        raise ValueError(
            f"{path}: unknown event file suffix {suffix or '(none)'!r}; supported: {supported()}"
        )
    return _BY_SUFFIX[suffix]
