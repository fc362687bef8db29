"""`pecs.read_ground_truth(run_dir)`: a run's ground truth, frame arrays loaded on demand."""

from __future__ import annotations

import json
import os
from collections.abc import Callable
from functools import cached_property
from pathlib import Path

import numpy as np
import pyarrow as pa
import pyarrow.parquet as pq

from pecs.ground_truth import layout
from pecs.ground_truth.boxes import Boxes, box_corners, boxes_2d
from pecs.ground_truth.classes import default_class
from pecs.ground_truth.flow import FlowBetween, flow_between_surfaces, surface_from_depth
from pecs.ground_truth.intrinsics import CameraModel
from pecs.ground_truth.rasterize import surface_at
from pecs.ground_truth.surface import SurfaceHits, z_depth_m
from pecs.ground_truth.tracks import Animation


class GroundTruth:
    """Ground truth of one `Simulation.run` folder. Frames count from 0 in time order."""

    def __init__(self, run_dir: str | os.PathLike[str]) -> None:
        self.run_dir = Path(run_dir)
        self.folder = self.run_dir / layout.FOLDER
        if not (self.folder / layout.CAMERAS).is_file():
            raise FileNotFoundError(
                f"{self.run_dir}: no ground truth here (run with ground_truth=... or "
                "`pecs simulate --ground-truth all`)"
            )
        cameras = pq.read_table(self.folder / layout.CAMERAS)
        #: Frame times, microseconds (int64).
        self.t_us: np.ndarray = cameras.column("t_us").to_numpy()
        self._camera_poses = _matrices(cameras)

    def __len__(self) -> int:
        return int(self.t_us.size)

    def camera_pose(self, i: int) -> np.ndarray:
        """Camera-to-world 4x4 of frame i (Mitsuba's camera frame: +z forward, +y up, +x left)."""
        return self._camera_poses[self._index(i)].copy()

    @cached_property
    def camera_model(self) -> CameraModel:
        """The projection: focal length, distortion (realistic lens), residual of the fit."""
        return CameraModel.from_dict(json.loads((self.folder / layout.INTRINSICS).read_text()))

    @property
    def intrinsics(self) -> np.ndarray:
        """3x3 K (OpenCV convention: x right, y down, pixel centres at integers)."""
        return self.camera_model.matrix

    @property
    def distortion(self) -> tuple[float, float, float]:
        """Brown-Conrady radial k1, k2, k3 (zeros for pinhole and thin lens)."""
        return self.camera_model.distortion

    @property
    def distortion_residual_px(self) -> float:
        return self.camera_model.residual_px

    def depth(self, i: int) -> np.ndarray:
        """z-depth of frame i, metres along the optical axis, float32 H x W (inf: no surface)."""
        return self._frame("depth", "depth", i)

    def flow(self, i: int) -> np.ndarray:
        """Motion field from frame i to frame i + 1, pixels (du right, dv down), float32
        H x W x 2; NaN where no surface, and everywhere in the last frame."""
        return self._frame("flow", "flow", i)

    def instance(self, i: int) -> np.ndarray:
        """Shape index per pixel of frame i, int32 H x W (-1: no surface); see `shape_ids`."""
        return self._frame("instances", "instance", i)

    @cached_property
    def shapes(self) -> pa.Table:
        """index, shape_id (Mitsuba id), animated."""
        return pq.read_table(self.folder / layout.SHAPES)

    @property
    def shape_ids(self) -> list[str]:
        """Mitsuba shape id of each instance index."""
        return [str(v) for v in self.shapes.column("shape_id").to_pylist()]

    @cached_property
    def object_poses(self) -> pa.Table:
        """t_us, frame, object, pose: each animated object's animation transform (row-major 4x4;
        a point placed at x by the Mitsuba scene is at pose @ x)."""
        return pq.read_table(self.folder / layout.OBJECT_POSES)

    def object_pose(self, name: str, i: int) -> np.ndarray:
        """Animation transform 4x4 of object `name` at frame i."""
        table = self.object_poses
        mask = np.asarray(table.column("object").to_pylist()) == name
        if not mask.any():
            objects = sorted(set(table.column("object").to_pylist()))
            raise KeyError(f"no animated object {name!r} (animated: {objects})")
        frames = table.column("frame").to_numpy()[mask]
        row = np.flatnonzero(frames == self._index(i))
        return _matrices(table.filter(pa.array(mask)))[row[0]]

    # -- any time: poses from the stored tracks, surfaces from the stored frames ------------

    def normals(self, i: int) -> np.ndarray:
        """Unit surface normals of frame i in the camera frame, facing the camera, float32
        H x W x 3 (NaN: no surface); Mitsuba's shading normal at each pixel centre's hit."""
        return self._frame("normals", "normal", i)

    @property
    def classes(self) -> list[str]:
        """The class of each instance index: the scene's `[classes]` entry for its shape id, else
        the id without a trailing number."""
        if "class" in self.shapes.column_names:
            return [str(v) for v in self.shapes.column("class").to_pylist()]
        return [default_class(shape_id) for shape_id in self.shape_ids]

    def camera_pose_at(self, t_us: int) -> np.ndarray:
        """Camera-to-world 4x4 at any time of the run (between frames: the camera's track,
        evaluated as the renderer evaluated it)."""
        frame = self._frame_at(self._check_time("t_us", t_us))
        return self.camera_pose(frame) if frame is not None else self._tracks.camera_pose(t_us)

    def object_pose_at(self, name: str, t_us: int) -> np.ndarray:
        """Animation transform 4x4 of animated object `name` at any time of the run."""
        frame = self._frame_at(self._check_time("t_us", t_us))
        if frame is not None:
            return self.object_pose(name, frame)
        pose = self._tracks.object_pose(name, int(t_us))
        if pose is None:
            raise KeyError(f"no animated object {name!r} (animated: {self._tracks.objects})")
        return pose

    def depth_at(self, t_us: int) -> np.ndarray:
        """z-depth at any time of the run, float32 H x W (metres, inf: no surface); between
        frames rebuilt from the two frames around it (docs/ground-truth.md)."""
        hits, _ = self._surface_at(self._check_time("t_us", t_us))
        return z_depth_m(hits, self.camera_model)

    def instance_at(self, t_us: int) -> np.ndarray:
        """Instance index per pixel at any time of the run, int32 H x W (-1: no surface)."""
        hits, _ = self._surface_at(self._check_time("t_us", t_us))
        return hits.shape_index.astype(np.int32)

    def flow_between(self, t0_us: int, t1_us: int) -> FlowBetween:
        """Where the point seen through each pixel at t0_us is seen at t1_us (t1 before t0:
        backward flow), from geometry: `.flow_px` (float32 H x W x 2), `.valid` (seen at both
        times, inside the image) and `.occluded`. Needs the depth and instances kinds."""
        t0 = self._check_time("t0_us", t0_us)
        t1 = self._check_time("t1_us", t1_us)
        start, depth_error = self._surface_at(t0)
        end, _ = self._surface_at(t1)
        return flow_between_surfaces(
            t0, t1, start, depth_error, end, self._shape_motion(t0, t1), self.camera_model
        )

    def boxes(self, i: int) -> Boxes:
        """The instances seen in frame i: 2D boxes in pixels and 3D boxes in the camera frame."""
        return self.boxes_at(int(self.t_us[self._index(i)]))

    def boxes_at(self, t_us: int) -> Boxes:
        """The instances seen at any time of the run: 2D boxes of the pixels each covers, and
        the 8 corners of its 3D box (the shape's box before animation, moved by its animation)
        in the camera frame."""
        t = self._check_time("t_us", t_us)
        seen, pixels, box_2d = boxes_2d(self.instance_at(t))
        shapes = self.shapes
        if "box_min_m" in shapes.column_names:
            low = np.array(shapes.column("box_min_m").to_pylist(), np.float64)[seen]
            high = np.array(shapes.column("box_max_m").to_pylist(), np.float64)[seen]
        else:
            low = high = np.full((seen.size, 3), np.nan)
        corners = box_corners(low, high)
        for k, index in enumerate(seen):
            motion = self._pose_of_shape(int(index), t)
            if motion is not None:
                corners[k] = corners[k] @ motion[:3, :3].T + motion[:3, 3]
        world_to_camera = np.linalg.inv(self.camera_pose_at(t))
        corners = corners @ world_to_camera[:3, :3].T + world_to_camera[:3, 3]
        classes = self.classes
        return Boxes(seen, [classes[k] for k in seen], pixels, box_2d, corners)

    @cached_property
    def _tracks(self) -> Animation:
        path = self.folder / layout.ANIMATION
        if not path.is_file():
            raise ValueError(
                f"{self.run_dir}: this run stored no animation (an older pecs): poses and "
                "surfaces are known at its frame times only"
            )
        return Animation(json.loads(path.read_text()), self._camera_poses[0])

    def _check_time(self, name: str, t_us: int) -> int:
        if isinstance(t_us, (bool, np.bool_)) or not isinstance(t_us, (int, np.integer)):
            raise TypeError(f"{name} must be an integer number of microseconds, got {t_us!r}")
        first, last = int(self.t_us[0]), int(self.t_us[-1])
        if not first <= t_us <= last:
            raise ValueError(f"{name}={t_us} is outside the run's frames ({first} to {last} us)")
        return int(t_us)

    def _frame_at(self, t_us: int) -> int | None:
        """The frame rendered at exactly t_us, or None."""
        k = int(np.searchsorted(self.t_us, t_us))
        return k if k < len(self) and self.t_us[k] == t_us else None

    def _pose_of_shape(self, index: int, t_us: int) -> np.ndarray | None:
        """The animation transform of shape `index` at t_us (None: not animated)."""
        shapes = self.shapes
        if "animated" in shapes.column_names and not shapes.column("animated")[index].as_py():
            return None
        return self.object_pose_at(self.shape_ids[index], t_us)

    def _shape_motion(self, t0_us: int, t1_us: int) -> Callable[[int], np.ndarray | None]:
        """Shape index -> its motion M(t1) M(t0)^-1 (None: static), each computed once."""
        poses: dict[int, np.ndarray | None] = {}

        def motion(index: int) -> np.ndarray | None:
            if index not in poses:
                start = self._pose_of_shape(index, t0_us)
                end = self._pose_of_shape(index, t1_us)
                poses[index] = None if start is None else end @ np.linalg.inv(start)
            return poses[index]

        return motion

    def _surface_at(self, t_us: int) -> tuple[SurfaceHits, np.ndarray]:
        """The surface seen at t_us and a bound on its z-depth error, metres (stored frames: 0)."""
        frame = self._frame_at(t_us)
        if frame is not None:
            hits = self._stored_surface(frame)
            return hits, np.zeros(hits.shape_index.shape)
        after = int(np.searchsorted(self.t_us, t_us))
        bracket = [after - 1, after]
        sources = [self._stored_surface(k) for k in bracket]
        motions = [self._shape_motion(int(self.t_us[k]), t_us) for k in bracket]
        return surface_at(sources, motions, self.camera_pose_at(t_us), self.camera_model)

    def _stored_surface(self, i: int) -> SurfaceHits:
        return surface_from_depth(
            self.depth(i), self.instance(i), self.camera_pose(i), self.camera_model
        )

    @cached_property
    def imu(self) -> pa.Table:
        """t_us, gyro_{x,y,z}_rad_s, accel_{x,y,z}_m_s2 (ideal: camera body frame, gravity
        included); with a real IMU (`imu_model`) also gyro_meas_*, accel_meas_* (what it read,
        its own axes) and gyro_bias_*, accel_bias_* (the bias inside those readings)."""
        path = self.folder / layout.IMU
        if not path.is_file():
            raise FileNotFoundError(f"{path}: no IMU in this run (ask for ground truth 'imu')")
        return pq.read_table(path)

    @property
    def imu_model(self) -> dict[str, object] | None:
        """The real IMU's parameters (pecs.ground_truth.imu_noise.ImuModel fields, its seed
        included), or None where the run wrote the ideal IMU alone."""
        raw = (self.imu.schema.metadata or {}).get(b"pecs.imu_model")
        return None if raw is None else dict(json.loads(raw))

    def _frame(self, kind: str, prefix: str, i: int) -> np.ndarray:
        path = self.folder / layout.FRAMES / layout.frame_file(prefix, self._index(i))
        if not path.is_file():
            raise FileNotFoundError(f"{path}: not written (ask for ground truth {kind!r})")
        return np.load(path)

    def _index(self, i: int) -> int:
        if not -len(self) <= i < len(self):
            raise IndexError(f"frame {i} out of range: the run has {len(self)} frames")
        return int(i) % len(self)


def read_ground_truth(run_dir: str | os.PathLike[str]) -> GroundTruth:
    """The ground truth a `Simulation.run` (or `pecs simulate --ground-truth`) wrote."""
    return GroundTruth(run_dir)


def _matrices(table: pa.Table) -> np.ndarray:
    column = table.column("pose").combine_chunks()
    return column.flatten().to_numpy().reshape(-1, 4, 4)
