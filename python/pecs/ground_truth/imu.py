"""An ideal IMU on the camera: angular velocity and specific force in the camera's body frame.

The body frame is the camera frame (Mitsuba's: +z forward, +y up, +x to the image's left).
The gyroscope measures omega with R^T dR/dt = [omega]x (R camera-to-world); the
accelerometer measures the specific force f = R^T (a - g), so a camera at rest reads +9.81 m/s^2
along the world's up axis. pecs scenes are +y up (Mitsuba's look-at default), so g = (0, -g0, 0).
Derivatives are central differences over +-step_s (0.1 ms); a sample closer than that to either
end of [0, duration] is the value at step_s from that end (the stencil stays inside the motion).
A camera path whose velocity jumps inside the run (linear keyframes, or a track that stops dead
at its last keyframe) has no acceleration there: `check_imu_path` refuses it.
"""

from __future__ import annotations

import json
from collections.abc import Callable
from typing import TYPE_CHECKING

import numpy as np
import pyarrow as pa

if TYPE_CHECKING:
    from pecs.ground_truth.imu_noise import ImuModel, ImuReadings
    from pecs.render.animation import Track

#: Standard gravity (CGPM 1901), m/s^2.
STANDARD_GRAVITY_M_S2 = 9.80665
#: World gravity in pecs scenes (+y up).
GRAVITY_WORLD_M_S2 = np.array([0.0, -STANDARD_GRAVITY_M_S2, 0.0])
#: Half-width of the difference stencil: small against any motion's time scale, large enough
#: that float64 positions (eps 1e-16 m) give accelerations good to ~1e-8 m/s^2.
DEFAULT_STEP_S = 1e-4

#: Velocity jumps up to this are rounding (collinear keyframes at one speed): one of 1e-6 m/s
#: reads as a 0.005 m/s^2 spike in the 0.1 ms stencil, below any real IMU's noise.
VELOCITY_JUMP_TOLERANCE_M_S = 1e-6

IMU_COLUMNS = (
    "t_us",
    "gyro_x_rad_s",
    "gyro_y_rad_s",
    "gyro_z_rad_s",
    "accel_x_m_s2",
    "accel_y_m_s2",
    "accel_z_m_s2",
)


def imu_times_us(duration_s: float, rate_hz: float) -> np.ndarray:
    """Sample times 0, 1/rate, ... up to the duration, rounded to microseconds."""
    if not (np.isfinite(rate_hz) and rate_hz > 0):
        raise ValueError(f"imu_rate_hz: must be a positive number, got {rate_hz!r}")
    count = int(np.floor(duration_s * rate_hz + 1e-9)) + 1
    return np.unique(np.round(np.arange(count) * 1e6 / rate_hz).astype(np.int64))


def check_imu_path(track: Track, duration_s: float, name: str, in_scene_file: bool) -> None:
    """Refuse an IMU of a camera path whose velocity jumps inside the run: its acceleration is an
    impulse there (the differences would read thousands of m/s^2 for one sample) and zero
    elsewhere, which no accelerometer would read. `name` says which track; the fix is named as
    a scene file (`in_scene_file`) or Python spells it."""
    jumps = [j for j in track.velocity_jumps(0.0, duration_s) if j[1] > VELOCITY_JUMP_TOLERANCE_M_S]
    if not jumps:
        return
    t_s, jump = max(jumps, key=lambda j: j[1])
    where = f"at t = {t_s:g} s" + (f" and {len(jumps) - 1} more times" if len(jumps) > 1 else "")
    if track.interpolation == "linear" and track.start_s < t_s < track.end_s:
        why = "linear keyframes have no acceleration"
        fix = (
            'set interpolation = "spline" in its table (a C2 path through the same keyframes)'
            if in_scene_file
            else 'build the Track with interpolation="spline"'
        )
    else:
        why = "the path holds its pose outside its keyframes"
        fix = f"give poses from 0 s to {duration_s:g} s or shorten the run"
    raise ValueError(
        f"{name}: the IMU needs the camera's acceleration, but its velocity jumps by "
        f"{jump:.3g} m/s {where} ({why}); {fix}; or ask for ground truth without imu"
    )


def imu_table(
    pose: Callable[[float], np.ndarray],
    duration_s: float,
    rate_hz: float,
    gravity_m_s2: np.ndarray = GRAVITY_WORLD_M_S2,
    step_s: float = DEFAULT_STEP_S,
    model: ImuModel | None = None,
) -> pa.Table:
    """IMU samples of the camera whose camera-to-world 4x4 at t is `pose(t)`, as an Arrow table.

    With a real IMU's `model` (pecs.ground_truth.imu_noise; its seed set) the table also holds
    what that IMU reads (`MEASURED_COLUMNS`), and the model in its metadata; the ideal columns
    are the same either way."""
    times_us = imu_times_us(duration_s, rate_hz)
    step = min(step_s, duration_s / 2.0)
    gyro, accel = _ideal(pose, times_us * 1e-6, duration_s, gravity_m_s2, step)
    columns = {"t_us": pa.array(times_us, pa.int64())}
    for k, axis in enumerate("xyz"):
        columns[f"gyro_{axis}_rad_s"] = pa.array(gyro[:, k])
    for k, axis in enumerate("xyz"):
        columns[f"accel_{axis}_m_s2"] = pa.array(accel[:, k])
    if model is None:
        return pa.table(columns)
    readings = _measured(pose, times_us, duration_s, rate_hz, gravity_m_s2, step, model)
    columns.update({name: pa.array(values) for name, values in readings.columns().items()})
    return pa.table(columns, metadata={"pecs.imu_model": json.dumps(model.as_dict())})


def _ideal(
    pose: Callable[[float], np.ndarray],
    times_s: np.ndarray,
    duration_s: float,
    gravity_m_s2: np.ndarray,
    step_s: float,
) -> tuple[np.ndarray, np.ndarray]:
    """Gyro and specific force (n x 3) at each time (moved inside the run as `imu_sample` does)."""
    gyro = np.empty((times_s.size, 3))
    accel = np.empty((times_s.size, 3))
    for row, t_s in enumerate(times_s):
        gyro[row], accel[row] = imu_sample(pose, float(t_s), duration_s, gravity_m_s2, step_s)
    return gyro, accel


def _measured(
    pose: Callable[[float], np.ndarray],
    times_us: np.ndarray,
    duration_s: float,
    rate_hz: float,
    gravity_m_s2: np.ndarray,
    step_s: float,
    model: ImuModel,
) -> ImuReadings:
    """The real IMU's readings: the motion at t - time_offset_s (clamped into the run: a sample
    whose instant falls before 0 or after the end reads the motion at that end)."""
    shifted_s = np.clip(times_us * 1e-6 - model.time_offset_s, 0.0, duration_s)
    gyro, accel = _ideal(pose, shifted_s, duration_s, gravity_m_s2, step_s)
    alpha = None
    if any(model.lever_arm_m):
        alpha = np.array([angular_acceleration(pose, t, duration_s, step_s) for t in shifted_s])
    return model.measure(times_us, gyro, accel, alpha, rate_hz)


def angular_acceleration(
    pose: Callable[[float], np.ndarray], t_s: float, duration_s: float, step_s: float
) -> np.ndarray:
    """d omega / dt (body frame, rad/s^2) at t_s: the central difference of the gyro over
    +-step_s, the stencil kept inside the run as `imu_sample` keeps its own."""
    step = min(step_s, duration_s / 4.0)
    centre = min(max(t_s, 2.0 * step), duration_s - 2.0 * step)
    before, _ = imu_sample(pose, centre - step, duration_s, GRAVITY_WORLD_M_S2, step)
    after, _ = imu_sample(pose, centre + step, duration_s, GRAVITY_WORLD_M_S2, step)
    return (after - before) / (2.0 * step)


def imu_sample(
    pose: Callable[[float], np.ndarray],
    t_s: float,
    duration_s: float,
    gravity_m_s2: np.ndarray,
    step_s: float,
) -> tuple[np.ndarray, np.ndarray]:
    """(gyro rad/s, specific force m/s^2), body frame, at s = t_s moved inside [h, duration - h]
    from the poses at s - h, s, s + h."""
    centre = min(max(t_s, step_s), duration_s - step_s)
    before, here, after = (pose(centre + k * step_s) for k in (-1.0, 0.0, 1.0))
    r_before, r_here, r_after = (_rotation(m) for m in (before, here, after))
    # R(s-h)^T R(s+h) = exp(2h [omega]x) for a constant body rate omega.
    gyro = rotation_log(r_before.T @ r_after) / (2.0 * step_s)
    # p'' = (p(s+h) - 2 p(s) + p(s-h)) / h^2.
    acceleration = (after[:3, 3] - 2.0 * here[:3, 3] + before[:3, 3]) / step_s**2
    specific_force = r_here.T @ (acceleration - gravity_m_s2)
    return gyro, specific_force


def rotation_log(rotation: np.ndarray) -> np.ndarray:
    """Rotation vector (axis * angle, rad) of a 3x3 rotation (angles below pi)."""
    cos_angle = np.clip((np.trace(rotation) - 1.0) / 2.0, -1.0, 1.0)
    angle = float(np.arccos(cos_angle))
    skew = np.array(
        [
            rotation[2, 1] - rotation[1, 2],
            rotation[0, 2] - rotation[2, 0],
            rotation[1, 0] - rotation[0, 1],
        ]
    )
    # vee(R - R^T) = 2 sin(angle) axis; angle / sin(angle) -> 1 as the angle -> 0.
    factor = 0.5 if angle < 1e-8 else angle / (2.0 * np.sin(angle))
    return factor * skew


def _rotation(pose: np.ndarray) -> np.ndarray:
    """The rotation of a pose, its columns normalised (a scaled camera transform still has one)."""
    rotation = pose[:3, :3]
    return rotation / np.linalg.norm(rotation, axis=0, keepdims=True)
