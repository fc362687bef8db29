"""Progress bars of the `pecs` commands: on stderr, shown when stderr is a terminal or when
`--progress` asks, never with `--quiet`; events done out of the total where the file says it."""

from __future__ import annotations

import argparse
import sys
from collections.abc import Iterable, Iterator
from pathlib import Path
from typing import Any

import pyarrow as pa


def add_progress_arguments(parser: argparse.ArgumentParser) -> None:
    group = parser.add_mutually_exclusive_group()
    group.add_argument(
        "--progress",
        action="store_true",
        help="show a progress bar on stderr even when it is not a terminal",
    )
    group.add_argument("--quiet", action="store_true", help="no progress bar")


def wants_progress(args: argparse.Namespace) -> bool:
    if args.quiet:
        return False
    return bool(args.progress) or sys.stderr.isatty()


def counted(
    batches: Iterable[pa.RecordBatch], enabled: bool, total: int | None = None
) -> Iterator[pa.RecordBatch]:
    """The batches, unchanged, while a bar counts their events."""
    if not enabled:
        yield from batches
        return
    from tqdm import tqdm

    with tqdm(total=total, unit="ev", unit_scale=True, dynamic_ncols=True, file=sys.stderr) as bar:
        for batch in batches:
            yield batch
            bar.update(batch.num_rows)


def event_total(path: str | Path, format: str | None = None) -> int | None:
    """The number of events a file holds, when its metadata says so without reading it (Parquet
    row count, HDF5 dataset length); None otherwise, and the bar shows a count and a rate."""
    import pecs.io

    try:
        name = pecs.io.format_for(Path(path), format).name
        if name == "parquet":
            import pyarrow.parquet as pq

            return int(pq.ParquetFile(path).metadata.num_rows)
        if name in ("hdf5", "v2e"):
            return _hdf5_total(path)
    except Exception:  # a bad file is the reader's to report, with its own message
        return None
    return None


def _hdf5_total(path: str | Path) -> int | None:
    import h5py

    with h5py.File(path, "r") as file:
        events: Any = file.get("events")
        if isinstance(events, h5py.Group) and "t" in events:
            return int(events["t"].shape[0])
        if isinstance(events, h5py.Dataset):
            return int(events.shape[0])
    return None
