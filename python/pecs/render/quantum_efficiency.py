"""Sensor quantum efficiency QE(lambda) and the photo-electron response QE * lambda / (h c)."""

from __future__ import annotations

import os
from dataclasses import dataclass
from pathlib import Path

import numpy as np

from pecs._data import scenes_dir
from pecs.render.spectrum import photons_per_joule
from pecs.render.spectrum_csv import read_spectrum_csv

# Which shipped curve each sensor preset uses (sources in pecs/scenes/qe/README.md and each file).
PRESET_QE = {
    "davis346": "generic_silicon_fsi",
    "color_davis346": "generic_silicon_fsi",  # the silicon's; its filters are pecs/scenes/cfa
    "dvxplorer": "generic_silicon_fsi",
    "imx636": "generic_silicon_bsi",
    "ideal": "pecs_relative",
    "esim": "pecs_relative",
}


@dataclass(frozen=True)
class QuantumEfficiency:
    """A QE curve (fraction of photons that become photo-electrons) and where it comes from."""

    name: str
    wavelength_nm: np.ndarray
    qe: np.ndarray
    source: str

    def __call__(self, wavelength_nm: np.ndarray) -> np.ndarray:
        """QE at the given wavelengths, zero outside the tabulated range."""
        return np.interp(wavelength_nm, self.wavelength_nm, self.qe, left=0.0, right=0.0)

    def electrons_per_joule(self) -> np.ndarray:
        """Photo-electrons per joule of light at each tabulated wavelength: QE * lambda / (h c)."""
        return self.qe * photons_per_joule(self.wavelength_nm)


def load_qe(name_or_path: str | os.PathLike[str]) -> QuantumEfficiency:
    """A shipped curve by name (`generic_silicon_fsi`, ...) or a CSV file `wavelength_nm,qe`."""
    text = str(name_or_path)
    path = Path(text) if text.endswith(".csv") else scenes_dir() / "qe" / f"{text}.csv"
    if not path.is_file():
        shipped = sorted(p.stem for p in (scenes_dir() / "qe").glob("*.csv"))
        raise FileNotFoundError(f"QE curve {text!r} not found (shipped curves: {shipped})")
    wavelength_nm, qe = read_spectrum_csv(path)
    if np.any(qe > 1.0):
        raise ValueError(f"{path}: QE is a fraction of photons, values must lie in [0, 1]")
    source = " ".join(
        line.lstrip("# ").strip() for line in path.read_text().splitlines() if line.startswith("#")
    )
    return QuantumEfficiency(path.stem, wavelength_nm, qe, source)


def preset_qe(preset: str) -> QuantumEfficiency:
    """The QE curve a sensor preset uses."""
    if preset not in PRESET_QE:
        raise ValueError(f"no QE curve for sensor preset {preset!r}; known: {sorted(PRESET_QE)}")
    return load_qe(PRESET_QE[preset])
