"""Per-instance boxes: 2D boxes of what each instance covers in the image, and 3D boxes of its
whole geometry in camera coordinates.

2D: the pixels an instance covers in the instance map, as a box whose sides are pixel edges
(column j spans u in [j - 0.5, j + 0.5]): a one-pixel instance is 1 x 1. Modal: only what is
seen. 3D: amodal, the shape's axis-aligned box as the scene places it (before animation),
carried by its animation transform and seen from the camera: 8 corners per instance (an
oriented box once the shape turns), corner k at (min or max by bit 0 for x, bit 1 for y,
bit 2 for z) of the box.
"""

from __future__ import annotations

from dataclasses import dataclass

import numpy as np

from pecs.ground_truth.surface import BACKGROUND


@dataclass(frozen=True)
class Boxes:
    """The instances seen at one time, one row each, in instance order."""

    #: int32 (n,): instance index (into `GroundTruth.shape_ids`).
    instance: np.ndarray
    #: The class of each instance (`GroundTruth.classes`).
    class_name: list[str]
    #: int64 (n,): pixels the instance covers.
    pixels: np.ndarray
    #: float64 (n, 4): u_min, v_min, u_max, v_max in pixels, sides on pixel edges.
    box_2d_px: np.ndarray
    #: float64 (n, 8, 3): the 3D box's corners in the camera frame (+z forward, +y up, +x to
    #: the image's left), metres; NaN where the run stored no box (older runs).
    corners_camera_m: np.ndarray


def boxes_2d(instance: np.ndarray) -> tuple[np.ndarray, np.ndarray, np.ndarray]:
    """(instances seen, pixel counts, boxes (n, 4)) of an instance map."""
    rows, columns = np.nonzero(instance != BACKGROUND)
    ids = instance[rows, columns]
    seen, inverse, counts = np.unique(ids, return_inverse=True, return_counts=True)
    box = np.empty((seen.size, 4))
    for k, (coordinates, reduce) in enumerate(
        [(columns, np.minimum), (rows, np.minimum), (columns, np.maximum), (rows, np.maximum)]
    ):
        start = np.full(seen.size, np.inf if reduce is np.minimum else -np.inf)
        reduce.at(start, inverse, coordinates.astype(np.float64))
        box[:, k] = start
    box[:, :2] -= 0.5
    box[:, 2:] += 0.5
    return seen.astype(np.int32), counts.astype(np.int64), box


def box_corners(box_min: np.ndarray, box_max: np.ndarray) -> np.ndarray:
    """(..., 8, 3) corners of axis-aligned boxes (..., 3): corner k takes max where bit
    (0 x, 1 y, 2 z) of k is set."""
    bits = (np.arange(8)[:, None] >> np.arange(3)) & 1
    low, high = np.asarray(box_min)[..., None, :], np.asarray(box_max)[..., None, :]
    return np.where(bits == 1, high, low)
