"""`pecs calibrate REC.aedat4 --fit-ms START:END -o sensor.toml`: fit a sensor to a recording
(`pecs.calibrate`); `pecs calibrate --noise-only static.aedat4 -o sensor.toml`: background
activity from a static scene's events alone (`pecs.calibrate_noise`)."""

from __future__ import annotations

import argparse
import tempfile
from pathlib import Path

from pecs.calibration.background_fit import calibrate_noise
from pecs.calibration.fit import DEFAULT_FIT, PARAMETERS, Recording, calibrate, check_budget
from pecs.cli._arguments import add_command, add_sensor_config_argument, number, sensor_config
from pecs.config import SensorConfig
from pecs.events import sensor_size
from pecs.footage.frame_interpolation import INTERPOLATIONS
from pecs.io import read_events


def register(subparsers: argparse._SubParsersAction) -> None:
    p = add_command(
        subparsers,
        "calibrate",
        help="fit sensor parameters to a real recording; write a sensor config file",
        description="Fit sensor parameters so that pecs, fed the APS frames of an AEDAT4 "
        "recording, gives events like the recorded ones; or, with --noise-only, fit background "
        "activity to the events of a static scene. Writes a TOML sensor file that "
        "`pecs frames2events --config`, `pecs simulate --config` and SensorConfig.from_file read.",
    )
    p.add_argument(
        "recording", help="AEDAT4 with APS frames and events (--noise-only: any event file)"
    )
    p.add_argument("-o", "--output", required=True, help="sensor config file to write (.toml)")
    p.add_argument(
        "--fit-ms",
        type=span,
        help="START:END, ms from the first APS frame; the fit reads the events of this span "
        "and the frames inside it plus the one bracketing each end, nothing else",
    )
    p.add_argument(
        "--holdout-ms",
        type=holdout_span,
        help="START:END scored but not fitted, or none (default: the rest of the recording, "
        "before and after the fitted span)",
    )
    p.add_argument(
        "--preset", default="davis346", choices=SensorConfig.PRESETS, help="starting sensor"
    )
    add_sensor_config_argument(p, replaces="--preset as the starting sensor")
    p.add_argument(
        "--parameters",
        default=",".join(DEFAULT_FIT),
        help=f"comma-separated fields to fit, of {', '.join(PARAMETERS)}",
    )
    p.add_argument(
        "--max-evaluations",
        type=number(int, at_least=1),
        default=300,
        help="most objective evaluations of the search, per light model searched; at least "
        "one a fitted parameter, plus one (the profile's come on top)",
    )
    p.add_argument("--seed", type=number(int, at_least=0), default=0, help="the simulations' seed")
    p.add_argument(
        "--interpolation",
        default="auto",
        choices=("auto", *INTERPOLATIONS),
        help="light between frames, as frames2events takes it: the interpolation the fitted "
        "file will be used with (auto: for camera footage the fit chooses between transition "
        "and flow, each searched in full, and says which; the guarantee is against the preset "
        "as frames2events runs it by default either way)",
    )
    p.add_argument(
        "--exposure",
        default="none",
        choices=("none", "auto"),
        help="undo the APS frames' recorded exposures, as frames2events --exposure auto does "
        "(none: the frames are the light at their times)",
    )
    p.add_argument(
        "--no-profile",
        action="store_true",
        help="skip the profile that says which fitted parameters the data pinned down "
        "(1 + 4 evaluations a parameter, after the fit)",
    )
    p.add_argument("--report", metavar="DIR", help="write report.md and calibration.png here")
    p.add_argument(
        "--noise-only",
        action="store_true",
        help="fit leak, shot and hot-pixel noise to a static scene",
    )
    p.add_argument(
        "--photocurrent",
        type=number(float, at_least=0),
        help="--noise-only: the static scene's frame value (the photocurrent at the sensor's "
        "white_lux, from --config or --preset), to convert its shot-noise rate to the law's "
        "dark rate (default: the scene is taken as dark)",
    )
    p.add_argument("--quiet", action="store_true", help="no progress lines (on stderr)")
    p.set_defaults(func=run)


def span(text: str) -> tuple[float, float]:
    """START:END in ms."""
    start, sep, end = text.partition(":")
    try:
        if not sep:
            raise ValueError
        return float(start), float(end)
    except ValueError:
        raise argparse.ArgumentTypeError(
            f"{text!r}: expected START:END in ms, e.g. 0:1160"
        ) from None


def holdout_span(text: str) -> tuple[float, float] | str:
    """START:END in ms, or none."""
    return "none" if text.strip().lower() == "none" else span(text)


def run(args: argparse.Namespace) -> int:
    # The files written at the end, checked before a fit of minutes, not after it.
    check_writable(args.output, "-o")
    if args.report and not args.noise_only:
        check_writable(args.report, "--report", folder=True)
    return run_noise(args) if args.noise_only else run_fit(args)


def check_writable(path: str, option: str, *, folder: bool = False) -> None:
    """A ValueError naming `option` unless `path` can be written as a file (or, with `folder`,
    made a folder): its nearest existing ancestor is a folder that takes a new file."""
    target = Path(path)
    if target.is_dir() and not folder:
        raise ValueError(f"{option} {path}: is a folder; give a file name, e.g. sensor.toml")
    if target.exists() and not target.is_dir() and folder:
        raise ValueError(f"{option} {path}: is a file; give a folder")
    ancestor = target if folder and target.is_dir() else target.parent
    while not ancestor.exists() and ancestor != ancestor.parent:
        ancestor = ancestor.parent
    if not ancestor.is_dir():
        raise ValueError(f"{option} {path}: {ancestor} is a file, not a folder")
    try:
        with tempfile.TemporaryFile(dir=ancestor):
            pass
    except OSError as error:
        raise ValueError(
            f"{option} {path}: cannot write in {ancestor} ({error.strerror})"
        ) from None


def holdout_ms(given: tuple[float, float] | str | None) -> tuple[float, float] | str | None:
    """--holdout-ms as `calibrate` takes it: absent is "rest", none is None."""
    if given is None:
        return "rest"
    return None if given == "none" else given


def run_fit(args: argparse.Namespace) -> int:
    if args.fit_ms is None:
        raise ValueError("--fit-ms START:END is required (or --noise-only)")
    parameters = [name.strip() for name in args.parameters.split(",") if name.strip()]
    for name in parameters:
        if name not in PARAMETERS:
            raise ValueError(
                f"--parameters: {name} cannot be fitted; choose from {', '.join(PARAMETERS)}"
            )
    check_budget(len(parameters), args.max_evaluations, "--max-evaluations")
    start = sensor_config(args)
    recording = Recording.load(
        args.recording, interpolation=args.interpolation, exposure=args.exposure
    )
    result = calibrate(
        recording,
        args.fit_ms,
        holdout_ms=holdout_ms(args.holdout_ms),
        preset=args.preset,
        start=start,
        parameters=parameters,
        max_evaluations=args.max_evaluations,
        seed=args.seed,
        progress=not args.quiet,
        profile=not args.no_profile,
    )
    result.config.to_file(args.output)
    from pecs.calibration.report import markdown, write_report

    print(markdown(result))
    if args.report:
        for path in write_report(result, recording, args.report):
            print(f"report: {path}")
    print(f"sensor -> {args.output} (use with --interpolation {result.interpolation})")
    return 0


def run_noise(args: argparse.Namespace) -> int:
    base = sensor_config(args) or SensorConfig.preset(args.preset)
    events = read_events(args.recording)
    width, height = sensor_size(events.schema) or (base.width, base.height)
    fit = calibrate_noise(
        events,
        sensor_size=(width, height),
        photocurrent=args.photocurrent,
        dark_current=base.dark_current,
        white_lux=base.white_lux,
        shot_light_exponent=base.shot_light_exponent,
    )
    fit.config(base.replace(width=width, height=height)).to_file(args.output)
    print(
        f"{fit.duration_s:.3f} s, {fit.pixels} pixels: leak {fit.leak_rate_hz:.4g} Hz "
        f"(spread {fit.leak_spread_decades:.3g} decades), shot {fit.scene_shot_rate_hz:.4g} Hz in "
        f"this scene ({fit.shot_rate_hz:.4g} Hz dark), hot pixels {fit.hot_pixel_fraction:.3g} "
        f"at {fit.hot_pixel_rate_hz:.4g} Hz -> {args.output}"
    )
    return 0
