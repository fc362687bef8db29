"""The `driving` scene generator: drawn ranges honoured, vehicles driving their lanes at their
speeds without meeting, the camera driving forward, the light accounted, scenes reproducible
from (dataset seed, index) in another process, and a tiny scene rendered into events."""

from __future__ import annotations

import json
import math
import subprocess
import sys
from pathlib import Path

import numpy as np
import pyarrow.parquet as pq
import pytest
import tomllib
from pecs.dataset import generators, parse_spec
from pecs.dataset.generators import driving
from pecs.render import Simulation
from pecs.render.scene_file import load_scene

PYTHON_PATH = str(Path(__file__).resolve().parents[1] / "python")
RANGES = {
    "lane_count": [2, 4],
    "lane_width_m": [3.2, 3.5],
    "setback_m": [3.0, 4.0],
    "building_width_m": [10.0, 20.0],
    "building_gap_m": [1.0, 3.0],
    "building_height_m": [8.0, 20.0],
    "texture_repeats": [2, 3],
    "albedo": [0.2, 0.6],
    "roughness": [0.1, 0.2],
    "vehicle_count": [3, 5],
    "vehicle_speed_m_s": [4.0, 12.0],
    "camera_speed_m_s": [5.0, 10.0],
    "camera_height_m": [1.3, 1.5],
    "pitch_deg": [0.1, 0.4],
    "roll_deg": [0.05, 0.2],
    "fov_deg": [70.0, 90.0],
    "day_illuminance_lux": [2000.0, 50_000.0],
    "night_illuminance_lux": [3.0, 20.0],
    "sun_elevation_deg": [20.0, 60.0],
    "sun_share": [0.6, 0.8],
    "sun_temperature_k": [5000.0, 6000.0],
    "street_light_spacing_m": [25.0, 35.0],
    "street_light_temperature_k": [2500.0, 4000.0],
}


def spec_text(draw: str = "", count: int = 1) -> str:
    return f"""
[dataset]
name = "drive"
seed = 7

[defaults]
duration_s = 0.5
rate_hz = 1000
spp = 1

[defaults.sensor]
width = 32
height = 24

[scene]
generator = "driving"

[scene.draw]
{draw}

[[sequences]]
count = {count}
"""


def within(value: float, key: str) -> bool:
    return RANGES[key][0] <= value <= RANGES[key][1]


def test_a_hundred_draws_honour_every_range() -> None:
    draw = "\n".join(f"{key} = {json.dumps(value)}" for key, value in RANGES.items())
    scenes = [generators.describe_task_scene(t) for t in parse_spec(spec_text(draw, 100)).sequences]
    lanes, times, skies, counts = set(), set(), set(), set()
    for scene in scenes:
        road, camera, lighting = scene["road"], scene["camera"], scene["lighting"]
        lanes.add(road["lanes"])
        assert within(road["lanes"], "lane_count") and within(road["lane_width_m"], "lane_width_m")
        assert within(road["setback_m"], "setback_m")
        for key in ("height_m", "speed_m_s", "fov_deg"):
            assert within(
                camera[key],
                {"height_m": "camera_height_m"}.get(key, f"camera_{key}")
                if key != "fov_deg"
                else "fov_deg",
            )
        assert within(camera["sway"]["pitch_deg"], "pitch_deg")
        assert within(camera["sway"]["roll_deg"], "roll_deg")
        assert driving.lane_direction(camera["lane"], road["lanes"]) == 1  # a forward lane
        for side in (-1, 1):
            row = sorted(
                (b for b in scene["buildings"] if b["side"] == side), key=lambda b: b["start_m"]
            )
            assert row[0]["start_m"] <= road["start_m"] + RANGES["building_gap_m"][1]
            assert row[-1]["start_m"] + row[-1]["width_m"] >= road["end_m"]
            for a, b in zip(row, row[1:], strict=False):
                assert within(b["start_m"] - a["start_m"] - a["width_m"], "building_gap_m")
        for building in scene["buildings"]:
            assert within(building["width_m"], "building_width_m")
            assert within(building["height_m"], "building_height_m")
        counts.add(len(scene["vehicles"]))
        for vehicle in scene["vehicles"]:
            assert within(vehicle["speed_m_s"], "vehicle_speed_m_s")
            assert vehicle["material"]["kind"] in ("plastic", "conductor")
            assert within(vehicle["material"]["roughness"], "roughness")
        times.add(lighting["time"])
        if lighting["time"] == "day":
            skies.add(lighting["sky"]["kind"])
            assert within(lighting["illuminance_lux"], "day_illuminance_lux")
            assert within(lighting["sky"]["sun_elevation_deg"], "sun_elevation_deg")
            assert within(lighting["temperature_k"], "sun_temperature_k")
            share = lighting["sun_share"]
            assert (
                share == 0.0
                if lighting["sky"]["kind"] == "overcast"
                else within(share, "sun_share")
            )
        else:
            assert within(lighting["illuminance_lux"], "night_illuminance_lux")
            assert within(lighting["spacing_m"], "street_light_spacing_m")
            assert within(lighting["temperature_k"], "street_light_temperature_k")
    assert lanes == {2, 3, 4} and counts == {3, 4, 5}
    assert times == {"day", "night"} and skies == {"clear", "partly_cloudy", "overcast"}
    hashes = {generators.description_hash(s) for s in scenes}
    assert len(hashes) == 100


def written(tmp_path: Path, draw: dict, index: int = 0, duration_s: float = 0.5) -> tuple:
    generator = generators.make_generator("driving", draw)
    description = generator.describe(generators.scene_rng(3, index), duration_s)
    settings = generators.SceneSettings(
        duration_s=duration_s, rate_hz=1000.0, spp=1, sensor={"width": 32, "height": 24}
    )
    return description, generator.write(description, tmp_path / f"drive-{index}", settings)


def test_vehicles_and_camera_drive_their_lanes_at_their_speeds(tmp_path: Path) -> None:
    draw = {"vehicle_count": [6, 6], "lane_count": [2, 2], "pitch_deg": [0, 0], "roll_deg": [0, 0]}
    description, path = written(tmp_path, draw, index=1)
    scene = load_scene(path)
    road, camera = description["road"], description["camera"]
    # Lane centres of a two-lane road 2 w wide: -w/2 (forward) and +w/2 (oncoming).
    w = road["lane_width_m"]
    assert driving.lane_centre_m(0, 2, w) == pytest.approx(-w / 2)
    assert driving.lane_centre_m(1, 2, w) == pytest.approx(w / 2)
    for t in (0.1, 0.25, 0.4):
        # Without sway the camera looks straight down the road: +z, at its drawn speed.
        pose = scene.camera.pose(t)
        assert pose[:3, 2] == pytest.approx([0, 0, 1], abs=1e-9)
        assert pose[:3, 3] == pytest.approx(
            [camera["x_m"] + camera["offset_m"], camera["height_m"], camera["speed_m_s"] * t],
            abs=1e-6,
        )
        for vehicle in description["vehicles"]:
            velocity = scene.objects[vehicle["id"]].velocity(t)
            forward = 1 if vehicle["lane"] == 0 else -1
            assert velocity == pytest.approx([0, 0, forward * vehicle["speed_m_s"]], abs=1e-6)
    # No two vehicles of a lane, nor one and the camera's car, ever meet.
    cars = description["vehicles"]
    for t in np.linspace(0.0, 0.5, 11):
        for i, a in enumerate(cars):
            for b in cars[i + 1 :]:
                if a["lane"] == b["lane"]:
                    gap = abs(driving.vehicle_z(a, t) - driving.vehicle_z(b, t))
                    assert gap > (a["length_m"] + b["length_m"]) / 2
            if a["lane"] == camera["lane"]:
                assert driving.vehicle_z(a, t) - a["length_m"] / 2 > camera["speed_m_s"] * t


def test_sway_is_pitch_and_roll_within_the_drawn_amplitudes(tmp_path: Path) -> None:
    draw = {"pitch_deg": [0.4, 0.4], "roll_deg": [0.2, 0.2]}
    _, path = written(tmp_path, draw, index=2)
    scene = load_scene(path)
    pitch, roll = [], []
    for t in np.linspace(0.0, 0.5, 101):
        rotation = scene.camera.pose(t)[:3, :3]
        forward, up = rotation[:, 2], rotation[:, 1]
        pitch.append(math.degrees(math.asin(forward[1])))
        roll.append(math.degrees(math.atan2(-up[0], up[1])))
    # Per axis the mean of two unit sines: within the amplitude, and moving.
    assert 0.02 < max(np.abs(pitch)) <= 0.4 + 1e-6
    assert 0.01 < max(np.abs(roll)) <= 0.2 * 1.02 + 1e-6


def test_day_and_night_light_accounting(tmp_path: Path) -> None:
    day, day_path = written(tmp_path, {"times": ["day"], "sky_kinds": ["clear"]}, index=3)
    table = tomllib.loads(day_path.read_text())
    lighting = day["lighting"]
    total, share = lighting["illuminance_lux"], lighting["sun_share"]
    assert table["light"]["illuminance_lux"] == pytest.approx(total, rel=1e-8)
    assert table["lights"] == [
        {
            "id": "sky",
            "illuminance_lux": pytest.approx(total * (1 - share), rel=1e-8),
            "at": table["light"]["at"],
            "normal": [0.0, 1.0, 0.0],
        }
    ]
    # The meter is above every roof: no building shadows it from the sun or the sky.
    assert table["light"]["at"][1] > max(b["height_m"] for b in day["buildings"])
    xml = (day_path.parent / "scene.xml").read_text()
    assert 'type="directional" id="sun"' in xml and 'type="envmap" id="sky"' in xml
    overcast, path = written(tmp_path, {"times": ["day"], "sky_kinds": ["overcast"]}, index=4)
    table = tomllib.loads(path.read_text())
    assert "light" not in table  # no sun: the sky is all the daylight
    assert table["lights"][0]["illuminance_lux"] == pytest.approx(
        overcast["lighting"]["illuminance_lux"], rel=1e-8
    )
    night, path = written(tmp_path, {"times": ["night"]}, index=5)
    table = tomllib.loads(path.read_text())
    assert "lights" not in table and table["light"]["at"][1] == driving.NIGHT_METER_HEIGHT_M
    lamps = driving.street_lights(night)
    assert len(lamps) >= 2 * math.floor(140 / night["lighting"]["spacing_m"])
    assert table["classes"][lamps[0][0]] == "street_light"
    assert {table["classes"][v["id"]] for v in night["vehicles"]} <= {"vehicle"}
    assert {table["classes"][b["id"]] for b in night["buildings"]} == {"building"}


def test_same_seed_and_index_give_byte_identical_files_in_another_process(tmp_path: Path) -> None:
    draw = 'facade_textures = ["image", "noise"]\ntimes = ["day"]'
    spec = tmp_path / "spec.toml"
    spec.write_text(spec_text(draw, count=2))
    task = parse_spec(spec.read_text()).sequences[1]
    here = generators.write_task_scene(task, tmp_path / "here").parent
    script = (
        "import sys; sys.modules['scipy'] = None\n"
        "from pathlib import Path\n"
        "from pecs.dataset import generators, load_spec\n"
        f"task = load_spec({str(spec)!r}).sequences[1]\n"
        f"generators.write_task_scene(task, Path({str(tmp_path / 'there')!r}))\n"
    )
    subprocess.run(
        [sys.executable, "-c", script],
        check=True,
        env={"PYTHONPATH": PYTHON_PATH, "PATH": ""},
        capture_output=True,
    )
    there = tmp_path / "there"
    files = sorted(p.relative_to(here) for p in here.rglob("*") if p.is_file())
    assert files == sorted(p.relative_to(there) for p in there.rglob("*") if p.is_file())
    assert {p.suffix for p in files} >= {".ply", ".png", ".pfm", ".toml", ".xml", ".json"}
    for relative in files:
        assert (here / relative).read_bytes() == (there / relative).read_bytes(), relative


@pytest.mark.parametrize("time", ["day", "night"])
def test_a_tiny_driving_scene_renders_events(tmp_path: Path, time: str) -> None:
    draw = {"times": [time], "camera_speed_m_s": [15, 15], "vehicle_count": [3, 3]}
    _, path = written(tmp_path, draw, index=6, duration_s=0.003)
    result = Simulation(path).run(tmp_path / "out")
    assert result.frames == 4
    assert pq.read_table(result.out_dir / "events.parquet").num_rows > 0
