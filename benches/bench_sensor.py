"""pecs's event engine against a vectorised numpy implementation of the ESIM algorithm on the same
frames, in one run (ratios are numpy time / pecs time, best of 11 rounds in which the three take
turns); what the readout and the on-chip rate controller add to the sensor's time (target: at
most 15 %); and the resident memory while 10,000 frames stream through `feed`.

Run: .venv/bin/python benches/bench_sensor.py [--frames N] [--memory-frames N]
"""

from __future__ import annotations

import argparse
import resource
import time
from functools import partial

import numpy as np
import pecs
from pecs.examples import quadrant_disk

EPS = 1e-3
THETA = 0.2
# Best of this many rounds: the machines we measure on are shared and noisy, and a slow spell of
# a second or two can cover all of pecs's short rounds when there are few of them.
REPEATS = 11


def disk_frames(
    n: int, width: int = 346, height: int = 260, fps: float = 2000.0, grain: float = 0.0
) -> np.ndarray:
    """A quadrant disk turning at 2 rev/s, 2x2 supersampled so its edges are anti-aliased;
    `grain` adds fresh multiplicative noise to every pixel of every frame (sensor/video noise)."""
    rng = np.random.default_rng(0)
    frames = np.empty((n, height, width), np.float32)
    for k in range(n):
        hi = quadrant_disk(2 * width, 2 * height, 2 * np.pi * 2.0 * k / fps)
        frames[k] = hi.reshape(height, 2, width, 2).mean(axis=(1, 3))
        if grain:
            frames[k] *= 1 + grain * rng.standard_normal((height, width)).astype(np.float32)
    return frames


def sinusoid_frames(
    n: int, width: int, height: int, phase_step_rad: float, contrast: float
) -> np.ndarray:
    """A sinusoidal grating over the whole frame, 32 pixels a period along x + y / 2, drifting
    `phase_step_rad` a frame: every pixel changes every frame and many fire (as
    rust/bench/benches/dense.rs's sinusoid scenes)."""
    y, x = np.mgrid[:height, :width]
    along = 2 * np.pi / 32.0 * (x + 0.5 * y)
    phases = phase_step_rad * np.arange(n)[:, None, None]
    return (0.5 * (1 + contrast * np.sin(along[None] - phases))).astype(np.float32)


#: Scenes of the speed table: name and frames (n, width, height). The sinusoids give the full
#: davis346 model about 0.15 and 0.5 events a pixel a frame.
SCENES = (
    ("disk", partial(disk_frames, grain=0.0)),
    ("disk + 1% grain: every pixel changes", partial(disk_frames, grain=0.01)),
    (
        "sinusoid: 0.15 events/pixel/frame",
        partial(sinusoid_frames, phase_step_rad=0.14, contrast=0.5),
    ),
    (
        "sinusoid: 0.5 events/pixel/frame",
        partial(sinusoid_frames, phase_step_rad=0.55, contrast=0.85),
    ),
)


def numpy_esim(frames: np.ndarray, times_us: np.ndarray) -> int:
    """ESIM, vectorised over pixels: crossings of ref + k C between frames at interpolated times,
    the reference advanced by C per crossing; events sorted by (t, y, x) like pecs's."""
    height, width = frames.shape[1:]
    ref = np.log(frames[0].ravel().astype(np.float64) + EPS)
    prev = ref.copy()
    total = 0
    for k in range(1, len(frames)):
        now = np.log(frames[k].ravel().astype(np.float64) + EPS)
        t0, dt = times_us[k - 1], times_us[k] - times_us[k - 1]
        parts = []
        for sign in (1.0, -1.0):
            n = np.floor(sign * (now - ref) / THETA)
            n[(sign * (now - prev) <= 0) | (n < 0)] = 0
            pixels = np.flatnonzero(n)
            counts = n[pixels].astype(np.int64)
            which = np.repeat(pixels, counts)
            step = np.arange(counts.sum()) - np.repeat(np.cumsum(counts) - counts, counts) + 1
            level = ref[which] + sign * step * THETA
            t = np.round(t0 + (level - prev[which]) / (now[which] - prev[which]) * dt).astype(
                np.int64
            )
            parts.append((t, which, np.full(which.size, sign > 0, np.int8)))
            ref[pixels] += sign * counts * THETA
        t = np.concatenate([p[0] for p in parts])
        which = np.concatenate([p[1] for p in parts])
        pol = np.concatenate([p[2] for p in parts])
        x, y = which % width, which // width
        order = np.lexsort((x, y, t))
        batch = (t[order], x[order].astype(np.uint16), y[order].astype(np.uint16), pol[order])
        total += batch[0].size
        prev = now
    return total


def pecs_events(frames: np.ndarray, times_us: np.ndarray, config: pecs.SensorConfig) -> int:
    sensor = pecs.EventSensor(config)
    total = sum(sensor.feed(f, int(t)).num_rows for f, t in zip(frames, times_us))
    return total + sensor.flush().num_rows


def best_interleaved(repeats: int, *runs, clock=time.perf_counter):  # noqa: ANN001, ANN002, ANN201
    """Best time (by `clock`) and result of each zero-argument run; the runs take turns, round
    after round, so a slow spell of a shared machine hits all of them rather than one."""
    best, results = [float("inf")] * len(runs), [None] * len(runs)
    for _ in range(repeats):
        for i, run in enumerate(runs):
            start = clock()
            results[i] = run()
            best[i] = min(best[i], clock() - start)
    return best, results


def speed(n_frames: int, clock=time.perf_counter) -> None:  # noqa: ANN001
    """The speed table. "pecs full" is the davis346 preset as users get it, its readout included
    (whose 12 M events/s bus caps the sinusoids' output); "pixels" the same preset with every
    readout stage off (`NO_READOUT`): the pixel model alone, all its events out. Timed by
    `clock`: wall time, or the process's CPU time (`--cpu-time`: one thread, RAYON_NUM_THREADS=1,
    on a machine that other work shares)."""
    print(
        f"{'scene':<44}{'numpy ESIM':>11}{'pecs esim':>11}{'ratio':>7}{'pecs full':>11}{'ratio':>7}"
        f"{'pixels':>11}{'ratio':>7}{'events':>9}"
    )
    for width, height, frames_here in ((346, 260, n_frames), (1280, 720, max(n_frames // 4, 10))):
        esim = pecs.SensorConfig.preset(
            "esim", width=width, height=height, theta_on=THETA, theta_off=THETA, dark_current=EPS
        )
        full = pecs.SensorConfig.preset("davis346", width=width, height=height)
        pixels = full.replace(**NO_READOUT)
        for name, make_frames in SCENES:
            frames = make_frames(frames_here, width, height)
            times = np.arange(frames_here, dtype=np.int64) * 500
            (t_numpy, t_esim, t_full, t_pixels), (n_numpy, n_esim, n_full, n_pixels) = (
                best_interleaved(
                    REPEATS,
                    partial(numpy_esim, frames, times),
                    partial(pecs_events, frames, times, esim),
                    partial(pecs_events, frames, times, full),
                    partial(pecs_events, frames, times, pixels),
                    clock=clock,
                )
            )
            assert abs(n_esim - n_numpy) <= 1e-4 * n_numpy, (n_esim, n_numpy)  # the same algorithm
            updates = (frames_here - 1) * width * height
            label = f"{width}x{height} x{frames_here} {name}"
            print(
                f"{label:<44}{t_numpy:>10.3f}s{t_esim:>10.3f}s{t_numpy / t_esim:>6.2f}x"
                f"{t_full:>10.3f}s{t_numpy / t_full:>6.2f}x"
                f"{t_pixels:>10.3f}s{t_numpy / t_pixels:>6.2f}x{n_esim:>9}"
            )
            print(
                f"{'   pixel updates per second':<44}{updates / t_numpy / 1e6:>9.0f}M {updates / t_esim / 1e6:>9.0f}M {'':>6}{updates / t_full / 1e6:>9.0f}M {'':>6}{updates / t_pixels / 1e6:>9.0f}M"
            )
            print(
                f"{'   events per second (full, pixels: their own)':<44}{n_numpy / t_numpy / 1e6:>9.1f}M {n_esim / t_esim / 1e6:>9.1f}M {'':>6}{n_full / t_full / 1e6:>9.1f}M {'':>6}{n_pixels / t_pixels / 1e6:>9.1f}M"
                f"  events/pixel/frame: full {n_full / updates:.3f}, pixels {n_pixels / updates:.3f}"
            )


#: Every readout stage off (the sensor as it was before the readout, item 1 of issue 36).
NO_READOUT = {
    "readout_row_service_ns": 0.0,
    "readout_bus_rate_meps": 0.0,
    "readout_overflow": "queue",
    "readout_queue_depth": 0,
    "timestamp_step_us": 0,
    "erc_rate_hz": 0.0,
}


def readout_cost(n_frames: int) -> None:
    """What the readout (arbiter, bus, drops, timestamp step) and the rate controller add to the
    sensor's time, for the presets that have them, on the scenes above. Target: at most 15 %.
    Measured in the process's CPU time (all threads), best of rounds taken in turn: on a shared
    machine other work changes the wall time of a run far more than the readout does."""
    print(
        f"\n{'readout + filters cost (CPU time)':<44}{'without':>11}{'with':>11}{'cost':>8}"
        f"{'events':>9}"
    )
    for width, height, frames_here in ((346, 260, n_frames), (1280, 720, max(n_frames // 4, 10))):
        for name, grain in (("disk", 0.0), ("disk + 1% grain", 0.01)):
            frames = disk_frames(frames_here, width, height, grain=grain)
            times = np.arange(frames_here, dtype=np.int64) * 500
            for preset in ("davis346", "imx636"):
                on = pecs.SensorConfig.preset(preset, width=width, height=height)
                off = on.replace(**NO_READOUT)
                (t_off, t_on), (_, n_on) = best_interleaved(
                    REPEATS,
                    partial(pecs_events, frames, times, off),
                    partial(pecs_events, frames, times, on),
                    clock=time.process_time,
                )
                label = f"{width}x{height} x{frames_here} {name}, {preset}"
                print(
                    f"{label:<44}{t_off:>10.3f}s{t_on:>10.3f}s{(t_on / t_off - 1) * 100:>7.1f}%"
                    f"{n_on:>9}"
                )


def rss_mib() -> float:
    with open("/proc/self/status") as status:
        for line in status:
            if line.startswith("VmRSS:"):
                return int(line.split()[1]) / 1024
    return float("nan")


def memory(n_frames: int) -> None:
    frames = disk_frames(100)
    sensor = pecs.EventSensor(pecs.SensorConfig.preset("davis346"))
    events = 0
    marks = {n_frames // 10 * i for i in range(1, 11)}
    print(
        f"\nresident memory while {n_frames} frames of 346 x 260 stream through feed (batches dropped):"
    )
    for k in range(n_frames):
        events += sensor.feed(frames[k % 100], k * 500).num_rows
        if k + 1 in marks:
            print(f"  after {k + 1:>6} frames: RSS {rss_mib():7.1f} MiB, {events} events")
    peak = resource.getrusage(resource.RUSAGE_SELF).ru_maxrss / 1024
    print(f"  peak RSS {peak:.1f} MiB")


def main() -> None:
    parser = argparse.ArgumentParser(description=__doc__)
    parser.add_argument("--frames", type=int, default=200)
    parser.add_argument("--memory-frames", type=int, default=10_000)
    parser.add_argument(
        "--cpu-time",
        action="store_true",
        help="time the speed table by the process's CPU time (one thread on a shared machine)",
    )
    args = parser.parse_args()
    speed(args.frames, time.process_time if args.cpu_time else time.perf_counter)
    readout_cost(args.frames)
    memory(args.memory_frames)


if __name__ == "__main__":
    main()
