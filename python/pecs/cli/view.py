"""`pecs view EVENTS -o out.png | out.mp4 | out.gif`: look at an event stream."""

from __future__ import annotations

import argparse
from pathlib import Path

import numpy as np
import pyarrow as pa

import pecs.io
import pecs.viz
from pecs.events import schema, sensor_size


def register(subparsers: argparse._SubParsersAction) -> None:
    parser = subparsers.add_parser(
        "view",
        help="render events to an image or video",
        description="PNG: one event frame (or time surface) over a window. MP4/GIF: consecutive "
        "event frames, one per window.",
    )
    parser.add_argument("events", help="event file")
    parser.add_argument("-o", "--output", required=True, help="out.png, out.mp4 or out.gif")
    parser.add_argument("--window-ms", type=float, default=33.3, help="event time per frame")
    parser.add_argument("--start-ms", type=float, help="first event time shown (default: first)")
    parser.add_argument("--end-ms", type=float, help="last event time shown (video)")
    parser.add_argument("--fps", type=float, default=30.0, help="video playback rate")
    parser.add_argument("--background", choices=("white", "black"), default="white")
    parser.add_argument("--time-surface", action="store_true", help="PNG: time surface instead")
    parser.add_argument("--width", type=int, help="sensor width, when the file does not say")
    parser.add_argument("--height", type=int, help="sensor height, when the file does not say")
    parser.set_defaults(func=run)


def run(args: argparse.Namespace) -> int:
    output = Path(args.output)
    suffix = output.suffix.lower()
    if suffix not in (".png", ".mp4", ".gif"):
        raise ValueError(f"{output}: output must be .png, .mp4 or .gif")
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
        pecs.io.iter_events(args.events),
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
    for batch in pecs.io.iter_events(args.events):
        t = batch.column("t").to_numpy()
        if len(t) == 0:
            continue
        if start_us is None:
            start_us = int(t[0])
        end = start_us + window_us if end_us is None else end_us
        first = start_us if not args.time_surface else end - 10 * window_us
        lo, hi = np.searchsorted(t, first, "left"), np.searchsorted(t, end, "left")
        if hi > lo:
            kept.append(batch.slice(lo, hi - lo))
        if t[-1] >= end:
            break
    if start_us is None:
        raise ValueError(f"{args.events}: no events to show")
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
    first = next(iter(pecs.io.iter_events(args.events, batch_size=1)), None)
    stated = sensor_size(first.schema) if first is not None else None
    if stated is not None:
        return stated
    # No size in the file: one pass for the largest address.
    table = pecs.io.read_events(args.events)
    if table.num_rows == 0:
        raise ValueError(f"{args.events}: no events and no sensor size; pass --width/--height")
    return int(max(table.column("x").to_numpy())) + 1, int(max(table.column("y").to_numpy())) + 1
