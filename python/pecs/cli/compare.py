"""`pecs compare A B`: the PECS chamfer and Gaussian distances between two event files."""

from __future__ import annotations

import argparse
import re

import pecs.io
from pecs.cli._arguments import add_command, number
from pecs.events import sensor_size
from pecs.metrics import NORMALIZATIONS, PECS_SIGMA, POLARITIES, compare

# The API's words in its messages, as the options a user of this command types them.
_CLI_WORDS = (
    ("sensor_size=(width, height)", "--sensor-size WIDTH HEIGHT"),
    ("the right sensor_size", "the right --sensor-size WIDTH HEIGHT"),
    ("normalize='sensor'", "--normalize sensor"),
    ("window_us=(start, end)", "--window-us START END"),
)


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
    _check_window(args)
    _check_sizes(args)
    try:
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
    except ValueError as error:
        raise ValueError(_in_cli_words(str(error), args)) from None
    if args.json:
        print(result.to_json())
    else:
        print(f"chamfer   {result.chamfer:.6g}")
        print(f"gaussian  {result.gaussian:.6g}")
        print(f"events    a {result.events_a}, b {result.events_b}")
    return 0


def _check_window(args: argparse.Namespace) -> None:
    if args.window_us and args.window_us[1] <= args.window_us[0]:
        start, end = args.window_us
        raise ValueError(f"--window-us {start} {end}: END must be after START")


def _check_sizes(args: argparse.Namespace) -> None:
    """--normalize sensor needs one sensor size: the files' own, or --sensor-size."""
    if args.normalize != "sensor" or args.sensor_size:
        return
    sizes = {path: _stated_size(path) for path in (args.a, args.b)}
    known = {size for size in sizes.values() if size is not None}
    if len(known) > 1:
        (a, size_a), (b, size_b) = sizes.items()
        raise ValueError(
            f"{a} is from a {size_a[0]} x {size_a[1]} sensor and {b} from a {size_b[0]} x "
            f"{size_b[1]} one: give --sensor-size WIDTH HEIGHT to compare them anyway"
        )
    if not known:
        raise ValueError(
            "--normalize sensor needs the sensor size, which neither file records: give "
            "--sensor-size WIDTH HEIGHT"
        )


def _stated_size(path: str) -> tuple[int, int] | None:
    """The sensor size a file records (its first batch's schema), None if it says none."""
    first = next(iter(pecs.io.iter_events(path, batch_size=1024)), None)
    return sensor_size(first.schema) if first is not None else None


def _in_cli_words(message: str, args: argparse.Namespace) -> str:
    """An API message with its argument names as this command's options, and its streams "a"
    and "b" as the files given."""
    for api, cli in _CLI_WORDS:
        message = message.replace(api, cli)
    files = {"a": args.a, "b": args.b}
    return re.sub(r"\bstream ([ab])\b", lambda match: files[match.group(1)], message)
