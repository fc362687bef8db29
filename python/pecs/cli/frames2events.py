"""`pecs frames2events INPUT -o events.parquet`: frames on disk to events."""

from __future__ import annotations

import argparse
import sys

from pecs._atomic import names_stdout
from pecs.cli._arguments import add_command, add_sensor_config_argument, number, sensor_config
from pecs.cli._overrides import parse_overrides, sensor_field_types
from pecs.cli._progress import add_progress_arguments, wants_progress
from pecs.config import SensorConfig
from pecs.footage.frame_interpolation import INTERPOLATIONS
from pecs.footage.frames import open_frames
from pecs.footage.input_noise import (
    DEFAULT_DEADBAND_SIGMAS,
    MAX_DEADBAND_SIGMAS,
    MAX_NOISE,
    InputNoise,
    is_camera_footage,
)
from pecs.render.flicker import LAMPS, MAX_FREQUENCY_HZ, WAVEFORMS, Flicker
from pecs.sensor import frames_to_file

# The frames fix the sensor size; a different one would be a silent mismatch between what the
# summary says and what the file holds.
_SIZE_FIELDS = ("width", "height")
# Frames read as a fraction of full scale (0 to 1): 8/16-bit images, videos, AEDAT4 APS frames.
# EXR and float arrays are in the user's own units.
_FULL_SCALE_KINDS = ("images", "video", "aedat4")


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
    p.add_argument(
        "-o",
        "--output",
        default="events.parquet",
        help="event file to write, or - for stdout (text)",
    )
    p.add_argument(
        "--preset", default="davis346", choices=SensorConfig.PRESETS, help="sensor preset"
    )
    add_sensor_config_argument(p, replaces="--preset")
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
        help="hold back the frames' own read and shot noise (estimated from the frames, or "
        "stated with --input-noise-sigma; pecs.footage.input_noise): auto = on for AEDAT4 APS frames "
        "and videos (and when the noise is stated), off otherwise",
    )
    p.add_argument(
        "--input-noise-sigma",
        type=noise_sigma,
        metavar="READ[,GAIN]",
        help="state the frames' noise instead of estimating it (frame units; implies input noise "
        "on): sigma^2 = READ^2 + GAIN * level, e.g. 0.006 (1.5 DN of 255 read noise) or "
        "0.006,0.0004; images, videos and AEDAT4 frames are read as 0 to 1, so their noise at "
        "full scale is at most 1",
    )
    p.add_argument(
        "--deadband-sigmas",
        type=deadband_sigmas,
        metavar="K",
        help="a pixel's input is held until a frame moves more than K sigma of the frames' noise "
        f"(stated or estimated) from it, K from 0 to {MAX_DEADBAND_SIGMAS:g}; implies input "
        f"noise on (default: {DEFAULT_DEADBAND_SIGMAS:g})",
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
    p.add_argument(
        "--exposure",
        type=exposure,
        default="none",
        metavar="none|auto|US",
        help="what each frame's exposure averaged the light over, undone before the sensor sees "
        "it (pecs.footage.exposure): none (the frames are the light at their times; the "
        "default), auto (an AEDAT4 recording's own exposures; nothing for other inputs), or a "
        "number of microseconds, at most the frame interval. A 50 %% exposure costs about 3 %% "
        "of the events of moving edges (docs/footage.md)",
    )
    p.add_argument(
        "--zero-time",
        action="store_true",
        help="start the event times at 0 (subtract the first event's t): for EVT3, EVT2, DAT "
        "and v2e, whose clock starts at 0, from an AEDAT4 recording's absolute (Unix) times",
    )
    _add_flicker_arguments(p)
    add_progress_arguments(p)
    p.set_defaults(func=run)


def _add_flicker_arguments(p: argparse.ArgumentParser) -> None:
    """--flicker-hz with --flicker-depth or --flicker-lamp: mains flicker on the frames' light."""
    p.add_argument(
        "--flicker-hz",
        type=flicker_hz,
        metavar="HZ",
        help="light the frames with a lamp on mains flickering at HZ: twice the mains "
        "frequency, 100 on 50 Hz mains, 120 on 60 Hz (fed as sub-frames, 20 a period: "
        "2000 frames a second at 100 Hz); with --flicker-depth or --flicker-lamp",
    )
    p.add_argument(
        "--flicker-depth",
        type=flicker_depth,
        metavar="D",
        help="modulation depth of the flicker, (max - min) / (max + min) of the light, 0 to 1 "
        "(percent flicker / 100)",
    )
    p.add_argument(
        "--flicker-lamp",
        choices=tuple(LAMPS),
        help="a kind of lamp in place of --flicker-depth and --flicker-waveform: "
        + "; ".join(f"{name} {lamp.depth:g}" for name, lamp in LAMPS.items()),
    )
    p.add_argument(
        "--flicker-waveform",
        choices=WAVEFORMS,
        help="shape of the flicker: sine (sin^2 of the mains, the default) or rectified "
        "(|sin| of the mains, as a magnetic ballast or a capacitor-less LED driver)",
    )


def flicker_hz(text: str) -> float:
    """HZ: a positive number of Hz, at most MAX_FREQUENCY_HZ (20 sub-frames a period, 1 us apart)."""
    value = _FLICKER_HZ(text)
    if value > MAX_FREQUENCY_HZ:
        raise argparse.ArgumentTypeError(
            f"{text}: at most {MAX_FREQUENCY_HZ:g} Hz (20 sub-frames a period, whole microseconds)"
        )
    return value


def flicker_depth(text: str) -> float:
    """D: a modulation depth from 0 (steady) to 1 (the light goes out every period)."""
    value = _NOISE_NUMBER(text)
    if value > 1.0:
        raise argparse.ArgumentTypeError(
            f"{text}: expected a depth from 0 (steady) to 1 (the light goes out every period)"
        )
    return value


_FLICKER_HZ = number(float, above=0)


def flicker(args: argparse.Namespace) -> Flicker | None:
    """The Flicker of --flicker-hz, --flicker-depth or --flicker-lamp, --flicker-waveform."""
    shape = {
        "--flicker-depth": args.flicker_depth,
        "--flicker-waveform": args.flicker_waveform,
        "--flicker-lamp": args.flicker_lamp,
    }
    given = [option for option, value in shape.items() if value is not None]
    if args.flicker_hz is None:
        if given:
            raise ValueError(f"{given[0]} needs --flicker-hz HZ (100 on 50 Hz mains, 120 on 60 Hz)")
        return None
    if args.flicker_lamp is not None:
        if len(given) > 1:
            raise ValueError(f"--flicker-lamp sets the depth and waveform; leave out {given[0]}")
        return Flicker.lamp(args.flicker_lamp, args.flicker_hz)
    if args.flicker_depth is None:
        raise ValueError("--flicker-hz needs --flicker-depth D (0 to 1) or --flicker-lamp NAME")
    return Flicker(args.flicker_hz, args.flicker_depth, args.flicker_waveform or "sine")


def run(args: argparse.Namespace) -> int:
    overrides = parse_overrides(args.set, sensor_field_types())
    noise, deadband_sigmas = input_noise(args)  # refused before any frame is read
    lamp = flicker(args)
    base = sensor_config(args) or SensorConfig.preset(args.preset)
    frames = open_frames(
        args.input,
        fps=args.fps,
        timestamps=args.timestamps,
        timestamp_unit=args.timestamp_unit,
        channel=args.channel,
        encoding=args.encoding,
        cfa=overrides.get("cfa", base.cfa),  # a colour sensor takes each pixel's channel
    )
    _check_noise_scale(args.input_noise_sigma, frames.kind)
    size = (frames.width, frames.height)
    for field, value in zip(_SIZE_FIELDS, size, strict=True):
        if field in overrides and overrides[field] != value:
            raise ValueError(
                f"--set {field}={overrides[field]}: the sensor size is the frames' size "
                f"({size[0]} x {size[1]}); resize the frames to change it"
            )
    overrides.update(width=size[0], height=size[1])
    config = base.replace(**overrides)
    counts = frames_to_file(
        frames,
        args.output,
        config,
        progress=wants_progress(args),
        input_noise=noise,
        deadband_sigmas=deadband_sigmas,
        interpolation=args.interpolation,
        zero_time=args.zero_time,
        flicker=lamp,
        exposure_us=args.exposure,
    )
    out = sys.stderr if names_stdout(args.output) else sys.stdout  # events on stdout: beside
    print(
        f"{counts['events']} events from {counts['frames']} frames "
        f"({config.width} x {config.height}) -> {args.output}",
        file=out,
    )
    if "readout_events_in" in counts:
        print(readout_summary(counts), file=out)
    return 0


def readout_summary(counts: dict[str, int]) -> str:
    """One line of what the sensor's readout did (docs/readout.md)."""
    made = counts["readout_events_in"]
    delayed = counts["readout_delayed"]
    mean_us = counts["readout_delay_total_us"] / delayed if delayed else 0.0
    return (
        f"readout: {made} events made, {counts['readout_dropped']} dropped by a full queue, "
        f"{counts['readout_erc_dropped']} by the rate controller; {delayed} delayed "
        f"(mean {mean_us:.1f} us, max {counts['readout_delay_max_us']} us)"
    )


def exposure(text: str) -> str | float:
    """none, auto, or a number of microseconds >= 0 (checked against the frame interval when
    the frames are read)."""
    if text in ("none", "auto"):
        return text
    try:
        return _EXPOSURE_US(text)
    except argparse.ArgumentTypeError:
        raise argparse.ArgumentTypeError(
            f"{text}: expected none, auto or a number of microseconds >= 0"
        ) from None


_EXPOSURE_US = number(float, at_least=0)


def noise_sigma(text: str) -> tuple[float, float]:
    """READ[,GAIN] (frame units): the read noise sigma and the shot-noise gain, each finite,
    >= 0 and within float32's range (the frames' type); GAIN defaults to 0 (read noise alone)."""
    parts = text.split(",")
    if len(parts) > 2:
        raise argparse.ArgumentTypeError(f"{text}: expected READ or READ,GAIN, e.g. 0.006,0.0004")
    values = [_NOISE_NUMBER(part) for part in parts]
    if max(values) > MAX_NOISE:
        raise argparse.ArgumentTypeError(
            f"{text}: past float32's range ({MAX_NOISE:.3g}), the frames' type"
        )
    return values[0], values[1] if len(values) == 2 else 0.0


_NOISE_NUMBER = number(float, at_least=0)


def deadband_sigmas(text: str) -> float:
    """K: a number of sigmas from 0 to MAX_DEADBAND_SIGMAS."""
    value = _NOISE_NUMBER(text)
    if value > MAX_DEADBAND_SIGMAS:
        raise argparse.ArgumentTypeError(
            f"{text}: expected at most {MAX_DEADBAND_SIGMAS:g} sigma (noise alone never leaves "
            "a band of 8; a wider one holds back real changes)"
        )
    return value


def _check_noise_scale(stated: tuple[float, float] | None, kind: str) -> None:
    """A stated noise that is more than the full scale of frames read as 0 to 1 at full light
    (sigma^2 = READ^2 + GAIN) is refused: every change of such frames would be held back."""
    if stated is None or kind not in _FULL_SCALE_KINDS:
        return
    read, gain = stated
    if read * read + gain > 1.0:
        source = "camera footage" if is_camera_footage(kind) else "8/16-bit images"
        raise ValueError(
            f"--input-noise-sigma {read:g},{gain:g}: a noise of more than the frames' full "
            f"scale ({source} is read as 0 to 1; sigma^2 = READ^2 + GAIN at 1 must be <= 1)"
        )


def input_noise(args: argparse.Namespace) -> tuple[InputNoise | bool | None, float | None]:
    """What frames_to_file takes from --input-noise, --input-noise-sigma, --deadband-sigmas (its
    input_noise and deadband_sigmas): a stated noise turns the deadband on with those numbers."""
    if args.input_noise_sigma is None:
        if args.deadband_sigmas is not None and args.input_noise == "off":
            raise ValueError(
                "--deadband-sigmas holds back the frames' noise; it cannot go with "
                "--input-noise off"
            )
        return {"auto": None, "on": True, "off": False}[args.input_noise], args.deadband_sigmas
    if args.input_noise == "off":
        raise ValueError(
            "--input-noise-sigma states the frames' noise to hold back; it cannot go with "
            "--input-noise off"
        )
    read, gain = args.input_noise_sigma
    k = DEFAULT_DEADBAND_SIGMAS if args.deadband_sigmas is None else args.deadband_sigmas
    return InputNoise(read, gain, k), None
