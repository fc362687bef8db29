"""Where a run's ground truth lies in its folder, and which kinds a user can ask for.

ground_truth.parquet            camera pose per frame (always written)
ground_truth/frames/depth_NNNNNN.npy     z-depth, float32 H x W, metres (inf: no surface)
ground_truth/frames/flow_NNNNNN.npy      motion field to frame N+1, float32 H x W x 2, px
ground_truth/frames/instance_NNNNNN.npy  shape index, int32 H x W (-1: no surface)
ground_truth/frames/normal_NNNNNN.npy    surface normal, float32 H x W x 3, camera frame
ground_truth/cameras.parquet    t_us, frame, camera-to-world 4x4 (16 numbers, row-major)
ground_truth/shapes.parquet     index -> Mitsuba shape id, animated or not, class, rest box
ground_truth/animation.json     the camera's and objects' tracks (poses at any time)
ground_truth/object_poses.parquet  t_us, frame, object, its animation's 4x4 per frame
ground_truth/intrinsics.json    K, distortion, residual, image size
ground_truth/imu.parquet        t_us, gyro (rad/s), specific force (m/s^2), camera body frame
"""

from __future__ import annotations

from collections.abc import Iterable

FOLDER = "ground_truth"
FRAMES = "frames"
SHAPES = "shapes.parquet"
CAMERAS = "cameras.parquet"
OBJECT_POSES = "object_poses.parquet"
INTRINSICS = "intrinsics.json"
IMU = "imu.parquet"
ANIMATION = "animation.json"
#: Per-frame arrays: file prefix of each kind.
FRAME_KINDS = {"depth": "depth", "flow": "flow", "instances": "instance", "normals": "normal"}
#: Every kind `--ground-truth` takes; `events` adds flow and instance columns to the events.
KINDS = ("depth", "flow", "instances", "normals", "imu", "events")


def frame_file(prefix: str, index: int) -> str:
    return f"{prefix}_{index:06d}.npy"


def parse_kinds(value: str | Iterable[str] | None) -> frozenset[str]:
    """`"all"`, `"depth,flow"` or a list of kinds as a set; ValueError naming an unknown kind."""
    if value is None:
        return frozenset()
    items = value.split(",") if isinstance(value, str) else list(value)
    names = {str(item).strip() for item in items if str(item).strip()}
    if "all" in names:
        return frozenset(KINDS)
    unknown = sorted(names - set(KINDS))
    if unknown:
        raise ValueError(
            f"ground_truth: unknown kind {unknown[0]!r}; known: {', '.join(KINDS)} or all"
        )
    return frozenset(names)
