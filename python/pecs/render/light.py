"""Light sources scaled to a measured illuminance, as one sets up a real room with a lux meter.

The scene writes its lamp spectra as `$light_spectrum` (XML parameter, or that string as a value in
a scene dict); pecs fills in a blackbody or a measured spectrum. It then measures, per emitter, the
direct illuminance E_v = 683 lm/W * integral V(lambda) E(lambda) at a point and scales emitters
through their Mitsuba parameters (spectrum values, or an environment map's `scale`):

- `[[lights]]`: each listed emitter alone gives its `illuminance_lux` at its point (or is
  multiplied by its `scale`);
- `[light]`: every emitter is counted at that point, the listed ones at their new level, the
  others as the scene gives them, and the `$light_spectrum` emitters not listed make up the rest.
  If the others already exceed the request, that is an error, not a silent excess.

A `flicker` in either section makes those emitters' levels the mean of a mains waveform
(`pecs.render.flicker`): the lux asked is the mean, and `FlickeringEmitter.set_time` sets each
frame's level, mean times the waveform at the frame's time, as animation sets a pose.
"""

from __future__ import annotations

from collections.abc import Callable
from dataclasses import dataclass, field
from types import ModuleType
from typing import Any

import numpy as np

from pecs.render.flicker import Flicker
from pecs.render.scene_file import EmitterLevel, Light, SceneSpec
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


LIGHT_SPECTRUM = "$light_spectrum"
# Emitter parameters that are a radiometric level (scaled linearly); an environment map's `scale`
# is preferred to its bitmap `data`.
_LEVEL_SUFFIXES = (
    "radiance.value",
    "radiance.values",
    "radiance.data",
    "intensity.value",
    "intensity.values",
    "intensity.data",
    "irradiance.value",
    "irradiance.values",
    "irradiance.data",
)


def spectrum_dict(light: Light, scale: float) -> dict[str, Any]:
    """The `$light_spectrum` value for Mitsuba's dict loader."""
    wavelength_nm, power = light_spectrum(light)
    pairs = [(float(w), float(v)) for w, v in zip(wavelength_nm, scale * power, strict=True)]
    return {"type": "spectrum", "value": pairs}


def with_light_spectrum(scene_dict: dict[str, Any], spectrum: dict[str, Any]) -> tuple[dict, int]:
    """A copy of a scene dict with every "$light_spectrum" value replaced; (copy, how many)."""
    count = 0

    def substitute(node: Any) -> Any:
        nonlocal count
        if isinstance(node, str) and node == LIGHT_SPECTRUM:
            count += 1
            return dict(spectrum)
        if isinstance(node, dict):
            return {key: substitute(value) for key, value in node.items()}
        return node

    return substitute(scene_dict), count


@dataclass(frozen=True)
class FlickeringEmitter:
    """An emitter whose level follows a flicker: its parameters at their mean level, kept."""

    name: str
    flicker: Flicker
    params: Any  # the emitter's own `mi.traverse`
    mean_levels: dict[str, Any]

    def set_time(self, t_s: float) -> None:
        """The emitter's level at `t_s`: its mean times the flicker's factor then."""
        # A lamp that goes fully dark (depth 1) is held at 1e-9 of its mean there: Mitsuba's
        # tabulated spectra refuse a zero level ("no probability mass found"), and 1e-9 of a
        # lamp is far below any pixel's dark current, so the events are those of darkness.
        factor = max(self.flicker.factor(t_s), DARKEST_FLICKER_FACTOR)
        for key, mean in self.mean_levels.items():
            self.params[key] = mean * factor
        # Mitsuba's emitters keep their levels opaque (not compiled into the kernel): 101
        # frames of a flickering point lamp, tabulated or uniform spectrum, render as fast as
        # steady ones, with no recompilation.
        self.params.update()


# The lowest level a flickering emitter is set to, relative to its mean (see set_time).
DARKEST_FLICKER_FACTOR = 1e-9


@dataclass
class LightLevels:
    """What the scaling did: the `$light_spectrum` scale and each emitter's factor, and the
    emitters that flicker."""

    light_scale: float = 1.0
    emitter_scales: dict[str, float] = field(default_factory=dict)
    flickering: list[FlickeringEmitter] = field(default_factory=list)


@dataclass(frozen=True)
class _Emitter:
    name: str
    emitter: Any
    params: Any  # the emitter's own `mi.traverse`, through which it is scaled
    level_keys: tuple[str, ...]
    uses_light_spectrum: bool


def level_emitters(mi: ModuleType, scene: Any, spec: SceneSpec) -> LightLevels:
    """Scale the emitters of a loaded scene as `[[lights]]` and `[light]` ask (see the module)."""
    if spec.light is None and not spec.lights:
        return LightLevels()
    unit = light_spectrum(spec.light)[1] if spec.light is not None else None
    emitters = _emitters(mi, scene, unit)
    levels = LightLevels()
    for level in spec.lights:
        levels.emitter_scales[level.emitter_id] = _listed_scale(mi, scene, spec, emitters, level)
    if spec.light is not None:
        levels.light_scale = _light_scale(mi, scene, spec, emitters, levels.emitter_scales)
        for emitter in emitters.values():
            if emitter.uses_light_spectrum and emitter.name not in levels.emitter_scales:
                levels.emitter_scales[emitter.name] = levels.light_scale
    for name, scale in levels.emitter_scales.items():
        params = emitters[name].params
        for key in emitters[name].level_keys:
            params[key] = params[key] * scale
        params.update()
    levels.flickering = _flickering(spec, emitters, levels.emitter_scales)
    return levels


def _flickering(
    spec: SceneSpec, emitters: dict[str, _Emitter], scaled: dict[str, float]
) -> list[FlickeringEmitter]:
    """The emitters whose `[[lights]]` entry, or `[light]` (its `$light_spectrum` emitters),
    has a flicker, each with its levels as scaled (the mean)."""
    flickers = {level.emitter_id: level.flicker for level in spec.lights if level.flicker}
    listed = {level.emitter_id for level in spec.lights}
    if spec.light is not None and spec.light.flicker is not None:
        for name in scaled:
            if name not in listed and emitters[name].uses_light_spectrum:
                flickers[name] = spec.light.flicker
    out = []
    for name, flicker in flickers.items():
        emitter = emitters[name]
        means = {key: emitter.params[key] * 1.0 for key in emitter.level_keys}  # copies
        out.append(FlickeringEmitter(name, flicker, emitter.params, means))
    return out


def _emitters(mi: ModuleType, scene: Any, unit_spectrum: np.ndarray | None) -> dict[str, _Emitter]:
    """Emitters by name: their id, an area light by its shape's id, else `emitter_<index>`."""
    out = {}
    for index, emitter in enumerate(scene.emitters()):
        shape = emitter.get_shape()
        name = (shape.id() if shape is not None else emitter.id()) or f"emitter_{index}"
        params = mi.traverse(emitter)
        keys = list(params.keys())
        level_keys = ["scale"] if "scale" in keys else [k for k in keys if k in _LEVEL_SUFFIXES]
        uses = unit_spectrum is not None and any(
            _same_values(params[k], unit_spectrum) for k in level_keys if k.endswith(".values")
        )
        out[name] = _Emitter(name, emitter, params, tuple(level_keys), uses)
    return out


def _same_values(parameter: Any, unit_spectrum: np.ndarray) -> bool:
    """Whether a spectrum parameter is the unit `$light_spectrum` the scene was loaded with (the
    loaded scene does not otherwise say which emitters used the placeholder)."""
    values = np.ravel(np.array(parameter, dtype=np.float64))
    return values.shape == unit_spectrum.shape and np.allclose(values, unit_spectrum, rtol=1e-5)


def _listed_scale(
    mi: ModuleType, scene: Any, spec: SceneSpec, emitters: dict[str, _Emitter], level: EmitterLevel
) -> float:
    where = f"{spec.path}: lights id {level.emitter_id!r}"
    if level.emitter_id not in emitters:
        raise ValueError(
            f"{where}: not an emitter of {spec.mitsuba_name} (emitters, area lights by their "
            f"shape's id: {sorted(emitters)})"
        )
    emitter = emitters[level.emitter_id]
    if not emitter.level_keys:
        raise ValueError(
            f"{where}: its spectrum has no value pecs can scale (a blackbody?); give it a "
            f"tabulated spectrum or {LIGHT_SPECTRUM} with [light]"
        )
    if level.scale is not None:
        return level.scale
    assert level.illuminance_lux is not None and level.at is not None and level.normal is not None
    measured = emitter_illuminance_lux(
        mi, scene, emitter.emitter, level.at, level.normal, spec.seed
    )
    if not measured > 0:
        raise ValueError(
            f"{where}: at = {list(level.at)} receives no direct light from it; cannot scale it "
            f"to {level.illuminance_lux} lux"
        )
    return level.illuminance_lux / measured


def _light_scale(
    mi: ModuleType,
    scene: Any,
    spec: SceneSpec,
    emitters: dict[str, _Emitter],
    listed: dict[str, float],
) -> float:
    """The `$light_spectrum` scale that makes the total at `[light] at` the requested lux."""
    light = spec.light
    assert light is not None
    lux = {
        name: listed.get(name, 1.0)
        * emitter_illuminance_lux(mi, scene, e.emitter, light.at, light.normal, spec.seed)
        for name, e in emitters.items()
    }
    scaled = [n for n, e in emitters.items() if e.uses_light_spectrum and n not in listed]
    variable = sum(lux[n] for n in scaled)
    fixed = {n: v for n, v in lux.items() if n not in scaled}
    where = f"{spec.path}: [light]"
    if not variable > 0:
        raise ValueError(
            f"{where} at = {list(light.at)} receives no direct light from the {LIGHT_SPECTRUM} "
            f"emitters of {spec.mitsuba_name} ({scaled or 'none left outside [[lights]]'}); "
            f"cannot scale to {light.illuminance_lux} lux"
        )
    remainder = light.illuminance_lux - sum(fixed.values())
    if not remainder > 0:
        others = ", ".join(f"{n}: {v:.4g} lux" for n, v in sorted(fixed.items()) if v > 0)
        raise ValueError(
            f"{where} asks {light.illuminance_lux} lux at {list(light.at)}, but the emitters that "
            f"do not use {LIGHT_SPECTRUM} already give {sum(fixed.values()):.4g} lux there "
            f"({others}); lower them with [[lights]] or ask for more"
        )
    return remainder / variable


def emitter_illuminance_lux(
    mi: ModuleType,
    scene: Any,
    emitter: Any,
    at: tuple[float, ...],
    normal: tuple[float, ...],
    seed: int = 0,
) -> float:
    """Direct illuminance at `at` from one emitter (next-event estimation, with visibility)."""

    import drjit as dr

    def sample(ref: Any, u_direction: Any) -> tuple[Any, Any]:
        ds, radiance_over_pdf = emitter.sample_direction(ref, u_direction)
        occluded = scene.ray_test(ref.spawn_ray_to(ds.p))
        return ds, dr.select(occluded, 0.0, 1.0) * mi.Spectrum(radiance_over_pdf)

    return _illuminance_lux(mi, sample, at, normal, seed)


def _illuminance_lux(
    mi: ModuleType,
    sample: Callable[[Any, Any], tuple[Any, Any]],
    at: tuple[float, ...],
    normal: tuple[float, ...],
    seed: int,
) -> float:
    """Monte Carlo E_v = integral over emitters of 683 V(lambda) L cos(theta) (direct light only).

    `sample(ref, u)` gives (direction sample, radiance / pdf, zero where occluded); wavelengths
    sampled uniformly over the photopic range, four per lane (Mitsuba's stratified spectral
    sampling). JIT variants trace all samples as one wavefront; the scalar variant loops over
    fewer of them.
    """
    import drjit as dr

    v_wavelength_nm, v = photopic()
    lo, hi = float(v_wavelength_nm[0]), float(v_wavelength_nm[-1])
    if dr.is_jit_v(mi.Float):
        sampler = mi.load_dict({"type": "independent"})
        sampler.seed(seed, _METER_SAMPLES)
        u_wavelength, u_direction = sampler.next_1d(), sampler.next_2d()
        wavelength_nm, weight = _direct_samples(mi, sample, at, normal, u_wavelength, u_direction)
    else:
        rng = np.random.default_rng(seed)
        pairs = [
            _direct_samples(
                mi, sample, at, normal, float(rng.random()), mi.Point2f(*rng.random(2).tolist())
            )
            for _ in range(_SCALAR_METER_SAMPLES)
        ]
        wavelength_nm = np.concatenate([p[0] for p in pairs])
        weight = np.concatenate([p[1] for p in pairs])
    efficiency = np.interp(wavelength_nm, v_wavelength_nm, v, left=0.0, right=0.0)
    return LUMINOUS_EFFICACY_LM_W * (hi - lo) * float(np.mean(efficiency * weight))


def _direct_samples(
    mi: ModuleType,
    sample: Callable[[Any, Any], tuple[Any, Any]],
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
    ds, radiance_over_pdf = sample(ref, u_direction)
    cos_theta = dr.maximum(dr.dot(ds.d, n), 0.0)
    wavelength_nm = np.array(ref.wavelengths, dtype=np.float64)
    weight = np.array(radiance_over_pdf, dtype=np.float64) * np.array(cos_theta, dtype=np.float64)
    if weight.shape != wavelength_nm.shape:
        raise RuntimeError(f"unexpected spectrum shape {weight.shape} from Mitsuba")
    return wavelength_nm.ravel(), weight.ravel()
