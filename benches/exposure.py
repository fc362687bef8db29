"""APS exposure: what averaging the light over each frame's exposure does to the events pecs
makes from the frames, where the light is known at every instant, and what deconvolving the
exposure (`pecs.footage.exposure`) gets back.

The light: a texture of soft-edged bars and sinusoids (values 0.05 to 0.95 of full scale,
edges about 1 px wide) moving along x, each row at its own speed (10 to 50 px/s: 0.4 to 2 px a frame at 25 Hz) that varies
in time (+-60 %, period 0.7 s), on a 64 x 48 sensor for 1.2 s. The truth: the light sampled at
2 kHz, fed to the sensor. The "APS frames": 25 Hz, each the mean of the light over an exposure
of 0, 25, 50 or 100 % of the 40 ms frame interval centred on the frame's time (the light
sampled every 50 us across it), fed to the same sensor at those times with linear
interpolation (in log) between them, as recorded ("as is") and deconvolved
(`frames_to_events(..., exposure_us=E)`); at 50 % also timed at the exposure start instead of
its midpoint ("at start", as the emlb recording's `timestamp` has them). The sensor: davis346 with its random noise off, one
mismatch seed, so that runs differ only by their input.

Each run is scored against the truth over the frames' span (first to last frame):
the count ratio, the per-pixel count-map correlation (`pecs.calibration.realism`), chamfer and
Gaussian distances (sensor normalisation), and the time offset of matched events: each event's
nearest truth event of the same pixel and polarity within one frame interval, the mean signed
offset (simulated - true) and the mean absolute offset, in ms.

    python benches/exposure.py [--seconds 1.2] [--rate-hz 2000]

Prints the table and the ratio of each run's Gaussian distance over the exposure-0 run's (the
baseline, measured in the same run): how much of the frames' error the exposure adds.
"""

from __future__ import annotations

import argparse

import numpy as np
import pecs
import pyarrow as pa
from pecs.calibration.realism import score
from pecs.config import NOISE_OFF

WIDTH, HEIGHT = 64, 48
FRAME_US = 40_000  # 25 Hz
EXPOSURE_FRACTIONS = (0.0, 0.25, 0.5, 1.0)
BOX_STEP_US = 50  # light samples across an exposure


def light(t_us: float | np.ndarray) -> np.ndarray:
    """The light (HEIGHT, WIDTH) at time t_us, or (len(t), HEIGHT, WIDTH) for an array of
    times: a texture moving along x, each row at its own time-varying speed."""
    t_s = np.atleast_1d(np.asarray(t_us, np.float64))[:, None, None] * 1e-6
    row = np.arange(HEIGHT, dtype=np.float64)[None, :, None]
    x = np.arange(WIDTH, dtype=np.float64)[None, None, :]
    speed = 10.0 + 40.0 * row / (HEIGHT - 1)  # px/s
    # Position of the texture: integral of speed * (1 + 0.6 sin(2 pi t / 0.7 + row)).
    period_s = 0.7
    phase = row * 0.37
    shift = speed * (
        t_s
        - 0.6
        * period_s
        / (2 * np.pi)
        * (np.cos(2 * np.pi * t_s / period_s + phase) - np.cos(phase))
    )
    u = x - shift  # texture coordinate, px
    bars = sum(
        0.5
        * (
            np.tanh((np.mod(u + offset, span) - 2.0) * 2.0)
            - np.tanh((np.mod(u + offset, span) - 2.0 - width) * 2.0)
        )
        for offset, span, width in ((0.0, 23.0, 5.0), (7.0, 37.0, 3.0), (3.0, 61.0, 9.0))
    )
    waves = 0.5 + 0.25 * np.sin(2 * np.pi * u / 17.0) + 0.25 * np.sin(2 * np.pi * u / 7.3 + 1.0)
    value = 0.05 + 0.9 * np.clip(0.55 * bars / 1.5 + 0.45 * waves, 0.0, 1.0)
    out = value.astype(np.float32)
    return out[0] if np.ndim(t_us) == 0 else out


def aps_frames(times_us: np.ndarray, exposure_us: float) -> np.ndarray:
    """Each frame the mean light over [t - E/2, t + E/2] (the instant itself for E = 0)."""
    if exposure_us == 0:
        return light(times_us.astype(np.float64))
    steps = max(2, round(exposure_us / BOX_STEP_US))
    # Midpoint rule over the exposure.
    offsets = (np.arange(steps) + 0.5) / steps * exposure_us - exposure_us / 2
    return np.stack([light(t + offsets).mean(axis=0) for t in times_us]).astype(np.float32)


def matched_offsets_ms(truth: pa.Table, sim: pa.Table, window: tuple[int, int]) -> np.ndarray:
    """Each simulated event's time minus its nearest truth event's of the same pixel and
    polarity (ms), where one lies within a frame interval."""

    def keyed(table: pa.Table) -> tuple[np.ndarray, np.ndarray]:
        t = table.column("t").to_numpy().astype(np.int64)
        keep = (t >= window[0]) & (t < window[1])
        group = (
            table.column("y").to_numpy().astype(np.int64)[keep] * WIDTH
            + table.column("x").to_numpy().astype(np.int64)[keep]
        ) * 2 + table.column("p").to_numpy().astype(np.int64)[keep]
        return group, t[keep]

    g_true, t_true = keyed(truth)
    g_sim, t_sim = keyed(sim)
    span = 1 << 40
    key_true = np.sort(g_true * span + t_true)
    key_sim = g_sim * span + t_sim
    i = np.searchsorted(key_true, key_sim)
    best = np.full(len(key_sim), np.iinfo(np.int64).max)
    for j in (i - 1, i):
        ok = (j >= 0) & (j < len(key_true))
        cand = np.where(ok, key_true[np.clip(j, 0, len(key_true) - 1)], 0)
        same = ok & (cand // span == g_sim)
        diff = np.where(same, key_sim - cand, np.iinfo(np.int64).max)
        best = np.where(np.abs(diff) < np.abs(best), diff, best)
    found = np.abs(best) <= FRAME_US
    return best[found] / 1e3


def main() -> None:
    parser = argparse.ArgumentParser(description=__doc__.split("\n\n")[0])
    parser.add_argument("--seconds", type=float, default=1.2, help="length of the light")
    parser.add_argument("--rate-hz", type=float, default=2000.0, help="the truth's frame rate")
    args = parser.parse_args()
    end_us = round(args.seconds * 1e6)
    config = pecs.SensorConfig.preset("davis346", width=WIDTH, height=HEIGHT, seed=0, **NOISE_OFF)
    truth_times = np.arange(0, end_us + 1, round(1e6 / args.rate_hz), dtype=np.int64)
    truth = pecs.frames_to_events(light(truth_times.astype(np.float64)), truth_times, config)
    times = np.arange(0, end_us + 1, FRAME_US, dtype=np.int64)
    window = (int(times[1]), int(times[-1]))  # the first interval: the sensor settling
    truth_count = np.count_nonzero(
        (truth.column("t").to_numpy() >= window[0]) & (truth.column("t").to_numpy() < window[1])
    )
    print(
        f"truth: {args.rate_hz:g} Hz light, {truth_count} events in {window[0] / 1e3:.0f}.."
        f"{window[1] / 1e3:.0f} ms; APS frames at 25 Hz, davis346 (noise off), linear in log"
    )
    header = (
        f"{'exposure':<10}{'frames':<12}{'events':>8}{'count x':>9}{'map r':>8}{'CD sens':>9}"
        f"{'GD sens':>9}{'dt mean':>9}{'|dt|':>8}{'GD / E=0':>10}"
    )
    print(header + "\n" + "-" * len(header))
    baseline = None
    for fraction in EXPOSURE_FRACTIONS:
        exposure_us = fraction * FRAME_US
        frames = aps_frames(times, exposure_us)
        runs = {"as is": None} if fraction == 0 else {"as is": None, "deconvolved": exposure_us}
        if fraction == 0.5:
            runs["at start"] = None  # timed at the exposure start, as DV's emlb timestamps
        for name, given in runs.items():
            shift = round(exposure_us / 2) if name == "at start" else 0
            sim = pecs.frames_to_events(frames, times - shift, config, exposure_us=given)
            got = score(truth, sim, window_us=window, sensor_size=(WIDTH, HEIGHT))
            offsets = matched_offsets_ms(truth, sim, window)
            if baseline is None:
                baseline = got["gaussian_sensor"]
            print(
                f"{fraction:<10.0%}{name:<12}{got['events_sim']:>8.0f}{got['count_ratio']:>9.3f}"
                f"{got['count_map_correlation']:>8.3f}{got['chamfer_sensor']:>9.3f}"
                f"{got['gaussian_sensor']:>9.3f}{np.mean(offsets):>9.2f}"
                f"{np.mean(np.abs(offsets)):>8.2f}{got['gaussian_sensor'] / baseline:>10.3f}"
            )
    print(
        "count x: events / truth's; map r: per-pixel count correlation (3 x 3); CD / GD: "
        "chamfer / Gaussian distance to the truth (sensor normalisation); dt: simulated - true "
        "time of matched events (same pixel and polarity, nearest within 40 ms), ms"
    )


if __name__ == "__main__":
    main()
