"""The camera's projection: pinhole intrinsics K, and for the realistic lens a fitted radial
distortion (Brown-Conrady, Brown 1966: x_d = x_u (1 + k1 r^2 + k2 r^4 + k3 r^6)).

Pixel coordinates follow OpenCV: u to the right, v down, pixel centres at integers (column j
spans [j - 0.5, j + 0.5]). Camera points are in Mitsuba's camera frame (+z forward, +y up, +x
to the image's left), so a point (X, Y, Z) lands at u = cx - f x_d, v = cy - f y_d with
x_u = X / (Z - centre_z_m), y_u = Y / (Z - centre_z_m); OpenCV's camera frame is (-X, -Y, Z).
"""

from __future__ import annotations

import math
from dataclasses import dataclass
from typing import Any

import numpy as np

# Film heights (from the centre to the corner) at which the lens's chief rays are traced.
_FIT_HEIGHTS = 48


@dataclass(frozen=True)
class CameraModel:
    """Pinhole projection (plus radial distortion for the realistic lens) of the film in pixels."""

    model: str
    width: int
    height: int
    focal_px: float
    #: Brown-Conrady radial coefficients k1, k2, k3 (0 for pinhole and thin lens).
    distortion: tuple[float, float, float] = (0.0, 0.0, 0.0)
    #: Largest difference (px) between the fitted model and the traced chief rays.
    residual_px: float = 0.0
    #: The projection centre on the optical axis, metres in front of the camera origin (the
    #: realistic lens's origin is the film centre; its rays seem to come from the entrance pupil).
    centre_z_m: float = 0.0

    @property
    def matrix(self) -> np.ndarray:
        """3x3 intrinsics K in OpenCV's convention (pixel centres at integers)."""
        return np.array(
            [
                [self.focal_px, 0.0, (self.width - 1) / 2.0],
                [0.0, self.focal_px, (self.height - 1) / 2.0],
                [0.0, 0.0, 1.0],
            ]
        )

    def project(self, points_camera: np.ndarray) -> np.ndarray:
        """(..., 3) camera-frame points to (..., 2) pixel coordinates (u, v); NaN behind the camera."""
        p = np.asarray(points_camera, dtype=np.float64)
        depth = p[..., 2] - self.centre_z_m
        ahead = depth > 0
        safe = np.where(ahead, depth, 1.0)
        x, y = p[..., 0] / safe, p[..., 1] / safe
        r2 = x * x + y * y
        k1, k2, k3 = self.distortion
        scale = self.focal_px * (1.0 + r2 * (k1 + r2 * (k2 + r2 * k3)))
        u = (self.width - 1) / 2.0 - scale * x
        v = (self.height - 1) / 2.0 - scale * y
        out = np.stack([u, v], axis=-1)
        out[~ahead] = np.nan
        return out

    def undistort(self, u: np.ndarray, v: np.ndarray) -> np.ndarray:
        """Pixel coordinates to (..., 2) undistorted image-plane coordinates (x_u, y_u): the
        inverse of `project`'s x_u = X / (Z - centre_z_m), y_u = Y / (Z - centre_z_m)."""
        x_d = ((self.width - 1) / 2.0 - np.asarray(u, dtype=np.float64)) / self.focal_px
        y_d = ((self.height - 1) / 2.0 - np.asarray(v, dtype=np.float64)) / self.focal_px
        radius_d = np.hypot(x_d, y_d)
        radius_u = _undistorted_radius(radius_d, self.distortion)
        ratio = np.divide(radius_u, radius_d, out=np.ones_like(radius_d), where=radius_d > 0)
        return np.stack([x_d * ratio, y_d * ratio], axis=-1)

    def unproject(self, u: np.ndarray, v: np.ndarray, z_depth_m: np.ndarray) -> np.ndarray:
        """(..., 3) camera-frame points seen at pixel (u, v) at z-depth `z_depth_m` (metres along
        the optical axis from the projection centre): the inverse of `project`."""
        plane = self.undistort(u, v)
        depth = np.asarray(z_depth_m, dtype=np.float64)
        return np.stack(
            [plane[..., 0] * depth, plane[..., 1] * depth, depth + self.centre_z_m], axis=-1
        )

    def as_dict(self) -> dict[str, Any]:
        return {
            "model": self.model,
            "width": self.width,
            "height": self.height,
            "K": self.matrix.tolist(),
            "focal_px": self.focal_px,
            "distortion_k1_k2_k3": list(self.distortion),
            "residual_px": self.residual_px,
            "centre_z_m": self.centre_z_m,
        }

    @classmethod
    def from_dict(cls, data: dict[str, Any]) -> CameraModel:
        k1, k2, k3 = (float(v) for v in data["distortion_k1_k2_k3"])
        return cls(
            str(data["model"]),
            int(data["width"]),
            int(data["height"]),
            float(data["focal_px"]),
            (k1, k2, k3),
            float(data["residual_px"]),
            float(data["centre_z_m"]),
        )


def _undistorted_radius(radius_d: np.ndarray, distortion: tuple[float, float, float]) -> np.ndarray:
    """r_u with r_u (1 + k1 r_u^2 + k2 r_u^4 + k3 r_u^6) = r_d, by Newton's method from r_d
    (the fitted lenses are monotonic over the film, where this converges in a few steps)."""
    k1, k2, k3 = distortion
    radius_u = radius_d.copy()
    if k1 == k2 == k3 == 0.0:
        return radius_u
    for _ in range(50):
        r2 = radius_u * radius_u
        value = radius_u * (1.0 + r2 * (k1 + r2 * (k2 + r2 * k3))) - radius_d
        slope = 1.0 + r2 * (3.0 * k1 + r2 * (5.0 * k2 + r2 * 7.0 * k3))
        step = value / slope
        radius_u -= step
        if np.max(np.abs(step), initial=0.0) < 1e-15:
            break
    return radius_u


def pinhole_model(model: str, width: int, height: int, fov_deg: float) -> CameraModel:
    """Mitsuba's perspective and thinlens sensors: fov across the width, f = (W / 2) / tan(fov / 2)."""
    focal_px = width / (2.0 * math.tan(math.radians(fov_deg) / 2.0))
    return CameraModel(model, width, height, focal_px)


def fitted_lens_model(
    lens_name: str,
    efl_mm: float | None,
    focus_m: float | None,
    width: int,
    height: int,
    pitch_um: float,
) -> CameraModel:
    """The realistic lens as the plugin builds it; f and k1..k3 fitted by least squares to chief
    rays traced from film heights out to the corner."""
    from pecs.lens import Lens

    lens = Lens.load(lens_name)
    if efl_mm is not None:
        lens = lens.scaled_to(efl_mm)
    lens = lens.focused(focus_m if focus_m is not None else math.inf)
    pitch_mm = pitch_um * 1e-3
    corner_mm = 0.5 * math.hypot(width, height) * pitch_mm
    heights_mm = corner_mm * np.arange(1, _FIT_HEIGHTS + 1) / _FIT_HEIGHTS
    tangent = np.tan(np.radians(lens.chief_ray_angle_deg(heights_mm)))
    traced = np.isfinite(tangent)
    if traced.sum() < 4:
        raise ValueError(
            f"lens {lens_name!r}: too few chief rays reach the film to fit its distortion"
        )
    x_u, radius_px = tangent[traced], heights_mm[traced] / pitch_mm
    # h / pitch = f x_u (1 + k1 x_u^2 + k2 x_u^4 + k3 x_u^6): linear in f, f k1, f k2, f k3.
    basis = np.column_stack([x_u, x_u**3, x_u**5, x_u**7])
    coefficients, *_ = np.linalg.lstsq(basis, radius_px, rcond=None)
    focal_px = float(coefficients[0])
    k1, k2, k3 = (float(c / focal_px) for c in coefficients[1:])
    residual = float(np.max(np.abs(basis @ coefficients - radius_px)))
    pupil_z_mm, _ = lens.entrance_pupil()
    centre_z_m = (lens.geometry.film_z_mm - pupil_z_mm) * 1e-3
    return CameraModel("lens", width, height, focal_px, (k1, k2, k3), residual, centre_z_m)
