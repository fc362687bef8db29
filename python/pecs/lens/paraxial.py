"""First-order (paraxial) optics by ray-transfer matrices.

A paraxial ray is (y, n u): height and reduced angle. Refraction at a surface of curvature c
between indices n and n' is nu' = nu - y c (n' - n); transfer over thickness t in index n' is
y' = y + t nu' / n' (Smith, Modern Optical Engineering, ch. 3). The system matrix gives the
cardinal points, the pupils (images of the stop) and the f-number.
"""

from __future__ import annotations

from dataclasses import dataclass

import numpy as np


def refraction_matrix(curvature_per_mm: float, n_before: float, n_after: float) -> np.ndarray:
    return np.array([[1.0, 0.0], [-curvature_per_mm * (n_after - n_before), 1.0]])


def transfer_matrix(thickness_mm: float, n: float) -> np.ndarray:
    return np.array([[1.0, thickness_mm / n], [0.0, 1.0]])


def system_matrix(
    curvatures: np.ndarray, thicknesses: np.ndarray, n_before: np.ndarray, n_after: np.ndarray
) -> np.ndarray:
    """Matrix from just before the first surface to just after the last one; the thicknesses
    between surfaces are thicknesses[:-1]."""
    m = np.eye(2)
    for i in range(len(curvatures)):
        if i > 0:
            m = transfer_matrix(thicknesses[i - 1], n_before[i]) @ m
        m = refraction_matrix(curvatures[i], n_before[i], n_after[i]) @ m
    return m


@dataclass(frozen=True)
class FirstOrder:
    """Cardinal points and pupils; z in mm from the first vertex, positive towards the film.

    The lens is in air on both sides.
    """

    efl_mm: float
    bfl_mm: float  # last vertex to rear focal point
    ffl_mm: float  # front focal point to first vertex (positive when in front)
    front_principal_z_mm: float
    rear_principal_z_mm: float
    entrance_pupil_z_mm: float
    entrance_pupil_diameter_mm: float
    exit_pupil_z_mm: float
    exit_pupil_diameter_mm: float
    pupil_magnification: float  # exit / entrance pupil diameter
    last_vertex_z_mm: float

    @property
    def f_number(self) -> float:
        """Paraxial f-number for an object at infinity: EFL / entrance pupil diameter."""
        return self.efl_mm / self.entrance_pupil_diameter_mm


def first_order(
    curvatures: np.ndarray,
    thicknesses: np.ndarray,
    n_before: np.ndarray,
    n_after: np.ndarray,
    stop_index: int,
    stop_diameter_mm: float,
) -> FirstOrder:
    """First-order properties of a system in air."""
    (a, b), (c, d) = system_matrix(curvatures, thicknesses, n_before, n_after)
    if abs(c) < 1e-15:
        raise ValueError("the lens is afocal (zero power): no focal length")
    efl = -1.0 / c
    last_z = float(np.sum(thicknesses[:-1]))
    bfl = -a / c
    ffl = -d / c
    # Front part: first vertex to the stop plane (the stop refracts nothing).
    k = stop_index
    front = system_matrix(curvatures[:k], thicknesses[:k], n_before[:k], n_after[:k])
    to_stop = transfer_matrix(thicknesses[k - 1], n_before[k]) @ front if k > 0 else np.eye(2)
    ak, bk = to_stop[0]
    if abs(ak) < 1e-15:
        raise ValueError("the entrance pupil is at infinity (telecentric object side)")
    ep_z = bk / ak  # chief ray (height 0 at the stop) crosses the axis here in object space
    ep_d = stop_diameter_mm / abs(ak)
    # Back part: stop plane to the last vertex.
    back = system_matrix(curvatures[k:], thicknesses[k:], n_before[k:], n_after[k:])
    _, bs = back[0]
    _, ds = back[1]
    if abs(ds) < 1e-15:
        raise ValueError("the exit pupil is at infinity (telecentric image side)")
    xp_z = last_z - bs / ds
    xp_d = stop_diameter_mm / abs(ds)
    return FirstOrder(
        efl_mm=efl,
        bfl_mm=bfl,
        ffl_mm=ffl,
        front_principal_z_mm=-ffl + efl,
        rear_principal_z_mm=last_z + bfl - efl,
        entrance_pupil_z_mm=ep_z,
        entrance_pupil_diameter_mm=ep_d,
        exit_pupil_z_mm=xp_z,
        exit_pupil_diameter_mm=xp_d,
        pupil_magnification=xp_d / ep_d,
        last_vertex_z_mm=last_z,
    )


def film_distance_for_focus(fo: FirstOrder, focus_mm: float) -> float:
    """Distance from the last vertex to the film that images an object `focus_mm` in front of
    the film (thick lens, Gaussian 1/s + 1/s' = 1/f with s + H + s' = focus, H the separation
    of the principal planes)."""
    if not np.isfinite(focus_mm):
        return fo.bfl_mm
    f = fo.efl_mm
    h = fo.rear_principal_z_mm - fo.front_principal_z_mm
    span = focus_mm - h
    disc = span * span - 4.0 * f * span
    if span <= 0 or disc < 0:
        raise ValueError(
            f"cannot focus at {focus_mm / 1000:g} m: the closest focus of this lens is "
            f"{(4.0 * f + h) / 1000:g} m from the film"
        )
    s_image = 0.5 * (span - np.sqrt(disc))
    return fo.rear_principal_z_mm + s_image - fo.last_vertex_z_mm
