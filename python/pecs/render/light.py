"""Light sources scaled to a measured illuminance, as one sets up a real room with a lux meter.

The scene XML writes its emitter spectra as `$light_spectrum`; pecs fills in a blackbody or a
measured spectrum, measures the direct illuminance E_v = 683 lm/W * integral V(lambda) E(lambda)
at the given point, and reloads the scene with the spectrum scaled to the requested lux.
"""

from __future__ import annotations

from types import ModuleType
from typing import Any

import numpy as np

from pecs.render.scene_file import Light
from pecs.render.spectrum import (
    LUMINOUS_EFFICACY_LM_W,
    WAVELENGTH_MAX_NM,
    WAVELENGTH_MIN_NM,
    mitsuba_spectrum_string,
    photopic,
    planck_radiance,
)
from pecs.render.spectrum_csv import read_spectrum_csv

_GRID_STEP_NM = 5.0
_METER_SAMPLES = 1 << 18
_SCALAR_METER_SAMPLES = 1 << 12


def light_spectrum(light: Light) -> tuple[np.ndarray, np.ndarray]:
    """Relative spectral power (peak 1) on a grid over the rendered wavelength range."""
    if light.temperature_k is not None:
        wavelength_nm = np.arange(WAVELENGTH_MIN_NM, WAVELENGTH_MAX_NM + 0.5, _GRID_STEP_NM)
        power = planck_radiance(wavelength_nm, light.temperature_k)
    else:
        assert light.spectrum_file is not None
        wavelength_nm, power = read_spectrum_csv(light.spectrum_file)
        if power.max() <= 0:
            raise ValueError(f"{light.spectrum_file}: spectrum is zero everywhere")
    return wavelength_nm, power / power.max()


def spectrum_parameter(light: Light, scale: float) -> str:
    """The `$light_spectrum` value for Mitsuba's XML loader."""
    wavelength_nm, power = light_spectrum(light)
    return mitsuba_spectrum_string(wavelength_nm, scale * power)


def direct_illuminance_lux(
    mi: ModuleType, scene: Any, at: tuple[float, ...], normal: tuple[float, ...], seed: int = 0
) -> float:
    """Monte Carlo E_v = integral over emitters of 683 V(lambda) L cos(theta) (direct light only).

    Next-event estimation from the point with visibility; wavelengths sampled uniformly over the
    photopic range, four per lane (Mitsuba's stratified spectral sampling). JIT variants trace
    all samples as one wavefront; the scalar variant loops over fewer of them.
    """
    import drjit as dr

    v_wavelength_nm, v = photopic()
    lo, hi = float(v_wavelength_nm[0]), float(v_wavelength_nm[-1])
    if dr.is_jit_v(mi.Float):
        sampler = mi.load_dict({"type": "independent"})
        sampler.seed(seed, _METER_SAMPLES)
        u_wavelength, u_direction = sampler.next_1d(), sampler.next_2d()
        wavelength_nm, weight = _direct_samples(mi, scene, at, normal, u_wavelength, u_direction)
    else:
        rng = np.random.default_rng(seed)
        pairs = [
            _direct_samples(
                mi, scene, at, normal, float(rng.random()), mi.Point2f(*rng.random(2).tolist())
            )
            for _ in range(_SCALAR_METER_SAMPLES)
        ]
        wavelength_nm = np.concatenate([p[0] for p in pairs])
        weight = np.concatenate([p[1] for p in pairs])
    efficiency = np.interp(wavelength_nm, v_wavelength_nm, v, left=0.0, right=0.0)
    return LUMINOUS_EFFICACY_LM_W * (hi - lo) * float(np.mean(efficiency * weight))


def _direct_samples(
    mi: ModuleType,
    scene: Any,
    at: tuple[float, ...],
    normal: tuple[float, ...],
    u_wavelength: Any,
    u_direction: Any,
) -> tuple[np.ndarray, np.ndarray]:
    """(wavelength_nm, radiance / pdf * cos) of emitter samples at `at`, over the V range."""
    import drjit as dr

    n = dr.normalize(mi.Vector3f(*normal))
    lanes = dr.width(u_wavelength) if dr.is_jit_v(mi.Float) else 1
    ref = dr.zeros(mi.Interaction3f, lanes)
    ref.p = mi.Point3f(*at)
    ref.n = mi.Normal3f(n)
    ref.t = mi.Float(0.0)
    v_wavelength_nm, _ = photopic()
    lo, hi = float(v_wavelength_nm[0]), float(v_wavelength_nm[-1])
    ref.wavelengths = lo + (hi - lo) * mi.sample_shifted(u_wavelength)
    ds, radiance_over_pdf = scene.sample_emitter_direction(ref, u_direction, True)
    cos_theta = dr.maximum(dr.dot(ds.d, n), 0.0)
    wavelength_nm = np.array(ref.wavelengths, dtype=np.float64)
    weight = np.array(radiance_over_pdf, dtype=np.float64) * np.array(cos_theta, dtype=np.float64)
    if weight.shape != wavelength_nm.shape:
        raise RuntimeError(f"unexpected spectrum shape {weight.shape} from Mitsuba")
    return wavelength_nm.ravel(), weight.ravel()
