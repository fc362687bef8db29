"""Lens prescriptions: sequential spherical surfaces in pbrt's RealisticCamera format.

One row per interface, scene side first, lengths in mm:
    radius_mm  thickness_mm  n_d  aperture_mm  [glass]
radius 0 is the aperture stop (n_d written 0); radius > 0 puts the centre of curvature towards
the film; thickness is the axial distance to the next interface (the last one: to the film,
replaced by focusing); n_d is the index of the medium behind the interface (1 = air);
aperture is a diameter. The optional fifth column gives the glass dispersion: an Abbe number
V_d or a catalogue glass name, optionally with its catalogue (N-BK7, SCHOTT:N-BK7; see
catalogue.py), whose n_d must round to the n_d column; "-" or nothing means no dispersion. `#` starts a
comment; a comment line `# name: X` names the lens.
"""

from __future__ import annotations

from dataclasses import dataclass, replace
from pathlib import Path

from pecs.lens.glass import Glass


@dataclass(frozen=True)
class Surface:
    """One interface. `glass` is the medium behind it (towards the film)."""

    radius_mm: float
    thickness_mm: float
    aperture_mm: float
    glass: Glass
    is_stop: bool = False

    @property
    def curvature_per_mm(self) -> float:
        return 0.0 if self.radius_mm == 0.0 else 1.0 / self.radius_mm

    def scaled(self, factor: float) -> Surface:
        factor = float(factor)
        return replace(
            self,
            radius_mm=float(self.radius_mm) * factor,
            thickness_mm=float(self.thickness_mm) * factor,
            aperture_mm=float(self.aperture_mm) * factor,
        )


def parse_prescription(text: str, source: str = "<text>") -> tuple[str, list[Surface]]:
    """(name, surfaces) from prescription text; errors name `source`, the line and the surface."""
    name = ""
    surfaces: list[Surface] = []
    for line_no, raw in enumerate(text.splitlines(), start=1):
        line, _, comment = raw.partition("#")
        if not line.strip():
            if comment.strip().lower().startswith("name:"):
                name = comment.split(":", 1)[1].strip()
            continue
        fields = line.split()
        where = f"{source}, line {line_no}, surface {len(surfaces)}"
        if len(fields) not in (4, 5):
            raise ValueError(
                f"{where}: expected 4 or 5 columns (radius thickness n_d aperture [glass]), "
                f"got {len(fields)}"
            )
        try:
            radius, thickness, n_d, aperture = (float(v) for v in fields[:4])
        except ValueError as error:
            raise ValueError(f"{where}: {error}") from None
        try:
            surfaces.append(
                _surface(radius, thickness, n_d, aperture, fields[4] if len(fields) == 5 else None)
            )
        except ValueError as error:
            raise ValueError(f"{where}: {error}") from None
    if not surfaces:
        raise ValueError(f"{source}: no surfaces")
    return name, surfaces


def _surface(
    radius: float, thickness: float, n_d: float, aperture: float, glass: str | None
) -> Surface:
    is_stop = radius == 0.0
    if is_stop:
        if n_d not in (0.0, 1.0) or glass not in (None, "-", "air"):
            raise ValueError("the aperture stop (radius 0) must sit in air (n_d 0 or 1)")
        n_d = 1.0
    if not n_d >= 1.0:
        raise ValueError(f"n_d must be >= 1, got {n_d}")
    return Surface(radius, thickness, aperture, Glass.from_column(n_d, glass), is_stop)


def read_prescription(path: str | Path) -> tuple[str, list[Surface]]:
    """(name, surfaces) of a prescription file; the name defaults to the file's stem."""
    path = Path(path)
    if not path.is_file():
        raise FileNotFoundError(f"lens prescription not found: {path}")
    name, surfaces = parse_prescription(path.read_text(), str(path))
    return name or path.stem, surfaces


def format_prescription(name: str, surfaces: list[Surface]) -> str:
    """Prescription text that `parse_prescription` reads back to the same surfaces."""
    lines = [f"# name: {name}", "# radius_mm thickness_mm n_d aperture_mm glass"]
    for s in surfaces:
        glass = "-"
        if s.glass.kind == "catalogue":
            glass = s.glass.name
        elif s.glass.kind == "abbe":
            glass = repr(s.glass.v_d)
        n_d = 0.0 if s.is_stop else s.glass.n_d
        lines.append(f"{s.radius_mm!r} {s.thickness_mm!r} {n_d!r} {s.aperture_mm!r} {glass}")
    return "\n".join(lines) + "\n"
