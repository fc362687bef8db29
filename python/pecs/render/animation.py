"""Rigid keyframe animation: positions interpolated linearly, orientations by slerp (Shoemake 1985).

Poses are 4x4 float64 matrices (column vectors, world = M @ local). Quaternions are (w, x, y, z).
"""

from __future__ import annotations

from collections.abc import Sequence
from dataclasses import dataclass

import numpy as np


@dataclass(frozen=True)
class Keyframe:
    """A pose at one time: position in metres and a unit quaternion."""

    t_s: float
    position: np.ndarray
    rotation: np.ndarray


def quaternion_from_axis_angle(axis: Sequence[float], angle_deg: float) -> np.ndarray:
    """q = (cos(a/2), sin(a/2) * axis / |axis|)."""
    axis_v = np.asarray(axis, dtype=np.float64)
    norm = np.linalg.norm(axis_v)
    if norm == 0.0:
        raise ValueError("rotation axis must not be the zero vector")
    half = np.radians(angle_deg) / 2.0
    return np.concatenate([[np.cos(half)], np.sin(half) * axis_v / norm])


def quaternion_from_matrix(rotation: np.ndarray) -> np.ndarray:
    """Unit quaternion of a 3x3 rotation matrix (Shepperd's method, stable for any angle)."""
    m = rotation
    trace = m[0, 0] + m[1, 1] + m[2, 2]
    if trace > 0:
        s = 2.0 * np.sqrt(trace + 1.0)
        q = [0.25 * s, (m[2, 1] - m[1, 2]) / s, (m[0, 2] - m[2, 0]) / s, (m[1, 0] - m[0, 1]) / s]
    elif m[0, 0] > m[1, 1] and m[0, 0] > m[2, 2]:
        s = 2.0 * np.sqrt(1.0 + m[0, 0] - m[1, 1] - m[2, 2])
        q = [(m[2, 1] - m[1, 2]) / s, 0.25 * s, (m[0, 1] + m[1, 0]) / s, (m[0, 2] + m[2, 0]) / s]
    elif m[1, 1] > m[2, 2]:
        s = 2.0 * np.sqrt(1.0 + m[1, 1] - m[0, 0] - m[2, 2])
        q = [(m[0, 2] - m[2, 0]) / s, (m[0, 1] + m[1, 0]) / s, 0.25 * s, (m[1, 2] + m[2, 1]) / s]
    else:
        s = 2.0 * np.sqrt(1.0 + m[2, 2] - m[0, 0] - m[1, 1])
        q = [(m[1, 0] - m[0, 1]) / s, (m[0, 2] + m[2, 0]) / s, (m[1, 2] + m[2, 1]) / s, 0.25 * s]
    q = np.asarray(q)
    return q / np.linalg.norm(q)


def matrix_from_quaternion(q: np.ndarray) -> np.ndarray:
    """3x3 rotation matrix of a unit quaternion (w, x, y, z)."""
    w, x, y, z = q / np.linalg.norm(q)
    return np.array(
        [
            [1 - 2 * (y * y + z * z), 2 * (x * y - w * z), 2 * (x * z + w * y)],
            [2 * (x * y + w * z), 1 - 2 * (x * x + z * z), 2 * (y * z - w * x)],
            [2 * (x * z - w * y), 2 * (y * z + w * x), 1 - 2 * (x * x + y * y)],
        ]
    )


def look_at_rotation(
    origin: Sequence[float], target: Sequence[float], up: Sequence[float]
) -> np.ndarray:
    """Quaternion of Mitsuba's look-at frame: camera +z towards the target, +y along `up`."""
    forward = np.asarray(target, dtype=np.float64) - np.asarray(origin, dtype=np.float64)
    if np.linalg.norm(forward) == 0.0:
        raise ValueError("look_at target coincides with the camera position")
    forward /= np.linalg.norm(forward)
    left = np.cross(np.asarray(up, dtype=np.float64), forward)
    if np.linalg.norm(left) < 1e-9:
        raise ValueError("up vector is parallel to the viewing direction")
    left /= np.linalg.norm(left)
    new_up = np.cross(forward, left)
    return quaternion_from_matrix(np.column_stack([left, new_up, forward]))


def slerp(q0: np.ndarray, q1: np.ndarray, u: float) -> np.ndarray:
    """Spherical linear interpolation along the shorter arc: constant angular velocity in u."""
    dot = float(np.dot(q0, q1))
    if dot < 0.0:
        q1, dot = -q1, -dot
    if dot > 0.9995:  # nearly equal: lerp and renormalise (slerp's sin() ratio is ill-conditioned)
        q = q0 + u * (q1 - q0)
        return q / np.linalg.norm(q)
    theta = np.arccos(dot)
    return (np.sin((1 - u) * theta) * q0 + np.sin(u * theta) * q1) / np.sin(theta)


def pose_matrix(position: np.ndarray, rotation: np.ndarray) -> np.ndarray:
    """4x4 rigid transform: rotate, then translate."""
    matrix = np.eye(4)
    matrix[:3, :3] = matrix_from_quaternion(rotation)
    matrix[:3, 3] = position
    return matrix


class Track:
    """Keyframes of one object; the pose is held constant before the first and after the last."""

    def __init__(
        self, keyframes: Sequence[Keyframe], pivot: Sequence[float] = (0.0, 0.0, 0.0)
    ) -> None:
        if not keyframes:
            raise ValueError("an animation track needs at least one keyframe")
        times = np.array([k.t_s for k in keyframes])
        if np.any(np.diff(times) <= 0):
            raise ValueError(f"keyframe times must increase strictly, got {times.tolist()}")
        self.keyframes = list(keyframes)
        self.pivot = np.asarray(pivot, dtype=np.float64)
        self._times = times

    def pose(self, t_s: float) -> np.ndarray:
        """4x4 pose at time t_s: rotation about the pivot, then translation by the position."""
        position, rotation = self.position_rotation(t_s)
        matrix = pose_matrix(position, rotation)
        matrix[:3, 3] += self.pivot - matrix[:3, :3] @ self.pivot
        return matrix

    def position_rotation(self, t_s: float) -> tuple[np.ndarray, np.ndarray]:
        """Interpolated position (lerp) and rotation (slerp) at time t_s."""
        frames = self.keyframes
        if t_s <= self._times[0] or len(frames) == 1:
            return frames[0].position, frames[0].rotation
        if t_s >= self._times[-1]:
            return frames[-1].position, frames[-1].rotation
        i = int(np.searchsorted(self._times, t_s, side="right")) - 1
        a, b = frames[i], frames[i + 1]
        u = (t_s - a.t_s) / (b.t_s - a.t_s)
        return a.position + u * (b.position - a.position), slerp(a.rotation, b.rotation, u)
