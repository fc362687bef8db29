"""Lens ghosts of the scene's bright sources, added to the rendered frames (`[optics] ghosts`).

At each frame, every emitter of the Mitsuba scene is a point source for the ghost tracer
(pecs.lens.ghosts): its spectral irradiance at the lens's front vertex, E(lambda) = radiance /
pdf of Mitsuba's `sample_direction` from there (zero when `scene.ray_test` finds it hidden), at
fixed sample points (point, spot and directional lights: their one point; area lights: a fixed
stratified set on the shape), and its place in lens space. The ghost image at a few wavelength
bands adds integral over each band of QE(lambda) lambda / (h c) T_c(lambda) E(lambda) d lambda
times the ghost's irradiance per unit source irradiance: the units of the QE film (photo-
electrons / s / m^2). Nothing is random, so a static scene's frames stay identical.
Environment maps and constant skies are not ghost sources (no point to trace from).
"""

from __future__ import annotations

from dataclasses import dataclass
from typing import Any

import numpy as np

from pecs.lens.coating import coating_from_value
from pecs.lens.ghosts import (
    DEFAULT_RAYS_PER_SIDE,
    CoverGlass,
    GhostOptions,
    GhostRays,
    GhostSystem,
    GhostTracer,
    PointSource,
    splat,
)
from pecs.lens.lens import Lens
from pecs.render.cfa import ColourFilterArray
from pecs.render.quantum_efficiency import QuantumEfficiency
from pecs.render.spectrum import photons_per_joule

GHOST_KEYS = ("coating", "cover_glass", "rays_per_side", "bands", "area_samples", "dispersion")
_SPECTRUM_STEP_NM = 10.0


@dataclass(frozen=True)
class GhostSettings:
    """The tracer's options, and how finely the renderer samples wavelength and area lights."""

    options: GhostOptions
    bands: int = 3
    area_samples: int = 1  # per side: area_samples^2 fixed points on each area light


def ghost_settings(raw: dict[str, Any], lens: Lens, where: str) -> GhostSettings:
    """Settings from the scene file's `[optics]` ghost keys (`raw`, as TOML gives them):
    coating ("quarter_wave", "none", a table, or an array with one per lens surface),
    cover_glass (true or a table of CoverGlass's fields), rays_per_side, bands, area_samples,
    dispersion (trace every band's own paths)."""
    unknown = sorted(set(raw) - set(GHOST_KEYS))
    if unknown:
        raise ValueError(f"{where}.{unknown[0]}: unknown key (known: {list(GHOST_KEYS)})")
    coating_value = raw.get("coating", "quarter_wave")
    if isinstance(coating_value, list):
        if len(coating_value) != len(lens.surfaces):
            raise ValueError(
                f"{where}.coating: {len(coating_value)} coatings for the "
                f"{len(lens.surfaces)} surfaces of {lens.name}"
            )
        coatings: Any = tuple(
            coating_from_value(v, f"{where}.coating[{k}]") for k, v in enumerate(coating_value)
        )
    else:
        coatings = coating_from_value(coating_value, f"{where}.coating")
    plate_value = raw.get("cover_glass", False)
    plate = None
    if plate_value is True:
        plate = CoverGlass()
    elif isinstance(plate_value, dict):
        fields = dict(plate_value)
        if "coating" in fields:
            fields["coating"] = coating_from_value(
                fields["coating"], f"{where}.cover_glass.coating"
            )
        try:
            plate = CoverGlass(**fields)
        except ValueError as error:
            raise ValueError(f"{where}: {error}") from None
        except TypeError:
            raise ValueError(
                f"{where}.cover_glass: known keys are thickness_mm, index, gap_mm, coating, "
                f"sensor_reflectance; got {sorted(plate_value)}"
            ) from None
    elif plate_value is not False:
        raise ValueError(f"{where}.cover_glass: expected true, false or a table")
    rays = _integer(raw, "rays_per_side", DEFAULT_RAYS_PER_SIDE, 4, 512, where)
    bands = _integer(raw, "bands", 3, 1, 32, where)
    area = _integer(raw, "area_samples", 1, 1, 8, where)
    dispersion = raw.get("dispersion", False)
    if not isinstance(dispersion, bool):
        raise ValueError(f"{where}.dispersion: expected true or false, got {dispersion!r}")
    try:
        options = GhostOptions(
            coatings=coatings, cover_glass=plate, rays_per_side=rays, dispersion=dispersion
        )
        GhostSystem(lens, options)
    except ValueError as error:
        raise ValueError(f"{where}: {error}") from None
    return GhostSettings(options, bands, area)


def realistic_lens(
    name: str, efl_mm: float | None, f_number: float | None, focus_m: float | None
) -> Lens:
    """The lens as the realisticlens sensor sets it up: scaled, stopped down, focused."""
    import warnings

    lens = Lens.load(name)
    if efl_mm is not None:
        lens = lens.scaled_to(efl_mm)
    if f_number is not None:
        with warnings.catch_warnings():  # the sensor warns about clamping, once
            warnings.simplefilter("ignore", RuntimeWarning)
            lens = lens.with_f_number(f_number, clamp=True)
    return lens.focused(np.inf if focus_m is None else focus_m)


def _integer(raw: dict[str, Any], key: str, default: int, lo: int, hi: int, where: str) -> int:
    value = raw.get(key, default)
    if isinstance(value, bool) or not isinstance(value, int) or not lo <= value <= hi:
        raise ValueError(f"{where}.{key}: expected an integer in [{lo}, {hi}], got {value!r}")
    return value


class LensGhosts:
    """Ghost photo-electron irradiance of a scene's emitters through a lens, per frame."""

    def __init__(
        self,
        mi: Any,
        scene: Any,
        lens: Lens,
        width: int,
        height: int,
        pitch_mm: float,
        qe: QuantumEfficiency,
        cfa: ColourFilterArray | None,
        settings: GhostSettings,
    ) -> None:
        import drjit as dr

        if not dr.is_jit_v(mi.Float):  # the lights are queried as one wide array
            raise ValueError(
                f"optics.ghosts: tracing ghosts needs Mitsuba's llvm or cuda variant, not "
                f"{mi.variant()} (install libLLVM >= 16, or set PECS_MITSUBA_VARIANT)"
            )
        self.mi, self.scene, self.lens = mi, scene, lens
        self.width, self.height, self.pitch_mm = width, height, pitch_mm
        self.tracer = GhostTracer(GhostSystem(lens, settings.options))
        self.settings = settings
        lo, hi = float(qe.wavelength_nm[0]), float(qe.wavelength_nm[-1])
        self.wavelength_nm = np.arange(lo + _SPECTRUM_STEP_NM / 2, hi, _SPECTRUM_STEP_NM)
        response = qe(self.wavelength_nm) * photons_per_joule(self.wavelength_nm)
        curves = (
            [np.ones_like(response)]
            if cfa is None
            else [cfa.filters[c](self.wavelength_nm) for c in cfa.channels]
        )
        self.cfa = cfa
        # Bands of equal width over the QE range; each traced at its response-weighted centre.
        edges = np.linspace(lo, hi, settings.bands + 1)
        self.band_of = np.clip(
            np.searchsorted(edges, self.wavelength_nm) - 1, 0, settings.bands - 1
        )
        self.band_nm = np.array(
            [
                np.average(
                    self.wavelength_nm[self.band_of == b],
                    weights=response[self.band_of == b] + 1e-30,
                )
                for b in range(settings.bands)
            ]
        )
        # (channels, wavelengths): electrons per joule through each filter, times d lambda.
        self.response = np.array(curves) * response * _SPECTRUM_STEP_NM
        self.skipped: list[str] = []
        self.emitters = []
        for emitter in scene.emitters():
            flags = emitter.flags()
            infinite = mi.has_flag(flags, mi.EmitterFlags.Infinite)
            delta_dir = mi.has_flag(flags, mi.EmitterFlags.DeltaDirection)
            if infinite and not delta_dir:
                self.skipped.append(str(emitter.id()) or type(emitter).__name__)
                continue
            self.emitters.append(emitter)

    def _samples(self, emitter: Any) -> np.ndarray:
        """Fixed sample points in [0, 1)^2 for an emitter (one for delta lights)."""
        mi = self.mi
        flags = emitter.flags()
        delta = mi.has_flag(flags, mi.EmitterFlags.DeltaPosition) or mi.has_flag(
            flags, mi.EmitterFlags.DeltaDirection
        )
        k = 1 if delta else self.settings.area_samples
        u = (np.arange(k) + 0.5) / k
        return np.array([(a, b) for b in u for a in u])

    def sources(self, camera_pose: np.ndarray) -> list[tuple[PointSource, np.ndarray]]:
        """(source in lens space, band weights (channels, bands) in electrons / s / m^2 per
        unit ghost irradiance ratio) of every visible emitter sample."""
        import drjit as dr

        mi = self.mi
        film_z = self.lens.geometry.film_z_mm
        front = camera_pose @ np.array([0.0, 0.0, film_z * 1e-3, 1.0])
        to_camera = np.linalg.inv(camera_pose)
        groups = -(-len(self.wavelength_nm) // 4)
        lam = np.resize(self.wavelength_nm, groups * 4)  # padded (the pad is ignored)
        out = []
        for emitter in self.emitters:
            u = self._samples(emitter)
            count = len(u)
            width = count * groups
            ref = dr.zeros(mi.Interaction3f, width)
            # Arrays, not literals: a moving camera must not compile a new kernel every frame.
            ref.p = mi.Point3f(*(mi.Float(np.full(width, v, np.float32)) for v in front[:3]))
            wavelengths = dr.zeros(type(ref.wavelengths), width)
            for c in range(4):
                wavelengths[c] = mi.Float(np.repeat(lam[c::4], count).astype(np.float32))
            ref.wavelengths = wavelengths
            sample = mi.Point2f(
                mi.Float(np.tile(u[:, 0], groups).astype(np.float32)),
                mi.Float(np.tile(u[:, 1], groups).astype(np.float32)),
            )
            ds, value = emitter.sample_direction(ref, sample)
            hidden = np.broadcast_to(
                np.array(self.scene.ray_test(ref.spawn_ray_to(ds.p)), dtype=bool).ravel(), width
            )
            # (width, 4); a value that depends on nothing comes back as one lane
            spectrum = np.broadcast_to(np.array(value, np.float64).reshape(-1, 4), (width, 4))
            spectrum = np.where(hidden[:, None], 0.0, spectrum)
            # (groups, count, 4) -> (count, wavelengths)
            per = spectrum.reshape(groups, count, 4).transpose(1, 0, 2).reshape(count, -1)
            per = per[:, : len(self.wavelength_nm)] / count  # each sample: 1/count of the light
            points = np.broadcast_to(np.array(ds.p, np.float64).reshape(-1, 3), (width, 3))
            directions = np.broadcast_to(np.array(ds.d, np.float64).reshape(-1, 3), (width, 3))
            points, directions = points[:count], directions[:count]
            delta_dir = mi.has_flag(emitter.flags(), mi.EmitterFlags.DeltaDirection)
            for s in range(count):
                if not np.any(per[s] > 0):
                    continue
                if delta_dir:  # light travels against ds.d, towards the camera
                    d_cam = to_camera[:3, :3] @ -directions[s]
                    if not -d_cam[2] > 0:
                        continue
                    source = PointSource(
                        direction=(float(d_cam[0]), float(d_cam[1]), float(-d_cam[2]))
                    )
                else:
                    p_cam = (to_camera @ np.append(points[s], 1.0))[:3] * 1e3
                    z_lens = film_z - p_cam[2]
                    if not z_lens < -1.0:  # behind or inside the lens
                        continue
                    source = PointSource(
                        position_mm=(float(p_cam[0]), float(p_cam[1]), float(z_lens))
                    )
                weights = np.zeros((len(self.response), self.settings.bands))
                for b in range(self.settings.bands):
                    band = self.band_of == b
                    weights[:, b] = self.response[:, band] @ per[s, band]
                out.append((source, weights))
        return out

    def frame(self, camera_pose: np.ndarray) -> np.ndarray:
        """Ghost photo-electron irradiance (H, W), float64 (each pixel its own CFA filter's)."""
        channels = np.zeros((self.height, self.width, len(self.response)))
        found = self.sources(camera_pose)
        if not found:
            return channels[..., 0] if self.cfa is None else self.cfa.mosaic(channels)
        rays = self.tracer.trace_many([s for s, _ in found], self.band_nm)
        # (sources, channels, bands) -> per row of the traced rays (sources x paths)
        weights = np.repeat(np.array([w for _, w in found]), len(self.tracer.paths), axis=0)
        for c in range(channels.shape[2]):
            flux = rays.flux_mm2 * weights[:, c, :, None, None]
            if self.tracer.system.options.dispersion:  # each band its own geometry
                layered = GhostRays(rays.film_mm, flux, rays.du_mm, rays.dv_mm, rays.alive)
            else:  # one geometry: the bands summed into one layer
                one = slice(0, 1)
                layered = GhostRays(
                    rays.film_mm[:, one],
                    flux.sum(axis=1, keepdims=True),
                    rays.du_mm[:, one],
                    rays.dv_mm[:, one],
                    rays.alive[:, one],
                )
            channels[..., c] = splat(layered, self.width, self.height, self.pitch_mm).sum(axis=0)
        return channels[..., 0] if self.cfa is None else self.cfa.mosaic(channels)
