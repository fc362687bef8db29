"""Spatiotemporal distances between two event streams: the chamfer and Gaussian distances of PECS.

Each event (x, y, p, t) is a point of a 4-D space. By default (``normalize="pecs"``, the paper's
definition) each stream is normalised on its own, per axis, by min-max over its events in the
evaluation window: x, y and p to [0, 100], t to [0, 1000] (v~ = s (v - min) / (max - min + 1e-8)).
With d(u, Q) the Euclidean distance from u to its nearest event of Q:

    CD(P, P') = mean_{u in P} d(u, P') + mean_{v in P'} d(v, P)
    GD(P, P') = mean_{u in P} [1 - exp(-d(u, P')^2 / sigma)] + (the same from P' to P)

with sigma = 0.4. Nearest neighbours are exact (BVH in Rust, equal to brute force).

Variants, never on by default:
- ``normalize="sensor"`` (recommended): x / width, y / height, p as is (times 100) and t by the
  window length (times 1000), the same transform for both streams, so global offsets and scale
  errors show. The paper's per-stream min-max is kept under its name for comparison with
  published numbers, but it is fragile: one far event rescales a whole stream. A car's events in
  one part of a 346 x 260 sensor against a simulation with 1-pixel, 100 us errors: chamfer 10.3;
  the same simulation plus one event at each sensor corner: 38.7 (sensor normalisation: 6.01 and
  6.04; tests/test_metrics.py, the corner test).
- ``polarity="separate"``: an event matches only events of its own polarity, over (x, y, t);
  an event whose polarity the other stream lacks has an infinite distance (CD is then infinite
  and that event adds 1 to its GD mean).

Evaluation window: ``first_us=N`` (the paper's protocol) shifts each stream to start at 0 and
keeps its first N µs (0 <= t < N after the shift); ``window_us=(start, end)`` keeps
start <= t < end of the original times. Without either, all events count.

Edge cases: both metrics need at least one event in each stream (ValueError otherwise). A
single-event stream is valid: every axis has zero range, so PECS normalisation puts it at the
origin. ``nearest_distances(a, b)`` accepts an empty ``a`` (empty table) but not an empty ``b``.
"""

from __future__ import annotations

import json
from dataclasses import asdict, dataclass
from typing import Any, Literal

import numpy as np
import pyarrow as pa
import pyarrow.compute as pc

from pecs import _core
from pecs.events import sensor_size
from pecs.io import to_table

__all__ = [
    "PECS_SIGMA",
    "Comparison",
    "MetricOptions",
    "chamfer_distance",
    "compare",
    "gaussian_distance",
    "nearest_distances",
]

PECS_SIGMA = 0.4
NORMALIZATIONS = ("pecs", "sensor")
POLARITIES = ("coordinate", "separate")


@dataclass(frozen=True)
class MetricOptions:
    """How two streams are compared (see the module docstring)."""

    first_us: int | None = None
    window_us: tuple[int, int] | None = None
    normalize: Literal["pecs", "sensor"] = "pecs"
    polarity: Literal["coordinate", "separate"] = "coordinate"
    sigma: float = PECS_SIGMA
    sensor_size: tuple[int, int] | None = None

    def __post_init__(self) -> None:
        if self.first_us is not None and self.window_us is not None:
            raise ValueError("give first_us or window_us, not both")
        if self.first_us is not None and int(self.first_us) <= 0:
            raise ValueError(
                f"first_us must be a positive number of microseconds, got {self.first_us}"
            )
        if self.window_us is not None:
            start, end = self.window_us
            if int(end) <= int(start):
                raise ValueError(f"window_us=(start, end) needs end > start, got {self.window_us}")
        if self.normalize not in NORMALIZATIONS:
            raise ValueError(f"normalize must be one of {NORMALIZATIONS}, got {self.normalize!r}")
        if self.polarity not in POLARITIES:
            raise ValueError(f"polarity must be one of {POLARITIES}, got {self.polarity!r}")
        if not (np.isfinite(self.sigma) and self.sigma > 0):
            raise ValueError(f"sigma must be positive and finite, got {self.sigma}")
        if self.sensor_size is not None and min(self.sensor_size) <= 0:
            raise ValueError(
                f"sensor_size=(width, height) must be positive, got {self.sensor_size}"
            )


@dataclass(frozen=True)
class Comparison:
    """Both PECS metrics of a pair of streams, the event counts compared and the options used."""

    chamfer: float
    gaussian: float
    events_a: int
    events_b: int
    options: MetricOptions

    def to_dict(self) -> dict[str, Any]:
        """Plain values, ready for JSON."""
        return asdict(self)

    def to_json(self) -> str:
        return json.dumps(self.to_dict(), allow_nan=True)


@dataclass(frozen=True)
class _Stream:
    """The evaluated events of one stream as contiguous numpy columns."""

    t_us: np.ndarray
    x: np.ndarray
    y: np.ndarray
    p: np.ndarray
    schema: pa.Schema
    # What `first_us` subtracted from the times (0 otherwise).
    t_shift_us: int = 0

    def columns(self) -> tuple[np.ndarray, np.ndarray, np.ndarray, np.ndarray]:
        return self.t_us, self.x, self.y, self.p

    def __len__(self) -> int:
        return len(self.t_us)


def compare(
    a: Any,
    b: Any,
    *,
    sigma: float = PECS_SIGMA,
    first_us: int | None = None,
    window_us: tuple[int, int] | None = None,
    normalize: Literal["pecs", "sensor"] = "pecs",
    polarity: Literal["coordinate", "separate"] = "coordinate",
    sensor_size: tuple[int, int] | None = None,
) -> Comparison:
    """Chamfer and Gaussian distances between event streams `a` and `b`.

    `a` and `b`: Arrow tables or record batches (anything with `__arrow_c_stream__`), numpy
    structured arrays with t, x, y, p, or paths of event files pecs reads.
    """
    options = MetricOptions(first_us, _window(window_us), normalize, polarity, sigma, sensor_size)
    stream_a, stream_b = _prepare(a, "a", options), _prepare(b, "b", options)
    for stream, name in ((stream_a, "a"), (stream_b, "b")):
        if len(stream) == 0:
            raise ValueError(
                f"stream {name} has no events{_where(options)}; both metrics need events"
            )
    chamfer, gaussian = _core.event_metrics(
        stream_a.columns(),
        stream_b.columns(),
        normalize=options.normalize,
        polarity=options.polarity,
        sensor=_sensor(stream_a, stream_b, options),
        sigma=float(options.sigma),
    )
    return Comparison(chamfer, gaussian, len(stream_a), len(stream_b), options)


def chamfer_distance(a: Any, b: Any, **options: Any) -> float:
    """The PECS chamfer distance between `a` and `b` (options as for `compare`)."""
    return compare(a, b, **options).chamfer


def gaussian_distance(a: Any, b: Any, sigma: float = PECS_SIGMA, **options: Any) -> float:
    """The PECS Gaussian distance between `a` and `b` (options as for `compare`)."""
    return compare(a, b, sigma=sigma, **options).gaussian


def nearest_distances(
    a: Any,
    b: Any,
    *,
    first_us: int | None = None,
    window_us: tuple[int, int] | None = None,
    normalize: Literal["pecs", "sensor"] = "pecs",
    polarity: Literal["coordinate", "separate"] = "coordinate",
    sensor_size: tuple[int, int] | None = None,
) -> pa.Table:
    """For every evaluated event of `a`, the distance to its nearest event of `b`.

    Returns an Arrow table with a's events in the window (t, x, y, p, with their original
    timestamps) and `distance` (float64, in the normalised space). Its schema metadata keeps
    a's and adds `pecs.metrics`, the JSON of the options.
    """
    options = MetricOptions(
        first_us, _window(window_us), normalize, polarity, PECS_SIGMA, sensor_size
    )
    stream_a, stream_b = _prepare(a, "a", options), _prepare(b, "b", options)
    if len(stream_b) == 0:
        raise ValueError(f"stream b has no events{_where(options)}; nothing to measure against")
    distances = (
        np.empty(0, dtype=np.float64)
        if len(stream_a) == 0
        else _core.event_nearest_distances(
            stream_a.columns(),
            stream_b.columns(),
            normalize=options.normalize,
            polarity=options.polarity,
            sensor=_sensor(stream_a, stream_b, options),
        )
    )
    metadata = dict(stream_a.schema.metadata or {})
    metadata[b"pecs.metrics"] = json.dumps(asdict(options)).encode()
    fields = [
        pa.field("t", pa.int64(), nullable=False),
        pa.field("x", pa.uint16(), nullable=False),
        pa.field("y", pa.uint16(), nullable=False),
        pa.field("p", pa.int8(), nullable=False),
        pa.field("distance", pa.float64(), nullable=False),
    ]
    original_t = stream_a.t_us + stream_a.t_shift_us
    columns = [original_t, stream_a.x, stream_a.y, stream_a.p, distances]
    return pa.table([pa.array(c) for c in columns], schema=pa.schema(fields, metadata=metadata))


def _window(window_us: Any) -> tuple[int, int] | None:
    if window_us is None:
        return None
    try:
        start, end = window_us
        return int(start), int(end)
    except (TypeError, ValueError):
        raise ValueError(
            f"window_us must be (start, end) in microseconds, got {window_us!r}"
        ) from None


def _where(options: MetricOptions) -> str:
    if options.first_us is not None:
        return f" in its first {options.first_us} us"
    if options.window_us is not None:
        return f" in the window {options.window_us[0]} <= t < {options.window_us[1]} us"
    return ""


def _prepare(events: Any, name: str, options: MetricOptions) -> _Stream:
    """Stream `name` as numpy columns of the pecs types, restricted to the evaluation window.

    With first_us, t is shifted so the stream starts at 0; `_shift` gives the offset back.
    """
    try:
        table = to_table(events)
    except TypeError as error:
        raise TypeError(f"stream {name}: {error}") from None
    missing = [c for c in ("t", "x", "y", "p") if c not in table.column_names]
    if missing:
        raise ValueError(
            f"stream {name}: no column {', '.join(missing)} (columns: {table.column_names})"
        )
    columns = {}
    for column, dtype, np_dtype in (
        ("t", pa.int64(), np.int64),
        ("x", pa.uint16(), np.uint16),
        ("y", pa.uint16(), np.uint16),
        ("p", pa.int8(), np.int8),
    ):
        array = table.column(column)
        if array.null_count:
            raise ValueError(f"stream {name}: column {column} has {array.null_count} null values")
        # Casting only when needed: a cast copies, and a column of the right type is the
        # common case.
        if array.type != dtype:
            try:
                array = pc.cast(array, dtype)
            except (pa.ArrowInvalid, pa.ArrowNotImplementedError) as error:
                raise ValueError(
                    f"stream {name}: column {column} does not fit {dtype} ({error})"
                ) from None
        columns[column] = _to_numpy(array, np_dtype)
    t = columns["t"]
    keep = None
    shift = 0
    if options.first_us is not None and len(t):
        shift = int(t.min())
        t = t - shift
        keep = t < options.first_us
    elif options.window_us is not None:
        keep = (t >= options.window_us[0]) & (t < options.window_us[1])
    if keep is not None:
        t = t[keep]
        columns = {k: v[keep] for k, v in columns.items()}
    p = columns["p"]
    bad = np.flatnonzero((p != 0) & (p != 1))
    if len(bad):
        raise ValueError(
            f"stream {name}: polarity at event {bad[0]} is {p[bad[0]]}; expected 0 (OFF) or 1 (ON)"
        )
    return _Stream(np.ascontiguousarray(t), columns["x"], columns["y"], p, table.schema, shift)


def _to_numpy(array: pa.ChunkedArray, dtype: type) -> np.ndarray:
    """A null-free fixed-width column as one numpy array, a view when it has one chunk.

    Read from the data buffers: pyarrow's `to_numpy` imports pandas, 0.2 s on first use.
    """
    parts = [
        np.frombuffer(
            chunk.buffers()[1],
            dtype,
            count=len(chunk),
            offset=chunk.offset * np.dtype(dtype).itemsize,
        )
        for chunk in array.chunks
    ]
    if len(parts) == 1:
        return parts[0]
    return np.concatenate(parts) if parts else np.empty(0, dtype)


def _sensor(a: _Stream, b: _Stream, options: MetricOptions) -> tuple[int, int, int, int] | None:
    """(width, height, t_origin_us, t_span_us) for normalize="sensor"; None for "pecs"."""
    if options.normalize != "sensor":
        return None
    width, height = _sensor_size(a, b, options)
    for stream, name in ((a, "a"), (b, "b")):
        outside = int(np.count_nonzero((stream.x >= width) | (stream.y >= height)))
        if outside:
            raise ValueError(
                f"stream {name}: {outside} events lie outside the {width} x {height} sensor; "
                "pass the right sensor_size"
            )
    if options.first_us is not None:
        return width, height, 0, int(options.first_us)
    if options.window_us is not None:
        start, end = options.window_us
        return width, height, start, end - start
    t_min = min(int(a.t_us.min()), int(b.t_us.min()))
    t_max = max(int(a.t_us.max()), int(b.t_us.max()))
    return width, height, t_min, max(t_max - t_min, 1)


def _sensor_size(a: _Stream, b: _Stream, options: MetricOptions) -> tuple[int, int]:
    if options.sensor_size is not None:
        return int(options.sensor_size[0]), int(options.sensor_size[1])
    sizes = {size for size in (sensor_size(a.schema), sensor_size(b.schema)) if size is not None}
    if len(sizes) > 1:
        raise ValueError(
            f"the streams were recorded on different sensor sizes {sorted(sizes)}; "
            "pass sensor_size=(width, height) to compare them anyway"
        )
    if not sizes:
        raise ValueError(
            "normalize='sensor' needs the sensor size: pass sensor_size=(width, height) "
            "or use events whose schema metadata has width and height"
        )
    return sizes.pop()
