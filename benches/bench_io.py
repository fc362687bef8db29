"""Event I/O throughput per format, pecs against faery alone on the same events, in one run.

    .venv/bin/python benches/bench_io.py [--events 5000000] [--repeat 3] [--formats evt3,evt2]

pecs writes from an Arrow table through `pecs.write_events` (validation, conversion, atomic
rename) and reads through `pecs.read_events`; faery writes its own structured array with
`faery.events_stream_from_array(...).to_file` and reads with `faery.events_stream_from_file`.
Where faery has no writer for a format (Parquet, HDF5, npz, text), the ratio is against faery's
EVT3 path, the fastest it has. Best of `--repeat` runs, million events per second.
"""

from __future__ import annotations

import argparse
import tempfile
import time
from pathlib import Path

import faery
import numpy as np
import pecs
import pecs.events
import pyarrow as pa

WIDTH, HEIGHT = 1280, 720

# (label, suffix, pecs format, faery format for the baseline or None)
CASES = [
    ("parquet", ".parquet", None, None),
    ("hdf5 dsec", ".h5", None, None),
    ("hdf5 v2e", ".h5", "v2e", None),
    ("aedat4", ".aedat4", None, ("aedat4", {})),
    ("evt3", ".raw", None, ("raw", {"version": "evt3"})),
    ("evt2", ".raw", "evt2", ("raw", {"version": "evt2"})),
    ("dat", ".dat", None, ("dat", {})),
    ("npz", ".npz", None, None),
    ("text", ".txt", None, None),
]


def make_events(n: int) -> tuple[pa.Table, np.ndarray]:
    rng = np.random.default_rng(0)
    t = np.sort(rng.integers(0, n // 2, n))  # ~2 Mev/s, past the EVT3 wrap for n > 3.4e7
    x = rng.integers(0, WIDTH, n, dtype=np.uint16)
    y = rng.integers(0, HEIGHT, n, dtype=np.uint16)
    p = rng.integers(0, 2, n, dtype=np.int8)
    batch = pecs.events.record_batch(
        {"t": t, "x": x, "y": y, "p": p}, pecs.events.schema(WIDTH, HEIGHT)
    )
    array = np.empty(n, dtype=faery.EVENTS_DTYPE)
    array["t"], array["x"], array["y"], array["on"] = t, x, y, p > 0
    return pa.Table.from_batches([batch]), array


def best_seconds(action, repeat: int) -> float:
    times = []
    for _ in range(repeat):
        start = time.perf_counter()
        action()
        times.append(time.perf_counter() - start)
    return min(times)


def main() -> None:
    parser = argparse.ArgumentParser(description=__doc__.split("\n")[0])
    parser.add_argument("--events", type=int, default=5_000_000)
    parser.add_argument("--repeat", type=int, default=3)
    parser.add_argument("--formats", help="comma-separated labels to run (default: all)")
    args = parser.parse_args()
    chosen = args.formats.split(",") if args.formats else [case[0] for case in CASES]
    n = args.events
    table, array = make_events(n)
    mev = n / 1e6
    folder = Path(tempfile.mkdtemp(prefix="pecs-bench-io-"))

    def faery_rates(suffix: str, options: dict) -> tuple[float, float]:
        path = folder / f"faery.{suffix}"
        stream = faery.events_stream_from_array

        def write() -> None:
            stream(array, dimensions=(WIDTH, HEIGHT)).to_file(path, zero_t0=False, **options)

        write_s = best_seconds(write, args.repeat)
        read_s = best_seconds(
            lambda: np.concatenate(list(faery.events_stream_from_file(path))), args.repeat
        )
        return mev / write_s, mev / read_s

    baseline_evt3 = faery_rates("raw", {"version": "evt3"})
    print(f"{n} events, {WIDTH} x {HEIGHT}, best of {args.repeat}; M events/s")
    print(
        f"{'format':<11}{'pecs write':>11}{'faery write':>12}{'ratio':>7}"
        f"{'pecs read':>11}{'faery read':>11}{'ratio':>7}  MB on disk"
    )
    for label, suffix, fmt, faery_case in CASES:
        if label not in chosen:
            continue
        path = folder / f"pecs{suffix}"
        write_s = best_seconds(
            lambda path=path, fmt=fmt: pecs.write_events(table, path, format=fmt), args.repeat
        )
        read_s = best_seconds(lambda path=path: pecs.read_events(path), args.repeat)
        size_mb = path.stat().st_size / 1e6
        if faery_case is None:
            base_write, base_read = baseline_evt3
            note = " (vs faery evt3)"
        else:
            base_write, base_read = faery_rates(*faery_case)
            note = ""
        write_rate, read_rate = mev / write_s, mev / read_s
        print(
            f"{label:<11}{write_rate:>11.1f}{base_write:>12.1f}{write_rate / base_write:>7.2f}"
            f"{read_rate:>11.1f}{base_read:>11.1f}{read_rate / base_read:>7.2f}"
            f"  {size_mb:8.1f}{note}"
        )
        path.unlink()
    for leftover in folder.iterdir():
        leftover.unlink()
    folder.rmdir()


if __name__ == "__main__":
    main()
