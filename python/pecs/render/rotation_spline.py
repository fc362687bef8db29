"""C2 rotation interpolation: a cubic spline through sign-aligned unit quaternions, renormalised.

q(t) = s(t) / |s(t)| with s the not-a-knot cubic spline of the quaternion components (`cubic_spline`).
Why this one: it passes through every sample (a ground-truth file is matched exactly, unlike the
approximating cumulative B-spline on SO(3)); it is C2 (SQUAD is only C1, so its angular
acceleration jumps and a gyro-derived signal would have kinks); it is bi-invariant (left or right
multiplication by a fixed rotation is an orthogonal map of R^4 that commutes with the spline and
the normalisation, so the choice of world or body axes does not change the motion); and its
angular velocity w = 2 vec(q* dq/dt) is analytic. Requirement: neighbouring samples less than
~90 degrees apart, which any sampled trajectory meets (s then stays far from 0).
Quaternions are (w, x, y, z); body-frame angular velocity follows R^T dR/dt = [w]x.
"""

from __future__ import annotations

import numpy as np

from pecs.render.cubic_spline import CubicSpline

# Largest rotation between neighbouring samples: beyond it the shorter arc is ambiguous (180) or
# the component spline can pass near zero.
MAX_STEP_DEG = 150.0


def quaternion_multiply(a: np.ndarray, b: np.ndarray) -> np.ndarray:
    """Hamilton product a b of (w, x, y, z) quaternions."""
    w1, x1, y1, z1 = a
    w2, x2, y2, z2 = b
    return np.array(
        [
            w1 * w2 - x1 * x2 - y1 * y2 - z1 * z2,
            w1 * x2 + x1 * w2 + y1 * z2 - z1 * y2,
            w1 * y2 - x1 * z2 + y1 * w2 + z1 * x2,
            w1 * z2 + x1 * y2 - y1 * x2 + z1 * w2,
        ]
    )


def conjugate(q: np.ndarray) -> np.ndarray:
    return np.array([q[0], -q[1], -q[2], -q[3]])


def rotation_vector(q: np.ndarray) -> np.ndarray:
    """Axis times angle (rad) of a unit quaternion, the shorter way round (angle <= pi)."""
    q = q if q[0] >= 0 else -q
    sin_half = float(np.linalg.norm(q[1:]))
    if sin_half < 1e-12:
        return 2.0 * q[1:]
    return 2.0 * np.arctan2(sin_half, q[0]) * q[1:] / sin_half


def aligned_quaternions(quaternions: np.ndarray) -> np.ndarray:
    """Flip signs so that neighbours have a non-negative dot product (q and -q are one rotation;
    without this a spline through the components would swing through zero). Flipping q_i flips
    its dot product with q_i+1 too, so the sign of q_i is the product of the signs before it."""
    q = np.array(quaternions, dtype=np.float64).reshape(-1, 4)
    step_sign = np.where(np.sum(q[1:] * q[:-1], axis=1) < 0, -1.0, 1.0)
    sign = np.concatenate([[1.0], np.cumprod(step_sign)])
    return q * sign[:, None]


class RotationSpline:
    """Unit quaternion q(t) and body angular velocity through (t_i, q_i)."""

    def __init__(self, t_s: np.ndarray, quaternions: np.ndarray) -> None:
        q = aligned_quaternions(quaternions)
        q /= np.linalg.norm(q, axis=1, keepdims=True)
        cos_half = np.clip(np.sum(q[1:] * q[:-1], axis=1), -1.0, 1.0)
        step_deg = np.degrees(2.0 * np.arccos(cos_half))
        if step_deg.size and step_deg.max() > MAX_STEP_DEG:
            i = int(np.argmax(step_deg))
            raise ValueError(
                f"rotation between samples {i} and {i + 1} (t = {t_s[i]} s, {t_s[i + 1]} s) is "
                f"{step_deg[i]:.1f} deg; more than {MAX_STEP_DEG:g} deg is ambiguous: add samples"
            )
        self._spline = CubicSpline(t_s, q)

    def rotation(self, t_s: float) -> np.ndarray:
        s = self._spline(t_s)
        return s / np.linalg.norm(s)

    def angular_velocity(self, t_s: float) -> np.ndarray:
        """w (rad/s, body frame) = 2 vec(q* dq/dt), dq/dt = (s' - q (q . s')) / |s|."""
        s, ds = self._spline(t_s), self._spline(t_s, 1)
        norm = np.linalg.norm(s)
        q = s / norm
        dq = (ds - q * np.dot(q, ds)) / norm
        return 2.0 * quaternion_multiply(conjugate(q), dq)[1:]
