"""Reading a dataset for training: windows of events (a fixed duration or a fixed count), each
with the camera poses of the frames that cover it, as Arrow or numpy.

`open_dataset(DIR).windows(duration_us=50_000)` is a sequence of `EventWindow`: indexable (for a
PyTorch `Dataset`, `pecs.dataset.torch_adaptor`), iterable (to stream), picklable (DataLoader
workers), and lazy: its length comes from the Parquet metadata, and a window reads only the row
groups it needs. Ground truth beyond the poses (depth, flow, instances, IMU, when the run wrote
them) comes from the sequence's run folder through `EventWindow.ground_truth()`, and the dense
ground truth of the window itself (flow from its start to its end, depth and instances at its
end) through `EventWindow.dense_ground_truth()`, or in `arrays()` with
`windows(..., dense_ground_truth=True)`.
"""

from __future__ import annotations

import math
import os
from collections.abc import Iterator
from dataclasses import dataclass
from functools import cached_property
from pathlib import Path
from typing import Any

import numpy as np
import pyarrow as pa
import pyarrow.parquet as pq

from pecs.dataset import layout

_POSE_COLUMNS = ("position_x_m", "position_y_m", "position_z_m", "qw", "qx", "qy", "qz")
_CACHED_SEQUENCES = 4


@dataclass(frozen=True)
class EventWindow:
    """One window of one sequence: events with `start_us <= t < end_us`, and its frames."""

    sequence: str
    #: The window's number within its sequence.
    index: int
    start_us: int
    end_us: int
    #: Every column of the sequence's events, as the dataset stores them: t (us), x, y,
    #: p (1 ON, 0 OFF), and where the sequence has them `label` (noise labels) and the
    #: per-event ground truth (gt_frame, flow_x_px, flow_y_px, instance).
    events: pa.Table
    #: Camera pose per frame (t_us, frame, position in m, quaternion w x y z), from the last
    #: frame at or before `start_us` to the first at or after `end_us`: enough to interpolate
    #: the pose at any event time of the window.
    poses: pa.Table
    #: The sequence's run folder (ground truth files).
    run_dir: Path
    width: int
    height: int
    #: Whether `arrays()` carries `dense_ground_truth()`.
    dense: bool = False

    @property
    def frame_indices(self) -> np.ndarray:
        """The rendered frames covering the window (rows of the sequence's per-frame ground
        truth)."""
        return self.poses.column("frame").to_numpy()

    @property
    def frame_t_us(self) -> np.ndarray:
        return self.poses.column("t_us").to_numpy()

    def arrays(self) -> dict[str, np.ndarray]:
        """Events and poses as numpy: every column of `events` (per event: t, x, y, p, and
        label, gt_frame, flow_x_px, flow_y_px, instance where the sequence has them),
        frame_t_us, frame (per frame) and pose (per frame: x, y, z in m, then qw, qx, qy, qz);
        with dense ground truth asked for, `dense_ground_truth()`'s arrays too."""
        columns = {name: self.events.column(name).to_numpy() for name in self.events.column_names}
        pose = np.stack([self.poses.column(c).to_numpy() for c in _POSE_COLUMNS], axis=-1)
        dense = self.dense_ground_truth() if self.dense else {}
        return {
            **columns,
            "frame_t_us": self.frame_t_us,
            "frame": self.frame_indices,
            "pose": pose.reshape(-1, len(_POSE_COLUMNS)),
            **dense,
        }

    def dense_ground_truth(self) -> dict[str, np.ndarray]:
        """The window's dense ground truth, from the sequence's depth and instances (a spec's
        `ground_truth = "depth,instances"` or "all"): `flow_px` (float32 H x W x 2) from the
        window's start to its end with `flow_valid` (bool H x W: seen at both ends, in the
        image), and `depth_m` (float32, z-depth) and `instance_map` (int32) at its end;
        `flow_t_us` holds the two times. Ends past the rendered frames (the last window's
        latency tail) are clipped to them. See docs/ground-truth.md."""
        truth = self.ground_truth()
        first, last = int(truth.t_us[0]), int(truth.t_us[-1])
        start_us = min(max(self.start_us, first), last)
        end_us = min(max(self.end_us, first), last)
        flow = truth.flow_between(start_us, end_us)
        return {
            "flow_px": flow.flow_px,
            "flow_valid": flow.valid,
            "flow_t_us": np.array([start_us, end_us], dtype=np.int64),
            "depth_m": truth.depth_at(end_us),
            # H x W: named apart from the events' own per-event `instance` column, which
            # arrays() returns beside it (a dict cannot hold both under one name).
            "instance_map": truth.instance_at(end_us),
        }

    def ground_truth(self) -> Any:
        """The sequence's per-frame ground truth (`pecs.read_ground_truth` of its run folder);
        index it with `frame_indices`. A RuntimeError when this pecs cannot read ground truth."""
        import pecs

        reader = getattr(pecs, "read_ground_truth", None)
        if reader is None:
            raise RuntimeError(
                "this pecs has no pecs.read_ground_truth; only camera poses (EventWindow.poses) "
                "are available"
            )
        return reader(self.run_dir)


class EventDataset:
    """A dataset folder written by `pecs.dataset.run_dataset`, for reading."""

    def __init__(self, root: str | os.PathLike[str]) -> None:
        self.root = Path(root)
        self.manifest = layout.read_manifest(self.root)
        records = {r["name"]: r for r in self.manifest["sequences"]}
        # A sequence's own record is the truth: the manifest may lag it by one sequence when
        # the run was killed between the two writes.
        finished = {name: layout.finished_record(self.root, name) for name in records}
        #: The finished sequences, in spec order (failed and pending ones have no data).
        self.sequences = [name for name, record in finished.items() if record is not None]
        self._records = {name: finished[name] or records[name] for name in records}

    def record(self, sequence: str) -> dict[str, Any]:
        """The manifest's record of a sequence: parameters drawn, sensor config, timings."""
        return self._records[self._known(sequence)]

    def events_path(self, sequence: str) -> Path:
        return layout.events_partition(self.root, self._known(sequence)) / layout.EVENTS_FILE

    def run_dir(self, sequence: str) -> Path:
        return layout.run_dir(self.root, self._known(sequence))

    def events(self, sequence: str) -> pa.Table:
        return pq.read_table(self.events_path(sequence))

    def poses(self, sequence: str) -> pa.Table:
        return pq.read_table(self.run_dir(sequence) / layout.POSES_FILE)

    def arrow(self) -> Any:
        """Every sequence's events as one `pyarrow.dataset` with a `sequence` column."""
        import pyarrow.dataset as ds

        return ds.dataset(self.root / layout.EVENTS_DIR, format="parquet", partitioning="hive")

    def windows(
        self,
        *,
        duration_us: int | None = None,
        count: int | None = None,
        sequences: list[str] | None = None,
        drop_partial: bool = False,
        dense_ground_truth: bool = False,
    ) -> EventWindows:
        """Windows of `duration_us` microseconds (from t = 0) or of `count` events, over the
        given sequences (default: all finished ones). `drop_partial` leaves out each sequence's
        last window when it holds fewer than `count` events (count windows only).
        `dense_ground_truth` puts each window's flow, depth and instances in its `arrays()`."""
        names = self.sequences if sequences is None else [self._known(s) for s in sequences]
        return EventWindows(self, names, duration_us, count, drop_partial, dense_ground_truth)

    def _known(self, sequence: str) -> str:
        if sequence not in self._records:
            raise KeyError(f"{self.root}: no sequence {sequence!r} in the manifest")
        return sequence


def open_dataset(root: str | os.PathLike[str]) -> EventDataset:
    """A dataset folder for reading (see `EventDataset`)."""
    return EventDataset(root)


class EventWindows:
    """The windows of a dataset, in sequence order then time order; `len()` and `[i]`."""

    def __init__(
        self,
        dataset: EventDataset,
        sequences: list[str],
        duration_us: int | None,
        count: int | None,
        drop_partial: bool,
        dense_ground_truth: bool = False,
    ) -> None:
        if (duration_us is None) == (count is None):
            raise ValueError("windows: give either duration_us or count, not both or neither")
        for name, value in (("duration_us", duration_us), ("count", count)):
            if value is not None and (isinstance(value, bool) or not isinstance(value, int)):
                raise ValueError(f"windows: {name} must be an integer, got {value!r}")
            if value is not None and value < 1:
                raise ValueError(f"windows: {name} must be at least 1, got {value}")
        self.dataset = dataset
        self.sequences = list(sequences)
        self.duration_us = duration_us
        self.count = count
        self.drop_partial = drop_partial
        self.dense_ground_truth = dense_ground_truth
        self._readers: dict[str, _SequenceReader] = {}

    @cached_property
    def _first_window(self) -> np.ndarray:
        """Index of each sequence's first window, and the total at the end."""
        counts = [self._window_count(self._reader(name)) for name in self.sequences]
        return np.concatenate([[0], np.cumsum(counts, dtype=np.int64)])

    def __len__(self) -> int:
        return int(self._first_window[-1])

    def __iter__(self) -> Iterator[EventWindow]:
        for i in range(len(self)):
            yield self[i]

    def __getitem__(self, i: int) -> EventWindow:
        if isinstance(i, (bool, np.bool_)) or not isinstance(i, (int, np.integer)):
            raise TypeError(f"window index must be an integer, got {i!r}")
        n = len(self)
        if not -n <= i < n:
            raise IndexError(f"window {i} of {n}")
        i = int(i) % n
        s = int(np.searchsorted(self._first_window, i, side="right")) - 1
        reader = self._reader(self.sequences[s])
        return self._window(reader, i - int(self._first_window[s]))

    def __getstate__(self) -> dict[str, Any]:
        # Open files stay with their process: a DataLoader worker opens its own.
        return {**self.__dict__, "_readers": {}}

    def _window_count(self, reader: _SequenceReader) -> int:
        if self.duration_us is not None:
            return max(1, math.ceil(reader.end_us / self.duration_us))
        assert self.count is not None
        whole, rest = divmod(reader.rows, self.count)
        return whole + (1 if rest and not self.drop_partial else 0)

    def _window(self, reader: _SequenceReader, k: int) -> EventWindow:
        if self.duration_us is not None:
            start_us, end_us = k * self.duration_us, (k + 1) * self.duration_us
            first, last = reader.rows_between(start_us, end_us)
            events = reader.read_rows(first, last)
        else:
            assert self.count is not None
            events = reader.read_rows(k * self.count, min((k + 1) * self.count, reader.rows))
            t = events.column("t")
            start_us = int(t[0].as_py()) if len(t) else 0
            end_us = int(t[-1].as_py()) + 1 if len(t) else 0
        return EventWindow(
            reader.name,
            k,
            start_us,
            end_us,
            events,
            reader.poses_covering(start_us, end_us),
            reader.run_dir,
            reader.width,
            reader.height,
            self.dense_ground_truth,
        )

    def _reader(self, name: str) -> _SequenceReader:
        if name not in self._readers:
            if len(self._readers) >= _CACHED_SEQUENCES:
                self._readers.pop(next(iter(self._readers)))
            self._readers[name] = _SequenceReader(self.dataset, name)
        return self._readers[name]


class _SequenceReader:
    """One sequence's events file, read by row ranges (whole row groups, then sliced)."""

    def __init__(self, dataset: EventDataset, name: str) -> None:
        self.name = name
        self.run_dir = dataset.run_dir(name)
        self.file = pq.ParquetFile(dataset.events_path(name))
        meta = self.file.metadata
        self.rows = meta.num_rows
        self.group_starts = np.concatenate(
            [[0], np.cumsum([meta.row_group(g).num_rows for g in range(meta.num_row_groups)])]
        ).astype(np.int64)
        schema_meta = self.file.schema_arrow.metadata or {}
        self.width = int(schema_meta.get(b"width", 0))
        self.height = int(schema_meta.get(b"height", 0))
        simulated_s = dataset.record(name).get("simulated_s", 0.0)
        self.duration_us = round(simulated_s * 1e6)
        self._t_us: np.ndarray | None = None
        self._poses: pa.Table | None = None

    @property
    def end_us(self) -> int:
        """The end of the sequence: its duration, or past its last event (the latency tail)."""
        return max(self.duration_us, self.last_t_us + 1)

    @cached_property
    def last_t_us(self) -> int:
        if self.rows == 0:
            return -1
        return int(self.read_rows(self.rows - 1, self.rows).column("t")[0].as_py())

    def rows_between(self, start_us: int, end_us: int) -> tuple[int, int]:
        if self._t_us is None:
            self._t_us = self.file.read(columns=["t"]).column("t").to_numpy()
        first, last = np.searchsorted(self._t_us, [start_us, end_us], side="left")
        return int(first), int(last)

    def read_rows(self, first: int, last: int) -> pa.Table:
        """Rows [first, last) of the events file."""
        if last <= first:
            return self.file.schema_arrow.empty_table()
        g0 = int(np.searchsorted(self.group_starts, first, side="right")) - 1
        g1 = int(np.searchsorted(self.group_starts, last, side="left"))
        table = self.file.read_row_groups(list(range(g0, g1)))
        offset = first - int(self.group_starts[g0])
        return table.slice(offset, last - first)

    def poses_covering(self, start_us: int, end_us: int) -> pa.Table:
        if self._poses is None:
            self._poses = pq.read_table(self.run_dir / layout.POSES_FILE)
        t = self._poses.column("t_us").to_numpy()
        if t.size == 0:
            return self._poses
        first = max(int(np.searchsorted(t, start_us, side="right")) - 1, 0)
        last = min(int(np.searchsorted(t, end_us, side="left")), t.size - 1)
        return self._poses.slice(first, last - first + 1)
