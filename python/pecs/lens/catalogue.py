"""Optical glass catalogues: each maker's dispersion formula, by glass name.

The shipped table (pecs/scenes/glass/catalogue.json) holds the SCHOTT, OHARA, HOYA, CDGM, Sumita
and Hikari catalogues as the `opticalglass` package ships them (scripts/glass_catalogue.py
writes it): per glass the maker's formula and coefficients and the range they hold over, the
span of wavelengths at which the maker tabulates measured indices. Fused silica comes from
Malitson, "Interspecimen comparison of the refractive index of fused silica", JOSA 55, 1205
(1965), measured over 210-3710 nm. Indices are relative to air, as catalogues give them.

A name is looked up case-insensitively and without spaces ("S-TIM 5" is S-TIM5); a name in more
than one catalogue needs its maker: `SCHOTT:F5`.
"""

from __future__ import annotations

import difflib
import json
from collections.abc import Sequence
from dataclasses import dataclass
from functools import cache
from typing import Any

import numpy as np
from numpy.typing import ArrayLike

from pecs._data import scenes_dir

# Fraunhofer lines that define n_d and V_d (nm).
D_LINE_NM = 587.5618
F_LINE_NM = 486.1327
C_LINE_NM = 656.2725

MALITSON = "MALITSON"
# Old or generic names of glasses the catalogues list under another name.
ALIASES = {"SIO2": "FUSED-SILICA", "SILICA": "FUSED-SILICA", "BK7": "SCHOTT:N-BK7"}


@dataclass(frozen=True)
class CatalogueGlass:
    """One catalogue glass: n(lambda) by its maker's formula, lambda in µm:

    - "sellmeier" (SCHOTT, OHARA): n^2 = 1 + sum_i B_i L^2 / (L^2 - C_i), coefficients
      (B1, B2, B3, C1, C2, C3), C in µm^2;
    - "schott" (HOYA, CDGM, Sumita): n^2 = A0 + A1 L^2 + A2 L^-2 + A3 L^-4 + A4 L^-6 + A5 L^-8;
    - "hikari": n^2 = A0 + A1 L^2 + A2 L^4 + A3 L^-2 + A4 L^-4 + ... + A8 L^-12.
    """

    catalogue: str
    name: str
    formula: str
    coefficients: tuple[float, ...]
    range_nm: tuple[float, float]

    @property
    def spec(self) -> str:
        """The unambiguous name, as a prescription may write it: "SCHOTT:N-BK7"."""
        return f"{self.catalogue}:{self.name}"

    def n_squared(self, lam2_um2: Any) -> Any:
        """n^2 at lambda^2 (µm^2). Only + - * / on the argument, so that numpy arrays and Dr.Jit
        variables (the renderer's) go through the same formula."""
        c = self.coefficients
        if self.formula == "sellmeier":
            return (
                1.0
                + c[0] * lam2_um2 / (lam2_um2 - c[3])
                + c[1] * lam2_um2 / (lam2_um2 - c[4])
                + c[2] * lam2_um2 / (lam2_um2 - c[5])
            )
        inv = 1.0 / lam2_um2
        if self.formula == "schott":
            return c[0] + c[1] * lam2_um2 + inv * _horner(c[2:], inv)
        return c[0] + lam2_um2 * (c[1] + lam2_um2 * c[2]) + inv * _horner(c[3:], inv)

    def index(self, wavelength_nm: ArrayLike, clamp: bool = False) -> np.ndarray:
        """n at `wavelength_nm`. Outside the catalogue's range: a ValueError, or with `clamp`
        the index at the nearer end of the range (what the renderer does)."""
        lam = np.asarray(wavelength_nm, dtype=np.float64)
        lo, hi = self.range_nm
        if clamp:
            lam = np.clip(lam, lo, hi)
        elif lam.size and not (lam.min() >= lo and lam.max() <= hi):
            outside = lam[(lam < lo) | (lam > hi) | np.isnan(lam)].flat[0]
            raise ValueError(
                f"glass {self.spec} is defined over {lo:g}-{hi:g} nm (its catalogue's range), "
                f"not at {outside:g} nm"
            )
        return np.sqrt(self.n_squared((lam * 1e-3) ** 2))

    @property
    def n_d(self) -> float:
        """The index at the helium d line, 587.5618 nm."""
        return float(self.index(D_LINE_NM))

    @property
    def v_d(self) -> float:
        """The Abbe number (n_d - 1) / (n_F - n_C)."""
        n_d, n_f, n_c = self.index([D_LINE_NM, F_LINE_NM, C_LINE_NM])
        return float((n_d - 1.0) / (n_f - n_c))

    @property
    def glass_code(self) -> str:
        """The six-digit glass code: 1000 (n_d - 1) and 10 V_d, rounded (N-BK7: 517642)."""
        return f"{round(1000 * (self.n_d - 1)):03d}{round(10 * self.v_d):03d}"


def _horner(coefficients: Sequence[float], x: Any) -> Any:
    """c0 + c1 x + c2 x^2 + ..."""
    total: Any = coefficients[-1]
    for c in reversed(coefficients[:-1]):
        total = c + x * total
    return total


def _key(name: str) -> str:
    return name.upper().replace(" ", "")


@cache
def _glasses() -> dict[str, tuple[CatalogueGlass, ...]]:
    """Normalised name -> the glasses of that name (one per catalogue that lists it)."""
    with open(scenes_dir() / "glass" / "catalogue.json", encoding="utf-8") as f:
        table = json.load(f)
    found: dict[str, list[CatalogueGlass]] = {}
    for maker, entry in table["catalogues"].items():
        for row in entry["glasses"]:
            name = row["name"].replace(" ", "")
            glass = CatalogueGlass(
                maker, name, entry["formula"], tuple(row["coefficients"]), tuple(row["range_nm"])
            )
            found.setdefault(_key(name), []).append(glass)
    silica = CatalogueGlass(
        MALITSON,
        "FUSED-SILICA",
        "sellmeier",
        (0.6961663, 0.4079426, 0.8974794, 0.0684043**2, 0.1162414**2, 9.896161**2),
        (210.0, 3710.0),
    )
    found[_key(silica.name)] = [silica]
    return {k: tuple(v) for k, v in found.items()}


def catalogues() -> list[str]:
    """The catalogue names a glass may be prefixed with."""
    return sorted({g.catalogue for glasses in _glasses().values() for g in glasses})


def catalogue_names() -> list[str]:
    """Every glass, as "CATALOGUE:NAME"."""
    return sorted(g.spec for glasses in _glasses().values() for g in glasses)


def catalogue_glass(spec: str) -> CatalogueGlass:
    """The glass `spec` names: "N-BK7" or, with its catalogue, "SCHOTT:N-BK7" (any case)."""
    maker, _, name = spec.rpartition(":")
    alias = ALIASES.get(_key(name))
    if alias and not maker:
        maker, _, name = alias.rpartition(":")
    if maker and _key(maker) not in catalogues():
        raise ValueError(
            f"unknown glass catalogue {maker!r} in {spec!r}; catalogues: {', '.join(catalogues())}"
        )
    found = [g for g in _glasses().get(_key(name), ()) if not maker or g.catalogue == _key(maker)]
    if len(found) == 1:
        return found[0]
    if found:
        specs = " or ".join(g.spec for g in found)
        raise ValueError(f"glass {name} is in several catalogues; write {specs}")
    raise ValueError(f"unknown glass {spec!r}; {_close_matches(name, maker)}")


def _close_matches(name: str, maker: str) -> str:
    specs: dict[str, list[str]] = {}
    for key, glasses in _glasses().items():
        specs[key] = [g.spec for g in glasses if not maker or g.catalogue == _key(maker)]
    candidates = [key for key, found in specs.items() if found]
    close = difflib.get_close_matches(_key(name), candidates, n=5, cutoff=0.6)
    if not close:
        return f"no close match in {', '.join(catalogues())}"
    return "close matches: " + ", ".join(spec for key in close for spec in specs[key])
