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
    boxes_mm: np.ndarray  # (bins, 4), in the frame that follows the pupil (see shift)
    ellipse_scale: np.ndarray  # (bins,)
    shift: float  # a film point at radius r sees the region displaced by shift * r along +x

    def to_rear_plane(self, x_mm: np.ndarray, film_radius_mm: np.ndarray) -> np.ndarray:
        """x on the rear plane of a region point x for a film point at `film_radius_mm` (+x)."""
        return x_mm + self.shift * film_radius_mm

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


def _passes(
    geometry: Geometry,
    n_media: list[np.ndarray],
    film_x_mm: np.ndarray,
    wave: np.ndarray,
    x_mm: np.ndarray,
    y_mm: np.ndarray,
    shift: float,
) -> np.ndarray:
    """Whether the ray from film point (film_x, 0) to region point (x, y) (the sliding frame)
    passes, at wavelength index `wave` (all arrays of one shape)."""
    shape = np.shape(x_mm)
    fx, px, py = (np.broadcast_to(a, shape).ravel() for a in (film_x_mm, x_mm, y_mm))
    n_rays = np.stack(n_media, axis=1)[:, np.broadcast_to(wave, shape).ravel()]
    start = np.column_stack([fx, np.zeros_like(fx), np.full_like(fx, geometry.film_z_mm)])
    target = np.column_stack([px + shift * fx, py, np.full_like(px, geometry.vertex_z_mm[-1])])
    return trace(geometry, n_rays, start, target - start, towards_film=False).alive.reshape(shape)


def _ellipse_scale(
    geometry: Geometry,
    n_media: list[np.ndarray],
    film_radii_mm: np.ndarray,
    centre: np.ndarray,
    semi: np.ndarray,
    shift: float,
    directions: int = 48,
    steps: int = 14,
) -> np.ndarray:
    """Per bin, the scale of the ellipse (centre, semi axes) that holds the passing region of
    every film radius and wavelength of the bin, from the boundary found by bisection along
    `directions` rays out of the centre (valid for regions star-shaped about the centre, as
    intersections of discs are); NaN where the centre itself does not pass."""
    bins, per_bin = film_radii_mm.shape
    waves = len(n_media)
    phi = 2 * np.pi * (np.arange(directions) + 0.5) / directions
    ux, uy = np.cos(phi), np.sin(phi)
    shape = (bins, per_bin, waves, directions)
    fx = np.broadcast_to(film_radii_mm[:, :, None, None], shape)
    wave = np.broadcast_to(np.arange(waves)[None, None, :, None], shape)
    cx, cy = (np.broadcast_to(centre[:, k, None, None, None], shape) for k in range(2))
    sx, sy = (np.broadcast_to(semi[:, k, None, None, None], shape) for k in range(2))
    centre_ok = _passes(geometry, n_media, fx, wave, cx, cy, shift).all(axis=(1, 2, 3))
    lo = np.zeros(shape)
    hi = np.full(shape, 1.5)  # beyond the box corners (sqrt 2) nothing passes
    for _ in range(steps):
        mid = 0.5 * (lo + hi)
        ok = _passes(geometry, n_media, fx, wave, cx + mid * sx * ux, cy + mid * sy * uy, shift)
        lo = np.where(ok, mid, lo)
        hi = np.where(ok, hi, mid)
    # Between two directions a convex boundary bulges by at most 1 / cos(pi / directions).
    scale = hi.max(axis=(1, 2, 3)) / np.cos(np.pi / directions)
    return np.where(centre_ok, scale, np.nan)


def _grid_rays(
    geometry: Geometry,
    n_media: list[np.ndarray],
    film_radii_mm: np.ndarray,
    lo: np.ndarray,
    hi: np.ndarray,
    grid: int,
    shift: float,
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
    target = np.column_stack([px + shift * fx, py, np.full_like(px, rear_z)])
    rays = trace(geometry, n_rays, start, target - start, towards_film=False)
    points = np.column_stack([px, py]).reshape(bins, -1, 2)
    return points, rays.alive.reshape(bins, -1)


#: The finest grid (points per side) tried on a film radius whose coarse grid passes no ray
#: before it is declared dark: a small stop's footprint on the rear plane can fall between the
#: coarse points (pecs4 from f/11: a disc of 0.47 mm radius between points 0.72 mm apart, over
#: 1.5 x its 5.5 mm rear aperture). 185 points (0.09 mm apart there) find pecs4 down to f/64.
FINEST_SEARCH_GRID = 185
#: Rays traced at once while searching (memory: a few hundred bytes each).
_SEARCH_RAYS = 2_000_000


def _find_small_pupils(
    geometry: Geometry,
    n_media: list[np.ndarray],
    film_radii_mm: np.ndarray,
    lo: np.ndarray,
    hi: np.ndarray,
    bins: np.ndarray,
    coarse_grid: int,
    shift: float,
) -> np.ndarray:
    """For `bins` where the coarse grid passed no ray: grids of halved spacing (each keeps the
    last one's points) over the same window until one passes; their lo/hi (in place) become
    the passing points' box plus a cell. Returns the bins found."""
    found = []
    size = coarse_grid
    missing = np.asarray(bins)
    while len(missing) and size < FINEST_SEARCH_GRID:
        size = min(2 * size - 1, FINEST_SEARCH_GRID)
        per_bin = film_radii_mm.shape[1] * len(n_media) * size * size
        chunk = max(1, _SEARCH_RAYS // per_bin)
        still = []
        for start in range(0, len(missing), chunk):
            part = missing[start : start + chunk]
            points, alive = _grid_rays(
                geometry, n_media, film_radii_mm[part], lo[part], hi[part], size, shift
            )
            cell = (hi[part] - lo[part]) / (size - 1)
            for i, b in enumerate(part):
                passed = points[i][alive[i]]
                if len(passed) == 0:
                    still.append(b)
                    continue
                lo[b], hi[b] = passed.min(axis=0) - cell[i], passed.max(axis=0) + cell[i]
                found.append(b)
        missing = np.array(still, dtype=np.int64)
    return np.array(found, dtype=np.int64)


def bound_exit_pupil(
    geometry: Geometry,
    n_media_per_wavelength: list[np.ndarray],
    film_radius_max_mm: float,
    bins: int = 32,
    grid: int = 40,
    coarse_grid: int = 24,
    exit_pupil_z_mm: float | None = None,
) -> PupilBounds:
    """Exit-pupil bounds for `bins` bins of film radius in [0, film_radius_max_mm].

    Each bin traces its film radii (both ends and the middle) at every wavelength through a
    grid over 1.5 x the rear aperture, then through finer grids over where rays passed. The
    boundary lies between a passing grid point and a failing one beside it, so one cell of the
    last grid is the margin that keeps every passing ray inside.

    The regions are stored in a frame that slides with the film radius as the paraxial exit
    pupil's centre does (the line from the film point to it), so that a bin's film points see
    nearly the same region and the union over the bin stays tight."""
    rear_z = float(geometry.vertex_z_mm[-1])
    shift = 0.0
    if exit_pupil_z_mm is not None and abs(geometry.film_z_mm - exit_pupil_z_mm) > 1e-9:
        shift = (rear_z - exit_pupil_z_mm) / (geometry.film_z_mm - exit_pupil_z_mm)
    half = 1.5 * float(geometry.semi_aperture_mm[-1])
    radii = (np.arange(bins)[:, None] + np.array([0.0, 0.5, 1.0])[None]) * film_radius_max_mm / bins
    lo = np.full((bins, 2), -half)
    hi = np.full((bins, 2), half)
    dead = np.zeros(bins, dtype=bool)  # nothing reaches these film radii: zero area, black
    boxes = np.zeros((bins, 4))
    scales = np.zeros(bins)
    for index, size in enumerate((coarse_grid, coarse_grid, grid)):
        points, alive = _grid_rays(geometry, n_media_per_wavelength, radii, lo, hi, size, shift)
        cell = (hi - lo) / (size - 1)
        for b in range(bins):
            passed = points[b][alive[b]]
            if dead[b] or len(passed) == 0:
                dead[b] = True
                continue
            lo[b] = passed.min(axis=0) - cell[b]
            hi[b] = passed.max(axis=0) + cell[b]
        if index == 0 and dead.any():
            found = _find_small_pupils(
                geometry, n_media_per_wavelength, radii, lo, hi, np.flatnonzero(dead), size, shift
            )
            dead[found] = False
    live = np.flatnonzero(~dead)
    centre = 0.5 * (lo + hi)
    semi = 0.5 * (hi - lo)
    # The ellipse is checked at more film radii than the box: five per bin, 1 % margin.
    fine_radii = (np.arange(bins)[:, None] + np.linspace(0, 1, 5)[None]) * film_radius_max_mm / bins
    boundary = np.full(bins, np.nan)
    if len(live):
        boundary[live] = _ellipse_scale(
            geometry, n_media_per_wavelength, fine_radii[live], centre[live], semi[live], shift
        )
    for b in live:
        boxes[b] = (lo[b, 0], hi[b, 0], lo[b, 1], hi[b, 1])
        if np.isfinite(boundary[b]):
            scale = 1.01 * boundary[b]
        else:  # the centre is blocked (a crescent): the grid's passing points, plus a cell
            passed = points[b][alive[b]]
            rho = np.sqrt((((passed - centre[b]) / semi[b]) ** 2).sum(axis=1)).max()
            scale = rho + (cell[b] / semi[b]).max()
        scales[b] = scale if np.pi / 4 * scale**2 < 1.0 else 0.0
    return PupilBounds(film_radius_max_mm, rear_z, boxes, scales, shift)
