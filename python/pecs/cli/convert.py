"""`pecs convert IN OUT`: re-encode an event file, streaming (any size fits in memory)."""

from __future__ import annotations

import argparse
from collections.abc import Iterator

import pyarrow as pa
import pyarrow.compute as pc

import pecs.io
from pecs.cli._arguments import add_command, number
from pecs.cli._progress import add_progress_arguments, counted, event_total, wants_progress
from pecs.events import sensor_size

# Events read to learn what the file states about itself (its schema metadata).
_PROBE_EVENTS = 1024


def register(subparsers: argparse._SubParsersAction) -> None:
    parser = add_command(
        subparsers,
        "convert",
        help="convert an event file to another format",
        description=f"Convert event files, streaming. Formats by suffix: {pecs.io.supported()}.",
    )
    parser.add_argument("input", help="event file to read")
    parser.add_argument("output", help="event file to write (format from its suffix)")
    parser.add_argument(
        "--format", help="output format name, e.g. evt2 or v2e (by suffix if unset)"
    )
    parser.add_argument("--input-format", help="input format name (by suffix if unset)")
    parser.add_argument(
        "--width", type=number(int, above=0), help="sensor width, when the input does not say"
    )
    parser.add_argument(
        "--height", type=number(int, above=0), help="sensor height, when the input does not say"
    )
    parser.add_argument(
        "--batch-size", type=number(int, above=0), default=1 << 20, help="events per batch"
    )
    add_progress_arguments(parser)
    parser.add_argument(
        "--compression",
        help="HDF5 compression: gzip (default, every HDF5 reads it), lzf, none, or blosc "
        "(smaller and faster, as DSEC ships; reading it needs hdf5plugin)",
    )
    parser.add_argument(
        "--zero-time",
        action="store_true",
        help="start the times at 0 (subtract the first event's t): for EVT3, whose clock starts "
        "at 0, from recordings in absolute (Unix) microseconds such as DV's AEDAT4",
    )
    parser.set_defaults(func=run)


def run(args: argparse.Namespace) -> int:
    width, height = args.width, args.height
    if width is None or height is None:
        width, height = _input_size(args) or (width, height)
    if width is None and pecs.io.format_for(args.output, args.format).needs_size:
        raise ValueError(
            f"{args.input}: states no sensor size and holds no events to infer it from; "
            f"{args.output} needs one: pass --width and --height"
        )
    batches = pecs.io.iter_events(args.input, batch_size=args.batch_size, format=args.input_format)
    if args.zero_time:
        batches = _from_zero(batches)
    show = wants_progress(args)
    total = event_total(args.input, args.input_format) if show else None
    with pecs.io.EventWriter(
        args.output, width=width, height=height, format=args.format, compression=args.compression
    ) as writer:
        for batch in counted(batches, show, total):
            writer.write(batch)
    print(f"{args.output}: {writer.count} events, {writer.width} x {writer.height}")
    return 0


def _from_zero(batches: Iterator[pa.RecordBatch]) -> Iterator[pa.RecordBatch]:
    """The batches with the first event's t subtracted from every t."""
    first_us = None
    for batch in batches:
        if batch.num_rows and first_us is None:
            first_us = batch.column("t")[0].as_py()
        if first_us:
            t = pc.subtract(batch.column("t"), pa.scalar(first_us, pa.int64()))
            batch = batch.set_column(batch.schema.get_field_index("t"), "t", t)
        yield batch


def _input_size(args: argparse.Namespace) -> tuple[int, int] | None:
    """The size the input states; else, for formats whose header needs one, the largest address
    + 1 found in a first pass over the input."""
    probe = pecs.io.iter_events(args.input, batch_size=_PROBE_EVENTS, format=args.input_format)
    first = next(iter(probe), None)
    stated = sensor_size(first.schema) if first is not None else None
    if stated is not None:
        return stated
    if not pecs.io.format_for(args.output, args.format).needs_size:
        return None
    width = height = 0
    batches = pecs.io.iter_events(args.input, batch_size=args.batch_size, format=args.input_format)
    for batch in counted(batches, wants_progress(args), event_total(args.input, args.input_format)):
        if batch.num_rows == 0:
            continue
        width = max(width, int(pc.max(batch.column("x")).as_py()) + 1)
        height = max(height, int(pc.max(batch.column("y")).as_py()) + 1)
    return (width, height) if width and height else None
