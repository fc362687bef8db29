"""Flow between any two times, from geometry, with an occlusion and validity mask.

The point seen through each pixel at t0 (its z-depth back-projected through the camera model,
in the world by the camera's pose) moves rigidly with its shape from t0 to t1 (the shape's
animation transform M(t1) M(t0)^-1; static shapes stay) and is projected by the camera at t1.
The point is valid when it is inside the image at t1 and visible there: the surface seen at
t1 at the pixel nearest its projection is the same instance at the same z-depth (within
1e-3 of the depth plus the depth's change over one pixel there, which covers the half pixel
between the projection and that pixel centre), and its flow is known to 1e-3 px: a surface
rebuilt between frames carries a bound on each point's z-depth error, and the point moved by
that bound along its ray must land within 1e-3 px of where it lands.
"""

from __future__ import annotations

from collections.abc import Callable
from dataclasses import dataclass

import numpy as np

from pecs.ground_truth.intrinsics import CameraModel
from pecs.ground_truth.surface import BACKGROUND, SurfaceHits, moved_points, to_camera, z_depth_m

# Relative z-depth agreement for "the same surface point" (float32 depths, sub-pixel offsets).
_DEPTH_RTOL = 1e-3
#: The flow a valid pixel's geometry pins down, pixels.
FLOW_TOLERANCE_PX = 1e-3


@dataclass(frozen=True)
class FlowBetween:
    """Where the point seen through each pixel at t0_us is seen at t1_us (either order)."""

    t0_us: int
    t1_us: int
    #: float32 H x W x 2: (du right, dv down) pixels; NaN where the pixel sees no surface at t0
    #: or its point is behind the camera at t1. Finite but not `valid` where occluded or
    #: outside the image at t1: the motion field of the point all the same.
    flow_px: np.ndarray
    #: bool H x W: the point is seen at both times, inside the image at t1, and its flow is
    #: known to FLOW_TOLERANCE_PX (see `GroundTruth.flow_between`).
    valid: np.ndarray
    #: bool H x W: the point lands inside the image at t1 but something else is seen there
    #: (another object, or another part of its own).
    occluded: np.ndarray


def surface_from_depth(
    depth_m: np.ndarray, instance: np.ndarray, camera_to_world: np.ndarray, model: CameraModel
) -> SurfaceHits:
    """A stored frame's surface: each pixel's z-depth back-projected through the camera model
    into the world (NaN and BACKGROUND where no surface)."""
    rows, columns = np.mgrid[0 : model.height, 0 : model.width]
    seen = np.isfinite(depth_m) & (instance != BACKGROUND)
    camera = model.unproject(columns, rows, np.where(seen, depth_m, 1.0))
    world = camera @ camera_to_world[:3, :3].T + camera_to_world[:3, 3]
    world[~seen] = np.nan
    return SurfaceHits(
        world, np.where(seen, instance, BACKGROUND).astype(np.int32), camera_to_world
    )


def flow_between_surfaces(
    t0_us: int,
    t1_us: int,
    start: SurfaceHits,
    start_depth_error_m: np.ndarray,
    end: SurfaceHits,
    shape_motion: Callable[[int], np.ndarray | None],
    model: CameraModel,
) -> FlowBetween:
    """Flow from the surface `start` (at t0; each point's z-depth known to
    `start_depth_error_m`) to the camera of `end` (the surface at t1, for occlusion);
    `shape_motion(index)` moves a shape from t0 to t1 (None: static)."""
    camera = to_camera(moved_points(start, shape_motion), end.camera_to_world)
    projected = model.project(camera)
    rows, columns = np.mgrid[0 : model.height, 0 : model.width]
    flow = projected - np.stack([columns, rows], axis=-1)
    flow[~start.valid] = np.nan
    landed = np.isfinite(flow).all(axis=-1)
    nearest = np.rint(np.where(landed[..., None], projected, -1.0)).astype(np.int64)
    u, v = nearest[..., 0], nearest[..., 1]
    inside = landed & (u >= 0) & (u < model.width) & (v >= 0) & (v < model.height)
    point_depth = camera[..., 2] - model.centre_z_m
    u, v = np.where(inside, u, 0), np.where(inside, v, 0)
    same = _seen_there(end, model, u, v, start.shape_index, point_depth)
    seen = inside & _flow_known(start, start_depth_error_m, shape_motion, end, model, projected)
    return FlowBetween(t0_us, t1_us, flow.astype(np.float32), seen & same, seen & ~same)


def _seen_there(
    end: SurfaceHits,
    model: CameraModel,
    u: np.ndarray,
    v: np.ndarray,
    instance: np.ndarray,
    depth_m: np.ndarray,
) -> np.ndarray:
    """Whether pixel (u, v) of the surface `end` sees the point of instance `instance` at
    z-depth `depth_m` that lands within half a pixel of it."""
    end_depth = z_depth_m(end, model).astype(np.float64)
    tolerance = _DEPTH_RTOL * depth_m + _depth_step(end_depth, end.shape_index)[v, u]
    return (end.shape_index[v, u] == instance) & (np.abs(depth_m - end_depth[v, u]) <= tolerance)


def _flow_known(
    start: SurfaceHits,
    depth_error_m: np.ndarray,
    shape_motion: Callable[[int], np.ndarray | None],
    end: SurfaceHits,
    model: CameraModel,
    projected: np.ndarray,
) -> np.ndarray:
    """Where the flow is pinned to FLOW_TOLERANCE_PX: the point slid along its t0 ray by its
    depth error lands as close (zero error: everywhere there is a surface)."""
    error = np.where(start.valid, depth_error_m, np.inf)
    known = error == 0.0
    loose = start.valid & (error > 0.0) & np.isfinite(error)
    if not loose.any():
        return known
    camera = to_camera(start.points_world, start.camera_to_world)
    depth = camera[..., 2] - model.centre_z_m
    scale = 1.0 + np.where(loose, error / np.where(loose, depth, 1.0), 0.0)
    centre = np.array([0.0, 0.0, model.centre_z_m])
    slid = (camera - centre) * scale[..., None] + centre
    world = slid @ start.camera_to_world[:3, :3].T + start.camera_to_world[:3, 3]
    shifted = SurfaceHits(world, start.shape_index, start.camera_to_world)
    moved = model.project(to_camera(moved_points(shifted, shape_motion), end.camera_to_world))
    spread = np.linalg.norm(moved - projected, axis=-1)
    return known | (loose & (spread <= FLOW_TOLERANCE_PX))


def _depth_step(depth_m: np.ndarray, instance: np.ndarray) -> np.ndarray:
    """Largest z-depth change from each pixel to a 4-neighbour of the same instance, metres
    (0 where none): how much the depth may differ half a pixel away on the same surface."""
    step = np.zeros_like(depth_m)
    for axis in (0, 1):
        change = np.abs(np.diff(depth_m, axis=axis))
        same = np.diff(instance, axis=axis) == 0
        change = np.where(same & np.isfinite(change), change, 0.0)
        lead = [slice(None), slice(None)]
        lead[axis] = slice(None, -1)
        step[tuple(lead)] = np.maximum(step[tuple(lead)], change)
        lead[axis] = slice(1, None)
        step[tuple(lead)] = np.maximum(step[tuple(lead)], change)
    return step
