"""Write pecs's glass table (python/pecs/scenes/glass/catalogue.json) from the makers' catalogues
that the `opticalglass` package ships (SCHOTT, OHARA, HOYA, CDGM, Hikari, Sumita spreadsheets).

    pip install opticalglass && python scripts/glass_catalogue.py python/pecs/scenes/glass/catalogue.json

pecs reads the table it writes and does not need opticalglass (which pulls in Qt and pandas) at
run time. Per glass: the maker's dispersion formula and coefficients as the catalogue gives them,
n_d and V_d, and the valid range: the span of wavelengths at which the maker tabulates measured
indices, the range the coefficients were fitted over. The script refuses to write a glass whose
formula misses one of its tabulated indices by more than TOLERANCE.
"""

from __future__ import annotations

import json
import math
import sys
import warnings
from importlib.metadata import version
from typing import Any

import numpy as np

# The makers' formulas (lambda in µm), as opticalglass evaluates each catalogue.
FORMULA = {
    "SCHOTT": "sellmeier",
    "OHARA": "sellmeier",
    "HOYA": "schott",
    "CDGM": "schott",
    "Sumita": "schott",
    "Hikari": "hikari",
}
# Catalogue indices are printed to 5 or 6 decimals and the makers' fits miss their own tables by
# up to 8e-5 (CDGM H-ZF88, Sumita K-LaSFn21); further off means a misread spreadsheet column.
TOLERANCE = 1e-4


def index(formula: str, coefficients: list[float], wavelength_nm: np.ndarray) -> np.ndarray:
    """n(lambda) by the maker's formula (the same equations as pecs.lens.catalogue)."""
    lam2 = (np.asarray(wavelength_nm, dtype=np.float64) * 1e-3) ** 2
    c = coefficients
    if formula == "sellmeier":
        n2 = 1.0 + sum(b * lam2 / (lam2 - cc) for b, cc in zip(c[:3], c[3:], strict=True))
    elif formula == "schott":
        n2 = c[0] + c[1] * lam2 + sum(a * lam2 ** -(k + 1) for k, a in enumerate(c[2:]))
    else:  # hikari
        n2 = c[0] + c[1] * lam2 + c[2] * lam2**2
        n2 = n2 + sum(a * lam2 ** -(k + 1) for k, a in enumerate(c[3:]))
    return np.sqrt(n2)


def tabulated(row: Any) -> tuple[np.ndarray, np.ndarray]:
    """(wavelengths nm, indices) the catalogue tabulates for one glass (empty cells dropped)."""
    from opticalglass.spectral_lines import get_wavelength

    wavelengths, indices = [], []
    for key, value in row["refractive indices"].items():
        try:
            lam, n = float(get_wavelength(key)), float(value)
        except (KeyError, TypeError, ValueError):
            continue
        if math.isfinite(n) and n > 1.0:
            wavelengths.append(lam)
            indices.append(n)
    return np.array(wavelengths), np.array(indices)


def catalogue_rows(maker: str) -> list[dict[str, Any]]:
    from opticalglass import glassfactory

    catalogue = glassfactory.get_glass_catalog(maker)
    rows = []
    for name in catalogue.get_glass_names():
        if not isinstance(name, str) or not name.strip():
            continue
        try:
            coefficients = [float(v) for v in catalogue.glass_coefs(name)]
        except (TypeError, ValueError):
            continue
        if not all(math.isfinite(v) for v in coefficients):
            continue
        row = catalogue.df.loc[name]
        lam, n = tabulated(row)
        if len(lam) < 3:
            continue
        error = float(np.abs(index(FORMULA[maker], coefficients, lam) - n).max())
        if error > TOLERANCE:
            print(f"skipped {maker} {name}: formula off its own table by {error:.1e}")
            continue
        n_d = float(index(FORMULA[maker], coefficients, np.array([587.5618]))[0])
        n_f, n_c = index(FORMULA[maker], coefficients, np.array([486.1327, 656.2725]))
        rows.append(
            {
                "name": name.strip(),
                "coefficients": coefficients,
                "range_nm": [float(lam.min()), float(lam.max())],
                "n_d": round(n_d, 6),
                "v_d": round((n_d - 1.0) / float(n_f - n_c), 3),
            }
        )
    return rows


def _one_glass_a_line(table: dict[str, Any]) -> str:
    """JSON with one glass a line: small, and a catalogue update diffs glass by glass."""
    catalogues = []
    for maker, entry in table["catalogues"].items():
        glasses = ",\n".join(json.dumps(g, ensure_ascii=False) for g in entry["glasses"])
        catalogues.append(
            f'{json.dumps(maker)}: {{"formula": {json.dumps(entry["formula"])}, "glasses": [\n'
            f"{glasses}\n]}}"
        )
    head = {k: v for k, v in table.items() if k != "catalogues"}
    text = json.dumps(head, ensure_ascii=False, indent=1)[:-2]
    return text + ',\n "catalogues": {\n' + ",\n".join(catalogues) + "\n}}\n"


def main(output: str) -> None:
    with warnings.catch_warnings():
        warnings.simplefilter("ignore")
        table = {
            "source": (
                f"opticalglass {version('opticalglass')} (M. J. Hayford, BSD-3-Clause): the "
                "makers' catalogue spreadsheets; written by scripts/glass_catalogue.py"
            ),
            "formulas": {
                "sellmeier": "n^2 = 1 + sum_i c[i] L^2 / (L^2 - c[i+3]), i = 0..2",
                "schott": "n^2 = c0 + c1 L^2 + c2 L^-2 + c3 L^-4 + c4 L^-6 + c5 L^-8",
                "hikari": "n^2 = c0 + c1 L^2 + c2 L^4 + c3 L^-2 + ... + c8 L^-12",
                "units": "L = wavelength in µm",
            },
            "catalogues": {
                maker.upper(): {"formula": formula, "glasses": catalogue_rows(maker)}
                for maker, formula in FORMULA.items()
            },
        }
    with open(output, "w") as f:
        f.write(_one_glass_a_line(table))
    counts = {k: len(v["glasses"]) for k, v in table["catalogues"].items()}
    print(f"wrote {output}: {counts}")


if __name__ == "__main__":
    main(sys.argv[1])
