"""Camera and object trajectories from files: TUM text and CSV, made into a spline `Track`.

TUM (https://cvg.cit.tum.de/data/datasets/rgbd-dataset/file_formats): one pose per line,
`t x y z qx qy qz qw` separated by spaces, t in seconds, position in metres, the pose of the body
in the world (body to world); lines starting with # are comments.
CSV: a header row naming the columns (any order, extra columns ignored): a time `t_s`, `t_us` or
`t_ns`, then `position_x_m, position_y_m, position_z_m, qw, qx, qy, qz` (the names of pecs's
ground_truth.parquet); # lines are comments.
"""

from __future__ import annotations

import csv
import math
import os
from dataclasses import dataclass
from pathlib import Path

import numpy as np

from pecs.render.animation import Track
from pecs.render.rotation_spline import quaternion_multiply

TUM_SUFFIXES = (".tum", ".txt")
CSV_SUFFIXES = (".csv",)
CSV_TIME_COLUMNS = {"t_s": 1.0, "t_us": 1e-6, "t_ns": 1e-9}
CSV_POSE_COLUMNS = ("position_x_m", "position_y_m", "position_z_m", "qw", "qx", "qy", "qz")
# Camera axes of the file: pecs/Mitsuba (+x left, +y up, +z forward) or OpenCV (+x right, +y down,
# +z forward; TUM RGB-D, EuRoC, COLMAP, ORB-SLAM). They differ by 180 degrees about +z.
AXES = ("mitsuba", "opencv")
_OPENCV_TO_MITSUBA = np.array([0.0, 0.0, 0.0, 1.0])  # (w, x, y, z): 180 degrees about z
# A quaternion further than this from unit length is a wrong column, not rounding.
_UNIT_TOLERANCE = 1e-2


@dataclass(frozen=True)
class TrajectorySamples:
    """Poses as read: times (n,) in seconds, positions (n, 3) in metres, unit quaternions (n, 4)
    as (w, x, y, z), body to world."""

    t_s: np.ndarray
    positions: np.ndarray
    quaternions_wxyz: np.ndarray


def read_trajectory(
    path: str | os.PathLike[str],
    *,
    time_offset_s: float | str = 0.0,
    time_scale: float = 1.0,
    axes: str = "mitsuba",
    pivot: tuple[float, float, float] = (0.0, 0.0, 0.0),
    interpolation: str = "spline",
) -> Track:
    """A `Track` through the poses of a TUM or CSV file (by suffix: .tum/.txt or .csv).

    Scene time t_s = (t_file - time_offset_s) * time_scale; `time_offset_s = "first"` starts the
    track at 0 (files with Unix timestamps). `axes = "opencv"` converts a camera trajectory written
    with OpenCV's camera axes to pecs's (Mitsuba's) camera axes. A simulation refuses the track
    unless its scene times cover the run (`check_covers`).
    """
    samples = read_trajectory_samples(path)
    if axes not in AXES:
        raise ValueError(f"axes must be one of {list(AXES)}, got {axes!r}")
    if time_offset_s == "first":
        offset = float(samples.t_s[0])
    elif isinstance(time_offset_s, (int, float)) and math.isfinite(time_offset_s):
        offset = float(time_offset_s)
    else:
        raise ValueError(
            f'time_offset_s must be a number of seconds or "first", got {time_offset_s!r}'
        )
    if not (isinstance(time_scale, (int, float)) and math.isfinite(time_scale) and time_scale > 0):
        raise ValueError(f"time_scale must be a positive number, got {time_scale!r}")
    quaternions = samples.quaternions_wxyz
    if axes == "opencv":
        quaternions = np.array([quaternion_multiply(q, _OPENCV_TO_MITSUBA) for q in quaternions])
    try:
        return Track.from_samples(
            (samples.t_s - offset) * time_scale,
            samples.positions,
            quaternions,
            pivot,
            interpolation,
            source=str(path),
        )
    except ValueError as error:
        raise ValueError(f"{path}: {error}") from error


def read_trajectory_samples(path: str | os.PathLike[str]) -> TrajectorySamples:
    """Validated samples of a TUM or CSV trajectory file; errors name the file and line."""
    path = Path(path)
    if not path.is_file():
        raise FileNotFoundError(f"trajectory file not found: {path}")
    suffix = path.suffix.lower()
    if suffix in TUM_SUFFIXES:
        numbers, table = _tum_table(path)
    elif suffix in CSV_SUFFIXES:
        numbers, table = _csv_table(path)
    else:
        raise ValueError(
            f"{path}: unknown trajectory format {suffix!r}; use {TUM_SUFFIXES} (TUM) or .csv"
        )
    if not numbers:
        raise ValueError(f"{path}: no poses in the file")
    return _validated(path, numbers, table)


# Column order of the parsed table: t_s, x, y, z, qw, qx, qy, qz.
_TUM_ORDER = [0, 1, 2, 3, 7, 4, 5, 6]  # from t x y z qx qy qz qw


def _tum_table(path: Path) -> tuple[list[int], np.ndarray]:
    numbers, rows = [], []
    for number, line in enumerate(_lines(path), start=1):
        text = line.strip()
        if not text or text.startswith("#"):
            continue
        fields = text.split()
        if len(fields) != 8:
            raise ValueError(
                f"{path}:{number}: expected 8 numbers (t x y z qx qy qz qw), got {len(fields)}"
            )
        numbers.append(number)
        rows.append(fields)
    return numbers, _floats(path, numbers, rows)[:, _TUM_ORDER]


def _csv_table(path: Path) -> tuple[list[int], np.ndarray]:
    content = [
        (n, line)
        for n, line in enumerate(_lines(path), start=1)
        if line.strip() and not line.lstrip().startswith("#")
    ]
    if not content:
        return [], np.zeros((0, 8))
    header_number, header_line = content[0]
    header = [name.strip() for name in next(csv.reader([header_line]))]
    time_columns = [name for name in CSV_TIME_COLUMNS if name in header]
    missing = [name for name in CSV_POSE_COLUMNS if name not in header]
    if len(time_columns) != 1 or missing:
        raise ValueError(
            f"{path}:{header_number}: the header needs one time column (t_s, t_us or t_ns) and "
            f"{', '.join(CSV_POSE_COLUMNS)}; got {header}"
            + (f" (missing {', '.join(missing)})" if missing else "")
        )
    index = [header.index(name) for name in (time_columns[0], *CSV_POSE_COLUMNS)]
    numbers, rows = [], []
    for number, fields in zip(
        (n for n, _ in content[1:]), csv.reader(line for _, line in content[1:])
    ):
        if len(fields) != len(header):
            raise ValueError(
                f"{path}:{number}: expected {len(header)} columns as in the header, got {len(fields)}"
            )
        numbers.append(number)
        rows.append([fields[i] for i in index])
    table = _floats(path, numbers, rows)
    table[:, 0] *= CSV_TIME_COLUMNS[time_columns[0]]
    return numbers, table


def _lines(path: Path) -> list[str]:
    try:
        return path.read_text().splitlines()
    except UnicodeDecodeError as error:
        raise ValueError(f"{path}: not a text file ({error})") from error


def _floats(path: Path, numbers: list[int], rows: list[list[str]]) -> np.ndarray:
    """The rows as a float64 table, or an error naming the first line that is not all finite
    numbers (converted in one call; the line is searched for only when that fails)."""
    if not rows:
        return np.zeros((0, 8))
    try:
        table = np.array(rows, dtype=np.float64)
    except ValueError:
        for number, fields in zip(numbers, rows, strict=True):
            try:
                [float(field) for field in fields]
            except ValueError as error:
                raise ValueError(f"{path}:{number}: not a number ({error})") from error
        raise
    bad = np.flatnonzero(~np.all(np.isfinite(table), axis=1))
    if bad.size:
        first = int(bad[0])
        raise ValueError(f"{path}:{numbers[first]}: values must be finite, got {rows[first]}")
    return table


def _validated(path: Path, numbers: list[int], table: np.ndarray) -> TrajectorySamples:
    t = table[:, 0]
    backwards = np.flatnonzero(np.diff(t) <= 0)
    if backwards.size:
        i = int(backwards[0]) + 1
        now, before = float(t[i]), float(t[i - 1])
        kind = "repeats" if now == before else "is before"
        raise ValueError(
            f"{path}:{numbers[i]}: time {now!r} s {kind} the previous pose's "
            f"(line {numbers[i - 1]}: {before!r} s); times must increase strictly"
        )
    norm = np.linalg.norm(table[:, 4:], axis=1)
    off = np.flatnonzero(np.abs(norm - 1.0) > _UNIT_TOLERANCE)
    if off.size:
        i = int(off[0])
        raise ValueError(
            f"{path}:{numbers[i]}: quaternion norm {norm[i]:.4g} is not 1 (within "
            f"{_UNIT_TOLERANCE:g}); check the column order"
        )
    return TrajectorySamples(t.copy(), table[:, 1:4].copy(), table[:, 4:] / norm[:, None])


# Frame and event times are whole microseconds: a file ending half a microsecond short of the
# run's end still covers its last frame.
_COVER_TOLERANCE_S = 0.5e-6


def check_covers(track: Track, duration_s: float, name: str) -> None:
    """Refuse a track of recorded poses (`track.source` set) whose times do not cover the run,
    0 to `duration_s`: held before its first pose or after its last, the camera (or object)
    would freeze there, and the IMU read an impulse at the jump. `name` says which track."""
    if track.source is None:
        return
    start_s, end_s = track.start_s, track.end_s
    if start_s <= _COVER_TOLERANCE_S and end_s >= duration_s - _COVER_TOLERANCE_S:
        return
    spans = (
        f"{name}: trajectory {track.source} covers {start_s:g} s to {end_s:g} s of scene time, "
        f"the simulation 0 s to {duration_s:g} s"
    )
    if start_s > _COVER_TOLERANCE_S:
        fix = (
            'its times start late (Unix-style times?): set time_offset_s = "first" (or the '
            "offset in seconds) where the trajectory is named"
        )
    else:
        fix = (
            f"it ends early: shorten the run to {end_s:g} s (--duration {end_s:g}), give "
            f"poses up to {duration_s:g} s, or stretch the file's times (time_scale)"
        )
    raise ValueError(f"{spans}; {fix}")
