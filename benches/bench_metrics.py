"""pecs.metrics.compare against scipy's cKDTree (workers=-1) computing the same chamfer and
Gaussian distances (PECS definitions: per-stream min-max normalisation, 4-D Euclidean nearest
neighbours), on two streams of an edge sweeping across 346 x 260 for 100 ms plus background
noise, in one run. Prints both times, the ratio, and the agreement of the values.

Run: .venv/bin/python benches/bench_metrics.py [--events 1000000] [--repeat 2]
(needs scipy: pip install -e '.[bench]')
"""

from __future__ import annotations

import argparse
import os
import time

import numpy as np
import pecs.metrics
from event_streams import edge_sweep
from scipy.spatial import cKDTree

SIGMA = 0.4


def scipy_compare(a, b) -> tuple[float, float]:
    """The same metrics with numpy normalisation and cKDTree nearest neighbours."""

    def points(events):
        cols = []
        for name, scale in (("x", 100), ("y", 100), ("p", 100), ("t", 1000)):
            v = events.column(name).to_numpy().astype(np.float64)
            cols.append(scale * (v - v.min()) / (v.max() - v.min() + 1e-8))
        return np.stack(cols, axis=1)

    pa_, pb = points(a), points(b)
    d_ab = cKDTree(pb).query(pa_, k=1, workers=-1)[0]
    d_ba = cKDTree(pa_).query(pb, k=1, workers=-1)[0]
    chamfer = d_ab.mean() + d_ba.mean()
    gaussian = (-np.expm1(-(d_ab**2) / SIGMA)).mean() + (-np.expm1(-(d_ba**2) / SIGMA)).mean()
    return chamfer, gaussian


def best_time(fn, repeat: int):
    best, value = np.inf, None
    for _ in range(repeat):
        start = time.perf_counter()
        value = fn()
        best = min(best, time.perf_counter() - start)
    return best, value


def main() -> None:
    parser = argparse.ArgumentParser(description=__doc__.splitlines()[0])
    parser.add_argument("--events", type=int, default=1_000_000, help="events per stream")
    parser.add_argument("--repeat", type=int, default=2, help="best of this many runs each")
    args = parser.parse_args()
    a = edge_sweep(args.events, seed=1)
    b = edge_sweep(args.events, seed=2)
    print(
        f"streams: {a.num_rows} vs {b.num_rows} events, 346 x 260, 100 ms; {os.cpu_count()} cores"
    )

    t_pecs, ours = best_time(lambda: pecs.metrics.compare(a, b), args.repeat)
    t_scipy, (chamfer, gaussian) = best_time(lambda: scipy_compare(a, b), args.repeat)
    print(
        f"pecs (BVH, Rust)        {t_pecs:8.3f} s   CD {ours.chamfer:.12g}  GD {ours.gaussian:.12g}"
    )
    print(f"scipy cKDTree (-1)      {t_scipy:8.3f} s   CD {chamfer:.12g}  GD {gaussian:.12g}")
    rel = max(abs(ours.chamfer - chamfer) / chamfer, abs(ours.gaussian - gaussian) / gaussian)
    print(f"largest relative difference of the values: {rel:.2e}")
    print(f"speed-up pecs / scipy: {t_scipy / t_pecs:.2f}x")


if __name__ == "__main__":
    main()
