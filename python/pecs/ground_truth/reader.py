"""`pecs.read_ground_truth(run_dir)`: a run's ground truth, frame arrays loaded on demand."""

from __future__ import annotations

import json
import os
from functools import cached_property
from pathlib import Path

import numpy as np
import pyarrow as pa
import pyarrow.parquet as pq

from pecs.ground_truth import layout
from pecs.ground_truth.intrinsics import CameraModel


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

    @cached_property
    def imu(self) -> pa.Table:
        """t_us, gyro_{x,y,z}_rad_s, accel_{x,y,z}_m_s2 (camera body frame, gravity included)."""
        path = self.folder / layout.IMU
        if not path.is_file():
            raise FileNotFoundError(f"{path}: no IMU in this run (ask for ground truth 'imu')")
        return pq.read_table(path)

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
