"""Reflectance of a lens surface: bare Fresnel, or a single-layer anti-reflection coating.

A film of index n1 and thickness d between media n0 (incident side) and n2 reflects the
amplitude r = (r01 + r12 e^{i delta}) / (1 + r01 r12 e^{i delta}), delta = 4 pi n1 d cos(theta1)
/ lambda (Airy summation; Born & Wolf, Principles of Optics, section 1.6.4), with the Fresnel
coefficients r of each interface for s and p light; R = |r|^2, unpolarised light the mean of
the two. The default coating is Hullin et al.'s (SIGGRAPH 2011) quarter-wave layer: n1 =
max(sqrt(n0 n2), 1.38) (MgF2 where no lower-index film exists), d = lambda0 / (4 n1), lambda0 =
550 nm, which at normal incidence and lambda0 reflects ((n0 n2 - n1^2) / (n0 n2 + n1^2))^2.
A lossless film reflects the same from either side, so a ray coming back from the film side
sees the same coating.
"""

from __future__ import annotations

from dataclasses import dataclass
from typing import Any

import numpy as np
from numpy.typing import ArrayLike

MGF2_INDEX = 1.38  # magnesium fluoride, the lowest-index durable coating material
DESIGN_WAVELENGTH_NM = 550.0


@dataclass(frozen=True)
class Coating:
    """A single-layer coating: its design wavelength and film index (None: Hullin's rule,
    max(sqrt(n0 n2), 1.38), from the indices on both sides at the design wavelength)."""

    design_wavelength_nm: float = DESIGN_WAVELENGTH_NM
    film_index: float | None = None

    def __post_init__(self) -> None:
        if not self.design_wavelength_nm > 0:
            raise ValueError(
                f"coating design_wavelength_nm must be > 0, got {self.design_wavelength_nm}"
            )
        if self.film_index is not None and not self.film_index >= 1.0:
            raise ValueError(f"coating film_index must be >= 1, got {self.film_index}")

    def film(self, n0_design: float, n2_design: float) -> tuple[float, float]:
        """(film index, thickness nm) of the quarter-wave layer between n0 and n2 (their
        indices at the design wavelength)."""
        n1 = self.film_index
        if n1 is None:
            n1 = max(float(np.sqrt(n0_design * n2_design)), MGF2_INDEX)
        return n1, self.design_wavelength_nm / (4.0 * n1)


def _cos_in(n_from: ArrayLike, n_to: ArrayLike, cos_from: ArrayLike) -> np.ndarray:
    """Complex cosine of the refraction angle (Snell); imaginary past total internal reflection."""
    n_from, n_to, cos_from = (np.asarray(v, dtype=np.complex128) for v in (n_from, n_to, cos_from))
    sin2 = (n_from / n_to) ** 2 * (1.0 - cos_from**2)
    cos = np.sqrt(1.0 - sin2)
    return np.where(cos.imag < 0, -cos, cos)  # the evanescent branch that decays


def _fresnel_rs_rp(n_i: Any, n_t: Any, cos_i: Any, cos_t: Any) -> tuple[Any, Any]:
    """Amplitude reflection coefficients (s, p) of one interface (Hecht, Optics, eq. 4.42-4.43)."""
    rs = (n_i * cos_i - n_t * cos_t) / (n_i * cos_i + n_t * cos_t)
    rp = (n_t * cos_i - n_i * cos_t) / (n_t * cos_i + n_i * cos_t)
    return rs, rp


def fresnel_reflectance(
    n0: ArrayLike, n2: ArrayLike, cos_theta0: ArrayLike
) -> tuple[np.ndarray, np.ndarray]:
    """(R_s, R_p) of a bare interface from index n0 into n2 at incidence cos(theta0)."""
    n0c, n2c = np.asarray(n0, np.complex128), np.asarray(n2, np.complex128)
    cos0 = np.asarray(cos_theta0, np.complex128)
    rs, rp = _fresnel_rs_rp(n0c, n2c, cos0, _cos_in(n0c, n2c, cos0))
    return np.abs(rs) ** 2, np.abs(rp) ** 2


def film_reflectance(
    n0: ArrayLike,
    n1: ArrayLike,
    n2: ArrayLike,
    thickness_nm: ArrayLike,
    wavelength_nm: ArrayLike,
    cos_theta0: ArrayLike,
) -> tuple[np.ndarray, np.ndarray]:
    """(R_s, R_p) of a single film n1 of `thickness_nm` between n0 (incident) and n2 (Airy sum).

    Every argument broadcasts; thickness 0 gives the bare interface n0 | n2. Where neither
    the film nor n2 totally reflects, the coefficients are real and |r|^2 = (r01^2 + r12^2 +
    2 r01 r12 cos delta) / (1 + r01^2 r12^2 + 2 r01 r12 cos delta), computed in real numbers
    (a ghost traces this at every surface); elsewhere in complex ones."""
    arrays = np.broadcast_arrays(
        *(np.asarray(v, np.float64) for v in (n0, n1, n2, thickness_nm, wavelength_nm, cos_theta0))
    )
    n0r, n1r, n2r, d, lam, c0 = arrays
    sin2_0 = np.maximum(0.0, 1.0 - c0 * c0)
    s1, s2 = (n0r / n1r) ** 2 * sin2_0, (n0r / n2r) ** 2 * sin2_0
    real = (s1 < 1.0) & (s2 < 1.0)
    c1, c2 = np.sqrt(np.maximum(0.0, 1.0 - s1)), np.sqrt(np.maximum(0.0, 1.0 - s2))
    cos_delta = np.cos(4.0 * np.pi * n1r * d * c1 / lam)
    out = []
    with np.errstate(divide="ignore", invalid="ignore"):  # grazing or TIR: redone below
        coefficients = _fresnel_rs_rp(n0r, n1r, c0, c1), _fresnel_rs_rp(n1r, n2r, c1, c2)
        for r01, r12 in zip(*coefficients, strict=True):
            cross = 2.0 * r01 * r12 * cos_delta
            out.append((r01 * r01 + r12 * r12 + cross) / (1.0 + (r01 * r12) ** 2 + cross))
    if not real.all():
        rs, rp = _film_reflectance_complex(*(a[~real] for a in (n0r, n1r, n2r, d, lam, c0)))
        out[0][~real], out[1][~real] = rs, rp
    return out[0], out[1]


def _film_reflectance_complex(
    n0: np.ndarray,
    n1: np.ndarray,
    n2: np.ndarray,
    thickness_nm: np.ndarray,
    wavelength_nm: np.ndarray,
    cos_theta0: np.ndarray,
) -> tuple[np.ndarray, np.ndarray]:
    """The Airy sum in complex numbers (evanescent waves past total internal reflection)."""
    n0c, n1c, n2c = (np.asarray(v, np.complex128) for v in (n0, n1, n2))
    cos0 = np.asarray(cos_theta0, np.complex128)
    cos1 = _cos_in(n0c, n1c, cos0)
    cos2 = _cos_in(n0c, n2c, cos0)
    delta = 4.0 * np.pi * n1c * np.asarray(thickness_nm) * cos1 / np.asarray(wavelength_nm)
    phase = np.exp(1j * delta)
    out = []
    for r01, r12 in zip(
        _fresnel_rs_rp(n0c, n1c, cos0, cos1), _fresnel_rs_rp(n1c, n2c, cos1, cos2), strict=True
    ):
        r = (r01 + r12 * phase) / (1.0 + r01 * r12 * phase)
        out.append(np.abs(r) ** 2)
    return out[0], out[1]


def reflectance(
    n0: ArrayLike,
    n2: ArrayLike,
    cos_theta0: ArrayLike,
    wavelength_nm: ArrayLike,
    film_index: ArrayLike = 1.0,
    thickness_nm: ArrayLike = 0.0,
) -> np.ndarray:
    """Unpolarised reflectance (mean of s and p) of a surface from n0 into n2, coated with a
    film (index, thickness) or bare (thickness 0)."""
    rs, rp = film_reflectance(n0, film_index, n2, thickness_nm, wavelength_nm, cos_theta0)
    return 0.5 * (rs + rp)


def coating_from_value(value: object, where: str) -> Coating | None:
    """A coating from a scene file or API value: "quarter_wave" (the default layer), "none",
    or a table {design_wavelength_nm = ..., film_index = ...}; errors name `where`."""
    if value is None or value == "none":
        return None
    if value == "quarter_wave":
        return Coating()
    if isinstance(value, Coating):
        return value
    if isinstance(value, dict):
        unknown = set(value) - {"design_wavelength_nm", "film_index"}
        if unknown:
            raise ValueError(
                f"{where}: unknown coating key(s) {sorted(unknown)}; known: "
                "design_wavelength_nm, film_index"
            )
        try:
            return Coating(
                float(value.get("design_wavelength_nm", DESIGN_WAVELENGTH_NM)),
                None if value.get("film_index") is None else float(value["film_index"]),
            )
        except (TypeError, ValueError) as error:
            raise ValueError(f"{where}: {error}") from None
    raise ValueError(
        f'{where}: a coating is "quarter_wave", "none" or a table '
        f"{{design_wavelength_nm, film_index}}, got {value!r}"
    )
