"""Rendering speed: frames of the demo scene at 346 x 260, simulated seconds, and `pecs demo`.

Prints, from one run:
- render time per frame (checkerboard scene, 346 x 260, QE spectral film) at 4 and 16 spp, next to
  the same frame rendered with Mitsuba's plain RGB film (hdrfilm, same scene and spp): the cost
  of the spectral QE film, measured in this run;
- wall time per simulated second of the whole pipeline (render + event sensor + Parquet) at
  1000 frames per second, and its ratio to EventTracer's published 1.12 min per simulated second
  at 360p on a GPU (the figure its authors published; 360p read as 640 x 360, so also per pixel);
- the wall time of `pecs demo` in a fresh process (its limit: 3 minutes on two cores).

Run: .venv/bin/python benches/bench_render.py [--frames N]
"""

from __future__ import annotations

import argparse
import subprocess
import sys
import tempfile
import time
from pathlib import Path

import numpy as np
import pecs

EVENTTRACER_S_PER_SIMULATED_S = 1.12 * 60.0
EVENTTRACER_PIXELS = 640 * 360
FULL = {"width": 346, "height": 260}


def render_seconds_per_frame(spp: int, frames: int, rgb: bool) -> float:
    """Median render time of `frames` frames of the moving checkerboard (after a warm-up)."""
    sim = pecs.Simulation("checkerboard", spp=spp, rate_hz=1000.0, sensor=FULL)
    renderer = sim.renderer
    mi = renderer.mi
    sensor = renderer.sensor
    if rgb:
        params = mi.traverse(sensor)
        sensor = mi.load_dict(
            {
                "type": "perspective",
                "fov": float(np.ravel(params["x_fov"])[0]),
                "to_world": mi.ScalarTransform4f(renderer.camera_pose(0.0)),
                "film": {
                    "type": "hdrfilm",
                    "width": 346,
                    "height": 260,
                    "rfilter": {"type": "box"},
                },
                "sampler": {"type": "independent", "sample_count": spp},
            }
        )
    times = []
    for k in range(frames + 1):
        renderer.set_time(k * 1e-3)
        start = time.perf_counter()
        image = mi.render(renderer.scene, sensor=sensor, integrator=renderer.integrator, spp=spp)
        np.asarray(image)  # wait for the kernel
        times.append(time.perf_counter() - start)
    return float(np.median(times[1:]))


def pipeline_seconds_per_simulated_second(duration_s: float) -> tuple[float, int]:
    sim = pecs.Simulation("checkerboard", spp=4, rate_hz=1000.0, duration_s=duration_s, sensor=FULL)
    with tempfile.TemporaryDirectory() as out:
        _ = sim.renderer  # load the scene outside the timing: a one-off per scene
        start = time.perf_counter()
        summary = sim.run(out)
        wall = time.perf_counter() - start
    return wall / duration_s, summary.events


def demo_wall_seconds() -> float:
    with tempfile.TemporaryDirectory() as out:
        start = time.perf_counter()
        subprocess.run(
            [sys.executable, "-m", "pecs", "demo", "-o", str(Path(out) / "demo"), "--quiet"],
            check=True,
            capture_output=True,
        )
        return time.perf_counter() - start


def main() -> None:
    parser = argparse.ArgumentParser(description=__doc__.splitlines()[0])
    parser.add_argument("--frames", type=int, default=10, help="frames timed per setting")
    parser.add_argument("--duration", type=float, default=0.05, help="simulated seconds")
    args = parser.parse_args()
    print(f"variant: {pecs.Simulation('checkerboard').renderer.mi.variant()}")
    for spp in (4, 16):
        qe = render_seconds_per_frame(spp, args.frames, rgb=False)
        rgb = render_seconds_per_frame(spp, args.frames, rgb=True)
        print(
            f"346x260 {spp:2d} spp: QE spectral film {qe * 1e3:7.1f} ms/frame, "
            f"RGB hdrfilm {rgb * 1e3:7.1f} ms/frame, ratio {qe / rgb:.2f}"
        )
    per_s, events = pipeline_seconds_per_simulated_second(args.duration)
    pixels = FULL["width"] * FULL["height"]
    print(
        f"pipeline 346x260, 4 spp, 1000 fps: {per_s:.1f} s wall per simulated second "
        f"({events} events in {args.duration} s)"
    )
    ratio = EVENTTRACER_S_PER_SIMULATED_S / per_s
    per_pixel = ratio * EVENTTRACER_PIXELS / pixels
    print(
        f"EventTracer (published, GPU, 360p): {EVENTTRACER_S_PER_SIMULATED_S:.0f} s per simulated "
        f"second; EventTracer / pecs = {ratio:.2f} ({per_pixel:.2f} per pixel; > 1: pecs faster)"
    )
    print(f"pecs demo wall time: {demo_wall_seconds():.1f} s (limit 180 s)")


if __name__ == "__main__":
    main()
