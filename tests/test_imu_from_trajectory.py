"""End to end: a camera trajectory from a TUM file, through `pecs.Simulation`'s ground truth,
to the IMU table `pecs.read_ground_truth` returns, against the analytic circle."""

from __future__ import annotations

from pathlib import Path

import numpy as np
import pecs
from pecs.render import Simulation, read_trajectory
from scipy.spatial.transform import Rotation

RADIUS_M, RATE_RAD_S = 1.5, 2.0  # 3 m/s; centripetal w^2 r = 6 m/s^2
GRAVITY_M_S2 = 9.80665


def write_circle_tum(path: Path) -> Path:
    """A level circle about the world's up axis (+y), the camera turning with it (yaw w t),
    sampled at 50 Hz from -1 s to 2 s (scene times 0-0.1 s lie well inside the spline)."""
    t = np.arange(-1.0, 2.0 + 1e-9, 0.02)
    angle = RATE_RAD_S * t
    position = RADIUS_M * np.stack([np.cos(angle), np.zeros_like(t), np.sin(angle)], axis=1)
    position[:, 1] = 0.2
    xyzw = Rotation.from_rotvec(-angle[:, None] * np.array([0.0, 1.0, 0.0])).as_quat()
    rows = [" ".join(f"{v:.12f}" for v in (ti, *p, *q)) for ti, p, q in zip(t, position, xyzw)]
    path.write_text("# t x y z qx qy qz qw\n" + "\n".join(rows) + "\n")
    return path


def test_circle_from_a_tum_file_gives_the_analytic_imu(tmp_path: Path) -> None:
    # Body frame: yaw about +y at -w (rotvec -w t about y), so the gyro reads (0, -w, 0); the
    # accelerometer reads R^T (a - g): w^2 r towards the centre in the level plane and
    # +9.80665 along the body's +y (up), whatever the yaw.
    camera = read_trajectory(write_circle_tum(tmp_path / "circle.tum"))
    simulation = Simulation(
        "checkerboard",
        camera=camera,
        duration_s=0.1,
        rate_hz=100,
        spp=1,
        sensor={"width": 16, "height": 12},
        ground_truth="imu",
        imu_rate_hz=500,
    )
    simulation.run(tmp_path / "out")
    imu = pecs.read_ground_truth(tmp_path / "out").imu.to_pydict()
    assert len(imu["t_us"]) == 51
    gyro = np.array([imu[f"gyro_{a}_rad_s"] for a in "xyz"]).T
    accel = np.array([imu[f"accel_{a}_m_s2"] for a in "xyz"]).T
    np.testing.assert_allclose(gyro, np.tile([0.0, -RATE_RAD_S, 0.0], (51, 1)), atol=2e-3)
    np.testing.assert_allclose(accel[:, 1], GRAVITY_M_S2, atol=1e-2)
    level = np.hypot(accel[:, 0], accel[:, 2])
    np.testing.assert_allclose(level, RATE_RAD_S**2 * RADIUS_M, rtol=1e-2)
    # Towards the centre: in the world, a = -w^2 p_level; in the body, R^T of it.
    t_s = np.array(imu["t_us"]) / 1e6
    angle = RATE_RAD_S * t_s
    towards_centre = -np.stack([np.cos(angle), np.zeros_like(angle), np.sin(angle)], axis=1)
    body = (
        Rotation.from_rotvec(-angle[:, None] * np.array([0.0, 1.0, 0.0]))
        .inv()
        .apply(towards_centre)
    )
    np.testing.assert_allclose(accel[:, [0, 2]], level[:, None] * body[:, [0, 2]], atol=0.06)
