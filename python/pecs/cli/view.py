"""`pecs view EVENTS -o out.png | out.mp4 | out.gif`: look at an event stream."""

from __future__ import annotations

import argparse
import sys
from collections.abc import Iterator
from pathlib import Path

import numpy as np
import pyarrow as pa
import pyarrow.parquet as pq

import pecs.io
import pecs.viz
from pecs.cli._arguments import add_command, number
from pecs.cli._progress import add_progress_arguments, counted, event_total, wants_progress
from pecs.events import schema, sensor_size

_SUFFIXES = (".png", ".mp4", ".gif")
# Events read to learn what the file states about itself (its schema metadata).
_PROBE_EVENTS = 1024
#: Default bound on a video's frames: 2.8 minutes at 30 fps. A 1 us window on a 2.3 s recording
#: asked for 2.3 M frames (a GIF of them filled 23 GB; an MP4 took 40 minutes).
MAX_FRAMES = 5000


def register(subparsers: argparse._SubParsersAction) -> None:
    parser = add_command(
        subparsers,
        "view",
        help="render events to an image or video",
        description="PNG: one event frame (or time surface) over a window. MP4/GIF: consecutive "
        "event frames, one per window. Blue: ON, red: OFF. Times are in ms after the stream's "
        "first event, unless --absolute-times.",
    )
    parser.add_argument("events", help="event file")
    parser.add_argument("-o", "--output", required=True, help="out.png, out.mp4 or out.gif")
    parser.add_argument(
        "--window-ms", type=number(float, above=0), default=33.3, help="event time per frame"
    )
    parser.add_argument(
        "--start-ms",
        type=number(float),
        help="start of the time shown, ms after the first event (the first event if unset)",
    )
    parser.add_argument(
        "--end-ms",
        type=number(float),
        help="end of the time shown, ms after the first event (video; the last event if unset)",
    )
    parser.add_argument(
        "--absolute-times",
        action="store_true",
        help="--start-ms and --end-ms are the file's own times in ms (a DV recording's are "
        "Unix time), not times after its first event",
    )
    parser.add_argument(
        "--max-frames",
        type=number(int, above=0),
        default=MAX_FRAMES,
        help="most frames a video may have: the count is worked out before anything is "
        "written, and a longer video is refused",
    )
    parser.add_argument(
        "--fps", type=number(float, above=0), default=30.0, help="video playback rate"
    )
    parser.add_argument(
        "--background", choices=("white", "black"), default="white", help="background colour"
    )
    parser.add_argument(
        "--time-surface", action="store_true", help="PNG only: a time surface instead"
    )
    parser.add_argument(
        "--width", type=number(int, above=0), help="sensor width, when the file does not say"
    )
    parser.add_argument(
        "--height", type=number(int, above=0), help="sensor height, when the file does not say"
    )
    add_progress_arguments(parser)
    parser.set_defaults(func=run)


def run(args: argparse.Namespace) -> int:
    output = Path(args.output)
    suffix = output.suffix.lower()
    _check(args, suffix)
    window_us = round(args.window_ms * 1000)
    width, height = _size(args)
    first_us = _first_event_us(args)
    # Times after the first event by default: a DV recording's clock is Unix time, so a window
    # "40 ms in" taken as absolute lies 52 years before its events.
    origin_us = 0 if args.absolute_times else first_us
    start_us = None if args.start_ms is None else origin_us + round(args.start_ms * 1000)
    end_us = None if args.end_ms is None else origin_us + round(args.end_ms * 1000)
    if suffix == ".png":
        image = _still(args, width, height, start_us, end_us, window_us, origin_us)
        pecs.viz.save_image(image, output)
        print(f"{output}: {image.shape[1]} x {image.shape[0]}")
        return 0
    start_us = first_us if start_us is None else start_us
    last_us = _last_event_us(args.events)
    _check_start(args, start_us, last_us, origin_us)
    end_us = _video_end(args, end_us, last_us, origin_us)
    _check_frame_count(args, (width, height), start_us, end_us, window_us)
    shown = [0]
    frames = pecs.viz.event_frames(
        _events(args, start_us, end_us, shown),
        width,
        height,
        window_us=window_us,
        t_start_us=start_us,
        t_end_us=end_us,
        background=args.background,
    )
    pecs.viz.save_video(frames, output, fps=args.fps)
    print(f"{output}: written")
    if not shown[0]:
        _warn(f"no events in {_span(start_us, end_us, origin_us)}: the video is blank")
    return 0


def _check(args: argparse.Namespace, suffix: str) -> None:
    """Refuse what would give a blank or different picture than asked, before reading."""
    if suffix not in _SUFFIXES:
        raise ValueError(f"{args.output}: output must be .png, .mp4 or .gif")
    if args.time_surface and suffix != ".png":
        raise ValueError(f"--time-surface draws one PNG; {suffix} videos show event frames")
    if round(args.window_ms * 1000) < 1:
        raise ValueError(f"--window-ms {args.window_ms:g}: shorter than the 1 us time resolution")
    if args.start_ms is not None and args.end_ms is not None and args.end_ms <= args.start_ms:
        end, start = _typed_ms(args.end_ms), _typed_ms(args.start_ms)
        raise ValueError(f"--end-ms {end} is not after --start-ms {start}: nothing to show")


def _warn(message: str) -> None:
    """A one-line notice on stderr: the output is written, but not what the user may expect."""
    print(f"pecs view: warning: {message}", file=sys.stderr)


def _ms(t_us: int) -> str:
    """Microseconds as milliseconds, exact and without trailing zeros (Unix times included)."""
    sign = "-" if t_us < 0 else ""
    whole, part = divmod(abs(t_us), 1000)
    return f"{sign}{whole}" + (f".{part:03d}".rstrip("0") if part else "")


def _typed_ms(value_ms: float) -> str:
    """An option's milliseconds as typed, not in exponent form (--end-ms 2000000, not 2e+06)."""
    return _ms(round(value_ms * 1000))


def _span(start_us: int, end_us: int, origin_us: int) -> str:
    return f"{_ms(start_us - origin_us)} .. {_ms(end_us - origin_us)} ms"


def _first_event_us(args: argparse.Namespace) -> int:
    """The first event's time, from the first batch that holds one."""
    for batch in pecs.io.iter_events(args.events, batch_size=_PROBE_EVENTS):
        if batch.num_rows:
            return int(batch.column("t")[0].as_py())
    raise ValueError(f"{args.events}: no events to show")


def _last_event_us(path: str) -> int:
    """The last event's time: from a Parquet file's column statistics where it has them, else
    by one streaming pass (a video needs it to count its frames before writing any)."""
    stated = _parquet_max_t(path)
    if stated is not None:
        return stated
    last_us = 0
    for batch in pecs.io.iter_events(path):
        if batch.num_rows:
            last_us = int(batch.column("t")[-1].as_py())
    return last_us


def _parquet_max_t(path: str) -> int | None:
    if pecs.io.format_for(Path(path)).name != "parquet":
        return None
    metadata = pq.ParquetFile(path).metadata
    column = metadata.schema.to_arrow_schema().get_field_index("t")
    maxima = []
    for group in range(metadata.num_row_groups):
        stats = metadata.row_group(group).column(column).statistics
        if stats is None or not stats.has_min_max or not isinstance(stats.max, int):
            return None
        maxima.append(stats.max)
    return max(maxima) if maxima else None


def _events(
    args: argparse.Namespace, start_us: int, end_us: int, shown: list[int]
) -> Iterator[pa.RecordBatch]:
    """The file's batches up to `end_us`; shown[0] counts the events in [start_us, end_us)."""
    show = wants_progress(args)
    total = event_total(args.events) if show else None
    for batch in counted(pecs.io.iter_events(args.events), show, total):
        t = batch.column("t").to_numpy()
        if len(t) and t[0] >= end_us:
            break  # sorted: nothing later is shown
        shown[0] += int(np.searchsorted(t, end_us) - np.searchsorted(t, start_us))
        yield batch


def _check_start(
    args: argparse.Namespace, start_us: int | None, last_us: int | None, origin_us: int
) -> None:
    if last_us is None:
        raise ValueError(f"{args.events}: no events to show")
    if start_us is not None and start_us > last_us:
        last = _ms(last_us - origin_us)
        raise ValueError(
            f"--start-ms {_typed_ms(args.start_ms)} is past the last event (t = {last} ms)"
        )


def _video_end(args: argparse.Namespace, end_us: int | None, last_us: int, origin_us: int) -> int:
    """Where the video ends: --end-ms, or just after the last event; an end past the last event
    is brought back to it, since the frames after it are blank."""
    if end_us is None:
        return last_us + 1
    if end_us > last_us + 1:
        end, last = _typed_ms(args.end_ms), _ms(last_us - origin_us)
        _warn(f"--end-ms {end} is past the last event (t = {last} ms): the video ends there")
        return last_us + 1
    return end_us


def _check_frame_count(
    args: argparse.Namespace, size: tuple[int, int], start_us: int, end_us: int, window_us: int
) -> None:
    """Refuse a video of more than --max-frames frames before any is made: their count and raw
    size follow from the span and the window."""
    count = -(-(end_us - start_us) // window_us)
    if count <= args.max_frames:
        return
    raw_bytes = count * size[0] * size[1] * 3
    raise ValueError(
        f"--window-ms {args.window_ms:g} over {_ms(end_us - start_us)} ms of events makes "
        f"{count:,} frames of {size[0]} x {size[1]} ({_bytes(raw_bytes)} of pixels), more than "
        f"--max-frames {args.max_frames:,}: give a longer --window-ms, a shorter span "
        "(--start-ms, --end-ms) or a larger --max-frames"
    )


def _bytes(count: int) -> str:
    for unit, size in (("TB", 1e12), ("GB", 1e9), ("MB", 1e6), ("kB", 1e3)):
        if count >= size:
            return f"{count / size:.1f} {unit}"
    return f"{count} bytes"


def _still(
    args: argparse.Namespace,
    width: int | None,
    height: int | None,
    start_us: int | None,
    end_us: int | None,
    window_us: int,
    origin_us: int,
) -> np.ndarray:
    """One frame over [start, end) (default: the first window), streaming through the file.
    The time surface is taken at the end of that window with tau = window / 3, so events older
    than the window have faded to under 5 %. A window without events gives a blank picture and
    a warning."""
    kept: list[pa.RecordBatch] = []
    last_t: int | None = None
    show = wants_progress(args)
    total = event_total(args.events) if show else None
    for batch in counted(pecs.io.iter_events(args.events), show, total):
        t = batch.column("t").to_numpy()
        if len(t) == 0:
            continue
        last_t = int(t[-1])
        if start_us is None:
            start_us = int(t[0])
        end = start_us + window_us if end_us is None else end_us
        first = start_us if not args.time_surface else end - 10 * window_us
        lo, hi = np.searchsorted(t, first, "left"), np.searchsorted(t, end, "left")
        if hi > lo:
            kept.append(batch.slice(lo, hi - lo))
        if t[-1] >= end:
            break
    _check_start(args, start_us, last_t, origin_us)
    assert start_us is not None
    end = start_us + window_us if end_us is None else end_us
    events = pa.Table.from_batches(kept, schema=kept[0].schema) if kept else None
    if events is None:
        first = start_us if not args.time_surface else end - 10 * window_us
        _warn(f"no events in {_span(first, end, origin_us)}: the picture is blank")
        return pecs.viz.event_frame(_empty(width, height), background=args.background)
    if args.time_surface:
        return pecs.viz.time_surface_image(
            events, width, height, t_us=end - 1, tau_us=window_us / 3, background=args.background
        )
    return pecs.viz.event_frame(
        events, width, height, t_start_us=start_us, t_end_us=end, background=args.background
    )


def _empty(width: int | None, height: int | None) -> pa.Table:
    return schema(width, height).empty_table()


def _size(args: argparse.Namespace) -> tuple[int | None, int | None]:
    if args.width is not None and args.height is not None:
        return args.width, args.height
    first = next(iter(pecs.io.iter_events(args.events, batch_size=_PROBE_EVENTS)), None)
    stated = sensor_size(first.schema) if first is not None else None
    if stated is not None:
        return stated
    # No size in the file: one streaming pass for the largest address.
    width = height = 0
    for batch in pecs.io.iter_events(args.events):
        if batch.num_rows:
            width = max(width, int(batch.column("x").to_numpy().max()) + 1)
            height = max(height, int(batch.column("y").to_numpy().max()) + 1)
    if not width:
        raise ValueError(f"{args.events}: no events and no sensor size; pass --width/--height")
    return width, height
