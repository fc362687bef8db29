"""Smooth random motion for generated scenes: drawn as a few numbers, written as keyframes that
the scene file's C2 spline (`interpolation = "spline"`) passes through.

A path is a random cubic curve B(s) = c1 s + c2 s^2 + c3 s^3 (s = t / duration, c_k drawn from a
standard normal), scaled so that its mean speed over the sequence is the drawn speed. A turn is
about a drawn axis by an angle whose rate varies smoothly (theta(s) proportional to s + b s^2,
|b| < 1/2, so it never reverses) with the drawn mean angular rate. Hand-held shake is a small
rotation, per camera axis the sum of two sines of drawn frequency (2-12 Hz: sway to
physiological tremor) and phase, of drawn peak amplitude. Keyframes sample the motion densely
(100 Hz for the camera, 50 Hz for objects, at least four): a not-a-knot spline reproduces a
cubic exactly, and the turn and the shake to well below a millidegree.
"""

from __future__ import annotations

import math
from typing import Any

import numpy as np

from pecs.render.rotation_spline import quaternion_multiply

CAMERA_KEYFRAME_HZ = 100.0
OBJECT_KEYFRAME_HZ = 50.0
MIN_KEYFRAMES = 4
SHAKE_HZ = (2.0, 12.0)
# Samples of the mean-speed integral (midpoint rule: exact to 1e-5 for these cubics).
_SPEED_SAMPLES = 256


def describe_motion(
    rng: np.random.Generator, speed_m_s: float, rate_deg_s: float
) -> dict[str, Any]:
    """A path of mean speed `speed_m_s` and a turn of mean rate `rate_deg_s` about a random
    axis (uniform on the sphere)."""
    axis = rng.normal(size=3)
    return {
        "speed_m_s": speed_m_s,
        "angular_rate_deg_s": rate_deg_s,
        "path": [[float(v) for v in row] for row in rng.normal(size=(3, 3))],
        "axis": [float(v) for v in axis / np.linalg.norm(axis)],
        "bend": float(rng.uniform(-0.45, 0.45)),
    }


def describe_shake(rng: np.random.Generator, amplitude_deg: float) -> dict[str, Any]:
    """Two sines per camera axis (x, y, z) of drawn frequency and phase."""
    return {
        "amplitude_deg": amplitude_deg,
        "frequencies_hz": [[float(v) for v in row] for row in rng.uniform(*SHAKE_HZ, (3, 2))],
        "phases": [[float(v) for v in row] for row in rng.uniform(0.0, 2.0 * math.pi, (3, 2))],
    }


def keyframe_times(duration_s: float, rate_hz: float) -> np.ndarray:
    """Evenly spaced times from 0 to `duration_s`, both included, at least `rate_hz` apart."""
    count = max(MIN_KEYFRAMES, math.ceil(duration_s * rate_hz) + 1)
    return np.linspace(0.0, duration_s, count)


def displacement(motion: dict[str, Any], t_s: np.ndarray, duration_s: float) -> np.ndarray:
    """Position relative to the start (m), (n, 3), at times `t_s`."""
    c = np.asarray(motion["path"], dtype=np.float64)
    s = np.asarray(t_s, dtype=np.float64)[:, None] / duration_s
    curve = c[0] * s + c[1] * s**2 + c[2] * s**3
    mid = (np.arange(_SPEED_SAMPLES) + 0.5) / _SPEED_SAMPLES
    tangent = c[0] + 2.0 * c[1] * mid[:, None] + 3.0 * c[2] * mid[:, None] ** 2
    mean_tangent = float(np.mean(np.linalg.norm(tangent, axis=1)))
    if motion["speed_m_s"] == 0.0 or mean_tangent == 0.0:
        return np.zeros_like(curve)
    # d/dt of duration * B(t / duration) is B'(s): scaled to the drawn mean speed.
    return curve * (motion["speed_m_s"] * duration_s / mean_tangent)


def turn_deg(motion: dict[str, Any], t_s: np.ndarray, duration_s: float) -> np.ndarray:
    """The turn's angle (degrees) at `t_s`: mean rate times duration times (s + b s^2) / (1 + b)."""
    s = np.asarray(t_s, dtype=np.float64) / duration_s
    bend = motion["bend"]
    return motion["angular_rate_deg_s"] * duration_s * (s + bend * s**2) / (1.0 + bend)


def axis_angle_quaternions(axis: list[float], angles_deg: np.ndarray) -> np.ndarray:
    """(n, 4) quaternions (w, x, y, z) of rotations about one unit axis."""
    half = np.radians(np.asarray(angles_deg, dtype=np.float64)) / 2.0
    return np.column_stack([np.cos(half), np.sin(half)[:, None] * np.asarray(axis)[None, :]])


def shake_quaternions(shake: dict[str, Any] | None, t_s: np.ndarray) -> np.ndarray:
    """(n, 4) small rotations of the shake at `t_s` (identity without shake)."""
    t = np.asarray(t_s, dtype=np.float64)
    if shake is None or shake["amplitude_deg"] == 0.0:
        return np.tile([1.0, 0.0, 0.0, 0.0], (t.size, 1))
    frequencies = np.asarray(shake["frequencies_hz"])
    phases = np.asarray(shake["phases"])
    # Each axis: the mean of two unit sines, so its peak is at most the amplitude.
    waves = np.sin(2.0 * math.pi * frequencies[None] * t[:, None, None] + phases[None])
    vector = np.radians(shake["amplitude_deg"]) * waves.mean(axis=2)  # (n, 3) rad
    angle = np.linalg.norm(vector, axis=1)
    safe = np.where(angle > 0, angle, 1.0)
    return np.column_stack([np.cos(angle / 2), np.sin(angle / 2)[:, None] * vector / safe[:, None]])


def compose(left: np.ndarray, right: np.ndarray) -> np.ndarray:
    """Row-wise Hamilton products of (n, 4) (or (4,)) quaternions."""
    left = np.broadcast_to(left, np.broadcast_shapes(np.shape(left), np.shape(right)))
    right = np.broadcast_to(right, left.shape)
    return np.array([quaternion_multiply(a, b) for a, b in zip(left, right, strict=True)])
