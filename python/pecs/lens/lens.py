"""`pecs.Lens`: a sequential spherical lens with first-order optics and a float64 ray tracer."""

from __future__ import annotations

import warnings
from dataclasses import replace
from functools import cached_property
from pathlib import Path

import numpy as np
from numpy.typing import ArrayLike

from pecs._data import scenes_dir
from pecs.lens import paraxial
from pecs.lens.glass import C_LINE_NM, D_LINE_NM, F_LINE_NM
from pecs.lens.prescription import (
    Surface,
    format_prescription,
    parse_prescription,
    read_prescription,
)
from pecs.lens.pupil import PupilBounds, bound_exit_pupil
from pecs.lens.raytrace import Geometry, Rays, propagate_to_z, sphere_sag_mm, trace

# Film sizes (width, height) in mm of event sensors: pixel count x pitch from the data sheets
# (DAVIS346: 346 x 260 px of 18.5 µm; DVXplorer: 640 x 480 px of 9 µm; Prophesee IMX636:
# 1280 x 720 px of 4.86 µm).
SENSOR_FILM_MM = {
    "davis346": (346 * 18.5e-3, 260 * 18.5e-3),
    "dvxplorer": (640 * 9e-3, 480 * 9e-3),
    "imx636": (1280 * 4.86e-3, 720 * 4.86e-3),
}
_BUILTIN_SUFFIX = ".lens"


def builtin_lens_dir() -> Path:
    """Folder of the built-in prescriptions (pecs/scenes/lenses, shipped in the package)."""
    candidate = scenes_dir() / "lenses"
    if not candidate.is_dir():
        raise FileNotFoundError(f"the built-in lens folder {candidate} was not found")
    return candidate


def sensor_film_mm(sensor: str | tuple[float, float]) -> tuple[float, float]:
    """Film (width, height) in mm of a sensor preset name or an explicit pair."""
    if isinstance(sensor, str):
        if sensor.lower() not in SENSOR_FILM_MM:
            raise ValueError(f"unknown sensor {sensor!r}; known: {', '.join(SENSOR_FILM_MM)}")
        return SENSOR_FILM_MM[sensor.lower()]
    width, height = (float(v) for v in sensor)
    if not (width > 0 and height > 0):
        raise ValueError(f"film size must be positive, got {sensor}")
    return width, height


class Lens:
    """A lens prescription (surfaces from the scene side) and its film distance.

    Lengths in mm; z in lens space runs from the first vertex (z = 0) towards the film.
    """

    def __init__(self, surfaces: list[Surface], name: str = "lens") -> None:
        self.surfaces = tuple(surfaces)
        self.name = name
        _validate(self.surfaces)
        self.stop_index = next(i for i, s in enumerate(self.surfaces) if s.is_stop)
        _check_transmits(self)

    # -- construction ---------------------------------------------------------------------
    @staticmethod
    def builtin_names() -> list[str]:
        """Names of the prescriptions shipped with pecs, for `Lens.builtin` and `--lens`."""
        return sorted(p.stem for p in builtin_lens_dir().glob("*" + _BUILTIN_SUFFIX))

    @classmethod
    def builtin(cls, name: str) -> Lens:
        """A built-in lens: dgauss50, wide22, telephoto250, fisheye10, pecs4."""
        path = builtin_lens_dir() / (name + _BUILTIN_SUFFIX)
        if not path.is_file():
            raise ValueError(
                f"unknown built-in lens {name!r}; known: {', '.join(cls.builtin_names())}"
            )
        return cls.from_file(path)

    @classmethod
    def from_file(cls, path: str | Path) -> Lens:
        """A lens from a prescription file (pbrt's four columns plus a glass column); a bad
        surface is a ValueError naming the file."""
        name, surfaces = read_prescription(path)
        try:
            return cls(surfaces, name)
        except ValueError as error:  # name the file as well as the surface
            raise ValueError(f"{path}: {error}") from None

    @classmethod
    def from_text(cls, text: str, name: str = "lens") -> Lens:
        """A lens from the text of a prescription file; `name` where the text names none."""
        parsed_name, surfaces = parse_prescription(text)
        return cls(surfaces, parsed_name or name)

    @classmethod
    def load(cls, name_or_path: str | Path) -> Lens:
        """A built-in name, or a prescription file."""
        text = str(name_or_path)
        if text in cls.builtin_names():
            return cls.builtin(text)
        if not Path(text).is_file():
            raise FileNotFoundError(
                f"{text!r} is neither a built-in lens ({', '.join(cls.builtin_names())}) nor a file"
            )
        return cls.from_file(text)

    def to_text(self) -> str:
        """The prescription file's text, which `from_text` reads back."""
        return format_prescription(self.name, list(self.surfaces))

    def scaled(self, factor: float) -> Lens:
        """Every length multiplied by `factor` (same f-number, field of view and glass)."""
        if not factor > 0:
            raise ValueError(f"scale factor must be > 0, got {factor}")
        return Lens([s.scaled(factor) for s in self.surfaces], self.name)

    def scaled_to(self, efl_mm: float) -> Lens:
        """The lens scaled so that its focal length at the d line is `efl_mm`."""
        if not efl_mm > 0:
            raise ValueError(f"efl_mm must be > 0, got {efl_mm}")
        return self.scaled(efl_mm / self.efl_mm())

    def with_f_number(self, f_number: float, clamp: bool = False) -> Lens:
        """The stop closed down to paraxial f-number `f_number` (at infinity focus, d line).

        A value faster than the widest aperture raises ValueError, or with clamp=True gives the
        lens wide open: silently within 2 % (a nominal "f/2" lens may be f/2.03 paraxially),
        with a warning beyond (as pbrt does)."""
        if not f_number > 0:
            raise ValueError(f"f_number must be > 0, got {f_number}")
        widest = self.f_number()
        if clamp and f_number < widest:
            if f_number < 0.98 * widest:
                warnings.warn(
                    f"f_number {f_number:g} is faster than {self.name}'s widest aperture; "
                    f"using f/{widest:.3g}",
                    RuntimeWarning,
                    stacklevel=2,
                )
            return self
        if not f_number >= widest * (1 - 1e-9):
            raise ValueError(
                f"f_number {f_number:g} is faster than this lens's widest aperture f/{widest:.3g}"
            )
        stop = self.surfaces[self.stop_index]
        surfaces = list(self.surfaces)
        surfaces[self.stop_index] = replace(
            stop, aperture_mm=float(stop.aperture_mm * widest / f_number)
        )
        return Lens(surfaces, self.name)

    def with_film_distance(self, film_distance_mm: float) -> Lens:
        """The lens with the last vertex-to-film distance set."""
        if not film_distance_mm >= 0:
            raise ValueError(f"film distance must be >= 0, got {film_distance_mm}")
        surfaces = list(self.surfaces)
        surfaces[-1] = replace(surfaces[-1], thickness_mm=float(film_distance_mm))
        return Lens(surfaces, self.name)

    def focused(self, focus_m: float, wavelength_nm: float = D_LINE_NM) -> Lens:
        """The film moved so that an object `focus_m` metres in front of the film is sharp
        (paraxial thick lens); focus_m = inf focuses at infinity."""
        if not focus_m > 0:
            raise ValueError(f"focus_m must be > 0, got {focus_m}")
        fo = self.first_order(wavelength_nm)
        return self.with_film_distance(paraxial.film_distance_for_focus(fo, focus_m * 1e3))

    # -- geometry and media ---------------------------------------------------------------
    @cached_property
    def geometry(self) -> Geometry:
        """Per-surface vertex positions, radii and semi-apertures (mm) for the ray tracer."""
        thickness = np.array([s.thickness_mm for s in self.surfaces])
        vertex_z = np.concatenate([[0.0], np.cumsum(thickness[:-1])])
        return Geometry(
            vertex_z_mm=vertex_z,
            radius_mm=np.array([s.radius_mm for s in self.surfaces]),
            semi_aperture_mm=np.array([s.aperture_mm / 2 for s in self.surfaces]),
            film_z_mm=float(np.sum(thickness)),
        )

    @property
    def film_distance_mm(self) -> float:
        """Last vertex to film, mm (the last surface's thickness)."""
        return self.surfaces[-1].thickness_mm

    @property
    def total_track_mm(self) -> float:
        """First vertex to film."""
        return self.geometry.film_z_mm

    @property
    def dispersive(self) -> bool:
        """Whether any glass's index depends on wavelength (a catalogue glass or an Abbe
        number), so that rays of different wavelengths take different paths."""
        return any(s.glass.dispersive for s in self.surfaces)

    def media_indices(
        self, wavelength_nm: ArrayLike = D_LINE_NM, clamp: bool = False
    ) -> np.ndarray:
        """Index in front of surface 0 then behind each surface: shape (S + 1,) + shape(lambda).

        The stop repeats the medium in front of it. A wavelength outside a catalogue glass's
        range is a ValueError, or with `clamp` takes the index at the range's nearer end (as
        the renderer does)."""
        lam = np.asarray(wavelength_nm, dtype=np.float64)
        media = [np.ones_like(lam)]
        for s in self.surfaces:
            media.append(media[-1] if s.is_stop else s.glass.index(lam, clamp))
        return np.stack(media)

    # -- first-order optics ---------------------------------------------------------------
    def first_order(self, wavelength_nm: float = D_LINE_NM) -> paraxial.FirstOrder:
        """Paraxial cardinal points and pupils at `wavelength_nm` (default the d line,
        587.56 nm): focal lengths, principal planes, entrance and exit pupils, in mm."""
        n = self.media_indices(wavelength_nm)
        return paraxial.first_order(
            np.array([s.curvature_per_mm for s in self.surfaces]),
            np.array([s.thickness_mm for s in self.surfaces]),
            n[:-1],
            n[1:],
            self.stop_index,
            self.surfaces[self.stop_index].aperture_mm,
        )

    def efl_mm(self, wavelength_nm: float = D_LINE_NM) -> float:
        """Effective (paraxial) focal length."""
        return float(self.first_order(wavelength_nm).efl_mm)

    def bfl_mm(self, wavelength_nm: float = D_LINE_NM) -> float:
        """Back focal length: last vertex to the rear focal point."""
        return float(self.first_order(wavelength_nm).bfl_mm)

    def f_number(self, wavelength_nm: float = D_LINE_NM) -> float:
        """Paraxial f-number at infinity focus: EFL / entrance pupil diameter."""
        return float(self.first_order(wavelength_nm).f_number)

    def entrance_pupil(self, wavelength_nm: float = D_LINE_NM) -> tuple[float, float]:
        """(z from the first vertex, diameter) of the entrance pupil, mm."""
        fo = self.first_order(wavelength_nm)
        return float(fo.entrance_pupil_z_mm), float(fo.entrance_pupil_diameter_mm)

    def exit_pupil(self, wavelength_nm: float = D_LINE_NM) -> tuple[float, float]:
        """(z from the first vertex, diameter) of the exit pupil, mm."""
        fo = self.first_order(wavelength_nm)
        return float(fo.exit_pupil_z_mm), float(fo.exit_pupil_diameter_mm)

    def longitudinal_chromatic_aberration_mm(
        self, wavelength_nm: ArrayLike = (F_LINE_NM, D_LINE_NM, C_LINE_NM)
    ) -> np.ndarray:
        """Paraxial focal shift BFL(lambda) - BFL(d line) at each wavelength, mm."""
        d = self.bfl_mm(D_LINE_NM)
        return np.array([self.bfl_mm(float(w)) - d for w in np.atleast_1d(wavelength_nm)])

    # -- real rays ------------------------------------------------------------------------
    def trace_from_film(
        self, origin: np.ndarray, direction: np.ndarray, wavelength_nm: ArrayLike = D_LINE_NM
    ) -> Rays:
        """Trace rays that start on the film side towards the scene (lens space, mm)."""
        return trace(self.geometry, self.media_indices(wavelength_nm), origin, direction, False)

    def trace_from_scene(
        self, origin: np.ndarray, direction: np.ndarray, wavelength_nm: ArrayLike = D_LINE_NM
    ) -> Rays:
        """Trace rays that start in the scene (z < first vertex) towards the film."""
        return trace(self.geometry, self.media_indices(wavelength_nm), origin, direction, True)

    def exit_pupil_bounds(
        self,
        film_radius_max_mm: float,
        wavelengths_nm: ArrayLike = (400.0, 700.0),
        bins: int = 32,
        grid: int = 40,
    ) -> PupilBounds:
        """Rear-plane regions that pass rays, per bin of film radius (union over wavelengths;
        past a glass's catalogue range, its index at the range's end, as the renderer traces)."""
        media = [self.media_indices(float(w), clamp=True) for w in np.atleast_1d(wavelengths_nm)]
        try:
            xp_z: float | None = self.exit_pupil()[0]
        except ValueError:  # no power or a telecentric back: regions do not slide
            xp_z = None
        return bound_exit_pupil(
            self.geometry, media, film_radius_max_mm, bins, grid, exit_pupil_z_mm=xp_z
        )

    def chief_ray_angle_deg(
        self, film_height_mm: ArrayLike, wavelength_nm: float = D_LINE_NM
    ) -> np.ndarray:
        """Object-space field angle of the ray from film height h (on +x) through the stop centre.

        Apertures are ignored (the chief ray defines the field even where it is vignetted)."""
        heights = np.atleast_1d(np.asarray(film_height_mm, dtype=np.float64))
        return np.array([_chief_ray_angle(self, float(h), wavelength_nm) for h in heights])

    def field_of_view_deg(self, sensor: str | tuple[float, float] = "davis346") -> dict[str, float]:
        """Full horizontal, vertical and diagonal field of view (real chief rays) for a sensor
        preset name or a film (width_mm, height_mm), at the current film distance."""
        width, height = sensor_film_mm(sensor)
        half = self.chief_ray_angle_deg([width / 2, height / 2, np.hypot(width, height) / 2])
        return {
            "horizontal": 2 * float(half[0]),
            "vertical": 2 * float(half[1]),
            "diagonal": 2 * float(half[2]),
        }

    def distortion_percent(
        self, film_height_mm: ArrayLike, wavelength_nm: float = D_LINE_NM
    ) -> np.ndarray:
        """100 (h - f tan theta) / (f tan theta): real image height against the paraxial one for
        the chief ray's field angle theta (infinity focus assumed for f)."""
        h = np.atleast_1d(np.asarray(film_height_mm, dtype=np.float64))
        ideal = self.efl_mm(wavelength_nm) * np.tan(
            np.radians(self.chief_ray_angle_deg(h, wavelength_nm))
        )
        return 100.0 * (h - ideal) / ideal

    def irradiance_ratio(
        self, film_radius_mm: ArrayLike, wavelength_nm: float = D_LINE_NM, grid: int = 256
    ) -> np.ndarray:
        """Film irradiance over scene radiance, E / L, at film radii (on +x).

        E / L = integral over the rear-vertex plane of cos^4(theta) / z^2 dA for the points whose
        rays pass (radiance is conserved through the lens in air; pbrt-v3 eq. 6.3)."""
        radii = np.atleast_1d(np.asarray(film_radius_mm, dtype=np.float64))
        r_max = float(radii.max()) * 1.0001 + 1e-9
        bounds = self.exit_pupil_bounds(r_max, (wavelength_nm,), bins=max(8, len(radii)), grid=48)
        out = []
        n = self.media_indices(wavelength_nm)
        dz = self.geometry.film_z_mm - bounds.rear_z_mm
        for r in radii:
            x0, x1, y0, y1 = bounds.boxes_mm[bounds.bin_of(r)]
            if x1 <= x0:
                out.append(0.0)
                continue
            x0, x1 = bounds.to_rear_plane(np.array([x0, x1]), r)
            xs = x0 + (np.arange(grid) + 0.5) * (x1 - x0) / grid
            ys = y0 + (np.arange(grid) + 0.5) * (y1 - y0) / grid
            gx, gy = (a.ravel() for a in np.meshgrid(xs, ys))
            start = np.column_stack(
                [np.full_like(gx, r), np.zeros_like(gx), np.full_like(gx, self.geometry.film_z_mm)]
            )
            target = np.column_stack([gx, gy, np.full_like(gx, bounds.rear_z_mm)])
            d = target - start
            cos_theta = dz / np.linalg.norm(d, axis=1)
            rays = trace(self.geometry, n, start, d, towards_film=False)
            cell = (x1 - x0) * (y1 - y0) / grid**2
            out.append(float(np.sum(cos_theta[rays.alive] ** 4)) * cell / dz**2)
        return np.array(out)

    def relative_illumination(
        self, film_radius_mm: ArrayLike, wavelength_nm: float = D_LINE_NM
    ) -> np.ndarray:
        """Irradiance at each film radius over the irradiance at the centre (vignetting + cos^4)."""
        radii = np.atleast_1d(np.asarray(film_radius_mm, dtype=np.float64))
        e = self.irradiance_ratio(np.concatenate([[0.0], radii]), wavelength_nm)
        return e[1:] / e[0]

    def spot_diagram(
        self,
        field_deg: float = 0.0,
        wavelength_nm: float = D_LINE_NM,
        rays_per_side: int = 64,
        object_distance_m: float = np.inf,
    ) -> np.ndarray:
        """Film positions (N, 2), mm, of rays from a point at `field_deg` (in the x-z plane; its
        image lies on +x) filling the entrance pupil, on the film at the current film distance.
        The point is at infinity or `object_distance_m` in front of the film."""
        theta = np.radians(field_deg)
        axis_direction = np.array([np.sin(theta), 0.0, np.cos(theta)])
        first = self.surfaces[0]
        a = first.aperture_mm / 2
        z0 = min(0.0, sphere_sag_mm(first.radius_mm, a)) - 1.0
        source = None
        if np.isfinite(object_distance_m):
            distance = object_distance_m * 1e3 - (self.geometry.film_z_mm - z0)
            source = np.array([-np.tan(theta) * distance, 0.0, z0 - distance])
        # Rays that can pass cross the plane z0 near the first aperture.
        reach = a + 2 * abs(sphere_sag_mm(first.radius_mm, a)) * abs(np.tan(theta)) + 1.0
        lo, hi = np.array([-reach, -reach]), np.array([reach, reach])
        n = self.media_indices(wavelength_nm)
        for _ in range(2):  # coarse grid, then a fine grid over where rays passed
            xs, ys = (
                np.linspace(lo[0], hi[0], rays_per_side),
                np.linspace(lo[1], hi[1], rays_per_side),
            )
            gx, gy = (v.ravel() for v in np.meshgrid(xs, ys))
            start = np.column_stack([gx, gy, np.full_like(gx, z0)])
            direction = np.tile(axis_direction, (len(gx), 1)) if source is None else start - source
            rays = trace(self.geometry, n, start, direction, towards_film=True)
            passed = start[rays.alive, :2]
            if len(passed) == 0:
                raise ValueError(f"no ray of field {field_deg} deg reaches the film of {self.name}")
            cell = (hi - lo) / (rays_per_side - 1)
            lo, hi = passed.min(axis=0) - cell, passed.max(axis=0) + cell
        alive = rays.alive
        return propagate_to_z(
            Rays(rays.origin[alive], rays.direction[alive], rays.blocked_at[alive]),
            self.geometry.film_z_mm,
        )

    def plot(
        self, path: str | Path | None = None, field_deg: float | None = None, ax: object = None
    ) -> object:
        """Layout with traced rays (matplotlib); saved to `path` when given. Returns the figure."""
        from pecs.lens.plot import plot_layout

        return plot_layout(self, path=path, field_deg=field_deg, ax=ax)

    def __repr__(self) -> str:
        return f"Lens({self.name!r}, efl_mm={self.efl_mm():.4g}, f/{self.f_number():.3g}, surfaces={len(self.surfaces)})"


def _validate(surfaces: tuple[Surface, ...]) -> None:
    """Geometry that cannot be a lens raises ValueError naming the surface (0 = scene side)."""
    stops = [i for i, s in enumerate(surfaces) if s.is_stop]
    if not stops:
        raise ValueError("no aperture stop: one surface must have radius 0")
    if len(stops) > 1:
        raise ValueError(f"surfaces {stops} are all stops (radius 0); a lens has one")
    for i, s in enumerate(surfaces):
        if not np.isfinite([s.radius_mm, s.thickness_mm, s.aperture_mm]).all():
            raise ValueError(f"surface {i}: non-finite value")
        if s.thickness_mm < 0:
            raise ValueError(f"surface {i}: negative thickness {s.thickness_mm} mm")
        if not s.aperture_mm > 0:
            raise ValueError(f"surface {i}: aperture diameter must be > 0, got {s.aperture_mm}")
        if s.radius_mm != 0 and s.aperture_mm / 2 > abs(s.radius_mm):
            raise ValueError(
                f"surface {i}: aperture diameter {s.aperture_mm} mm is larger than its sphere "
                f"(radius {s.radius_mm} mm)"
            )
    for i in range(len(surfaces) - 1):
        a, b = surfaces[i], surfaces[i + 1]
        h = np.linspace(0, min(a.aperture_mm, b.aperture_mm) / 2, 16)
        gap = a.thickness_mm + np.array(
            [sphere_sag_mm(b.radius_mm, x) - sphere_sag_mm(a.radius_mm, x) for x in h]
        )
        if gap.min() < -1e-9:
            raise ValueError(
                f"surfaces {i} and {i + 1} cross inside their apertures (thickness {a.thickness_mm} mm "
                f"is too small for their curvatures)"
            )


def _check_transmits(lens: Lens) -> None:
    """A collimated on-axis beam over the first aperture must reach the film; else name the
    surface that stopped the last rays."""
    a = lens.surfaces[0].aperture_mm / 2
    xs = np.linspace(-a, a, 41)
    gx, gy = (v.ravel() for v in np.meshgrid(xs, xs))
    z0 = min(0.0, sphere_sag_mm(lens.surfaces[0].radius_mm, a)) - 1.0
    start = np.column_stack([gx, gy, np.full_like(gx, z0)])
    direction = np.tile([0.0, 0.0, 1.0], (len(gx), 1))
    rays = lens.trace_from_scene(start, direction)
    if not rays.alive.any():
        last = int(rays.blocked_at.max())
        raise ValueError(
            f"no ray passes through the lens {lens.name!r}: surface {last} stops the last rays"
        )


def _chief_ray_angle(lens: Lens, film_height_mm: float, wavelength_nm: float) -> float:
    """Field angle (deg) of the ray from (h, 0, film) that crosses the stop centre (secant method)."""
    geometry = lens.geometry
    open_geometry = replace(
        geometry, semi_aperture_mm=np.full_like(geometry.semi_aperture_mm, np.inf)
    )
    k = lens.stop_index
    back = Geometry(
        open_geometry.vertex_z_mm[k + 1 :],
        open_geometry.radius_mm[k + 1 :],
        open_geometry.semi_aperture_mm[k + 1 :],
        geometry.film_z_mm,
    )
    n = lens.media_indices(wavelength_nm)
    stop_z = geometry.vertex_z_mm[k]
    film = np.array([[film_height_mm, 0.0, geometry.film_z_mm]])

    def stop_height(slope: float) -> float:
        d = np.array([[slope, 0.0, -1.0]])
        rays = trace(back, n[k + 1 :], film, d, towards_film=False)
        if not rays.alive[0]:
            return np.nan
        return float(propagate_to_z(rays, stop_z)[0, 0])

    # Start from the paraxial exit-pupil direction, then secant iterations on the stop height.
    xp_z, _ = lens.exit_pupil(wavelength_nm)
    s0 = -film_height_mm / (geometry.film_z_mm - xp_z)
    s1 = s0 * 1.01 + 1e-6
    f0, f1 = stop_height(s0), stop_height(s1)
    for _ in range(50):
        if not (np.isfinite(f0) and np.isfinite(f1)) or f1 == f0:
            break
        s0, s1, f0 = s1, s1 - f1 * (s1 - s0) / (f1 - f0), f1
        f1 = stop_height(s1)
        if abs(f1) < 1e-10:
            break
    if not np.isfinite(f1) or abs(f1) > 1e-6:
        return np.nan
    rays = trace(open_geometry, n, film, np.array([[s1, 0.0, -1.0]]), towards_film=False)
    if not rays.alive[0]:
        return np.nan
    d = rays.direction[0]
    return float(np.degrees(np.arctan2(np.hypot(d[0], d[1]), -d[2])))
