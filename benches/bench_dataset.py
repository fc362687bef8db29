"""Dataset throughput: the example spec (`pecs dataset example`) in one process, then on a local
Ray with 1 and 2 workers, in the same run.

Prints sequences per hour and events per second of each, and Ray's overhead per sequence against
the same sequences in one process (baseline: `run_dataset(workers=1)`, sequential engine, in a
process that has run them once already): the difference of wall times divided by the sequence
count, and the ratio of wall times. Ray's start (`ray.init`) is timed apart, since a long dataset
pays it once; its workers' first import of pecs and Mitsuba is in their times.

    python benches/bench_dataset.py [--repeat K]   # K copies of each sequence (steadier figures)
"""

from __future__ import annotations

import argparse
import dataclasses
import tempfile
import time
from pathlib import Path

from pecs.dataset import example_spec_text, parse_spec, run_dataset
from pecs.dataset.spec import DatasetSpec


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


def main() -> None:
    parser = argparse.ArgumentParser(description=__doc__.splitlines()[0])
    parser.add_argument("--repeat", type=int, default=1, help="copies of each sequence")
    args = parser.parse_args()
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
