"""Simulations refuse what they cannot do right, before any work: trajectories that do not cover
the run, an IMU asked of a path without an acceleration, absurd rates, durations and sample
counts, and a dataset's bad draw is blamed on the draw. Nothing here renders."""

from __future__ import annotations

from pathlib import Path

import numpy as np
import pytest
from cli_run import PYTHON_SYNTAX, run_cli
from pecs.dataset import parse_spec
from pecs.dataset.sequence import build_simulation
from pecs.ground_truth.imu import GRAVITY_WORLD_M_S2, imu_table
from pecs.render import Simulation, Track, read_trajectory
from pecs.render.animation import Keyframe, quaternion_from_axis_angle
from pecs.render.scene_file import load_scene
from scipy.interpolate import CubicSpline as ScipySpline

REPO = Path(__file__).resolve().parents[1]
SETTINGS = """[scene]
mitsuba = "scene.xml"
[time]
duration_s = {duration_s}
rate_hz = 100
[sensor]
preset = "davis346"
[optics]
model = "pinhole"
efl_mm = 8.0
"""


def write_line_tum(path: Path, t_s: np.ndarray) -> Path:
    """A camera moving along +x at 1 m/s, looking down +z (identity rotation)."""
    rows = [f"{t:.6f} {t - t_s[0]:.6f} 0 0 0 0 0 1" for t in t_s]
    path.write_text("\n".join(rows) + "\n")
    return path


def scene_file(folder: Path, camera: str, duration_s: float = 0.3) -> Path:
    (folder / "scene.xml").write_text('<scene version="3.0.0"/>')
    path = folder / "scene.toml"
    path.write_text(SETTINGS.format(duration_s=duration_s) + "[camera]\n" + camera + "\n")
    return path


# -- 6: trajectories that do not cover the run --------------------------------------------------


def test_a_trajectory_ending_before_the_run_is_refused_with_both_spans(tmp_path: Path) -> None:
    camera = read_trajectory(write_line_tum(tmp_path / "cam.tum", np.linspace(0.0, 0.1, 11)))
    with pytest.raises(ValueError, match=r"0 s to 0\.1 s.*0 s to 0\.3 s.*--duration 0\.1"):
        Simulation("checkerboard", camera=camera, duration_s=0.3)
    Simulation("checkerboard", camera=camera, duration_s=0.1)  # covered: accepted


def test_unix_style_times_without_an_offset_are_refused_and_first_fixes_them(
    tmp_path: Path,
) -> None:
    path = write_line_tum(tmp_path / "cam.tum", 5.0 + np.linspace(0.0, 0.3, 31))
    with pytest.raises(ValueError, match=r'5 s to 5\.3 s.*time_offset_s = "first"'):
        Simulation("checkerboard", camera=read_trajectory(path), duration_s=0.3)
    Simulation("checkerboard", camera=read_trajectory(path, time_offset_s="first"), duration_s=0.3)


def test_a_scene_files_trajectory_is_checked_against_the_duration_given(
    tmp_path: Path, capsys: pytest.CaptureFixture
) -> None:
    write_line_tum(tmp_path / "cam.tum", np.linspace(0.0, 0.2, 21))
    scene = scene_file(tmp_path, 'trajectory = "cam.tum"', duration_s=0.2)
    Simulation(scene)
    code, _, err = run_cli(
        capsys, "simulate", str(scene), "--duration", "0.3", "-o", str(tmp_path / "out")
    )
    assert code == 2 and err.count("\n") == 1, err
    assert "camera" in err and "cam.tum" in err and "0 s to 0.2 s" in err
    assert "Traceback" not in err and not PYTHON_SYNTAX.search(err)


# -- 7: IMU of piecewise-linear keyframes ------------------------------------------------------


def independent_world_acceleration(
    keyframes_t_s: np.ndarray, positions: np.ndarray, t_s: np.ndarray
) -> np.ndarray:
    """d2p/dt2 of scipy's not-a-knot spline through the keyframe positions, by central
    differences of its positions (h = 1 ms, inside the track)."""
    spline = ScipySpline(keyframes_t_s, positions, bc_type="not-a-knot")
    h = 1e-3
    t = np.clip(t_s, keyframes_t_s[0] + h, keyframes_t_s[-1] - h)
    return (spline(t + h) - 2.0 * spline(t) + spline(t - h)) / h**2


@pytest.mark.parametrize(
    ("scene", "camera_keyframes"),
    [
        (
            "room",
            ([0.0, 0.5, 1.0], [[-0.5, 0.6, 2.0], [0.0, 0.7, 1.8], [0.5, 0.6, 2.0]]),
        ),
        (
            REPO / "scenes" / "city_flight" / "scene.toml",
            ([0.0, 0.25, 0.5], [[0.0, 8.0, 12.0], [1.5, 7.0, 2.0], [0.0, 6.5, -8.0]]),
        ),
    ],
)
def test_shipped_scenes_give_a_bounded_smooth_imu_acceleration(
    scene: str | Path, camera_keyframes: tuple[list[float], list[list[float]]]
) -> None:
    spec = Simulation(scene, ground_truth="imu").spec  # not refused
    assert spec.camera is not None
    duration_s = spec.time.duration_s
    imu = imu_table(spec.camera.pose, duration_s, 1000.0).to_pydict()
    specific_force = np.array([imu[f"accel_{a}_m_s2"] for a in "xyz"]).T
    t_s = np.array(imu["t_us"]) / 1e6
    # Back to the world: a = R f + g (R from the pose: a change of frame, not what is tested).
    world = np.array(
        [spec.camera.pose(t)[:3, :3] @ f + GRAVITY_WORLD_M_S2 for t, f in zip(t_s, specific_force)]
    )
    key_t, key_p = np.array(camera_keyframes[0]), np.array(camera_keyframes[1])
    expected = independent_world_acceleration(key_t, key_p, t_s)
    # Three keyframes: the parabola through them, one constant acceleration (up to 48 m/s^2).
    np.testing.assert_allclose(world, expected, atol=1e-3 * np.abs(expected).max() + 1e-6)
    assert np.abs(world).max() < 200.0  # no impulse (a linear path read 121,657 m/s^2)
    assert np.abs(np.diff(world, axis=0)).max() < 1.0  # smooth from sample to sample


def test_imu_of_linear_keyframes_with_a_corner_is_refused_naming_the_fix(
    tmp_path: Path, capsys: pytest.CaptureFixture
) -> None:
    corner = (
        "keyframes = [{ t_s = 0.0, position = [0, 0, 0] }, { t_s = 0.1, position = [1, 0, 0] },"
        " { t_s = 0.3, position = [1, 0, 1] }]"
    )
    scene = scene_file(tmp_path, corner)
    with pytest.raises(ValueError, match=r'0\.1 s.*interpolation = "spline"'):
        Simulation(scene, ground_truth="imu")
    Simulation(scene, ground_truth="depth")  # no IMU: linear keyframes are fine
    code, _, err = run_cli(
        capsys, "simulate", str(scene), "--ground-truth", "imu", "-o", str(tmp_path / "out")
    )
    assert code == 2 and err.count("\n") == 1 and 'interpolation = "spline"' in err, err
    # The same keyframes as a spline, and a straight line at constant speed, are accepted.
    Simulation(scene_file(tmp_path, corner + '\ninterpolation = "spline"'), ground_truth="imu")
    line = "keyframes = [{ t_s = 0.0, position = [0, 0, 0] }, { t_s = 0.3, position = [3, 0, 0] }]"
    Simulation(scene_file(tmp_path, line), ground_truth="imu")


def test_imu_past_the_end_of_a_moving_spline_is_refused(tmp_path: Path) -> None:
    # The camera stops dead at 0.3 s (held after its last keyframe): an impulse at 0.3 s.
    moving = (
        'interpolation = "spline"\nkeyframes = [{ t_s = 0.0, position = [0, 0, 0] }, '
        "{ t_s = 0.15, position = [1, 0, 0] }, { t_s = 0.3, position = [2, 0, 1] }]"
    )
    scene = scene_file(tmp_path, moving)
    Simulation(scene, ground_truth="imu")
    with pytest.raises(ValueError, match=r"0\.3 s"):
        Simulation(scene, ground_truth="imu", duration_s=0.5)


def test_a_linear_turn_about_a_pivot_jumps_by_the_change_of_rate_times_the_arm() -> None:
    # About +y at 1 rad/s, then 2 rad/s: the origin, 1 m from the pivot, jumps by 1 m/s.
    angles_deg = np.degrees([0.0, 0.5, 1.5])
    keys = [
        Keyframe(t, np.zeros(3), quaternion_from_axis_angle((0, 1, 0), a))
        for t, a in zip((0.0, 0.5, 1.0), angles_deg)
    ]
    jumps = Track(keys, pivot=(1.0, 0.0, 0.0)).velocity_jumps(0.0, 2.0)
    assert [t for t, _ in jumps] == [0.5, 1.0]  # the change of rate, then the stop
    np.testing.assert_allclose([j for _, j in jumps], [1.0, 2.0], rtol=1e-9)
    assert Track(keys).velocity_jumps(0.0, 2.0) == []  # turning on the spot: no velocity


# -- 10: absurd numbers --------------------------------------------------------------------------


@pytest.mark.parametrize(
    ("settings", "name"),
    [
        ({"rate_hz": 1e12}, "rate_hz"),
        ({"rate_hz": 3e6}, "rate_hz"),
        ({"duration_s": 1e7}, "duration_s"),
        ({"duration_s": 1e-9}, "duration_s"),
        ({"imu_rate_hz": 1e12, "ground_truth": "imu"}, "imu_rate_hz"),
        ({"duration_s": 1e5, "rate_hz": 1.0, "ground_truth": "imu"}, "imu_rate_hz"),
        ({"spp": 10**12}, "spp"),
        ({"spp": 4 * 10**9}, "spp"),
        ({"spp": 60_000}, "spp"),  # 346 x 260 x 60,000 > 2^32 samples a frame
    ],
)
def test_absurd_numbers_are_refused_before_any_work(settings: dict, name: str) -> None:
    with pytest.raises(ValueError, match=rf"^{name}: "):
        Simulation("checkerboard", **settings)


def test_the_limits_themselves_are_accepted() -> None:
    Simulation("checkerboard", rate_hz=1e6, duration_s=1e-3)
    Simulation("checkerboard", spp=47_000)  # 346 x 260 x 47,000 < 2^32
    Simulation("checkerboard", imu_rate_hz=1e6, duration_s=1.0, ground_truth="imu")


@pytest.mark.parametrize(
    ("argv", "option"),
    [
        (["--rate", "1e12"], "--rate"),
        (["--rate", "3e6"], "--rate"),
        (["--duration", "1e7"], "--duration"),
        (["--imu-rate", "1e12", "--ground-truth", "imu"], "--imu-rate"),
        (["--spp", "1000000000000"], "--spp"),
        (["--spp", "4000000000"], "--spp"),
        (["--set", "theta_on=-1"], "--set theta_on"),
    ],
)
def test_the_cli_names_the_option(
    tmp_path: Path, capsys: pytest.CaptureFixture, argv: list[str], option: str
) -> None:
    code, _, err = run_cli(capsys, "simulate", "checkerboard", "-o", str(tmp_path / "out"), *argv)
    assert code == 2 and err.count("\n") == 1, err
    assert err.startswith(f"pecs simulate: error: {option}"), err
    assert "checkerboard.toml" not in err and "Traceback" not in err


@pytest.mark.parametrize(
    ("time", "key"),
    [
        ("duration_s = 0.1\nrate_hz = 1e12", r"time\.rate_hz"),
        ("duration_s = 1e7\nrate_hz = 100", r"time\.duration_s"),
        (
            "duration_s = 1e6\nadaptive = true\nmin_rate_hz = 100\nmax_rate_hz = 1000",
            r"time\.duration_s",
        ),
        (
            "duration_s = 0.1\nadaptive = true\nmin_rate_hz = 1\nmax_rate_hz = 1e9",
            r"time\.max_rate_hz",
        ),
    ],
)
def test_a_scene_files_absurd_times_name_the_key(tmp_path: Path, time: str, key: str) -> None:
    scene = scene_file(tmp_path, "keyframes = [{ t_s = 0.0 }]")
    scene.write_text(scene.read_text().replace("duration_s = 0.3\nrate_hz = 100", time))
    with pytest.raises(ValueError, match=rf"scene\.toml: {key}: "):
        Simulation(scene)


def test_a_scene_files_absurd_spp_names_the_key(tmp_path: Path) -> None:
    scene = scene_file(tmp_path, "keyframes = [{ t_s = 0.0 }]")
    scene.write_text(scene.read_text() + "[render]\nspp = 1000000000000\n")
    with pytest.raises(ValueError, match=r"scene\.toml: render\.spp: "):
        Simulation(scene)


# -- 13f: a bad drawn value names the draw -----------------------------------------------------

SPEC = """
[dataset]
name = "draws"
seed = 3
[defaults]
duration_s = 0.01
[draw]
theta_on = {{ normal = [0.1, 1.0] }}
[[sequences]]
scene = "checkerboard"
count = 6
{own_draw}
"""


@pytest.mark.parametrize(
    ("own_draw", "where"),
    [
        ("", r"dataset spec: draw\.theta_on"),
        (
            "draw.theta_on = { normal = [0.1, 1.0] }",
            r"dataset spec: sequences\[0\]\.draw\.theta_on",
        ),
    ],
)
def test_a_bad_drawn_value_names_the_specs_draw(own_draw: str, where: str) -> None:
    spec = parse_spec(SPEC.format(own_draw=own_draw))
    bad = [task for task in spec.sequences if task.drawn["theta_on"] < 0.01]
    good = [task for task in spec.sequences if task.drawn["theta_on"] >= 0.01]
    assert bad and good  # the seed gives both
    build_simulation(good[0])
    for task in bad:
        with pytest.raises(ValueError, match=rf"^{where}: drew -?[0-9.e-]+ for {task.name}") as e:
            build_simulation(task)
        assert "checkerboard.toml" not in str(e.value) and "theta_on" in str(e.value)


def test_the_scene_files_own_bad_override_still_names_the_file(tmp_path: Path) -> None:
    scene = scene_file(tmp_path, "keyframes = [{ t_s = 0.0 }]")
    scene.write_text(
        scene.read_text().replace(
            'preset = "davis346"', 'preset = "davis346"\noverrides = { theta_on = -1.0 }'
        )
    )
    with pytest.raises(ValueError, match=r"scene\.toml: sensor\.overrides: theta_on"):
        Simulation(scene)
    Simulation(scene, sensor={"theta_on": 0.3})  # the caller's value replaces the bad one
    assert load_scene(scene).sensor_overrides == {"theta_on": -1.0}


def test_a_bad_fixed_sensor_field_names_its_table_and_absurd_settings_fail_at_load() -> None:
    fixed = SPEC.format(own_draw="sensor = { refractory_us = -5.0 }").replace("count = 6", "")
    task = parse_spec(fixed.replace("[draw]\ntheta_on = { normal = [0.1, 1.0] }", "")).sequences[0]
    with pytest.raises(ValueError, match=r"^dataset spec: sequences\[0\]\.sensor\.refractory_us: "):
        build_simulation(task)
    with pytest.raises(ValueError, match=r"^dataset spec: defaults\.rate_hz: 1e\+12 Hz"):
        parse_spec(SPEC.format(own_draw="").replace("duration_s = 0.01", "rate_hz = 1e12"))
