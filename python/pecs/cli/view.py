"""`pecs view EVENTS -o out.png | out.mp4 | out.gif`: look at an event stream."""

from __future__ import annotations

import argparse
from collections.abc import Iterator
from pathlib import Path

import numpy as np
import pyarrow as pa

import pecs.io
import pecs.viz
from pecs.cli._arguments import add_command, number
from pecs.cli._progress import add_progress_arguments, counted, event_total, wants_progress
from pecs.events import schema, sensor_size

_SUFFIXES = (".png", ".mp4", ".gif")
# Events read to learn what the file states about itself (its schema metadata).
_PROBE_EVENTS = 1024


def register(subparsers: argparse._SubParsersAction) -> None:
    parser = add_command(
        subparsers,
        "view",
        help="render events to an image or video",
        description="PNG: one event frame (or time surface) over a window. MP4/GIF: consecutive "
        "event frames, one per window. Blue: ON, red: OFF.",
    )
    parser.add_argument("events", help="event file")
    parser.add_argument("-o", "--output", required=True, help="out.png, out.mp4 or out.gif")
    parser.add_argument(
        "--window-ms", type=number(float, above=0), default=33.3, help="event time per frame"
    )
    parser.add_argument(
        "--start-ms", type=number(float), help="first event time shown (the first event if unset)"
    )
    parser.add_argument(
        "--end-ms", type=number(float), help="last event time shown (video; the last if unset)"
    )
    parser.add_argument(
        "--fps", type=number(float, above=0), default=30.0, help="video playback rate"
    )
    parser.add_argument(
        "--background", choices=("white", "black"), default="white", help="background colour"
    )
    parser.add_argument(
        "--time-surface", action="store_true", help="PNG only: a time surface instead"
    )
    parser.add_argument(
        "--width", type=number(int, above=0), help="sensor width, when the file does not say"
    )
    parser.add_argument(
        "--height", type=number(int, above=0), help="sensor height, when the file does not say"
    )
    add_progress_arguments(parser)
    parser.set_defaults(func=run)


def run(args: argparse.Namespace) -> int:
    output = Path(args.output)
    suffix = output.suffix.lower()
    _check(args, suffix)
    window_us = round(args.window_ms * 1000)
    start_us = None if args.start_ms is None else round(args.start_ms * 1000)
    end_us = None if args.end_ms is None else round(args.end_ms * 1000)
    width, height = _size(args)
    if suffix == ".png":
        image = _still(args, width, height, start_us, end_us, window_us)
        pecs.viz.save_image(image, output)
        print(f"{output}: {image.shape[1]} x {image.shape[0]}")
        return 0
    frames = pecs.viz.event_frames(
        _events(args, start_us),
        width,
        height,
        window_us=window_us,
        t_start_us=start_us,
        t_end_us=end_us,
        background=args.background,
    )
    pecs.viz.save_video(frames, output, fps=args.fps)
    print(f"{output}: written")
    return 0


def _check(args: argparse.Namespace, suffix: str) -> None:
    """Refuse what would give a blank or different picture than asked, before reading."""
    if suffix not in _SUFFIXES:
        raise ValueError(f"{args.output}: output must be .png, .mp4 or .gif")
    if args.time_surface and suffix != ".png":
        raise ValueError(f"--time-surface draws one PNG; {suffix} videos show event frames")
    if round(args.window_ms * 1000) < 1:
        raise ValueError(f"--window-ms {args.window_ms:g}: shorter than the 1 us time resolution")
    if args.start_ms is not None and args.end_ms is not None and args.end_ms <= args.start_ms:
        raise ValueError(
            f"--end-ms {args.end_ms:g} is not after --start-ms {args.start_ms:g}: nothing to show"
        )


def _events(args: argparse.Namespace, start_us: int | None) -> Iterator[pa.RecordBatch]:
    """The file's batches; a start past the last event is a ValueError, not a blank video."""
    show = wants_progress(args)
    total = event_total(args.events) if show else None
    last_t: int | None = None
    for batch in counted(pecs.io.iter_events(args.events), show, total):
        if batch.num_rows:
            last_t = int(batch.column("t")[-1].as_py())
        yield batch
    _check_start(args, start_us, last_t)


def _check_start(args: argparse.Namespace, start_us: int | None, last_t: int | None) -> None:
    if last_t is None:
        raise ValueError(f"{args.events}: no events to show")
    if start_us is not None and start_us > last_t:
        raise ValueError(
            f"--start-ms {args.start_ms:g} is past the last event (t = {last_t / 1000:g} ms)"
        )


def _still(
    args: argparse.Namespace,
    width: int | None,
    height: int | None,
    start_us: int | None,
    end_us: int | None,
    window_us: int,
) -> np.ndarray:
    """One frame over [start, end) (default: the first window), streaming through the file.
    The time surface is taken at the end of that window with tau = window / 3, so events older
    than the window have faded to under 5 %."""
    kept: list[pa.RecordBatch] = []
    last_t: int | None = None
    show = wants_progress(args)
    total = event_total(args.events) if show else None
    for batch in counted(pecs.io.iter_events(args.events), show, total):
        t = batch.column("t").to_numpy()
        if len(t) == 0:
            continue
        last_t = int(t[-1])
        if start_us is None:
            start_us = int(t[0])
        end = start_us + window_us if end_us is None else end_us
        first = start_us if not args.time_surface else end - 10 * window_us
        lo, hi = np.searchsorted(t, first, "left"), np.searchsorted(t, end, "left")
        if hi > lo:
            kept.append(batch.slice(lo, hi - lo))
        if t[-1] >= end:
            break
    _check_start(args, start_us, last_t)
    assert start_us is not None
    end = start_us + window_us if end_us is None else end_us
    events = pa.Table.from_batches(kept, schema=kept[0].schema) if kept else None
    if events is None:
        return pecs.viz.event_frame(_empty(width, height), background=args.background)
    if args.time_surface:
        return pecs.viz.time_surface_image(
            events, width, height, t_us=end - 1, tau_us=window_us / 3, background=args.background
        )
    return pecs.viz.event_frame(
        events, width, height, t_start_us=start_us, t_end_us=end, background=args.background
    )


def _empty(width: int | None, height: int | None) -> pa.Table:
    return schema(width, height).empty_table()


def _size(args: argparse.Namespace) -> tuple[int | None, int | None]:
    if args.width is not None and args.height is not None:
        return args.width, args.height
    first = next(iter(pecs.io.iter_events(args.events, batch_size=_PROBE_EVENTS)), None)
    stated = sensor_size(first.schema) if first is not None else None
    if stated is not None:
        return stated
    # No size in the file: one streaming pass for the largest address.
    width = height = 0
    for batch in pecs.io.iter_events(args.events):
        if batch.num_rows:
            width = max(width, int(batch.column("x").to_numpy().max()) + 1)
            height = max(height, int(batch.column("y").to_numpy().max()) + 1)
    if not width:
        raise ValueError(f"{args.events}: no events and no sensor size; pass --width/--height")
    return width, height
