"""Frames on disk to an event file, streamed: memory does not grow with the sequence length."""

from __future__ import annotations

import os
from pathlib import Path

import pyarrow.parquet as pq

from pecs._atomic import atomic_path
from pecs.config import SensorConfig
from pecs.frames import FrameSource, open_frames
from pecs.sensor import EventSensor


def frames_to_file(
    frames: FrameSource | str | os.PathLike[str],
    output: str | os.PathLike[str],
    config: SensorConfig,
    *,
    fps: float | None = None,
    progress: bool = False,
) -> dict[str, int]:
    """Simulate the sensor on a frame sequence and write its events to a Parquet file.

    The file appears at `output` only when complete. Returns counts: frames and events.
    """
    source = frames if isinstance(frames, FrameSource) else open_frames(frames, fps=fps)
    if (source.width, source.height) != (config.width, config.height):
        config = config.replace(width=source.width, height=source.height)
    sensor = EventSensor(config)
    schema = sensor.schema.with_metadata(
        {**sensor.schema.metadata, b"pecs.source": source.path.name.encode()}
    )
    counts = {"frames": 0, "events": 0}
    bar = _progress_bar(progress, len(source) or None)
    with atomic_path(Path(output)) as tmp, pq.ParquetWriter(tmp, schema) as writer:
        for t_us, frame in source:
            batch = sensor.feed(frame, t_us)
            _write(writer, batch, schema, counts)
            counts["frames"] += 1
            if bar is not None:
                bar.update(1)
                bar.set_postfix(t=f"{t_us / 1e6:.3f}s", events=str(counts["events"]))
        _write(writer, sensor.flush(), schema, counts)
    if bar is not None:
        bar.close()
    return counts


def _write(writer: pq.ParquetWriter, batch, schema, counts: dict[str, int]) -> None:  # noqa: ANN001
    if batch.num_rows:
        writer.write_batch(batch.replace_schema_metadata(schema.metadata))
        counts["events"] += batch.num_rows


def _progress_bar(enabled: bool, total: int | None):  # noqa: ANN202 (tqdm or None)
    if not enabled:
        return None
    from tqdm import tqdm

    return tqdm(total=total, unit="frame", dynamic_ncols=True)
