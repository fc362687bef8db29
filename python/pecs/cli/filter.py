"""`pecs filter IN -o OUT`: the on-chip filters of Prophesee's sensors (pecs.filters) on an event
file, streaming: event rate controller, anti-flicker, STC or trail."""

from __future__ import annotations

import argparse
import sys

from pecs.cli._arguments import add_command, number
from pecs.cli.convert import add_stream_arguments, copy_events
from pecs.filters import (
    AFK_MAX_HZ,
    AFK_MAX_THRESHOLD,
    AFK_MIN_HZ,
    AFK_MODES,
    ERC_PERIOD_US,
    STC_MODES,
    TRAIL_MAX_MS,
    TRAIL_MIN_MS,
    EventFilter,
    FilterSettings,
)


def register(subparsers: argparse._SubParsersAction) -> None:
    parser = add_command(
        subparsers,
        "filter",
        help="run a sensor's on-chip filters (rate controller, anti-flicker, STC/trail) on "
        "an event file",
        description="Run the on-chip event filters of Prophesee's sensors (the IMX636's ESP) on "
        "an event file of any camera or simulation, streaming: the anti-flicker filter, the "
        "event trail filter (STC or trail) and the event rate controller, in that order. Give "
        "at least one. The rules and their sources: docs/filters.md.",
    )
    parser.add_argument("input", help="event file to read (sorted by t)")
    parser.add_argument(
        "-o",
        "--output",
        required=True,
        help="event file to write (format from its suffix), or - for stdout",
    )
    parser.add_argument(
        "--erc",
        metavar="RATE",
        type=number(float, above=0),
        help="event rate controller: at most RATE events/s, counted over 200 us periods "
        "(the EVK4's default is 50e6; at least 5000, one event a period)",
    )
    parser.add_argument(
        "--stc",
        metavar="MS",
        type=_threshold_ms,
        help=f"STC filter, bursts separated by MS whole milliseconds ({TRAIL_MIN_MS}-"
        f"{TRAIL_MAX_MS}): keeps the second event of each burst, so isolated events go",
    )
    parser.add_argument(
        "--stc-mode",
        choices=STC_MODES,
        default="cut-trail",
        help="cut-trail: only the second event of a burst; keep-trail: every event of a burst "
        "but its first",
    )
    parser.add_argument(
        "--trail",
        metavar="MS",
        type=_threshold_ms,
        help=f"trail filter, bursts separated by MS whole milliseconds ({TRAIL_MIN_MS}-"
        f"{TRAIL_MAX_MS}): keeps the first event of each burst (not with --stc: the chip runs "
        "one of the two)",
    )
    parser.add_argument(
        "--afk",
        metavar="LO-HI",
        type=_band,
        help=f"anti-flicker filter over 4 x 4 pixel regions, band LO-HI in whole Hz "
        f"({AFK_MIN_HZ} <= LO < HI <= {AFK_MAX_HZ}), e.g. 90-130 for 100 and 120 Hz mains light",
    )
    parser.add_argument(
        "--afk-mode",
        choices=AFK_MODES,
        default="band-stop",
        help="band-stop drops the events of regions flickering in the band; band-pass keeps "
        "only those",
    )
    parser.add_argument(
        "--afk-thresholds",
        nargs=2,
        metavar=("START", "STOP"),
        type=number(int, at_least=0, below=AFK_MAX_THRESHOLD + 1),
        default=[6, 4],
        help=f"anti-flicker hysteresis: a region counts as flickering from START periods in the "
        f"band and stops at STOP (0 <= STOP < START <= {AFK_MAX_THRESHOLD})",
    )
    add_stream_arguments(parser)
    parser.set_defaults(func=run)


def _threshold_ms(text: str) -> int:
    """A threshold in whole milliseconds, 1-100, as the chip takes it."""
    wanted = f"a whole number of milliseconds, {TRAIL_MIN_MS} to {TRAIL_MAX_MS}"
    try:
        value = float(text)
    except ValueError:
        raise argparse.ArgumentTypeError(f"{text}: expected {wanted}") from None
    if not (value.is_integer() and TRAIL_MIN_MS <= value <= TRAIL_MAX_MS):
        raise argparse.ArgumentTypeError(f"{text}: expected {wanted}")
    return int(value)


def _band(text: str) -> tuple[int, int]:
    """LO-HI in whole Hz, within the chip's 50-520 Hz."""
    wanted = f"LO-HI in whole Hz with {AFK_MIN_HZ} <= LO < HI <= {AFK_MAX_HZ}, e.g. 90-130"
    low_text, dash, high_text = text.partition("-")
    try:
        low, high = float(low_text), float(high_text)
    except ValueError:
        raise argparse.ArgumentTypeError(f"{text}: expected {wanted}") from None
    whole = dash and low.is_integer() and high.is_integer()
    if not (whole and AFK_MIN_HZ <= low < high <= AFK_MAX_HZ):
        raise argparse.ArgumentTypeError(f"{text}: expected {wanted}")
    return int(low), int(high)


def settings(args: argparse.Namespace) -> FilterSettings:
    """The filters the options ask for; a ValueError naming the options where they conflict."""
    if args.stc is not None and args.trail is not None:
        raise ValueError(
            "--stc and --trail: the chip's event trail filter runs as STC or as trail, not "
            "both; give one"
        )
    start, stop = args.afk_thresholds
    if not stop < start:
        raise ValueError(
            f"--afk-thresholds {start} {stop}: STOP must be below START (0 <= STOP < START <= "
            f"{AFK_MAX_THRESHOLD})"
        )
    least_rate = 1e6 / ERC_PERIOD_US
    if args.erc is not None and args.erc < least_rate:
        raise ValueError(
            f"--erc {args.erc:g}: below one event per {ERC_PERIOD_US} us period; give at least "
            f"{least_rate:g} events/s"
        )
    chosen = FilterSettings(
        erc_rate_hz=args.erc,
        stc_ms=args.stc,
        stc_mode=args.stc_mode,
        trail_ms=args.trail,
        afk_band_hz=args.afk,
        afk_mode=args.afk_mode,
        afk_start=start,
        afk_stop=stop,
    )
    if not chosen.enabled:
        raise ValueError("no filter asked for: give --erc, --stc, --trail or --afk (or several)")
    return chosen


def run(args: argparse.Namespace) -> int:
    stream = EventFilter(settings(args))
    _, to_stdout = copy_events(args, through=stream.apply, last=stream.flush)
    summary = sys.stderr if to_stdout else sys.stdout
    print(_summary(args.output, stream), file=summary)
    return 0


def _summary(output: str, stream: EventFilter) -> str:
    """'OUT: 812 of 1000 events kept (dropped: trail 30, ERC 158); trail 5 ms, ERC 20 Mev/s'."""
    counts = stream.counts
    total = counts["events_in"]
    dropped = []
    trail = "STC" if stream.settings.stc_ms is not None else "trail"
    for name, key in (("AFK", "afk_dropped"), (trail, "trail_dropped")):
        if counts[key]:
            dropped.append(f"{name} {counts[key]}")
    if counts["erc_dropped"]:
        dropped.append(f"ERC {counts['erc_dropped']}")
    why = f" (dropped: {', '.join(dropped)})" if dropped else ""
    return f"{output}: {counts['events_out']} of {total} events kept{why}; {stream.settings.describe()}"
