"""The QE film: Mitsuba's spectral film with one channel whose response is QE(lambda) lambda/(h c).

specfilm stores integral of response(lambda) * L(lambda) d lambda per pixel (measured: no
normalisation, wavelengths sampled in proportion to the response, also beyond 830 nm), so with
radiance L in W/(m^2 sr nm) a pixel holds photo-electrons per second per m^2 and steradian.
"""

from __future__ import annotations

from typing import Any

from pecs.render.quantum_efficiency import QuantumEfficiency


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
