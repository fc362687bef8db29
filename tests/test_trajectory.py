"""Trajectories from TUM/CSV files and spline tracks, against analytic motion and scipy."""

from __future__ import annotations

from pathlib import Path

import numpy as np
import pytest
from pecs.render.animation import Keyframe, Track
from pecs.render.scene_file import load_scene
from pecs.render.trajectory_file import read_trajectory, read_trajectory_samples
from scipy.interpolate import CubicSpline as ScipySpline
from scipy.spatial.transform import Rotation

RADIUS_M, RATE_RAD_S = 2.0, 3.0  # v = 6 m/s, centripetal 18 m/s^2
TILT = Rotation.from_euler("xy", [20.0, -35.0], degrees=True)  # body axes tilted on the body


def circle_pose(t: np.ndarray) -> tuple[np.ndarray, Rotation]:
    """On a horizontal circle, turning with the heading: R(t) = Rz(w t) TILT."""
    angle = RATE_RAD_S * t
    position = RADIUS_M * np.stack([np.cos(angle), np.sin(angle), np.full_like(t, 0.5)], axis=-1)
    turn = Rotation.from_rotvec(np.asarray(angle)[..., None] * np.array([0.0, 0.0, 1.0]))
    return position, turn * TILT


def write_tum(path: Path, t: np.ndarray, position: np.ndarray, rotation: Rotation) -> Path:
    xyzw = rotation.as_quat()  # scipy's order is the TUM order: qx qy qz qw
    lines = ["# timestamp tx ty tz qx qy qz qw", ""]
    lines += [
        " ".join(f"{v:.12f}" for v in (ti, *p, *q))
        for ti, p, q in zip(t, position, xyzw, strict=True)
    ]
    path.write_text("\n".join(lines) + "\n")
    return path


@pytest.fixture
def circle_track(tmp_path: Path) -> Track:
    t = 1000.0 + np.arange(0.0, 2.0 + 1e-9, 0.02)  # Unix-like start, 50 Hz
    position, rotation = circle_pose(t - 1000.0)
    return read_trajectory(
        write_tum(tmp_path / "circle.tum", t, position, rotation), time_offset_s="first"
    )


def test_circle_spline_gives_centripetal_acceleration_and_the_turn_rate(
    circle_track: Track,
) -> None:
    for t in np.linspace(0.2, 1.8, 41):  # interior, off the knots too
        position, rotation = circle_pose(np.array(t))
        angle = RATE_RAD_S * t
        centripetal = -(RATE_RAD_S**2) * RADIUS_M * np.array([np.cos(angle), np.sin(angle), 0])
        acceleration = circle_track.acceleration(t)
        assert np.linalg.norm(acceleration - centripetal) < 0.01 * RATE_RAD_S**2 * RADIUS_M
        velocity = RATE_RAD_S * RADIUS_M * np.array([-np.sin(angle), np.cos(angle), 0])
        np.testing.assert_allclose(circle_track.velocity(t), velocity, atol=1e-3 * 6.0)
        # body rate: R^T dR/dt = TILT^T [w z]x TILT -> w TILT^T z
        body_rate = TILT.inv().apply([0.0, 0.0, RATE_RAD_S])
        np.testing.assert_allclose(circle_track.angular_velocity(t), body_rate, atol=1e-3 * 3.0)
        np.testing.assert_allclose(circle_track.pose(t)[:3, 3], position, atol=1e-5)
        np.testing.assert_allclose(circle_track.pose(t)[:3, :3], rotation.as_matrix(), atol=1e-5)


def test_spline_passes_through_every_sample_and_is_c2_at_the_knots() -> None:
    rng = np.random.default_rng(5)
    t = np.cumsum(rng.uniform(0.01, 0.05, 30))
    positions = np.cumsum(rng.normal(scale=0.01, size=(30, 3)), axis=0)
    rotations = Rotation.from_rotvec(np.cumsum(rng.normal(scale=0.1, size=(30, 3)), axis=0))
    wxyz = np.roll(rotations.as_quat(), 1, axis=1) * rng.choice([-1, 1], size=(30, 1))
    track = Track.from_samples(t, positions, wxyz)
    reference = ScipySpline(t, positions)  # not-a-knot, as ours
    for k in range(30):
        np.testing.assert_allclose(track.pose(t[k])[:3, 3], positions[k], atol=1e-12)
        np.testing.assert_allclose(track.pose(t[k])[:3, :3], rotations[k].as_matrix(), atol=1e-12)
    for x in np.linspace(t[0], t[-1], 200):
        np.testing.assert_allclose(track.acceleration(x), reference(x, 2), atol=1e-9)
    eps = 1e-9
    for knot in t[1:-1]:
        for derivative in (track.velocity, track.acceleration, track.angular_velocity):
            before, after = derivative(knot - eps), derivative(knot + eps)
            assert np.linalg.norm(after - before) < 1e-5 * (1 + np.linalg.norm(before))
        # angular acceleration continuous too (C2 rotation), by central differences
        h = 1e-5
        left = (track.angular_velocity(knot) - track.angular_velocity(knot - h)) / h
        right = (track.angular_velocity(knot + h) - track.angular_velocity(knot)) / h
        assert np.linalg.norm(right - left) < 1e-2 * (1 + np.linalg.norm(left))


def test_straight_line_is_reproduced_exactly(tmp_path: Path) -> None:
    rng = np.random.default_rng(1)
    t = [float(x) for x in np.sort(rng.uniform(0, 3, 12))]
    start, velocity = np.array([0.3, -1.0, 2.0]), np.array([1.5, 0.2, -0.7])
    header = "t_us,qw,qx,qy,qz,position_x_m,position_y_m,position_z_m,frame\n"
    q = Rotation.from_euler("y", 30, degrees=True).as_quat().tolist()  # x y z w
    rows = [
        f"{ti * 1e6!r},{q[3]!r},{q[0]!r},{q[1]!r},{q[2]!r},{p[0]!r},{p[1]!r},{p[2]!r},{i}"
        for i, (ti, p) in enumerate(zip(t, (start + np.outer(t, velocity)).tolist(), strict=True))
    ]
    path = tmp_path / "line.csv"
    path.write_text("# a straight line\n" + header + "\n".join(rows) + "\n")
    track = read_trajectory(path)
    for x in np.linspace(t[0], t[-1], 50)[1:-1]:  # inside: t_us / 1e6 may round past the ends
        np.testing.assert_allclose(track.pose(x)[:3, 3], start + x * velocity, atol=1e-9)
        np.testing.assert_allclose(track.velocity(x), velocity, atol=1e-9)
        np.testing.assert_allclose(track.acceleration(x), 0.0, atol=1e-8)
        np.testing.assert_allclose(track.angular_velocity(x), 0.0, atol=1e-12)


def test_csv_and_tum_files_agree(tmp_path: Path) -> None:
    t = np.arange(0.0, 1.0, 0.1)
    position, rotation = circle_pose(t)
    tum = read_trajectory_samples(write_tum(tmp_path / "a.txt", t, position, rotation))
    wxyz = np.roll(rotation.as_quat(), 1, axis=1)
    table = np.column_stack([t * 1e9, position, wxyz])
    header = "t_ns,position_x_m,position_y_m,position_z_m,qw,qx,qy,qz"
    np.savetxt(tmp_path / "a.csv", table, delimiter=",", header=header, comments="", fmt="%.12f")
    from_csv = read_trajectory_samples(tmp_path / "a.csv")
    np.testing.assert_allclose(from_csv.t_s, t, atol=1e-12)
    np.testing.assert_allclose(from_csv.positions, tum.positions, atol=1e-11)
    np.testing.assert_allclose(from_csv.quaternions_wxyz, wxyz, atol=1e-11)


@pytest.mark.parametrize(
    ("body", "suffix", "message"),
    [
        ("0 0 0 0 0 0 0 1\n0.2 0 0 0 0 0 0 1\n0.1 0 0 0 0 0 0 1\n", ".tum", r"\.tum:3: time 0\.1"),
        ("0 0 0 0 0 0 0 1\n0 1 0 0 0 0 0 1\n", ".tum", r"\.tum:2: time 0\.0 s repeats"),
        ("# c\n0 0 0 0 0 0 0 1\n0.1 nan 0 0 0 0 0 1\n", ".tum", r"\.tum:3: values must be finite"),
        ("0 0 0 0 0 0 0 1\n0.1 0 0 0 0 0 1\n", ".tum", r"\.tum:2: expected 8 numbers .* got 7"),
        ("0 0 0 0 0 0 0 2\n", ".tum", r"\.tum:1: quaternion norm 2"),
        ("0 0 0 0 0 0 zero 1\n", ".tum", r"\.tum:1: not a number"),
        (
            "t_s,position_x_m,position_y_m,position_z_m,qw,qx,qy\n",
            ".csv",
            r"\.csv:1: the header .*missing qz",
        ),
        (
            "t_s,position_x_m,position_y_m,position_z_m,qw,qx,qy,qz\n0,0,0,0,1,0,0\n",
            ".csv",
            r"\.csv:2: expected 8 columns",
        ),
        ("", ".tum", "no poses"),
        ("0 0 0 0 0 0 0 1\n", ".json", "unknown trajectory format"),
    ],
)
def test_bad_trajectory_files_name_the_line(
    tmp_path: Path, body: str, suffix: str, message: str
) -> None:
    path = tmp_path / f"bad{suffix}"
    path.write_text(body)
    with pytest.raises(ValueError, match=message):
        read_trajectory(path)


def test_rotations_170_degrees_apart_are_refused() -> None:
    quarter_turns = Rotation.from_euler("z", [[0.0], [170.0]], degrees=True).as_quat()
    with pytest.raises(ValueError, match="add samples"):
        Track.from_samples(
            np.array([0.0, 1.0]), np.zeros((2, 3)), np.roll(quarter_turns, 1, axis=1)
        )


def test_linear_keyframes_have_the_slerp_rate() -> None:
    # A quarter turn about z in 0.125 s: 4 pi rad/s about the body z axis (as the quadrant disk).
    quarter = np.array([np.cos(np.pi / 4), 0.0, 0.0, np.sin(np.pi / 4)])
    track = Track(
        [
            Keyframe(0.0, np.zeros(3), np.array([1.0, 0, 0, 0])),
            Keyframe(0.125, np.array([0.1, 0, 0]), quarter),
        ]
    )
    np.testing.assert_allclose(track.angular_velocity(0.06), [0, 0, 4 * np.pi], atol=1e-12)
    np.testing.assert_allclose(track.velocity(0.06), [0.8, 0, 0], atol=1e-12)
    np.testing.assert_allclose(track.acceleration(0.06), 0.0)
    np.testing.assert_allclose(track.velocity(0.2), 0.0)  # held after the last keyframe


SCENE = """
[scene]
mitsuba = "scene.xml"
[time]
duration_s = 1.0
rate_hz = 10
[sensor]
preset = "davis346"
[optics]
model = "pinhole"
efl_mm = 8.0
"""


def test_scene_file_reads_trajectories_relative_to_itself(tmp_path: Path) -> None:
    (tmp_path / "scene.xml").write_text('<scene version="3.0.0"/>')
    (tmp_path / "paths").mkdir()
    t = np.arange(0.0, 1.01, 0.05)
    position, rotation = circle_pose(t)
    write_tum(tmp_path / "paths" / "cam.tum", 100.0 + 2.0 * t, position, rotation)
    write_tum(tmp_path / "paths" / "obj.tum", t, position, rotation)
    (tmp_path / "scene.toml").write_text(
        SCENE
        + '[camera]\ntrajectory = "paths/cam.tum"\ntime_offset_s = 100.0\ntime_scale = 0.5\n'
        + 'axes = "opencv"\n'
        + '[[objects]]\nid = "a"\ntrajectory = "paths/obj.tum"\ninterpolation = "linear"\n'
        + '[[objects]]\nid = "b"\ninterpolation = "spline"\nkeyframes = [\n'
        + "  { t_s = 0.0, position = [0, 0, 0] }, { t_s = 0.5, position = [1, 0, 0] },\n"
        + "  { t_s = 1.0, position = [0, 0, 0] }]\n"
    )
    spec = load_scene(tmp_path / "scene.toml")
    assert spec.camera is not None
    # scene time (t_file - 100) * 0.5 = t; OpenCV axes (x right, y down) -> pecs's (x left, y up)
    flip = np.diag([-1.0, -1.0, 1.0])
    for k in (0, 7, 20):
        pose = spec.camera.pose(t[k])
        np.testing.assert_allclose(pose[:3, 3], position[k], atol=1e-9)
        np.testing.assert_allclose(pose[:3, :3], rotation[k].as_matrix() @ flip, atol=1e-9)
    np.testing.assert_allclose(spec.objects["a"].pose(0.025)[:3, 3], position[:2].mean(0))
    # three keyframes: the spline is the parabola through them, x(t) = 4 t (1 - t)
    np.testing.assert_allclose(spec.objects["b"].pose(0.25)[:3, 3], [0.75, 0, 0], atol=1e-12)
    np.testing.assert_allclose(spec.objects["b"].acceleration(0.25), [-8.0, 0, 0], atol=1e-9)


@pytest.mark.parametrize(
    ("camera", "message"),
    [
        ('trajectory = "nope.tum"', r"camera\.trajectory: trajectory file not found"),
        ('trajectory = "cam.tum"\nkeyframes = []', "keyframes or a trajectory, not both"),
        ('trajectory = "cam.tum"\ntime_offset_s = "start"', r"camera\.time_offset_s"),
        ('trajectory = "cam.tum"\ninterpolation = "cubic"', r"camera\.interpolation"),
        ('trajectory = "cam.tum"\naxes = "ros"', r"camera\.trajectory: axes must be one of"),
        ('trajectory = "cam.tum"\ntime_scale = 0', r"camera\.time_scale: must be a positive"),
    ],
)
def test_bad_trajectory_keys_name_the_key(tmp_path: Path, camera: str, message: str) -> None:
    (tmp_path / "scene.xml").write_text('<scene version="3.0.0"/>')
    (tmp_path / "cam.tum").write_text("0 0 0 0 0 0 0 1\n1 1 0 0 0 0 0 1\n")
    (tmp_path / "scene.toml").write_text(SCENE + f"[camera]\n{camera}\n")
    with pytest.raises((ValueError, FileNotFoundError), match=message):
        load_scene(tmp_path / "scene.toml")
