"""Exit-pupil bounds per film radius (pbrt-v3 RealisticCamera::BoundExitPupil, section 6.4.5).

Seen from a film point, only part of the rear element's plane sends rays that reach the scene.
For bins of film radius along +x, a grid of rays from film points in the bin towards the plane
of the rear vertex finds that region; a camera samples inside it (rotated to the film point's
azimuth) and weights by its area. Tight sampling: the smallest ellipse, centred in the bounding
box with axes in its proportions, that holds every passing grid point (plus one grid cell), used
when it is smaller than the box.
"""

from __future__ import annotations

from dataclasses import dataclass

import numpy as np

from pecs.lens.raytrace import Geometry, trace


@dataclass(frozen=True)
class PupilBounds:
    """Per bin: box (x_min, x_max, y_min, y_max) on the rear plane, mm, and the ellipse scale s
    (0 when the box is the sampling region, else an ellipse with semi-axes s * half sides)."""

    film_radius_max_mm: float
    rear_z_mm: float
    boxes_mm: np.ndarray  # (bins, 4)
    ellipse_scale: np.ndarray  # (bins,)

    @property
    def bins(self) -> int:
        return len(self.boxes_mm)

    def area_mm2(self, tight: bool = True) -> np.ndarray:
        """Area of the sampling region of each bin."""
        w = self.boxes_mm[:, 1] - self.boxes_mm[:, 0]
        h = self.boxes_mm[:, 3] - self.boxes_mm[:, 2]
        box = w * h
        if not tight:
            return box
        return np.where(self.ellipse_scale > 0, np.pi / 4 * self.ellipse_scale**2 * box, box)

    def bin_of(self, film_radius_mm: np.ndarray) -> np.ndarray:
        idx = (np.asarray(film_radius_mm) / self.film_radius_max_mm * self.bins).astype(np.int64)
        return np.clip(idx, 0, self.bins - 1)


def _grid_rays(
    geometry: Geometry,
    n_media: list[np.ndarray],
    film_radii_mm: np.ndarray,
    lo: np.ndarray,
    hi: np.ndarray,
    grid: int,
) -> tuple[np.ndarray, np.ndarray]:
    """Trace a grid on the rear plane for every bin at once.

    film_radii_mm (B, R), lo/hi (B, 2): per bin the film radii and the grid's corners.
    Returns the grid points (B, R * W * G * G, 2) and whether each ray passes."""
    bins, per_bin = film_radii_mm.shape
    u = np.linspace(0.0, 1.0, grid)
    gu, gv = (a.ravel() for a in np.meshgrid(u, u))
    gx = lo[:, None, 0] + gu[None] * (hi - lo)[:, None, 0]  # (B, G*G)
    gy = lo[:, None, 1] + gv[None] * (hi - lo)[:, None, 1]
    waves = len(n_media)
    shape = (bins, per_bin, waves, grid * grid)
    px = np.broadcast_to(gx[:, None, None, :], shape).ravel()
    py = np.broadcast_to(gy[:, None, None, :], shape).ravel()
    fx = np.broadcast_to(film_radii_mm[:, :, None, None], shape).ravel()
    n_all = np.stack(n_media, axis=1)  # (S + 1, W)
    n_rays = np.broadcast_to(n_all[:, None, None, :, None], (n_all.shape[0], *shape)).reshape(
        n_all.shape[0], -1
    )
    rear_z = geometry.vertex_z_mm[-1]
    start = np.column_stack([fx, np.zeros_like(fx), np.full_like(fx, geometry.film_z_mm)])
    target = np.column_stack([px, py, np.full_like(px, rear_z)])
    rays = trace(geometry, n_rays, start, target - start, towards_film=False)
    return target[:, :2].reshape(bins, -1, 2), rays.alive.reshape(bins, -1)


def bound_exit_pupil(
    geometry: Geometry,
    n_media_per_wavelength: list[np.ndarray],
    film_radius_max_mm: float,
    bins: int = 32,
    grid: int = 40,
    coarse_grid: int = 24,
) -> PupilBounds:
    """Exit-pupil bounds for `bins` bins of film radius in [0, film_radius_max_mm]: a coarse grid
    over 1.5 x the rear aperture, then a fine grid over where rays passed (each bin's film radii:
    its two ends and its middle; the union over the wavelengths)."""
    rear_z = float(geometry.vertex_z_mm[-1])
    half = 1.5 * float(geometry.semi_aperture_mm[-1])
    radii = (np.arange(bins)[:, None] + np.array([0.0, 0.5, 1.0])[None]) * film_radius_max_mm / bins
    lo = np.full((bins, 2), -half)
    hi = np.full((bins, 2), half)
    boxes = np.zeros((bins, 4))
    scales = np.zeros(bins)
    for size, cell_margin in ((coarse_grid, 2.0), (grid, 1.0)):  # coarse, then fine inside
        points, alive = _grid_rays(geometry, n_media_per_wavelength, radii, lo, hi, size)
        cell = (hi - lo) / (size - 1)
        for b in range(bins):
            passed = points[b][alive[b]]
            if len(passed) == 0:
                lo[b], hi[b] = 0.0, 0.0  # nothing reaches this film radius: zero area, black
                continue
            lo[b] = passed.min(axis=0) - cell_margin * cell[b]
            hi[b] = passed.max(axis=0) + cell_margin * cell[b]
    for b in range(bins):
        if not (hi[b] > lo[b]).all():
            continue
        boxes[b] = (lo[b, 0], hi[b, 0], lo[b, 1], hi[b, 1])
        passed = points[b][alive[b]]
        centre = 0.5 * (lo[b] + hi[b])
        semi = 0.5 * (hi[b] - lo[b])
        rho = np.sqrt((((passed - centre) / semi) ** 2).sum(axis=1)).max()
        scale = rho + (cell[b] / semi).max()
        scales[b] = scale if np.pi / 4 * scale**2 < 1.0 else 0.0
    return PupilBounds(film_radius_max_mm, rear_z, boxes, scales)
