"""Synthetic inputs for demos and tests: a rotating black-and-white quadrant disk, as in the PECS
paper's real set-up, written as 8-bit sRGB PNG frames a camera would record."""

from __future__ import annotations

import os
from pathlib import Path

import numpy as np

from pecs._atomic import atomic_path


def quadrant_disk(
    width: int,
    height: int,
    angle_rad: float,
    *,
    white: float = 0.9,
    black: float = 0.05,
    room: float = 0.2,
) -> np.ndarray:
    """Linear radiance of a disk with alternating white and black quadrants, turned by `angle_rad`."""
    y, x = np.mgrid[0:height, 0:width].astype(np.float64)
    cx, cy, radius = (width - 1) / 2, (height - 1) / 2, 0.42 * min(width, height)
    theta = np.arctan2(y - cy, x - cx) - angle_rad
    quadrant = np.floor(np.mod(theta, 2 * np.pi) / (np.pi / 2)).astype(int) % 2
    disk = np.where(quadrant == 0, white, black)
    inside = np.hypot(x - cx, y - cy) <= radius
    return np.where(inside, disk, room)


def linear_to_srgb8(linear: np.ndarray) -> np.ndarray:
    """IEC 61966-2-1 encoding of linear [0, 1] values to 8 bits."""
    v = np.clip(linear, 0.0, 1.0)
    encoded = np.where(v <= 0.0031308, 12.92 * v, 1.055 * v ** (1 / 2.4) - 0.055)
    return np.round(encoded * 255).astype(np.uint8)


def write_quadrant_disk_frames(
    folder: str | os.PathLike[str],
    *,
    width: int = 346,
    height: int = 260,
    frames: int = 100,
    fps: float = 1000.0,
    turns_per_s: float = 2.0,
) -> Path:
    """Write a rotating quadrant disk as numbered PNG frames; returns the folder."""
    import cv2

    out = Path(folder)
    out.mkdir(parents=True, exist_ok=True)
    for k in range(frames):
        angle = 2 * np.pi * turns_per_s * k / fps
        image = linear_to_srgb8(quadrant_disk(width, height, angle))
        ok, png = cv2.imencode(".png", image)
        if not ok:
            raise OSError("PNG encoding failed")
        with atomic_path(out / f"frame_{k:05d}.png") as tmp:
            tmp.write_bytes(png.tobytes())
    return out
