"""Texture patterns (procedural noise, stripes, checkers; natural images, `images.py`), drawn
as a few numbers and written as small tileable bitmaps.

A bitmap is not a colour: it is the weight between two drawn reflectance spectra of a material
(`materials.py`), so that the texture stays spectral (an RGB image would be turned into spectra
by Mitsuba's RGB upsampling, which says nothing of the near infrared a sensor sees). Patterns
tile (noise on a wrapped grid, stripes with whole wave numbers) so that uv repeats show no seam.
A colour natural image is the exception: an sRGB bitmap that Mitsuba upsamples to spectra
(`images.py` says why and what that means beyond the visible).
"""

from __future__ import annotations

from pathlib import Path
from typing import Any

import numpy as np

from pecs.dataset.generators import images

TEXTURES = ("none", "noise", "stripes", "checkers", "image")
#: Bitmap side in pixels: small files, fine enough for the cells and stripes drawn here.
SIZE_PX = 128
#: A natural image's side: finer, as a photograph's detail is what it is drawn for.
IMAGE_SIZE_PX = 256
# Fixed ranges of the pattern parameters (documented in docs/datasets.md).
NOISE_OCTAVES = (2, 5)
NOISE_BASE_CELLS = (2, 8)
STRIPE_WAVES = (1, 8)
STRIPE_DUTY = (0.2, 0.8)
CHECKER_CELLS = (2, 3, 4, 6, 8)


def describe_texture(
    kind: str, rng: np.random.Generator, albedo_range: tuple[float, float] = (0.0, 1.0)
) -> dict[str, Any] | None:
    """The drawn parameters of a pattern (`None` for "none"); the pixels are made on writing.
    `albedo_range`: the reflectances a colour image's pixels are mapped into."""
    if kind == "none":
        return None
    if kind == "image":
        return images.describe_image(rng, list(albedo_range))
    if kind == "noise":
        return {
            "kind": kind,
            "octaves": int(rng.integers(NOISE_OCTAVES[0], NOISE_OCTAVES[1], endpoint=True)),
            "base_cells": int(
                rng.integers(NOISE_BASE_CELLS[0], NOISE_BASE_CELLS[1], endpoint=True)
            ),
            # The lattice values are drawn on writing, from this seed: 1000s of numbers need not
            # sit in the description.
            "seed": int(rng.integers(0, 2**63 - 1)),
        }
    if kind == "stripes":
        waves = [0, 0]
        while waves == [0, 0]:  # whole wave numbers along u and v: tileable, at any angle
            waves = [
                int(w) for w in rng.integers(-STRIPE_WAVES[1], STRIPE_WAVES[1], 2, endpoint=True)
            ]
        return {"kind": kind, "waves": waves, "duty": float(rng.uniform(*STRIPE_DUTY))}
    if kind == "checkers":
        return {"kind": kind, "cells": int(CHECKER_CELLS[int(rng.integers(len(CHECKER_CELLS)))])}
    raise ValueError(f"unknown texture {kind!r} (known: {', '.join(TEXTURES)})")


def texture_image(texture: dict[str, Any], size_px: int = SIZE_PX) -> np.ndarray:
    """The pattern as weights in [0, 1], float64 (size_px, size_px), row 0 at v = 0; a colour
    image: linear RGB reflectance (size_px, size_px, 3)."""
    if texture["kind"] == "image":
        return images.image_texture(texture, size_px)
    u = (np.arange(size_px) + 0.5) / size_px
    uu, vv = np.meshgrid(u, u)
    kind = texture["kind"]
    if kind == "stripes":
        kx, ky = texture["waves"]
        phase = np.mod(kx * uu + ky * vv, 1.0)
        return (phase < texture["duty"]).astype(np.float64)
    if kind == "checkers":
        cells = texture["cells"]
        return (np.mod(np.floor(uu * cells) + np.floor(vv * cells), 2.0)).astype(np.float64)
    if kind == "noise":
        return _fractal_noise(texture, size_px)
    raise ValueError(f"unknown texture {kind!r} (known: {', '.join(TEXTURES)})")


def _fractal_noise(texture: dict[str, Any], size_px: int) -> np.ndarray:
    """Value noise summed over octaves (amplitude halving, cells doubling), on wrapped lattices,
    stretched to [0, 1]."""
    rng = np.random.default_rng(texture["seed"])
    total = np.zeros((size_px, size_px))
    for octave in range(texture["octaves"]):
        cells = texture["base_cells"] * 2**octave
        lattice = rng.random((cells, cells))
        total += 0.5**octave * _wrapped_bilinear(lattice, size_px)
    low, high = total.min(), total.max()
    return (total - low) / (high - low) if high > low else np.zeros_like(total)


def _wrapped_bilinear(lattice: np.ndarray, size_px: int) -> np.ndarray:
    """A periodic lattice sampled at pixel centres, smoothstep-interpolated (no seams)."""
    cells = lattice.shape[0]
    position = (np.arange(size_px) + 0.5) * cells / size_px - 0.5
    start = np.floor(position).astype(np.int64)
    fraction = position - start
    weight = fraction * fraction * (3.0 - 2.0 * fraction)
    i0, i1 = np.mod(start, cells), np.mod(start + 1, cells)
    rows = lattice[i0] * (1.0 - weight)[:, None] + lattice[i1] * weight[:, None]
    return rows[:, i0] * (1.0 - weight)[None, :] + rows[:, i1] * weight[None, :]


def is_colour(texture: dict[str, Any]) -> bool:
    """Whether a texture is a reflectance bitmap (sRGB, upsampled by Mitsuba), not weights."""
    return texture["kind"] == "image" and bool(texture["colour"])


def write_texture(texture: dict[str, Any], path: Path) -> None:
    """The pattern as an 8-bit greyscale PNG (Mitsuba reads it as raw weights, not sRGB); a
    colour image as an 8-bit sRGB PNG of its reflectance."""
    from PIL import Image

    size_px = IMAGE_SIZE_PX if texture["kind"] == "image" else SIZE_PX
    values = texture_image(texture, size_px)
    if is_colour(texture):
        values = _linear_to_srgb(values)
    pixels = np.round(np.clip(values, 0.0, 1.0) * 255.0).astype(np.uint8)
    path.parent.mkdir(parents=True, exist_ok=True)
    Image.fromarray(pixels).save(path, format="PNG", optimize=False)


def _linear_to_srgb(value: np.ndarray) -> np.ndarray:
    """IEC 61966-2-1's sRGB encoding (Mitsuba decodes it on reading)."""
    value = np.clip(value, 0.0, 1.0)
    return np.where(value <= 0.0031308, 12.92 * value, 1.055 * value ** (1.0 / 2.4) - 0.055)
