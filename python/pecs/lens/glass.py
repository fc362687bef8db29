"""Optical glass: refractive index as a function of wavelength.

A glass is either a catalogue glass, named in a prescription (N-BK7, S-LAH66, SCHOTT:F5), whose
index is its maker's dispersion formula over the range the catalogue gives (catalogue.py), or a
glass known only by n_d and the Abbe number V_d, whose dispersion is modelled by the two-term
Cauchy formula fitted to n_d and to n_F - n_C = (n_d - 1) / V_d.
Indices are relative to air (as catalogues give them); air itself is taken as n = 1.
"""

from __future__ import annotations

from dataclasses import dataclass

import numpy as np
from numpy.typing import ArrayLike

from pecs.lens.catalogue import (
    C_LINE_NM,
    D_LINE_NM,
    F_LINE_NM,
    CatalogueGlass,
    catalogue_glass,
    catalogue_names,
)

__all__ = [
    "C_LINE_NM",
    "D_LINE_NM",
    "F_LINE_NM",
    "N_D_TOLERANCE",
    "CatalogueGlass",
    "Glass",
    "catalogue_glass",
    "catalogue_names",
]

# How far a prescription's n_d column may be from its named glass's n_d: sources round n_d to
# two or three decimals; further off, the name and the n_d describe different glasses.
N_D_TOLERANCE = 0.005


@dataclass(frozen=True)
class Glass:
    """A medium behind a lens surface.

    `kind` is "catalogue" (a named glass: its maker's formula, `catalogue` holds it; `n_d` is
    the catalogue's), "abbe" (Cauchy fit to n_d and V_d) or "constant" (no dispersion: no glass
    column given).
    """

    n_d: float
    name: str = ""
    v_d: float | None = None
    kind: str = "constant"
    catalogue: CatalogueGlass | None = None

    @staticmethod
    def from_column(n_d: float, column: str | None) -> Glass:
        """The glass for a prescription's n_d and its optional glass column (V_d or a name)."""
        if column is None or column.lower() in ("-", "air"):
            return Glass(n_d=n_d)
        try:
            v_d = float(column)
        except ValueError:
            return Glass.named(column, n_d)
        if not v_d > 0:
            raise ValueError(f"Abbe number V_d must be > 0, got {column}")
        return Glass(n_d=n_d, name=f"V_d={v_d:g}", v_d=v_d, kind="abbe")

    @staticmethod
    def named(spec: str, n_d: float | None = None) -> Glass:
        """The catalogue glass `spec` ("N-BK7", "SCHOTT:N-BK7"); `n_d`, where given (a
        prescription's column), must agree with the catalogue's within N_D_TOLERANCE."""
        glass = catalogue_glass(spec)
        own_n_d = glass.n_d
        if n_d is not None and abs(own_n_d - n_d) > N_D_TOLERANCE:
            raise ValueError(
                f"glass {glass.spec} has n_d = {own_n_d:.5f}, not the n_d column's {n_d:g} "
                f"(more than {N_D_TOLERANCE:g} apart: another glass?)"
            )
        return Glass(own_n_d, glass.spec, glass.v_d, "catalogue", glass)

    @property
    def range_nm(self) -> tuple[float, float] | None:
        """The wavelengths the index is defined over (a catalogue glass), else None (any)."""
        return None if self.catalogue is None else self.catalogue.range_nm

    def index(self, wavelength_nm: ArrayLike, clamp: bool = False) -> np.ndarray:
        """Refractive index at `wavelength_nm` (array-like). A catalogue glass refuses a
        wavelength outside its catalogue's range (ValueError), or with `clamp` holds the index
        of the range's nearer end there."""
        lam = np.asarray(wavelength_nm, dtype=np.float64)
        if self.catalogue is not None:
            return self.catalogue.index(lam, clamp)
        if self.kind == "abbe":
            a, b = self.cauchy_coefficients()
            return a + b / (lam * 1e-3) ** 2
        return np.full_like(lam, self.n_d)

    def cauchy_coefficients(self) -> tuple[float, float]:
        """(A, B µm^2) of n = A + B / lambda^2 through n_d with n_F - n_C = (n_d - 1) / V_d."""
        assert self.v_d is not None
        b_um2 = (self.n_d - 1.0) / self.v_d / ((F_LINE_NM * 1e-3) ** -2 - (C_LINE_NM * 1e-3) ** -2)
        return self.n_d - b_um2 / (D_LINE_NM * 1e-3) ** 2, b_um2

    @property
    def dispersive(self) -> bool:
        return self.kind != "constant"
