"""`pecs frames2events INPUT -o events.parquet`: frames on disk to events."""

from __future__ import annotations

import argparse

from pecs.cli._arguments import add_command, number
from pecs.cli._overrides import parse_overrides, sensor_field_types
from pecs.cli._progress import add_progress_arguments, wants_progress
from pecs.config import SensorConfig
from pecs.frame_interpolation import INTERPOLATIONS
from pecs.frames import open_frames
from pecs.sensor import frames_to_file

# The frames fix the sensor size; a different one would be a silent mismatch between what the
# summary says and what the file holds.
_SIZE_FIELDS = ("width", "height")


def register(subparsers: argparse._SubParsersAction) -> None:
    p = add_command(
        subparsers,
        "frames2events",
        help="convert frames (image folder, video, EXR sequence, .npy) to events",
        description="Simulate a DVS sensor on a frame sequence and write its events. The "
        "sensor has the frames' size; resize the frames to change it.",
    )
    p.add_argument(
        "input",
        help="a folder of images or EXR files, a video file, a .npy array (N, H, W), or an "
        "AEDAT4 recording (its APS frames, timed at their exposure midpoints)",
    )
    p.add_argument("-o", "--output", default="events.parquet", help="event file to write")
    p.add_argument(
        "--preset", default="davis346", choices=SensorConfig.PRESETS, help="sensor preset"
    )
    p.add_argument(
        "--config", help="sensor config file (TOML, e.g. from pecs calibrate); replaces --preset"
    )
    timing = p.add_mutually_exclusive_group()
    timing.add_argument(
        "--fps",
        type=number(float, above=0),
        help="frame rate, when the input has no timestamps",
    )
    timing.add_argument("--timestamps", help="text file with one timestamp per line (first column)")
    p.add_argument(
        "--timestamp-unit",
        default="us",
        choices=("us", "ms", "s"),
        help="unit of --timestamps",
    )
    p.add_argument(
        "--channel", help="EXR channel to read (Y if present, else luminance of R, G, B)"
    )
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
        help="override a sensor field, e.g. --set theta_on=0.3 or --set labels=true "
        "(repeat for more)",
    )
    p.add_argument(
        "--input-noise",
        default="auto",
        choices=("auto", "on", "off"),
        help="hold back the frames' own read and shot noise (estimated from the frames; "
        "pecs.input_noise): auto = on for AEDAT4 APS frames and videos, off otherwise",
    )
    p.add_argument(
        "--interpolation",
        default="auto",
        choices=("auto", *INTERPOLATIONS),
        help="light between frames, one of auto, linear, transition, flow: linear in log "
        "(ESIM), transition (each pixel's change a short transition at a random time of the "
        "interval), flow (sub-frames warped along the optical flow: an edge reaches each pixel "
        "when its motion says); auto = transition for AEDAT4 APS frames and videos, linear "
        "otherwise",
    )
    add_progress_arguments(p)
    p.set_defaults(func=run)


def run(args: argparse.Namespace) -> int:
    overrides = parse_overrides(args.set, sensor_field_types())
    frames = open_frames(
        args.input,
        fps=args.fps,
        timestamps=args.timestamps,
        timestamp_unit=args.timestamp_unit,
        channel=args.channel,
        encoding=args.encoding,
    )
    size = (frames.width, frames.height)
    for field, value in zip(_SIZE_FIELDS, size, strict=True):
        if field in overrides and overrides[field] != value:
            raise ValueError(
                f"--set {field}={overrides[field]}: the sensor size is the frames' size "
                f"({size[0]} x {size[1]}); resize the frames to change it"
            )
    overrides.update(width=size[0], height=size[1])
    base = SensorConfig.from_file(args.config) if args.config else SensorConfig.preset(args.preset)
    config = base.replace(**overrides)
    counts = frames_to_file(
        frames,
        args.output,
        config,
        progress=wants_progress(args),
        input_noise={"auto": None, "on": True, "off": False}[args.input_noise],
        interpolation=args.interpolation,
    )
    print(
        f"{counts['events']} events from {counts['frames']} frames "
        f"({config.width} x {config.height}) -> {args.output}"
    )
    return 0
