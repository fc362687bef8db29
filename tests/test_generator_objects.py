"""The `objects` scene generator (`pecs.dataset.generators`): drawn ranges honoured, scenes
distinct and reproducible from (dataset seed, index) alone, meshes and textures sound, paths with
the drawn speeds, and a generated sequence rendered through a dataset run and again alone."""

from __future__ import annotations

import json
import math
import subprocess
import sys
from pathlib import Path

import numpy as np
import pyarrow.parquet as pq
import pytest
from cli_run import run_cli
from pecs.dataset import generators, parse_spec, run_dataset
from pecs.dataset.generators import shapes, textures
from pecs.render import Simulation
from pecs.render.scene_file import load_scene

PYTHON_PATH = str(Path(__file__).resolve().parents[1] / "python")
ALL_SHAPES = {
    "sphere",
    "cube",
    "cylinder",
    "rectangle",
    "box",
    "capped_cylinder",
    "torus",
    "superquadric",
    "convex_hull",
    "extrusion",
}

# Ranges unlike the defaults, so that a generator ignoring the spec fails.
RANGES = {
    "object_count": [3, 6],
    "object_size_m": [0.12, 0.3],
    "spread_m": [0.4, 0.9],
    "roughness": [0.1, 0.3],
    "albedo": [0.2, 0.7],
    "ior": [1.4, 1.6],
    "texture_repeats": [2, 3],
    "object_speed_m_s": [0.2, 0.8],
    "object_angular_rate_deg_s": [30.0, 90.0],
    "camera_distance_m": [3.0, 4.0],
    "camera_elevation_deg": [10.0, 30.0],
    "fov_deg": [60.0, 70.0],
    "camera_speed_m_s": [0.3, 1.2],
    "camera_angular_rate_deg_s": [10.0, 40.0],
    "shake_deg": [0.05, 0.2],
    "light_count": [1, 3],
    "illuminance_lux": [10.0, 50_000.0],
    "temperature_k": [3000.0, 6000.0],
    "light_elevation_deg": [30.0, 70.0],
    "light_distance_m": [2.0, 4.0],
    "sky_share": [0.4, 0.6],
    "sun_elevation_deg": [20.0, 50.0],
}


def spec_text(draw: str = "", count: int = 1, width: int = 346, height: int = 260) -> str:
    return f"""
[dataset]
name = "generated"
seed = 3

[defaults]
duration_s = 0.5
rate_hz = 1000
spp = 1

[defaults.sensor]
width = {width}
height = {height}

[scene]
generator = "objects"

[scene.draw]
{draw}

[[sequences]]
count = {count}
"""


def within(value: float, bounds: list[float]) -> bool:
    return bounds[0] <= value <= bounds[1]


def test_a_hundred_draws_honour_every_range() -> None:
    draw = "\n".join(f"{key} = {json.dumps(value)}" for key, value in RANGES.items())
    tasks = parse_spec(spec_text(draw, count=100)).sequences
    scenes = [generators.describe_task_scene(task) for task in tasks]
    counts, kinds, materials, texture_kinds, lights_per_scene, backgrounds = [], [], [], [], [], []
    for scene in scenes:
        assert scene["duration_s"] == 0.5
        assert within(scene["spread_m"], RANGES["spread_m"])
        assert within(scene["illuminance_lux"], RANGES["illuminance_lux"])
        backgrounds.append(scene["background"]["kind"])
        check_background(scene["background"], texture_kinds)
        counts.append(len(scene["objects"]))
        for obj in scene["objects"]:
            kinds.append(obj["shape"]["kind"])
            assert obj["class"] == obj["shape"]["kind"]
            assert within(obj["shape"]["size_m"], RANGES["object_size_m"])
            check_material(obj["material"], texture_kinds)
            materials.append(obj["material"]["kind"])
            assert within(obj["motion"]["speed_m_s"], RANGES["object_speed_m_s"])
            assert within(obj["motion"]["angular_rate_deg_s"], RANGES["object_angular_rate_deg_s"])
            assert abs(np.linalg.norm(obj["rotation"]) - 1) < 1e-12
        camera = scene["camera"]
        for key, name in [
            ("distance_m", "camera_distance_m"),
            ("elevation_deg", "camera_elevation_deg"),
            ("fov_deg", "fov_deg"),
        ]:
            assert within(camera[key], RANGES[name])
        assert within(camera["motion"]["speed_m_s"], RANGES["camera_speed_m_s"])
        assert within(camera["motion"]["angular_rate_deg_s"], RANGES["camera_angular_rate_deg_s"])
        assert within(camera["shake"]["amplitude_deg"], RANGES["shake_deg"])
        lights_per_scene.append(len(scene["lights"]))
        for light in scene["lights"]:
            assert within(light["temperature_k"], RANGES["temperature_k"])
            assert within(light["elevation_deg"], RANGES["light_elevation_deg"])
            assert within(light["distance_m"], RANGES["light_distance_m"])
            assert light["kind"] in ("point", "sphere")
    # Every count, kind and material of the ranges shows up in 100 scenes.
    assert set(counts) == {3, 4, 5, 6}
    assert set(lights_per_scene) == {1, 2, 3}
    assert set(kinds) == ALL_SHAPES
    assert set(materials) == {"diffuse", "plastic", "conductor", "dielectric"}
    assert set(texture_kinds) == {"noise", "stripes", "checkers", "image"}
    assert set(backgrounds) == {"plane", "room", "sky"}


def check_background(background: dict, texture_kinds: list[str]) -> None:
    for surface in ("floor", "walls"):
        if surface in background:
            check_material(background[surface], texture_kinds)
    assert ("sky" in background) == (background["kind"] == "sky")
    if "sky" in background:
        sky = background["sky"]
        assert sky["kind"] in ("clear", "partly_cloudy", "overcast")
        assert within(sky["share"], RANGES["sky_share"])
        assert within(sky["sun_elevation_deg"], RANGES["sun_elevation_deg"])
        assert 0.0 <= sky["sun_azimuth_deg"] < 360.0


def check_material(material: dict, texture_kinds: list[str]) -> None:
    for key in ("albedo", "albedo_2"):
        for value in material.get(key, []):
            assert within(value, RANGES["albedo"])
    if "roughness" in material:
        assert within(material["roughness"], RANGES["roughness"])
    if "ior" in material:
        assert within(material["ior"], RANGES["ior"])
    if "texture" in material:
        texture_kinds.append(material["texture"]["kind"])
        assert within(material["repeats"], RANGES["texture_repeats"])
        if material["texture"]["kind"] == "image":
            check_image(material)
            return
        # The two spectra of a pattern differ in level, so that it shows.
        gap = abs(np.mean(material["albedo"]) - np.mean(material["albedo_2"]))
        assert gap >= 0.25 * (RANGES["albedo"][1] - RANGES["albedo"][0]) - 0.05


def check_image(material: dict) -> None:
    """A natural image: its licence and credit recorded, its crop within its drawn ranges; a
    colour image is the reflectance itself (the albedo range mapped into), a grey one weights
    two spectra."""
    texture = material["texture"]
    assert texture["licence"] == "public domain"
    assert "matplotlib sample data" in texture["credit"]
    assert 0.3 <= texture["crop_fraction"] <= 1.0
    assert all(0.0 <= c <= 1.0 for c in texture["centre"])
    if texture["colour"]:
        assert "albedo" not in material and texture["albedo_range"] == RANGES["albedo"]
    else:
        assert "albedo_2" in material and 20.0 <= texture["light_altitude_deg"] <= 60.0


def test_a_thousand_sequences_have_no_two_identical_scenes() -> None:
    tasks = parse_spec(spec_text(count=1000)).sequences
    hashes = {generators.description_hash(generators.describe_task_scene(t)) for t in tasks}
    assert len(hashes) == 1000


def test_a_scene_depends_on_the_dataset_seed_and_index_alone() -> None:
    few = parse_spec(spec_text(count=3)).sequences
    # More sequences after it, a sensor draw and another film do not change sequence 2's scene.
    more = parse_spec(
        spec_text(count=9, width=32, height=24).replace(
            "[scene]", "[draw]\ntheta_on = { uniform = [0.1, 0.3] }\n\n[scene]"
        )
    ).sequences
    assert generators.describe_task_scene(few[2]) == generators.describe_task_scene(more[2])
    other_seed = parse_spec(spec_text(count=3).replace("seed = 3", "seed = 4")).sequences
    assert generators.describe_task_scene(few[2]) != generators.describe_task_scene(other_seed[2])


def test_same_seed_and_index_give_byte_identical_files_in_another_process(tmp_path: Path) -> None:
    # Every shape, so that every mesh kind is written; the other process has no SciPy (pecs
    # does not depend on it: trimesh must not need it here).
    draw = f"object_count = [10, 10]\nshapes = {json.dumps(sorted(ALL_SHAPES))}"
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
    written = sorted(p.relative_to(here) for p in here.rglob("*") if p.is_file())
    assert written == sorted(p.relative_to(there) for p in there.rglob("*") if p.is_file())
    assert len([p for p in written if p.suffix == ".ply"]) >= 1
    for relative in written:
        assert (here / relative).read_bytes() == (there / relative).read_bytes(), relative
    other = generators.write_task_scene(parse_spec(spec.read_text()).sequences[0], tmp_path / "o")
    assert other.read_bytes() != (here / "scene.toml").read_bytes()


def scene_with(draw: dict, tmp_path: Path, index: int = 0, duration_s: float = 0.5) -> tuple:
    """A written scene of the given ranges: (description, loaded SceneSpec)."""
    generator = generators.make_generator("objects", draw)
    description = generator.describe(generators.scene_rng(1, index), duration_s)
    settings = generators.SceneSettings(duration_s=duration_s, rate_hz=100.0, spp=1)
    path = generator.write(description, tmp_path / f"scene-{index}", settings)
    return description, load_scene(path)


def mean_speed(track, duration_s: float, samples: int = 2000) -> float:
    t = (np.arange(samples) + 0.5) / samples * duration_s
    return float(np.mean([np.linalg.norm(track.velocity(x)) for x in t]))


def mean_rate_deg_s(track, duration_s: float, samples: int = 2000) -> float:
    t = (np.arange(samples) + 0.5) / samples * duration_s
    return math.degrees(float(np.mean([np.linalg.norm(track.angular_velocity(x)) for x in t])))


def test_the_written_paths_move_at_the_drawn_mean_speeds(tmp_path: Path) -> None:
    draw = {
        "shake_deg": [0.0, 0.0],
        "object_count": [3, 3],
        "object_speed_m_s": [0.5, 1.0],
        "camera_speed_m_s": [0.5, 1.5],
    }
    description, scene = scene_with(draw, tmp_path)
    camera = description["camera"]["motion"]
    # The scene file's own C2 spline through the written keyframes, differentiated by pecs.
    assert mean_speed(scene.camera, 0.5) == pytest.approx(camera["speed_m_s"], rel=2e-3)
    assert mean_rate_deg_s(scene.camera, 0.5) == pytest.approx(
        camera["angular_rate_deg_s"], rel=5e-3
    )
    for obj in description["objects"]:
        track = scene.objects[obj["id"]]
        assert mean_speed(track, 0.5) == pytest.approx(obj["motion"]["speed_m_s"], rel=2e-3)
        assert mean_rate_deg_s(track, 0.5) == pytest.approx(
            obj["motion"]["angular_rate_deg_s"], rel=5e-3
        )


def test_shake_stays_within_its_amplitude_and_moves_the_view(tmp_path: Path) -> None:
    still = {"camera_speed_m_s": [0.0, 0.0], "camera_angular_rate_deg_s": [0.0, 0.0]}
    _, calm = scene_with({**still, "shake_deg": [0.0, 0.0]}, tmp_path, index=4)
    description, shaken = scene_with({**still, "shake_deg": [0.5, 0.5]}, tmp_path / "s", index=4)
    angles = []
    for t in np.linspace(0.0, 0.5, 101):
        relative = calm.camera.pose(t)[:3, :3].T @ shaken.camera.pose(t)[:3, :3]
        angles.append(math.degrees(math.acos(np.clip((np.trace(relative) - 1) / 2, -1, 1))))
    # Per axis the mean of two sines of peak 0.5 degrees: at most 0.5 * sqrt(3) in all.
    assert 0.05 < max(angles) <= 0.5 * math.sqrt(3) + 1e-6
    assert description["camera"]["shake"]["amplitude_deg"] == 0.5


def test_lights_share_the_drawn_illuminance(tmp_path: Path) -> None:
    draw = {"light_count": [3, 3], "backgrounds": ["plane", "room"]}  # no sky: lamps only
    description, scene = scene_with(draw, tmp_path, index=2)
    total = description["illuminance_lux"]
    assert scene.light.illuminance_lux == pytest.approx(total, rel=1e-8)
    assert scene.light.temperature_k == pytest.approx(description["lights"][0]["temperature_k"])
    weights = [light["weight"] for light in description["lights"]]
    fills = [level.illuminance_lux for level in scene.lights]
    assert [level.emitter_id for level in scene.lights] == ["light_1", "light_2"]
    assert fills == pytest.approx([total * w / sum(weights) for w in weights[1:]], rel=1e-8)
    # The meter is above every object, where no object shadows it.
    assert scene.light.at[1] > max(
        o["position"][1] + o["shape"]["size_m"] for o in description["objects"]
    )


def test_each_object_is_of_its_shape_class(tmp_path: Path) -> None:
    description, scene = scene_with({"object_count": [4, 4]}, tmp_path, index=3)
    assert scene.classes == {o["id"]: o["shape"]["kind"] for o in description["objects"]}


@pytest.mark.parametrize("kind", sorted(shapes.MESHES))
def test_meshes_are_closed_outward_and_of_the_drawn_size(kind: str) -> None:
    import trimesh

    rng = np.random.default_rng(5)
    for _ in range(5):
        shape = shapes.describe_shape(kind, 0.3, rng)
        mesh = shapes.build_mesh(shape)
        solid = trimesh.Trimesh(mesh.vertices, mesh.faces, process=False)
        solid.merge_vertices(merge_tex=True, merge_norm=True)
        assert solid.is_watertight, kind
        assert solid.volume > 0, kind  # faces wound outward: one-sided materials are lit
        assert np.linalg.norm(mesh.vertices, axis=1).max() == pytest.approx(0.3, rel=1e-9)
        assert mesh.uv.shape == (len(mesh.vertices), 2) and np.all(np.isfinite(mesh.uv))
        if mesh.normals is not None:  # smooth shapes: the surface's normals (trimesh's, here)
            merged = trimesh.Trimesh(mesh.vertices, mesh.faces)  # welds seams and poles
            index = merged.kdtree.query(mesh.vertices)[1]
            cosine = np.sum(mesh.normals * merged.vertex_normals[index], axis=1)
            assert cosine.min() > 0.98, kind
        if kind == "convex_hull":
            assert solid.is_convex
            assert len(solid.vertices) == shape["points"]


def test_the_superquadric_of_unit_exponents_is_the_ellipsoid() -> None:
    axes = [1.0, 0.7, 0.5]
    mesh = shapes.superquadric([1.0, 1.0], axes, size_m=1.0)
    x, y, z = mesh.vertices.T
    assert np.allclose((x / 1.0) ** 2 + (y / 0.7) ** 2 + (z / 0.5) ** 2, 1.0, atol=1e-12)
    # Normals of an ellipsoid: the gradient (x / a^2, y / b^2, z / c^2), normalised.
    gradient = mesh.vertices / np.square(axes)
    expected = gradient / np.linalg.norm(gradient, axis=1, keepdims=True)
    assert np.allclose(mesh.normals, expected, atol=1e-9)


def test_texture_patterns_tile_and_have_their_drawn_cells() -> None:
    rng = np.random.default_rng(8)
    checkers = textures.texture_image({"kind": "checkers", "cells": 4}, size_px=64)
    assert np.count_nonzero(np.diff(checkers[0])) == 3  # 4 cells: 3 edges inside a row
    assert checkers[0, 0] != checkers[0, -1]  # and the 4th edge at the tile's seam
    stripes = textures.texture_image({"kind": "stripes", "waves": [3, 0], "duty": 0.5}, 64)
    assert np.count_nonzero(np.diff(stripes[0])) == 5  # 3 stripes: 6 edges, one at the seam
    noise = textures.texture_image(textures.describe_texture("noise", rng), size_px=128)
    assert noise.min() == 0.0 and noise.max() == 1.0
    # Tileable: the step across the seam is like a step inside the image.
    assert np.abs(noise[:, 0] - noise[:, -1]).max() < 4 * np.abs(np.diff(noise, axis=1)).max()


def test_spec_errors_name_the_key() -> None:
    cases = [
        ('generator = "rooms"', "scene.generator: unknown scene generator 'rooms'"),
        ('generator = "objects"\ndraw = { objects = [1, 2] }', "scene.draw.objects: unknown key"),
        (
            'generator = "objects"\ndraw = { object_count = [5, 2] }',
            "scene.draw.object_count: min 5 is above max 2",
        ),
        (
            'generator = "objects"\ndraw = { shapes = ["teapot"] }',
            "scene.draw.shapes: unknown name 'teapot'",
        ),
        (
            'generator = "objects"\ndraw = { albedo = [0.5, 1.5] }',
            "scene.draw.albedo: reflectance must lie within [0, 1]",
        ),
        (
            'generator = "objects"\ndraw = { camera_distance_m = [1.0, 2.0] }',
            "scene.draw.camera_distance_m: min 1.0 m would put the camera among the objects",
        ),
    ]
    for table, message in cases:
        text = f'[dataset]\nname = "x"\n[scene]\n{table}\n[[sequences]]\ncount = 1\n'
        with pytest.raises(ValueError, match="^spec.toml: " + message.replace("[", r"\[")):
            parse_spec(text, Path("spec.toml"))
    with pytest.raises(ValueError, match=r"sequences\[0\]\.scene: missing required key"):
        parse_spec('[dataset]\nname = "x"\n[[sequences]]\ncount = 1\n', Path("spec.toml"))


def test_a_sequence_may_name_its_own_generator_table() -> None:
    text = """
[dataset]
name = "mixed"
[[sequences]]
scene = "checkerboard"
[[sequences]]
name = "few"
count = 2
scene = { generator = "objects", draw = { object_count = [1, 1] } }
"""
    tasks = parse_spec(text).sequences
    assert [t.name for t in tasks] == ["checkerboard", "few-0", "few-1"]
    assert tasks[0].generator == "" and tasks[1].generator == "objects"
    assert tasks[1].record()["scene"]["draw"]["object_count"] == [1, 1]
    assert len(generators.describe_task_scene(tasks[2])["objects"]) == 1


def test_a_generated_sequence_renders_in_a_dataset_run_and_alone(
    tmp_path: Path, capsys: pytest.CaptureFixture
) -> None:
    # Tiny and short (32 x 24, 1 spp, 3 frames), a camera that moves and a lit scene: events.
    draw = (
        'object_count = [2, 2]\nbackgrounds = ["room"]\nilluminance_lux = [300, 300]\n'
        "camera_speed_m_s = [1.5, 1.5]\ncamera_angular_rate_deg_s = [60, 60]"
    )
    spec = tmp_path / "spec.toml"
    spec.write_text(spec_text(draw, width=32, height=24).replace("0.5", "0.002"))
    code, out, err = run_cli(
        capsys,
        "dataset",
        "run",
        str(spec),
        "-o",
        str(tmp_path / "data"),
        "--workers",
        "1",
        "--quiet",
    )
    assert code == 0, err
    run = tmp_path / "data" / "runs" / "objects"
    events = pq.read_table(tmp_path / "data" / "events" / "sequence=objects" / "part-0.parquet")
    assert events.num_rows > 0
    record = json.loads((run / "sequence.json").read_text())
    assert record["frames"] == 3 and record["task"]["scene"]["generator"] == "objects"
    # The kept scene renders the same events alone.
    again = Simulation(run / "scene" / "scene.toml").run(tmp_path / "again")
    alone = pq.read_table(again.out_dir / "events.parquet")
    assert alone.select(["t", "x", "y", "p"]).equals(events.select(["t", "x", "y", "p"]))
    # A rerun finds it finished (its record, with the generator's ranges, is unchanged).
    summary = run_dataset(spec, tmp_path / "data", workers=1)
    assert summary.skipped == ["objects"] and summary.done == []


def test_a_bad_generator_range_is_one_line_from_the_cli(
    tmp_path: Path, capsys: pytest.CaptureFixture
) -> None:
    spec = tmp_path / "spec.toml"
    spec.write_text(spec_text("illuminance_lux = [0, 100]"))
    code, out, err = run_cli(capsys, "dataset", "run", str(spec), "-o", str(tmp_path / "data"))
    assert code == 2 and out == ""
    assert err.count("\n") == 1 and "Traceback" not in err
    assert "scene.draw.illuminance_lux: illuminance at the scene must lie within" in err
