"""Paraxial ghost analysis: each two-reflection path as a 2x2 ray-transfer matrix.

A reflection at a surface of curvature c in index n is a refraction into index -n (nu' = nu +
2 n c y); behind it distances and indices change sign together, so a transfer keeps its form
y' = y + t nu / n (Smith, Modern Optical Engineering, ch. 3; Lee and Eisemann, "Practical
real-time lens-flare rendering", EGSR 2013). For a source at infinity at slope u0 the ghost is
the image of the stop: rays with stop height y_s and slope u0 land at y_f = P y_s + Q u0, so
the ghost is a disk of radius |P| r_stop centred at Q u0 (where one stop crossing limits it).
"""

from __future__ import annotations

from dataclasses import dataclass

import numpy as np

from pecs.lens.coating import reflectance
from pecs.lens.ghosts import GhostOptions, GhostPath, GhostSystem
from pecs.lens.lens import Lens
from pecs.lens.paraxial import refraction_matrix, transfer_matrix


@dataclass(frozen=True)
class ParaxialGhost:
    """One path's first-order ghost for a source at infinity, mm on the film."""

    path: GhostPath
    names: tuple[str, str]
    centre_per_slope_mm: float  # Q: ghost centre = Q tan(field angle)
    radius_mm: float  # |P| r_stop: radius of the stop's ghost image (0 where stop crossed twice+)
    stop_crossings: int
    entrance_radius_mm: float  # r_stop / |a|: half-width of the entering bundle (first crossing)
    focus_from_film_mm: float  # where the ghost of an axial point focuses, film at 0 (inf: afocal)
    energy: float  # R_i R_j at normal incidence, design wavelength


def ghost_matrices(
    system: GhostSystem, path: GhostPath, wavelength_nm: float
) -> tuple[np.ndarray, list[np.ndarray], np.ndarray]:
    """(film matrix, matrices at each stop crossing, matrix just behind the last surface), all
    from the plane of the first vertex (in air) along the path; rays are (y, n u)."""
    n = system.media(wavelength_nm)[:, 0]
    z = np.array(system.z_mm)
    curvature = np.array([0.0 if r == 0 else 1.0 / r for r in system.radius_mm])
    stop = system.lens.stop_index
    only_reflect = {k for k, r in enumerate(system.fixed_reflectance) if r >= 0}
    i, j = path.first, path.second
    stops: list[np.ndarray] = []

    def forward(m: np.ndarray, at_z: float, surfaces: range) -> tuple[np.ndarray, float]:
        """Refracted forwards through `surfaces` (the die-only reflectors skipped)."""
        for k in surfaces:
            if k in only_reflect:
                continue
            m = transfer_matrix(z[k] - at_z, n[k]) @ m
            at_z = float(z[k])
            m = refraction_matrix(curvature[k], n[k], n[k + 1]) @ m
            if k == stop:
                stops.append(m)
        return m, at_z

    m, at_z = forward(np.eye(2), 0.0, range(i))  # forward to the first reflector
    m = transfer_matrix(z[i] - at_z, n[i]) @ m
    at_z = float(z[i])
    m = refraction_matrix(curvature[i], n[i], -n[i]) @ m
    for k in range(i - 1, j, -1):  # back to the second reflector
        m = transfer_matrix(z[k] - at_z, -n[k + 1]) @ m
        at_z = float(z[k])
        m = refraction_matrix(curvature[k], -n[k + 1], -n[k]) @ m
        if k == stop:
            stops.append(m)
    m = transfer_matrix(z[j] - at_z, -n[j + 1]) @ m
    at_z = float(z[j])
    m = refraction_matrix(curvature[j], -n[j + 1], n[j + 1]) @ m
    m, at_z = forward(m, at_z, range(j + 1, system.surface_count))  # on to the film
    film = transfer_matrix(system.film_z_mm - at_z, 1.0) @ m
    return film, stops, m


def paraxial_ghost(system: GhostSystem, path: GhostPath, wavelength_nm: float) -> ParaxialGhost:
    """First-order centre, size, focus and energy of one ghost path."""
    film, stops, _ = ghost_matrices(system, path, wavelength_nm)
    (a_f, b_f), _ = film
    r_stop = system.lens.surfaces[system.lens.stop_index].aperture_mm / 2
    if len(stops) == 1:
        (a_s, b_s), _ = stops[0]
        p = a_f / a_s
        q = b_f - a_f * b_s / a_s
        radius = abs(p) * r_stop
    else:  # the bundle is the overlap of several stop images: no single disk
        q = b_f - a_f * stops[0][0, 1] / stops[0][0, 0]
        radius = 0.0
    # Focus of an axial bundle: the ray (1, 0) at the film has height A and slope C.
    c_f = film[1, 0]
    focus = -a_f / c_f if abs(c_f) > 1e-15 else float("inf")
    return ParaxialGhost(
        path=path,
        names=(system.names[path.first], system.names[path.second]),
        centre_per_slope_mm=float(q),
        radius_mm=float(radius),
        stop_crossings=len(stops),
        entrance_radius_mm=float(r_stop / abs(stops[0][0, 0])) if stops else float("inf"),
        focus_from_film_mm=float(focus),
        energy=_normal_reflectance(system, path.first) * _normal_reflectance(system, path.second),
    )


def _normal_reflectance(system: GhostSystem, k: int) -> float:
    if system.fixed_reflectance[k] >= 0:
        return float(system.fixed_reflectance[k])
    coating = system.coatings[k]
    lam = coating.design_wavelength_nm if coating is not None else 550.0
    n = system.media(lam)[:, 0]
    n1, d = system.films()
    return float(reflectance(n[k], n[k + 1], 1.0, lam, n1[k], d[k]))


def ghost_table(lens: Lens, options: GhostOptions | None = None) -> list[ParaxialGhost]:
    """Every two-reflection ghost of `lens` (with the cover glass and die if `options` add
    them), first-order, brightest first: names, centre per unit field slope, radius on the film,
    focus relative to the film, energy R_i R_j at normal incidence."""
    system = GhostSystem(lens, options)
    lam = 550.0
    table = [paraxial_ghost(system, p, lam) for p in system.paths()]
    return sorted(table, key=lambda g: -g.energy)
