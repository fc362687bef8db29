"""Events that lens ghosts add: the headlight scene with ghosts and without (docs/ghosts.png).

Renders scenes/headlight at 346 x 260 over a window (default 60 ms, the scene's 1000 Hz steps
and spp) twice, with the sensor's random noise off so that every event comes from the light,
and counts the events of each run and those of the ghost run in pixels where the run without
ghosts has none (away from the lamps' own images and the road they light). Draws the ghosts'
photocurrent in the first frame (with minus without, log scale) and both event windows to
`--out` (default /tmp/ghosts.png).

    .venv/bin/python benches/fig_ghosts.py [--window-s 0.06] [--out docs/ghosts.png]
"""

from __future__ import annotations

import argparse
import dataclasses
from pathlib import Path

import numpy as np
import pyarrow as pa
from pecs.config import NOISE_OFF
from pecs.render import Simulation, load_scene

SCENE = Path(__file__).resolve().parents[1] / "scenes" / "headlight" / "scene.toml"


def run(ghosts: bool, window_s: float) -> tuple[np.ndarray, pa.Table]:
    spec = load_scene(SCENE)
    if not ghosts:
        spec = dataclasses.replace(spec, optics=dataclasses.replace(spec.optics, ghosts=None))
    sim = Simulation(spec, duration_s=window_s, sensor=dict(NOISE_OFF))
    first = next(iter(sim.frames())).photocurrent_pa
    events = pa.Table.from_batches(list(sim.event_batches()))
    return first, events


def counts(events: pa.Table, width: int, height: int) -> np.ndarray:
    x, y = events.column("x").to_numpy(), events.column("y").to_numpy()
    return np.bincount(y.astype(np.int64) * width + x, minlength=width * height).reshape(
        height, width
    )


def main() -> None:
    parser = argparse.ArgumentParser(description=__doc__.splitlines()[0])
    parser.add_argument("--window-s", type=float, default=0.06)
    parser.add_argument("--out", default="/tmp/ghosts.png")
    args = parser.parse_args()
    frame, with_ghosts = run(True, args.window_s)
    plain, without = run(False, args.window_s)
    height, width = frame.shape
    per_pixel_with = counts(with_ghosts, width, height)
    per_pixel_without = counts(without, width, height)
    away = per_pixel_without == 0
    print(f"headlight scene, {width} x {height}, {args.window_s * 1e3:g} ms, noise off")
    print(f"  events without ghosts  {without.num_rows}")
    print(f"  events with ghosts     {with_ghosts.num_rows}")
    print(
        f"  ghost events away from the direct images: {int(per_pixel_with[away].sum())} "
        f"in {int(np.count_nonzero(per_pixel_with[away]))} pixels"
    )
    import matplotlib

    matplotlib.use("Agg")
    import matplotlib.pyplot as plt

    fig, axes = plt.subplots(1, 3, figsize=(10.5, 2.9))
    ghost = np.maximum(frame.astype(np.float64) - plain, 0.0)
    log = np.log10(np.maximum(ghost, ghost.max() * 1e-4))
    axes[0].imshow(log, cmap="magma")
    axes[0].set_title("the ghosts' photocurrent, first frame (log)", fontsize=9)
    for ax, table, title in (
        (axes[1], without, f"events, no ghosts ({without.num_rows})"),
        (axes[2], with_ghosts, f"events, ghosts traced ({with_ghosts.num_rows})"),
    ):
        image = np.full((height, width, 3), 1.0)
        x, y = table.column("x").to_numpy(), table.column("y").to_numpy()
        on = table.column("p").to_numpy() == 1
        image[y[on], x[on]] = (0.1, 0.3, 0.9)
        image[y[~on], x[~on]] = (0.9, 0.2, 0.1)
        ax.imshow(image)
        ax.set_title(title, fontsize=9)
    for ax in axes:
        ax.set_xticks([])
        ax.set_yticks([])
    fig.tight_layout()
    fig.savefig(args.out, dpi=80)
    print(f"  wrote {args.out}")


if __name__ == "__main__":
    main()
