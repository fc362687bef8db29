"""Catalogue glass (pecs.lens.catalogue): indices against the makers' formulas written here from
their definitions, with coefficients typed from data sheets or read from the `opticalglass`
package's copies of the catalogues, against the makers' tabulated indices, and against
refractiveindex.info (through optiland); name lookup, ranges and prescriptions. The tests against
opticalglass run where it is installed (`pip install opticalglass`, as scripts/glass_catalogue.py
needs it; not in the test extra, since it pulls in about 670 MB of Qt): elsewhere optiland's
copy checks every shipped glass to the same 1e-5."""

from __future__ import annotations

import re
import warnings
from functools import cache
from typing import Any

import numpy as np
import pytest
from pecs._data import scenes_dir
from pecs.lens import Glass, Lens, catalogue_glass
from pecs.lens.prescription import format_prescription, parse_prescription

WAVELENGTHS_NM = np.linspace(400.0, 700.0, 61)


def _shipped_glass_names() -> list[str]:
    """Every glass name in the glass column of the shipped prescriptions."""
    names = set()
    for path in sorted((scenes_dir() / "lenses").glob("*.lens")):
        for line in path.read_text().splitlines():
            fields = line.partition("#")[0].split()
            if len(fields) == 5 and re.match(r"[A-Za-z]", fields[4]) and fields[4] != "-":
                names.add(fields[4])
    return sorted(names)


SHIPPED = _shipped_glass_names()


def _in_range(spec: str) -> np.ndarray:
    """400-700 nm, where the catalogue defines the glass (some start at 404.7 nm)."""
    lo, hi = catalogue_glass(spec).range_nm
    return WAVELENGTHS_NM[(WAVELENGTHS_NM >= lo) & (WAVELENGTHS_NM <= hi)]


# The makers' formulas, written out from their definitions (lambda in µm).
def _sellmeier(c: list[float], lam_um: np.ndarray) -> np.ndarray:
    b1, b2, b3, c1, c2, c3 = c
    l2 = lam_um**2
    return np.sqrt(1 + b1 * l2 / (l2 - c1) + b2 * l2 / (l2 - c2) + b3 * l2 / (l2 - c3))


def _schott(c: list[float], lam_um: np.ndarray) -> np.ndarray:
    a0, a1, a2, a3, a4, a5 = c
    return np.sqrt(
        a0 + a1 * lam_um**2 + a2 * lam_um**-2 + a3 * lam_um**-4 + a4 * lam_um**-6 + a5 * lam_um**-8
    )


def _hikari(c: list[float], lam_um: np.ndarray) -> np.ndarray:
    n2 = c[0] + c[1] * lam_um**2 + c[2] * lam_um**4
    for k in range(1, 7):
        n2 = n2 + c[2 + k] * lam_um ** (-2 * k)
    return np.sqrt(n2)


MAKER_FORMULA = {
    "SCHOTT": _sellmeier,
    "OHARA": _sellmeier,
    "HOYA": _schott,
    "CDGM": _schott,
    "SUMITA": _schott,
    "HIKARI": _hikari,
}

# SCHOTT optical glass data sheets: Sellmeier B1, B2, B3, C1, C2, C3 (µm^2) as printed.
SCHOTT_DATASHEET = {
    "N-BK7": [1.03961212, 0.231792344, 1.01046945, 0.00600069867, 0.0200179144, 103.560653],
    "N-BAF10": [1.5851495, 0.143559385, 1.08521269, 0.00926681282, 0.0424489805, 105.613573],
    "N-SK16": [1.34317774, 0.241144399, 0.994317969, 0.00704687339, 0.0229005, 92.7508526],
    "N-SF5": [1.52481889, 0.187085527, 1.42729015, 0.011254756, 0.0588995392, 129.141675],
    "N-SF6": [1.77931763, 0.338149866, 2.08734474, 0.0133714182, 0.0617533621, 174.01759],
}


@pytest.mark.parametrize("name", sorted(SCHOTT_DATASHEET))
def test_schott_glasses_follow_the_data_sheet_sellmeier(name):
    lam = _in_range(name)
    expected = _sellmeier(SCHOTT_DATASHEET[name], lam * 1e-3)
    ours = Glass.named(name).index(lam)
    assert np.abs(ours - expected).max() < 1e-5


def test_n_bk7_d_line_and_abbe_number_as_the_data_sheet_prints():
    glass = catalogue_glass("N-BK7")
    assert glass.n_d == pytest.approx(1.5168, abs=5e-6)
    assert glass.v_d == pytest.approx(64.17, abs=5e-3)
    assert glass.glass_code == "517642"


# -- against the opticalglass package's copies of the catalogues -------------------------------


@cache
def _opticalglass(spec: str) -> Any:
    """The opticalglass glass object for `spec` (its spreadsheet name may hold a space)."""
    glassfactory = pytest.importorskip("opticalglass.glassfactory")
    maker, name = catalogue_glass(spec).spec.split(":")
    with warnings.catch_warnings():
        warnings.simplefilter("ignore")
        catalogue = glassfactory.get_glass_catalog(maker.capitalize() if maker != "CDGM" else maker)
        raw = next(
            n for n in catalogue.get_glass_names() if n.replace(" ", "").upper() == name.upper()
        )
        return catalogue, raw, catalogue.create_glass(raw, maker)


@pytest.mark.parametrize("spec", SHIPPED)
def test_shipped_glasses_follow_their_makers_formula_within_1e5(spec):
    catalogue, _, theirs = _opticalglass(spec)
    lam = _in_range(spec)
    coefficients = [float(v) for v in catalogue.glass_coefs(theirs.gname)]
    maker = catalogue_glass(spec).catalogue
    expected = MAKER_FORMULA[maker](coefficients, lam * 1e-3)
    ours = Glass.named(spec).index(lam)
    assert len(lam) > 50
    assert np.abs(ours - expected).max() < 1e-5
    assert np.abs(ours - theirs.calc_rindex(lam)).max() < 1e-9  # the library's own evaluation


@pytest.mark.parametrize("spec", SHIPPED)
def test_shipped_glasses_meet_the_makers_tabulated_indices(spec):
    # Measured indices the maker prints at the spectral lines in 400-700 nm, rounded to 5 or 6
    # decimals: the formula meets them within 1e-5 (HOYA FDS18 9.3e-6 is the furthest).
    catalogue, raw, _ = _opticalglass(spec)  # skips where opticalglass is not installed
    from opticalglass.spectral_lines import get_wavelength

    row = catalogue.df.loc[raw]["refractive indices"]
    pairs = []
    for key, value in row.items():
        try:
            lam, n = float(get_wavelength(key)), float(value)
        except (KeyError, TypeError, ValueError):
            continue
        if 400.0 <= lam <= 700.0 and np.isfinite(n):
            pairs.append((lam, n))
    lam, tabulated = np.array(pairs).T
    assert len(lam) >= 6
    assert np.abs(Glass.named(spec).index(lam) - tabulated).max() < 2e-5


@pytest.mark.parametrize("spec", SHIPPED)
def test_shipped_glasses_agree_with_refractiveindex_info(spec):
    # A third copy of the catalogues, refractiveindex.info's (the same editions).
    pytest.importorskip("optiland")
    from optiland.materials import Material

    maker, name = catalogue_glass(spec).spec.split(":")
    lam = _in_range(spec)
    with warnings.catch_warnings():
        warnings.simplefilter("ignore")
        theirs = np.ravel(Material(name, reference=maker).n(lam * 1e-3))
    assert np.abs(Glass.named(spec).index(lam) - theirs).max() < 1e-5


def test_fused_silica_is_malitson():
    lam_um = WAVELENGTHS_NM * 1e-3
    l2 = lam_um**2
    n = np.sqrt(
        1
        + 0.6961663 * l2 / (l2 - 0.0684043**2)
        + 0.4079426 * l2 / (l2 - 0.1162414**2)
        + 0.8974794 * l2 / (l2 - 9.896161**2)
    )
    assert np.abs(Glass.named("FUSED-SILICA").index(WAVELENGTHS_NM) - n).max() < 1e-12
    assert catalogue_glass("SiO2").n_d == pytest.approx(1.458464, abs=2e-6)  # Malitson's n_d


def test_hikari_formula_glass():
    # A catalogue with the nine-term Hikari formula: J-BK7A, an N-BK7 equivalent (517642).
    glass = catalogue_glass("J-BK7A")
    assert glass.formula == "hikari"
    assert glass.n_d == pytest.approx(1.5168, abs=1e-5)
    assert abs(glass.v_d - 64.17) < 0.1


# -- names -----------------------------------------------------------------------------------


def test_names_are_case_and_space_insensitive_with_an_optional_catalogue():
    assert catalogue_glass("n-bk7") == catalogue_glass("SCHOTT:N-BK7")
    assert catalogue_glass("S-LAH66").catalogue == "OHARA"
    assert catalogue_glass("ohara:s-tim 5") == catalogue_glass("S-TIM5")
    assert catalogue_glass("BK7").spec == "SCHOTT:N-BK7"  # the old name


def test_unknown_glass_names_close_matches():
    with pytest.raises(ValueError, match=r"unknown glass 'N-BK8'; close matches: .*SCHOTT:N-BK7"):
        catalogue_glass("N-BK8")
    with pytest.raises(ValueError, match="no close match"):
        catalogue_glass("QQQQQQQ")


def test_a_name_in_two_catalogues_needs_its_catalogue():
    with pytest.raises(ValueError, match="F5 is in several catalogues; write SCHOTT:F5 or CDGM:F5"):
        catalogue_glass("F5")
    assert catalogue_glass("CDGM:F5").formula == "schott"


def test_unknown_catalogue():
    with pytest.raises(ValueError, match="unknown glass catalogue 'ACME'.*SCHOTT"):
        catalogue_glass("ACME:N-BK7")


# -- wavelength range ------------------------------------------------------------------------


def test_outside_the_catalogue_range_is_refused_or_clamped():
    glass = Glass.named("HOYA:FDS18")  # tabulated 404.66-1529.6 nm
    lo, hi = glass.range_nm
    assert (lo, hi) == pytest.approx((404.6561, 1529.6))
    with pytest.raises(ValueError, match=r"HOYA:FDS18 is defined over 404.656-1529.6 nm .* 380 nm"):
        glass.index([500.0, 380.0])
    assert glass.index(380.0, clamp=True) == glass.index(lo)
    assert glass.index(1600.0, clamp=True) == glass.index(hi)
    with pytest.raises(ValueError, match="not at 380 nm"):
        Lens.builtin("pecs4").first_order(380.0)


def test_exit_pupil_bounds_clamp_across_the_render_band():
    # The renderer bounds the pupil over 360-830 nm; pecs4's FDS18 starts at 404.7 nm.
    lens = Lens.builtin("pecs4")
    clamped = lens.exit_pupil_bounds(1.0, (360.0, 830.0), bins=4, grid=16)
    at_ends = lens.exit_pupil_bounds(1.0, (404.6561, 830.0), bins=4, grid=16)
    np.testing.assert_array_equal(clamped.boxes_mm, at_ends.boxes_mm)


def test_renderer_index_is_the_same_formula_clamped():
    dr = pytest.importorskip("drjit")
    from pecs.lens.mitsuba_sensor import _dr_index

    lam = np.array([360.0, 404.6561, 550.0, 700.0, 1100.0])
    for spec in ("HOYA:FDS18", "HIKARI:J-BK7A", "CDGM:H-K9L", "SCHOTT:N-BK7"):
        glass = Glass.named(spec)
        theirs = np.array([float(_dr_index(glass, float(w), True, dr)) for w in lam])
        np.testing.assert_allclose(theirs, glass.index(lam, clamp=True), atol=1e-12)


# -- prescriptions ---------------------------------------------------------------------------


def test_prescription_n_d_must_match_the_named_glass():
    text = "0 1 0 5 -\n50 2 1.60 10 N-BK7\n-50 40 1 10 -\n"
    with pytest.raises(
        ValueError,
        match=r"surface 1: glass SCHOTT:N-BK7 has n_d = 1.51680, not the n_d column's 1.6",
    ):
        parse_prescription(text)


def test_prescription_catalogue_glass_round_trips():
    name, surfaces = parse_prescription("0 1 0 5 -\n50 2 1.517 10 SCHOTT:N-BK7\n-50 40 1 10 -\n")
    glass = surfaces[1].glass
    assert glass.kind == "catalogue" and glass.name == "SCHOTT:N-BK7"
    assert glass.n_d == pytest.approx(1.5168, abs=5e-6)  # the catalogue's, not the column's
    _, again = parse_prescription(format_prescription("x", surfaces))
    assert again == surfaces


def test_shipped_prescriptions_keep_cauchy_only_where_no_glass_matches():
    # telephoto250's 1.599 and wide22's 1.617 glasses have no catalogue glass (see their headers).
    abbe = {
        (name, s.glass.n_d)
        for name in Lens.builtin_names()
        for s in Lens.builtin(name).surfaces
        if s.glass.kind == "abbe"
    }
    assert abbe == {("telephoto250", 1.599), ("wide22", 1.617)}
    assert len(SHIPPED) == 20


def test_lens_info_lists_the_glasses(capsys):
    from pecs.cli import main

    assert main(["lens", "info", "telephoto250"]) == 0
    out = capsys.readouterr().out
    # N-PK51 on the SCHOTT data sheet: n_d 1.52855, V_d 76.98, tabulated 312.6-2325.4 nm.
    assert "SCHOTT:N-PK51  n_d 1.52855, V_d 76.98, 313-2325 nm" in out
    assert "n_d 1.599, V_d 46 (Cauchy fit)" in out
