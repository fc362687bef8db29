"""Adaptive time steps: frames rendered and event-time error against a fixed high rate.

For each scene (small film, low spp, the sensor's random noise off and its mismatch seed fixed,
so that runs differ only by their frame times and Monte Carlo noise):
- the reference: fixed steps at the scene's `max_rate_hz`, rendered with another sampler seed,
  so that no run shares its Monte Carlo noise (a run at the same times but the first seed
  measures that noise floor);
- fixed steps at max_rate and max/2, max/4, ... (every 2nd, 4th, ... frame of one render pass);
- adaptive steps with ESIM's rule (largest |Delta L| over pixels: the baseline) and with pecs's
  (`AdaptiveStepper.change`: the image motion measured over blocks, noise removed) at the
  scene's `threshold_fraction` (pixels of motion per step) and at a half and a quarter of it.
Each run is compared with the reference: chamfer and Gaussian distance in sensor normalisation
(`pecs.metrics`: t over the window, x / width, y / height) and the event-count ratio. Printed:
frames rendered (rejected retries included), the distances, the count ratio, and "saved": the
frames fixed steps need to come as close to the reference as the adaptive run (chamfer,
interpolated linearly between the fixed rates), over the adaptive run's frames: above 1 where
adaptive steps beat fixed ones at equal error.

At low spp most events of moving parts are Monte Carlo noise, and their number grows with the
frame rate (a finer sampling of the noise's path): on trees_wind at 64 x 36, 8 spp gives 5954
events at 2000 Hz and 0.715 of them at 125 Hz; 128 spp gives 926 and 0.914. A fixed-rate
reference at low spp is then no ground truth; run with a high --spp on a small film to see the
stepping.

Run: .venv/bin/python benches/bench_adaptive.py [--scenes room,scenes/trees_wind/scene.toml]
     [--spp 8] [--duration 0.25] [--size 160]
(minutes: each scene renders 2 x duration x max_rate frames for the fixed runs).
"""

from __future__ import annotations

import argparse
import dataclasses
from collections.abc import Callable, Iterator
from dataclasses import dataclass

import numpy as np
import pecs
import pyarrow as pa
from pecs.config import NOISE_OFF
from pecs.metrics import compare
from pecs.render.simulation import Frame
from pecs.render.time_stepping import max_log_change
from pecs.sensor import EventSensor

# The pixel circuit as the scene's preset has it, without its random noise: two runs that
# differ only in their frame times then differ only by the stepping.
QUIET = {**NOISE_OFF, "jitter_us": 0.0}
SUBSAMPLING = (2, 4, 8, 16)


@dataclass(frozen=True)
class Run:
    """Events of one stepping and what it cost."""

    name: str
    frames: int
    events: pa.Table


def simulation(
    scene: str, spp: int, duration_s: float, width: int, **kw: object
) -> pecs.Simulation:
    """The scene on a film `width` pixels wide, same field of view, noise off, mismatch seed 0."""
    geometry = pecs.Simulation(scene).geometry
    scale = width / geometry.width
    sensor = {
        "width": width,
        "height": round(geometry.height * scale),
        "pixel_pitch_um": geometry.pitch_um / scale,
        "seed": 0,
        **QUIET,
    }
    return pecs.Simulation(scene, spp=spp, duration_s=duration_s, sensor=sensor, **kw)


def events_of(sim: pecs.Simulation, frames: Iterator[Frame]) -> tuple[pa.Table, int]:
    """Feed frames to a fresh sensor of the simulation's configuration; (events, frames)."""
    sensor, batches, count = EventSensor(sim.sensor_config), [], 0
    for frame in frames:
        batches.append(sensor.feed(frame.photocurrent_pa, frame.t_us))
        count += 1
    batches.append(sensor.flush())
    return pa.Table.from_batches(batches), count


def fixed_runs(sim: pecs.Simulation, max_rate_hz: float) -> list[Run]:
    """Fixed steps at max_rate_hz and at max/k from the same renders."""
    sensors = {k: EventSensor(sim.sensor_config) for k in (1, *SUBSAMPLING)}
    batches: dict[int, list[pa.RecordBatch]] = {k: [] for k in sensors}
    fed = dict.fromkeys(sensors, 0)
    frames = list(sim.frames())  # the fixed rate of the Simulation: max_rate_hz
    for index, frame in enumerate(frames):
        last = index == len(frames) - 1
        for k, sensor in sensors.items():
            if index % k == 0 or last:
                batches[k].append(sensor.feed(frame.photocurrent_pa, frame.t_us))
                fed[k] += 1
    runs = []
    for k, sensor in sensors.items():
        batches[k].append(sensor.flush())
        name = f"fixed {max_rate_hz / k:g} Hz"
        runs.append(Run(name, fed[k], pa.Table.from_batches(batches[k])))
    return runs


def adaptive_run(
    name: str,
    sim: pecs.Simulation,
    change_of: Callable[[np.ndarray, np.ndarray], float] | None,
    exact_motion: bool = False,
) -> Run:
    """Adaptive stepping with the given change statistic (or the exact-motion rule); frames
    counts every render."""
    renders = 0
    render = sim.renderer.render

    def counted(t_s: float) -> np.ndarray:
        nonlocal renders
        renders += 1
        return render(t_s)

    sim.renderer.render = counted  # type: ignore[method-assign]
    events, _ = events_of(sim, sim._adaptive_frames(change_of, exact_motion=exact_motion))
    return Run(name, renders, events)


def equal_error_frames(fixed: list[Run], errors: list[float], error: float) -> float:
    """Frames fixed steps need for `error`: linear interpolation between the fixed runs (the
    most frames of them when the error is below theirs)."""
    frames = np.array([run.frames for run in fixed], dtype=np.float64)
    order = np.argsort(errors)
    return float(np.interp(error, np.asarray(errors)[order], frames[order]))


def bench_scene(scene: str, spp: int, duration_s: float, width: int) -> None:
    spec = pecs.Simulation(scene).spec.time
    max_rate = spec.max_rate_hz or spec.rate_hz or 1000.0
    reference_sim = simulation(scene, spp, duration_s, width, rate_hz=max_rate, seed=1)
    reference = events_of(reference_sim, reference_sim.frames())
    height = reference_sim.geometry.height
    fixed = fixed_runs(simulation(scene, spp, duration_s, width, rate_hz=max_rate), max_rate)
    adaptive = [
        adaptive_run(
            "adaptive, ESIM max", simulation(scene, spp, duration_s, width), max_log_change
        )
    ]
    fraction = reference_sim.spec.time.threshold_fraction
    for share in (1.0, 0.5, 0.25):
        sim = simulation(scene, spp, duration_s, width)
        time = dataclasses.replace(sim.spec.time, threshold_fraction=fraction * share)
        sim.spec = dataclasses.replace(sim.spec, time=time)
        adaptive.append(adaptive_run(f"adaptive, pecs {fraction * share:g}", sim, None))
    print(
        f"\n{scene}: {width} x {height}, {spp} spp, {duration_s} s; reference: fixed {max_rate:g} Hz,"
        f" other seed ({reference[1]} frames, {reference[0].num_rows} events)"
    )
    print(f"{'run':<22}{'frames':>8}{'chamfer':>10}{'gaussian':>10}{'count':>8}{'saved':>8}")
    compared = {}
    for run in fixed + adaptive:
        compared[run.name] = compare(
            run.events, reference[0], normalize="sensor", sensor_size=(width, height)
        )
    fixed_errors = [compared[run.name].chamfer for run in fixed]
    for run in fixed + adaptive:
        c = compared[run.name]
        saved = ""
        if run in adaptive:
            saved = f"{equal_error_frames(fixed, fixed_errors, c.chamfer) / run.frames:.2f}x"
        count = run.events.num_rows / reference[0].num_rows
        print(
            f"{run.name:<22}{run.frames:>8}{c.chamfer:>10.3f}{c.gaussian:>10.4f}{count:>8.3f}{saved:>8}"
        )
    esim, pecs_run = adaptive[0], adaptive[1]
    floor = compared[fixed[0].name]
    print(
        f"noise floor (fixed {max_rate:g} Hz, first seed): chamfer {floor.chamfer:.3f}; "
        f"frames, ESIM's rule / pecs's at fraction {fraction:g}: "
        f"{esim.frames / pecs_run.frames:.2f}x, fixed {max_rate:g} Hz / pecs's: "
        f"{fixed[0].frames / pecs_run.frames:.2f}x (chamfer {compared[pecs_run.name].chamfer:.3f})"
    )


def main() -> None:
    parser = argparse.ArgumentParser(description=__doc__.splitlines()[0])
    parser.add_argument("--scenes", default="room,scenes/trees_wind/scene.toml")
    parser.add_argument("--spp", type=int, default=8)
    parser.add_argument("--duration", type=float, default=0.25)
    parser.add_argument("--size", type=int, default=160, help="film width in pixels")
    args = parser.parse_args()
    for scene in args.scenes.split(","):
        bench_scene(scene, args.spp, args.duration, args.size)


if __name__ == "__main__":
    main()
