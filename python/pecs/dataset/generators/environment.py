"""Environment maps of generated scenes: a procedural daylight sky written as a lat-long map for
Mitsuba's `envmap` emitter, set to its drawn share of the illuminance by `[[lights]]`.

The sky's luminance follows the CIE standard general sky (CIE S 011/E:2003, ISO 15469): relative
to the zenith, L(Z, chi) / L_z = f(chi) phi(Z) / (f(Z_s) phi(0)), with the gradation
phi(Z) = 1 + a exp(b / cos Z) and the indicatrix f(chi) = 1 + c (exp(d chi) - exp(d pi / 2)) +
e cos^2 chi (Z: zenith angle, chi: angle to the sun, Z_s: the sun's zenith angle). Three of its
fifteen types are drawn: 12 (clear), 7 (partly cloudy), 1 (overcast). Its colour is a gradient
from a blue zenith to a white horizon and sun (none under an overcast sky); Mitsuba's envmap
multiplies the map's RGB, upsampled, by the D65 illuminant in spectral variants, so white is
daylight. D65 is tabulated to 830 nm: the sky gives no light from 830 to 1100 nm. The sun
itself is not in the map (a disk of 0.5 degrees is far below a map pixel): a scene adds it as a
directional emitter (`driving.py`) or leaves it out.

Below the horizon the map is a grey ground of albedo 0.2 lit by the sky (L = 0.2 E_h / pi), for
the directions no floor covers.
"""

from __future__ import annotations

import math
from pathlib import Path
from typing import Any
from xml.etree.ElementTree import Element, SubElement

import numpy as np

from pecs.dataset.generators.lights import direction

SKY_KINDS = ("clear", "partly_cloudy", "overcast")
#: CIE standard general sky coefficients (a, b, c, d, e) of the drawn types.
CIE_SKY = {
    "clear": (-1.0, -0.32, 10.0, -3.0, 0.45),  # type 12, the CIE standard clear sky
    "partly_cloudy": (0.0, -1.0, 5.0, -2.5, 0.30),  # type 7
    "overcast": (4.0, -0.70, 0.0, -1.0, 0.0),  # type 1, the CIE standard overcast sky
}
#: How blue the zenith is per kind (0: white).
_SATURATION = {"clear": 1.0, "partly_cloudy": 0.5, "overcast": 0.0}
# Linear sRGB of a clear zenith, luminance 1 (Rec. 709 weights).
_ZENITH_RGB = np.array([0.45, 0.75, 1.0])
_LUMA = np.array([0.2126, 0.7152, 0.0722])
_GROUND_ALBEDO = 0.2
#: Map size (lat-long, width = 2 height): about 1.4 degrees a pixel.
MAP_HEIGHT_PX = 128
SKY_ID = "sky"


def describe_sky(rng: np.random.Generator, kind: str, sun_elevation_deg: float) -> dict[str, Any]:
    """A sky of `kind` with the sun at a drawn azimuth and the given elevation."""
    if kind not in SKY_KINDS:
        raise ValueError(f"unknown sky {kind!r} (known: {', '.join(SKY_KINDS)})")
    return {
        "kind": kind,
        "sun_elevation_deg": float(sun_elevation_deg),
        "sun_azimuth_deg": float(rng.uniform(0.0, 360.0)),
    }


def map_directions(height_px: int = MAP_HEIGHT_PX) -> np.ndarray:
    """Unit direction (h, 2h, 3) of each pixel centre of Mitsuba's lat-long map (y up): row r
    at zenith angle pi (r + 0.5) / h, column c where atan2(x, -z) = 2 pi (c + 0.5) / 2h."""
    theta = math.pi * (np.arange(height_px) + 0.5) / height_px
    phi = 2.0 * math.pi * (np.arange(2 * height_px) + 0.5) / (2 * height_px)
    theta, phi = np.meshgrid(theta, phi, indexing="ij")
    return np.stack(
        [np.sin(theta) * np.sin(phi), np.cos(theta), -np.sin(theta) * np.cos(phi)], axis=-1
    )


def relative_luminance(sky: dict[str, Any], directions: np.ndarray) -> np.ndarray:
    """The CIE sky's luminance relative to the zenith in `directions` (..., 3) above the
    horizon (zero below)."""
    a, b, c, d, e = CIE_SKY[sky["kind"]]
    sun = direction(sky["sun_elevation_deg"], sky["sun_azimuth_deg"])
    cos_z = directions[..., 1]
    chi = np.arccos(np.clip(directions @ sun, -1.0, 1.0))
    sun_zenith = math.radians(90.0 - sky["sun_elevation_deg"])

    def gradation(cos_zenith: np.ndarray | float) -> np.ndarray:
        safe = np.maximum(cos_zenith, 1e-6)
        return 1.0 + a * np.exp(b / safe)

    def indicatrix(angle: np.ndarray | float) -> np.ndarray:
        return 1.0 + c * (np.exp(d * angle) - math.exp(d * math.pi / 2.0)) + e * np.cos(angle) ** 2

    luminance = indicatrix(chi) * gradation(cos_z) / (indicatrix(sun_zenith) * gradation(1.0))
    return np.where(cos_z > 0.0, luminance, 0.0)


def sky_map(sky: dict[str, Any], height_px: int = MAP_HEIGHT_PX) -> np.ndarray:
    """The map's linear RGB radiance (h, 2h, 3), zenith luminance 1 (pecs scales it to lux)."""
    directions = map_directions(height_px)
    luminance = relative_luminance(sky, directions)
    sun = direction(sky["sun_elevation_deg"], sky["sun_azimuth_deg"])
    # Whiter towards the horizon and around the sun; the chroma has luminance 1.
    horizon = np.clip(1.0 - directions[..., 1], 0.0, 1.0) ** 3
    near_sun = np.clip(directions @ sun, 0.0, 1.0) ** 8
    white = np.clip(horizon + near_sun, 0.0, 1.0)
    blue = _ZENITH_RGB / float(_LUMA @ _ZENITH_RGB)
    chroma = 1.0 + _SATURATION[sky["kind"]] * (1.0 - white[..., None]) * (blue - 1.0)
    rgb = luminance[..., None] * chroma
    # The ground: a grey Lambertian reflector lit by the sky above (E_h from the map itself).
    solid_angle = _pixel_solid_angles(height_px)
    irradiance = float(np.sum(luminance * np.maximum(directions[..., 1], 0.0) * solid_angle))
    below = directions[..., 1] <= 0.0
    rgb[below] = _GROUND_ALBEDO * irradiance / math.pi
    return rgb


def _pixel_solid_angles(height_px: int) -> np.ndarray:
    """(h, 1) solid angle of each map pixel (steradians)."""
    theta = math.pi * (np.arange(height_px + 1)) / height_px
    band = 2.0 * math.pi * (np.cos(theta[:-1]) - np.cos(theta[1:]))
    return (band / (2 * height_px))[:, None]


def write_sky(sky: dict[str, Any], path: Path) -> None:
    """The map as a PFM (float32 RGB, little-endian; written with numpy: the same bytes on any
    machine, and no OpenEXR needed)."""
    rgb = sky_map(sky).astype("<f4")
    height, width = rgb.shape[:2]
    path.parent.mkdir(parents=True, exist_ok=True)
    with open(path, "wb") as out:
        out.write(f"PF\n{width} {height}\n-1.0\n".encode("ascii"))
        out.write(np.ascontiguousarray(rgb[::-1]).tobytes())  # PFM rows run bottom to top


def emitter_element(map_file: str) -> Element:
    """The `envmap` emitter (id `SKY_ID`, which `[[lights]]` names) of a written map."""
    emitter = Element("emitter", type="envmap", id=SKY_ID)
    SubElement(emitter, "string", name="filename", value=map_file)
    return emitter
