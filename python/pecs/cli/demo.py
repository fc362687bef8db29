"""`pecs demo [-o OUT]`: the built-in checkerboard scene, briefly, with all outputs."""

from __future__ import annotations

import argparse
from typing import Any

from pecs.cli._arguments import add_command, add_sensor_config_argument, sensor_config
from pecs.cli._progress import add_progress_arguments, wants_progress

# The scene's DAVIS346 at full resolution, 0.1 s at 1000 frames per second and 4 spp: tens of
# seconds (38 s measured on a busy 2-core machine, most of it rendering 101 spectral frames),
# well inside the 3-minute budget of a fresh clone.
DEMO_DURATION_S = 0.1
DEMO_RATE_HZ = 1000.0
DEMO_SPP = 4


def register(subparsers: argparse._SubParsersAction) -> None:
    p = add_command(
        subparsers,
        "demo",
        help="simulate the built-in checkerboard scene briefly",
        description="Render the translating checkerboard (0.1 s at 1000 frames per second, "
        "4 samples per pixel, a DAVIS346 or the sensor of --config) and write its events, "
        "ground truth and a preview.",
    )
    p.add_argument("-o", "--output", default="pecs-demo", help="output folder")
    add_sensor_config_argument(p, replaces="the scene's DAVIS346 (its size is the film's)")
    add_progress_arguments(p)
    p.set_defaults(func=run)


def demo_simulation(args: argparse.Namespace) -> Any:
    """The demo's `pecs.Simulation`: the checkerboard, briefly, with the sensor of --config."""
    from pecs.render import Simulation

    return Simulation(
        "checkerboard",
        duration_s=DEMO_DURATION_S,
        rate_hz=DEMO_RATE_HZ,
        spp=DEMO_SPP,
        sensor=sensor_config(args),
    )


def run(args: argparse.Namespace) -> int:
    from pecs.cli.simulate import run_with_progress

    simulation = demo_simulation(args)
    summary = run_with_progress(simulation, args.output, show=wants_progress(args))
    print(
        f"{summary.events} events from {summary.frames} frames in {summary.wall_s:.1f} s; "
        f"wrote {', '.join(p.name for p in summary.files.values())} in {summary.out_dir}"
    )
    return 0
