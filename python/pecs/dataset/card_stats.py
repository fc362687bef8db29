"""The numbers of a dataset card (`pecs.dataset.card`): per sequence and pooled, read from a
dataset folder's manifest, events files, run folders (ground truth) and scene files.

Pure numbers, no figures: what a user checks before training on a dataset. Events per second
and the ON fraction come from every event; flow, depth and instances from up to `max_frames`
evenly spaced stored ground-truth frames per sequence (all of them in a short sequence), pooled
values thinned to at most `max_values` per sequence so that a card of a thousand sequences stays
cheap.
"""

from __future__ import annotations

import dataclasses
import math
import os
import sys
from dataclasses import dataclass, field
from pathlib import Path
from typing import Any

import numpy as np
import pyarrow.compute as pc
import pyarrow.parquet as pq

from pecs.dataset import layout
from pecs.dataset.distributions import Distribution, parse_distribution

if sys.version_info >= (3, 11):
    import tomllib
else:  # pragma: no cover - Python 3.10
    import tomli as tomllib

#: The window that flow magnitudes are scaled to: DSEC's flow ground truth and the windows
#: E-RAFT and others train on are 100 ms.
FLOW_WINDOW_US = 100_000
# A generated scene's files, in its run folder (pecs.dataset.generators.SCENE_FOLDER).
_SCENE_FILE = Path("scene") / "scene.toml"


@dataclass(frozen=True)
class SequenceStats:
    """One sequence of the manifest; the measured fields are None where it has no data."""

    name: str
    #: done, failed or pending.
    status: str
    scene: str
    events: int = 0
    duration_s: float = 0.0
    width: int = 0
    height: int = 0
    #: Rendered frames.
    frames: int = 0
    events_per_s: float = math.nan
    #: ON events / all events (NaN without events).
    on_fraction: float = math.nan
    #: Sensor fields drawn for the sequence (the manifest's `task.drawn`).
    drawn: dict[str, Any] = field(default_factory=dict)
    #: |flow| of valid pixels scaled to FLOW_WINDOW_US, px (thinned); None: no flow stored.
    flow_px_per_100ms: np.ndarray | None = None
    #: Finite, positive z-depths, m (thinned); None: no depth stored.
    depth_m: np.ndarray | None = None
    #: Instances (shapes) seen in the frames read; None: no instances stored.
    instances: int | None = None
    #: `[light] illuminance_lux` of the sequence's scene file; None: the scene states none.
    illuminance_lux: float | None = None
    #: Bytes on disk (events file and run folder).
    size_bytes: int = 0
    error: str | None = None


@dataclass(frozen=True)
class DatasetStats:
    root: Path
    name: str
    sequences: list[SequenceStats]
    #: Per drawn sensor field, the spec's distributions of it (one per table that draws it).
    draw_ranges: dict[str, list[Distribution]]
    #: Per `[scene.draw]` parameter of a generated scene, its [min, max] ranges (for marking).
    scene_ranges: dict[str, list[list[Any]]]
    versions: dict[str, Any]

    @property
    def done(self) -> list[SequenceStats]:
        return [s for s in self.sequences if s.status == "done"]

    def count(self, status: str) -> int:
        return sum(s.status == status for s in self.sequences)

    @property
    def total_events(self) -> int:
        return sum(s.events for s in self.done)

    @property
    def total_duration_s(self) -> float:
        return sum(s.duration_s for s in self.done)

    @property
    def size_bytes(self) -> int:
        return sum(s.size_bytes for s in self.sequences)

    @property
    def sensor_sizes(self) -> dict[tuple[int, int], int]:
        """(width, height) -> number of finished sequences at that size."""
        sizes: dict[tuple[int, int], int] = {}
        for s in self.done:
            sizes[(s.width, s.height)] = sizes.get((s.width, s.height), 0) + 1
        return sizes

    def pooled(self, attribute: str) -> np.ndarray:
        """The per-pixel values of every finished sequence that has them, as one array."""
        parts = [getattr(s, attribute) for s in self.done if getattr(s, attribute) is not None]
        return np.concatenate(parts) if parts else np.zeros(0)

    def per_sequence(self, attribute: str) -> np.ndarray:
        """One number per finished sequence that has it (NaN and None left out)."""
        values = [getattr(s, attribute) for s in self.done]
        kept = [float(v) for v in values if v is not None and not math.isnan(float(v))]
        return np.asarray(kept, dtype=np.float64)

    def drawn_values(self, key: str) -> list[Any]:
        return [s.drawn[key] for s in self.done if key in s.drawn]

    @property
    def drawn_fields(self) -> list[str]:
        return sorted({key for s in self.done for key in s.drawn})


def dataset_stats(
    root: str | os.PathLike[str], *, max_frames: int = 32, max_values: int = 20_000
) -> DatasetStats:
    """The card's numbers for the dataset folder `root`; a FileNotFoundError naming the folder
    when it is missing or holds no manifest."""
    folder = Path(root)
    if not folder.is_dir():
        raise FileNotFoundError(
            f"{folder}: no such dataset folder (give the folder of a dataset run)"
        )
    manifest = layout.read_manifest(folder)
    records = [_current_record(folder, record) for record in manifest.get("sequences", [])]
    sequences = [_sequence_stats(folder, r, max_frames, max_values) for r in records]
    draw_ranges, scene_ranges = _spec_ranges(manifest.get("spec", ""), records)
    return DatasetStats(
        folder,
        str(manifest.get("name", folder.name)),
        sequences,
        draw_ranges,
        scene_ranges,
        dict(manifest.get("versions", {})),
    )


def _current_record(root: Path, record: dict[str, Any]) -> dict[str, Any]:
    """A sequence's own record where it is finished: the manifest may lag it by one sequence
    (a run killed between the two writes), as `EventDataset` reads it."""
    return layout.finished_record(root, record["name"]) or record


def _sequence_stats(
    root: Path, record: dict[str, Any], max_frames: int, max_values: int
) -> SequenceStats:
    name = record["name"]
    task = record.get("task", {})
    base = SequenceStats(
        name,
        record.get("status", "pending"),
        _scene_name(record),
        drawn=dict(task.get("drawn", {})),
        error=record.get("error"),
        size_bytes=_size_bytes(root, name),
    )
    if base.status != "done":
        return base
    events_file = layout.events_partition(root, name) / layout.EVENTS_FILE
    run_dir = layout.run_dir(root, name)
    events, on_fraction, width, height = _event_numbers(events_file)
    duration_s = float(record.get("simulated_s", 0.0))
    frames = _FrameSample(run_dir, max_frames, max_values)
    return dataclasses.replace(
        base,
        events=events,
        duration_s=duration_s,
        width=width,
        height=height,
        frames=int(record.get("frames", 0)),
        events_per_s=events / duration_s if duration_s > 0 else math.nan,
        on_fraction=on_fraction,
        flow_px_per_100ms=frames.flow_px_per_100ms(),
        depth_m=frames.depth_m(),
        instances=frames.instances(),
        illuminance_lux=scene_illuminance_lux(run_dir, record),
    )


def _scene_name(record: dict[str, Any]) -> str:
    scene = record.get("task", {}).get("scene", "")
    if isinstance(scene, dict):
        return f"generator:{scene.get('generator', '?')}"
    return str(scene)


def _size_bytes(root: Path, name: str) -> int:
    folders = (layout.events_partition(root, name), layout.run_dir(root, name))
    return sum(p.stat().st_size for folder in folders for p in folder.rglob("*") if p.is_file())


def _event_numbers(path: Path) -> tuple[int, float, int, int]:
    """(events, ON fraction, width, height) of an events file, reading its polarity column only."""
    file = pq.ParquetFile(path)
    meta = file.schema_arrow.metadata or {}
    width, height = int(meta.get(b"width", 0)), int(meta.get(b"height", 0))
    events = file.metadata.num_rows
    if events == 0:
        return 0, math.nan, width, height
    polarity = file.read(columns=["p"]).column("p")
    on = pc.sum(pc.greater(polarity, 0).cast("int64")).as_py() or 0
    return events, on / events, width, height


class _FrameSample:
    """The stored ground-truth frames of a run, up to `max_frames` of them evenly spaced."""

    def __init__(self, run_dir: Path, max_frames: int, max_values: int) -> None:
        self.truth = _ground_truth(run_dir)
        self.max_values = max_values
        count = len(self.truth) if self.truth is not None else 0
        self.frames = np.unique(
            np.linspace(0, count - 1, min(count, max_frames)).round().astype(int)
        )

    def flow_px_per_100ms(self) -> np.ndarray | None:
        """|flow| from frame i to i + 1 over the frames' interval, scaled to 100 ms: the
        displacement a pixel's point would make in 100 ms at its speed over that interval."""
        truth = self.truth
        if truth is None or len(truth) < 2 or not self._stored(truth.flow):
            return None
        parts = []
        for i in self.frames[self.frames < len(truth) - 1]:  # the last frame has no flow
            dt_us = float(truth.t_us[i + 1] - truth.t_us[i])
            magnitude = np.hypot(*np.moveaxis(truth.flow(int(i)), -1, 0))
            if dt_us > 0:
                parts.append(magnitude[np.isfinite(magnitude)] * (FLOW_WINDOW_US / dt_us))
        return self._thinned(parts)

    def depth_m(self) -> np.ndarray | None:
        truth = self.truth
        if truth is None or not self._stored(truth.depth):
            return None
        parts = []
        for i in self.frames:
            depth = truth.depth(int(i))
            parts.append(depth[np.isfinite(depth) & (depth > 0)])
        return self._thinned(parts)

    def instances(self) -> int | None:
        truth = self.truth
        if truth is None or not self._stored(truth.instance):
            return None
        seen = {int(v) for i in self.frames for v in np.unique(truth.instance(int(i)))}
        return len(seen - {-1})

    def _stored(self, kind: Any) -> bool:
        if not len(self.frames):
            return False
        try:
            kind(int(self.frames[0]))
        except FileNotFoundError:
            return False
        return True

    def _thinned(self, parts: list[np.ndarray]) -> np.ndarray:
        """The values, every k-th kept so that at most max_values remain (float32)."""
        values = np.concatenate(parts) if parts else np.zeros(0, np.float32)
        step = max(1, math.ceil(values.size / self.max_values))
        return values[::step].astype(np.float32)


def _ground_truth(run_dir: Path) -> Any:
    """`pecs.read_ground_truth` of a run folder, or None where the run wrote none."""
    from pecs.ground_truth.reader import read_ground_truth

    try:
        return read_ground_truth(run_dir)
    except FileNotFoundError:
        return None


def scene_illuminance_lux(run_dir: Path, record: dict[str, Any]) -> float | None:
    """The illuminance at the scene that its `[light]` table states (lux): from the generated
    scene kept in the run folder, else the scene file or built-in scene the sequence names.
    None where the scene has no `[light]` (its emitters are as the Mitsuba scene gives them)."""
    scene_file = run_dir / _SCENE_FILE
    if not scene_file.is_file():
        scene_file = _named_scene_file(str(record.get("scene_path") or ""))
    if scene_file is None:
        return None
    try:
        doc = tomllib.loads(scene_file.read_text())
    except (OSError, tomllib.TOMLDecodeError):
        return None
    light = doc.get("light")
    lux = light.get("illuminance_lux") if isinstance(light, dict) else None
    return float(lux) if isinstance(lux, (int, float)) and not isinstance(lux, bool) else None


def _named_scene_file(scene: str) -> Path | None:
    if not scene or scene.startswith("generator:"):
        return None
    from pecs.render.scene_file import resolve_scene_path

    try:
        return resolve_scene_path(scene)
    except FileNotFoundError:
        return None


def _spec_ranges(
    text: str, records: list[dict[str, Any]]
) -> tuple[dict[str, list[Distribution]], dict[str, list[list[Any]]]]:
    """The spec's draws of each sensor field (`[draw]` and every sequence's `draw`), and each
    generated scene's `[scene.draw]` ranges as the manifest's records state them."""
    try:
        doc = tomllib.loads(text)
    except tomllib.TOMLDecodeError:
        doc = {}
    tables = [doc.get("draw", {})]
    tables += [e.get("draw", {}) for e in doc.get("sequences", []) if isinstance(e, dict)]
    draws: dict[str, list[Distribution]] = {}
    for table in tables:
        for key, value in table.items() if isinstance(table, dict) else ():
            try:
                distribution = parse_distribution(value, f"draw.{key}")
            except ValueError:
                continue
            if distribution not in draws.setdefault(key, []):
                draws[key].append(distribution)
    scene: dict[str, list[list[Any]]] = {}
    for record in records:
        ranges = record.get("task", {}).get("scene", {})
        for key, value in (ranges.get("draw", {}) if isinstance(ranges, dict) else {}).items():
            if value not in scene.setdefault(key, []):
                scene[key].append(value)
    return draws, scene
