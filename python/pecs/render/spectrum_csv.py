"""Spectral tables on disk: two-column CSV (wavelength_nm, value) with `#` comments and a header."""

from __future__ import annotations

import os
from pathlib import Path

import numpy as np


def read_spectrum_csv(path: str | os.PathLike[str]) -> tuple[np.ndarray, np.ndarray]:
    """(wavelength_nm, value) from a two-column CSV with a header row and `#` comment lines."""
    file = Path(path)
    if not file.is_file():
        raise FileNotFoundError(f"spectrum file not found: {file}")
    rows: list[tuple[float, float]] = []
    header_seen = False
    for number, line in enumerate(file.read_text().splitlines(), start=1):
        text = line.split("#", 1)[0].strip()
        if not text:
            continue
        cells = [c.strip() for c in text.replace(";", ",").replace("\t", ",").split(",")]
        try:
            rows.append((float(cells[0]), float(cells[1])))
        except (ValueError, IndexError):
            if header_seen or rows:
                raise ValueError(
                    f"{file}:{number}: expected 'wavelength_nm,value', got {line!r}"
                ) from None
            header_seen = True
    if len(rows) < 2:
        raise ValueError(f"{file}: a spectrum needs at least two rows, found {len(rows)}")
    wavelength_nm, value = (np.array(c, dtype=np.float64) for c in zip(*rows, strict=True))
    if np.any(np.diff(wavelength_nm) <= 0):
        raise ValueError(f"{file}: wavelengths must increase strictly")
    if np.any(value < 0) or not np.all(np.isfinite(value)):
        raise ValueError(f"{file}: values must be finite and non-negative")
    return wavelength_nm, value
