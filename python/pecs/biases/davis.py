"""DAVIS346 coarse/fine biases (iniVation, libcaer) mapped to the pixel model's parameters.

A bias current is I = coarse_current[coarse] x fine / 255 (libcaer `caerBiasCoarseFineToCurrent`,
its coarse table in pA; fine 0 turns the bias off). The relations, from the standard DVS pixel
analysis (sources and the uncertainty of each in docs/biases.md):

- thresholds: theta_on = (C2/C1) ln(I_OnBn / I_DiffBn), theta_off = (C2/C1) ln(I_DiffBn / I_OffBn),
  C1/C2 = 20 (the comparator offsets are U_T ln of the current ratio, divided by the
  differencing gain C1/C2; the kappa ratios left out);
- bandwidth: the photoreceptor's source follower, tau = C_sf U_T / I_PrSFBp, cutoff 1/(2 pi tau),
  C_sf = 581 fF (Graca and Delbruck's pixel model);
- refractory period: the reset capacitor recharged by the RefrBp current, T = Q / I_RefrBp, with
  the charge Q calibrated so that libcaer's default RefrBp gives the davis346 preset's 500 us (no
  published constant: this fixes the scale, the 1 / I law is the circuit's).
"""

from __future__ import annotations

import math
import re
from collections.abc import Mapping
from typing import Any

from pecs.biases._mapping import BiasMapping, Estimate, spread

#: libcaer's coarse currents (pA), coarse 0-7, each 8x the one before (caerBiasCoarseFineToCurrent).
COARSE_CURRENTS_PA = (11.0, 94.0, 756.0, 6054.0, 48437.0, 387500.0, 3.1e6, 24.8e6)
FINE_MAX = 255

#: libcaer's DAVIS346 defaults (davisCommonSendDefaultChipConfig), (coarse, fine).
DAVIS346_DEFAULTS: dict[str, tuple[int, int]] = {
    "DiffBn": (4, 39),
    "OnBn": (5, 255),
    "OffBn": (4, 1),
    "PrBp": (2, 58),
    "PrSFBp": (1, 16),
    "RefrBp": (4, 25),
}

#: Differencing gain C1/C2 of the public DVS pixel model (C1 400 fF, C2 20 fF;
#: juan-pablo-giron/algorithm-testing-cameras matlab/DVS_model_fn.m).
C1_OVER_C2 = 20.0
#: Source-follower load capacitance of Graca and Delbruck's pixel model (581 fF; 10 pA -> 1.5 ms).
C_SF_F = 581e-15
#: Thermal voltage kT/q at 300 K.
U_T_V = 1.380649e-23 * 300.0 / 1.602176634e-19
#: The davis346 preset's refractory period, which libcaer's default RefrBp is calibrated to give.
PRESET_REFRACTORY_US = 500.0

# Ranges each mapped value may be off by, as factors (docs/biases.md says where each comes from).
#: Thresholds: the kappa ratios the relation leaves out (0.7-0.9 each [assumed typical]) and the
#: road recording's calibration at (presumably) default biases, 0.245 / 0.267, x1.24 / x1.46.
THETA_FACTORS = (0.75, 1.5)
#: Bandwidth: the follower's kappa (tau = C U_T / (kappa I) lowers the cutoff by kappa, 0.6-0.9)
#: and C_sf +-25 % [assumed].
CUTOFF_FACTORS = (0.5, 1.25)
#: Refractory period: the calibrated scale is v2e's default, not a measurement; the road
#: recording's calibration found 64-93 us, x0.13-0.19 of it.
REFRACTORY_FACTORS = (0.1, 1.5)

_NAMES = {name.lower(): name for name in DAVIS346_DEFAULTS}
_COARSE_FINE = re.compile(r"^\s*(\d+)\s*/\s*(\d+)\s*$")


def coarse_fine_current_pa(coarse: int, fine: int) -> float:
    """The current of a coarse/fine bias in pA, as libcaer computes it (without its rounding to
    whole pA, which would turn the smallest settings off); fine 0 is 0 (the bias is off)."""
    if not (isinstance(coarse, int) and 0 <= coarse < len(COARSE_CURRENTS_PA)):
        raise ValueError(f"coarse must be an integer 0-7, got {coarse!r}")
    if not (isinstance(fine, int) and 0 <= fine <= FINE_MAX):
        raise ValueError(f"fine must be an integer 0-255, got {fine!r}")
    return COARSE_CURRENTS_PA[coarse] * fine / FINE_MAX


def parse_coarse_fine(name: str, value: Any) -> tuple[int, int]:
    """A bias value as written, "5/255" or (5, 255), checked: coarse 0-7, fine 1-255."""
    if isinstance(value, str):
        match = _COARSE_FINE.match(value)
        if not match:
            raise ValueError(f"{name}: {value!r} is not COARSE/FINE (e.g. {name}=5/255)")
        coarse, fine = int(match.group(1)), int(match.group(2))
    elif isinstance(value, (tuple, list)) and len(value) == 2:
        coarse, fine = value
    else:
        raise ValueError(f"{name}: {value!r} is not COARSE/FINE (e.g. {name}=5/255)")
    if not (isinstance(coarse, int) and 0 <= coarse <= 7):
        raise ValueError(f"{name}: coarse {coarse} is out of range 0-7 (COARSE/FINE)")
    if not (isinstance(fine, int) and 0 <= fine <= FINE_MAX):
        raise ValueError(f"{name}: fine {fine} is out of range 0-255 (COARSE/FINE)")
    if fine == 0:
        raise ValueError(f"{name}: fine 0 turns the bias off; pecs maps biases that are on (1-255)")
    return coarse, fine


def davis346_biases(biases: Mapping[str, Any]) -> dict[str, tuple[int, int]]:
    """libcaer's defaults with the given biases over them (names as libcaer spells them, any
    case), each checked."""
    merged = dict(DAVIS346_DEFAULTS)
    for given, value in biases.items():
        name = _NAMES.get(str(given).lower())
        if name is None:
            known = ", ".join(DAVIS346_DEFAULTS)
            raise ValueError(f"{given}: not a DAVIS346 bias pecs maps; biases: {known}")
        merged[name] = parse_coarse_fine(name, value)
    return merged


def davis346_mapping(biases: Mapping[str, Any]) -> BiasMapping:
    """DAVIS346 coarse/fine biases ({"OnBn": "5/255", ...}; the rest at libcaer's defaults) mapped
    to theta_on, theta_off, cutoff_hz and refractory_us, each with its range."""
    settings = davis346_biases(biases)
    current = {name: coarse_fine_current_pa(*cf) for name, cf in settings.items()}
    _check_threshold_order(settings, current)
    theta_on = math.log(current["OnBn"] / current["DiffBn"]) / C1_OVER_C2
    theta_off = math.log(current["DiffBn"] / current["OffBn"]) / C1_OVER_C2
    tau_s = C_SF_F * U_T_V / (current["PrSFBp"] * 1e-12)
    cutoff_hz = 1.0 / (2.0 * math.pi * tau_s)
    refractory_us = PRESET_REFRACTORY_US * (_default_current("RefrBp") / current["RefrBp"])
    parameters = {
        "theta_on": Estimate(
            theta_on,
            *spread(theta_on, *THETA_FACTORS),
            "(C2/C1) ln(I_OnBn / I_DiffBn), C1/C2 = 20",
            "OnBn, DiffBn",
        ),
        "theta_off": Estimate(
            theta_off,
            *spread(theta_off, *THETA_FACTORS),
            "(C2/C1) ln(I_DiffBn / I_OffBn), C1/C2 = 20",
            "OffBn, DiffBn",
        ),
        "cutoff_hz": Estimate(
            cutoff_hz,
            *spread(cutoff_hz, *CUTOFF_FACTORS),
            "I_PrSFBp / (2 pi C_sf U_T), C_sf = 581 fF, U_T = 25.9 mV",
            "PrSFBp",
        ),
        "refractory_us": Estimate(
            refractory_us,
            *spread(refractory_us, *REFRACTORY_FACTORS),
            f"Q / I_RefrBp, Q = {_refractory_charge_pc():.3g} pC (calibrated: defaults give 500 us)",
            "RefrBp",
        ),
    }
    shown = {name: f"{c}/{f}" for name, (c, f) in settings.items()}
    return BiasMapping("davis346", shown, parameters, _unmapped(current))


def _check_threshold_order(settings: dict[str, tuple[int, int]], current: dict[str, float]) -> None:
    """OnBn above DiffBn above OffBn: otherwise a threshold would be zero or negative."""
    diff = f"DiffBn {_written(settings['DiffBn'])} ({_nano_amps(current['DiffBn'])})"
    if current["OnBn"] <= current["DiffBn"]:
        on = f"OnBn {_written(settings['OnBn'])} ({_nano_amps(current['OnBn'])})"
        raise ValueError(f"{on} must give more current than {diff}, or the ON threshold is <= 0")
    if current["OffBn"] >= current["DiffBn"]:
        off = f"OffBn {_written(settings['OffBn'])} ({_nano_amps(current['OffBn'])})"
        raise ValueError(f"{off} must give less current than {diff}, or the OFF threshold is <= 0")


def _unmapped(current: dict[str, float]) -> dict[str, str]:
    ratio = current["PrBp"] / current["PrSFBp"]
    which = "so the follower (PrSFBp) sets the bandwidth" if ratio > 3 else "so cutoff_hz is high"
    return {
        "PrBp": f"the photoreceptor amplifier's pole, which the model does not have: it is "
        f"{ratio:.3g}x PrSFBp, {which}",
        "high-pass": "the DAVIS346 pixel has no high-pass bias, and the model no high-pass stage",
    }


def _default_current(name: str) -> float:
    return coarse_fine_current_pa(*DAVIS346_DEFAULTS[name])


def _refractory_charge_pc() -> float:
    """Q = T x I at the defaults: 500 us x 4.75 nA."""
    return PRESET_REFRACTORY_US * 1e-6 * _default_current("RefrBp")


def _written(cf: tuple[int, int]) -> str:
    return f"{cf[0]}/{cf[1]}"


def _nano_amps(pa: float) -> str:
    return f"{pa / 1000:.3g} nA"
