"""Per-event ground truth: each event gets the flow and instance of its pixel in the frame whose
interval holds it.

An event at t belongs to frame i with t_i < t <= t_{i+1} (the interval over which the sensor
saw the change that fired it); events after the last frame (held back by latency) belong to the
last interval. Its flow is flow(i) at its pixel (pixels moved from t_i to t_{i+1}), its
instance instance(i) at its pixel.
"""

from __future__ import annotations

from collections.abc import Callable
from pathlib import Path

import numpy as np
import pyarrow as pa
import pyarrow.parquet as pq

from pecs._atomic import atomic_path

EVENT_COLUMNS = ("gt_frame", "flow_x_px", "flow_y_px", "instance")


def event_frames(t_us: np.ndarray, frame_times_us: np.ndarray) -> np.ndarray:
    """Index i of the interval (t_i, t_{i+1}] holding each event time (clipped to the intervals)."""
    last_interval = max(len(frame_times_us) - 2, 0)
    index = np.searchsorted(frame_times_us, t_us, side="left") - 1
    return np.clip(index, 0, last_interval)


def add_event_columns(
    events_path: Path,
    frame_times_us: np.ndarray,
    flow: Callable[[int], np.ndarray],
    instance: Callable[[int], np.ndarray],
) -> None:
    """Rewrite an events Parquet file with the columns of EVENT_COLUMNS appended (atomically)."""
    source = pq.ParquetFile(events_path)
    schema = source.schema_arrow
    fields = [
        pa.field("gt_frame", pa.uint32(), nullable=False),
        pa.field("flow_x_px", pa.float32()),
        pa.field("flow_y_px", pa.float32()),
        pa.field("instance", pa.int32(), nullable=False),
    ]
    out_schema = pa.schema(list(schema) + fields, metadata=schema.metadata)
    cache = _FrameCache(flow, instance)
    with atomic_path(events_path) as tmp:
        writer = pq.ParquetWriter(
            tmp,
            out_schema,
            compression="zstd",
            use_dictionary=[n for n in ("p", "label") if n in out_schema.names],
            column_encoding={"t": "DELTA_BINARY_PACKED", "gt_frame": "DELTA_BINARY_PACKED"},
        )
        try:
            for batch in source.iter_batches(batch_size=1 << 20):
                writer.write_batch(_annotated(batch, frame_times_us, cache, out_schema))
        finally:
            writer.close()


class _FrameCache:
    """The flow and instance arrays of one frame at a time (events come in time order)."""

    def __init__(
        self, flow: Callable[[int], np.ndarray], instance: Callable[[int], np.ndarray]
    ) -> None:
        self.flow, self.instance = flow, instance
        self.index = -1
        self.arrays: tuple[np.ndarray, np.ndarray] | None = None

    def get(self, index: int) -> tuple[np.ndarray, np.ndarray]:
        if index != self.index or self.arrays is None:
            self.index, self.arrays = index, (self.flow(index), self.instance(index))
        return self.arrays


def _annotated(
    batch: pa.RecordBatch, frame_times_us: np.ndarray, cache: _FrameCache, schema: pa.Schema
) -> pa.RecordBatch:
    t = batch.column("t").to_numpy()
    x = batch.column("x").to_numpy().astype(np.intp)
    y = batch.column("y").to_numpy().astype(np.intp)
    frames = event_frames(t, frame_times_us)
    flow = np.full((t.size, 2), np.nan, dtype=np.float32)
    instance = np.full(t.size, -1, dtype=np.int32)
    # Events are sorted by t, so each frame's events form one contiguous run.
    starts = np.flatnonzero(np.r_[True, frames[1:] != frames[:-1]]) if t.size else []
    ends = list(starts[1:]) + [t.size]
    for start, end in zip(starts, ends, strict=True):
        frame_flow, frame_instance = cache.get(int(frames[start]))
        flow[start:end] = frame_flow[y[start:end], x[start:end]]
        instance[start:end] = frame_instance[y[start:end], x[start:end]]
    columns = [*batch.columns, pa.array(frames.astype(np.uint32))]
    columns += [pa.array(flow[:, 0]), pa.array(flow[:, 1]), pa.array(instance)]
    return pa.RecordBatch.from_arrays(columns, schema=schema)
