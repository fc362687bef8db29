"""Rendering an animated scene into photocurrent frames (Mitsuba 3, spectral, QE film) and events.

Mitsuba is imported lazily (first render), with the variant chosen by `pecs._mitsuba`.
"""

from pecs.render.scene_file import SceneSpec, builtin_scenes, load_scene
from pecs.render.simulation import Frame, RunSummary, Simulation

__all__ = ["Frame", "RunSummary", "SceneSpec", "Simulation", "builtin_scenes", "load_scene"]
