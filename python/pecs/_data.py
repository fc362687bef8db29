"""Where pecs finds the data it ships (scenes, lens prescriptions, QE curves, spectra).

One place to change when the data moves: every module asks `scenes_dir()`.
"""

from __future__ import annotations

import os
from functools import cache
from pathlib import Path


@cache
def scenes_dir() -> Path:
    """The `scenes/` folder: `PECS_DATA_DIR` if set, else the first `scenes/` above the package."""
    override = os.environ.get("PECS_DATA_DIR")
    if override:
        path = Path(override)
        if not path.is_dir():
            raise FileNotFoundError(f"PECS_DATA_DIR={override} is not a folder")
        return path
    for parent in Path(__file__).resolve().parents:
        candidate = parent / "scenes"
        if (candidate / "lenses").is_dir():
            return candidate
    raise FileNotFoundError("the pecs data folder scenes/ was not found above the package")
