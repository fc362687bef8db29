"""`pecs simulate SCENE.toml -o OUT`: render an animated scene and write its events."""

from __future__ import annotations

import argparse
from typing import Any

from pecs.cli._arguments import (
    add_command,
    add_sensor_config_argument,
    number,
    plain_default,
    sensor_config,
)
from pecs.cli._overrides import parse_overrides, sensor_field_types
from pecs.cli._progress import add_progress_arguments, wants_progress
from pecs.config import SensorConfig
from pecs.ground_truth.imu_noise import IMU_CAMERAS, IMU_MODELS
from pecs.ground_truth.layout import KINDS
from pecs.render.limits import SettingError
from pecs.render.simulation import DEFAULT_IMU_RATE_HZ


def register(subparsers: argparse._SubParsersAction) -> None:
    p = add_command(
        subparsers,
        "simulate",
        help="render an animated 3D scene (TOML scene file) into events",
        description="Render a scene spectrally with Mitsuba and simulate the event sensor on it. "
        "The output folder is built beside its target and takes its place when complete; an "
        "existing output folder is replaced only if it holds nothing but pecs outputs.",
    )
    p.add_argument("scene", help="scene file (.toml) or the name of a built-in scene")
    p.add_argument("-o", "--output", default="pecs-out", help="output folder")
    p.add_argument(
        "--duration", type=number(float, above=0), help="simulated seconds (the scene's if unset)"
    )
    p.add_argument(
        "--spp", type=number(int, at_least=1), help="samples per pixel (the scene's if unset)"
    )
    p.add_argument(
        "--preset", choices=SensorConfig.PRESETS, help="sensor preset (the scene's if unset)"
    )
    p.add_argument(
        "--rate", type=number(float, above=0), help="fixed frame rate in Hz (replaces the scene's)"
    )
    add_sensor_config_argument(p, replaces="the scene's sensor")
    p.add_argument("--seed", type=number(int, at_least=0), help="render and sensor seed")
    p.add_argument(
        "--set",
        action="append",
        default=[],
        metavar="FIELD=VALUE",
        help="override a sensor field or the film (width, height, pixel_pitch_um, fill_factor), "
        "e.g. --set width=173 (repeat for more)",
    )
    p.add_argument("--frames", action="store_true", help="also write EXR photocurrent frames")
    p.add_argument(
        "--depth",
        action="store_true",
        help="also write EXR range (metres along each pixel's ray) per frame",
    )
    p.add_argument(
        "--ground-truth",
        metavar="KINDS",
        help="write ground truth into OUT/ground_truth: a comma list of "
        f"{','.join(KINDS)}, or all (events: flow and instance columns in events.parquet)",
    )
    p.add_argument(
        "--imu-rate",
        type=number(float, above=0),
        default=DEFAULT_IMU_RATE_HZ,
        help="IMU samples per second of --ground-truth imu",
    )
    p.add_argument(
        "--imu-model",
        choices=list(IMU_MODELS),
        help="also write what a real IMU reads (noise, bias, its datasheet's; next to the ideal "
        "IMU of --ground-truth imu): "
        + ", ".join(f"{name} ({camera}'s)" for name, camera in IMU_CAMERAS.items())
        + "; replaces the scene's [imu] model, seeded by --seed",
    )
    add_progress_arguments(p)
    p.set_defaults(func=run)


def run(args: argparse.Namespace) -> int:
    from pecs.render import Simulation
    from pecs.render.simulation import config_overrides

    types = sensor_field_types(pixel_pitch_um="float", fill_factor="float")
    sensor = parse_overrides(args.set, types)
    preset = args.preset
    config = sensor_config(args)
    if config is not None:
        preset = preset or config.known_preset
        from_file = config_overrides(config)
        if args.seed is not None:  # --seed is the sensor's seed too, not only the render's
            from_file.pop("seed")
        sensor = {**from_file, **sensor}
    try:
        simulation = Simulation(
            args.scene,
            duration_s=args.duration,
            spp=args.spp,
            preset=preset,
            seed=args.seed,
            rate_hz=args.rate,
            sensor=sensor or None,
            write_frames=args.frames or None,
            write_depth=args.depth or None,
            ground_truth=args.ground_truth,
            imu_rate_hz=args.imu_rate,
            imu_model=args.imu_model,
        )
    except SettingError as error:
        raise ValueError(_as_option(error, args)) from None
    summary = run_with_progress(simulation, args.output, show=wants_progress(args))
    print(
        f"{summary.events} events from {summary.frames} frames "
        f"({summary.simulated_s:g} s simulated in {summary.wall_s:.1f} s) -> {summary.out_dir}"
    )
    return 0


# Simulation's keyword arguments as this command's options.
_OPTIONS = {
    "duration_s": "--duration",
    "rate_hz": "--rate",
    "spp": "--spp",
    "imu_rate_hz": "--imu-rate",
    "imu_model": "--imu-model",
    "seed": "--seed",
    "preset": "--preset",
}


def _as_option(error: SettingError, args: argparse.Namespace) -> str:
    """The API's message about one of its settings, naming the option that gave it."""
    if error.source is not None:  # the scene file's value: the message names its key
        return str(error)
    if error.setting in _OPTIONS:
        return f"{_OPTIONS[error.setting]} {plain_default(error.value)}: {error.reason}"
    typed = {item.partition("=")[0].strip(): item for item in args.set}
    if error.setting == "sensor" and error.field in typed:
        reason = error.reason.removeprefix(f"{error.field}: ")
        return f"--set {typed[error.field]}: {reason}"
    if error.setting == "sensor" and args.config:  # with the scene's preset and the --set ones
        return f"--config {args.config}: {error.reason}"
    return str(error)


def run_with_progress(simulation: Any, output: str, show: bool) -> Any:
    """`simulation.run(output)` with a tqdm bar over simulated milliseconds when `show`."""
    if not show:
        return simulation.run(output)
    import sys

    from tqdm import tqdm

    total_ms = simulation.duration_us / 1000.0
    with tqdm(
        total=total_ms, unit="ms", unit_scale=False, dynamic_ncols=True, file=sys.stderr
    ) as bar:

        def progress(frame: Any, events: int) -> None:
            bar.update(frame.t_us / 1000.0 - bar.n)
            bar.set_postfix(frames=str(frame.index + 1), events=str(events), refresh=False)

        return simulation.run(output, progress=progress)
