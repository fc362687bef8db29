"""`pecs simulate SCENE.toml -o OUT`: render an animated scene and write its events."""

from __future__ import annotations

import argparse
from typing import Any

from pecs.cli.frames2events import parse_overrides
from pecs.config import SensorConfig


def register(subparsers: argparse._SubParsersAction) -> None:
    p = subparsers.add_parser(
        "simulate",
        help="render an animated 3D scene (TOML scene file) into events",
        description="Render a scene spectrally with Mitsuba and simulate the event sensor on it.",
    )
    p.add_argument("scene", help="scene file (.toml) or the name of a built-in scene")
    p.add_argument("-o", "--output", default="pecs-out", help="output folder (default: pecs-out)")
    p.add_argument("--duration", type=float, help="simulated seconds (default: the scene's)")
    p.add_argument("--spp", type=int, help="samples per pixel (default: the scene's)")
    p.add_argument("--preset", choices=SensorConfig.PRESETS, help="sensor preset")
    p.add_argument("--rate", type=float, help="fixed frame rate in Hz (replaces the scene's)")
    p.add_argument("--seed", type=int, help="render and sensor seed")
    p.add_argument(
        "--set",
        action="append",
        default=[],
        metavar="FIELD=VALUE",
        help="override a sensor field or the film size, e.g. --set width=173",
    )
    p.add_argument("--frames", action="store_true", help="also write EXR photocurrent frames")
    p.add_argument("--depth", action="store_true", help="also write EXR depth per frame")
    p.add_argument("--quiet", action="store_true", help="no progress bar")
    p.set_defaults(func=run)


def run(args: argparse.Namespace) -> int:
    from pecs.render import Simulation

    simulation = Simulation(
        args.scene,
        duration_s=args.duration,
        spp=args.spp,
        preset=args.preset,
        seed=args.seed,
        rate_hz=args.rate,
        sensor=parse_overrides(args.set) or None,
        write_frames=args.frames or None,
        write_depth=args.depth or None,
    )
    summary = run_with_progress(simulation, args.output, quiet=args.quiet)
    print(
        f"{summary.events} events from {summary.frames} frames "
        f"({summary.simulated_s:g} s simulated in {summary.wall_s:.1f} s) -> {summary.out_dir}"
    )
    return 0


def run_with_progress(simulation: Any, output: str, quiet: bool = False) -> Any:
    """`simulation.run(output)` with a tqdm bar over simulated milliseconds."""
    if quiet:
        return simulation.run(output)
    from tqdm import tqdm

    total_ms = simulation.duration_us / 1000.0
    with tqdm(total=total_ms, unit="ms", unit_scale=False, dynamic_ncols=True) as bar:

        def progress(frame: Any, events: int) -> None:
            bar.update(frame.t_us / 1000.0 - bar.n)
            bar.set_postfix(frames=str(frame.index + 1), events=str(events), refresh=False)

        return simulation.run(output, progress=progress)
