"""Writing generated scenes: the scene TOML (pecs reads TOML with the standard library, which
does not write it, so a small writer for the values a scene file holds), the Mitsuba XML, and
the numbers in both.

Numbers are written with 9 significant digits: more than Mitsuba's float32 holds, and the same
text on any machine even where a transcendental function differs in its last bit between CPUs.
"""

from __future__ import annotations

import json
import math
from pathlib import Path
from typing import Any
from xml.etree import ElementTree
from xml.etree.ElementTree import Element, SubElement

import numpy as np

from pecs.dataset.generators.base import SceneSettings


def number(value: float) -> str:
    """A float as TOML and Mitsuba read it: 9 significant digits, always a float literal."""
    value = float(value)
    if not math.isfinite(value):
        raise ValueError(f"cannot write {value} in a scene file")
    text = f"{value:.9g}"
    if text == "-0":
        text = "0"
    return text if any(c in text for c in ".en") else f"{text}.0"


def toml_value(value: Any) -> str:
    """A TOML value: strings, booleans, integers, floats, lists and inline tables."""
    if isinstance(value, bool):
        return "true" if value else "false"
    if isinstance(value, (int, np.integer)):
        return str(int(value))
    if isinstance(value, (float, np.floating)):
        return number(float(value))
    if isinstance(value, str):
        return json.dumps(value)  # a TOML basic string: JSON's escapes are TOML's
    if isinstance(value, (list, tuple, np.ndarray)):
        return "[" + ", ".join(toml_value(v) for v in value) + "]"
    if isinstance(value, dict):
        return "{ " + ", ".join(f"{k} = {toml_value(v)}" for k, v in value.items()) + " }"
    raise TypeError(f"cannot write {type(value).__name__} in a scene file")


def toml_table(header: str, values: dict[str, Any]) -> str:
    """`[header]` (or `[[header]]`) and its keys; a list of tables one per line. None is left
    out (TOML has no null: absent means None)."""
    lines = [header]
    for key, value in values.items():
        if value is None:
            continue
        if isinstance(value, list) and value and all(isinstance(v, dict) for v in value):
            lines.append(f"{key} = [")
            lines += [f"  {toml_value(v)}," for v in value]
            lines.append("]")
        else:
            lines.append(f"{key} = {toml_value(value)}")
    return "\n".join(lines) + "\n"


def transform_element(parent: Element, matrix: np.ndarray, name: str = "to_world") -> None:
    """`<transform name="to_world"><matrix value="16 numbers, row by row"/></transform>`."""
    transform = SubElement(parent, "transform", name=name)
    SubElement(transform, "matrix", value=" ".join(number(v) for v in np.ravel(matrix)))


def write_xml(root: Element, path: Path, comment: str) -> None:
    """The Mitsuba scene, indented, with a comment that says what made it."""
    ElementTree.indent(root)
    text = f"<!-- {comment} -->\n" + ElementTree.tostring(root, encoding="unicode") + "\n"
    path.write_text(text)


def scene_root() -> Element:
    """`<scene>` with the `$light_spectrum` default that pecs replaces by `[light]`'s spectrum."""
    root = Element("scene", version="3.0.0")
    SubElement(root, "default", name="light_spectrum", value="400:1, 700:1")
    return root


def settings_tables(description: dict[str, Any], settings: SceneSettings) -> list[str]:
    """The head of a generated scene file: where it came from, and the settings the dataset
    simulated it with ([scene], [time], [sensor], [optics], [render])."""
    return [
        f"# Drawn by pecs's {description['generator']} generator; description.json holds the "
        "drawn values.\n# `pecs simulate scene.toml` renders it again as the dataset did.\n",
        toml_table("[scene]", {"mitsuba": "scene.xml"}),
        toml_table("[time]", _time_table(settings)),
        toml_table(
            "[sensor]", {"preset": settings.preset, "overrides": _sensor_overrides(settings)}
        ),
        toml_table("[optics]", {"model": "pinhole", "fov_deg": description["camera"]["fov_deg"]}),
        toml_table("[render]", {"spp": settings.spp, "max_depth": 5, "seed": settings.seed}),
    ]


def _time_table(settings: SceneSettings) -> dict[str, Any]:
    if settings.rate_hz is not None:
        return {"duration_s": settings.duration_s, "rate_hz": settings.rate_hz}
    return {
        "duration_s": settings.duration_s,
        "adaptive": True,
        "min_rate_hz": 100.0,
        "max_rate_hz": 2000.0,
        # Steps from the exact image motion, a quarter pixel each: on generated scenes 6.2x
        # fewer frames than 2 kHz with events within 1.08 of the Monte Carlo floor, where the
        # measured rule at half a pixel passed 1.10 (docs/performance.md, bench_dataset --steps).
        "motion": "exact",
        "threshold_fraction": 0.25,
    }


def _sensor_overrides(settings: SceneSettings) -> dict[str, Any]:
    """The sensor fields (None, which TOML cannot write, is what leaving a field out means)."""
    return {key: value for key, value in sorted(settings.sensor.items()) if value is not None}
