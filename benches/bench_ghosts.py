"""Cost of traced lens ghosts: the headlight scene at 346 x 260 with ghosts and without.

The same Simulation settings twice (scenes/headlight: dgauss50 at 12 mm f/2, two lamps, the
scene's spp), frames rendered turn by turn at the same times so that the machine's drift
cancels. Prints the median time per frame of each, their ratio (target: at most 2x), the
number of ghost paths traced and rays per frame, the whole ghost pass's time per lamp and
the part of it spent tracing the rays (coarse and fine passes, in Rust).

    .venv/bin/python benches/bench_ghosts.py [--frames 6] [--spp N]
"""

from __future__ import annotations

import argparse
import dataclasses
import statistics
import time
from pathlib import Path

from pecs.render import Simulation, load_scene

SCENE = Path(__file__).resolve().parents[1] / "scenes" / "headlight" / "scene.toml"


def main() -> None:
    parser = argparse.ArgumentParser(description=__doc__.splitlines()[0])
    parser.add_argument("--frames", type=int, default=6)
    parser.add_argument("--spp", type=int, default=None, help="default: the scene's")
    args = parser.parse_args()
    spec = load_scene(SCENE)
    plain = dataclasses.replace(spec, optics=dataclasses.replace(spec.optics, ghosts=None))
    sims = {
        "ghosts": Simulation(spec, spp=args.spp),
        "plain": Simulation(plain, spp=args.spp),
    }
    renderers = {name: sim.renderer for name, sim in sims.items()}
    times_s = [0.05 + 0.2 * k / max(args.frames - 1, 1) for k in range(args.frames)]
    for r in renderers.values():  # warm-up: kernels compiled
        r.render(times_s[0])
    spent: dict[str, list[float]] = {name: [] for name in renderers}
    tracer_s: list[float] = []
    rays_s: list[float] = []
    ghosts = renderers["ghosts"].ghosts
    for t in times_s:
        for name, r in renderers.items():
            start = time.perf_counter()
            r.render(t)
            spent[name].append(time.perf_counter() - start)
        start = time.perf_counter()
        sources = ghosts.sources(renderers["ghosts"].camera_pose(t))
        ghosts.frame(renderers["ghosts"].camera_pose(t))
        tracer_s.append((time.perf_counter() - start) / max(len(sources), 1))
        start = time.perf_counter()
        ghosts.tracer.trace_many([s for s, _ in sources], ghosts.band_nm)
        rays_s.append((time.perf_counter() - start) / max(len(sources), 1))
    g = sims["ghosts"].geometry
    with_s, without_s = statistics.median(spent["ghosts"]), statistics.median(spent["plain"])
    tracer = ghosts.tracer
    n = tracer.system.options.rays_per_side
    lamps = len(ghosts.sources(renderers["ghosts"].camera_pose(times_s[0])))
    print(
        f"headlight scene, {g.width} x {g.height}, spp {sims['plain'].spec.spp}, "
        f"{args.frames} frames, {time.strftime('%Y-%m-%d')}"
    )
    print(f"  frame without ghosts  {without_s * 1e3:8.1f} ms")
    print(f"  frame with ghosts     {with_s * 1e3:8.1f} ms")
    print(f"  ratio with / without  {with_s / without_s:8.2f}x   (target <= 2x)")
    print(
        f"  ghost paths traced    {len(tracer.paths)} of {len(tracer.system.paths())} "
        f"(the others below {tracer.system.options.min_relative_energy:g} of the brightest)"
    )
    per_path = n * n * (len(ghosts.band_nm) if tracer.system.options.dispersion else 1)
    print(
        f"  rays per lamp         {len(tracer.paths) * per_path} ({n} x {n} per path, "
        f"{len(ghosts.band_nm)} bands, dispersion {tracer.system.options.dispersion}) "
        f"+ a coarse pass; {lamps} lamps"
    )
    print(f"  tracer time per lamp  {statistics.median(tracer_s) * 1e3:8.1f} ms")
    print(f"  of which ray tracing  {statistics.median(rays_s) * 1e3:8.1f} ms")


if __name__ == "__main__":
    main()
