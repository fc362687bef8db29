"""Lens ghosts: every two-reflection path through the lens, traced deterministically.

Hullin, Eisemann, Seidel and Lee, "Physically-based real-time lens flare rendering", SIGGRAPH
2011: light from a bright point enters the lens, reflects backwards at surface i, forwards again
at an earlier surface j < i, and goes on to the film. Each path is traced as a fixed grid of
rays over the part of the entrance plane whose rays survive it (found by a coarse pass); every
ray carries its cell's flux times the reflectance R at the two reflecting surfaces and (1 - R)
at every surface it crosses (coating.py's Airy sum, at its angle and wavelength); the rays are
traced in Rust (pecs_core's ghost module), built and splatted here. The flux lands on the
film spread over the quad its grid cell maps to (a k x k sub-grid of the cell's film Jacobian,
splatted bilinearly), so irradiance = flux / quad area, with no random numbers: a static source
gives the same ghost image every time. Optional reflectors behind the lens: the sensor's cover
glass (two flat, coated faces of a plate) and the sensor die itself (a flat reflectance).

Lens space as raytrace.py: z along the axis from the first vertex, light towards +z, mm.
"""

from __future__ import annotations

from collections.abc import Container
from dataclasses import dataclass, field

import numpy as np
from numpy.typing import ArrayLike

from pecs import _core
from pecs.lens.coating import Coating, reflectance
from pecs.lens.lens import Lens
from pecs.lens.raytrace import sphere_sag_mm

COARSE_RAYS_PER_SIDE = 12
DEFAULT_RAYS_PER_SIDE = 16
_MAX_SUBSAMPLES = 16


@dataclass(frozen=True)
class CoverGlass:
    """The sensor's cover glass: a flat plate `gap_mm` in front of the die (its back face to the
    die), and optionally the die as a reflector (`sensor_reflectance`, 0: not a reflector).

    Defaults: a 0.5 mm borosilicate plate (n 1.52, no dispersion) 0.5 mm from the die, both faces
    with the default quarter-wave coating; typical of packaged image sensors, not a data sheet."""

    thickness_mm: float = 0.5
    index: float = 1.52
    gap_mm: float = 0.5
    coating: Coating | None = field(default_factory=Coating)
    sensor_reflectance: float = 0.0

    def __post_init__(self) -> None:
        if not self.thickness_mm > 0:
            raise ValueError(f"cover_glass thickness_mm must be > 0, got {self.thickness_mm}")
        if not self.index >= 1.0:
            raise ValueError(f"cover_glass index must be >= 1, got {self.index}")
        if not self.gap_mm >= 0:
            raise ValueError(f"cover_glass gap_mm must be >= 0, got {self.gap_mm}")
        if not 0.0 <= self.sensor_reflectance < 1.0:
            raise ValueError(
                f"cover_glass sensor_reflectance must be in [0, 1), got {self.sensor_reflectance}"
            )


@dataclass(frozen=True)
class GhostOptions:
    """What reflects: `coatings` is one coating for every lens surface or one per surface (None:
    bare glass); `cover_glass` adds the plate (and the die) in front of the film."""

    coatings: Coating | None | tuple[Coating | None, ...] = field(default_factory=Coating)
    cover_glass: CoverGlass | None = None
    rays_per_side: int = DEFAULT_RAYS_PER_SIDE
    #: Paths whose R_i R_j (normal incidence, 550 nm) is below this fraction of the brightest
    #: path's are not traced (a cemented surface's ideal film reflects ~1e-12).
    min_relative_energy: float = 1e-3
    #: Trace each wavelength's own ray paths (glass dispersion bends them apart: coloured ghost
    #: edges); False: one geometry at the middle wavelength, reflectances at every wavelength
    #: (the coatings' colour), a third of the cost with three bands.
    dispersion: bool = False

    def __post_init__(self) -> None:
        if not 4 <= self.rays_per_side <= 512:
            raise ValueError(f"rays_per_side must be in [4, 512], got {self.rays_per_side}")
        if not 0.0 <= self.min_relative_energy < 1.0:
            raise ValueError(
                f"min_relative_energy must be in [0, 1), got {self.min_relative_energy}"
            )


@dataclass(frozen=True)
class GhostPath:
    """Reflect backwards at surface `first`, forwards again at `second` < `first` (indices
    into `GhostSystem.names`)."""

    first: int
    second: int


class GhostSystem:
    """The reflecting and refracting surfaces of a lens (plus the cover glass and die) in the
    order light meets them, with each surface's coating film resolved."""

    def __init__(self, lens: Lens, options: GhostOptions | None = None) -> None:
        options = options or GhostOptions()
        self.lens, self.options = lens, options
        g = lens.geometry
        count = len(lens.surfaces)
        coatings = options.coatings
        if isinstance(coatings, tuple):
            if len(coatings) != count:
                raise ValueError(
                    f"coatings: {len(coatings)} given for the {count} surfaces of {lens.name}"
                )
            per_surface = list(coatings)
        else:
            per_surface = [coatings] * count
        self.z_mm = list(g.vertex_z_mm)
        self.radius_mm = list(g.radius_mm)
        self.semi_mm = list(g.semi_aperture_mm)
        self.names = [f"surface {i}" for i in range(count)]
        self.reflector = [not s.is_stop for s in lens.surfaces]
        self.coatings: list[Coating | None] = [
            None if s.is_stop else c for s, c in zip(lens.surfaces, per_surface, strict=True)
        ]
        self.fixed_reflectance = [-1.0] * count
        self.film_z_mm = float(g.film_z_mm)
        # The plate's index after each of its faces; None: the lens's media.
        self._extra_index: list[float] = []
        plate = options.cover_glass
        if plate is not None:
            back_z = self.film_z_mm - plate.gap_mm
            front_z = back_z - plate.thickness_mm
            if front_z <= g.vertex_z_mm[-1] + max(
                0.0, sphere_sag_mm(g.radius_mm[-1], g.semi_aperture_mm[-1])
            ):
                raise ValueError(
                    f"cover_glass: the plate ({plate.thickness_mm} mm + gap {plate.gap_mm} mm) "
                    f"does not fit between {lens.name}'s last surface and the film"
                )
            reach = float(np.inf)
            self.z_mm += [front_z, back_z]
            self.radius_mm += [0.0, 0.0]
            self.semi_mm += [reach, reach]
            self.names += ["cover glass front", "cover glass back"]
            self.reflector += [True, True]
            self.coatings += [plate.coating, plate.coating]
            self.fixed_reflectance += [-1.0, -1.0]
            self._extra_index = [plate.index, 1.0]
            if plate.sensor_reflectance > 0:
                self.z_mm.append(self.film_z_mm)
                self.radius_mm.append(0.0)
                self.semi_mm.append(reach)
                self.names.append("sensor")
                self.reflector.append(True)
                self.coatings.append(None)
                self.fixed_reflectance.append(plate.sensor_reflectance)
                self._extra_index.append(1.0)

    @property
    def surface_count(self) -> int:
        """Surfaces in the order light meets them (lens, then cover glass and die)."""
        return len(self.z_mm)

    def paths(self) -> list[GhostPath]:
        """Every pair of reflectors (first > second): N (N - 1) / 2 for N reflectors."""
        reflectors = [k for k in range(self.surface_count) if self.reflector[k]]
        return [GhostPath(i, j) for i in reflectors for j in reflectors if j < i]

    def normal_reflectance(self, wavelength_nm: float = 550.0) -> np.ndarray:
        """Each surface's reflectance at normal incidence (0 for the stop)."""
        n = self.media(wavelength_nm)[:, 0]
        n1, d = self.films()
        r = reflectance(n[:-1], n[1:], 1.0, wavelength_nm, n1, d)
        fixed = np.array(self.fixed_reflectance)
        return np.where(fixed >= 0, fixed, r)

    def bright_paths(self) -> list[GhostPath]:
        """`paths()` without those fainter than `options.min_relative_energy` of the brightest."""
        paths = self.paths()
        r = self.normal_reflectance()
        energy = np.array([r[p.first] * r[p.second] for p in paths])
        if not len(paths):
            return paths
        keep = energy >= self.options.min_relative_energy * energy.max()
        return [p for p, k in zip(paths, keep, strict=True) if k]

    def media(self, wavelength_nm: ArrayLike) -> np.ndarray:
        """Index in front of surface 0, then behind each surface: (surfaces + 1, L)."""
        lam = np.atleast_1d(np.asarray(wavelength_nm, dtype=np.float64))
        n = self.lens.media_indices(lam, clamp=True)
        extra = [np.full_like(lam, v) for v in self._extra_index]
        return np.concatenate([n, np.array(extra).reshape(-1, len(lam))])

    def films(self) -> tuple[np.ndarray, np.ndarray]:
        """Per surface (film index, thickness nm); thickness 0 where bare."""
        n1, d = np.ones(self.surface_count), np.zeros(self.surface_count)
        for k, coating in enumerate(self.coatings):
            if coating is None:
                continue
            media = self.media(coating.design_wavelength_nm)[:, 0]
            n1[k], d[k] = coating.film(float(media[k]), float(media[k + 1]))
        return n1, d


@dataclass(frozen=True)
class PointSource:
    """A point source: at infinity (`direction`, the direction light travels in lens space,
    towards +z) or at `position_mm` in lens space (z in front of the lens)."""

    direction: tuple[float, float, float] | None = None
    position_mm: tuple[float, float, float] | None = None

    def __post_init__(self) -> None:
        if (self.direction is None) == (self.position_mm is None):
            raise ValueError("a ghost source needs a direction or a position_mm, not both")
        if self.direction is not None and not self.direction[2] > 0:
            raise ValueError("a source at infinity must shine towards the lens (direction z > 0)")

    @staticmethod
    def at_field_angle(field_deg: float, azimuth_deg: float = 0.0) -> PointSource:
        """A source at infinity at `field_deg` off axis; azimuth 0 images on -x (inverted)."""
        theta, phi = np.radians(field_deg), np.radians(azimuth_deg)
        return PointSource(
            direction=(
                float(-np.sin(theta) * np.cos(phi)),
                float(-np.sin(theta) * np.sin(phi)),
                float(np.cos(theta)),
            )
        )


@dataclass
class GhostRays:
    """Traced ghost rays: film positions (..., 2) in mm, flux per unit source irradiance
    (mm^2: the cell's area on a plane facing the source times R and T factors), the grid's
    film Jacobian columns (..., 2) per ray, and which reached the film."""

    film_mm: np.ndarray
    flux_mm2: np.ndarray
    du_mm: np.ndarray
    dv_mm: np.ndarray
    alive: np.ndarray


class GhostTracer:
    """Traces ghost paths of one system for point sources; `image` renders them on a film."""

    def __init__(self, system: GhostSystem, paths: list[GhostPath] | None = None) -> None:
        self.system = system
        self.paths = system.bright_paths() if paths is None else list(paths)
        s = system
        self._z = np.array(s.z_mm)
        self._radius = np.array(s.radius_mm)
        self._semi2 = np.array(s.semi_mm) ** 2
        self._fixed = np.array(s.fixed_reflectance)
        self._film_n1, self._film_d = s.films()
        # Steps of every path (paths, steps): (surface, reflect, forward); padded with -1.
        only_reflect = {k for k in range(s.surface_count) if s.fixed_reflectance[k] >= 0}
        sequences = [_sequence(p, s.surface_count, only_reflect) for p in self.paths]
        steps = max((len(q) for q in sequences), default=0)
        self._step_surface = np.full((len(self.paths), steps), -1, dtype=np.int64)
        self._step_reflect = np.zeros((len(self.paths), steps), dtype=bool)
        self._step_forward = np.ones((len(self.paths), steps), dtype=bool)
        for p, q in enumerate(sequences):
            for k, (surface, reflect, forward) in enumerate(q):
                self._step_surface[p, k] = surface
                self._step_reflect[p, k] = reflect
                self._step_forward[p, k] = forward
        first = s.lens.surfaces[0]
        a = first.aperture_mm / 2
        self._entrance_z = min(0.0, sphere_sag_mm(first.radius_mm, a)) - 1.0
        self._reach_base = a
        self._sag = abs(sphere_sag_mm(first.radius_mm, a)) + 1.0
        try:
            self._pupil_mm = min(float(s.lens.entrance_pupil()[1]), 2 * a)
        except ValueError:  # no paraxial pupil (afocal, telecentric): the front aperture
            self._pupil_mm = 2 * a

    # -- tracing --------------------------------------------------------------------------
    def trace(
        self,
        source: PointSource,
        wavelengths_nm: ArrayLike,
        rays_per_side: int | None = None,
    ) -> GhostRays:
        """Rays of every path at every wavelength: arrays (paths, L, n, n, ...)."""
        return self.trace_many([source], wavelengths_nm, rays_per_side)

    def trace_many(
        self,
        sources: list[PointSource],
        wavelengths_nm: ArrayLike,
        rays_per_side: int | None = None,
    ) -> GhostRays:
        """Rays of every path of every source, traced together: arrays (S * paths, L, n, n,
        ...), source s's paths in rows s * paths ... (s + 1) * paths - 1."""
        n = rays_per_side or self.system.options.rays_per_side
        lam = np.atleast_1d(np.asarray(wavelengths_nm, dtype=np.float64))
        media = self.system.media(lam)
        rows = len(sources) * len(self.paths)
        boxes = self._entrance_boxes(sources, media, lam)
        # Fine grid per path over its box, cell centres.
        frac = (np.arange(n) + 0.5) / n
        x = boxes[:, 0, None] + (boxes[:, 1] - boxes[:, 0])[:, None] * frac  # (rows, n)
        y = boxes[:, 2, None] + (boxes[:, 3] - boxes[:, 2])[:, None] * frac
        cell_mm2 = (boxes[:, 1] - boxes[:, 0]) * (boxes[:, 3] - boxes[:, 2]) / n**2
        spread = self.system.options.dispersion and len(lam) > 1
        geometries = len(lam) if spread else 1
        grid = (rows, geometries, n, n)
        gx = np.broadcast_to(x[:, None, None, :], grid).ravel()
        gy = np.broadcast_to(y[:, None, :, None], grid).ravel()
        row_of = np.broadcast_to(np.arange(rows)[:, None, None, None], grid).ravel()
        if spread:  # each ray at its own wavelength
            lam_of = np.broadcast_to(np.arange(len(lam))[None, :, None, None], grid).ravel()
            weight_lam = lam_of[:, None]
        else:  # one geometry (the middle wavelength), weights at every wavelength
            lam_of = np.full(len(gx), len(lam) // 2)
            weight_lam = np.broadcast_to(np.arange(len(lam)), (len(gx), len(lam)))
        paths = len(self.paths)
        origin, direction = self._rays(sources, row_of // paths, gx, gy)
        film, weight, alive = self._trace(
            origin, direction, row_of % paths, lam_of, weight_lam, media, lam
        )
        shape = (rows, len(lam), n, n)
        if spread:
            weight = weight.reshape(shape)
        else:
            weight = weight.reshape(rows, n, n, len(lam)).transpose(0, 3, 1, 2)
        film = np.broadcast_to(film.reshape(*grid, 2), (*shape, 2))
        alive = np.broadcast_to(alive.reshape(grid), shape) & (cell_mm2 > 0)[:, None, None, None]
        cos = np.broadcast_to(np.abs(direction[:, 2]).reshape(grid), shape)
        # A cell's flux for unit irradiance on a plane facing the source: area * cos.
        flux = weight * cell_mm2[:, None, None, None] * cos
        flux = np.where(alive, flux, 0.0)
        du, dv = _grid_jacobian(film, alive)
        return GhostRays(film, flux, du, dv, alive)

    def _rays(
        self, sources: list[PointSource], which: np.ndarray, gx: np.ndarray, gy: np.ndarray
    ) -> tuple[np.ndarray, np.ndarray]:
        """Rays from source `which` (per ray) through the entrance-plane points (gx, gy)."""
        origin = np.column_stack([gx, gy, np.full_like(gx, self._entrance_z)])
        at_infinity = np.array([s.direction is not None for s in sources])
        vector = np.array(
            [s.direction if s.direction is not None else s.position_mm for s in sources],
            dtype=np.float64,
        )
        v = vector[which]
        direction = np.where(at_infinity[which][:, None], v, origin - v)
        direction /= np.linalg.norm(direction, axis=1, keepdims=True)
        return origin, direction

    def _entrance_boxes(
        self, sources: list[PointSource], media: np.ndarray, lam: np.ndarray
    ) -> np.ndarray:
        """Per source and path (x0, x1, y0, y1) on the entrance plane that holds its surviving
        rays (a coarse pass at the middle wavelength, one coarse cell of margin)."""
        reach = np.empty(len(sources))
        for k, source in enumerate(sources):
            if source.direction is not None:
                d = np.array(source.direction, dtype=np.float64)
            else:
                d = -np.array(source.position_mm, dtype=np.float64)
                d[2] += self._entrance_z
            tan = np.hypot(d[0], d[1]) / abs(d[2])
            reach[k] = self._reach_base + 2 * self._sag * tan + 1.0
        # Spacing at most a quarter of the entrance pupil: a small stop's bundles are not missed.
        n = int(np.clip(np.ceil(8 * reach.max() / self._pupil_mm), COARSE_RAYS_PER_SIDE, 128))
        unit = np.linspace(-1.0, 1.0, n)
        ux, uy = (v.ravel() for v in np.meshgrid(unit, unit))
        paths = len(self.paths)
        rows = len(sources) * paths
        row_reach = np.repeat(reach, paths)
        gx = (row_reach[:, None] * ux).ravel()
        gy = (row_reach[:, None] * uy).ravel()
        row_of = np.repeat(np.arange(rows), n * n)
        origin, direction = self._rays(sources, row_of // paths, gx, gy)
        mid = np.array([len(lam) // 2])
        zeros = np.zeros_like(row_of)
        _, _, alive = self._trace(  # no weights: only which rays survive
            origin, direction, row_of % paths, zeros, zeros[:, None][:, :0], media[:, mid], lam[mid]
        )
        alive = alive.reshape(rows, n * n)
        gx, gy = gx.reshape(rows, n * n), gy.reshape(rows, n * n)
        boxes = np.zeros((rows, 4))
        for r in np.nonzero(alive.any(axis=1))[0]:  # the others: empty boxes, every ray misses
            cell, lim = 2 * row_reach[r] / (n - 1), row_reach[r]
            px, py = gx[r, alive[r]], gy[r, alive[r]]
            boxes[r] = (
                max(px.min() - cell, -lim),
                min(px.max() + cell, lim),
                max(py.min() - cell, -lim),
                min(py.max() + cell, lim),
            )
        return boxes

    def _trace(
        self,
        origin: np.ndarray,
        direction: np.ndarray,
        path_of: np.ndarray,
        lam_of: np.ndarray,
        weight_lam: np.ndarray,
        media: np.ndarray,
        lam: np.ndarray,
    ) -> tuple[np.ndarray, np.ndarray, np.ndarray]:
        """(film xy (N, 2), weight (N, B), alive (N,)) of rays following their paths' steps:
        the geometry at wavelength index `lam_of` (N,), the weights at `weight_lam` (N, B)
        (pecs_core's ghost tracer, rust/core/src/ghost)."""
        f64 = np.float64
        return _core.ghost_trace(
            np.ascontiguousarray(origin, f64),
            np.ascontiguousarray(direction, f64),
            np.ascontiguousarray(path_of, np.int64),
            np.ascontiguousarray(lam_of, np.int64),
            np.ascontiguousarray(weight_lam, np.int64),
            self._step_surface,
            self._step_reflect,
            self._step_forward,
            self._z,
            self._radius,
            self._semi2,
            self._fixed,
            self._film_n1,
            self._film_d,
            np.ascontiguousarray(media, f64),
            np.ascontiguousarray(lam, f64),
            float(self.system.film_z_mm),
        )

    # -- rendering ------------------------------------------------------------------------
    def image(
        self,
        source: PointSource,
        wavelengths_nm: ArrayLike,
        width_px: int,
        height_px: int,
        pitch_mm: float,
        rays_per_side: int | None = None,
    ) -> np.ndarray:
        """Ghost irradiance over source irradiance (the irradiance at the lens on a plane facing
        the source), (L, H, W) float64; pixel (0, 0) at the top-left, film x = (col + 0.5 -
        W / 2) pitch, as the realisticlens sensor maps its film."""
        rays = self.trace(source, wavelengths_nm, rays_per_side)
        return splat(rays, width_px, height_px, pitch_mm)


def splat(rays: GhostRays, width_px: int, height_px: int, pitch_mm: float) -> np.ndarray:
    """Each ray's flux spread over its grid cell's film quad, / pixel area: (L, H, W)
    irradiance per unit source irradiance, summed over paths.

    A quad is drawn as k x k sub-rays (bilinear splats) on the level of an image pyramid whose
    pixels are about its size (level l: 2^l x 2^l pixels), and the levels are summed after
    bilinear upsampling: the cost per ray stays small however wide the ghost."""
    lam_count = rays.flux_mm2.shape[1]
    alive = rays.alive & (rays.flux_mm2 > 0)
    lam_index = np.broadcast_to(np.arange(lam_count)[None, :, None, None], rays.flux_mm2.shape)[
        alive
    ]
    # Film position in pixels from the film's top-left corner.
    pos = rays.film_mm[alive] / pitch_mm + np.array([width_px / 2, height_px / 2])
    du = rays.du_mm[alive] / pitch_mm
    dv = rays.dv_mm[alive] / pitch_mm
    flux = rays.flux_mm2[alive] / pitch_mm**2
    span = np.abs(du).sum(axis=1) + np.abs(dv).sum(axis=1)
    reach = 0.5 * span + 1.0
    on_film = (
        (pos[:, 0] > -reach)
        & (pos[:, 0] < width_px + reach)
        & (pos[:, 1] > -reach)
        & (pos[:, 1] < height_px + reach)
    )
    pos, du, dv, flux, span, lam_index = (v[on_film] for v in (pos, du, dv, flux, span, lam_index))
    top = max(0, int(np.floor(np.log2(max(min(width_px, height_px), 4) / 4))))
    level_of = np.clip(np.ceil(np.log2(np.maximum(span, 1.0))), 0, top).astype(np.int64)
    levels: dict[int, np.ndarray] = {}
    for level in np.unique(level_of):
        scale = 2 ** int(level)
        sel = level_of == level
        w_l, h_l = -(-width_px // scale), -(-height_px // scale)
        coarse = np.zeros(lam_count * h_l * w_l)
        k_of = np.clip(np.ceil(2 * span[sel] / scale), 2, _MAX_SUBSAMPLES).astype(np.int64)
        for k in np.unique(k_of):
            pick = np.nonzero(sel)[0][k_of == k]
            offsets = (np.arange(k) + 0.5) / k - 0.5
            su, sv = (a.ravel() for a in np.meshgrid(offsets, offsets))
            p = (
                pos[pick, None, :]
                + su[None, :, None] * du[pick, None, :]
                + sv[None, :, None] * dv[pick, None, :]
            ) / scale
            f = np.repeat(flux[pick] / (k * k * scale * scale), k * k)
            li = np.repeat(lam_index[pick], k * k)
            _bilinear(coarse, p.reshape(-1, 2), f, li, w_l, h_l)
        levels[int(level)] = coarse.reshape(lam_count, h_l, w_l)
    # Collapse the pyramid: each level doubled into the one below, down to the film.
    image = np.zeros((lam_count, height_px, width_px))
    carried: np.ndarray | None = None
    for level in range(max(levels, default=0), -1, -1):
        h_l, w_l = -(-height_px // 2**level), -(-width_px // 2**level)
        here = levels.get(level)
        if carried is not None:
            carried = _upsample(carried, 2, w_l, h_l)
            here = carried if here is None else here + carried
        carried = here
    if carried is not None:
        image += carried
    return image


def _upsample(coarse: np.ndarray, scale: int, width: int, height: int) -> np.ndarray:
    """Bilinear interpolation of (L, h, w) pixels of `scale` fine pixels to (L, height, width)."""
    h_l, w_l = coarse.shape[1:]
    y0, y1, fy = _interpolation(height, h_l, scale)
    x0, x1, fx = _interpolation(width, w_l, scale)
    rows = coarse[:, y0, :] * (1 - fy)[None, :, None] + coarse[:, y1, :] * fy[None, :, None]
    return rows[:, :, x0] * (1 - fx) + rows[:, :, x1] * fx


def _interpolation(fine: int, coarse: int, scale: int) -> tuple[np.ndarray, ...]:
    """(left index, right index, weight of the right) of each fine pixel centre between the
    coarse pixel centres (clamped at the edges)."""
    x = np.clip((np.arange(fine) + 0.5) / scale - 0.5, 0, coarse - 1)
    x0 = np.minimum(np.floor(x).astype(np.int64), max(coarse - 2, 0))
    x1 = np.minimum(x0 + 1, coarse - 1)
    return x0, x1, x - x0


def _bilinear(
    image: np.ndarray,
    film_px: np.ndarray,
    flux: np.ndarray,
    lam_index: np.ndarray,
    width: int,
    height: int,
) -> None:
    """Add each flux to the four pixels around its position, in pixels from the top-left
    corner (pixel centres at +0.5)."""
    x = film_px[:, 0] - 0.5
    y = film_px[:, 1] - 0.5
    x0, y0 = np.floor(x), np.floor(y)
    fx, fy = x - x0, y - y0
    x0, y0 = x0.astype(np.int64), y0.astype(np.int64)
    base = lam_index * (width * height)
    for dx, dy, wgt in (
        (0, 0, (1 - fx) * (1 - fy)),
        (1, 0, fx * (1 - fy)),
        (0, 1, (1 - fx) * fy),
        (1, 1, fx * fy),
    ):
        xi, yi = x0 + dx, y0 + dy
        inside = (xi >= 0) & (xi < width) & (yi >= 0) & (yi < height)
        flat = base[inside] + yi[inside] * width + xi[inside]
        image += np.bincount(flat, weights=(flux * wgt)[inside], minlength=image.size)


def _sequence(
    path: GhostPath, surfaces: int, only_reflect: Container[int] = ()
) -> list[tuple[int, bool, bool]]:
    """(surface, reflect, forward) of each interface a ghost ray meets, in order; surfaces in
    `only_reflect` (the die, which is the film) are met only where the path reflects."""
    i, j = path.first, path.second
    steps = [(k, False, True) for k in range(i)] + [(i, True, True)]
    steps += [(k, False, False) for k in range(i - 1, j, -1)] + [(j, True, False)]
    steps += [(k, False, True) for k in range(j + 1, surfaces)]
    return [s for s in steps if s[1] or s[0] not in only_reflect]


def _grid_jacobian(film: np.ndarray, alive: np.ndarray) -> tuple[np.ndarray, np.ndarray]:
    """Film step per grid step along the two grid axes (central differences where both
    neighbours reached the film, one-sided where one did, 0 where none)."""
    out = []
    for axis in (3, 2):  # columns (x on the entrance plane), rows (y)
        fwd = np.roll(film, -1, axis=axis) - film
        bwd = film - np.roll(film, 1, axis=axis)
        a_fwd = np.roll(alive, -1, axis=axis)
        a_bwd = np.roll(alive, 1, axis=axis)
        last = [slice(None)] * 4
        last[axis] = -1
        a_fwd[tuple(last)] = False
        first = [slice(None)] * 4
        first[axis] = 0
        a_bwd[tuple(first)] = False
        both = (a_fwd & a_bwd)[..., None]
        step = np.where(
            both,
            0.5 * (fwd + bwd),
            np.where(a_fwd[..., None], fwd, np.where(a_bwd[..., None], bwd, 0.0)),
        )
        out.append(step)
    return out[0], out[1]
