"""Helpers for the scene generators (`*/make.py`): Mitsuba XML shapes and TOML keyframes as text.

Units are metres and seconds; Mitsuba's camera looks down -z with +y up. The generators write
`scene.xml` and `scene.toml` next to themselves, deterministically (fixed seeds), so the files in
git are exactly what `python scenes/NAME/make.py` writes.
"""

from __future__ import annotations

from collections.abc import Iterable, Sequence
from pathlib import Path


def vec(values: Sequence[float]) -> str:
    """`x, y, z` for XML attributes, rounded to the millimetre (and 1e-4 for small numbers)."""
    return ", ".join(
        f"{v:.4g}" if abs(v) < 1 else f"{v:.3f}".rstrip("0").rstrip(".") for v in values
    )


def diffuse(reflectance: float | str) -> str:
    """A diffuse BSDF of a constant reflectance, or of a texture's XML."""
    if isinstance(reflectance, str):
        return f'<bsdf type="diffuse">{reflectance}</bsdf>'
    return f'<bsdf type="diffuse"><float name="reflectance" value="{reflectance:g}"/></bsdf>'


def checker(color0: float, color1: float, scale_u: float, scale_v: float) -> str:
    """A checkerboard reflectance texture with scale_u x scale_v periods over the uv square."""
    return (
        f'<texture type="checkerboard" name="reflectance"><float name="color0" value="{color0:g}"/>'
        f'<float name="color1" value="{color1:g}"/><transform name="to_uv">'
        f'<scale x="{scale_u:.4g}" y="{scale_v:.4g}"/></transform></texture>'
    )


def box(shape_id: str, centre: Sequence[float], half: Sequence[float], bsdf: str) -> str:
    """An axis-aligned box (Mitsuba's cube spans [-1, 1]^3)."""
    return (
        f'<shape type="cube" id="{shape_id}"><transform name="to_world">'
        f'<scale x="{half[0]:.4g}" y="{half[1]:.4g}" z="{half[2]:.4g}"/>'
        f'<translate value="{vec(centre)}"/></transform>{bsdf}</shape>'
    )


def cylinder(
    shape_id: str, p0: Sequence[float], p1: Sequence[float], radius: float, bsdf: str
) -> str:
    return (
        f'<shape type="cylinder" id="{shape_id}"><point name="p0" value="{vec(p0)}"/>'
        f'<point name="p1" value="{vec(p1)}"/><float name="radius" value="{radius:.4g}"/>{bsdf}</shape>'
    )


def sphere(shape_id: str, centre: Sequence[float], radius: float, bsdf: str) -> str:
    return (
        f'<shape type="sphere" id="{shape_id}"><point name="center" value="{vec(centre)}"/>'
        f'<float name="radius" value="{radius:.4g}"/>{bsdf}</shape>'
    )


def rectangle(shape_id: str, transform: str, bsdf: str) -> str:
    """Mitsuba's rectangle spans [-1, 1]^2 at z = 0 facing +z, before `transform`."""
    return f'<shape type="rectangle" id="{shape_id}"><transform name="to_world">{transform}</transform>{bsdf}</shape>'


def scene_xml(comment: str, camera: str, shapes: Iterable[str], emitter: str) -> str:
    body = "\n  ".join([camera, *shapes, emitter])
    return (
        f"<!-- {comment} -->\n"
        '<scene version="3.0.0">\n  <default name="light_spectrum" value="400:1, 700:1"/>\n'
        f"  {body}\n</scene>\n"
    )


def keyframe(
    t_s: float,
    position: Sequence[float] | None = None,
    angle_deg: float | None = None,
    axis: Sequence[float] = (0, 0, 1),
    look_at: Sequence[float] | None = None,
) -> str:
    """One TOML inline keyframe."""
    parts = [f"t_s = {t_s:.4g}"]
    if position is not None:
        parts.append(f"position = [{vec(position)}]")
    if look_at is not None:
        parts.append(f"look_at = [{vec(look_at)}]")
    if angle_deg is not None:
        parts.append(f"axis = [{vec(axis)}], angle_deg = {angle_deg:.4g}")
    return "{ " + ", ".join(parts) + " }"


def object_track(
    object_id: str, keyframes: Sequence[str], pivot: Sequence[float] | None = None
) -> str:
    """A `[[objects]]` table."""
    pivot_line = f"pivot = [{vec(pivot)}]\n" if pivot is not None else ""
    keys = ",\n  ".join(keyframes)
    return f'[[objects]]\nid = "{object_id}"\n{pivot_line}keyframes = [\n  {keys},\n]\n'


def write(folder: Path, xml: str, toml: str) -> None:
    (folder / "scene.xml").write_text(xml)
    (folder / "scene.toml").write_text(toml)
    print(f"wrote {folder / 'scene.xml'} and {folder / 'scene.toml'}")
