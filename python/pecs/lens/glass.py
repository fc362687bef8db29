"""Optical glass: refractive index as a function of wavelength.

A glass is either a catalogue glass with Sellmeier coefficients (the equation the makers publish),
or a glass known only by n_d and the Abbe number V_d, whose dispersion is modelled by the
two-term Cauchy formula fitted to n_d and to n_F - n_C = (n_d - 1) / V_d.
Indices are relative to air (as catalogues give them); air itself is taken as n = 1.
"""

from __future__ import annotations

from dataclasses import dataclass

import numpy as np
from numpy.typing import ArrayLike

# Fraunhofer lines used to define n_d and V_d (nm).
D_LINE_NM = 587.5618
F_LINE_NM = 486.1327
C_LINE_NM = 656.2725


@dataclass(frozen=True)
class Sellmeier:
    """n^2(lambda) = 1 + sum_i B_i lambda^2 / (lambda^2 - C_i), lambda in µm, C_i in µm^2."""

    b: tuple[float, float, float]
    c_um2: tuple[float, float, float]
    source: str

    def index(self, wavelength_nm: ArrayLike) -> np.ndarray:
        lam2_um2 = (np.asarray(wavelength_nm, dtype=np.float64) * 1e-3) ** 2
        n2 = 1.0 + sum(
            b * lam2_um2 / (lam2_um2 - c) for b, c in zip(self.b, self.c_um2, strict=False)
        )
        return np.sqrt(n2)


# Catalogue. SCHOTT optical glass data sheets (SCHOTT AG, "Optical Glass - Data Sheets"), and
# I. H. Malitson, "Interspecimen comparison of the refractive index of fused silica", JOSA 55,
# 1205 (1965) for fused silica.
_SCHOTT = "SCHOTT optical glass data sheet"
CATALOGUE: dict[str, Sellmeier] = {
    "N-BK7": Sellmeier(
        (1.03961212, 0.231792344, 1.01046945), (0.00600069867, 0.0200179144, 103.560653), _SCHOTT
    ),
    "N-SF11": Sellmeier(
        (1.73759695, 0.313747346, 1.89878101), (0.013188707, 0.0623068142, 155.23629), _SCHOTT
    ),
    "F2": Sellmeier(
        (1.34533359, 0.209073176, 0.937357162), (0.00997743871, 0.0470450767, 111.886764), _SCHOTT
    ),
    "N-LAK9": Sellmeier(
        (1.46231905, 0.344399589, 1.15508372), (0.00724270156, 0.0243353131, 85.4686868), _SCHOTT
    ),
    "N-BAF10": Sellmeier(
        (1.5851495, 0.143559385, 1.08521269), (0.00926681282, 0.0424489805, 105.613573), _SCHOTT
    ),
    "N-SF5": Sellmeier(
        (1.52481889, 0.187085527, 1.42729015), (0.011254756, 0.0588995392, 129.141675), _SCHOTT
    ),
    "N-SF6": Sellmeier(
        (1.77931763, 0.338149866, 2.08734474), (0.0133714182, 0.0617533621, 174.01759), _SCHOTT
    ),
    "N-SK16": Sellmeier(
        (1.34317774, 0.241144399, 0.994317969), (0.00704687339, 0.0229005, 92.7508526), _SCHOTT
    ),
    "FUSED-SILICA": Sellmeier(
        (0.6961663, 0.4079426, 0.8974794),
        (0.0684043**2, 0.1162414**2, 9.896161**2),
        "Malitson, JOSA 55, 1205 (1965)",
    ),
}
_ALIASES = {"SIO2": "FUSED-SILICA", "SILICA": "FUSED-SILICA", "BK7": "N-BK7"}


def catalogue_glass(name: str) -> Sellmeier:
    """The Sellmeier glass called `name` (case-insensitive)."""
    key = name.upper()
    key = _ALIASES.get(key, key)
    if key not in CATALOGUE:
        raise ValueError(f"unknown glass {name!r}; known: {', '.join(sorted(CATALOGUE))}")
    return CATALOGUE[key]


@dataclass(frozen=True)
class Glass:
    """A medium behind a lens surface: n(lambda) with the prescription's n_d at the d line.

    `kind` is "sellmeier" (a catalogue glass; its dispersion is kept and its index shifted by
    the small difference between the prescription's n_d and the catalogue's), "abbe" (Cauchy
    fit to n_d and V_d) or "constant" (no dispersion: no glass column given).
    """

    n_d: float
    name: str = ""
    v_d: float | None = None
    kind: str = "constant"

    @staticmethod
    def from_column(n_d: float, column: str | None) -> Glass:
        """The glass for a prescription's n_d and its optional glass column (V_d or a name)."""
        if column is None or column.lower() in ("-", "air"):
            return Glass(n_d=n_d)
        try:
            v_d = float(column)
        except ValueError:
            sellmeier = catalogue_glass(column)
            own_n_d = float(sellmeier.index(D_LINE_NM))
            if abs(own_n_d - n_d) > 0.01:
                raise ValueError(
                    f"glass {column} has n_d = {own_n_d:.4f}, too far from the prescription's "
                    f"n_d = {n_d:.4f}"
                ) from None
            return Glass(
                n_d=n_d, name=column.upper(), v_d=abbe_number(sellmeier.index), kind="sellmeier"
            )
        if not v_d > 0:
            raise ValueError(f"Abbe number V_d must be > 0, got {column}")
        return Glass(n_d=n_d, name=f"V_d={v_d:g}", v_d=v_d, kind="abbe")

    def index(self, wavelength_nm: ArrayLike) -> np.ndarray:
        """Refractive index at `wavelength_nm` (array-like)."""
        lam = np.asarray(wavelength_nm, dtype=np.float64)
        if self.kind == "sellmeier":
            sellmeier = catalogue_glass(self.name)
            return self.n_d + sellmeier.index(lam) - sellmeier.index(D_LINE_NM)
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


def abbe_number(index: object) -> float:
    """V_d = (n_d - 1) / (n_F - n_C) of an index function of wavelength in nm."""
    n_d, n_f, n_c = (float(index(w)) for w in (D_LINE_NM, F_LINE_NM, C_LINE_NM))  # type: ignore[operator]
    return (n_d - 1.0) / (n_f - n_c)
