"""The IMU against analytic motions: circle, spin about the optical axis, constant velocity."""

from __future__ import annotations

import numpy as np
import pyarrow as pa
import pytest
from pecs.ground_truth.imu import STANDARD_GRAVITY_M_S2, imu_table, imu_times_us
from scipy.spatial.transform import Rotation

G = STANDARD_GRAVITY_M_S2


class CircleFacingCentre:
    """Camera on a horizontal circle (radius r, rate w about world +y), looking at the centre."""

    def __init__(self, radius_m: float, rate_rad_s: float) -> None:
        self.radius_m, self.rate_rad_s = radius_m, rate_rad_s

    def pose(self, t_s: float) -> np.ndarray:
        rotation = Rotation.from_rotvec([0.0, self.rate_rad_s * t_s, 0.0]).as_matrix()
        forward = rotation[:, 2]
        pose = np.eye(4)
        pose[:3, :3] = rotation
        pose[:3, 3] = np.array([0.5, 1.0, -2.0]) - self.radius_m * forward
        return pose


class SpinAboutOpticalAxis:
    def __init__(self, rate_rad_s: float) -> None:
        self.rate_rad_s = rate_rad_s

    def pose(self, t_s: float) -> np.ndarray:
        pose = np.eye(4)
        pose[:3, :3] = Rotation.from_rotvec([0.0, 0.0, self.rate_rad_s * t_s]).as_matrix()
        return pose


def columns(table: pa.Table, prefix: str) -> np.ndarray:
    unit = "rad_s" if prefix == "gyro" else "m_s2"
    return np.column_stack([table.column(f"{prefix}_{a}_{unit}").to_numpy() for a in "xyz"])


def test_circle_gives_centripetal_acceleration_towards_the_centre_and_its_rate() -> None:
    radius, rate = 0.8, 3.0
    table = imu_table(CircleFacingCentre(radius, rate).pose, 1.0, 200.0)
    assert table.num_rows == 201
    # Body frame: the centre is straight ahead (+z), so a = w^2 r along +z; gravity reads +y.
    np.testing.assert_allclose(columns(table, "gyro").mean(0), [0.0, rate, 0.0], atol=1e-9)
    np.testing.assert_allclose(columns(table, "gyro"), [[0.0, rate, 0.0]] * 201, atol=1e-7)
    np.testing.assert_allclose(
        columns(table, "accel"), [[0.0, G, rate**2 * radius]] * 201, rtol=0, atol=1e-4
    )


def test_spin_about_the_optical_axis_reads_its_rate_and_turning_gravity() -> None:
    rate = 5.0
    table = imu_table(SpinAboutOpticalAxis(rate).pose, 0.5, 100.0)
    # The two end samples are the values 0.1 ms inside (the difference stencil stays inside).
    t = np.clip(table.column("t_us").to_numpy() * 1e-6, 1e-4, 0.5 - 1e-4)
    np.testing.assert_allclose(columns(table, "gyro"), [[0.0, 0.0, rate]] * t.size, atol=1e-7)
    # R^T (0, g, 0) with R = Rz(w t).
    expected = np.column_stack([G * np.sin(rate * t), G * np.cos(rate * t), 0 * t])
    np.testing.assert_allclose(columns(table, "accel"), expected, atol=1e-5)


def test_constant_velocity_reads_gravity_only() -> None:
    def pose(t_s: float) -> np.ndarray:
        matrix = np.eye(4)
        matrix[:3, 3] = [3.0 * t_s, -1.0 * t_s, 0.5]
        return matrix

    table = imu_table(pose, 0.2, 1000.0)
    np.testing.assert_allclose(columns(table, "gyro"), 0.0, atol=1e-12)
    np.testing.assert_allclose(columns(table, "accel"), [[0.0, G, 0.0]] * table.num_rows, atol=1e-6)


def test_sample_times_and_bad_rate() -> None:
    np.testing.assert_array_equal(imu_times_us(0.01, 300.0), [0, 3333, 6667, 10000])
    with pytest.raises(ValueError, match="imu_rate_hz"):
        imu_times_us(1.0, 0.0)
