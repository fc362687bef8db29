"""Ground truth over any window, against geometry done by hand: a box turning and sliding in
front of a wall, seen by a camera sliding sideways (32 x 24, 1 kHz frames over 50 ms).

The expected values come from the pinhole equations written here (back-projection of the
stored depth with the stored K and poses, or a ray cast by hand against the wall's plane and
the box's slabs), and the object and camera poses between frames from the keyframes written
into the scene file (linear motion, constant turn rate); nothing here calls pecs's geometry.
"""

from __future__ import annotations

import math
from pathlib import Path

import numpy as np
import pecs
import pytest
from pecs.dataset import open_dataset, run_dataset
from pecs.render import Simulation
from scipy.spatial import ConvexHull

WIDTH, HEIGHT, FOV_DEG = 32, 24, 60.0
FOCAL_PX = WIDTH / 2 / math.tan(math.radians(FOV_DEG) / 2)
DURATION_US = 50_000
WALL_Z_M = 3.0
# The box: a cube of half size 0.25 m centred at BOX_CENTRE_M, sliding BOX_SLIDE_M in 50 ms and
# turning BOX_TURN_DEG about +y through its centre; the camera slides CAMERA_SLIDE_M.
BOX_HALF_M = 0.25
BOX_CENTRE_M = np.array([-0.6, 0.0, 1.5])
BOX_SLIDE_M = np.array([1.2, 0.0, 0.0])
BOX_TURN_DEG = 30.0
CAMERA_SLIDE_M = np.array([0.05, 0.02, 0.0])

SCENE_XML = f"""<scene version="3.0.0">
  <emitter type="constant"><spectrum name="radiance" value="1.0"/></emitter>
  <shape type="rectangle" id="wall">
    <transform name="to_world"><scale x="20" y="20"/><rotate y="1" angle="180"/>
      <translate z="{WALL_Z_M}"/></transform>
    <bsdf type="diffuse"/></shape>
  <shape type="cube" id="box_1">
    <transform name="to_world"><scale value="{BOX_HALF_M}"/>
      <translate x="{BOX_CENTRE_M[0]}" y="{BOX_CENTRE_M[1]}" z="{BOX_CENTRE_M[2]}"/></transform>
    <bsdf type="diffuse"/></shape>
</scene>"""

# TOML's inline tables stay on one line.
LOOK_AT = (CAMERA_SLIDE_M + [0, 0, 1]).tolist()
BOX_AXIS_ANGLE = f"axis = [0, 1, 0], angle_deg = {BOX_TURN_DEG}"
SCENE_TOML = f"""[scene]
mitsuba = "scene.xml"
[time]
duration_s = {DURATION_US * 1e-6}
rate_hz = 1000
[sensor]
preset = "ideal"
overrides = {{ width = {WIDTH}, height = {HEIGHT} }}
[optics]
model = "pinhole"
fov_deg = {FOV_DEG}
[render]
spp = 1
[camera]
keyframes = [
  {{ t_s = 0.0, position = [0, 0, 0], look_at = [0, 0, 1] }},
  {{ t_s = {DURATION_US * 1e-6}, position = {CAMERA_SLIDE_M.tolist()}, look_at = {LOOK_AT} }},
]
[[objects]]
id = "box_1"
pivot = {BOX_CENTRE_M.tolist()}
keyframes = [
  {{ t_s = 0.0, position = [0, 0, 0], axis = [0, 1, 0], angle_deg = 0 }},
  {{ t_s = {DURATION_US * 1e-6}, position = {BOX_SLIDE_M.tolist()}, {BOX_AXIS_ANGLE} }},
]
[classes]
wall = "background"
"""


@pytest.fixture(scope="module")
def truth(tmp_path_factory: pytest.TempPathFactory) -> pecs.ground_truth.GroundTruth:
    folder = tmp_path_factory.mktemp("box_wall")
    (folder / "scene.xml").write_text(SCENE_XML)
    (folder / "scene.toml").write_text(SCENE_TOML)
    Simulation(folder / "scene.toml", ground_truth="depth,instances,normals").run(folder / "run")
    return pecs.read_ground_truth(folder / "run")


# -- the scene by hand ------------------------------------------------------------------------


def camera_position(t_us: float) -> np.ndarray:
    """The camera's keyframes, lerped; it keeps the world's axes (look_at straight ahead)."""
    return CAMERA_SLIDE_M * (t_us / DURATION_US)


def box_pose(t_us: float) -> tuple[np.ndarray, np.ndarray]:
    """(centre, rotation) of the box: lerped slide, turn at a constant rate about +y."""
    angle = math.radians(BOX_TURN_DEG) * t_us / DURATION_US
    c, s = math.cos(angle), math.sin(angle)
    rotation = np.array([[c, 0.0, s], [0.0, 1.0, 0.0], [-s, 0.0, c]])
    return BOX_CENTRE_M + BOX_SLIDE_M * (t_us / DURATION_US), rotation


def pixel_rays(u: np.ndarray, v: np.ndarray, k: np.ndarray) -> np.ndarray:
    """Camera-frame directions with unit z through pixels (u, v): Mitsuba's camera frame is
    OpenCV's with x and y negated."""
    x_cv = (u - k[0, 2]) / k[0, 0]
    y_cv = (v - k[1, 2]) / k[1, 1]
    return np.stack([-x_cv, -y_cv, np.ones_like(x_cv)], axis=-1)


def project(points_world: np.ndarray, t_us: float, k: np.ndarray) -> np.ndarray:
    camera = points_world - camera_position(t_us)
    u = k[0, 2] - k[0, 0] * camera[..., 0] / camera[..., 2]
    v = k[1, 2] - k[1, 1] * camera[..., 1] / camera[..., 2]
    return np.stack([u, v], axis=-1)


def cast(t_us: float, k: np.ndarray, u: np.ndarray, v: np.ndarray) -> tuple[np.ndarray, ...]:
    """(z-depth, is-box, face) of the first surface along the rays through (u, v) at t_us: the
    wall's plane and the box's slabs (the ray's parameter is its z-depth: direction z is 1);
    face: 0 the wall, 1 + the box's axis whose slab the ray enters."""
    directions = pixel_rays(u, v, k)
    origin = camera_position(t_us)
    wall = WALL_Z_M - origin[2]
    centre, rotation = box_pose(t_us)
    local_origin = rotation.T @ (origin - centre)
    local_direction = directions @ rotation  # rotation.T applied to each direction
    with np.errstate(divide="ignore", invalid="ignore"):
        low = (-BOX_HALF_M - local_origin) / local_direction
        high = (BOX_HALF_M - local_origin) / local_direction
    near = np.nanmax(np.minimum(low, high), axis=-1)
    far = np.nanmin(np.maximum(low, high), axis=-1)
    box = (near <= far) & (near > 0) & (near < wall)
    face = np.where(box, 1 + np.nanargmax(np.minimum(low, high), axis=-1), 0)
    return np.where(box, near, wall), box, face


def move(points_world: np.ndarray, is_box: np.ndarray, t0_us: float, t1_us: float) -> np.ndarray:
    """Box points ride with the box from t0 to t1; wall points stay."""
    c0, r0 = box_pose(t0_us)
    c1, r1 = box_pose(t1_us)
    moved = (points_world - c0) @ r0 @ r1.T + c1  # c1 + R1 R0^T (x - c0)
    return np.where(is_box[..., None], moved, points_world)


def expected_flow_from_depth(
    depth: np.ndarray, is_box: np.ndarray, t0_us: float, t1_us: float, k: np.ndarray
) -> np.ndarray:
    """Back-project each pixel's z-depth at t0, move it, project it at t1, minus the pixel."""
    v, u = np.mgrid[0:HEIGHT, 0:WIDTH].astype(np.float64)
    points = camera_position(t0_us) + pixel_rays(u, v, k) * depth[..., None]
    return project(move(points, is_box, t0_us, t1_us), t1_us, k) - np.stack([u, v], axis=-1)


def box_outline(t_us: float, k: np.ndarray) -> ConvexHull:
    """The box's outline in the image at t_us: the hull of its 8 projected corners."""
    bits = (np.arange(8)[:, None] >> np.arange(3)) & 1
    centre, rotation = box_pose(t_us)
    corners = centre + (np.where(bits == 1, BOX_HALF_M, -BOX_HALF_M)) @ rotation.T
    return ConvexHull(project(corners, t_us, k))


def outline_distance(hull: ConvexHull, points: np.ndarray) -> np.ndarray:
    """Signed distance bound to the hull (negative inside; |d| > 1 means > 1 px from it)."""
    normals, offsets = hull.equations[:, :2], hull.equations[:, 2]
    return np.max(points @ normals.T + offsets, axis=-1)


# -- tests -----------------------------------------------------------------------------------


def test_the_hand_scene_matches_the_stored_frames(truth: pecs.ground_truth.GroundTruth) -> None:
    k = truth.intrinsics
    np.testing.assert_allclose(k[0, 0], FOCAL_PX, rtol=1e-12)
    assert truth.shape_ids == ["wall", "box_1"]
    for i in (0, 17, 50):
        t_us = int(truth.t_us[i])
        np.testing.assert_allclose(truth.camera_pose(i)[:3, 3], camera_position(t_us), atol=1e-12)
        v, u = np.mgrid[0:HEIGHT, 0:WIDTH].astype(np.float64)
        depth, is_box, _ = cast(t_us, k, u, v)
        np.testing.assert_allclose(truth.depth(i), depth, rtol=1e-5)
        np.testing.assert_array_equal(truth.instance(i), is_box.astype(np.int32))


@pytest.mark.parametrize(
    ("t0_us", "t1_us"),
    [(10_000, 11_000), (10_000, 12_500), (10_000, 43_217), (40_000, 3_700), (0, 50_000)],
)
def test_flow_from_a_frame_to_any_time_matches_the_pinhole_equations(
    truth: pecs.ground_truth.GroundTruth, t0_us: int, t1_us: int
) -> None:
    i = int(np.flatnonzero(truth.t_us == t0_us)[0])
    expected = expected_flow_from_depth(
        truth.depth(i).astype(np.float64), truth.instance(i) == 1, t0_us, t1_us, truth.intrinsics
    )
    flow = truth.flow_between(t0_us, t1_us)
    assert flow.flow_px.shape == (HEIGHT, WIDTH, 2) and flow.flow_px.dtype == np.float32
    assert flow.valid.sum() > 0.5 * WIDTH * HEIGHT
    error = np.abs(flow.flow_px - expected)[flow.valid]
    assert error.max() < 1e-3, error.max()


def test_flow_from_between_frames_matches_a_ray_cast_by_hand(
    truth: pecs.ground_truth.GroundTruth,
) -> None:
    """t0 between frames: the surface seen then is rebuilt from the frames around it; on the
    wall and the box's flat faces that is exact, within a pixel of the box's outline it may be
    approximate (and is then not valid)."""
    k, t0_us, t1_us = truth.intrinsics, 20_500, 34_250
    v, u = np.mgrid[0:HEIGHT, 0:WIDTH].astype(np.float64)
    depth, is_box, face = cast(t0_us, k, u, v)
    # Exact wherever the pixel and its 8 neighbours see one plane; across the box's edges the
    # rebuilt surface is a chord (within a few percent).
    padded = np.pad(face, 1, mode="edge")
    one_face = np.all(
        [
            padded[1 + dv : 1 + dv + HEIGHT, 1 + du : 1 + du + WIDTH] == face
            for dv in (-1, 0, 1)
            for du in (-1, 0, 1)
        ],
        axis=0,
    )
    rebuilt = truth.depth_at(t0_us)
    assert one_face.sum() > 0.8 * WIDTH * HEIGHT
    np.testing.assert_allclose(rebuilt[one_face], depth[one_face], rtol=1e-6)
    away_from_outline = np.abs(outline_distance(box_outline(t0_us, k), np.stack([u, v], -1))) > 1
    instance = truth.instance_at(t0_us)
    np.testing.assert_array_equal(instance[away_from_outline], is_box[away_from_outline])
    flow = truth.flow_between(t0_us, t1_us)
    expected = expected_flow_from_depth(depth, is_box, t0_us, t1_us, k)
    assert flow.valid.sum() > 0.5 * WIDTH * HEIGHT
    assert np.abs(flow.flow_px - expected)[flow.valid].max() < 1e-3


@pytest.mark.parametrize(("t0_us", "t1_us"), [(0, 20_000), (2_000, 20_500), (40_000, 9_000)])
def test_mask_is_false_where_the_box_covers_the_point_and_true_where_nothing_does(
    truth: pecs.ground_truth.GroundTruth, t0_us: int, t1_us: int
) -> None:
    k = truth.intrinsics
    v, u = np.mgrid[0:HEIGHT, 0:WIDTH].astype(np.float64)
    depth, is_box, _ = cast(t0_us, k, u, v)
    landing = np.stack([u, v], axis=-1) + expected_flow_from_depth(depth, is_box, t0_us, t1_us, k)
    distance = outline_distance(box_outline(t1_us, k), landing)
    in_image = (
        (landing[..., 0] > 0.5)
        & (landing[..., 0] < WIDTH - 1.5)
        & (landing[..., 1] > 0.5)
        & (landing[..., 1] < HEIGHT - 1.5)
    )
    flow = truth.flow_between(t0_us, t1_us)
    covered = ~is_box & (distance < -1.0) & in_image  # wall points behind the box at t1
    clear = ~is_box & (distance > 1.0) & in_image
    assert covered.sum() >= 20 and clear.sum() >= 100
    assert not flow.valid[covered].any()
    assert flow.occluded[covered].all()
    assert flow.valid[clear].all()
    # Out of the image at t1: never valid.
    outside = (landing[..., 0] < -0.5) | (landing[..., 0] > WIDTH - 0.5)
    assert not flow.valid[outside].any()


def bilinear(field: np.ndarray, points: np.ndarray) -> np.ndarray:
    x0 = np.floor(points[:, 0]).astype(int)
    y0 = np.floor(points[:, 1]).astype(int)
    fx, fy = points[:, 0] - x0, points[:, 1] - y0
    x1, y1 = x0 + 1, y0 + 1
    w = [(1 - fx) * (1 - fy), fx * (1 - fy), (1 - fx) * fy, fx * fy]
    corners = [field[y0, x0], field[y0, x1], field[y1, x0], field[y1, x1]]
    shape = (-1,) + (1,) * (field.ndim - 2)
    return sum(weight.reshape(shape) * value for weight, value in zip(w, corners, strict=True))


@pytest.mark.parametrize("start_us", [0, 500])
def test_composed_1ms_flows_agree_with_the_direct_flow_where_the_point_stays_visible(
    truth: pecs.ground_truth.GroundTruth, start_us: int
) -> None:
    """From frames (start 0) and from between frames (start 0.5 ms): 50 or 49 steps of 1 ms,
    each sampled bilinearly where its four pixels are valid and on the tracked instance. The
    wall's flow is affine in the pixel, so bilinear sampling is exact there; on the box's
    turning faces it is not, and 49 samples of it add up to a few thousandths of a pixel."""
    steps = (DURATION_US - start_us) // 1000
    end_us = start_us + steps * 1000
    v, u = np.mgrid[0:HEIGHT, 0:WIDTH].astype(np.float64)
    start = np.stack([u.ravel(), v.ravel()], axis=-1)
    points = start.copy()
    on_box = truth.instance_at(start_us).ravel() == 1
    alive = truth.instance_at(start_us).ravel() >= 0
    for step in range(steps):
        t0 = start_us + step * 1000
        flow = truth.flow_between(t0, t0 + 1000)
        alive &= np.all((points >= 0) & (points < [WIDTH - 1, HEIGHT - 1]), axis=1)
        safe = np.where(alive[:, None], points, 0.0)
        alive &= bilinear(flow.valid.astype(float), safe) > 1 - 1e-9
        box_share = bilinear((truth.instance_at(t0) == 1).astype(float), safe)
        alive &= np.abs(box_share - on_box) < 1e-9
        points += np.where(alive[:, None], bilinear(np.nan_to_num(flow.flow_px), safe), 0.0)
    direct = truth.flow_between(start_us, end_us)
    both = alive & direct.valid.ravel()
    assert (both & ~on_box).sum() > 150 and (both & on_box).sum() > 30
    error = np.abs(points - start - direct.flow_px.reshape(-1, 2)).max(axis=1)
    assert error[both & ~on_box].max() < 1e-5
    assert error[both & on_box].max() < 5e-3


def test_boxes_classes_and_normals_match_the_scene(truth: pecs.ground_truth.GroundTruth) -> None:
    k, t_us = truth.intrinsics, 25_000
    assert truth.classes == ["background", "box"]  # [classes], then the id less its number
    boxes = truth.boxes_at(t_us)
    np.testing.assert_array_equal(boxes.instance, [0, 1])
    assert boxes.class_name == ["background", "box"]
    # 3D: the box's corners at 25 ms, in the camera frame (camera axes = world axes).
    bits = (np.arange(8)[:, None] >> np.arange(3)) & 1
    centre, rotation = box_pose(t_us)
    corners = centre + np.where(bits == 1, BOX_HALF_M, -BOX_HALF_M) @ rotation.T
    np.testing.assert_allclose(
        boxes.corners_camera_m[1], corners - camera_position(t_us), atol=1e-6
    )
    # 2D: the pixels the box covers, sides on pixel edges.
    covered = truth.instance_at(t_us) == 1
    rows, columns = np.nonzero(covered)
    np.testing.assert_array_equal(
        boxes.box_2d_px[1],
        [columns.min() - 0.5, rows.min() - 0.5, columns.max() + 0.5, rows.max() + 0.5],
    )
    assert boxes.pixels[1] == covered.sum()
    # ... and that is the projected outline's box, to the pixel.
    hull = box_outline(t_us, k)
    outline = hull.points[hull.vertices]
    np.testing.assert_allclose(boxes.box_2d_px[1, :2], outline.min(axis=0), atol=1.0)
    np.testing.assert_allclose(boxes.box_2d_px[1, 2:], outline.max(axis=0), atol=1.0)
    # Normals: the wall faces the camera (-z in the camera frame); the box's front face is
    # turned by its angle about +y.
    normals = truth.normals(25)
    wall = truth.instance(25) == 0
    np.testing.assert_allclose(normals[wall], np.tile([0.0, 0.0, -1.0], (wall.sum(), 1)), atol=1e-6)
    angle = math.radians(BOX_TURN_DEG) * 0.5
    front = np.array([-math.sin(angle), 0.0, -math.cos(angle)])  # R_y(angle) @ (0, 0, -1)
    box_normals = normals[truth.instance(25) == 1]
    assert np.isclose(box_normals @ front, 1.0, atol=1e-5).sum() > 0.5 * len(box_normals)
    assert np.all(np.einsum("ij,ij->i", box_normals, box_normals) > 0.999)


def test_times_outside_the_run_are_refused(truth: pecs.ground_truth.GroundTruth) -> None:
    with pytest.raises(ValueError, match=r"t1_us=50001 is outside the run's frames \(0 to 50000"):
        truth.flow_between(0, 50_001)
    with pytest.raises(TypeError, match="t0_us must be an integer"):
        truth.flow_between(0.5, 1000)  # type: ignore[arg-type]


def test_dataset_windows_carry_the_flow_over_the_window_and_depth_and_instances_at_its_end(
    tmp_path: Path,
) -> None:
    """Windows of 3.5 ms over 10 ms of the scene: their ends fall between frames (1 kHz)."""
    (tmp_path / "scene.xml").write_text(SCENE_XML)
    (tmp_path / "scene.toml").write_text(SCENE_TOML)
    (tmp_path / "spec.toml").write_text(
        f"""[dataset]
name = "box"
seed = 3
[defaults]
duration_s = 0.01
ground_truth = "depth,instances"
[defaults.sensor]
width = {WIDTH}
height = {HEIGHT}
[[sequences]]
scene = "scene.toml"
"""
    )
    run_dataset(tmp_path / "spec.toml", tmp_path / "out", workers=1)
    windows = open_dataset(tmp_path / "out").windows(duration_us=3_500, dense_ground_truth=True)
    v, u = np.mgrid[0:HEIGHT, 0:WIDTH].astype(np.float64)
    k = windows[0].ground_truth().intrinsics
    ends = []
    for window in windows:
        arrays = window.arrays()
        t0_us, t1_us = (int(t) for t in arrays["flow_t_us"])
        ends.append((t0_us, t1_us))
        depth, is_box, _ = cast(t0_us, k, u, v)
        expected = expected_flow_from_depth(depth, is_box, t0_us, t1_us, k)
        valid = arrays["flow_valid"]
        assert valid.sum() > 0.5 * WIDTH * HEIGHT
        assert np.abs(arrays["flow_px"] - expected)[valid].max() < 1e-3
        end_depth, end_box, _ = cast(t1_us, k, u, v)
        away = np.abs(outline_distance(box_outline(t1_us, k), np.stack([u, v], -1))) > 1
        np.testing.assert_array_equal(arrays["instance_map"][away], end_box[away])
        np.testing.assert_allclose(arrays["depth_m"][away & ~end_box], WALL_Z_M, rtol=1e-6)
    assert ends == [(0, 3_500), (3_500, 7_000), (7_000, 10_000)]  # the last clipped to 10 ms


def test_classes_naming_no_shape_or_not_a_name_are_refused(tmp_path: Path) -> None:
    (tmp_path / "scene.xml").write_text(SCENE_XML)
    scene = tmp_path / "scene.toml"
    scene.write_text(SCENE_TOML.replace('wall = "background"', 'wal = "background"'))
    with pytest.raises(ValueError, match=r"\[classes\] wal: no shape has this id"):
        Simulation(scene, ground_truth="instances").run(tmp_path / "run")
    assert not (tmp_path / "run").exists()
    scene.write_text(SCENE_TOML.replace('wall = "background"', "wall = 3"))
    with pytest.raises(ValueError, match=r"classes\.wall: expected a class name, got 3"):
        Simulation(scene)
