"""Rendering an animated scene into photocurrent frames (Mitsuba 3, spectral, QE film) and events.

Mitsuba is imported lazily (first render), with the variant chosen by `pecs._mitsuba`.
"""

from pecs.render.animation import Track
from pecs.render.flicker import Flicker
from pecs.render.scene_file import SceneSpec, builtin_scenes, load_scene
from pecs.render.simulation import Frame, RunSummary, Simulation
from pecs.render.trajectory_file import read_trajectory

__all__ = [
    "Flicker",
    "Frame",
    "RunSummary",
    "SceneSpec",
    "Simulation",
    "Track",
    "builtin_scenes",
    "load_scene",
    "read_trajectory",
]
