"""The run's animation (the camera's and the animated objects' tracks), stored with the ground
truth so that poses between frames are evaluated exactly as the renderer evaluated them.

A track is stored as its keyframes (t_s, position, quaternion w x y z), pivot and
interpolation; reading it back builds the same `pecs.render.animation.Track`, so
`pose(t_s)` is the same function of time (JSON keeps every float64 exactly).
"""

from __future__ import annotations

from typing import Any

import numpy as np

from pecs.render.animation import Keyframe, Track


def track_dict(track: Track) -> dict[str, Any]:
    """A track as JSON-ready lists."""
    return {
        "interpolation": track.interpolation,
        "pivot": [float(v) for v in track.pivot],
        "source": track.source,
        "t_s": [float(k.t_s) for k in track.keyframes],
        "position": [[float(v) for v in k.position] for k in track.keyframes],
        "rotation_wxyz": [[float(v) for v in k.rotation] for k in track.keyframes],
    }


def track_from_dict(data: dict[str, Any]) -> Track:
    """The track `track_dict` wrote."""
    frames = [
        Keyframe(float(t), np.asarray(p, dtype=np.float64), np.asarray(q, dtype=np.float64))
        for t, p, q in zip(data["t_s"], data["position"], data["rotation_wxyz"], strict=True)
    ]
    return Track(frames, data["pivot"], data["interpolation"], data["source"])


def animation_dict(camera: Track | None, objects: dict[str, Track]) -> dict[str, Any]:
    """The run's tracks: the camera's (None: the scene's fixed camera) and each object's."""
    return {
        "camera": None if camera is None else track_dict(camera),
        "objects": {name: track_dict(track) for name, track in objects.items()},
    }


class Animation:
    """Poses at any time from a stored animation; the camera falls back to `fixed_camera` when
    the run's camera did not move (no track)."""

    def __init__(self, data: dict[str, Any], fixed_camera: np.ndarray) -> None:
        camera = data.get("camera")
        self._camera = None if camera is None else track_from_dict(camera)
        self._fixed_camera = np.asarray(fixed_camera, dtype=np.float64)
        self._objects = {name: track_from_dict(d) for name, d in data["objects"].items()}

    @property
    def objects(self) -> list[str]:
        return list(self._objects)

    def camera_pose(self, t_us: int) -> np.ndarray:
        """Camera-to-world 4x4 at t_us."""
        if self._camera is None:
            return self._fixed_camera.copy()
        return self._camera.pose(t_us / 1_000_000)

    def object_pose(self, name: str, t_us: int) -> np.ndarray | None:
        """Animation transform 4x4 of object `name` at t_us (None: not animated)."""
        track = self._objects.get(name)
        return None if track is None else track.pose(t_us / 1_000_000)
