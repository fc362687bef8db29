"""Training frames in the E2VID recipe (Rebecq et al., TPAMI 2019, section 4: natural images
moved by random 2-D motions, foreground objects over a background, rendered at a high frame rate
and run through an event simulator): a textured background under a slow random affine motion
(static in some sequences, as both test recordings' cameras are) and 1-3 textured discs crossing
it at their own speeds. Linear intensity in [0, 1].

Textures: crops of the two public-domain natural images that pecs's scene generator uses
(matplotlib's sample data: a photograph, shown in grey, and a shaded elevation model;
pecs.dataset.generators.images) and its fractal value noise (textures.py), each stretched to a
drawn contrast range. The test recordings' frames are never used."""

from __future__ import annotations

from dataclasses import dataclass

import numpy as np
from pecs.dataset.generators import images, textures
from scipy.ndimage import map_coordinates

TEXTURE_PX = 256
#: Sequences with a still background: both test recordings are taken by a fixed camera.
STILL_BACKGROUND_FRACTION = 0.5
BACKGROUND_SPEED_PX_S = (5.0, 80.0)  # log-uniform
OBJECT_SPEED_PX_S = (20.0, 400.0)  # log-uniform
OBJECT_RADIUS_FRACTION = (0.08, 0.3)  # of the side
OBJECTS = (1, 3)
ROTATION_RAD_S = 1.0  # uniform in +-
ZOOM_PER_S = 0.3  # log scale rate, uniform in +-
# Luminance of linear sRGB primaries (ITU-R BT.709), for the photograph in grey.
_LUMA = np.array([0.2126, 0.7152, 0.0722])


@dataclass(frozen=True)
class Sequence:
    """Frames (N, side, side) float32 at `frame_times_us`; the targets are the frames at the
    window ends `target_times_us`."""

    frames: np.ndarray
    frame_times_us: np.ndarray
    target_times_us: np.ndarray

    @property
    def targets(self) -> np.ndarray:
        return self.frames[np.searchsorted(self.frame_times_us, self.target_times_us)]


def texture(rng: np.random.Generator) -> np.ndarray:
    """A (TEXTURE_PX, TEXTURE_PX) grey texture, stretched to a drawn range inside [0.01, 1]."""
    if rng.uniform() < 0.6:
        drawn = images.describe_image(rng, [0.0, 1.0])
        pixels = images.image_texture(drawn, TEXTURE_PX)
        grey = pixels @ _LUMA if pixels.ndim == 3 else pixels
    else:
        grey = textures.texture_image(textures.describe_texture("noise", rng), TEXTURE_PX)
    lo, hi = float(grey.min()), float(grey.max())
    unit = (grey - lo) / (hi - lo) if hi > lo else np.zeros_like(grey)
    dark = rng.uniform(0.01, 0.3)
    bright = rng.uniform(0.5, 1.0)
    return dark + (bright - dark) * unit


def _affine_sample(
    image: np.ndarray, side_px: int, centre: np.ndarray, angle: float, scale: float
) -> np.ndarray:
    """The view (side_px square) of `image` seen through a rotation by `angle` and a zoom
    `scale` about the view's centre, the image's point `centre` at the view's centre."""
    offsets = np.arange(side_px) - (side_px - 1) / 2.0
    u, v = np.meshgrid(offsets, offsets)
    cos, sin = np.cos(angle) / scale, np.sin(angle) / scale
    x = centre[0] + cos * u - sin * v
    y = centre[1] + sin * u + cos * v
    return map_coordinates(image, [y, x], order=1, mode="mirror")


def sequence(
    rng: np.random.Generator, side_px: int, windows: int, window_us: int, frame_us: int
) -> Sequence:
    """One drawn sequence of `windows` windows, frames every `frame_us` from 0."""
    times = np.arange(0, windows * window_us + 1, frame_us, dtype=np.int64)
    t_s = times * 1e-6
    background = texture(rng)
    centre = rng.uniform(side_px, TEXTURE_PX - side_px, 2)
    if rng.uniform() < STILL_BACKGROUND_FRACTION:
        velocity, spin, zoom = np.zeros(2), 0.0, 0.0
    else:
        speed = np.exp(rng.uniform(*np.log(BACKGROUND_SPEED_PX_S)))
        heading = rng.uniform(0, 2 * np.pi)
        velocity = speed * np.array([np.cos(heading), np.sin(heading)])
        spin = rng.uniform(-ROTATION_RAD_S, ROTATION_RAD_S) * 0.2
        zoom = rng.uniform(-ZOOM_PER_S, ZOOM_PER_S)
    frames = np.stack(
        [
            _affine_sample(background, side_px, centre + velocity * t, spin * t, np.exp(zoom * t))
            for t in t_s
        ]
    )
    offsets = np.arange(side_px) - (side_px - 1) / 2.0
    u, v = np.meshgrid(offsets, offsets)
    for _ in range(int(rng.integers(OBJECTS[0], OBJECTS[1], endpoint=True))):
        frames = _with_object(rng, frames, t_s, side_px, u, v)
    return Sequence(frames.astype(np.float32), times, times[:: window_us // frame_us][1:])


def _with_object(
    rng: np.random.Generator,
    frames: np.ndarray,
    t_s: np.ndarray,
    side_px: int,
    u: np.ndarray,
    v: np.ndarray,
) -> np.ndarray:
    """A textured disc crossing the view: drawn start, heading, speed and spin; its edge
    anti-aliased over one pixel."""
    radius = rng.uniform(*OBJECT_RADIUS_FRACTION) * side_px
    patch = texture(rng)
    start = rng.uniform(-side_px / 2, side_px / 2, 2)
    speed = np.exp(rng.uniform(*np.log(OBJECT_SPEED_PX_S)))
    heading = rng.uniform(0, 2 * np.pi)
    velocity = speed * np.array([np.cos(heading), np.sin(heading)])
    spin = rng.uniform(-ROTATION_RAD_S, ROTATION_RAD_S)
    texture_centre = np.array([TEXTURE_PX / 2, TEXTURE_PX / 2])
    out = frames.copy()
    for k, t in enumerate(t_s):
        position = start + velocity * t
        du, dv = u - position[0], v - position[1]
        coverage = np.clip(radius + 0.5 - np.hypot(du, dv), 0.0, 1.0)
        if not coverage.any():
            continue
        angle = spin * t
        cos, sin = np.cos(angle), np.sin(angle)
        x = texture_centre[0] + cos * du - sin * dv
        y = texture_centre[1] + sin * du + cos * dv
        inside = map_coordinates(patch, [y, x], order=1, mode="mirror")
        out[k] = coverage * inside + (1.0 - coverage) * out[k]
    return out
