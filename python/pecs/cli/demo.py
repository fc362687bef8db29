"""`pecs demo [-o OUT]`: the built-in checkerboard scene, briefly, with all outputs."""

from __future__ import annotations

import argparse

# Half the DAVIS346 resolution with twice the pixel pitch: the same field of view and the same
# photocurrent per pixel area, a quarter of the rendering work.
DEMO_SENSOR = {"width": 173, "height": 130, "pixel_pitch_um": 37.0}
DEMO_DURATION_S = 0.1
DEMO_RATE_HZ = 1000.0
DEMO_SPP = 4


def register(subparsers: argparse._SubParsersAction) -> None:
    p = subparsers.add_parser(
        "demo",
        help="simulate the built-in checkerboard scene briefly",
        description="Render the translating checkerboard and write its events and a preview.",
    )
    p.add_argument("-o", "--output", default="pecs-demo", help="output folder (default: pecs-demo)")
    p.add_argument("--quiet", action="store_true", help="no progress bar")
    p.set_defaults(func=run)


def run(args: argparse.Namespace) -> int:
    from pecs.cli.simulate import run_with_progress
    from pecs.render import Simulation

    simulation = Simulation(
        "checkerboard",
        duration_s=DEMO_DURATION_S,
        rate_hz=DEMO_RATE_HZ,
        spp=DEMO_SPP,
        sensor=DEMO_SENSOR,
    )
    summary = run_with_progress(simulation, args.output, quiet=args.quiet)
    print(
        f"{summary.events} events from {summary.frames} frames in {summary.wall_s:.1f} s; "
        f"wrote {', '.join(p.name for p in summary.files.values())} in {summary.out_dir}"
    )
    return 0
