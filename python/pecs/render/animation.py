"""Rigid animation: positions lerped and orientations slerped (Shoemake 1985), or C2 splines.

Poses are 4x4 float64 matrices (column vectors, world = M @ local). Quaternions are (w, x, y, z).
"""

from __future__ import annotations

from collections.abc import Sequence
from dataclasses import dataclass

import numpy as np

from pecs.render.cubic_spline import CubicSpline
from pecs.render.rotation_spline import (
    RotationSpline,
    aligned_quaternions,
    conjugate,
    quaternion_multiply,
    rotation_vector,
)


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


INTERPOLATIONS = ("linear", "spline")


class Track:
    """Poses of one object (or the camera) over time, held constant before the first keyframe and
    after the last.

    `interpolation = "linear"`: positions lerped, rotations slerped (the default for keyframes).
    `"spline"`: a C2 not-a-knot cubic spline through the positions and through the sign-aligned
    quaternion components, renormalised (`rotation_spline`): both pass through every keyframe,
    and velocity, acceleration and angular velocity are analytic (what an IMU needs).

    `source` names where sampled poses came from (a trajectory file, or "samples"): such a track
    is a recording, and a simulation refuses one that does not cover its time span; keyframe
    tracks (source None) may hold their first and last pose.
    """

    def __init__(
        self,
        keyframes: Sequence[Keyframe],
        pivot: Sequence[float] = (0.0, 0.0, 0.0),
        interpolation: str = "linear",
        source: str | None = None,
    ) -> None:
        if not keyframes:
            raise ValueError("an animation track needs at least one keyframe")
        if interpolation not in INTERPOLATIONS:
            raise ValueError(
                f"interpolation must be one of {list(INTERPOLATIONS)}, got {interpolation!r}"
            )
        times = np.array([k.t_s for k in keyframes], dtype=np.float64)
        if not np.all(np.isfinite(times)):
            raise ValueError(f"keyframe times must be finite, got {times.tolist()}")
        if np.any(np.diff(times) <= 0):
            raise ValueError(f"keyframe times must increase strictly, got {times.tolist()}")
        self.keyframes = list(keyframes)
        self.pivot = np.asarray(pivot, dtype=np.float64)
        self.interpolation = interpolation
        self.source = source
        self._times = times
        self._rotations = aligned_quaternions(np.array([k.rotation for k in keyframes]))
        self._position_spline: CubicSpline | None = None
        self._rotation_spline: RotationSpline | None = None
        if interpolation == "spline":
            self._position_spline = CubicSpline(times, np.array([k.position for k in keyframes]))
            self._rotation_spline = RotationSpline(times, self._rotations)

    @classmethod
    def from_samples(
        cls,
        t_s: np.ndarray,
        positions: np.ndarray,
        quaternions_wxyz: np.ndarray,
        pivot: Sequence[float] = (0.0, 0.0, 0.0),
        interpolation: str = "spline",
        source: str = "samples",
    ) -> Track:
        """A track through sampled poses: times (n,), positions (n, 3) in metres, unit
        quaternions (n, 4) as (w, x, y, z); `source` names them in messages (e.g. the file)."""
        t_s = np.asarray(t_s, dtype=np.float64)
        positions = np.asarray(positions, dtype=np.float64)
        quaternions = np.asarray(quaternions_wxyz, dtype=np.float64)
        n = t_s.size
        if t_s.shape != (n,) or positions.shape != (n, 3) or quaternions.shape != (n, 4):
            raise ValueError(
                f"expected times (n,), positions (n, 3), quaternions (n, 4); got {t_s.shape}, "
                f"{positions.shape}, {quaternions.shape}"
            )
        norms = np.linalg.norm(quaternions, axis=1)
        if not np.all(np.isfinite(norms)) or np.any(norms == 0):
            raise ValueError("quaternions must be finite and not all zero")
        unit = quaternions / norms[:, None]
        frames = [Keyframe(float(t), p, q) for t, p, q in zip(t_s, positions, unit, strict=True)]
        return cls(frames, pivot, interpolation, source)

    @property
    def start_s(self) -> float:
        """Time of the first keyframe (or sample), seconds."""
        return float(self._times[0])

    @property
    def end_s(self) -> float:
        """Time of the last keyframe (or sample), seconds."""
        return float(self._times[-1])

    def pose(self, t_s: float) -> np.ndarray:
        """4x4 pose at time t_s: rotation about the pivot, then translation by the position."""
        position, rotation = self.position_rotation(t_s)
        matrix = pose_matrix(position, rotation)
        matrix[:3, 3] += self.pivot - matrix[:3, :3] @ self.pivot
        return matrix

    def position_rotation(self, t_s: float) -> tuple[np.ndarray, np.ndarray]:
        """Interpolated position (m) and unit rotation quaternion (w, x, y, z) at time t_s."""
        if self._position_spline is not None and self._rotation_spline is not None:
            return self._position_spline(t_s), self._rotation_spline.rotation(t_s)
        segment = self._segment(t_s)
        if segment is None:
            frame = self.keyframes[0] if t_s <= self._times[0] else self.keyframes[-1]
            return frame.position, frame.rotation
        i, u = segment
        a, b = self.keyframes[i], self.keyframes[i + 1]
        return a.position + u * (b.position - a.position), slerp(a.rotation, b.rotation, u)

    def velocity(self, t_s: float) -> np.ndarray:
        """d/dt of the position (the pivot point's world velocity), m/s; 0 outside the track.
        Linear tracks: the velocity of the segment starting at t_s (one-sided at keyframes)."""
        if self._position_spline is not None:
            return self._position_spline(t_s, 1)
        segment = self._segment(t_s)
        if segment is None:
            return np.zeros(3)
        i = segment[0]
        a, b = self.keyframes[i], self.keyframes[i + 1]
        return (b.position - a.position) / (b.t_s - a.t_s)

    def acceleration(self, t_s: float) -> np.ndarray:
        """d2/dt2 of the position, m/s^2 (linear tracks: 0 between keyframes; the impulses at the
        keyframes are not represented: use the spline where acceleration matters)."""
        if self._position_spline is not None:
            return self._position_spline(t_s, 2)
        return np.zeros(3)

    def angular_velocity(self, t_s: float) -> np.ndarray:
        """Angular velocity in the body frame (the track's own axes), rad/s: R^T dR/dt = [w]x."""
        if self._rotation_spline is not None:
            return self._rotation_spline.angular_velocity(t_s)
        segment = self._segment(t_s)
        if segment is None:
            return np.zeros(3)
        i = segment[0]
        a, b = self.keyframes[i], self.keyframes[i + 1]
        return rotation_vector(quaternion_multiply(conjugate(a.rotation), b.rotation)) / (
            b.t_s - a.t_s
        )

    def velocity_jumps(self, start_s: float, end_s: float) -> list[tuple[float, float]]:
        """(t_s, |jump| in m/s) wherever the velocity of the pose's origin jumps strictly inside
        (start_s, end_s): at every keyframe of a linear track where the segments' velocities
        differ, and where any moving track starts or stops (it holds its first and last pose).
        There the acceleration is an impulse, which no IMU table can represent."""
        jumps = []
        last = len(self._times) - 1
        for k, t_s in enumerate(self._times):
            if last == 0 or not start_s < t_s < end_s:
                continue
            if self._position_spline is None:
                before, after = self._segment_velocity(k - 1, k), self._segment_velocity(k, k)
            elif k in (0, last):  # a spline is C2 inside; it stops dead at its ends
                moving = self._spline_velocity(float(t_s))
                before, after = (np.zeros(3), moving) if k == 0 else (moving, np.zeros(3))
            else:
                continue
            jump = float(np.linalg.norm(after - before))
            if jump > 0.0:
                jumps.append((float(t_s), jump))
        return jumps

    def _segment_velocity(self, i: int, k: int) -> np.ndarray:
        """Velocity of the pose's origin on linear segment i (keyframes i to i + 1) at keyframe
        k, one of its ends; zero on the holds before the first and after the last keyframe.
        The origin is p + c - R c for pivot c, so it moves with p' - R (w x c), w the
        segment's body rate."""
        if i < 0 or i >= len(self._times) - 1:
            return np.zeros(3)
        a, b = self.keyframes[i], self.keyframes[i + 1]
        dt = b.t_s - a.t_s
        rate = rotation_vector(quaternion_multiply(conjugate(a.rotation), b.rotation)) / dt
        rotation = matrix_from_quaternion(self.keyframes[k].rotation)
        return (b.position - a.position) / dt - rotation @ np.cross(rate, self.pivot)

    def _spline_velocity(self, t_s: float) -> np.ndarray:
        """Velocity of the pose's origin on a spline track at t_s inside its keyframes."""
        assert self._position_spline is not None and self._rotation_spline is not None
        rotation = matrix_from_quaternion(self._rotation_spline.rotation(t_s))
        rate = self._rotation_spline.angular_velocity(t_s)
        return self._position_spline(t_s, 1) - rotation @ np.cross(rate, self.pivot)

    def _segment(self, t_s: float) -> tuple[int, float] | None:
        """(keyframe index i, fraction u in [0, 1)) of t_s, or None outside the keyframes."""
        times = self._times
        if len(times) == 1 or t_s < times[0] or t_s >= times[-1]:
            return None
        i = int(np.searchsorted(times, t_s, side="right")) - 1
        return i, (t_s - times[i]) / (times[i + 1] - times[i])
