"""The IMX636 (Prophesee EVK4) saturated: a fast textured pan under bright light at 1280 x 720,
through the `imx636` preset with its readout (row arbiter, 1 us timestamps, the event rate
controller at 50 Mev/s) and without it. Prints the event rate over time, what the readout dropped
and delayed, and how many events share a timestamp; draws docs/readout-rate.png with --figure.

Run: .venv/bin/python benches/bench_readout.py [--ms 20] [--figure docs/readout-rate.png]
"""

from __future__ import annotations

import argparse
import time

import numpy as np
import pecs

WIDTH, HEIGHT = 1280, 720
FRAME_US = 250
BIN_US = 1000
#: The pan's speed rises linearly from 0 to this (pixels per second) over the clip.
TOP_SPEED_PX_S = 500.0
#: Every readout stage off: the pixels' own events.
NO_READOUT = {
    "readout_row_service_ns": 0.0,
    "readout_bus_rate_meps": 0.0,
    "timestamp_step_us": 0,
    "erc_rate_hz": 0.0,
}


def texture(width: int, height: int) -> np.ndarray:
    """A random texture of blobs about 4 px across, reflectance 0.05-1 (bright light: its white
    at 10,000 lux)."""
    rng = np.random.default_rng(0)
    coarse = rng.uniform(0.0, 1.0, (height // 4 + 2, width // 4 + 2))
    fine = np.kron(coarse, np.ones((4, 4)))[:height, :width]
    # A 3-tap blur each way: smooth edges, so motion gives ramps rather than steps.
    fine = (np.roll(fine, 1, 1) + fine + np.roll(fine, -1, 1)) / 3
    fine = (np.roll(fine, 1, 0) + fine + np.roll(fine, -1, 0)) / 3
    return (0.05 + 0.95 * fine).astype(np.float32)


def pan_frames(ms: float) -> tuple[list[np.ndarray], np.ndarray]:
    """The texture panned left at a speed rising from 0 to TOP_SPEED_PX_S, sampled every
    FRAME_US, shifted with linear interpolation between columns."""
    n = int(ms * 1000 / FRAME_US) + 1
    times = np.arange(n, dtype=np.int64) * FRAME_US
    t_s = times / 1e6
    duration_s = ms / 1000
    shift_px = 0.5 * TOP_SPEED_PX_S / duration_s * t_s**2  # integral of a linear speed ramp
    wide = texture(WIDTH + int(shift_px[-1]) + 2, HEIGHT)
    frames = []
    for shift in shift_px:
        whole, part = int(shift), shift - int(shift)
        left = wide[:, whole : whole + WIDTH]
        right = wide[:, whole + 1 : whole + 1 + WIDTH]
        frames.append(((1 - part) * left + part * right).astype(np.float32))
    return frames, times


def simulate(config: pecs.SensorConfig, frames: list[np.ndarray], times: np.ndarray) -> dict:
    """Events per microsecond over the clip, and the readout's counts."""
    sensor = pecs.EventSensor(config)
    per_us = np.zeros(int(times[-1]) + 1, np.int64)
    start = time.perf_counter()
    batches = [sensor.feed(frame, int(t)) for frame, t in zip(frames, times, strict=True)]
    batches.append(sensor.flush())
    seconds = time.perf_counter() - start
    t = np.concatenate([b["t"].to_numpy() for b in batches])
    inside = t[(t >= 0) & (t < len(per_us))]
    per_us += np.bincount(inside, minlength=len(per_us))
    same = int(np.count_nonzero(t[1:] == t[:-1]))
    return {
        "per_us": per_us,
        "events": len(t),
        "same_timestamp": same,
        "counts": sensor.readout_counts,
        "seconds": seconds,
    }


def report(name: str, run: dict, start_us: int) -> None:
    per_us = run["per_us"][start_us:]
    busy = per_us[per_us.cumsum() > 0]
    empty = np.count_nonzero(busy == 0) / max(len(busy), 1)
    print(
        f"{name:<16}{run['events']:>11,} events in {run['seconds']:.1f} s; "
        f"{run['same_timestamp'] / max(run['events'], 1):.1%} share the timestamp before them; "
        f"{empty:.1%} of 1 us bins empty"
    )


def main() -> None:
    parser = argparse.ArgumentParser(description=__doc__)
    parser.add_argument("--ms", type=float, default=20.0, help="clip length (ms)")
    parser.add_argument("--figure", help="write the rate plot here (PNG)")
    args = parser.parse_args()
    frames, times = pan_frames(args.ms)
    imx636 = pecs.SensorConfig.preset("imx636", width=WIDTH, height=HEIGHT, white_lux=10_000.0)
    runs = {
        "pixels alone": simulate(imx636.replace(**NO_READOUT), frames, times),
        "with readout": simulate(imx636, frames, times),
    }
    bins = len(runs["pixels alone"]["per_us"]) // BIN_US
    rates = {
        name: run["per_us"][: bins * BIN_US].reshape(bins, BIN_US).sum(axis=1) / BIN_US
        for name, run in runs.items()
    }
    print(f"{'t (ms)':>7}{'pixels (Mev/s)':>16}{'out (Mev/s)':>13}")
    for k in range(bins):
        print(
            f"{k * BIN_US / 1000:>7.0f}{rates['pixels alone'][k]:>16.1f}{rates['with readout'][k]:>13.1f}"
        )
    print()
    for name, run in runs.items():
        report(name, run, FRAME_US)
    c = runs["with readout"]["counts"]
    print(
        f"readout: {c['events_in']:,} in, {c['events_out']:,} out, {c['dropped']:,} dropped by "
        f"a full queue, {c['erc_dropped']:,} ({c['erc_dropped'] / c['events_in']:.1%}) by the "
        f"rate controller, {c['held']} held; {c['delayed']:,} delayed, mean "
        f"{c['delay_total_us'] / max(c['delayed'], 1):.1f} us, max {c['delay_max_us']} us"
    )
    if args.figure:
        draw(rates, args.figure)


def draw(rates: dict[str, np.ndarray], path: str) -> None:
    import matplotlib

    matplotlib.use("Agg")
    import matplotlib.pyplot as plt

    t_ms = (np.arange(len(rates["pixels alone"])) + 0.5) * BIN_US / 1000
    fig, ax = plt.subplots(figsize=(6, 3), dpi=90)
    ax.plot(t_ms, rates["pixels alone"], label="pixels (no readout)")
    ax.plot(t_ms, rates["with readout"], label="imx636 readout + ERC")
    ax.axhline(50, color="grey", linestyle=":", label="ERC 50 Mev/s")
    ax.set_xlabel("time (ms): pan speeding up from 0 to 500 px/s")
    ax.set_ylabel("events (M/s)")
    ax.legend(loc="upper left", fontsize=8)
    fig.tight_layout()
    fig.savefig(path)
    print(f"figure: {path}")


if __name__ == "__main__":
    main()
