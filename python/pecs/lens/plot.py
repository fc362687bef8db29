"""Drawings of a lens: the layout (elements, stop, film) with traced rays, and spot diagrams."""

from __future__ import annotations

from pathlib import Path
from typing import TYPE_CHECKING, Any

import numpy as np

from pecs._atomic import atomic_path
from pecs.lens.glass import D_LINE_NM
from pecs.lens.raytrace import Geometry, trace

if TYPE_CHECKING:
    from pecs.lens.lens import Lens


def _profile(lens: Lens, i: int, count: int = 41) -> tuple[np.ndarray, np.ndarray]:
    """(z, y) of surface i's cross-section over its clear aperture."""
    from pecs.lens.lens import _sag

    s = lens.surfaces[i]
    y = np.linspace(-s.aperture_mm / 2, s.aperture_mm / 2, count)
    z = lens.geometry.vertex_z_mm[i] + np.array([_sag(s.radius_mm, v) for v in y])
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
    """Draw the layout (y-z section) with ray fans on axis and at `field_deg` (default: the
    field of a 6.4 mm-wide film), plus spot diagrams; save to `path` if given."""
    import matplotlib

    if path is not None:
        matplotlib.use("Agg")
    import matplotlib.pyplot as plt

    if field_deg is None:
        angle = lens.chief_ray_angle_deg(min(3.2, 0.4 * lens.efl_mm()))[0]
        field_deg = float(angle) if np.isfinite(angle) else 0.0
    if ax is None:
        fig, (ax, ax_spot) = plt.subplots(
            1, 2, figsize=(12, 5), gridspec_kw={"width_ratios": [3, 1]}
        )
    else:
        fig, ax_spot = ax.figure, None
    for i, s in enumerate(lens.surfaces):
        z, y = _profile(lens, i)
        ax.plot(z, y, color="k" if not s.is_stop else "tab:red", lw=1.2 if not s.is_stop else 2)
    for field, colour in ((0.0, "tab:blue"), (field_deg, "tab:green")):
        for line in _fan(lens, field):
            ax.plot(line[:, 0], line[:, 1], color=colour, lw=0.6)
    film_z = lens.geometry.film_z_mm
    ax.axvline(film_z, color="tab:gray", ls="--", lw=1)
    ax.set_aspect("equal")
    ax.set_xlabel("z (mm)")
    ax.set_ylabel("y (mm)")
    ax.set_title(f"{lens.name}: f = {lens.efl_mm():.2f} mm, f/{lens.f_number():.2f}")
    if ax_spot is not None:
        for field, marker in ((0.0, "."), (field_deg, "+")):
            for wl, colour in ((486.1, "tab:blue"), (D_LINE_NM, "tab:green"), (656.3, "tab:red")):
                try:
                    spot = lens.spot_diagram(field, wl, rays_per_side=24)
                except ValueError:
                    continue
                centre = lens.spot_diagram(field, D_LINE_NM, rays_per_side=24).mean(axis=0)
                ax_spot.plot(
                    (spot[:, 0] - centre[0]) * 1e3,
                    (spot[:, 1] - centre[1]) * 1e3,
                    marker,
                    color=colour,
                    ms=2,
                    ls="none",
                    label=f"{field:.1f} deg, {wl:.0f} nm",
                )
        ax_spot.set_aspect("equal")
        ax_spot.set_xlabel("x (µm)")
        ax_spot.set_ylabel("y (µm)")
        ax_spot.set_title("spot diagram")
        ax_spot.legend(fontsize=6)
    fig.tight_layout()
    if path is not None:
        with atomic_path(path) as tmp:
            fig.savefig(tmp, dpi=120, format=Path(path).suffix.lstrip(".") or "png")
    return fig
