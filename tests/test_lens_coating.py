"""Coating reflectance against closed forms and a characteristic-matrix computation."""

from __future__ import annotations

import numpy as np
import pytest
from pecs.lens.coating import (
    Coating,
    coating_from_value,
    film_reflectance,
    fresnel_reflectance,
    reflectance,
)


def _characteristic_matrix_reflectance(
    n0: float, n1: float, n2: float, d_nm: float, lam_nm: float, theta0: float, pol: str
) -> float:
    """Macleod, Thin-Film Optical Filters, ch. 2: [B, C] = M [1, eta2], r = (eta0 B - C) /
    (eta0 B + C), M = [[cos b, i sin b / eta1], [i eta1 sin b, cos b]], b = 2 pi n1 d cos1 / lam,
    tilted admittance eta = n cos (s) or n / cos (p)."""
    sin0 = np.sin(theta0)
    cos = [np.sqrt(complex(1 - (n0 * sin0 / n) ** 2)) for n in (n0, n1, n2)]
    eta = [n * c if pol == "s" else n / c for n, c in zip((n0, n1, n2), cos, strict=True)]
    b = 2 * np.pi * n1 * d_nm * cos[1] / lam_nm
    m = np.array([[np.cos(b), 1j * np.sin(b) / eta[1]], [1j * eta[1] * np.sin(b), np.cos(b)]])
    big_b, big_c = m @ np.array([1.0, eta[2]])
    r = (eta[0] * big_b - big_c) / (eta[0] * big_b + big_c)
    return float(abs(r) ** 2)


def test_quarter_wave_at_design_wavelength_matches_closed_form() -> None:
    n0, n2 = 1.0, 1.67
    n1, d = Coating().film(n0, n2)
    assert n1 == pytest.approx(1.38) and d == pytest.approx(550 / 4 / 1.38)
    rs, rp = film_reflectance(n0, n1, n2, d, 550.0, 1.0)
    expected = ((n0 * n2 - n1**2) / (n0 * n2 + n1**2)) ** 2
    assert rs == pytest.approx(expected, rel=1e-12) and rp == pytest.approx(expected, rel=1e-12)
    # sqrt(n0 n2) above 1.38: the ideal film, zero reflection at lambda0.
    n1, d = Coating().film(1.5, 1.9)
    assert n1 == pytest.approx(np.sqrt(1.5 * 1.9))
    assert reflectance(1.5, 1.9, 1.0, 550.0, n1, d) == pytest.approx(0.0, abs=1e-15)


def test_bare_interface_normal_incidence_and_brewster() -> None:
    for n1, n2 in ((1.0, 1.5), (1.7, 1.0), (1.5, 1.62)):
        rs, rp = fresnel_reflectance(n1, n2, 1.0)
        expected = ((n1 - n2) / (n1 + n2)) ** 2
        assert rs == pytest.approx(expected) and rp == pytest.approx(expected)
        assert reflectance(n1, n2, 1.0, 600.0) == pytest.approx(expected)
    theta_b = np.arctan(1.5 / 1.0)
    rs, rp = fresnel_reflectance(1.0, 1.5, np.cos(theta_b))
    assert rp == pytest.approx(0.0, abs=1e-20) and rs > 0.1
    # Beyond the critical angle (glass to air) everything is reflected.
    rs, rp = fresnel_reflectance(1.5, 1.0, np.cos(np.radians(50)))
    assert rs == pytest.approx(1.0) and rp == pytest.approx(1.0)


@pytest.mark.parametrize("theta_deg", [0.0, 20.0, 45.0, 70.0])
@pytest.mark.parametrize("lam_nm", [420.0, 550.0, 700.0, 950.0])
def test_film_matches_characteristic_matrix(theta_deg: float, lam_nm: float) -> None:
    n0, n2 = 1.0, 1.717
    n1, d = Coating(design_wavelength_nm=550.0).film(n0, n2)
    theta = np.radians(theta_deg)
    rs, rp = film_reflectance(n0, n1, n2, d, lam_nm, np.cos(theta))
    assert rs == pytest.approx(
        _characteristic_matrix_reflectance(n0, n1, n2, d, lam_nm, theta, "s"), rel=1e-9, abs=1e-15
    )
    assert rp == pytest.approx(
        _characteristic_matrix_reflectance(n0, n1, n2, d, lam_nm, theta, "p"), rel=1e-9, abs=1e-15
    )
    # From the glass side (a ray coming back through the lens): same film, n0 and n2 swapped.
    theta_g = np.arcsin(np.sin(theta) / n2)
    rs_back, _ = film_reflectance(n2, n1, n0, d, lam_nm, np.cos(theta_g))
    assert rs_back == pytest.approx(rs, rel=1e-9, abs=1e-15)


def test_coating_lowers_reflectance_across_the_visible() -> None:
    lam = np.linspace(420, 700, 15)
    n1, d = Coating().film(1.0, 1.6)
    coated = reflectance(1.0, 1.6, 1.0, lam, n1, d)
    bare = reflectance(1.0, 1.6, 1.0, lam)
    assert np.all(coated < bare) and coated.min() < 0.015


def test_coating_values() -> None:
    assert coating_from_value("none", "x") is None
    assert coating_from_value("quarter_wave", "x") == Coating()
    assert coating_from_value({"design_wavelength_nm": 500}, "x") == Coating(500.0)
    with pytest.raises(ValueError, match="optics.coating"):
        coating_from_value("thick", "optics.coating")
    with pytest.raises(ValueError, match="unknown coating key"):
        coating_from_value({"index": 1.4}, "optics.coating")
    with pytest.raises(ValueError, match="film_index"):
        Coating(film_index=0.5)
