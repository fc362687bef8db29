"""`pecs convert IN OUT`: re-encode an event file, streaming (any size fits in memory)."""

from __future__ import annotations

import argparse
import sys
from collections.abc import Callable
from typing import Any

import pyarrow as pa
import pyarrow.compute as pc

import pecs.io
from pecs._atomic import names_stdout
from pecs.cli._arguments import add_command, number
from pecs.cli._progress import add_progress_arguments, counted, event_total, wants_progress
from pecs.cli._stop import StdoutClosed
from pecs.events import sensor_size

# Events read to learn what the file states about itself (its schema metadata).
_PROBE_EVENTS = 1024


def register(subparsers: argparse._SubParsersAction) -> None:
    parser = add_command(
        subparsers,
        "convert",
        help="convert an event file to another format",
        description=f"Convert event files, streaming. Formats by suffix: {_formats()}.",
    )
    parser.add_argument("input", help="event file to read")
    parser.add_argument(
        "output",
        help="event file to write (format from its suffix), or - for stdout (text unless "
        "--format says; HDF5 is sent once complete, the other formats as they are written)",
    )
    add_stream_arguments(parser)
    parser.add_argument(
        "--compression",
        help="HDF5 compression: gzip (default, every HDF5 reads it), lzf, none, or blosc "
        "(smaller and faster, as DSEC ships; reading it needs hdf5plugin)",
    )
    parser.add_argument(
        "--zero-time",
        action="store_true",
        help="start the times at 0 (subtract the first event's t): for EVT3, EVT2, DAT and "
        "v2e, whose clock starts at 0, from recordings in absolute (Unix) microseconds such as "
        "DV's AEDAT4",
    )
    parser.set_defaults(func=run)


def _formats() -> str:
    """The formats and their suffixes, as a user of this command asks for them (the API's
    `pecs.io.supported()` names the Python argument, format='v2e')."""
    from pecs.io.formats import FORMATS

    parts = []
    for name, event_format in FORMATS.items():
        where = ", ".join(event_format.suffixes) or f"--format {name}"
        parts.append(f"{name} ({where})")
    return "; ".join(parts)


def add_stream_arguments(parser: argparse.ArgumentParser) -> None:
    """The options `copy_events` reads: formats, the size where the input states none, the
    batch size, progress (`pecs convert` and `pecs filter`)."""
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


def run(args: argparse.Namespace) -> int:
    writer, to_stdout = copy_events(args, compression=args.compression, zero_time=args.zero_time)
    # Events on stdout: the summary goes beside them, to stderr.
    summary = sys.stderr if to_stdout else sys.stdout
    print(f"{args.output}: {writer.count} events, {writer.width} x {writer.height}", file=summary)
    return 0


def copy_events(
    args: argparse.Namespace,
    through: Callable[[pa.RecordBatch], pa.RecordBatch] | None = None,
    last: Callable[[], pa.RecordBatch] | None = None,
    **writer_options: Any,
) -> tuple[pecs.io.EventWriter, bool]:
    """Stream `args.input` to `args.output` as `convert` does (the size the input states or
    shows, progress, `-` for stdout and a reader that goes away), each batch passed `through`
    and `last()`'s batch written at the end (`pecs filter`'s stream); returns the closed writer
    and whether it wrote to stdout."""
    width, height = args.width, args.height
    if width is None or height is None:
        width, height = _input_size(args) or (width, height)
    if width is None and pecs.io.format_for(args.output, args.format).needs_size:
        raise ValueError(
            f"{args.input}: states no sensor size and holds no events to infer it from; "
            f"{args.output} needs one: pass --width and --height"
        )
    batches = pecs.io.iter_events(args.input, batch_size=args.batch_size, format=args.input_format)
    show = wants_progress(args)
    total = event_total(args.input, args.input_format) if show else None
    to_stdout = names_stdout(args.output)
    try:
        with pecs.io.EventWriter(
            args.output, width=width, height=height, format=args.format, **writer_options
        ) as writer:
            for batch in counted(batches, show, total):
                writer.write(through(batch) if through else batch)
            if last is not None:
                writer.write(last())
    except BrokenPipeError:
        if to_stdout:  # `pecs convert IN - | head`: the reader has what it wanted
            raise StdoutClosed from None
        raise
    return writer, to_stdout


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
