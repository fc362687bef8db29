"""Keyframe animation against scipy's rotations and Mitsuba's look-at transform."""

from __future__ import annotations

import numpy as np
import pytest
from pecs.render.animation import Keyframe, Track, look_at_rotation, matrix_from_quaternion
from scipy.spatial.transform import Rotation, Slerp


def wxyz(rotation: Rotation) -> np.ndarray:
    x, y, z, w = rotation.as_quat()
    return np.array([w, x, y, z])


def test_track_interpolates_positions_linearly_and_rotations_like_scipy_slerp() -> None:
    rng = np.random.default_rng(3)
    rotations = Rotation.random(4, random_state=7)
    times = np.array([0.0, 0.1, 0.25, 0.4])
    positions = rng.normal(size=(4, 3))
    track = Track(
        [Keyframe(t, p, wxyz(r)) for t, p, r in zip(times, positions, rotations, strict=True)]
    )
    reference = Slerp(times, rotations)
    for t in np.linspace(0.0, 0.4, 37):
        pose = track.pose(float(t))
        np.testing.assert_allclose(pose[:3, :3], reference(t).as_matrix(), atol=1e-9)
        expected_position = [np.interp(t, times, positions[:, k]) for k in range(3)]
        np.testing.assert_allclose(pose[:3, 3], expected_position, atol=1e-12)
    # held constant outside the keyframes
    np.testing.assert_allclose(track.pose(-1.0)[:3, :3], rotations[0].as_matrix(), atol=1e-12)
    np.testing.assert_allclose(track.pose(9.0)[:3, 3], positions[-1], atol=1e-12)


def test_pivot_rotates_about_its_own_centre() -> None:
    quarter = wxyz(Rotation.from_euler("y", 90, degrees=True))
    track = Track([Keyframe(0.0, np.zeros(3), quarter)], pivot=(1.0, 0.0, 0.0))
    pose = track.pose(0.0)
    np.testing.assert_allclose(pose @ [1.0, 0.0, 0.0, 1.0], [1.0, 0.0, 0.0, 1.0], atol=1e-12)


def test_look_at_matches_mitsuba() -> None:
    from pecs._mitsuba import mitsuba

    mi = mitsuba()
    origin, target, up = [0.3, 0.7, 2.0], [0.0, 0.2, -0.1], [0.0, 1.0, 0.0]
    reference = np.array(
        mi.ScalarTransform4f().look_at(origin=origin, target=target, up=up).matrix, dtype=float
    )
    mine = matrix_from_quaternion(look_at_rotation(origin, target, up))
    np.testing.assert_allclose(mine, reference[:3, :3], atol=1e-6)


def test_bad_keyframes_are_rejected() -> None:
    with pytest.raises(ValueError, match="increase"):
        Track([Keyframe(0.1, np.zeros(3), np.array([1.0, 0, 0, 0]))] * 2)
    with pytest.raises(ValueError, match="parallel"):
        look_at_rotation([0, 0, 0], [0, 1, 0], [0, 1, 0])
