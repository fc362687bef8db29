"""What each pixel sees: the first surface along its central ray, and the geometry derived from
it (z-depth, and the motion field: where that surface point is seen one frame later)."""

from __future__ import annotations

from collections.abc import Callable
from dataclasses import dataclass

import numpy as np

from pecs.ground_truth.intrinsics import CameraModel

#: Instance value of pixels that see no surface.
BACKGROUND = -1


@dataclass(frozen=True)
class SurfaceHits:
    """Per pixel (H x W): the world point hit (NaN where none) and the index of the shape hit
    in `shape_ids` (BACKGROUND where none)."""

    points_world: np.ndarray
    shape_index: np.ndarray
    camera_to_world: np.ndarray
    #: Per pixel the surface's shading normal (unit, world frame; NaN where no surface), when
    #: the renderer gave it.
    normals_world: np.ndarray | None = None

    @property
    def valid(self) -> np.ndarray:
        return self.shape_index != BACKGROUND


def z_depth_m(hits: SurfaceHits, model: CameraModel) -> np.ndarray:
    """Distance of each hit from the projection centre along the optical axis, metres (inf: none)."""
    camera = to_camera(hits.points_world, hits.camera_to_world)
    depth = camera[..., 2] - model.centre_z_m
    return np.where(hits.valid, depth, np.inf).astype(np.float32)


def motion_field_px(
    hits: SurfaceHits,
    next_camera_to_world: np.ndarray,
    shape_motion: Callable[[int], np.ndarray | None],
    model: CameraModel,
) -> np.ndarray:
    """H x W x 2 pixels moved (du, dv) by each pixel's surface point until the next frame.

    The point moves rigidly with its shape (`shape_motion(index)`: the 4x4 taking the shape's
    pose now to its pose at the next frame, None when the shape is static), then is projected by
    the next frame's camera. Occlusion is not considered (the motion field of the visible point);
    NaN where no surface was hit or the point ends behind the camera."""
    moved = moved_points(hits, shape_motion)
    projected = model.project(to_camera(moved, next_camera_to_world))
    height, width = hits.shape_index.shape
    rows, columns = np.mgrid[0:height, 0:width]
    flow = projected - np.stack([columns, rows], axis=-1)
    flow[~hits.valid] = np.nan
    return flow.astype(np.float32)


def moved_points(hits: SurfaceHits, shape_motion: Callable[[int], np.ndarray | None]) -> np.ndarray:
    """Each pixel's world point moved rigidly with its shape (`shape_motion(index)`: a 4x4
    world motion, None when the shape stays), float64 H x W x 3 (NaN where no surface)."""
    moved = hits.points_world.astype(np.float64)
    for index in np.unique(hits.shape_index[hits.valid]):
        motion = shape_motion(int(index))
        if motion is None:
            continue
        mask = hits.shape_index == index
        moved[mask] = moved[mask] @ motion[:3, :3].T + motion[:3, 3]
    return moved


def normals_camera(hits: SurfaceHits) -> np.ndarray:
    """Unit surface normals in the camera frame, turned to face the camera (a surface seen from
    behind gets its back's normal), float32 H x W x 3; NaN where no surface."""
    if hits.normals_world is None:
        raise ValueError("surface normals: the renderer gave none for this frame")
    rotation = hits.camera_to_world[:3, :3]
    # Normals transform with the inverse transpose; for camera-to-world M that is M^T.
    normals = hits.normals_world.astype(np.float64) @ rotation
    normals /= np.linalg.norm(normals, axis=-1, keepdims=True)
    view = to_camera(hits.points_world.astype(np.float64), hits.camera_to_world)
    away = np.einsum("...i,...i->...", normals, view) > 0
    normals[away] *= -1.0
    normals[~hits.valid] = np.nan
    return normals.astype(np.float32)


def to_camera(points_world: np.ndarray, camera_to_world: np.ndarray) -> np.ndarray:
    """World points (..., 3) in the camera frame (the full inverse: a scaled camera stays exact)."""
    world_to_camera = np.linalg.inv(camera_to_world)
    return points_world @ world_to_camera[:3, :3].T + world_to_camera[:3, 3]
