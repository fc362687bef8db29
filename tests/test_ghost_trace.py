"""The Rust ghost tracer (pecs_core's ghost module) against independent numpy: coating.py's
thin-film reflectance, and a ray trace of two spherical surfaces written here."""

from __future__ import annotations

import itertools

import numpy as np
import pytest
from pecs import _core
from pecs.lens.coating import film_reflectance, reflectance

QUARTER_WAVE_NM = 550.0 / (4 * 1.38)


def test_rust_film_reflectance_equals_coating_py_including_total_internal_reflection() -> None:
    indices = [1.0, 1.38, 1.52, 1.75]
    grid = itertools.product(
        indices,  # n0
        [1.0, 1.2, 1.38, 1.9],  # film
        indices,  # n2
        [0.0, QUARTER_WAVE_NM, 240.0],  # thickness nm
        [420.0, 550.0, 860.0],
        np.linspace(0.02, 1.0, 25),  # cos theta0
    )
    n0, n1, n2, d, lam, cos0 = (np.ascontiguousarray(v) for v in np.array(list(grid)).T)
    rs, rp = _core.ghost_film_reflectance(n0, n1, n2, d, lam, cos0)
    want_s, want_p = film_reflectance(n0, n1, n2, d, lam, cos0)
    np.testing.assert_allclose(rs, want_s, rtol=0, atol=1e-12)
    np.testing.assert_allclose(rp, want_p, rtol=0, atol=1e-12)
    # The grid holds total reflection at n2, in the film only (frustrated), and neither.
    sin2 = 1 - cos0**2
    tir_2 = (n0 / n2) ** 2 * sin2 >= 1
    tir_film = ((n0 / n1) ** 2 * sin2 >= 1) & ~tir_2 & (d > 0)
    assert tir_2.sum() > 100 and tir_film.sum() > 100 and (~tir_2 & ~tir_film).sum() > 100
    np.testing.assert_allclose(rs[tir_2], 1.0, atol=1e-12)  # lossless: all of it comes back
    assert np.all((rs[tir_film] > 0) & (rs[tir_film] < 1))  # some tunnels through the film


def test_rust_film_reflectance_refuses_arrays_of_different_lengths() -> None:
    one, two = np.ones(1), np.ones(2)
    with pytest.raises(ValueError, match="differ in length"):
        _core.ghost_film_reflectance(one, one, one, one, one, two)


# A biconvex singlet: R +20 mm at z 0, R -30 mm at z 4, glass n 1.5 (1.52 in the second band),
# quarter-wave coated; the film at z 30.
Z_MM, RADIUS_MM, GLASS, FILM_Z_MM = [0.0, 4.0], [20.0, -30.0], [1.5, 1.52], 30.0
LAM_NM = [550.0, 450.0]
# Path 0 straight through; path 1 reflects at the back surface, then at the front.
STEPS = [  # (surface, reflect, forward)
    [(0, False, True), (1, False, True), (-1, False, True), (-1, False, True)],
    [(0, False, True), (1, True, True), (0, True, False), (1, False, True)],
]


def _sphere_hit(o: np.ndarray, d: np.ndarray, k: int) -> tuple[np.ndarray, np.ndarray]:
    """The point of the sphere |p - c| = |R| near surface k's vertex, and p - c over R."""
    centre = np.array([0.0, 0.0, Z_MM[k] + RADIUS_MM[k]])
    oc = o - centre
    roots = np.roots([d @ d, 2 * oc @ d, oc @ oc - RADIUS_MM[k] ** 2])
    points = [o + t * d for t in roots.real if t > 0]
    p = min(points, key=lambda q: abs(q[2] - Z_MM[k]))
    return p, (p - centre) / RADIUS_MM[k]


def _snell(d: np.ndarray, n: np.ndarray, eta: float) -> np.ndarray:
    """The refracted unit direction from its tangential part: eta (d - (d.n) n), and the
    normal part sqrt(1 - |tangential|^2) along the side the ray goes to."""
    n = n if d @ n < 0 else -n
    tangential = eta * (d - (d @ n) * n)
    return tangential - np.sqrt(1 - tangential @ tangential) * n


def _numpy_trace(o: np.ndarray, d: np.ndarray, path: int) -> tuple[np.ndarray, list[float]]:
    """Film xy and the weight per band along `path`, reflectances from coating.py."""
    media = [[1.0, 1.0], GLASS, [1.0, 1.0]]
    weight = [1.0, 1.0]
    d = d / np.linalg.norm(d)
    for k, mirror, forward in STEPS[path]:
        if k < 0:
            break
        p, normal = _sphere_hit(o, d, k)
        n_in, n_out = (media[k], media[k + 1]) if forward else (media[k + 1], media[k])
        cos0 = abs(d @ normal)
        for b in range(2):
            r = float(reflectance(n_in[b], n_out[b], cos0, LAM_NM[b], 1.38, QUARTER_WAVE_NM))
            weight[b] *= r if mirror else 1 - r
        d = d - 2 * (d @ normal) * normal if mirror else _snell(d, normal, n_in[0] / n_out[0])
        o = p
    return o[:2] + (FILM_Z_MM - o[2]) / d[2] * d[:2], weight


def _rust_trace(origin: np.ndarray, direction: np.ndarray, path: np.ndarray, **change):
    table = np.array(STEPS)  # (paths, steps, 3)
    args = dict(
        origin_mm=origin,
        direction=direction / np.linalg.norm(direction, axis=1, keepdims=True),
        path=path,
        band=np.zeros(len(path), np.int64),
        weight_band=np.ascontiguousarray(np.tile([0, 1], (len(path), 1)), np.int64),
        step_surface=np.ascontiguousarray(table[..., 0], np.int64),
        step_reflect=np.ascontiguousarray(table[..., 1], bool),
        step_forward=np.ascontiguousarray(table[..., 2], bool),
        vertex_z_mm=np.array(Z_MM),
        radius_mm=np.array(RADIUS_MM),
        semi_aperture2_mm2=np.array([6.0, 6.0]) ** 2,
        fixed_reflectance=np.array([-1.0, -1.0]),
        film_index=np.array([1.38, 1.38]),
        film_thickness_nm=np.full(2, QUARTER_WAVE_NM),
        media=np.array([[1.0, 1.0], GLASS, [1.0, 1.0]]),
        wavelength_nm=np.array(LAM_NM),
        film_z_mm=FILM_Z_MM,
    )
    args.update(change)
    return _core.ghost_trace(*args.values())


def test_rust_tracer_equals_a_numpy_trace_through_two_spheres() -> None:
    starts = [(0.0, 0.0), (1.5, -0.5), (-3.0, 2.0), (0.4, 4.1)]
    tilts = [(0.0, 0.0), (0.05, 0.02), (-0.1, 0.03)]
    rays = [(x, y, tx, ty, p) for x, y in starts for tx, ty in tilts for p in (0, 1)]
    origin = np.array([[x, y, -5.0] for x, y, *_ in rays])
    direction = np.array([[tx, ty, 1.0] for _, _, tx, ty, _ in rays])
    path = np.array([r[-1] for r in rays], np.int64)
    film, weight, alive = _rust_trace(origin, direction, path)
    assert alive.all()
    for i in range(len(rays)):
        want_xy, want_w = _numpy_trace(origin[i], direction[i], int(path[i]))
        np.testing.assert_allclose(film[i], want_xy, rtol=0, atol=1e-10)
        np.testing.assert_allclose(weight[i], want_w, rtol=1e-12, atol=0)
    # The ghost is dim: R^2 of a coated surface, below 1e-3; the straight ray loses ~1 %.
    assert np.all(weight[path == 1] < 1e-3) and np.all(weight[path == 0] > 0.95)


def test_rust_tracer_loses_rays_outside_the_aperture_and_refuses_bad_indices() -> None:
    origin = np.array([[5.9, 0.0, -5.0], [7.0, 0.0, -5.0]])
    direction = np.array([[0.0, 0.0, 1.0], [0.0, 0.0, 1.0]])
    path = np.zeros(2, np.int64)
    film, weight, alive = _rust_trace(origin, direction, path)
    assert list(alive) == [True, False]  # 5.9 mm in, 7 mm out of the 6 mm semi-aperture
    assert np.all(weight[1] == 0) and np.all(film[1] == 0)
    with pytest.raises(ValueError, match="path index 2 out of range"):
        _rust_trace(origin, direction, np.array([0, 2], np.int64))
    with pytest.raises(ValueError, match="not C-contiguous"):
        _rust_trace(origin[:, ::2], direction, path)
