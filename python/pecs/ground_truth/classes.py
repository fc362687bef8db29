"""A class per instance: what the scene says (`[classes]` of the scene file: shape id = class),
else the shape's id without a trailing number ("car_2" and "car3" are "car")."""

from __future__ import annotations

import re

_TRAILING_NUMBER = re.compile(r"[_\-.\s]*\d+$")


def default_class(shape_id: str) -> str:
    """The shape id without a trailing number and separator; the id itself when nothing is left."""
    stripped = _TRAILING_NUMBER.sub("", shape_id)
    return stripped or shape_id


def instance_classes(shape_ids: list[str], classes: dict[str, str]) -> list[str]:
    """The class of each shape; ValueError naming a `[classes]` id that is no shape's."""
    unknown = sorted(set(classes) - set(shape_ids))
    if unknown:
        raise ValueError(
            f"[classes] {unknown[0]}: no shape has this id (shape ids: {', '.join(shape_ids)})"
        )
    return [classes.get(shape_id, default_class(shape_id)) for shape_id in shape_ids]
