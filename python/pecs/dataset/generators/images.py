"""Natural-image textures: crops of images that ship inside a wheel pecs already depends on
(matplotlib's sample data; nothing is downloaded), each with its licence, at a drawn scale,
position and rotation.

Two images, both public domain:

- `grace_hopper`: a colour photograph (600 x 512 px). Rendered in colour: its sRGB values are
  decoded to linear, mapped into the drawn `albedo` range and left to Mitsuba's spectral
  upsampling of RGB bitmaps (Jakob and Hanika 2019: per texel a smooth sigmoid spectrum,
  evaluated at each rendered wavelength). pecs itself has no RGB-to-spectrum model (its
  reflectances are tabulated spectra); beyond 780 nm the sigmoid's tail is a model, not a
  measurement.
- `jacksboro_fault`: a digital elevation model (403 x 344 samples, 3 arc-seconds) shown as shaded
  relief, lit from a drawn azimuth: a natural grey image, which weights two drawn reflectance
  spectra as the procedural patterns do (spectral to 1100 nm).

A crop's side is a drawn fraction of the largest square that fits at its drawn rotation, its
centre anywhere that keeps it inside the image; it is resampled bilinearly (numpy only, so that
the bytes are the same on any machine) and tiles by mirroring (Mitsuba's `wrap_mode = mirror`),
as a photograph has no seamless edge.
"""

from __future__ import annotations

import math
from dataclasses import dataclass
from functools import cache
from pathlib import Path
from typing import Any

import numpy as np

#: Drawn crop side, a fraction of the largest rotated square that fits in the image.
CROP_FRACTION = (0.3, 1.0)
#: Shaded relief: the light's elevation range (degrees) and the vertical exaggeration.
RELIEF_ALTITUDE_DEG = (20.0, 60.0)
_RELIEF_EXAGGERATION = 3.0
# Metres per arc-second of latitude (the relief's sample spacing, for its slopes).
_M_PER_ARCSEC = 30.87


@dataclass(frozen=True)
class NaturalImage:
    """An image that ships in matplotlib's wheel, its licence and where it comes from."""

    file: str
    colour: bool
    licence: str
    credit: str


IMAGES = {
    "grace_hopper": NaturalImage(
        file="grace_hopper.jpg",
        colour=True,
        licence="public domain",
        credit=(
            "Commodore Grace M. Hopper, USN: a US Navy photograph (a work of the US federal "
            "government); matplotlib sample data, mpl-data/sample_data/grace_hopper.jpg"
        ),
    ),
    "jacksboro_fault": NaturalImage(
        file="jacksboro_fault_dem.npz",
        colour=False,
        licence="public domain",
        credit=(
            "elevation of the Jacksboro fault, Tennessee, 3 arc-second grid: US government "
            "elevation data (a work of the US federal government); matplotlib sample data, "
            "mpl-data/sample_data/jacksboro_fault_dem.npz"
        ),
    ),
}


def describe_image(rng: np.random.Generator, albedo_range: list[float]) -> dict[str, Any]:
    """A drawn crop of one of `IMAGES`, with the image's licence and credit (they go into the
    scene's description.json). `albedo_range`: what a colour image's linear RGB is mapped into."""
    name = sorted(IMAGES)[int(rng.integers(len(IMAGES)))]
    source = IMAGES[name]
    texture: dict[str, Any] = {
        "kind": "image",
        "image": name,
        "colour": source.colour,
        "licence": source.licence,
        "credit": source.credit,
        "crop_fraction": float(rng.uniform(*CROP_FRACTION)),
        # Where the crop's centre sits in the room left for it, per image axis, 0 to 1.
        "centre": [float(v) for v in rng.uniform(0.0, 1.0, 2)],
        "angle_deg": float(rng.uniform(0.0, 360.0)),
    }
    if source.colour:
        texture["albedo_range"] = [float(v) for v in albedo_range]
    else:
        texture["light_azimuth_deg"] = float(rng.uniform(0.0, 360.0))
        texture["light_altitude_deg"] = float(rng.uniform(*RELIEF_ALTITUDE_DEG))
    return texture


def image_texture(texture: dict[str, Any], size_px: int) -> np.ndarray:
    """The crop, (size_px, size_px, 3) linear RGB reflectance for a colour image, (size_px,
    size_px) weights in [0, 1] for a grey one; row 0 at v = 0."""
    if texture["colour"]:
        linear = _srgb_to_linear(_photo(IMAGES[texture["image"]].file) / 255.0)
        low, high = texture["albedo_range"]
        return low + (high - low) * _crop(linear, texture, size_px)
    relief = _relief(texture)
    crop = _crop(relief[:, :, None], texture, size_px)[:, :, 0]
    lo, hi = crop.min(), crop.max()
    return (crop - lo) / (hi - lo) if hi > lo else np.zeros_like(crop)


def _crop(image: np.ndarray, texture: dict[str, Any], size_px: int) -> np.ndarray:
    """The drawn rotated square of `image` (h, w, c), bilinearly resampled to size_px."""
    height, width = image.shape[:2]
    angle = math.radians(texture["angle_deg"])
    cos, sin = math.cos(angle), math.sin(angle)
    # The largest square at this angle that fits: its bounding box is side * (|cos| + |sin|).
    side = texture["crop_fraction"] * min(height, width) / (abs(cos) + abs(sin))
    reach = side * (abs(cos) + abs(sin)) / 2.0
    cx = reach + texture["centre"][0] * (width - 2.0 * reach)
    cy = reach + texture["centre"][1] * (height - 2.0 * reach)
    offsets = ((np.arange(size_px) + 0.5) / size_px - 0.5) * side
    du, dv = np.meshgrid(offsets, offsets)
    x = cx + cos * du - sin * dv - 0.5
    y = cy + sin * du + cos * dv - 0.5
    return _bilinear(image, x, y)


def _bilinear(image: np.ndarray, x: np.ndarray, y: np.ndarray) -> np.ndarray:
    height, width = image.shape[:2]
    x = np.clip(x, 0.0, width - 1.0)
    y = np.clip(y, 0.0, height - 1.0)
    x0 = np.minimum(np.floor(x).astype(np.int64), width - 2)
    y0 = np.minimum(np.floor(y).astype(np.int64), height - 2)
    fx, fy = (x - x0)[..., None], (y - y0)[..., None]
    top = image[y0, x0] * (1.0 - fx) + image[y0, x0 + 1] * fx
    bottom = image[y0 + 1, x0] * (1.0 - fx) + image[y0 + 1, x0 + 1] * fx
    return top * (1.0 - fy) + bottom * fy


def _srgb_to_linear(value: np.ndarray) -> np.ndarray:
    """IEC 61966-2-1's sRGB decoding."""
    return np.where(value <= 0.04045, value / 12.92, ((value + 0.055) / 1.055) ** 2.4)


@cache
def _photo(file: str) -> np.ndarray:
    from PIL import Image

    with Image.open(_sample_data(file)) as image:
        pixels = np.asarray(image.convert("RGB"), dtype=np.float64)
    pixels.setflags(write=False)
    return pixels


@cache
def _elevation(file: str) -> np.ndarray:
    with np.load(_sample_data(file)) as dem:
        elevation = np.asarray(dem["elevation"], dtype=np.float64)
    elevation.setflags(write=False)
    return elevation


def _relief(texture: dict[str, Any]) -> np.ndarray:
    """Lambertian shaded relief of the elevation, lit from the drawn azimuth and altitude."""
    elevation = _elevation(IMAGES[texture["image"]].file) * _RELIEF_EXAGGERATION
    spacing_m = 3.0 * _M_PER_ARCSEC
    dz_dy, dz_dx = np.gradient(elevation, spacing_m)
    normal = np.stack([-dz_dx, -dz_dy, np.ones_like(elevation)], axis=-1)
    normal /= np.linalg.norm(normal, axis=-1, keepdims=True)
    azimuth = math.radians(texture["light_azimuth_deg"])
    altitude = math.radians(texture["light_altitude_deg"])
    light = np.array(
        [
            math.cos(altitude) * math.sin(azimuth),
            math.cos(altitude) * math.cos(azimuth),
            math.sin(altitude),
        ]
    )
    return np.clip(normal @ light, 0.0, 1.0)


def _sample_data(file: str) -> Path:
    """A file of matplotlib's sample data, inside its installed package."""
    import matplotlib

    path = Path(matplotlib.get_data_path()) / "sample_data" / file
    if not path.is_file():
        raise FileNotFoundError(f"{path}: matplotlib's sample image is missing; reinstall it")
    return path
