"""Cost of the ground truth per frame against rendering the frame itself (the baseline), on the
built-in room scene at the DAVIS346's 346 x 260: `python benches/bench_ground_truth.py`."""

from __future__ import annotations

import time

import numpy as np
from pecs.ground_truth.surface import motion_field_px, z_depth_m
from pecs.render import Simulation

REPEATS = 5


def best_of(function: object) -> float:
    times = []
    for k in range(REPEATS):
        start = time.perf_counter()
        function(0.01 * (k + 1))  # type: ignore[operator]
        times.append(time.perf_counter() - start)
    return min(times)


def main() -> None:
    simulation = Simulation("room", spp=16)
    renderer = simulation.renderer
    model = renderer.camera_model()
    renderer.render(0.0), renderer.surface(0.0)  # compile both kernels first
    render_s = best_of(renderer.render)

    def ground_truth(t_s: float) -> None:
        hits = renderer.surface(t_s)
        z_depth_m(hits, model)
        motion_field_px(hits, renderer.camera_pose(t_s + 1e-3), lambda _: np.eye(4), model)

    truth_s = best_of(ground_truth)
    print(f"render (spp 16): {render_s * 1e3:.1f} ms/frame")
    print(f"ground truth (ray cast, depth, flow): {truth_s * 1e3:.1f} ms/frame")
    print(f"ratio ground truth / render: {truth_s / render_s:.3f}")


if __name__ == "__main__":
    main()
