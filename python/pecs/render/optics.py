"""Camera optics as a Mitsuba sensor, and the radiometric factor from scene radiance to film.

Pinhole and thin lens render radiance L; an ideal lens of f-number N puts the film irradiance
E = L * pi / (4 N^2) * cos^4(theta) at field angle theta (camera equation, Smith, Modern Optical
Engineering ch. 9). The realistic lens plugin traces the prescription and returns irradiance itself.
"""

from __future__ import annotations

import math
from typing import Any

import numpy as np

from pecs.render.pixel_geometry import PixelGeometry
from pecs.render.scene_file import Optics


def horizontal_fov_deg(optics: Optics, geometry: PixelGeometry, xml_fov_deg: float | None) -> float:
    """Field of view across the film width: 2 atan(w / 2f), or as given, or the XML camera's."""
    if optics.fov_deg is not None:
        return optics.fov_deg
    if optics.efl_mm is not None:
        return math.degrees(2.0 * math.atan(geometry.film_width_mm / (2.0 * optics.efl_mm)))
    if xml_fov_deg is None:
        raise ValueError("optics: give efl_mm or fov_deg (the Mitsuba scene has no camera fov)")
    return xml_fov_deg


def sensor_dict(
    optics: Optics,
    geometry: PixelGeometry,
    film: dict[str, Any],
    sampler: dict[str, Any],
    to_world: Any,
    xml_fov_deg: float | None,
) -> dict[str, Any]:
    """Mitsuba sensor dict for the optics (the realistic lens plugin is registered on demand)."""
    common = {"to_world": to_world, "film": film, "sampler": sampler}
    if optics.model == "lens":
        _register_realistic_lens(optics.lens or "")
        lens: dict[str, Any] = {
            "type": "realisticlens",
            "lens": optics.lens,
            "pixel_pitch_um": geometry.pitch_um,
            **common,
        }
        if optics.f_number is not None:  # else wide open
            lens["f_number"] = optics.f_number
        if optics.efl_mm is not None:
            lens["efl_mm"] = optics.efl_mm
        if optics.focus_m is not None:
            lens["focus_m"] = optics.focus_m
        return lens
    fov = horizontal_fov_deg(optics, geometry, xml_fov_deg)
    if optics.model == "pinhole":
        return {"type": "perspective", "fov": fov, "fov_axis": "x", **common}
    assert optics.efl_mm is not None and optics.focus_m is not None
    assert optics.f_number is not None  # 2.0 unless given (scene_file)
    aperture_radius_m = optics.efl_mm / (2.0 * optics.f_number) * 1e-3
    return {
        "type": "thinlens",
        "fov": fov,
        "fov_axis": "x",
        "aperture_radius": aperture_radius_m,
        "focus_distance": optics.focus_m,
        **common,
    }


def _register_realistic_lens(lens: str) -> None:
    """Register the plugin for the variant just chosen; check the lens name first."""
    from pecs.lens import Lens, register_realistic_lens

    try:
        Lens.load(lens)
    except (FileNotFoundError, ValueError) as error:
        raise ValueError(f"optics.lens = {lens!r}: {error}") from error
    register_realistic_lens()


def irradiance_per_radiance(
    optics: Optics, geometry: PixelGeometry, xml_fov_deg: float | None
) -> np.ndarray:
    """Per pixel E / L: pi / (4 N^2) cos^4(theta) for pinhole and thin lens, 1 for the lens plugin."""
    if optics.model == "lens":
        return np.ones((geometry.height, geometry.width), dtype=np.float64)
    fov = math.radians(horizontal_fov_deg(optics, geometry, xml_fov_deg))
    focal_px = geometry.width / (2.0 * math.tan(fov / 2.0))
    x = np.arange(geometry.width) + 0.5 - geometry.width / 2.0
    y = np.arange(geometry.height) + 0.5 - geometry.height / 2.0
    r2 = (x[None, :] ** 2 + y[:, None] ** 2) / focal_px**2
    cos4 = 1.0 / (1.0 + r2) ** 2
    assert optics.f_number is not None  # 2.0 unless given (scene_file)
    return math.pi / (4.0 * optics.f_number**2) * cos4
