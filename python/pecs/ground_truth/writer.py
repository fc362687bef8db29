"""Writes a run's ground truth frame by frame (streamed: only the previous frame is kept)."""

from __future__ import annotations

import json
from collections.abc import Callable
from dataclasses import dataclass, field
from pathlib import Path
from typing import Any

import numpy as np
import pyarrow as pa
import pyarrow.parquet as pq

from pecs._atomic import atomic_path
from pecs.ground_truth import layout
from pecs.ground_truth.classes import instance_classes
from pecs.ground_truth.imu import imu_table
from pecs.ground_truth.imu_noise import ImuModel
from pecs.ground_truth.intrinsics import CameraModel
from pecs.ground_truth.surface import SurfaceHits, motion_field_px, normals_camera, z_depth_m

Pose = Callable[[float], np.ndarray]


@dataclass(frozen=True)
class SceneFacts:
    """What the ground truth takes from the scene besides each frame's surface."""

    #: `pecs.ground_truth.tracks.animation_dict` of the run (None: poses at frames only).
    animation: dict[str, Any] | None = None
    #: (shapes, 2, 3) each shape's box before animation (`Renderer.shape_boxes`).
    shape_boxes: np.ndarray | None = None
    #: Shape id -> class, where the scene names one (`[classes]`).
    classes: dict[str, str] = field(default_factory=dict)


class GroundTruthWriter:
    """Per frame: depth, instance and (once the next frame is known) flow; at the end: shapes,
    object poses, intrinsics and IMU."""

    def __init__(
        self,
        run_dir: Path,
        kinds: frozenset[str],
        shape_ids: list[str],
        object_poses: dict[str, Pose],
        model: CameraModel,
        scene: SceneFacts | None = None,
    ) -> None:
        self.folder = run_dir / layout.FOLDER
        #: What the scene knows beyond the frames: tracks, shape boxes and classes.
        self.scene = scene or SceneFacts()
        # Checked now, not after the render: a [classes] id that is no shape's is refused.
        self._classes = instance_classes(shape_ids, self.scene.classes)
        (self.folder / layout.FRAMES).mkdir(parents=True, exist_ok=True)
        self.kinds, self.shape_ids, self.objects, self.model = kinds, shape_ids, object_poses, model
        self._previous: tuple[int, int, SurfaceHits] | None = None
        self._object_rows: list[tuple[int, int, str, np.ndarray]] = []
        self._camera_rows: list[tuple[int, int, np.ndarray]] = []

    @property
    def wants_flow(self) -> bool:
        return "flow" in self.kinds or "events" in self.kinds

    @property
    def wants_instances(self) -> bool:
        return "instances" in self.kinds or "events" in self.kinds

    @property
    def needs_surface(self) -> bool:
        """Whether `add` needs the surface each pixel sees (not for poses and IMU alone)."""
        return bool(self.kinds - {"imu"})

    def add(
        self, index: int, t_us: int, camera_to_world: np.ndarray, hits: SurfaceHits | None
    ) -> None:
        """Frame `index` at `t_us` and the surface it sees (None: not `needs_surface`); writes
        the previous frame's flow."""
        self._camera_rows.append((t_us, index, camera_to_world))
        for name, pose in self.objects.items():
            self._object_rows.append((t_us, index, name, pose(t_us * 1e-6)))
        if hits is None:
            return
        if "depth" in self.kinds:
            self._save("depth", index, z_depth_m(hits, self.model))
        if self.wants_instances:
            self._save("instance", index, hits.shape_index.astype(np.int32))
        if "normals" in self.kinds:
            self._save("normal", index, normals_camera(hits))
        if self._previous is not None and self.wants_flow:
            self._save_flow(*self._previous, t_us, hits.camera_to_world)
        self._previous = (index, t_us, hits)

    def finish(
        self,
        camera_pose: Pose,
        duration_s: float,
        imu_rate_hz: float,
        imu_model: ImuModel | None = None,
    ) -> None:
        """The last frame's flow (NaN: no next frame) and the tables; the IMU table with what
        the real IMU `imu_model` (seeded) reads, if one is given."""
        if self._previous is not None and self.wants_flow:
            last_index, _, hits = self._previous
            height, width = hits.shape_index.shape
            self._save("flow", last_index, np.full((height, width, 2), np.nan, np.float32))
        self._write_table(layout.SHAPES, self._shapes_table())
        self._write_table(layout.CAMERAS, _poses_table(self._camera_rows, {}))
        objects = [(t, i, m) for t, i, _, m in self._object_rows]
        names = {"object": pa.array([r[2] for r in self._object_rows], pa.string())}
        self._write_table(layout.OBJECT_POSES, _poses_table(objects, names))
        with atomic_path(self.folder / layout.INTRINSICS) as tmp:
            tmp.write_text(json.dumps(self.model.as_dict(), indent=2) + "\n")
        if self.scene.animation is not None:
            with atomic_path(self.folder / layout.ANIMATION) as tmp:
                tmp.write_text(json.dumps(self.scene.animation) + "\n")
        if "imu" in self.kinds:
            imu = imu_table(camera_pose, duration_s, imu_rate_hz, model=imu_model)
            self._write_table(layout.IMU, imu)

    def _save_flow(
        self, index: int, t_us: int, hits: SurfaceHits, next_t_us: int, next_camera: np.ndarray
    ) -> None:
        shape_motion = self._shape_motion(t_us * 1e-6, next_t_us * 1e-6)
        self._save("flow", index, motion_field_px(hits, next_camera, shape_motion, self.model))

    def _shape_motion(self, t0_s: float, t1_s: float) -> Callable[[int], np.ndarray | None]:
        """Shape index -> M(t1) M(t0)^-1 of its animation (None: static)."""

        def motion(shape_index: int) -> np.ndarray | None:
            pose = self.objects.get(self.shape_ids[shape_index])
            return None if pose is None else pose(t1_s) @ np.linalg.inv(pose(t0_s))

        return motion

    def _save(self, prefix: str, index: int, array: np.ndarray) -> None:
        path = self.folder / layout.FRAMES / layout.frame_file(prefix, index)
        with atomic_path(path) as tmp, open(tmp, "wb") as file:
            np.save(file, array)

    def _shapes_table(self) -> pa.Table:
        n = len(self.shape_ids)
        boxes = self.scene.shape_boxes
        boxes = np.full((n, 2, 3), np.nan) if boxes is None else np.asarray(boxes, np.float64)
        return pa.table(
            {
                "index": pa.array(range(n), pa.int32()),
                "shape_id": pa.array(self.shape_ids, pa.string()),
                "animated": pa.array([s in self.objects for s in self.shape_ids], pa.bool_()),
                "class": pa.array(self._classes, pa.string()),
                "box_min_m": pa.FixedSizeListArray.from_arrays(pa.array(boxes[:, 0].ravel()), 3),
                "box_max_m": pa.FixedSizeListArray.from_arrays(pa.array(boxes[:, 1].ravel()), 3),
            }
        )

    def _write_table(self, name: str, table: pa.Table) -> None:
        with atomic_path(self.folder / name) as tmp:
            pq.write_table(table, tmp)


def _poses_table(rows: list[tuple[int, int, np.ndarray]], extra: dict[str, pa.Array]) -> pa.Table:
    """t_us, frame, (extra columns,) pose: the 4x4 as 16 float64 in row-major order."""
    matrices = np.array([m for *_, m in rows], dtype=np.float64).reshape(-1, 16)
    return pa.table(
        {
            "t_us": pa.array([r[0] for r in rows], pa.int64()),
            "frame": pa.array([r[1] for r in rows], pa.uint32()),
            **extra,
            "pose": pa.FixedSizeListArray.from_arrays(pa.array(matrices.ravel()), 16),
        }
    )
