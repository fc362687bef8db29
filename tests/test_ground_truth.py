"""Ground truth of rendered runs against geometry worked out by hand: a camera sliding past and
spinning in front of a fronto-parallel wall, a card moving across a static wall."""

from __future__ import annotations

import math
from pathlib import Path

import numpy as np
import pecs
import pyarrow.parquet as pq
import pytest
from pecs.render import Simulation

WIDTH, HEIGHT, FOV_DEG = 64, 48, 60.0
# Focal length in pixels of a pinhole with this horizontal field of view.
FOCAL_PX = WIDTH / 2 / math.tan(math.radians(FOV_DEG) / 2)

CHECKER = """<bsdf type="diffuse"><texture type="checkerboard" name="reflectance">
      <rgb name="color0" value="0.05"/><rgb name="color1" value="0.8"/>
      <transform name="to_uv"><scale x="{tiles}" y="{tiles}"/></transform></texture></bsdf>"""


def write_scene(
    folder: Path,
    shapes: str,
    camera: str,
    objects: str = "",
    duration_s: float = 0.004,
    stepping: str = "rate_hz = 1000",
) -> Path:
    (folder / "scene.xml").write_text(
        f"""<scene version="3.0.0">
  <emitter type="constant"><spectrum name="radiance" value="1.0"/></emitter>
  {shapes}
</scene>"""
    )
    toml = folder / "scene.toml"
    toml.write_text(
        f"""[scene]
mitsuba = "scene.xml"
[time]
duration_s = {duration_s}
{stepping}
[sensor]
preset = "ideal"
overrides = {{ width = {WIDTH}, height = {HEIGHT} }}
[optics]
model = "pinhole"
fov_deg = {FOV_DEG}
[render]
spp = 1
[camera]
keyframes = {camera}
{objects}"""
    )
    return toml


# Rectangles face +z; turned to face the camera (diffuse surfaces are black from behind).
def wall(z_m: float, half_m: float = 20.0, name: str = "wall", tiles: int = 40) -> str:
    return f"""<shape type="rectangle" id="{name}">
    <transform name="to_world"><scale x="{half_m}" y="{half_m}"/><rotate y="1" angle="180"/>
      <translate z="{z_m}"/></transform>
    {CHECKER.format(tiles=tiles)}</shape>"""


# The thin lens's central ray passes through the lens centre: a pinhole of focal length efl
# (1 mm over the ideal preset's 18.5 um pixels).
OPTICS = {
    "pinhole": (f'model = "pinhole"\nfov_deg = {FOV_DEG}', FOCAL_PX),
    "thinlens": ('model = "thinlens"\nefl_mm = 1.0\nfocus_m = 2.0', 1.0 / 18.5e-3),
}


@pytest.mark.parametrize("optics", OPTICS)
def test_sideways_camera_sees_uniform_flow_f_v_dt_over_z_and_depth_z(
    tmp_path: Path, optics: str
) -> None:
    z_m, speed_m_s, duration_s = 2.0, 5.0, 0.004
    end = speed_m_s * duration_s
    camera = (
        f"[{{ t_s = 0.0, position = [0, 0, 0], look_at = [0, 0, 1] }}, "
        f"{{ t_s = {duration_s}, position = [{end}, 0, 0], look_at = [{end}, 0, 1] }}]"
    )
    scene = write_scene(tmp_path, wall(z_m), camera, duration_s=duration_s)
    optics_toml, focal_px = OPTICS[optics]
    scene.write_text(scene.read_text().replace(OPTICS["pinhole"][0], optics_toml))
    Simulation(scene, ground_truth="all").run(tmp_path / "run")
    truth = pecs.read_ground_truth(tmp_path / "run")
    assert len(truth) == 5
    np.testing.assert_array_equal(truth.t_us, [0, 1000, 2000, 3000, 4000])
    # The camera moves towards its +x, the image's left: the wall moves right (+u) in the image.
    expected_du = focal_px * speed_m_s * 1e-3 / z_m
    for i in range(4):
        flow = truth.flow(i)
        assert flow.shape == (HEIGHT, WIDTH, 2)
        np.testing.assert_allclose(flow[..., 0], expected_du, rtol=0.01)
        np.testing.assert_allclose(flow[..., 1], 0.0, atol=1e-3 * expected_du)
        np.testing.assert_allclose(truth.depth(i), z_m, rtol=1e-5)
        np.testing.assert_allclose(truth.camera_pose(i)[:3, 3], [speed_m_s * i * 1e-3, 0, 0])
    assert np.isnan(truth.flow(4)).all()  # no next frame
    np.testing.assert_allclose(truth.intrinsics[0, 0], focal_px, rtol=1e-12)
    np.testing.assert_allclose(truth.intrinsics[:2, 2], [(WIDTH - 1) / 2, (HEIGHT - 1) / 2])
    assert truth.shape_ids == ["wall"] and (truth.instance(0) == 0).all()
    imu = truth.imu
    assert imu.num_rows == 5  # 1 kHz over 4 ms
    for axis in "xyz":
        np.testing.assert_allclose(imu.column(f"gyro_{axis}_rad_s").to_numpy(), 0.0, atol=1e-9)
    np.testing.assert_allclose(imu.column("accel_y_m_s2").to_numpy(), 9.80665, atol=1e-6)
    np.testing.assert_allclose(imu.column("accel_x_m_s2").to_numpy(), 0.0, atol=1e-6)


def test_camera_spinning_about_its_optical_axis_sees_the_rotation_field(tmp_path: Path) -> None:
    rate_deg_s, duration_s, z_m = 2000.0, 0.004, 3.0
    camera = (
        "[{ t_s = 0.0, axis = [0, 0, 1], angle_deg = 0 }, "
        f"{{ t_s = {duration_s}, axis = [0, 0, 1], angle_deg = {rate_deg_s * duration_s} }}]"
    )
    scene = write_scene(tmp_path, wall(z_m), camera, duration_s=duration_s)
    Simulation(scene, ground_truth=["flow", "imu", "depth"], imu_rate_hz=500).run(tmp_path / "run")
    truth = pecs.read_ground_truth(tmp_path / "run")
    gyro_z = truth.imu.column("gyro_z_rad_s").to_numpy()
    np.testing.assert_allclose(gyro_z, math.radians(rate_deg_s), rtol=1e-9)
    # Image coordinates about the centre, (cx - u, cy - v), are proportional to the camera's
    # (X, Y); turning the camera by +a about z turns them by -a.
    angle = math.radians(rate_deg_s) * 1e-3
    v, u = np.mgrid[0:HEIGHT, 0:WIDTH].astype(np.float64)
    cx, cy = (WIDTH - 1) / 2, (HEIGHT - 1) / 2
    x, y = cx - u, cy - v
    x1 = math.cos(angle) * x + math.sin(angle) * y
    y1 = -math.sin(angle) * x + math.cos(angle) * y
    expected = np.stack([(cx - x1) - u, (cy - y1) - v], axis=-1)
    np.testing.assert_allclose(truth.flow(1), expected, atol=2e-4)
    # z-depth is Z everywhere on the plane (range along the ray would grow off axis).
    np.testing.assert_allclose(truth.depth(2), z_m, rtol=1e-5)
    with pytest.raises(FileNotFoundError, match="instances"):
        truth.instance(0)


def card_scene(
    tmp_path: Path, stepping: str = "rate_hz = 1000", stop_s: float = 0.004
) -> tuple[Path, dict[str, float]]:
    """A card 2 m away moving right to left at 100 m/s until stop_s, then resting, over a
    checkered backdrop 4 m away."""
    geometry = {
        "z": 2.0,
        "half_w": 0.3,
        "half_h": 0.2,
        "x0": -0.4,
        "speed": 100.0,
        "stop_s": stop_s,
    }
    card = f"""<shape type="rectangle" id="card">
    <transform name="to_world"><scale x="{geometry["half_w"]}" y="{geometry["half_h"]}"/>
      <rotate y="1" angle="180"/><translate x="{geometry["x0"]}" z="{geometry["z"]}"/></transform>
    <bsdf type="diffuse"><rgb name="reflectance" value="0.9"/></bsdf></shape>"""
    camera = "[{ t_s = 0.0, position = [0, 0, 0], look_at = [0, 0, 1] }]"
    end = geometry["speed"] * stop_s
    objects = f"""[[objects]]
id = "card"
keyframes = [{{ t_s = 0.0, position = [0, 0, 0] }}, {{ t_s = {stop_s}, position = [{end}, 0, 0] }}]"""
    shapes = wall(4.0, name="backdrop", tiles=8) + card
    return write_scene(tmp_path, shapes, camera, objects, stepping=stepping), geometry


def card_offset_m(geometry: dict[str, float], t_s: float) -> float:
    return geometry["speed"] * min(t_s, geometry["stop_s"])


def card_pixels(geometry: dict[str, float], t_s: float) -> np.ndarray:
    """Pixels whose centre sees the card at t_s: its rectangle projected by hand."""
    centre_x = geometry["x0"] + card_offset_m(geometry, t_s)
    v, u = np.mgrid[0:HEIGHT, 0:WIDTH].astype(np.float64)
    # u = cx - f X / Z (camera +x is the image's left), v = cy - f Y / Z.
    x = ((WIDTH - 1) / 2 - u) * geometry["z"] / FOCAL_PX
    y = ((HEIGHT - 1) / 2 - v) * geometry["z"] / FOCAL_PX
    return (np.abs(x - centre_x) < geometry["half_w"]) & (np.abs(y) < geometry["half_h"])


def test_moving_card_has_flow_only_on_itself_and_instances_match_its_projection(
    tmp_path: Path,
) -> None:
    scene, geometry = card_scene(tmp_path)
    Simulation(scene, ground_truth="all").run(tmp_path / "run")
    truth = pecs.read_ground_truth(tmp_path / "run")
    card = truth.shape_ids.index("card")
    backdrop = truth.shape_ids.index("backdrop")
    assert truth.shapes.column("animated").to_pylist()[card] is True
    expected_du = -FOCAL_PX * geometry["speed"] * 1e-3 / geometry["z"]  # +x world is image left
    for i in range(4):
        inside = card_pixels(geometry, i * 1e-3)
        assert inside.sum() > 50
        instance = truth.instance(i)
        np.testing.assert_array_equal(instance == card, inside)
        assert (instance[~inside] == backdrop).all()
        flow = truth.flow(i)
        np.testing.assert_allclose(flow[inside, 0], expected_du, rtol=1e-3)
        np.testing.assert_allclose(flow[inside, 1], 0.0, atol=1e-3)
        assert (np.abs(flow[~inside]) < 1e-4).all()  # the backdrop and camera stand still
        np.testing.assert_allclose(truth.depth(i)[inside], geometry["z"], rtol=1e-5)
        pose = truth.object_pose("card", i)
        np.testing.assert_allclose(pose[:3, 3], [geometry["speed"] * i * 1e-3, 0, 0], atol=1e-12)
    with pytest.raises(IndexError, match="frame 5 out of range: the run has 5 frames"):
        truth.flow(5)
    with pytest.raises(KeyError, match="no animated object 'backdrop'"):
        truth.object_pose("backdrop", 0)


def test_adaptive_steps_give_each_frame_the_flow_of_its_own_interval(tmp_path: Path) -> None:
    # The card moves for 1 ms (fast steps), then rests (the steps grow).
    stepping = "adaptive = true\nmin_rate_hz = 1000\nmax_rate_hz = 8000"
    scene, geometry = card_scene(tmp_path, stepping, stop_s=0.001)
    Simulation(scene, ground_truth="flow,instances").run(tmp_path / "run")
    truth = pecs.read_ground_truth(tmp_path / "run")
    steps_us = np.diff(truth.t_us)
    assert len(set(steps_us.tolist())) > 1  # the steps do vary
    card = truth.shape_ids.index("card")
    t_s = truth.t_us * 1e-6
    for i in range(len(steps_us)):
        inside = truth.instance(i) == card
        np.testing.assert_array_equal(inside, card_pixels(geometry, t_s[i]))
        moved_m = card_offset_m(geometry, t_s[i + 1]) - card_offset_m(geometry, t_s[i])
        expected_du = -FOCAL_PX * moved_m / geometry["z"]
        np.testing.assert_allclose(truth.flow(i)[inside, 0], expected_du, rtol=1e-3, atol=1e-5)


def test_each_event_gets_the_flow_and_instance_of_its_frame_interval(tmp_path: Path) -> None:
    scene, geometry = card_scene(tmp_path)
    Simulation(scene, ground_truth="events").run(tmp_path / "run")
    events = pq.read_table(tmp_path / "run" / "events.parquet")
    assert events.num_rows > 100
    truth = pecs.read_ground_truth(tmp_path / "run")
    t = events.column("t").to_numpy()
    frame = events.column("gt_frame").to_numpy().astype(np.int64)
    # The interval (t_i, t_{i+1}] that holds each event; frames are 1 ms apart.
    np.testing.assert_array_equal(frame, np.clip(np.ceil(t / 1000.0).astype(int) - 1, 0, 3))
    x = events.column("x").to_numpy().astype(int)
    y = events.column("y").to_numpy().astype(int)
    instance = events.column("instance").to_numpy()
    on_card = np.array([card_pixels(geometry, f * 1e-3)[yy, xx] for f, xx, yy in zip(frame, x, y)])
    card = truth.shape_ids.index("card")
    np.testing.assert_array_equal(instance == card, on_card)
    flow_x = events.column("flow_x_px").to_numpy()
    expected_du = -FOCAL_PX * geometry["speed"] * 1e-3 / geometry["z"]
    np.testing.assert_allclose(flow_x[on_card], expected_du, rtol=1e-3)
    assert (np.abs(flow_x[~on_card]) < 1e-4).all()
    # The event readers still read the file.
    assert len(pecs.read_events(tmp_path / "run" / "events.parquet")) == events.num_rows


def test_a_folder_without_ground_truth_is_named(tmp_path: Path) -> None:
    with pytest.raises(FileNotFoundError, match="no ground truth here"):
        pecs.read_ground_truth(tmp_path)


def test_unknown_ground_truth_kind_and_bad_imu_rate_are_refused() -> None:
    with pytest.raises(ValueError, match="unknown kind 'albedo'"):
        Simulation("checkerboard", ground_truth="depth,albedo")
    with pytest.raises(ValueError, match="imu_rate_hz"):
        Simulation("checkerboard", ground_truth="imu", imu_rate_hz=-5)


def test_cli_writes_the_ground_truth_asked_for_and_a_rerun_replaces_it(
    tmp_path: Path, capsys: pytest.CaptureFixture
) -> None:
    from pecs.cli import main

    scene, _ = card_scene(tmp_path)
    out = tmp_path / "out"
    argv = ["simulate", str(scene), "-o", str(out), "--quiet"]
    assert main([*argv, "--ground-truth", "depth,imu", "--imu-rate", "2000"]) == 0
    truth = pecs.read_ground_truth(out)
    assert truth.imu.num_rows == 9  # 0 to 4 ms at 2 kHz
    np.testing.assert_allclose(truth.depth(0)[24, 32], 4.0, rtol=1e-5)  # the backdrop
    with pytest.raises(FileNotFoundError, match="flow"):
        truth.flow(0)
    # The ground-truth folder counts as the run's output: a rerun may replace it.
    assert main([*argv, "--ground-truth", "all"]) == 0
    assert pecs.read_ground_truth(out).flow(0).shape == (HEIGHT, WIDTH, 2)
    assert main([*argv, "--ground-truth", "depth,speed"]) == 2
    assert "unknown kind 'speed'" in capsys.readouterr().err


def test_realistic_lens_model_reprojects_the_plugins_traced_rays_onto_their_pixels(
    tmp_path: Path,
) -> None:
    # Static camera and wall: the flow is the fitted model's reprojection error of the points
    # that Mitsuba's lens plugin (a separate Dr.Jit trace) hits through each pixel centre.
    camera = "[{ t_s = 0.0, position = [0, 0, 0], look_at = [0, 0, 1] }]"
    scene = write_scene(tmp_path, wall(1.0, tiles=8), camera, duration_s=0.001)
    text = scene.read_text().replace(
        f'model = "pinhole"\nfov_deg = {FOV_DEG}',
        'lens = "pecs4"\nefl_mm = 4.0\nfocus_m = 1.0\nf_number = 4.5',
    )
    scene.write_text(text.replace(f"width = {WIDTH}", f"width = {WIDTH}, pixel_pitch_um = 60"))
    Simulation(scene, ground_truth="flow,depth").run(tmp_path / "run")
    truth = pecs.read_ground_truth(tmp_path / "run")
    model = truth.camera_model
    assert model.model == "lens" and model.residual_px < 0.01
    assert truth.distortion[0] < 0  # barrel, as pecs4's distortion_percent says at the edge
    # Paraxial focal length 4 mm over 60 um pixels, lengthened slightly by focusing at 1 m.
    assert 66.6 < truth.intrinsics[0, 0] < 67.2
    flow = truth.flow(0)
    assert np.isfinite(flow).all() and np.abs(flow).max() < 0.1
    # z-depth from the entrance pupil: the wall is 1 m from the film (the camera's origin).
    np.testing.assert_allclose(truth.depth(0) + model.centre_z_m, 1.0, rtol=1e-5)
