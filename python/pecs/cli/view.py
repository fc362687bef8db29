"""`pecs view EVENTS -o out.png | out.mp4 | out.gif`: look at an event stream."""

from __future__ import annotations

import argparse
from pathlib import Path

import pecs.io
import pecs.viz
from pecs.events import sensor_size


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
        events = pecs.io.read_events(args.events)
        if start_us is None and events.num_rows:
            start_us = int(events.column("t")[0].as_py())
        end = (start_us or 0) + window_us if end_us is None else end_us
        if args.time_surface:
            window = events.filter(events.column("t").to_numpy() < end)
            image = pecs.viz.time_surface_image(
                window,
                width,
                height,
                t_us=end - 1,
                tau_us=window_us / 3,
                background=args.background,
            )
        else:
            image = pecs.viz.event_frame(
                events, width, height, t_start_us=start_us, t_end_us=end, background=args.background
            )
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
