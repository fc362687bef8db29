"""The scenes of the library, and how long a window shows each one's motion: shared by the
gallery's previews (preview.py) and the library's tests."""

from __future__ import annotations

from pathlib import Path

HERE = Path(__file__).resolve().parent

SCENES = ("quadrant_disk", "checkerboard", "city_flight", "cyclist_night", "trees_wind")
# The scenes whose files a make.py writes (the others are written by hand).
GENERATED = tuple(name for name in SCENES if (HERE / name / "make.py").exists())
# Long enough for each scene's motion to cross a few pixels, even of a small film.
MOTION_WINDOW_S = {
    "quadrant_disk": 0.02,
    "checkerboard": 0.02,
    "city_flight": 0.02,
    "cyclist_night": 0.04,
    "trees_wind": 0.1,
}
