"""Materials of generated objects: diffuse, rough plastic, rough conductor and dielectric, with
drawn roughness and reflectance spectra, as Mitsuba BSDF elements.

pecs renders spectrally over 360-1100 nm (the sensor's QE reaches the near infrared), so
reflectances are spectra, `lambda:value` pairs at `ALBEDO_NM` (Mitsuba interpolates linearly
between them), never RGB colours. A texture is the weight of a `blendbsdf` between the material
with two drawn spectra: a spectral pattern. A colour natural image is the material's reflectance
itself (an sRGB bitmap Mitsuba upsamples to spectra; `images.py`).
"""

from __future__ import annotations

from typing import Any
from xml.etree.ElementTree import Element, SubElement

import numpy as np

from pecs.dataset.generators.ranges import Draws
from pecs.dataset.generators.textures import describe_texture, is_colour
from pecs.render.spectrum import mitsuba_spectrum_string

MATERIALS = ("diffuse", "plastic", "conductor", "dielectric")
#: Wavelengths of the drawn reflectance spectra: the rendered range, denser in the visible.
ALBEDO_NM = (360.0, 440.0, 520.0, 600.0, 680.0, 780.0, 900.0, 1100.0)
# Air's index: the outside of a dielectric.
AIR_IOR = 1.000277
# Materials whose reflectance may carry a texture (a metal or glass pattern is another object).
TEXTURED = ("diffuse", "plastic")


def describe_material(kind: str, draws: Draws, textures_key: str = "textures") -> dict[str, Any]:
    """The drawn parameters of a material of `kind`; `textures_key` names the parameter its
    texture is picked from (objects and backgrounds have their own lists)."""
    material: dict[str, Any] = {"kind": kind}
    if kind in ("diffuse", "plastic", "conductor"):
        material["albedo"] = albedo_spectrum(draws)
    if kind in ("plastic", "conductor", "dielectric"):
        material["roughness"] = draws.value("roughness")
    if kind == "dielectric":
        material["ior"] = draws.value("ior")
    if kind in TEXTURED:
        texture = describe_texture(draws.pick(textures_key), draws.rng, draws.ranges["albedo"])
        if texture is not None:
            material["texture"] = texture
            if is_colour(texture):  # the image is the reflectance: no drawn spectra
                del material["albedo"]
            else:
                material["albedo_2"] = albedo_spectrum(draws, contrast_to=material["albedo"])
            material["repeats"] = draws.integer("texture_repeats")
    return material


def albedo_spectrum(draws: Draws, contrast_to: list[float] | None = None) -> list[float]:
    """Reflectance at each of `ALBEDO_NM`, within the `albedo` range: a level (uniform in the
    range) and a tint around it (smooth: neighbouring wavelengths averaged), which never leaves
    the range. Independent values per wavelength would average out under the sensor's QE into
    the same grey for every object; the level keeps objects apart. `contrast_to`: a texture's
    first spectrum, whose level the second sits away from (by half the room on the wider side)
    so that the pattern shows."""
    low, high = draws.ranges["albedo"]
    if contrast_to is None:
        level = draws.value("albedo")
    else:
        first = float(np.mean(contrast_to))
        step = draws.rng.uniform(0.5, 1.0)
        level = (
            first + step * (high - first)
            if high - first >= first - low
            else first - step * (first - low)
        )
    saturation = draws.rng.uniform(0.0, 1.0)
    tint = np.convolve(draws.rng.uniform(-1.0, 1.0, len(ALBEDO_NM) + 2), np.ones(3) / 3, "valid")
    room = min(level - low, high - level)
    return [float(np.clip(level + saturation * room * t, low, high)) for t in tint]


def bsdf_element(
    material: dict[str, Any], texture_file: str | None, open_surface: bool = False
) -> Element:
    """The material as a Mitsuba `<bsdf>`; `texture_file` is its bitmap (relative to the XML).
    An open surface (a rectangle, Mitsuba's capless cylinder) is seen from both sides: opaque
    materials are two-sided, a dielectric is a thin sheet (a solid needs a closed surface)."""
    kind = material["kind"]
    if kind == "dielectric" and open_surface:
        bsdf = Element("bsdf", type="thindielectric")
        _number(bsdf, "int_ior", material["ior"])
        _number(bsdf, "ext_ior", AIR_IOR)
        return bsdf
    if "texture" in material and texture_file is not None and is_colour(material["texture"]):
        bsdf = _plain(material, _bitmap(material, texture_file, "reflectance", raw=False))
    elif "texture" in material and texture_file is not None:
        bsdf = _blend(material, texture_file)
    else:
        bsdf = _plain(material, material.get("albedo", []))
    if not open_surface or kind == "dielectric":
        return bsdf
    sides = Element("bsdf", type="twosided")
    sides.append(bsdf)
    return sides


def _blend(material: dict[str, Any], texture_file: str) -> Element:
    bsdf = Element("bsdf", type="blendbsdf")
    # The PNG holds weights, not sRGB colours: read its values as they are.
    bsdf.append(_bitmap(material, texture_file, "weight", raw=True))
    bsdf.append(_plain(material, material["albedo"]))
    bsdf.append(_plain(material, material["albedo_2"]))
    return bsdf


def _bitmap(material: dict[str, Any], texture_file: str, name: str, raw: bool) -> Element:
    """A bitmap texture repeated `repeats` times per uv unit; a photograph (no seamless edge)
    repeats mirrored."""
    bitmap = Element("texture", type="bitmap", name=name)
    SubElement(bitmap, "string", name="filename", value=texture_file)
    if raw:
        SubElement(bitmap, "boolean", name="raw", value="true")
    if material["texture"]["kind"] == "image":
        SubElement(bitmap, "string", name="wrap_mode", value="mirror")
    to_uv = SubElement(bitmap, "transform", name="to_uv")
    repeats = str(material["repeats"])
    SubElement(to_uv, "scale", x=repeats, y=repeats)
    return bitmap


def _plain(material: dict[str, Any], albedo: list[float] | Element) -> Element:
    kind = material["kind"]
    if kind == "diffuse":
        bsdf = Element("bsdf", type="diffuse")
        _spectrum(bsdf, "reflectance", albedo)
        return bsdf
    if kind == "plastic":
        bsdf = Element("bsdf", type="roughplastic")
        _spectrum(bsdf, "diffuse_reflectance", albedo)
    elif kind == "conductor":
        bsdf = Element("bsdf", type="roughconductor")
        # A perfect mirror's Fresnel term, scaled by the drawn reflectance spectrum.
        SubElement(bsdf, "string", name="material", value="none")
        _spectrum(bsdf, "specular_reflectance", albedo)
    elif kind == "dielectric":
        bsdf = Element("bsdf", type="roughdielectric")
        _number(bsdf, "int_ior", material["ior"])
        _number(bsdf, "ext_ior", AIR_IOR)
    else:
        raise ValueError(f"unknown material {kind!r} (known: {', '.join(MATERIALS)})")
    SubElement(bsdf, "string", name="distribution", value="ggx")
    _number(bsdf, "alpha", material["roughness"])
    return bsdf


def _spectrum(parent: Element, name: str, values: list[float] | Element) -> None:
    """A reflectance: drawn spectrum values, or a texture (renamed to the parameter)."""
    if isinstance(values, Element):
        values.set("name", name)
        parent.append(values)
        return
    SubElement(parent, "spectrum", name=name, value=spectrum_value(values))


def spectrum_value(values: list[float]) -> str:
    """`lambda:value, ...` at `ALBEDO_NM`."""
    return mitsuba_spectrum_string(list(ALBEDO_NM), values)


def _number(parent: Element, name: str, value: float) -> None:
    SubElement(parent, "float", name=name, value=f"{value:.9g}")
