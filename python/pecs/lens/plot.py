"""Drawings of a lens: the layout (elements, stop, film) with traced rays, and spot diagrams."""

from __future__ import annotations

from pathlib import Path
from typing import TYPE_CHECKING, Any

import numpy as np

from pecs._atomic import atomic_path
from pecs.lens.glass import D_LINE_NM
from pecs.lens.raytrace import Geometry, sphere_sag_mm, trace

if TYPE_CHECKING:
    from pecs.lens.lens import Lens


def _profile(lens: Lens, i: int, count: int = 41) -> tuple[np.ndarray, np.ndarray]:
    """(z, y) of surface i's cross-section over its clear aperture."""
    s = lens.surfaces[i]
    y = np.linspace(-s.aperture_mm / 2, s.aperture_mm / 2, count)
    z = lens.geometry.vertex_z_mm[i] + np.array([sphere_sag_mm(s.radius_mm, v) for v in y])
    return z, y


def _fan(lens: Lens, field_deg: float, count: int = 7) -> list[np.ndarray]:
    """Meridional rays from infinity at `field_deg` that reach the film: polylines (z, y)."""
    theta = np.radians(field_deg)
    a = lens.surfaces[0].aperture_mm / 2
    ys = np.linspace(-1.5 * a, 1.5 * a, 301)
    z0 = -0.3 * lens.total_track_mm
    start = np.column_stack(
        [np.zeros_like(ys), ys - np.tan(theta) * (0 - z0), np.full_like(ys, z0)]
    )
    direction = np.tile([0.0, np.sin(theta), np.cos(theta)], (len(ys), 1))
    passed = lens.trace_from_scene(start, direction).alive
    if not passed.any():
        return []
    chosen = np.linspace(ys[passed].min(), ys[passed].max(), count)
    start = np.column_stack(
        [np.zeros(count), chosen - np.tan(theta) * (0 - z0), np.full(count, z0)]
    )
    lines = []
    for k in range(count):
        points = [start[k, 1:][::-1]]
        d = direction[:1]
        geometry = lens.geometry
        for i in range(len(lens.surfaces)):
            # The lens cut after surface i: where the ray leaves that surface.
            sub = Geometry(
                geometry.vertex_z_mm[: i + 1],
                geometry.radius_mm[: i + 1],
                geometry.semi_aperture_mm[: i + 1],
                geometry.film_z_mm,
            )
            r = trace(sub, lens.media_indices()[: i + 2], start[k : k + 1], d, True)
            if not r.alive[0]:
                break
            points.append(np.array([r.origin[0, 2], r.origin[0, 1]]))
            last = r
        else:
            t = (geometry.film_z_mm - last.origin[0, 2]) / last.direction[0, 2]
            end = last.origin[0] + t * last.direction[0]
            points.append(np.array([end[2], end[1]]))
        lines.append(np.array(points))
    return lines


def plot_layout(
    lens: Lens, path: str | Path | None = None, field_deg: float | None = None, ax: Any = None
) -> Any:
    """Draw the lens: layout (y-z section) with ray fans on axis and at `field_deg` (default:
    the field at 3.2 mm film height, half a DAVIS346 width), spot diagrams at both fields in
    F, d and C light, distortion and relative illumination against film height, and the
    longitudinal chromatic focal shift. With `ax`, only the layout is drawn into it. Saved to
    `path` when given; returns the matplotlib figure."""
    from matplotlib.figure import Figure

    if field_deg is None:
        angle = lens.chief_ray_angle_deg(min(3.2, 0.4 * lens.efl_mm()))[0]
        field_deg = float(angle) if np.isfinite(angle) else 0.0
    if ax is not None:
        _draw_layout(lens, ax, field_deg)
        return ax.figure
    fig = Figure(figsize=(13, 8), layout="constrained")
    grid = fig.add_gridspec(2, 4, height_ratios=[1.3, 1])
    _draw_layout(lens, fig.add_subplot(grid[0, :]), field_deg)
    for k, field in enumerate((0.0, field_deg)):
        _draw_spots(lens, fig.add_subplot(grid[1, k]), field)
    _draw_field_curves(lens, fig.add_subplot(grid[1, 2]), field_deg)
    _draw_focal_shift(lens, fig.add_subplot(grid[1, 3]))
    if path is not None:
        with atomic_path(path) as tmp:
            fig.savefig(tmp, dpi=110, format=Path(path).suffix.lstrip(".") or "png")
    return fig


def _draw_layout(lens: Lens, ax: Any, field_deg: float) -> None:
    for i, s in enumerate(lens.surfaces):
        z, y = _profile(lens, i)
        ax.plot(z, y, color="tab:red" if s.is_stop else "k", lw=2 if s.is_stop else 1.2)
    for field, colour in ((0.0, "tab:blue"), (field_deg, "tab:green")):
        for line in _fan(lens, field):
            ax.plot(line[:, 0], line[:, 1], color=colour, lw=0.6)
    ax.axvline(lens.geometry.film_z_mm, color="tab:gray", ls="--", lw=1)
    ax.set_aspect("equal")
    ax.set_xlabel("z (mm)")
    ax.set_ylabel("y (mm)")
    ax.set_title(
        f"{lens.name}: f = {lens.efl_mm():.2f} mm, f/{lens.f_number():.2f}, "
        f"rays at 0 and {field_deg:.1f} deg"
    )


def _draw_spots(lens: Lens, ax: Any, field_deg: float) -> None:
    """Spots in F, d and C light around the d-light centroid, µm."""
    try:
        centre = lens.spot_diagram(field_deg, D_LINE_NM, rays_per_side=24).mean(axis=0)
    except ValueError:
        ax.set_title(f"no ray at {field_deg:.1f} deg")
        return
    for wl, colour in ((486.1, "tab:blue"), (D_LINE_NM, "tab:green"), (656.3, "tab:red")):
        spot = (lens.spot_diagram(field_deg, wl, rays_per_side=24) - centre) * 1e3
        ax.plot(spot[:, 0], spot[:, 1], ".", color=colour, ms=2, label=f"{wl:.0f} nm")
    ax.set_aspect("equal")
    ax.set_xlabel("x (µm)")
    ax.set_ylabel("y (µm)")
    ax.set_title(f"spot, {field_deg:.1f} deg")
    ax.legend(fontsize=6)


def _draw_field_curves(lens: Lens, ax: Any, field_deg: float) -> None:
    """Distortion (%) and relative illumination against film height up to the drawn field."""
    h_max = max(lens.efl_mm() * np.tan(np.radians(max(field_deg, 1.0))), 1e-3)
    h = np.linspace(h_max / 12, h_max, 12)
    ax.plot(h, lens.distortion_percent(h), color="tab:purple", label="distortion (%)")
    ax.set_xlabel("film height (mm)")
    ax.set_ylabel("distortion (%)")
    twin = ax.twinx()
    twin.plot(h, lens.relative_illumination(h), color="tab:orange", label="relative illumination")
    twin.set_ylim(0, 1.05)
    twin.set_ylabel("relative illumination")
    ax.set_title("distortion (purple), illumination (orange)", fontsize=9)


def _draw_focal_shift(lens: Lens, ax: Any) -> None:
    wavelengths = np.linspace(420.0, 700.0, 29)
    ax.plot(lens.longitudinal_chromatic_aberration_mm(wavelengths) * 1e3, wavelengths)
    ax.axvline(0.0, color="tab:gray", lw=0.8)
    ax.set_xlabel("focal shift from d light (µm)")
    ax.set_ylabel("wavelength (nm)")
    ax.set_title("longitudinal colour")
