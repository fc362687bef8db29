"""Mitsuba sensor plugin "realisticlens": rays traced from the film through a real lens.

pbrt-v3's RealisticCamera (Pharr, Jakob, Humphreys, section 6.4) in Dr.Jit, vectorised: a film
point, a point on the rear-vertex plane inside the exit-pupil bounds of the film point's radius
bin (rotated to its azimuth), a ray between them traced through every surface towards the scene
with the glass indices at the ray's hero wavelength, and the weight cos^4(theta) A / z^2 so that
a pixel measures film irradiance (E = L pi / (4 N^2) at the centre of an aberration-free lens).

Spectral variants trace each ray at the first of its sampled wavelengths (the hero) and drop
the others: every lane of the ray carries the hero wavelength and its weight, so any film
(hdrfilm, specfilm) averages lanes that agree. One geometric ray refracts one way only.

Properties (dict or XML):
    lens        string  built-in name or prescription file (default "dgauss50")
    efl_mm      float   focal length the lens is scaled to (default: as designed)
    f_number    float   paraxial f-number; the stop closes to it (default: wide open; a
                        value faster than the lens is clamped to wide open, with a warning
                        when it is more than 2 % faster)
    focus_m     float   distance from the film to the sharp object plane, m (default: infinity)
    film_diagonal_mm  float  film diagonal (default 8.0, the DAVIS346); or
    pixel_pitch_um    float  pixel pitch, film size = film pixels x pitch
    dispersion  bool    wavelength-dependent indices (default true)
    tight_pupil bool    sample an ellipse inside the exit-pupil box where smaller (default true)
    pupil_bins  int     film-radius bins of the exit-pupil table (default 32)
    to_world    transform  pose; the film centre is the origin, looking along +z; animatable
Scene units are metres. Pixel (0, 0) is the top-left of the upright image, as with
Mitsuba's perspective sensor. The lens values (lens, efl_mm, f_number, focus_m, film size) are
fixed when the scene loads and are compiled into the kernel; only the pose is a parameter
(`mi.traverse(scene)["<sensor id>.to_world"]`), changed between frames without recompiling.
Film crop windows are honoured. Variants: JIT (llvm, cuda) and scalar; spectral variants
disperse, RGB variants trace at the d line.
"""

from __future__ import annotations

import math
from types import ModuleType
from typing import Any

import numpy as np

from pecs.lens.glass import D_LINE_NM
from pecs.lens.lens import Lens

PLUGIN_NAME = "realisticlens"
DEFAULT_FILM_DIAGONAL_MM = 8.0  # DAVIS346: 346 x 260 px of 18.5 µm
_registered_variants: set[str] = set()
_classes: dict[str, type] = {}


def _mitsuba() -> ModuleType:
    """Mitsuba with its current variant, or with pecs's best variant if none is set yet."""
    import sys

    if "mitsuba" in sys.modules:
        mi = sys.modules["mitsuba"]
        if mi.variant() is not None:
            return mi
    from pecs._mitsuba import mitsuba

    return mitsuba()


def register() -> None:
    """Register "realisticlens" for the current Mitsuba variant (once per variant)."""
    mi = _mitsuba()
    variant = mi.variant()
    if variant in _registered_variants:
        return
    cls = sensor_class(mi)
    mi.register_sensor(PLUGIN_NAME, lambda props: cls(props))
    _registered_variants.add(variant)


def _dr_index(glass: Any, lam_nm: Any, dispersion: bool, dr: ModuleType) -> Any:
    """n(lambda) of a medium as a Dr.Jit expression (the same models as glass.py)."""
    if not dispersion or glass is None or not glass.dispersive:
        return 1.0 if glass is None else float(glass.n_d)
    if glass.catalogue is not None:
        # Past the catalogue's range (silicon responds 360-1100 nm, many glasses are tabulated
        # from 405 nm or to 1014 nm) the index of the range's nearer end: glass.index(clamp=True).
        lo_nm, hi_nm = glass.catalogue.range_nm
        lam_um = dr.clip(lam_nm, lo_nm, hi_nm) * 1e-3
        return dr.sqrt(glass.catalogue.n_squared(dr.square(lam_um)))
    lam2 = dr.square(lam_nm * 1e-3)
    a, b = glass.cauchy_coefficients()
    return float(a) + float(b) / lam2


def sensor_class(mi: ModuleType) -> type:
    """The sensor class for Mitsuba's current variant."""
    variant = mi.variant()
    if variant in _classes:
        return _classes[variant]
    import drjit as dr

    class RealisticLensSensor(mi.Sensor):  # type: ignore[misc, name-defined]
        def __init__(self, props: Any) -> None:
            super().__init__(props)
            lens = Lens.load(props.get("lens", "dgauss50"))
            if "efl_mm" in props:
                lens = lens.scaled_to(float(props.get("efl_mm")))
            if "f_number" in props:
                lens = lens.with_f_number(float(props.get("f_number")), clamp=True)
            focus_m = float(props.get("focus_m", math.inf))
            self.lens = lens.focused(focus_m)
            self.focus_m = focus_m
            self.dispersion = bool(props.get("dispersion", True))
            self.tight_pupil = bool(props.get("tight_pupil", True))
            self._hero = self.dispersion and self.lens.dispersive
            bins = int(props.get("pupil_bins", 32))
            size = self.film().size()
            width_px, height_px = int(size[0]), int(size[1])
            if "pixel_pitch_um" in props:
                pitch_mm = float(props.get("pixel_pitch_um")) * 1e-3
                if "film_diagonal_mm" in props:
                    raise ValueError(
                        "realisticlens: give pixel_pitch_um or film_diagonal_mm, not both"
                    )
            else:
                diagonal_mm = float(props.get("film_diagonal_mm", DEFAULT_FILM_DIAGONAL_MM))
                pitch_mm = diagonal_mm / math.hypot(width_px, height_px)
            if not pitch_mm > 0:
                raise ValueError("realisticlens: the film size must be > 0")
            self.film_mm = (width_px * pitch_mm, height_px * pitch_mm)
            crop_size, crop_offset = self.film().crop_size(), self.film().crop_offset()
            self._crop_scale = tuple(float(crop_size[k]) * pitch_mm for k in range(2))
            self._crop_shift = tuple(
                (float(crop_offset[k]) - 0.5 * float(size[k])) * pitch_mm for k in range(2)
            )
            self.pitch_mm = pitch_mm
            self.m_needs_sample_3 = True
            self._setup_pupil(bins)
            self._setup_pose()

        # -- precomputation ------------------------------------------------------------
        def _setup_pupil(self, bins: int) -> None:
            r_max = 0.5 * math.hypot(*self.film_mm) * 1.0001
            wavelengths = (360.0, 830.0) if self.dispersion else (D_LINE_NM,)
            bounds = self.lens.exit_pupil_bounds(r_max, wavelengths, bins=bins)
            self.pupil = bounds
            boxes = bounds.boxes_mm
            scale = bounds.ellipse_scale if self.tight_pupil else np.zeros(bins)
            self._bins = bins
            self._r_max = r_max
            # Per bin: x0, x1, y0, y1, ellipse scale, area. JIT variants gather from device arrays
            # (opaque inputs, not constants baked into the kernel); scalar variants index numpy.
            table = np.column_stack([boxes, scale, bounds.area_mm2(self.tight_pupil)])
            self._table_np = table
            if dr.is_jit_v(mi.Float):
                self._table = [mi.Float(np.ascontiguousarray(table[:, j])) for j in range(6)]

        def _setup_pose(self) -> None:
            self._to_world = mi.Transform4f(self.m_to_world)
            dr.make_opaque(self._to_world)

        def parameters_changed(self, keys: list[str] | None = None) -> None:
            self._setup_pose()

        def traverse(self, callback: Any) -> None:
            callback.put("to_world", self.m_to_world, mi.ParamFlags.NonDifferentiable)

        # -- ray generation ------------------------------------------------------------
        def _trace(self, film_sample: Any, aperture_sample: Any, lam_nm: Any, active: Any) -> tuple:
            """(origin m, direction, weight, active) in camera space for film samples in [0,1]^2."""
            geometry = self.lens.geometry
            film_z = float(geometry.film_z_mm)
            rear_z = float(geometry.vertex_z_mm[-1])
            # Samples span the film's crop window (as Mitsuba's integrators pass them).
            fx = film_sample.x * self._crop_scale[0] + self._crop_shift[0]
            fy = film_sample.y * self._crop_scale[1] + self._crop_shift[1]
            r = dr.sqrt(dr.square(fx) + dr.square(fy))
            index = mi.UInt32(dr.minimum(r * (self._bins / self._r_max), self._bins - 1))
            if dr.is_jit_v(mi.Float):
                x0, x1, y0, y1, ellipse, area = (
                    dr.gather(mi.Float, column, index, active) for column in self._table
                )
            else:
                x0, x1, y0, y1, ellipse, area = (float(v) for v in self._table_np[int(index)])
            disk = mi.warp.square_to_uniform_disk_concentric(aperture_sample)
            cx, cy = 0.5 * (x0 + x1), 0.5 * (y0 + y1)
            px = dr.select(
                ellipse > 0,
                cx + ellipse * 0.5 * (x1 - x0) * disk.x,
                dr.lerp(x0, x1, aperture_sample.x),
            )
            py = dr.select(
                ellipse > 0,
                cy + ellipse * 0.5 * (y1 - y0) * disk.y,
                dr.lerp(y0, y1, aperture_sample.y),
            )
            # Bins lie along +x: rotate the pupil point to the film point's azimuth.
            inv_r = dr.select(r > 0, dr.rcp(r), 0.0)
            cos_phi = dr.select(r > 0, fx * inv_r, 1.0)
            sin_phi = dr.select(r > 0, fy * inv_r, 0.0)
            px = px + self.pupil.shift * r  # the region slides with the film radius
            tx = cos_phi * px - sin_phi * py
            ty = sin_phi * px + cos_phi * py
            o = mi.Vector3f(fx, fy, film_z)
            d = dr.normalize(mi.Vector3f(tx - fx, ty - fy, rear_z - film_z))
            cos_theta = -d.z
            weight = dr.square(dr.square(cos_theta)) * area / float(film_z - rear_z) ** 2
            active = active & (area > 0)
            media = [None] + [
                None if s.glass.n_d == 1.0 and not s.glass.dispersive else s.glass
                for s in self.lens.surfaces
            ]
            for i, s in enumerate(self.lens.surfaces):  # the stop keeps the medium in front
                if s.is_stop:
                    media[i + 1] = media[i]
            for i in range(len(self.lens.surfaces) - 1, -1, -1):
                surface = self.lens.surfaces[i]
                vz = float(geometry.vertex_z_mm[i])
                radius = float(surface.radius_mm)
                if radius == 0.0:
                    t = (vz - o.z) / d.z
                    hit = t > -1e-6
                else:
                    centre_z = vz + radius
                    oc = mi.Vector3f(o.x, o.y, o.z - centre_z)
                    b = dr.dot(oc, d)
                    c = dr.dot(oc, oc) - radius * radius
                    disc = dr.square(b) - c
                    root = dr.sqrt(dr.maximum(disc, 0.0))
                    # Travelling towards the scene (d.z < 0): the vertex cap is met first when
                    # the centre lies in front (radius < 0).
                    t = -b - root if radius < 0 else -b + root
                    hit = (disc >= 0) & (t > -1e-6)
                p = o + t * d
                semi = float(surface.aperture_mm) * 0.5
                active = active & hit & (dr.square(p.x) + dr.square(p.y) <= semi * semi)
                if radius != 0.0:
                    normal = mi.Vector3f(p.x, p.y, p.z - (vz + radius)) * (1.0 / radius)
                    n_in = _dr_index(media[i + 1], lam_nm, self.dispersion, dr)
                    n_out = _dr_index(media[i], lam_nm, self.dispersion, dr)
                    eta = n_in / n_out
                    cos_i = -dr.dot(d, normal)
                    normal = dr.select(cos_i < 0, -normal, normal)
                    cos_i = dr.abs(cos_i)
                    sin2_t = dr.square(eta) * dr.maximum(0.0, 1.0 - dr.square(cos_i))
                    active = active & (sin2_t <= 1.0)
                    cos_t = dr.sqrt(dr.maximum(0.0, 1.0 - sin2_t))
                    d = dr.normalize(eta * d + (eta * cos_i - cos_t) * normal)
                o = p
            # Lens space (film at film_z, scene towards -z) to camera space (film at the origin,
            # scene towards +z), mm to m.
            origin = mi.Point3f(o.x * 1e-3, o.y * 1e-3, (film_z - o.z) * 1e-3)
            direction = mi.Vector3f(d.x, d.y, -d.z)
            direction = dr.select(active, direction, mi.Vector3f(0, 0, 1))
            return origin, direction, dr.select(active, weight, 0.0), active

        def _wavelengths(self, wavelength_sample: Any, active: Any) -> tuple:
            """(wavelengths, their weight, hero) with every lane set to the hero wavelength."""
            if not mi.is_spectral:
                return mi.Color0f(), mi.Spectrum(1.0), mi.Float(D_LINE_NM)
            wavelengths, wav_weight = self.sample_wavelengths(
                dr.zeros(mi.SurfaceInteraction3f), wavelength_sample, active
            )
            hero = wavelengths[0]
            if not self._hero:  # the geometry is the same at every wavelength: keep them all
                return wavelengths, wav_weight, hero
            return type(wavelengths)(hero), mi.Spectrum(wav_weight[0]), hero

        def sample_ray(
            self,
            time: Any,
            wavelength_sample: Any,
            position_sample: Any,
            aperture_sample: Any,
            active: Any = True,
        ) -> tuple:
            wavelengths, wav_weight, hero = self._wavelengths(wavelength_sample, active)
            origin, direction, weight, active = self._trace(
                position_sample, aperture_sample, hero, mi.Bool(active)
            )
            ray = mi.Ray3f(self._to_world @ origin, self._to_world @ direction, time, wavelengths)
            return ray, wav_weight * weight

        def sample_ray_differential(
            self,
            time: Any,
            wavelength_sample: Any,
            position_sample: Any,
            aperture_sample: Any,
            active: Any = True,
        ) -> tuple:
            ray, weight = self.sample_ray(
                time, wavelength_sample, position_sample, aperture_sample, active
            )
            out = mi.RayDifferential3f(ray)
            # One pixel turns a ray by about pitch / f (the image is inverted): a pinhole's
            # differentials, enough for texture filtering, without tracing two more rays.
            step = float(self.pitch_mm / self.lens.efl_mm())
            out.o_x = ray.o
            out.o_y = ray.o
            out.d_x = dr.normalize(ray.d - self._to_world @ mi.Vector3f(step, 0, 0))
            out.d_y = dr.normalize(ray.d - self._to_world @ mi.Vector3f(0, step, 0))
            out.has_differentials = True
            return out, weight

        def bbox(self) -> Any:
            # The film centre and the lens in front of it (within its total track of it).
            matrix = np.array(self.m_to_world.matrix, dtype=np.float64).reshape(4, 4)
            centre = matrix[:3, 3]
            reach = self.lens.total_track_mm * 1e-3
            return mi.ScalarBoundingBox3f(
                mi.ScalarPoint3f(*(centre - reach)), mi.ScalarPoint3f(*(centre + reach))
            )

        def to_string(self) -> str:
            return (
                f"RealisticLensSensor[lens={self.lens.name}, efl_mm={self.lens.efl_mm():.4g}, "
                f"f_number={self.lens.f_number():.3g}, focus_m={self.focus_m}, "
                f"film_mm={self.film_mm[0]:.4g}x{self.film_mm[1]:.4g}, dispersion={self.dispersion}]"
            )

    _classes[variant] = RealisticLensSensor
    return RealisticLensSensor
