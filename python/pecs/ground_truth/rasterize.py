"""The surface seen at a time between stored frames, rebuilt from the stored frames' surfaces.

The stored frames' surfaces (one world point per pixel) are moved to time t with their shapes'
exact motions and meshed: two triangles for every 2 x 2 block of pixels that see the same
instance. Each triangle is rasterised into the camera at t (a z-buffer keeps the nearest), and
the point through each pixel centre is the exact intersection of its ray with the triangle's
plane (1/depth is affine across a planar triangle in the undistorted image plane). On planar
faces this is the surface the renderer would have hit, to rounding; across a crease or a
curve it is the chord. Each point carries a bound on its z-depth error: how far the 4 x 4
pixels around its triangle (same instance) are from the triangle's plane, 0 on a plane. Pixels
no triangle covers (within a pixel of an instance's outline, or surfaces no stored frame saw)
get the nearest moved point, off the pixel's ray, and farther surfaces within a pixel of a
nearer instance's points may be hidden by its outline: both get the bound inf.
"""

from __future__ import annotations

from collections.abc import Callable, Sequence
from dataclasses import dataclass

import numpy as np

from pecs.ground_truth.intrinsics import CameraModel
from pecs.ground_truth.surface import BACKGROUND, SurfaceHits, moved_points, to_camera

# Barycentric slack: a pixel centre on an edge shared by two triangles belongs to both.
_EDGE_TOLERANCE = 1e-9
# Pixels searched around a triangle's corners (the distortion's bend of its edges is far less).
_BOUNDS_MARGIN_PX = 0.01


def surface_at(
    sources: Sequence[SurfaceHits],
    motions: Sequence[Callable[[int], np.ndarray | None]],
    camera_to_world: np.ndarray,
    model: CameraModel,
) -> tuple[SurfaceHits, np.ndarray]:
    """The surface seen by the camera `camera_to_world` from stored surfaces `sources`, each
    moved by `motions[k]` (shape index -> world motion from its time to the new one). Returns
    the surface and a bound on each point's z-depth error, metres (inf: not on the pixel's
    ray; where nothing is seen: inf too)."""
    height, width = model.height, model.width
    rows, columns = np.mgrid[0:height, 0:width]
    plane_grid = model.undistort(columns, rows)
    candidates = [
        _rasterise(
            moved_points(source, motion), source.shape_index, camera_to_world, model, plane_grid
        )
        for source, motion in zip(sources, motions, strict=True)
    ]
    pixel, depth, instance, error = (np.concatenate(c) for c in zip(*candidates, strict=True))
    _, first = _nearest_per_pixel(pixel, depth)
    covered, d = pixel[first], depth[first]
    camera_points = np.column_stack(
        [plane_grid.reshape(-1, 2)[covered] * d[:, None], d + model.centre_z_m]
    )
    points = np.full((height * width, 3), np.nan)
    points[covered] = camera_points @ camera_to_world[:3, :3].T + camera_to_world[:3, 3]
    index = np.full(height * width, BACKGROUND, np.int32)
    index[covered] = instance[first]
    depth_error = np.full(height * width, np.inf)
    depth_error[covered] = error[first]
    splat = _splat(sources, motions, camera_to_world, model)
    # An outline reaches up to a pixel past its outermost point: a farther surface rebuilt
    # next to a nearer instance's points may be hidden there.
    depth_error[_beside_nearer(splat, index, points, camera_to_world, model)] = np.inf
    uncovered = index == BACKGROUND
    points[uncovered] = splat.points[uncovered]
    index[uncovered] = splat.instance[uncovered]
    hits = SurfaceHits(
        points.reshape(height, width, 3), index.reshape(height, width), camera_to_world
    )
    return hits, depth_error.reshape(height, width)


def _rasterise(
    moved_world: np.ndarray,
    shape_index: np.ndarray,
    camera_to_world: np.ndarray,
    model: CameraModel,
    plane_grid: np.ndarray,
) -> tuple[np.ndarray, np.ndarray, np.ndarray, np.ndarray]:
    """(pixel, depth, instance, depth error bound) of every pixel centre inside a triangle of
    the moved surface."""
    height, width = model.height, model.width
    camera = to_camera(moved_world, camera_to_world)
    depth = camera[..., 2] - model.centre_z_m
    with np.errstate(invalid="ignore", divide="ignore"):
        plane = camera[..., :2] / depth[..., None]
    pixels = model.project(camera)
    usable = (shape_index != BACKGROUND) & (depth > 0)
    triangles, bend = _triangles(usable, shape_index, plane, depth)
    flat_plane, flat_pixels = plane.reshape(-1, 2), pixels.reshape(-1, 2)
    planes = _InverseDepth(flat_plane, depth.reshape(-1), triangles)
    corner_pixels = flat_pixels[triangles]  # (n, 3, 2)
    # The triangle's pixel-space bounds, with a margin for the lens's distortion bending its
    # edges (far below 0.01 px over a pixel); inside-tests are done in the undistorted plane,
    # where the triangle is exact.
    low = np.ceil(corner_pixels.min(axis=1) - _BOUNDS_MARGIN_PX).astype(np.int64)
    high = np.floor(corner_pixels.max(axis=1) + _BOUNDS_MARGIN_PX).astype(np.int64)
    low = np.maximum(low, 0)
    high = np.minimum(high, [width - 1, height - 1])
    sizes = np.maximum(high - low + 1, 0)
    counts = sizes[:, 0] * sizes[:, 1]
    triangle = np.repeat(np.arange(len(triangles)), counts)
    offset = np.arange(counts.sum()) - np.repeat(np.cumsum(counts) - counts, counts)
    u = low[triangle, 0] + offset % sizes[triangle, 0]
    v = low[triangle, 1] + offset // sizes[triangle, 0]
    weights = _barycentric(flat_plane[triangles[triangle]], plane_grid[v, u])
    inside = np.all(weights >= -_EDGE_TOLERANCE, axis=1)
    triangle, u, v = triangle[inside], u[inside], v[inside]
    inverse_depth = planes.at(plane_grid[v, u], triangle)
    instance = shape_index.reshape(-1)[triangles[triangle, 0]]
    return v * width + u, 1.0 / inverse_depth, instance.astype(np.int32), bend[triangle]


def _triangles(
    usable: np.ndarray, shape_index: np.ndarray, plane: np.ndarray, depth: np.ndarray
) -> tuple[np.ndarray, np.ndarray]:
    """(n, 3) flat pixel indices, two triangles per 2 x 2 block seeing one instance, and each
    triangle's departure from the surface around it (z-depth, metres): the largest difference
    between the z-depth of a pixel of the 4 x 4 block around it (same instance) and the one
    its plane gives that pixel's ray. Zero on a plane; a chord across a crease parallel to
    the pixel grid is planar with its own four corners, not with the ring around them."""
    height, width = usable.shape
    ids = np.arange(height * width).reshape(height, width)
    a, b = ids[:-1, :-1], ids[:-1, 1:]
    c, d = ids[1:, :-1], ids[1:, 1:]
    same = shape_index[:-1, :-1]
    block = (
        usable[:-1, :-1]
        & usable[:-1, 1:]
        & usable[1:, :-1]
        & usable[1:, 1:]
        & (shape_index[:-1, 1:] == same)
        & (shape_index[1:, :-1] == same)
        & (shape_index[1:, 1:] == same)
    )
    first = np.stack([a[block], b[block], c[block]], axis=-1)
    second = np.stack([b[block], d[block], c[block]], axis=-1)
    flat_plane, flat_depth = plane.reshape(-1, 2), depth.reshape(-1)
    rows, columns = np.nonzero(block)
    instance = shape_index[rows, columns]
    everyone = np.arange(len(rows))
    bends = []
    for triangles in (first, second):
        planes = _InverseDepth(flat_plane, flat_depth, triangles)
        bend = np.zeros(len(triangles))
        for dv in (-1, 0, 1, 2):
            for du in (-1, 0, 1, 2):
                v, u = rows + dv, columns + du
                there = (v >= 0) & (v < height) & (u >= 0) & (u < width)
                v, u = np.where(there, v, 0), np.where(there, u, 0)
                there &= usable[v, u] & (shape_index[v, u] == instance)
                other = ids[v, u]
                # 1/z is affine over a plane in the undistorted image plane: extrapolate it.
                with np.errstate(divide="ignore", invalid="ignore"):
                    off = np.abs(flat_depth[other] - 1.0 / planes.at(flat_plane[other], everyone))
                off = np.where(np.isfinite(off), off, np.inf)
                bend = np.maximum(bend, np.where(there, off, 0.0))
        bends.append(bend)
    return np.concatenate([first, second]), np.concatenate(bends)


class _InverseDepth:
    """1/z over each triangle's plane as an affine function of the undistorted image plane:
    1/z(q) = w0 + g . (q - p0), from its three corners (NaN for a degenerate triangle)."""

    def __init__(self, plane: np.ndarray, depth: np.ndarray, triangles: np.ndarray) -> None:
        p = plane[triangles]
        w = 1.0 / depth[triangles]
        e1, e2 = p[:, 1] - p[:, 0], p[:, 2] - p[:, 0]
        dw1, dw2 = w[:, 1] - w[:, 0], w[:, 2] - w[:, 0]
        area = e1[:, 0] * e2[:, 1] - e1[:, 1] * e2[:, 0]
        with np.errstate(divide="ignore", invalid="ignore"):
            gx = (e2[:, 1] * dw1 - e1[:, 1] * dw2) / area
            gy = (e1[:, 0] * dw2 - e2[:, 0] * dw1) / area
        self.origin, self.w0 = p[:, 0], w[:, 0]
        self.gradient = np.column_stack([gx, gy])

    def at(self, points: np.ndarray, which: np.ndarray) -> np.ndarray:
        """1/z of triangles `which` at `points` (n, 2)."""
        offset = points - self.origin[which]
        return self.w0[which] + np.einsum("ij,ij->i", self.gradient[which], offset)


def _barycentric(corners: np.ndarray, points: np.ndarray) -> np.ndarray:
    """(n, 3) barycentric weights of 2D `points` (n, 2) in triangles `corners` (n, 3, 2);
    degenerate triangles give NaN (never inside)."""
    p0, p1, p2 = corners[:, 0], corners[:, 1], corners[:, 2]
    e1, e2, q = p1 - p0, p2 - p0, points - p0
    area = e1[:, 0] * e2[:, 1] - e1[:, 1] * e2[:, 0]
    with np.errstate(invalid="ignore", divide="ignore"):
        w1 = (q[:, 0] * e2[:, 1] - q[:, 1] * e2[:, 0]) / area
        w2 = (e1[:, 0] * q[:, 1] - e1[:, 1] * q[:, 0]) / area
    weights = np.column_stack([1.0 - w1 - w2, w1, w2])
    weights[area == 0] = np.nan
    return weights


def _nearest_per_pixel(pixel: np.ndarray, depth: np.ndarray) -> tuple[np.ndarray, np.ndarray]:
    """The candidate nearest the camera at each pixel: (pixels, index of the winner)."""
    order = np.lexsort((depth, pixel))
    winners, first = np.unique(pixel[order], return_index=True)
    return winners, order[first]


@dataclass(frozen=True)
class _Splat:
    """Per pixel (flat): the nearest moved point that lands in it (NaN, BACKGROUND, inf: none)."""

    points: np.ndarray
    instance: np.ndarray
    depth: np.ndarray


def _splat(
    sources: Sequence[SurfaceHits],
    motions: Sequence[Callable[[int], np.ndarray | None]],
    camera_to_world: np.ndarray,
    model: CameraModel,
) -> _Splat:
    """Every moved point at its nearest pixel, the nearest to the camera kept: off the pixel's
    ray by up to half a pixel (outlines and their instances, not exact geometry)."""
    height, width = model.height, model.width
    pixel_parts, depth_parts, point_parts, instance_parts = [], [], [], []
    for source, motion in zip(sources, motions, strict=True):
        moved = moved_points(source, motion).reshape(-1, 3)
        camera = to_camera(moved, camera_to_world)
        uv = np.rint(model.project(camera))
        keep = np.isfinite(uv).all(axis=1) & (source.shape_index.reshape(-1) != BACKGROUND)
        uv = uv[keep].astype(np.int64)
        inside = (uv[:, 0] >= 0) & (uv[:, 0] < width) & (uv[:, 1] >= 0) & (uv[:, 1] < height)
        pixel_parts.append(uv[inside, 1] * width + uv[inside, 0])
        depth_parts.append(camera[keep][inside, 2] - model.centre_z_m)
        point_parts.append(moved[keep][inside])
        instance_parts.append(source.shape_index.reshape(-1)[keep][inside])
    pixel, depth = np.concatenate(pixel_parts), np.concatenate(depth_parts)
    winners, first = _nearest_per_pixel(pixel, depth)
    splat = _Splat(
        np.full((height * width, 3), np.nan),
        np.full(height * width, BACKGROUND, np.int32),
        np.full(height * width, np.inf),
    )
    splat.points[winners] = np.concatenate(point_parts)[first]
    splat.instance[winners] = np.concatenate(instance_parts)[first]
    splat.depth[winners] = depth[first]
    return splat


def _beside_nearer(
    splat: _Splat,
    index: np.ndarray,
    points: np.ndarray,
    camera_to_world: np.ndarray,
    model: CameraModel,
) -> np.ndarray:
    """Flat mask: pixels with a point of another instance, nearer by more than 1e-3 of the
    depth, landing in them or in one of their 8 neighbours."""
    height, width = model.height, model.width
    depth = to_camera(points, camera_to_world)[:, 2] - model.centre_z_m
    depth = np.where(index == BACKGROUND, np.inf, depth).reshape(height, width)
    mine = index.reshape(height, width)
    near_depth = np.pad(splat.depth.reshape(height, width), 1, constant_values=np.inf)
    near_instance = np.pad(splat.instance.reshape(height, width), 1, constant_values=BACKGROUND)
    beside = np.zeros((height, width), bool)
    for dv in (0, 1, 2):
        for du in (0, 1, 2):
            other = near_instance[dv : dv + height, du : du + width]
            nearer = near_depth[dv : dv + height, du : du + width] < depth * (1.0 - 1e-3)
            beside |= nearer & (other != mine) & (other != BACKGROUND)
    return beside.reshape(-1)
