"""Spectra of light: Planck's blackbody law, photometric weighting, and Mitsuba spectrum values."""

from __future__ import annotations

from functools import cache

import numpy as np

from pecs._data import scenes_dir
from pecs.render.spectrum_csv import read_spectrum_csv

H_PLANCK_J_S = 6.62607015e-34
C_LIGHT_M_S = 299792458.0
K_BOLTZMANN_J_K = 1.380649e-23
Q_ELECTRON_C = 1.602176634e-19
LUMINOUS_EFFICACY_LM_W = 683.0  # peak of the photopic curve, by the definition of the candela

# Wavelengths rendered: the visible range and the near infrared silicon still absorbs.
WAVELENGTH_MIN_NM = 360.0
WAVELENGTH_MAX_NM = 1100.0


def planck_radiance(wavelength_nm: np.ndarray, temperature_k: float) -> np.ndarray:
    """Planck: L(lambda, T) = 2 h c^2 / lambda^5 / (exp(h c / (lambda k T)) - 1), in W/(m^2 sr nm)."""
    wavelength_m = np.asarray(wavelength_nm, dtype=np.float64) * 1e-9
    exponent = H_PLANCK_J_S * C_LIGHT_M_S / (wavelength_m * K_BOLTZMANN_J_K * temperature_k)
    per_m = 2.0 * H_PLANCK_J_S * C_LIGHT_M_S**2 / wavelength_m**5 / np.expm1(exponent)
    return per_m * 1e-9


def photons_per_joule(wavelength_nm: np.ndarray) -> np.ndarray:
    """Photon count per joule at each wavelength: lambda / (h c)."""
    return np.asarray(wavelength_nm, dtype=np.float64) * 1e-9 / (H_PLANCK_J_S * C_LIGHT_M_S)


@cache
def photopic() -> tuple[np.ndarray, np.ndarray]:
    """CIE 1924 photopic luminous efficiency V(lambda) (shipped table, 380-780 nm)."""
    return read_spectrum_csv(scenes_dir() / "spectra" / "cie1924_photopic.csv")


def luminous(wavelength_nm: np.ndarray, spectral_power: np.ndarray) -> float:
    """Photometric value: 683 lm/W * integral of V(lambda) * spectral power (trapezoid rule)."""
    v_wavelength_nm, v = photopic()
    grid = np.arange(v_wavelength_nm[0], v_wavelength_nm[-1] + 0.5, 1.0)
    power = np.interp(grid, wavelength_nm, spectral_power, left=0.0, right=0.0)
    return LUMINOUS_EFFICACY_LM_W * integrate(np.interp(grid, v_wavelength_nm, v) * power, grid)


def integrate(value: np.ndarray, wavelength_nm: np.ndarray) -> float:
    """Trapezoid rule over wavelength (numpy 1 and 2 spell it differently)."""
    value = np.asarray(value, dtype=np.float64)
    return float(np.sum(0.5 * (value[1:] + value[:-1]) * np.diff(wavelength_nm)))


def mitsuba_spectrum_string(wavelength_nm: np.ndarray, value: np.ndarray) -> str:
    """A spectrum in Mitsuba's XML notation 'lambda:value, ...'."""
    return ", ".join(f"{w:.6g}:{v:.9g}" for w, v in zip(wavelength_nm, value, strict=True))
