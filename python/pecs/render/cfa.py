"""Colour filter arrays (CFA): which filter covers each pixel, what each filter transmits, and the
mosaic that gives every pixel its own channel.

A colour event camera (Color-DAVIS346) is a DVS whose pixels sit under a 2 x 2 filter pattern;
its events are ordinary events and the colour of each is given by its pixel's position. pecs
names the patterns as libcaer does (`caer_frame_event_color_filter`): the four letters read
clockwise from the top-left pixel of each 2 x 2 cell, (x, y) = (0, 0), (1, 0), (1, 1), (0, 1).
So "RGBG" (the Color-DAVIS346's Bayer pattern) has R at even x and even y, B at odd x and odd y,
as E2VID's colour mode and ESIM's `simulate_color_events` split it; the RGBW patterns put a clear
(white) pixel where RGBG has its second green.

Physically each pixel's photocurrent is integral L(lambda) T_c(lambda) QE(lambda) lambda / (h c)
d lambda with T_c its filter's transmission: the renderer weights radiance by one such response
per channel and keeps, at each pixel, its own channel (`mosaic`).
"""

from __future__ import annotations

import os
from dataclasses import dataclass
from pathlib import Path

import numpy as np

from pecs._data import scenes_dir
from pecs.render.spectrum_csv import read_spectrum_csv

#: Channels a pattern may use: red, green, blue, and white (a clear pixel, no colour filter).
CHANNELS = ("R", "G", "B", "W")
#: libcaer's colour-filter patterns (clockwise from the top-left pixel of each 2 x 2 cell).
PATTERNS = ("RGBG", "GRGB", "GBGR", "BGRG", "RGBW", "GRWB", "WBGR", "BWRG")
#: The shipped (assumed, generic) transmission curve of each channel: pecs/scenes/cfa.
_SHIPPED_FILTERS = {
    "R": "generic_red",
    "G": "generic_green",
    "B": "generic_blue",
    "W": "generic_white",
}
#: (x, y) offsets inside the 2 x 2 cell of the pattern's four letters, in reading order.
_CELL_XY = ((0, 0), (1, 0), (1, 1), (0, 1))
#: Display colour (8-bit RGB) of each channel's events (`pecs view`).
CHANNEL_COLOURS_RGB = {
    "R": (230, 40, 40),
    "G": (40, 200, 60),
    "B": (50, 90, 240),
    "W": (235, 235, 235),
}


@dataclass(frozen=True)
class FilterCurve:
    """One colour filter's transmission (fraction, 0..1) and where the curve comes from."""

    channel: str
    wavelength_nm: np.ndarray
    transmission: np.ndarray
    source: str

    def __call__(self, wavelength_nm: np.ndarray) -> np.ndarray:
        """Transmission at the given wavelengths, zero outside the tabulated range."""
        return np.interp(wavelength_nm, self.wavelength_nm, self.transmission, left=0.0, right=0.0)


@dataclass(frozen=True)
class ColourFilterArray:
    """A 2 x 2 colour filter pattern (libcaer's name) and the transmission of each channel in it."""

    pattern: str
    filters: dict[str, FilterCurve]

    @property
    def channels(self) -> tuple[str, ...]:
        """The distinct channels of the pattern, in CHANNELS order (R, G, B, W): the order of
        the film's channels and of `channel_index`."""
        return tuple(c for c in CHANNELS if c in self.pattern)

    def cell(self) -> np.ndarray:
        """The 2 x 2 cell as channel letters indexed [y, x]."""
        cell = np.empty((2, 2), dtype="<U1")
        for letter, (x, y) in zip(self.pattern, _CELL_XY, strict=True):
            cell[y, x] = letter
        return cell

    def channel_index(self, width: int, height: int) -> np.ndarray:
        """Index into `channels` of each pixel's filter, uint8 (height, width)."""
        lookup = {c: k for k, c in enumerate(self.channels)}
        cell = np.vectorize(lookup.__getitem__, otypes=[np.uint8])(self.cell())
        return np.tile(cell, ((height + 1) // 2, (width + 1) // 2))[:height, :width]

    def channel_of(self, x: np.ndarray, y: np.ndarray) -> np.ndarray:
        """Index into `channels` of the filter over pixels (x, y): the colour of events there."""
        index = self.channel_index(2, 2)
        return index[np.asarray(y, dtype=np.int64) % 2, np.asarray(x, dtype=np.int64) % 2]

    def mosaic(self, channel_images: np.ndarray) -> np.ndarray:
        """One value per pixel from (height, width, channels) images, one per channel of
        `channels`: each pixel keeps its own filter's."""
        height, width, count = channel_images.shape
        if count != len(self.channels):
            raise ValueError(
                f"{count} channel images for the {len(self.channels)} channels "
                f"{''.join(self.channels)} of the {self.pattern} pattern"
            )
        index = self.channel_index(width, height)[..., None].astype(np.intp)
        return np.take_along_axis(channel_images, index, axis=2)[..., 0]

    def mosaic_rgb(self, linear_rgb: np.ndarray) -> np.ndarray:
        """A linear RGB image (height, width, 3) through the pattern, float32 (height, width):
        R, G and B pixels take their channel of the image, as ESIM's colour mode does; a white
        (clear) pixel takes the Rec. 709 luminance, the value a grey frame gives every pixel."""
        rgb = np.asarray(linear_rgb, dtype=np.float32)[..., :3]
        luminance = rgb @ np.array([0.2126, 0.7152, 0.0722], np.float32)
        planes = {"R": rgb[..., 0], "G": rgb[..., 1], "B": rgb[..., 2], "W": luminance}
        return self.mosaic(np.stack([planes[c] for c in self.channels], axis=-1))


def load_cfa(
    pattern: str, filters_folder: str | os.PathLike[str] | None = None
) -> ColourFilterArray:
    """The pattern (libcaer's name, e.g. "RGBG") with the shipped generic (assumed) filter curves,
    or with the curves `R.csv`, `G.csv`, `B.csv`, `W.csv` (`wavelength_nm,transmission`) of
    `filters_folder`, e.g. a measurement of a real sensor's filters."""
    name = str(pattern).upper()
    if name not in PATTERNS:
        raise ValueError(
            f"cfa: unknown colour filter pattern {pattern!r}; choose one of {', '.join(PATTERNS)}"
        )
    files = {
        c: (
            Path(filters_folder) / f"{c}.csv"
            if filters_folder is not None
            else scenes_dir() / "cfa" / f"{_SHIPPED_FILTERS[c]}.csv"
        )
        for c in CHANNELS
        if c in name
    }
    return ColourFilterArray(name, {c: _read_filter(c, path) for c, path in files.items()})


def _read_filter(channel: str, path: Path) -> FilterCurve:
    if not path.is_file():
        raise FileNotFoundError(f"cfa: no transmission curve for channel {channel}: {path}")
    wavelength_nm, transmission = read_spectrum_csv(path)
    if np.any(transmission > 1.0):
        raise ValueError(f"{path}: a filter transmits a fraction of light, values must be <= 1")
    source = " ".join(
        line.lstrip("# ").strip() for line in path.read_text().splitlines() if line.startswith("#")
    )
    return FilterCurve(channel, wavelength_nm, transmission, source)
