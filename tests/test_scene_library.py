"""The scene library in scenes/: every scene loads, renders small and fast, and moves.

Each scene runs at 64 x 36 pixels (the pixel pitch scaled up so that the field of view stays),
1 spp, a few frames, with the sensor's random noise off: every event then comes from a change
in the rendered light, and motion that brightens some edges and darkens others gives both
polarities. The paper set-ups are checked against the PECS set-up's numbers (EVK4 geometry,
pecs4 lens, 1 m/s slab).
"""

from __future__ import annotations

import subprocess
import sys
from pathlib import Path

import numpy as np
import pyarrow as pa
import pytest
from pecs.config import NOISE_OFF
from pecs.render import Simulation, load_scene

LIBRARY = Path(__file__).resolve().parents[1] / "scenes"
sys.path.insert(0, str(LIBRARY))
from scene_library import GENERATED, MOTION_WINDOW_S, SCENES  # noqa: E402

QUIET = NOISE_OFF


def small(scene: str) -> Simulation:
    path = LIBRARY / scene / "scene.toml"
    full = load_scene(path)
    assert full.preset == "imx636"
    scale = 64 / 1280
    sensor = {"width": 64, "height": 36, "pixel_pitch_um": 4.86 / scale, **QUIET}
    return Simulation(path, duration_s=MOTION_WINDOW_S[scene], spp=1, rate_hz=250.0, sensor=sensor)


@pytest.mark.parametrize("scene", SCENES)
def test_each_scene_renders_small_and_its_motion_fires_both_polarities(scene: str) -> None:
    sim = small(scene)
    events = pa.Table.from_batches(list(sim.event_batches()))
    polarity = events.column("p").to_numpy()
    assert events.num_rows > 10
    assert np.count_nonzero(polarity == 1) > 0 and np.count_nonzero(polarity == 0) > 0
    frame = next(iter(sim.frames())).photocurrent_pa
    assert frame.shape == (36, 64) and np.all(np.isfinite(frame)) and np.max(frame) > 0


def test_the_paper_set_ups_use_the_evk4_geometry_and_the_pecs4_lens() -> None:
    # IMX636 (Prophesee EVK4): 1280 x 720, 4.86 um (sensor-characterisation.md); the PECS
    # authors' four-element lens, focused at 1.56 m (optics-and-spectra.md)
    for scene in ("quadrant_disk", "checkerboard"):
        sim = Simulation(LIBRARY / scene / "scene.toml")
        assert (sim.geometry.width, sim.geometry.height) == (1280, 720)
        assert sim.geometry.pitch_um == pytest.approx(4.86)
        assert sim.spec.optics.lens == "pecs4" and sim.spec.optics.focus_m == pytest.approx(1.56)
    slab = load_scene(LIBRARY / "checkerboard" / "scene.toml").objects["slab"]
    moved = slab.pose(0.2)[:3, 3] - slab.pose(0.1)[:3, 3]
    assert np.linalg.norm(moved) / 0.1 == pytest.approx(1.0)  # 1 m/s
    disk = load_scene(LIBRARY / "quadrant_disk" / "scene.toml").objects["disk"]
    quarter = disk.pose(0.125)[:3, :3]  # a quarter turn about the optical axis after 1/8 s
    assert quarter @ np.array([1.0, 0.0, 0.0]) == pytest.approx([0.0, 1.0, 0.0], abs=1e-9)


@pytest.mark.parametrize("scene", GENERATED)
def test_generated_files_are_what_the_generator_writes(scene: str, tmp_path: Path) -> None:
    folder = LIBRARY / scene
    committed = {name: (folder / name).read_text() for name in ("scene.xml", "scene.toml")}
    copy = tmp_path / scene
    copy.mkdir()
    (copy / "make.py").write_text((folder / "make.py").read_text())
    (tmp_path / "scene_writing.py").write_text((LIBRARY / "scene_writing.py").read_text())
    subprocess.run([sys.executable, str(copy / "make.py")], check=True, capture_output=True)
    for name, text in committed.items():
        assert (copy / name).read_text() == text, f"{scene}/{name} differs from make.py's output"
