"""Real multi-element lenses: prescriptions, glass, first-order optics, a float64 ray tracer,
lens ghosts (coatings, traced two-reflection paths, their paraxial table) and the Mitsuba sensor
plugin "realisticlens".

`register_realistic_lens()` registers the plugin for Mitsuba's current variant; importing this
package does it when Mitsuba is already imported, and the render module calls it again after it
selects its variant (registration is per variant and idempotent).
"""

from __future__ import annotations

import sys

from pecs.lens.coating import Coating
from pecs.lens.ghosts import CoverGlass, GhostOptions, GhostTracer, PointSource
from pecs.lens.glass import CatalogueGlass, Glass, catalogue_glass, catalogue_names
from pecs.lens.lens import SENSOR_FILM_MM, Lens
from pecs.lens.paraxial_ghosts import ghost_table
from pecs.lens.prescription import Surface


def register_realistic_lens() -> None:
    """Register the "realisticlens" sensor for Mitsuba's current variant (idempotent)."""
    from pecs.lens.mitsuba_sensor import register

    register()


def _register_if_mitsuba_is_ready() -> None:
    """On import: register only when Mitsuba is imported with a variant set (importing pecs
    never chooses a variant; the render module registers after choosing one)."""
    mi = sys.modules.get("mitsuba")
    try:
        ready = mi is not None and mi.variant() is not None
    except AttributeError:
        ready = False
    if ready:
        register_realistic_lens()


_register_if_mitsuba_is_ready()

__all__ = [
    "CatalogueGlass",
    "Coating",
    "CoverGlass",
    "GhostOptions",
    "GhostTracer",
    "Glass",
    "Lens",
    "PointSource",
    "SENSOR_FILM_MM",
    "Surface",
    "catalogue_glass",
    "catalogue_names",
    "ghost_table",
    "register_realistic_lens",
]
