"""The QE film: Mitsuba's spectral film with one channel whose response is QE(lambda) lambda/(h c).

specfilm stores integral of response(lambda) * L(lambda) d lambda per pixel (measured: no
normalisation, wavelengths sampled in proportion to the response, also beyond 830 nm), so with
radiance L in W/(m^2 sr nm) a pixel holds photo-electrons per second per m^2 and steradian.
"""

from __future__ import annotations

from typing import TYPE_CHECKING, Any

import numpy as np

from pecs.render.quantum_efficiency import QuantumEfficiency
from pecs.render.spectrum import photons_per_joule

if TYPE_CHECKING:
    from pecs.render.cfa import ColourFilterArray


def qe_film(qe: QuantumEfficiency, width: int, height: int) -> dict[str, Any]:
    """Mitsuba film dict: box filter (a pixel integrates its own area, as a photodiode does)."""
    response = qe.electrons_per_joule()
    return {
        "type": "specfilm",
        "width": int(width),
        "height": int(height),
        "rfilter": {"type": "box"},
        "photoelectrons": {
            "type": "irregular",
            "wavelengths": ", ".join(f"{w:.6g}" for w in qe.wavelength_nm),
            "values": ", ".join(f"{v:.9g}" for v in response),
        },
    }


def cfa_film(
    qe: QuantumEfficiency, cfa: ColourFilterArray, width: int, height: int
) -> dict[str, Any]:
    """The QE film with one channel per filter of the colour filter array, in `cfa.channels`
    order (specfilm keeps the order its responses are given in): channel c holds integral
    T_c(lambda) QE(lambda) lambda/(h c) L(lambda) d lambda. One render gives every channel, its
    wavelengths sampled in proportion to the channels' summed response."""
    # Both curves interpolated on a 1 nm grid over the QE's range (beyond it QE is 0): Mitsuba
    # interpolates the response linearly, so it is their product, not a product of 10 nm steps.
    grid_nm = np.arange(qe.wavelength_nm[0], qe.wavelength_nm[-1] + 0.5, 1.0)
    electrons_per_joule = qe(grid_nm) * photons_per_joule(grid_nm)
    film: dict[str, Any] = {
        "type": "specfilm",
        "width": int(width),
        "height": int(height),
        "rfilter": {"type": "box"},
    }
    for channel in cfa.channels:
        film[f"cfa_{channel}"] = {
            "type": "irregular",
            "wavelengths": ", ".join(f"{w:.6g}" for w in grid_nm),
            "values": ", ".join(
                f"{v:.9g}" for v in cfa.filters[channel](grid_nm) * electrons_per_joule
            ),
        }
    return film
