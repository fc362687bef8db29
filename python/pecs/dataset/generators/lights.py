"""Lights of generated scenes: point or spherical emitters with blackbody spectra of drawn colour
temperature, above the scene, set to a drawn illuminance by the scene file's light accounting.

The first light uses `$light_spectrum` (`[light] temperature_k`); the others carry their own
blackbody spectrum and a `[[lights]]` level: each gets the share weight_i / sum(weights) of the
drawn illuminance, and `[light]` scales the first so that the total is the drawn illuminance
(docs/scene-files.md, "Light levels"). The meter point is above every object's path, facing up,
so that no object shadows it (the accounting counts direct light with occlusion) and every light
(at least 5 degrees above its horizon) reaches it.
"""

from __future__ import annotations

import math
from typing import Any
from xml.etree.ElementTree import Element, SubElement

import numpy as np

from pecs.dataset.generators.ranges import Draws
from pecs.render.spectrum import (
    WAVELENGTH_MAX_NM,
    WAVELENGTH_MIN_NM,
    mitsuba_spectrum_string,
    planck_radiance,
)

LIGHT_KINDS = ("point", "sphere")
LIGHT_WEIGHT = (0.2, 1.0)  # relative share of the illuminance
SPHERE_RADIUS_M = (0.03, 0.15)
# The fills' tabulated blackbody: 10 nm steps over the rendered range.
_SPECTRUM_STEP_NM = 10.0


def describe_lights(draws: Draws) -> list[dict[str, Any]]:
    """`light_count` lights, each with its kind, direction and distance from the meter point,
    colour temperature and share weight."""
    lights = []
    for index in range(draws.integer("light_count")):
        light: dict[str, Any] = {
            "id": f"light_{index}",
            "kind": draws.pick("light_kinds"),
            "elevation_deg": draws.value("light_elevation_deg"),
            "azimuth_deg": float(draws.rng.uniform(0.0, 360.0)),
            "distance_m": draws.value("light_distance_m"),
            "temperature_k": draws.value("temperature_k"),
            "weight": float(draws.rng.uniform(*LIGHT_WEIGHT)),
        }
        if light["kind"] == "sphere":
            light["radius_m"] = float(draws.rng.uniform(*SPHERE_RADIUS_M))
        lights.append(light)
    return lights


def direction(elevation_deg: float, azimuth_deg: float) -> np.ndarray:
    """Unit vector at an elevation above the horizontal plane (y up) and an azimuth from +z."""
    el, az = math.radians(elevation_deg), math.radians(azimuth_deg)
    return np.array([math.cos(el) * math.sin(az), math.sin(el), math.cos(el) * math.cos(az)])


def light_position(light: dict[str, Any], meter_at: np.ndarray) -> np.ndarray:
    return meter_at + light["distance_m"] * direction(light["elevation_deg"], light["azimuth_deg"])


def shares(lights: list[dict[str, Any]]) -> list[float]:
    """Each light's fraction of the total illuminance."""
    total = sum(light["weight"] for light in lights)
    return [light["weight"] / total for light in lights]


def emitter_element(light: dict[str, Any], position: np.ndarray, first: bool) -> Element:
    """The light as a Mitsuba point emitter or a spherical area light (a shape with the light's
    id, which is how `[[lights]]` names an area light)."""
    spectrum = "$light_spectrum" if first else blackbody_value(light["temperature_k"])
    at = ", ".join(f"{v:.9g}" for v in position)
    if light["kind"] == "point":
        emitter = Element("emitter", type="point", id=light["id"])
        SubElement(emitter, "point", name="position", value=at)
        SubElement(emitter, "spectrum", name="intensity", value=spectrum)
        return emitter
    shape = Element("shape", type="sphere", id=light["id"])
    SubElement(shape, "point", name="center", value=at)
    SubElement(shape, "float", name="radius", value=f"{light['radius_m']:.9g}")
    area = SubElement(shape, "emitter", type="area")
    SubElement(area, "spectrum", name="radiance", value=spectrum)
    return shape


def blackbody_value(temperature_k: float) -> str:
    """Planck's spectrum at `temperature_k`, peak 1, as Mitsuba's `lambda:value` list (its
    level is set by `[[lights]]`)."""
    wavelength_nm = np.arange(WAVELENGTH_MIN_NM, WAVELENGTH_MAX_NM + 0.5, _SPECTRUM_STEP_NM)
    power = planck_radiance(wavelength_nm, temperature_k)
    return mitsuba_spectrum_string(wavelength_nm, power / power.max())
