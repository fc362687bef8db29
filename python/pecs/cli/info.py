"""`pecs info FILE`: what an event file holds, read in one streaming pass.

Events, duration, resolution, event rate, ON/OFF balance, and percentiles of the per-pixel event
rate over all pixels of the sensor (a hot pixel shows as a max far above p99).
"""

from __future__ import annotations

import argparse
import json
from pathlib import Path
from typing import Any

import numpy as np

import pecs.io
from pecs.cli._arguments import add_command
from pecs.events import sensor_size

PERCENTILES = (50, 90, 99, 99.9)


def register(subparsers: argparse._SubParsersAction) -> None:
    parser = add_command(
        subparsers,
        "info",
        help="summarise an event file",
        description="Events, duration, resolution, event rate, ON/OFF balance and percentiles "
        "of the per-pixel event rate (a hot pixel shows as a max far above p99), in one "
        "streaming pass over the file.",
    )
    parser.add_argument("file", help="event file")
    parser.add_argument("--format", help="input format name (by suffix if unset)")
    parser.add_argument("--json", action="store_true", help="print JSON instead of text")
    parser.set_defaults(func=run)


def summarise(path: str | Path, format: str | None = None) -> dict[str, Any]:
    """The statistics `pecs info` prints, as a dict."""
    counts = np.zeros((0, 0), dtype=np.int64)
    size = None
    n_events = n_on = 0
    t_first = t_last = None
    for batch in pecs.io.iter_events(path, format=format):
        size = size or sensor_size(batch.schema)
        if batch.num_rows == 0:
            continue
        t = batch.column("t").to_numpy()
        x = batch.column("x").to_numpy().astype(np.intp)
        y = batch.column("y").to_numpy().astype(np.intp)
        t_first = int(t[0]) if t_first is None else t_first
        t_last = int(t[-1])
        n_events += len(t)
        n_on += int(np.count_nonzero(batch.column("p").to_numpy() > 0))
        counts = _grow(counts, int(y.max()) + 1, int(x.max()) + 1)
        pixel = y * counts.shape[1] + x
        counts += np.bincount(pixel, minlength=counts.size).reshape(counts.shape)
    width, height = size if size else (counts.shape[1], counts.shape[0])
    counts = _grow(counts, height, width)
    duration_us = (t_last - t_first) if n_events else 0
    duration_s = duration_us / 1e6
    rates = counts.ravel() / duration_s if duration_s > 0 else np.zeros(counts.size)
    return {
        "file": str(path),
        "events": n_events,
        "t_first_us": t_first,
        "t_last_us": t_last,
        "duration_s": duration_s,
        "width": width,
        "height": height,
        "resolution_from": "file" if size else "largest address + 1",
        "event_rate_per_s": n_events / duration_s if duration_s > 0 else None,
        "on_events": n_on,
        "off_events": n_events - n_on,
        "on_fraction": n_on / n_events if n_events else None,
        "pixel_rate_percentiles_hz": {
            f"p{q:g}": float(np.percentile(rates, q)) if rates.size else 0.0 for q in PERCENTILES
        },
        "pixel_rate_max_hz": float(rates.max()) if rates.size else 0.0,
        "active_pixels": int(np.count_nonzero(counts)),
    }


def _grow(counts: np.ndarray, height: int, width: int) -> np.ndarray:
    if counts.shape[0] >= height and counts.shape[1] >= width:
        return counts
    grown = np.zeros((max(height, counts.shape[0]), max(width, counts.shape[1])), np.int64)
    grown[: counts.shape[0], : counts.shape[1]] = counts
    return grown


def run(args: argparse.Namespace) -> int:
    info = summarise(args.file, args.format)
    if args.json:
        print(json.dumps(info, indent=2))
        return 0
    rate = info["event_rate_per_s"]
    on = info["on_fraction"]
    lines = [
        f"file:        {info['file']}",
        f"events:      {info['events']}",
        f"duration:    {info['duration_s']:.6f} s",
        f"resolution:  {info['width']} x {info['height']} ({info['resolution_from']})",
        f"event rate:  {rate / 1e6:.4f} Mev/s" if rate is not None else "event rate:  n/a",
        f"ON / OFF:    {info['on_events']} / {info['off_events']}"
        + (f" (ON fraction {on:.3f})" if on is not None else ""),
        "pixel rate:  "
        + ", ".join(f"{k} {v:.3g} Hz" for k, v in info["pixel_rate_percentiles_hz"].items())
        + f", max {info['pixel_rate_max_hz']:.3g} Hz",
        f"active:      {info['active_pixels']} pixels",
    ]
    print("\n".join(lines))
    return 0
