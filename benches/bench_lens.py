"""Lens sensor against Mitsuba's perspective sensor on the Cornell box (best variant here).

Same scene, resolution (DAVIS346, 346 x 260 px of 18.5 µm) and spp for every sensor; a
single-channel spectral film weighted by the PECS relative QE curve (the pecs pipeline's film)
and, for colour, an RGB hdrfilm. Prints:
  - time per frame (median of --frames renders after a warm-up) and the ratio
    realisticlens / perspective (target: at most 1.3x);
  - noise at equal spp from two independent renders: the RMS per-pixel standard deviation over
    the image mean (dominated by the light's pixels) and the median relative standard deviation
    over pixels (a typical surface pixel);
  - what tight (ellipse) exit-pupil sampling saves against the whole bounding box, and what the
    hero wavelength costs (dispersion off keeps all four wavelengths of a ray).

    .venv/bin/python benches/bench_lens.py [--spp 16] [--frames 5]
"""

from __future__ import annotations

import argparse
import math
import statistics
import time

import numpy as np
from pecs._mitsuba import mitsuba
from pecs.lens import register_realistic_lens

WIDTH, HEIGHT, PITCH_UM = 346, 260, 18.5
LENS, F_NUMBER, FOCUS_M = "wide22", 2.8, 3.9
# PECS relative QE, 400-700 nm in 10 nm steps (reference/optics-and-spectra.md).
QE = [
    0.82,
    0.85,
    0.87,
    0.88,
    0.92,
    0.95,
    0.96,
    0.96,
    0.98,
    1.00,
    0.99,
    1.00,
    0.99,
    1.00,
    0.99,
    1.00,
]
QE += [0.99, 0.98, 0.98, 0.97, 0.95, 0.94, 0.92, 0.92, 0.87, 0.86, 0.85, 0.82, 0.79, 0.78, 0.76]


def film(kind: str) -> dict:
    base = {"width": WIDTH, "height": HEIGHT, "rfilter": {"type": "box"}}
    if kind == "rgb":
        return {"type": "hdrfilm", **base}
    qe = [(400.0 + 10.0 * k, value) for k, value in enumerate(QE)]
    return {"type": "specfilm", **base, "qe": {"type": "spectrum", "value": qe}}


def scene_dict(mi, sensor: dict, spp: int, film_kind: str, sampler: str = "independent") -> dict:
    scene = mi.cornell_box()
    sensor = dict(sensor)
    sensor["to_world"] = scene["sensor"]["to_world"]
    sensor["film"] = film(film_kind)
    sensor["sampler"] = {"type": sampler, "sample_count": spp}
    scene["sensor"] = sensor
    scene["integrator"] = {"type": "path", "max_depth": 6}
    return scene


def frame_times(mi, scenes: list, frames: int) -> list[list[float]]:
    """Seconds per frame of each scene, rendered in turn (A, B, C, A, B, C, ...) so that a
    change of machine load hits every scene alike; one warm-up render each compiles kernels."""
    for scene in scenes:
        np.array(mi.render(scene, seed=0))
    times: list[list[float]] = [[] for _ in scenes]
    for _ in range(frames):
        for k, scene in enumerate(scenes):
            start = time.perf_counter()
            np.array(mi.render(scene, seed=0))
            times[k].append(time.perf_counter() - start)
    return times


def relative_noise(mi, scene) -> tuple[float, float]:
    """From two independent frames: the RMS per-pixel standard deviation over the image mean
    (dominated by the brightest pixels, the light), and the median over pixels of the standard
    deviation over the pixel's value (the typical surface pixel)."""
    a = np.array(mi.render(scene, seed=11)).mean(axis=2)
    b = np.array(mi.render(scene, seed=12)).mean(axis=2)
    sd = np.abs(a - b) / np.sqrt(2)
    mean = 0.5 * (a + b)
    rms = float(np.sqrt(np.mean(sd**2)) / mean.mean())
    median = float(np.median(sd[mean > 0] / mean[mean > 0]))
    return rms, median


def main() -> None:
    parser = argparse.ArgumentParser(
        description=__doc__, formatter_class=argparse.RawDescriptionHelpFormatter
    )
    parser.add_argument("--spp", type=int, default=16)
    parser.add_argument("--frames", type=int, default=9)
    parser.add_argument(
        "--sampler",
        default="independent",
        help="Mitsuba sampler (independent, ldsampler, multijitter)",
    )
    args = parser.parse_args()
    mi = mitsuba()
    register_realistic_lens()
    film_h_mm = HEIGHT * PITCH_UM * 1e-3
    # The focal length whose vertical field matches the Cornell box camera (39.3 deg).
    efl_mm = film_h_mm / 2 / math.tan(math.radians(39.3077 / 2))
    fov_deg = 2 * math.degrees(math.atan(film_h_mm / 2 / efl_mm))
    lens = {
        "type": "realisticlens",
        "lens": LENS,
        "efl_mm": efl_mm,
        "f_number": F_NUMBER,
        "focus_m": FOCUS_M,
        "pixel_pitch_um": PITCH_UM,
    }
    runs = [
        ("perspective", {"type": "perspective", "fov": fov_deg, "fov_axis": "y"}, "qe"),
        ("realisticlens", lens, "qe"),
        ("realisticlens, box pupil", {**lens, "tight_pupil": False}, "qe"),
        ("realisticlens, no dispersion", {**lens, "dispersion": False}, "qe"),
        ("perspective, RGB film", {"type": "perspective", "fov": fov_deg, "fov_axis": "y"}, "rgb"),
        ("realisticlens, RGB film", lens, "rgb"),
    ]
    print(
        f"Mitsuba {mi.__version__} {mi.variant()}: Cornell box, path depth 6, {WIDTH}x{HEIGHT}, {args.spp} spp"
    )
    print(
        f"lens {LENS} scaled to {efl_mm:.2f} mm, f/{F_NUMBER}, focus {FOCUS_M} m, {PITCH_UM} um pixels"
    )
    results = {}
    scenes = {}
    for name, sensor, film_kind in runs:
        start = time.perf_counter()
        scenes[name] = mi.load_dict(scene_dict(mi, sensor, args.spp, film_kind, args.sampler))
        load_s = time.perf_counter() - start
        noise = relative_noise(mi, scenes[name])
        results[name] = noise
        print(f"  {name:30s} load {load_s:5.2f} s  noise rms {noise[0]:.4f}  median {noise[1]:.4f}")
    timed = ["perspective", "realisticlens", "realisticlens, no dispersion"]
    times = frame_times(mi, [scenes[name] for name in timed], args.frames)
    for name, t in zip(timed, times, strict=True):
        print(
            f"  {name:30s} frame median {statistics.median(t) * 1e3:7.1f} ms  min {min(t) * 1e3:7.1f} ms"
        )
    ratios = [lens / persp for persp, lens in zip(times[0], times[1], strict=True)]
    print(
        f"time per frame, realisticlens / perspective: median of interleaved pairs "
        f"{statistics.median(ratios):.2f}x, best frames {min(times[1]) / min(times[0]):.2f}x "
        f"(target <= 1.3x)"
    )
    p_n, l_n = results["perspective"], results["realisticlens"]
    for k, label in ((0, "rms over the image mean"), (1, "median pixel")):
        box_n = results["realisticlens, box pupil"][k]
        flat_n = results["realisticlens, no dispersion"][k]
        rgb_p, rgb_l = (
            results["perspective, RGB film"][k],
            results["realisticlens, RGB film"][k],
        )
        print(f"noise at equal spp ({label}):")
        print(f"  realisticlens / perspective, QE film: {l_n[k] / p_n[k]:.2f}x")
        print(f"  tight pupil: {(1 - (l_n[k] / box_n) ** 2) * 100:.1f}% less variance than the box")
        print(
            f"  hero wavelength: variance x{(l_n[k] / flat_n) ** 2:.2f} against all four wavelengths"
        )
        print(f"  no dispersion / perspective: {flat_n / p_n[k]:.2f}x (pupil sampling alone)")
        print(
            f"  RGB film, realisticlens / perspective: {rgb_l / rgb_p:.2f}x (one wavelength per ray)"
        )


if __name__ == "__main__":
    main()
