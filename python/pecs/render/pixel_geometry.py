"""Pixel geometry of the sensor presets: resolution, pitch and fill factor (photodiode area).

Photocurrent I = q * (photo-electrons per second per m^2 of photodiode) * pitch^2 * fill factor.
"""

from __future__ import annotations

from dataclasses import dataclass
from typing import Any

# width, height, pixel pitch (um), fill factor; sources per line.
PRESET_PIXELS: dict[str, tuple[int, int, float, float]] = {
    # DAVIS346 (iniVation datasheet): 346 x 260, 18.5 um; front-illuminated, fill factor 22 %
    # (Taverni et al., IEEE TCAS-II 2018, front- vs back-illuminated DAVIS346).
    "davis346": (346, 260, 18.5, 0.22),
    # Color-DAVIS346: the same chip under a colour filter array.
    "color_davis346": (346, 260, 18.5, 0.22),
    # DVXplorer (iniVation datasheet): 640 x 480, 9 um; fill factor not published: 0.22 assumed.
    "dvxplorer": (640, 480, 9.0, 0.22),
    # Sony IMX636 / Prophesee Gen4 (Finateu et al., ISSCC 2020): 1280 x 720, 4.86 um, stacked
    # back-illuminated, fill factor > 77 %.
    "imx636": (1280, 720, 4.86, 0.77),
    # Idealised pixels: DAVIS346 format with the whole pixel sensitive.
    "ideal": (346, 260, 18.5, 1.0),
    "esim": (346, 260, 18.5, 1.0),
}


@dataclass(frozen=True)
class PixelGeometry:
    """Sensor resolution and pixel size; the film of the camera."""

    width: int
    height: int
    pitch_um: float
    fill_factor: float

    @property
    def film_width_mm(self) -> float:
        return self.width * self.pitch_um * 1e-3

    @property
    def film_height_mm(self) -> float:
        return self.height * self.pitch_um * 1e-3

    @property
    def photodiode_area_m2(self) -> float:
        return (self.pitch_um * 1e-6) ** 2 * self.fill_factor


def pixel_geometry(preset: str, overrides: dict[str, Any] | None = None) -> PixelGeometry:
    """The preset's geometry with `width`, `height`, `pixel_pitch_um`, `fill_factor` overridden."""
    if preset not in PRESET_PIXELS:
        raise ValueError(f"unknown sensor preset {preset!r}; known: {sorted(PRESET_PIXELS)}")
    width, height, pitch_um, fill_factor = PRESET_PIXELS[preset]
    o = overrides or {}
    geometry = PixelGeometry(
        int(o.get("width", width)),
        int(o.get("height", height)),
        float(o.get("pixel_pitch_um", pitch_um)),
        float(o.get("fill_factor", fill_factor)),
    )
    # Each message starts with the field's name, as SensorConfig's do: callers name its source.
    for name, value in (("width", geometry.width), ("height", geometry.height)):
        if value < 1:
            raise ValueError(f"{name}: must be a positive number of pixels, got {value}")
    if not geometry.pitch_um > 0:
        raise ValueError(f"pixel_pitch_um: must be positive, got {geometry.pitch_um}")
    if not 0 < geometry.fill_factor <= 1:
        raise ValueError(f"fill_factor: must lie in (0, 1], got {geometry.fill_factor}")
    return geometry
