"""`pecs frames2events INPUT -o events.parquet`: frames on disk to events."""

from __future__ import annotations

import argparse
import ast
from typing import Any

from pecs.config import SensorConfig
from pecs.frames import open_frames
from pecs.sensor import frames_to_file


def register(subparsers: argparse._SubParsersAction) -> None:
    p = subparsers.add_parser(
        "frames2events",
        help="convert frames (image folder, video, EXR sequence, .npy) to events",
        description="Simulate a DVS sensor on a frame sequence and write its events.",
    )
    p.add_argument(
        "input", help="a folder of images or EXR files, a video file, or a .npy array (N, H, W)"
    )
    p.add_argument(
        "-o",
        "--output",
        default="events.parquet",
        help="event file to write (default: events.parquet)",
    )
    p.add_argument(
        "--preset",
        default="davis346",
        choices=SensorConfig.PRESETS,
        help="sensor preset (default: davis346)",
    )
    p.add_argument(
        "--config", help="sensor config file (TOML, e.g. from pecs calibrate); replaces --preset"
    )
    timing = p.add_mutually_exclusive_group()
    timing.add_argument("--fps", type=float, help="frame rate, when the input has no timestamps")
    timing.add_argument("--timestamps", help="text file with one timestamp per line (first column)")
    p.add_argument(
        "--timestamp-unit",
        default="us",
        choices=("us", "ms", "s"),
        help="unit of --timestamps (default: us)",
    )
    p.add_argument("--channel", help="EXR channel to read (default: Y, else luminance of R, G, B)")
    p.add_argument(
        "--encoding",
        default="srgb",
        choices=("srgb", "linear"),
        help="how 8/16-bit images are encoded",
    )
    p.add_argument(
        "--set",
        action="append",
        default=[],
        metavar="FIELD=VALUE",
        help="override a sensor field, e.g. --set theta_on=0.3",
    )
    p.add_argument("--quiet", action="store_true", help="no progress bar")
    p.set_defaults(func=run)


def parse_overrides(items: list[str]) -> dict[str, Any]:
    """FIELD=VALUE pairs; values are Python literals (0.3, 1e-3, True, None) or plain strings."""
    overrides: dict[str, Any] = {}
    for item in items:
        field, sep, text = item.partition("=")
        if not sep or not field:
            raise ValueError(f"--set {item!r}: expected FIELD=VALUE")
        try:
            overrides[field.strip()] = ast.literal_eval(text)
        except (ValueError, SyntaxError):
            overrides[field.strip()] = text
    return overrides


def run(args: argparse.Namespace) -> int:
    frames = open_frames(
        args.input,
        fps=args.fps,
        timestamps=args.timestamps,
        timestamp_unit=args.timestamp_unit,
        channel=args.channel,
        encoding=args.encoding,
    )
    overrides = parse_overrides(args.set)
    overrides.setdefault("width", frames.width)
    overrides.setdefault("height", frames.height)
    base = SensorConfig.from_file(args.config) if args.config else SensorConfig.preset(args.preset)
    config = base.replace(**overrides)
    counts = frames_to_file(frames, args.output, config, progress=not args.quiet)
    print(
        f"{counts['events']} events from {counts['frames']} frames ({config.width} x {config.height}) -> {args.output}"
    )
    return 0
