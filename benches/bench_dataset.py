"""Dataset throughput: the example spec (`pecs dataset example`) in one process, then on a local
Ray with 1 and 2 workers, in the same run.

Prints sequences per hour and events per second of each, and Ray's overhead per sequence against
the same sequences in one process (baseline: `run_dataset(workers=1)`, sequential engine, in a
process that has run them once already): the difference of wall times divided by the sequence
count, and the ratio of wall times. Ray's start (`ray.init`) is timed apart, since a long dataset
pays it once; its workers' first import of pecs and Mitsuba is in their times.

    python benches/bench_dataset.py [--repeat K]   # K copies of each sequence (steadier figures)

With --steps, the cost of the `objects` generator's scenes instead: per drawn scene (small film,
the scene's spp, noise off, as benches/bench_adaptive.py runs), fixed 2 kHz steps against
adaptive steps by the measured rule and by the exact-motion rule (steps from the image motion
the animation gives), each at the given pixels of motion a step: frames rendered (retries
included) and per simulated second, wall time and sequences per hour of each stepping, and the
events' chamfer distance to a 2 kHz reference rendered with another seed, over the Monte Carlo
floor (the same 2 kHz times with the first seed). Target: 5x fewer frames, within 1.10 of it.

    python benches/bench_dataset.py --steps [--scenes 0,1,2,3] [--size 96] [--spp 16]
        [--duration 0.1] [--fractions 0.5,0.25]
"""

from __future__ import annotations

import argparse
import dataclasses
import math
import tempfile
import time
from dataclasses import dataclass
from pathlib import Path

from bench_adaptive import Run, adaptive_run, events_of, fixed_runs, simulation
from pecs.dataset import example_spec_text, parse_spec, run_dataset
from pecs.dataset.generators import SceneSettings, make_generator, scene_rng
from pecs.dataset.spec import DatasetSpec
from pecs.metrics import compare

#: The fixed steps adaptive ones are measured against: the generator's scenes' max rate.
FIXED_RATE_HZ = 2000.0


def repeated(spec: DatasetSpec, copies: int) -> DatasetSpec:
    """The spec's sequences `copies` times over, renamed (same draws: it is a benchmark)."""
    tasks = [
        dataclasses.replace(task, name=f"{task.name}.{k}", index=k * len(spec.sequences) + i)
        for k in range(copies)
        for i, task in enumerate(spec.sequences)
    ]
    return dataclasses.replace(spec, sequences=tuple(tasks))


def timed_run(spec: DatasetSpec, folder: Path, workers: int, engine: str) -> tuple[float, int]:
    started = time.perf_counter()
    summary = run_dataset(spec, folder, workers=workers, engine=engine)
    wall_s = time.perf_counter() - started
    assert not summary.failed, summary.failed
    return wall_s, summary.events


def report(label: str, sequences: int, wall_s: float, events: int) -> None:
    print(
        f"{label:<28} {wall_s:7.2f} s  {sequences / wall_s * 3600:9.0f} sequences/h  "
        f"{events / wall_s:9.0f} events/s"
    )


@dataclass(frozen=True)
class Stepped:
    """One stepping of one scene: its events' run, wall time and distance to the reference."""

    run: Run
    wall_s: float
    chamfer: float
    count_ratio: float


def generated_scene(index: int, duration_s: float, spp: int, folder: Path) -> str:
    """Scene `index` of the `objects` generator with its default ranges (dataset seed 0),
    written into `folder`: the scene TOML's path (adaptive steps, 100 to 2000 Hz, fraction 0.5)."""
    generator = make_generator("objects", {})
    description = generator.describe(scene_rng(0, index), duration_s)
    settings = SceneSettings(duration_s=duration_s, spp=spp)
    return str(generator.write(description, folder / f"scene_{index}", settings))


def stepping_costs(
    scene: str, spp: int, duration_s: float, width: int, fractions: list[float]
) -> dict[str, Stepped]:
    """Fixed 2 kHz steps (the floor's run), adaptive steps by the measured and the exact rule
    at each of `fractions`, against the reference."""
    reference_sim = simulation(scene, spp, duration_s, width, rate_hz=FIXED_RATE_HZ, seed=1)
    reference, _ = events_of(reference_sim, reference_sim.frames())
    size = (width, reference_sim.geometry.height)
    timed: dict[str, tuple[Run, float]] = {}
    started = time.perf_counter()
    fixed = fixed_runs(
        simulation(scene, spp, duration_s, width, rate_hz=FIXED_RATE_HZ), FIXED_RATE_HZ
    )
    timed[fixed[0].name] = (fixed[0], time.perf_counter() - started)
    # every 2nd, 4th, ... frame of the same renders: fixed steps at 1000, 500, ... Hz
    for run in fixed[1:]:
        timed[run.name] = (run, math.nan)
    for fraction in fractions:
        for rule in ("measured", "exact"):
            name = f"{rule} {fraction:g}"
            sim = simulation(scene, spp, duration_s, width)
            # the rules' pixels of image motion a step
            stepping = dataclasses.replace(sim.spec.time, threshold_fraction=fraction)
            sim.spec = dataclasses.replace(sim.spec, time=stepping)
            started = time.perf_counter()
            run = adaptive_run(name, sim, None, exact_motion=rule == "exact")
            timed[name] = (run, time.perf_counter() - started)
    costs = {}
    for name, (run, wall_s) in timed.items():
        distance = compare(run.events, reference, normalize="sensor", sensor_size=size).chamfer
        costs[name] = Stepped(run, wall_s, distance, run.events.num_rows / reference.num_rows)
    return costs


def bench_steps(
    scenes: list[int], width: int, spp: int, duration_s: float, fractions: list[float]
) -> None:
    print(
        f"objects generator, scenes {scenes} (default ranges): {width} px wide, {spp} spp, "
        f"{duration_s} s; reference: fixed {FIXED_RATE_HZ:g} Hz, other seed"
    )
    print(
        f"{'scene':<6}{'stepping':<20}{'frames':>7}{'frames/s':>9}{'wall s':>8}{'seq/h':>7}"
        f"{'chamfer':>9}{'/floor':>8}{'count':>7}{'saved':>7}"
    )
    totals: dict[str, int] = {}
    worst: dict[str, float] = {}
    fewest: dict[str, float] = {}  # the least saving of a scene
    with tempfile.TemporaryDirectory() as scratch:
        for index in scenes:
            scene = generated_scene(index, duration_s, spp, Path(scratch))
            costs = stepping_costs(scene, spp, duration_s, width, fractions)
            floor = costs[f"fixed {FIXED_RATE_HZ:g} Hz"]
            for name, cost in costs.items():
                frames = cost.run.frames
                totals[name] = totals.get(name, 0) + frames
                worst[name] = max(worst.get(name, 0.0), cost.chamfer / floor.chamfer)
                fewest[name] = min(fewest.get(name, math.inf), floor.run.frames / frames)
                print(
                    f"{index:<6}{name:<20}{frames:>7}{frames / duration_s:>9.0f}"
                    f"{cost.wall_s:>8.1f}{3600 / cost.wall_s:>7.0f}{cost.chamfer:>9.3f}"
                    f"{cost.chamfer / floor.chamfer:>8.3f}{cost.count_ratio:>7.3f}"
                    f"{floor.run.frames / frames:>6.1f}x"
                )
    fixed_total = totals.pop(f"fixed {FIXED_RATE_HZ:g} Hz")
    for name, total in totals.items():
        if name.startswith("fixed"):
            continue
        print(
            f"{name}: {fixed_total / total:.1f}x fewer frames than {FIXED_RATE_HZ:g} Hz over "
            f"{len(scenes)} scenes (at least {fewest[name]:.1f}x), chamfer at most "
            f"{worst[name]:.3f} of the floor (target: 5x, 1.10)"
        )


def main() -> None:
    parser = argparse.ArgumentParser(description=__doc__.splitlines()[0])
    parser.add_argument("--repeat", type=int, default=1, help="copies of each sequence")
    parser.add_argument("--steps", action="store_true", help="fixed vs adaptive steps instead")
    parser.add_argument("--scenes", default="0,1,2,3", help="--steps: generated scenes' indices")
    parser.add_argument(
        "--fractions", default="0.5", help="--steps: the adaptive rules' pixels of motion a step"
    )
    parser.add_argument("--size", type=int, default=96, help="--steps: film width in pixels")
    parser.add_argument("--spp", type=int, default=16, help="--steps: samples per pixel")
    parser.add_argument("--duration", type=float, default=0.1, help="--steps: seconds a scene")
    args = parser.parse_args()
    if args.steps:
        scenes = [int(index) for index in args.scenes.split(",")]
        fractions = [float(fraction) for fraction in args.fractions.split(",")]
        bench_steps(scenes, args.size, args.spp, args.duration, fractions)
        return
    spec = repeated(parse_spec(example_spec_text()), args.repeat)
    n = len(spec.sequences)
    print(f"example spec: {n} sequences")
    with tempfile.TemporaryDirectory() as scratch:
        root = Path(scratch)
        # Warm-up, not timed: Mitsuba imported here and Dr.Jit's kernels compiled into its disk
        # cache, which every later process (Ray's workers too) reuses.
        run_dataset(spec, root / "warm-up", workers=1, engine="sequential")
        one_wall, events = timed_run(spec, root / "one-process", 1, "sequential")
        report("one process (baseline)", n, one_wall, events)

        import ray

        started = time.perf_counter()
        ray.init(num_cpus=2, include_dashboard=False, log_to_driver=False)
        print(f"ray.init (local, 2 CPUs)     {time.perf_counter() - started:7.2f} s")
        try:
            walls = {}
            for workers in (1, 2):
                wall_s, ray_events = timed_run(spec, root / f"ray-{workers}", workers, "ray")
                assert ray_events == events, (ray_events, events)
                walls[workers] = wall_s
                report(f"ray, {workers} worker{'s' if workers > 1 else ''}", n, wall_s, events)
        finally:
            ray.shutdown()
    overhead_s = (walls[1] - one_wall) / n
    print(
        f"ray overhead per sequence (1 worker vs one process): {overhead_s * 1000:+.0f} ms; "
        f"wall ratio ray-1 / one process: {walls[1] / one_wall:.2f}x; "
        f"speed-up ray-2 / ray-1: {walls[1] / walls[2]:.2f}x"
    )


if __name__ == "__main__":
    main()
