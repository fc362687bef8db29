"""`pecs compare A B`: the PECS chamfer and Gaussian distances between two event files."""

from __future__ import annotations

import argparse

from pecs.cli._arguments import add_command, number
from pecs.metrics import NORMALIZATIONS, PECS_SIGMA, POLARITIES, compare


def register(subparsers: argparse._SubParsersAction) -> None:
    parser = add_command(
        subparsers,
        "compare",
        help="chamfer and Gaussian distances between two event streams",
        description="Compare two event files with the spatiotemporal metrics of PECS "
        "(lower is closer; identical streams give 0).",
    )
    parser.add_argument("a", help="first event file")
    parser.add_argument("b", help="second event file")
    window = parser.add_mutually_exclusive_group()
    window.add_argument(
        "--first-us",
        type=number(int, above=0),
        metavar="N",
        help="shift each stream to start at 0 and keep its first N microseconds (paper protocol)",
    )
    window.add_argument(
        "--window-us",
        type=int,
        nargs=2,
        metavar=("START", "END"),
        help="keep events with START <= t < END (original times)",
    )
    parser.add_argument(
        "--normalize",
        choices=NORMALIZATIONS,
        default="pecs",
        help="pecs: per-stream min-max (the paper; one far event rescales a stream); sensor: by "
        "sensor size and window length (recommended)",
    )
    parser.add_argument(
        "--polarity",
        choices=POLARITIES,
        default="coordinate",
        help="coordinate: polarity is an axis; separate: match same polarity only",
    )
    parser.add_argument(
        "--sigma", type=number(float, above=0), default=PECS_SIGMA, help="Gaussian distance sigma"
    )
    parser.add_argument(
        "--sensor-size",
        type=number(int, above=0),
        nargs=2,
        metavar=("WIDTH", "HEIGHT"),
        help="sensor size for --normalize sensor when the files do not record it",
    )
    parser.add_argument("--json", action="store_true", help="print the result as JSON")
    parser.set_defaults(func=run)


def run(args: argparse.Namespace) -> int:
    result = compare(
        args.a,
        args.b,
        sigma=args.sigma,
        first_us=args.first_us,
        window_us=tuple(args.window_us) if args.window_us else None,
        normalize=args.normalize,
        polarity=args.polarity,
        sensor_size=tuple(args.sensor_size) if args.sensor_size else None,
    )
    if args.json:
        print(result.to_json())
    else:
        print(f"chamfer   {result.chamfer:.6g}")
        print(f"gaussian  {result.gaussian:.6g}")
        print(f"events    a {result.events_a}, b {result.events_b}")
    return 0
