"""Real (finite) ray tracing through spherical surfaces in float64, vectorised over rays.

Lens space: the optical axis is z, the first vertex at z = 0, the film at z = film_z_mm, light
travels from the scene (z < 0) towards +z. A ray meets a surface on the spherical cap around
the vertex, is stopped outside the clear aperture, and refracts by Snell's law in vector form
(Heckbert; pbrt-v3 section 8.2.3); total internal reflection stops it.
"""

from __future__ import annotations

from dataclasses import dataclass

import numpy as np


@dataclass(frozen=True)
class Geometry:
    """Per-surface arrays in lens space (mm)."""

    vertex_z_mm: np.ndarray
    radius_mm: np.ndarray  # 0 = plane (the stop)
    semi_aperture_mm: np.ndarray
    film_z_mm: float


@dataclass
class Rays:
    """A bundle of rays; `blocked_at` is the surface that stopped a ray, -1 while alive."""

    origin: np.ndarray  # (N, 3)
    direction: np.ndarray  # (N, 3), unit
    blocked_at: np.ndarray  # (N,) int

    @property
    def alive(self) -> np.ndarray:
        return self.blocked_at < 0


def intersect_surface(
    origin: np.ndarray, direction: np.ndarray, vertex_z: float, radius: float
) -> tuple[np.ndarray, np.ndarray, np.ndarray]:
    """(t, hit, normal) for the cap of the sphere (or plane if radius == 0) at `vertex_z`.

    The normal is the unit sphere normal (pointing away from the centre for radius > 0)."""
    if radius == 0.0:
        t = (vertex_z - origin[:, 2]) / direction[:, 2]
        normal = np.zeros_like(origin)
        normal[:, 2] = -1.0
        return t, np.isfinite(t) & (t > -1e-9), normal
    centre_z = vertex_z + radius
    oc = origin.copy()
    oc[:, 2] -= centre_z
    b = np.einsum("ij,ij->i", oc, direction)
    c = np.einsum("ij,ij->i", oc, oc) - radius * radius
    disc = b * b - c
    hit = disc >= 0
    root = np.sqrt(np.where(hit, disc, 0.0))
    # The cap around the vertex is met first when travelling towards the centre (d_z > 0 with
    # R > 0, or d_z < 0 with R < 0), else second.
    closer = (direction[:, 2] > 0) == (radius > 0)
    t = np.where(closer, -b - root, -b + root)
    point = origin + t[:, None] * direction
    normal = (point - np.array([0.0, 0.0, centre_z])) / radius
    return t, hit & (t > -1e-9), normal


def refract(
    direction: np.ndarray, normal: np.ndarray, eta: np.ndarray
) -> tuple[np.ndarray, np.ndarray]:
    """(refracted direction, ok) for unit `direction`, eta = n_in / n_out; ok is False on TIR."""
    cos_i = -np.einsum("ij,ij->i", direction, normal)
    flip = cos_i < 0  # orient the normal against the incoming ray
    normal = np.where(flip[:, None], -normal, normal)
    cos_i = np.abs(cos_i)
    sin2_t = eta * eta * np.maximum(0.0, 1.0 - cos_i * cos_i)
    ok = sin2_t <= 1.0
    cos_t = np.sqrt(np.maximum(0.0, 1.0 - sin2_t))
    out = eta[:, None] * direction + (eta * cos_i - cos_t)[:, None] * normal
    return out / np.linalg.norm(out, axis=1, keepdims=True), ok


def trace(
    geometry: Geometry,
    n_media: np.ndarray,
    origin: np.ndarray,
    direction: np.ndarray,
    towards_film: bool,
) -> Rays:
    """Trace rays through every surface.

    `n_media` has shape (S + 1, N) or (S + 1,): the index before surface 0, then behind each
    surface. towards_film=True starts in the scene, False starts at the film. Only the rays
    still alive are traced at each surface.
    """
    origin = np.array(origin, dtype=np.float64)
    direction = np.array(direction, dtype=np.float64)
    direction /= np.linalg.norm(direction, axis=1, keepdims=True)
    count = origin.shape[0]
    n_media = np.asarray(n_media, dtype=np.float64)
    per_ray = n_media.ndim == 2 and n_media.shape[1] > 1
    blocked = np.full(count, -1, dtype=np.int64)
    live = np.arange(count)
    o, d = origin, direction
    surfaces = len(geometry.radius_mm)
    order = range(surfaces) if towards_film else range(surfaces - 1, -1, -1)
    for i in order:
        t, hit, normal = intersect_surface(o, d, geometry.vertex_z_mm[i], geometry.radius_mm[i])
        point = o + t[:, None] * d
        passed = hit & (point[:, 0] ** 2 + point[:, 1] ** 2 <= geometry.semi_aperture_mm[i] ** 2)
        if geometry.radius_mm[i] != 0.0:
            n_in, n_out = (i, i + 1) if towards_film else (i + 1, i)
            if per_ray:
                eta = n_media[n_in, live] / n_media[n_out, live]
            else:
                eta = np.full(
                    len(live), float(np.ravel(n_media[n_in])[0] / np.ravel(n_media[n_out])[0])
                )
            d, ok = refract(d, normal, eta)
            passed &= ok
        blocked[live[~passed]] = i
        live, o, d = live[passed], point[passed], d[passed]
    origin[live], direction[live] = o, d
    return Rays(origin, direction, blocked)


def propagate_to_z(rays: Rays, z_mm: float) -> np.ndarray:
    """(N, 2) transverse position where each ray crosses the plane z = z_mm."""
    t = (z_mm - rays.origin[:, 2]) / rays.direction[:, 2]
    return rays.origin[:, :2] + t[:, None] * rays.direction[:, :2]


def sphere_sag_mm(radius_mm: float, h_mm: float) -> float:
    """z of a spherical cap at height h relative to its vertex: R - sign(R) sqrt(R^2 - h^2)
    (0 for a plane, R = 0), clamped at the hemisphere's rim."""
    if radius_mm == 0.0:
        return 0.0
    return radius_mm - np.sign(radius_mm) * np.sqrt(max(radius_mm * radius_mm - h_mm * h_mm, 0.0))
