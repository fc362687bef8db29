"""Where pecs finds the data it ships (scenes, lens prescriptions, QE curves, spectra).

One place to change when the data moves: every module asks `scenes_dir()`.
"""

from __future__ import annotations

import os
from functools import cache
from pathlib import Path


@cache
def scenes_dir() -> Path:
    """The data folder `pecs/scenes` inside the package (`PECS_DATA_DIR` overrides it)."""
    override = os.environ.get("PECS_DATA_DIR")
    if override:
        path = Path(override)
        if not path.is_dir():
            raise FileNotFoundError(f"PECS_DATA_DIR={override} is not a folder")
        return path
    shipped = Path(__file__).resolve().parent / "scenes"
    if not (shipped / "lenses").is_dir():
        raise FileNotFoundError(f"the pecs data folder {shipped} is missing; reinstall pecs")
    return shipped
