"""Lens sensor against Mitsuba's perspective sensor on the Cornell box (llvm variant).

Prints, for the same scene, resolution (DAVIS346, 346 x 260) and spp: the time per frame of
each sensor and their ratio (target: realisticlens at most 1.3x perspective); the noise at equal
spp (RMS error against each sensor's own high-spp reference, over the mean); and what tight
(ellipse) exit-pupil sampling saves against sampling the whole bounding box.

    .venv/bin/python benches/bench_lens.py [--spp 16] [--frames 5] [--reference-spp 512]
"""

from __future__ import annotations

import argparse
import math
import statistics
import time

import numpy as np
from pecs._mitsuba import mitsuba
from pecs.lens import Lens, register_realistic_lens

WIDTH, HEIGHT, PITCH_UM = 346, 260, 18.5
LENS, F_NUMBER, FOCUS_M = "wide22", 2.8, 3.9


def scene_dict(mi, sensor: dict, spp: int) -> dict:
    scene = mi.cornell_box()
    base = scene["sensor"]
    sensor = dict(sensor)
    sensor["to_world"] = base["to_world"]
    sensor["film"] = {
        "type": "hdrfilm",
        "width": WIDTH,
        "height": HEIGHT,
        "rfilter": {"type": "box"},
    }
    sensor["sampler"] = {"type": "independent", "sample_count": spp}
    scene["sensor"] = sensor
    scene["integrator"] = {"type": "path", "max_depth": 6}
    return scene


def sensors(efl_mm: float) -> dict[str, dict]:
    film_h_mm = HEIGHT * PITCH_UM * 1e-3
    fov_deg = 2 * math.degrees(math.atan(film_h_mm / 2 / efl_mm))
    lens = {
        "type": "realisticlens",
        "lens": LENS,
        "efl_mm": efl_mm,
        "f_number": F_NUMBER,
        "focus_m": FOCUS_M,
        "pixel_pitch_um": PITCH_UM,
    }
    return {
        "perspective": {"type": "perspective", "fov": fov_deg, "fov_axis": "y"},
        "realisticlens": lens,
        "realisticlens (box pupil)": {**lens, "tight_pupil": False},
    }


def time_frames(mi, scene, frames: int) -> float:
    mi.render(scene, seed=0)  # compile the kernel once
    times = []
    for _ in range(frames):
        start = time.perf_counter()
        np.array(mi.render(scene, seed=0))
        times.append(time.perf_counter() - start)
    return statistics.median(times)


def noise(mi, scene_low, scene_ref, seeds: int = 3) -> float:
    """RMS error of low-spp frames against the high-spp reference, over the reference mean."""
    ref = np.array(mi.render(scene_ref, seed=1000)).mean(axis=2)
    errors = [
        np.sqrt(np.mean((np.array(mi.render(scene_low, seed=s)).mean(axis=2) - ref) ** 2))
        for s in range(seeds)
    ]
    return float(np.mean(errors) / ref.mean())


def main() -> None:
    parser = argparse.ArgumentParser(
        description=__doc__, formatter_class=argparse.RawDescriptionHelpFormatter
    )
    parser.add_argument("--spp", type=int, default=16)
    parser.add_argument("--frames", type=int, default=5)
    parser.add_argument("--reference-spp", type=int, default=512)
    args = parser.parse_args()
    mi = mitsuba()
    register_realistic_lens()
    film_h_mm = HEIGHT * PITCH_UM * 1e-3
    # The focal length whose field matches the Cornell box camera's 39.3 deg vertical field.
    efl_mm = film_h_mm / 2 / math.tan(math.radians(39.3077 / 2))
    print(
        f"Mitsuba {mi.__version__}, variant {mi.variant()}, {WIDTH}x{HEIGHT}, {args.spp} spp, Cornell box, path depth 6"
    )
    print(
        f"lens: {LENS} scaled to {efl_mm:.2f} mm, f/{F_NUMBER}, focus {FOCUS_M} m, pixel {PITCH_UM} um"
    )
    results = {}
    for name, sensor in sensors(efl_mm).items():
        start = time.perf_counter()
        scene = mi.load_dict(scene_dict(mi, sensor, args.spp))
        load_s = time.perf_counter() - start
        frame_s = time_frames(mi, scene, args.frames)
        ref = mi.load_dict(scene_dict(mi, sensor, args.reference_spp))
        rel_noise = noise(mi, scene, ref)
        results[name] = (frame_s, rel_noise)
        print(
            f"{name:28s} load {load_s:6.2f} s   frame {frame_s * 1e3:7.1f} ms   noise at {args.spp} spp {rel_noise:.4f}"
        )
    persp_s, persp_noise = results["perspective"]
    lens_s, lens_noise = results["realisticlens"]
    box_s, box_noise = results["realisticlens (box pupil)"]
    print(f"time ratio realisticlens / perspective: {lens_s / persp_s:.2f}x (target <= 1.3x)")
    print(f"noise ratio realisticlens / perspective at equal spp: {lens_noise / persp_noise:.2f}")
    saving = 1 - (lens_noise / box_noise) ** 2
    print(
        f"tight pupil sampling: variance {saving * 100:+.1f}% against the box (= spp saved at equal noise)"
    )
    lens = Lens.builtin(LENS).scaled_to(efl_mm).with_f_number(F_NUMBER).focused(FOCUS_M)
    bounds = lens.exit_pupil_bounds(
        0.5 * math.hypot(WIDTH, HEIGHT) * PITCH_UM * 1e-3, (360.0, 830.0)
    )
    used = bounds.area_mm2(False) > 0
    area_ratio = bounds.area_mm2(True)[used] / bounds.area_mm2(False)[used]
    print(
        f"tight region area / box area over the film-radius bins: mean {area_ratio.mean():.3f}, min {area_ratio.min():.3f}"
    )


if __name__ == "__main__":
    main()
