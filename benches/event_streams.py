"""Synthetic event streams for the metrics benchmarks (numpy only, no event engine needed).

`edge_sweep`: a bright bar sweeping left to right across a 346 x 260 sensor; its leading edge
fires ON events and its trailing edge OFF events, each pixel a few times as the edge passes
(timestamps spread around the crossing), plus uniform background noise of both polarities.
"""

from __future__ import annotations

import numpy as np
import pyarrow as pa
from pecs.events import record_batch, schema

WIDTH, HEIGHT = 346, 260


def edge_sweep(
    n_events: int,
    *,
    duration_us: int = 100_000,
    noise_share: float = 0.1,
    seed: int = 0,
    width: int = WIDTH,
    height: int = HEIGHT,
) -> pa.Table:
    """About `n_events` events over `duration_us`, sorted by t, with the sensor size attached."""
    rng = np.random.default_rng(seed)
    n_noise = int(n_events * noise_share)
    n_edge = n_events - n_noise
    # Each edge event: a row, which edge (leading ON / trailing OFF, 40 px behind), and a
    # position along the sweep; the pixel fires near the time the edge crosses it.
    y = rng.integers(0, height, n_edge)
    on = rng.random(n_edge) < 0.5
    speed_px_per_us = (width + 40) / duration_us
    x = rng.integers(0, width, n_edge)
    crossing_us = (x + np.where(on, 0, 40)) / speed_px_per_us
    t = crossing_us + rng.gamma(2.0, 150.0, n_edge)  # pixel latency and refractory spread
    t_all = np.concatenate([t, rng.uniform(0, duration_us, n_noise)])
    x_all = np.concatenate([x, rng.integers(0, width, n_noise)])
    y_all = np.concatenate([y, rng.integers(0, height, n_noise)])
    p_all = np.concatenate([on.astype(np.int8), rng.integers(0, 2, n_noise).astype(np.int8)])
    keep = t_all < duration_us
    order = np.argsort(t_all[keep], kind="stable")
    columns = {
        "t": t_all[keep][order].astype(np.int64),
        "x": x_all[keep][order],
        "y": y_all[keep][order],
        "p": p_all[keep][order],
    }
    return pa.Table.from_batches([record_batch(columns, schema(width, height))])
