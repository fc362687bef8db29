"""Shapes of generated objects: Mitsuba's primitives, and meshes made with trimesh (boxes, capped
cylinders, tori, extruded outlines) or here (superquadrics, random convex hulls), written as PLY.

Every shape is drawn as its kind, its bounding radius (`size_m`: the farthest point from its
centre) and a few proportions; meshes are built from those when the scene is written, so that a
description stays small. Mesh vertices are in the object's frame, centred on the origin; its
pose is the `to_world` of the Mitsuba shape. Textured meshes need uv coordinates: box projection
for faceted shapes, the surface's own angles for tori and superquadrics.

trimesh's convex hull needs SciPy (a test-only dependency of pecs), so the hull of the dozen or
so drawn points is found here by brute force: every triangle with all other points on one side.
"""

from __future__ import annotations

import itertools
import math
from pathlib import Path
from typing import Any

import numpy as np

PRIMITIVES = ("sphere", "cube", "cylinder", "rectangle")
MESHES = ("box", "capped_cylinder", "torus", "superquadric", "convex_hull", "extrusion")
SHAPES = PRIMITIVES + MESHES
#: Surfaces with a visible back side (no inside): two-sided materials, thin dielectrics.
OPEN_SURFACES = ("cylinder", "rectangle")
# Fixed ranges of the proportions (documented in docs/datasets.md).
CYLINDER_ASPECT = (0.3, 2.0)  # height / diameter
RECTANGLE_ASPECT = (0.3, 1.0)  # short side / long side
BOX_EXTENTS = (0.3, 1.0)  # each side relative to the longest possible
TORUS_THICKNESS = (0.15, 0.5)  # tube radius / ring radius
SUPERQUADRIC_EXPONENT = (0.3, 2.0)  # < 1 boxy, 1 ellipsoid, 2 octahedron-like
SUPERQUADRIC_AXES = (0.5, 1.0)
HULL_POINTS = (8, 20)
HULL_AXES = (0.5, 1.0)
EXTRUSION_CORNERS = (5, 12)
EXTRUSION_RADIUS = (0.45, 1.0)
EXTRUSION_DEPTH = (0.2, 1.0)  # thickness / outline radius


def describe_shape(kind: str, size_m: float, rng: np.random.Generator) -> dict[str, Any]:
    """The drawn proportions of a shape of `kind` whose bounding radius is `size_m`."""
    shape: dict[str, Any] = {"kind": kind, "size_m": size_m}
    if kind in ("cylinder", "capped_cylinder"):
        shape["aspect"] = float(rng.uniform(*CYLINDER_ASPECT))
    elif kind == "rectangle":
        shape["aspect"] = float(rng.uniform(*RECTANGLE_ASPECT))
    elif kind == "box":
        shape["extents"] = [float(v) for v in rng.uniform(*BOX_EXTENTS, 3)]
    elif kind == "torus":
        shape["thickness"] = float(rng.uniform(*TORUS_THICKNESS))
    elif kind == "superquadric":
        shape["exponents"] = [float(v) for v in rng.uniform(*SUPERQUADRIC_EXPONENT, 2)]
        shape["axes"] = [float(v) for v in rng.uniform(*SUPERQUADRIC_AXES, 3)]
    elif kind == "convex_hull":
        shape["points"] = int(rng.integers(HULL_POINTS[0], HULL_POINTS[1], endpoint=True))
        shape["axes"] = [float(v) for v in rng.uniform(*HULL_AXES, 3)]
        shape["seed"] = int(rng.integers(0, 2**63 - 1))
    elif kind == "extrusion":
        corners = int(rng.integers(EXTRUSION_CORNERS[0], EXTRUSION_CORNERS[1], endpoint=True))
        shape["corners"] = corners
        shape["depth"] = float(rng.uniform(*EXTRUSION_DEPTH))
        shape["seed"] = int(rng.integers(0, 2**63 - 1))
    elif kind not in PRIMITIVES:
        raise ValueError(f"unknown shape {kind!r} (known: {', '.join(SHAPES)})")
    return shape


def primitive_scale(shape: dict[str, Any]) -> np.ndarray:
    """The 4x4 object-frame transform of a Mitsuba primitive (unit sphere, cube [-1, 1]^3,
    cylinder of radius 1 from z = 0 to 1, rectangle [-1, 1]^2) to the drawn proportions."""
    r = shape["size_m"]
    kind = shape["kind"]
    if kind == "sphere":
        return np.diag([r, r, r, 1.0])
    if kind == "cube":
        return np.diag([r / math.sqrt(3.0)] * 3 + [1.0])
    if kind == "cylinder":
        radius = r / math.sqrt(1.0 + shape["aspect"] ** 2)  # corner of the side at distance r
        height = 2.0 * radius * shape["aspect"]
        matrix = np.diag([radius, radius, height, 1.0])
        matrix[2, 3] = -0.5 * height  # centred on the origin
        return matrix
    if kind == "rectangle":
        half_width = r / math.sqrt(1.0 + shape["aspect"] ** 2)
        return np.diag([half_width, half_width * shape["aspect"], 1.0, 1.0])
    raise ValueError(f"{kind!r} is not a Mitsuba primitive ({', '.join(PRIMITIVES)})")


class Mesh:
    """Triangles with one vertex per corner (so that uv and normals may jump across edges)."""

    def __init__(
        self,
        vertices: np.ndarray,
        faces: np.ndarray,
        uv: np.ndarray,
        normals: np.ndarray | None,
    ) -> None:
        self.vertices, self.faces, self.uv, self.normals = vertices, faces, uv, normals


def build_mesh(shape: dict[str, Any]) -> Mesh:
    """The mesh of a drawn mesh shape, centred, its farthest vertex at `size_m`."""
    import trimesh.creation

    kind = shape["kind"]
    if kind == "box":
        solid = trimesh.creation.box(extents=shape["extents"])
        return _faceted(solid.vertices, solid.faces, shape["size_m"])
    if kind == "capped_cylinder":
        solid = trimesh.creation.cylinder(radius=1.0, height=2.0 * shape["aspect"], sections=32)
        return _faceted(solid.vertices, solid.faces, shape["size_m"])
    if kind == "torus":
        solid = trimesh.creation.torus(
            major_radius=1.0, minor_radius=shape["thickness"], major_sections=48, minor_sections=24
        )
        return _torus(solid, shape["size_m"])
    if kind == "superquadric":
        return superquadric(shape["exponents"], shape["axes"], shape["size_m"])
    if kind == "convex_hull":
        vertices, faces = random_convex_hull(shape)
        return _faceted(vertices, faces, shape["size_m"])
    if kind == "extrusion":
        solid = _extrusion(shape)
        return _faceted(solid.vertices, solid.faces, shape["size_m"])
    raise ValueError(f"{kind!r} is not a mesh shape ({', '.join(MESHES)})")


def _normalised(vertices: np.ndarray, size_m: float) -> np.ndarray:
    """Centred on the bounding box's centre, the farthest vertex at `size_m`."""
    vertices = np.asarray(vertices, dtype=np.float64)
    centred = vertices - 0.5 * (vertices.min(axis=0) + vertices.max(axis=0))
    return centred * (size_m / np.linalg.norm(centred, axis=1).max())


def _faceted(vertices: np.ndarray, faces: np.ndarray, size_m: float) -> Mesh:
    """Flat-shaded (Mitsuba uses face normals without vertex normals), uv by box projection:
    each face takes the two coordinates across its normal's largest component."""
    vertices = _normalised(vertices, size_m)
    faces = np.asarray(faces, dtype=np.int64)
    corners = vertices[faces]  # (m, 3, 3)
    normal = np.cross(corners[:, 1] - corners[:, 0], corners[:, 2] - corners[:, 0])
    axis = np.argmax(np.abs(normal), axis=1)
    across = np.array([[1, 2], [0, 2], [0, 1]])[axis]  # (m, 2)
    uv = np.take_along_axis(corners, across[:, None, :].repeat(3, axis=1), axis=2)
    uv = uv / (2.0 * size_m) + 0.5
    return Mesh(
        corners.reshape(-1, 3), np.arange(faces.size).reshape(-1, 3), uv.reshape(-1, 2), None
    )


def _torus(solid: Any, size_m: float) -> Mesh:
    """Smooth normals, from the nearest point of the ring (trimesh's vertex normals differ in
    their last bits with and without SciPy), uv from the ring and tube angles (around z)."""
    scale = size_m / np.linalg.norm(solid.vertices, axis=1).max()
    vertices = np.asarray(solid.vertices) * scale
    faces = np.asarray(solid.faces, dtype=np.int64)
    ring = np.arctan2(vertices[:, 1], vertices[:, 0])
    radial = np.hypot(vertices[:, 0], vertices[:, 1])
    ring_radius = 0.5 * (radial.max() + radial.min())
    tube = np.arctan2(vertices[:, 2], radial - ring_radius)
    normals = np.column_stack(
        [np.cos(tube) * np.cos(ring), np.cos(tube) * np.sin(ring), np.sin(tube)]
    )
    uv = np.stack([ring, tube], axis=1)[faces] / (2.0 * math.pi) + 0.5  # (m, 3, 2)
    uv = _unwrapped(uv)
    return Mesh(
        vertices[faces].reshape(-1, 3),
        np.arange(faces.size).reshape(-1, 3),
        uv.reshape(-1, 2),
        normals[faces].reshape(-1, 3),
    )


def _unwrapped(uv: np.ndarray) -> np.ndarray:
    """Per face, angles that wrap (a corner near 1 and another near 0) moved past 1: the
    texture repeats, so the face then samples one continuous patch."""
    uv = uv.copy()
    for k in range(2):
        values = uv[:, :, k]
        wraps = values.max(axis=1) - values.min(axis=1) > 0.5
        values[wraps] = np.where(values[wraps] < 0.5, values[wraps] + 1.0, values[wraps])
    return uv


def superquadric(
    exponents: list[float], axes: list[float], size_m: float, rings: int = 24, segments: int = 48
) -> Mesh:
    """Barr's superellipsoid: x = a1 c(eta)^e1 c(w)^e2, y = a2 c(eta)^e1 s(w)^e2,
    z = a3 s(eta)^e1 (signed powers), eta in [-pi/2, pi/2], w in [-pi, pi]; normals from the
    same formula with exponents 2 - e and axes inverted; uv = (w, eta). trimesh has no
    superquadric. The grid repeats the seam column and the pole rows (their own uv); the
    triangles that would be degenerate at the poles are left out."""
    e1, e2 = exponents
    eta = np.linspace(-math.pi / 2, math.pi / 2, rings + 1)
    omega = np.linspace(-math.pi, math.pi, segments + 1)
    ee, ww = np.meshgrid(eta, omega, indexing="ij")
    a = np.asarray(axes, dtype=np.float64)
    vertices = np.stack(
        [
            a[0] * _power(np.cos(ee), e1) * _power(np.cos(ww), e2),
            a[1] * _power(np.cos(ee), e1) * _power(np.sin(ww), e2),
            a[2] * _power(np.sin(ee), e1),
        ],
        axis=-1,
    ).reshape(-1, 3)
    normals = np.stack(
        [
            _power(np.cos(ee), 2 - e1) * _power(np.cos(ww), 2 - e2) / a[0],
            _power(np.cos(ee), 2 - e1) * _power(np.sin(ww), 2 - e2) / a[1],
            _power(np.sin(ee), 2 - e1) / a[2],
        ],
        axis=-1,
    ).reshape(-1, 3)
    length = np.linalg.norm(normals, axis=1, keepdims=True)
    normals = np.where(length > 0, normals / np.maximum(length, 1e-300), [0.0, 0.0, 1.0])
    # At the poles cos(eta) = 0 exactly only in exact arithmetic: fix their normals.
    normals[: segments + 1] = [0.0, 0.0, -1.0]
    normals[-(segments + 1) :] = [0.0, 0.0, 1.0]
    uv = np.stack([(ww + math.pi) / (2 * math.pi), (ee + math.pi / 2) / math.pi], axis=-1)
    faces = _grid_faces(rings, segments)
    scale = size_m / np.linalg.norm(vertices, axis=1).max()
    return Mesh(vertices * scale, faces, uv.reshape(-1, 2), normals)


def _power(value: np.ndarray, exponent: float) -> np.ndarray:
    """sign(v) |v|^e, with |v| below rounding (cos(pi/2) = 6e-17) taken as 0."""
    magnitude = np.abs(value)
    magnitude = np.where(magnitude < 1e-12, 0.0, magnitude)
    return np.sign(value) * magnitude**exponent


def _grid_faces(rings: int, segments: int) -> np.ndarray:
    """Two triangles per grid cell (counter-clockwise seen from outside), one at the poles."""
    columns = segments + 1
    faces = []
    for j in range(rings):
        for i in range(segments):
            a, b = j * columns + i, j * columns + i + 1
            c, d = (j + 1) * columns + i + 1, (j + 1) * columns + i
            if j > 0:
                faces.append((a, b, c))
            if j < rings - 1:
                faces.append((a, c, d))
    return np.array(faces, dtype=np.int64)


def random_convex_hull(shape: dict[str, Any]) -> tuple[np.ndarray, np.ndarray]:
    """The hull of `points` random points on an ellipsoid of the drawn axes (all of them are
    corners): vertices and outward triangles. Drawn again, from the same generator, in the
    (measure-zero) case of four nearly coplanar points."""
    rng = np.random.default_rng(shape["seed"])
    while True:
        directions = rng.normal(size=(shape["points"], 3))
        points = directions / np.linalg.norm(directions, axis=1, keepdims=True)
        points = points * np.asarray(shape["axes"])
        faces = _hull_faces(points)
        if len(faces) == 2 * len(points) - 4:  # Euler: a triangulated hull of n corners
            return points, faces


def _hull_faces(points: np.ndarray) -> np.ndarray:
    """Every triangle whose plane has all the other points strictly on one side, turned to
    face away from them."""
    n = len(points)
    triples = np.array(list(itertools.combinations(range(n), 3)), dtype=np.int64)
    p0, p1, p2 = points[triples[:, 0]], points[triples[:, 1]], points[triples[:, 2]]
    normal = np.cross(p1 - p0, p2 - p0)
    side = points @ normal.T - np.sum(normal * p0, axis=1)  # (n, triples)
    member = np.zeros_like(side, dtype=bool)
    member[triples[:, 0], np.arange(len(triples))] = True
    member[triples[:, 1], np.arange(len(triples))] = True
    member[triples[:, 2], np.arange(len(triples))] = True
    tolerance = 1e-9 * np.linalg.norm(normal, axis=1)
    below = np.all((side < -tolerance) | member, axis=0)
    above = np.all((side > tolerance) | member, axis=0)
    faces = np.concatenate([triples[below], triples[above][:, [0, 2, 1]]])
    return faces[np.lexsort(faces.T[::-1])]


def _extrusion(shape: dict[str, Any]) -> Any:
    """A star-shaped outline (corners at sorted random angles and radii) extruded by trimesh;
    fan-triangulated from its centre, which sees every corner (so no polygon library is
    needed)."""
    import trimesh.creation

    rng = np.random.default_rng(shape["seed"])
    corners = shape["corners"]
    while True:
        angles = np.sort(rng.uniform(0.0, 2.0 * math.pi, corners))
        gaps = np.diff(np.concatenate([angles, [angles[0] + 2.0 * math.pi]]))
        if gaps.max() < 0.9 * math.pi and gaps.min() > 0.05:  # a fan of proper triangles
            break
    radii = rng.uniform(*EXTRUSION_RADIUS, corners)
    outline = np.stack([radii * np.cos(angles), radii * np.sin(angles)], axis=1)
    vertices = np.vstack([[0.0, 0.0], outline])
    fan = np.array([(0, 1 + k, 1 + (k + 1) % corners) for k in range(corners)], dtype=np.int64)
    solid = trimesh.creation.extrude_triangulation(vertices, fan, shape["depth"])
    if solid.volume < 0:
        solid.invert()
    return solid


def write_ply(mesh: Mesh, path: Path) -> None:
    """Binary little-endian PLY: positions, normals where the mesh has them, uv; float32."""
    columns = [mesh.vertices]
    names = ["x", "y", "z"]
    if mesh.normals is not None:
        columns.append(mesh.normals)
        names += ["nx", "ny", "nz"]
    columns.append(mesh.uv)
    names += ["u", "v"]
    vertex = np.ascontiguousarray(np.hstack(columns), dtype="<f4")
    header = ["ply", "format binary_little_endian 1.0", f"element vertex {len(vertex)}"]
    header += [f"property float {name}" for name in names]
    header += [f"element face {len(mesh.faces)}", "property list uchar int vertex_indices"]
    header.append("end_header")
    face = np.empty(len(mesh.faces), dtype=[("count", "u1"), ("index", "<i4", (3,))])
    face["count"] = 3
    face["index"] = mesh.faces
    path.parent.mkdir(parents=True, exist_ok=True)
    with open(path, "wb") as out:
        out.write(("\n".join(header) + "\n").encode("ascii"))
        out.write(vertex.tobytes())
        out.write(face.tobytes())
