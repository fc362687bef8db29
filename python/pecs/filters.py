"""The on-chip event filters of Prophesee's sensors (the ESP block of the Gen4.1 / IMX636, the
EVK4's sensor), run on any events: a recording, a file of another camera, or a simulation.

- Event rate controller (ERC, `erc_rate_hz`): at most rate x 200 us events pass in each 200 us
  period, spread evenly over the period's events.
- Anti-flicker (AFK, `afk_band_hz`): drops the events of 4 x 4 pixel regions that flicker at a
  frequency inside a band of 50-520 Hz (`afk_mode="band-stop"`), or keeps only those
  (`"band-pass"`).
- Event trail filter, one type at a time with a threshold of 1-100 whole milliseconds: STC
  (`stc_ms`) keeps the second event of each burst (`stc_mode="cut-trail"`) or every event of a
  burst but its first (`"keep-trail"`), so isolated events go; TRAIL (`trail_ms`) keeps the
  first event of each burst. A burst is a pixel's run of same-polarity events, each less than
  the threshold after the one before.

The rules, with their sources, are in the Rust core's `filters` module and docs/filters.md. They
run in the order the chip's documentation lists them (AFK, event trail, ERC).

    kept = pecs.filter_events(events, erc_rate_hz=20e6, trail_ms=5)
    stream = pecs.filters.EventFilter(afk_band_hz=(90, 130))   # state kept across batches
    for batch in batches:
        out = stream.apply(batch)
    out = stream.flush()

Filtering a stream whole or batch by batch gives the same events: each filter keeps its state
per pixel (or region) across batches, and the ERC holds back the events of its current 200 us
period until the period ends (`flush()` ends the stream).
"""

from __future__ import annotations

import dataclasses
import json
import math
import numbers
from dataclasses import dataclass
from typing import Any

import numpy as np
import pyarrow as pa
import pyarrow.compute as pc

from pecs import _core
from pecs.events import sensor_size, to_table

__all__ = [
    "AFK_MODES",
    "STC_MODES",
    "EventFilter",
    "FilterSettings",
    "afk",
    "erc",
    "filter_events",
    "stc",
    "trail",
]

STC_MODES = ("cut-trail", "keep-trail")
AFK_MODES = ("band-stop", "band-pass")
#: The anti-flicker band the chip takes (Hz) and its hysteresis counter's range.
AFK_MIN_HZ, AFK_MAX_HZ = 50, 520
AFK_MAX_THRESHOLD = 7
#: The event trail filter's threshold range (whole milliseconds).
TRAIL_MIN_MS, TRAIL_MAX_MS = 1, 100
#: The Gen4.1 / IMX636 ERC period (us).
ERC_PERIOD_US = 200
#: Schema metadata key: the settings of each filtering applied, a JSON list in order.
METADATA_KEY = "pecs.filters"
_COLUMN_TYPES = {"t": pa.int64(), "x": pa.uint16(), "y": pa.uint16(), "p": pa.int8()}


@dataclass(frozen=True)
class FilterSettings:
    """Which on-chip filters run, and how; a filter whose main setting is None is off.

    `erc_rate_hz`: the event rate controller's rate (events/s), at least one event per
    `erc_period_us` period (200 us on the Gen4.1 / IMX636, 100 us on the GenX320).
    `stc_ms` / `trail_ms`: the event trail filter's threshold, whole ms in 1-100, as STC (in
    `stc_mode` "cut-trail" or "keep-trail") or as TRAIL; the chip runs one type at a time.
    `afk_band_hz`: (low, high), whole Hz with 50 <= low < high <= 520; `afk_mode` "band-stop"
    or "band-pass"; `afk_start` / `afk_stop`: the hysteresis counts (0-7, stop < start) at which
    a region starts and stops counting as flickering.
    """

    erc_rate_hz: float | None = None
    erc_period_us: int = ERC_PERIOD_US
    stc_ms: int | None = None
    stc_mode: str = "cut-trail"
    trail_ms: int | None = None
    afk_band_hz: tuple[int, int] | None = None
    afk_mode: str = "band-stop"
    afk_start: int = 6
    afk_stop: int = 4

    def __post_init__(self) -> None:
        set_field = object.__setattr__
        if self.erc_rate_hz is not None:
            set_field(self, "erc_rate_hz", _rate(self.erc_rate_hz, self.erc_period_us))
        set_field(self, "erc_period_us", _whole("erc_period_us", self.erc_period_us, 1, 10**6))
        if self.stc_ms is not None and self.trail_ms is not None:
            raise ValueError(
                "stc_ms and trail_ms: the chip's event trail filter runs as STC or as TRAIL, "
                "not both; give one"
            )
        for name in ("stc_ms", "trail_ms"):
            value = getattr(self, name)
            if value is not None:
                set_field(self, name, _whole(name, value, TRAIL_MIN_MS, TRAIL_MAX_MS, "ms"))
        _choice("stc_mode", self.stc_mode, STC_MODES)
        _choice("afk_mode", self.afk_mode, AFK_MODES)
        if self.afk_band_hz is not None:
            set_field(self, "afk_band_hz", _band(self.afk_band_hz))
        start = _whole("afk_start", self.afk_start, 0, AFK_MAX_THRESHOLD)
        stop = _whole("afk_stop", self.afk_stop, 0, AFK_MAX_THRESHOLD)
        if not stop < start:
            raise ValueError(
                f"afk_stop ({stop}) must be below afk_start ({start}): a region stops counting "
                "as flickering at a lower count than it starts"
            )
        set_field(self, "afk_start", start)
        set_field(self, "afk_stop", stop)

    @property
    def enabled(self) -> bool:
        """Whether any filter is on."""
        return any(
            value is not None
            for value in (self.erc_rate_hz, self.stc_ms, self.trail_ms, self.afk_band_hz)
        )

    def to_dict(self) -> dict[str, Any]:
        """The settings by name (the band as a list), as `FilterSettings(**d)` takes them."""
        values = dataclasses.asdict(self)
        if self.afk_band_hz is not None:
            values["afk_band_hz"] = list(self.afk_band_hz)
        return values

    def describe(self) -> str:
        """The filters that are on, in a few words: 'STC cut-trail 10 ms, ERC 20 Mev/s'."""
        parts = []
        if self.afk_band_hz is not None:
            low, high = self.afk_band_hz
            parts.append(f"AFK {self.afk_mode} {low}-{high} Hz")
        if self.stc_ms is not None:
            parts.append(f"STC {self.stc_mode} {self.stc_ms} ms")
        if self.trail_ms is not None:
            parts.append(f"trail {self.trail_ms} ms")
        if self.erc_rate_hz is not None:
            rate = self.erc_rate_hz
            parts.append(f"ERC {rate / 1e6:g} Mev/s" if rate >= 1e6 else f"ERC {rate:g} ev/s")
        return ", ".join(parts) or "none"

    def _core_chain(self, width: int, height: int) -> _core.FilterChain:
        afk = None
        if self.afk_band_hz is not None:
            low, high = self.afk_band_hz
            afk = (low, high, self.afk_mode, self.afk_start, self.afk_stop)
        trail = None
        if self.stc_ms is not None:
            trail = (f"stc-{self.stc_mode}", self.stc_ms)
        elif self.trail_ms is not None:
            trail = ("trail", self.trail_ms)
        erc = None if self.erc_rate_hz is None else (self.erc_rate_hz, self.erc_period_us)
        return _core.FilterChain(afk=afk, trail=trail, erc=erc, width=width, height=height)


def _whole(name: str, value: Any, least: int, most: int, unit: str = "") -> int:
    """`value` as an int in [least, most]; a float is taken when it holds a whole number."""
    of = f" of {unit}" if unit else ""
    what = f"{name}: must be a whole number{of} in {least}-{most}, got {value!r}"
    if isinstance(value, bool) or not isinstance(value, numbers.Real):
        raise ValueError(what)
    if not isinstance(value, numbers.Integral):
        if not (math.isfinite(value) and float(value).is_integer()):
            raise ValueError(what)
    number = int(value)
    if not least <= number <= most:
        raise ValueError(what)
    return number


def _rate(value: Any, period_us: Any) -> float:
    period = _whole("erc_period_us", period_us, 1, 10**6)
    least = 1e6 / period
    if (
        isinstance(value, bool)
        or not isinstance(value, numbers.Real)
        or not math.isfinite(value)
        or not least <= value <= 1e15
    ):
        raise ValueError(
            f"erc_rate_hz: must be a number of events/s from {least:g} (one event per "
            f"{period} us period) to 1e15, got {value!r}"
        )
    return float(value)


def _band(value: Any) -> tuple[int, int]:
    what = (
        f"afk_band_hz: must be (low, high) in whole Hz with {AFK_MIN_HZ} <= low < high <= "
        f"{AFK_MAX_HZ}, got {value!r}"
    )
    if isinstance(value, (str, bytes)) or not hasattr(value, "__len__") or len(value) != 2:
        raise ValueError(what)
    low = _whole("afk_band_hz", value[0], AFK_MIN_HZ, AFK_MAX_HZ, "Hz")
    high = _whole("afk_band_hz", value[1], AFK_MIN_HZ, AFK_MAX_HZ, "Hz")
    if not low < high:
        raise ValueError(what)
    return low, high


def _choice(name: str, value: Any, choices: tuple[str, ...]) -> None:
    if value not in choices:
        raise ValueError(f"{name}: choose one of {', '.join(choices)}, got {value!r}")


def _settings(settings: FilterSettings | None, fields: dict[str, Any]) -> FilterSettings:
    if settings is None:
        return FilterSettings(**fields)
    if not isinstance(settings, FilterSettings):
        raise TypeError(
            f"settings must be a pecs.filters.FilterSettings, got {type(settings).__name__}"
        )
    return dataclasses.replace(settings, **fields) if fields else settings


class EventFilter:
    """The on-chip filters over one stream of events in time order, given batch by batch.

    `apply(batch)` returns the events decided so far that pass; the ERC holds back the events
    of its current period (200 us) until a later event or `flush()` ends it, so a batch's
    output may lag it by one period. The stream filtered whole or in any batches gives the same
    events. `counts` tells how many came in and how many each filter dropped.

    Built from a `FilterSettings`, its fields as keywords, or both (keywords override):
    `EventFilter(erc_rate_hz=20e6, trail_ms=5)`. `width` and `height` are the sensor's size if
    known (else taken from the first batch's metadata); any address is taken regardless.
    """

    def __init__(
        self,
        settings: FilterSettings | None = None,
        *,
        width: int | None = None,
        height: int | None = None,
        **fields: Any,
    ) -> None:
        self.settings = _settings(settings, fields)
        if (width is None) != (height is None):
            raise ValueError("give both width and height, or neither")
        if width is not None:
            _whole("width", width, 1, 65536)
            _whole("height", height, 1, 65536)
        self._size = (width, height) if width is not None else None
        self._chain: _core.FilterChain | None = None
        self._input_schema: pa.Schema | None = None  # the first batch's, with pecs's types
        self._may_hold_nulls = False  # its t, x, y or p may hold nulls: check every batch
        self._schema: pa.Schema | None = None
        self._metadata: dict[bytes, bytes] = {}
        self._held: pa.RecordBatch | None = None

    @property
    def counts(self) -> dict[str, int]:
        """events_in, afk_dropped, trail_dropped (STC or TRAIL), erc_dropped and events_out;
        events still held are counted in events_in only."""
        if self._chain is None:
            keys = ("events_in", "afk_dropped", "trail_dropped", "erc_dropped", "events_out")
            return dict.fromkeys(keys, 0)
        return self._chain.counts()

    @property
    def schema(self) -> pa.Schema | None:
        """The output's schema: the first batch's, with the settings in its metadata."""
        return self._schema

    def apply(self, batch: pa.RecordBatch | pa.Table) -> pa.RecordBatch:
        """The events that pass, of those decided with this batch (held events first)."""
        batch = self._conformed(batch)
        verdicts = self._chain.push(*(batch.column(name).to_numpy() for name in "txyp"))
        rows = batch if self._held is None else pa.concat_batches([self._held, batch])
        decided = len(verdicts)
        self._held = rows.slice(decided) if decided < rows.num_rows else None
        return _passed(rows.slice(0, decided) if self._held is not None else rows, verdicts)

    def flush(self) -> pa.RecordBatch:
        """The events still held that pass: the stream ended."""
        if self._chain is None:
            return pa.RecordBatch.from_pylist([], schema=_bare_schema())
        verdicts = self._chain.finish()
        held, self._held = self._held, None
        if held is None:
            return pa.RecordBatch.from_pylist([], schema=self._schema)
        return _passed(held, verdicts)

    def _conformed(self, batch: pa.RecordBatch | pa.Table) -> pa.RecordBatch:
        """The batch with pecs's column types and the stream's metadata; the chain is made at
        the first batch, sized from its metadata where the size is not given."""
        if isinstance(batch, pa.Table):
            batch = batch.combine_chunks().to_batches()[0] if batch.num_rows else _empty_of(batch)
        if not isinstance(batch, pa.RecordBatch):
            raise TypeError(f"batch must be a pyarrow RecordBatch, got {type(batch).__name__}")
        # The batches of a stream share one schema: checked in a comparison, converted only
        # where it differs (a table built by hand, with int64 columns, say).
        known = self._input_schema is not None and batch.schema.equals(self._input_schema)
        if not known or self._may_hold_nulls:
            batch = _with_pecs_types(batch)
            if self._input_schema is None:
                self._start(batch.schema)
            elif batch.schema.names != self._input_schema.names or not all(
                a.type == b.type for a, b in zip(batch.schema, self._input_schema, strict=True)
            ):
                raise ValueError(
                    f"batch columns {batch.schema.names} differ from the stream's "
                    f"{self._input_schema.names}: a stream's batches share one schema"
                )
            else:
                batch = pa.RecordBatch.from_arrays(batch.columns, schema=self._input_schema)
        return batch.replace_schema_metadata(self._metadata)

    def _start(self, schema: pa.Schema) -> None:
        # Only a hint for the state's first allocation: a file's metadata may say anything.
        try:
            width, height = self._size or sensor_size(schema) or (0, 0)
        except ValueError:  # width or height metadata that is not a number
            width, height = 0, 0
        self._chain = self.settings._core_chain(
            min(max(int(width), 0), 65536), min(max(int(height), 0), 65536)
        )
        self._input_schema = schema
        self._may_hold_nulls = any(schema.field(name).nullable for name in _COLUMN_TYPES)
        self._schema = _with_settings(schema, self.settings)
        self._metadata = dict(self._schema.metadata)


def _passed(rows: pa.RecordBatch, verdicts: np.ndarray) -> pa.RecordBatch:
    """The rows whose verdict is True (the rows themselves where all are)."""
    if verdicts.all():
        return rows
    return rows.filter(verdicts)


def _empty_of(table: pa.Table) -> pa.RecordBatch:
    return pa.RecordBatch.from_pylist([], schema=table.schema)


def _bare_schema() -> pa.Schema:
    return pa.schema([pa.field(name, kind, nullable=False) for name, kind in _COLUMN_TYPES.items()])


def _with_pecs_types(batch: pa.RecordBatch) -> pa.RecordBatch:
    """The batch with t, x, y, p as pecs types them (int64, uint16, uint16, int8): other
    integer types are converted where every value fits; anything else is refused."""
    names = batch.schema.names
    missing = [name for name in _COLUMN_TYPES if name not in names]
    if missing:
        raise ValueError(
            f"events need columns t, x, y and p; missing {', '.join(missing)} (have "
            f"{', '.join(names)})"
        )
    columns = list(batch.columns)
    changed = False
    for name, kind in _COLUMN_TYPES.items():
        index = names.index(name)
        column = columns[index]
        if column.null_count:
            raise ValueError(f"column {name} has {column.null_count} missing values")
        if column.type == kind:
            continue
        if name == "p" and pa.types.is_boolean(column.type):
            columns[index] = pc.cast(column, pa.int8())
        elif pa.types.is_integer(column.type):
            try:
                columns[index] = pc.cast(column, kind)
            except pa.ArrowInvalid:
                raise ValueError(
                    f"column {name} holds values outside {kind} (pecs's type for it)"
                ) from None
        else:
            raise ValueError(f"column {name} is {column.type}; the filters need integers")
        changed = True
    if not changed:
        return batch
    fields = [
        pa.field(f.name, columns[i].type, nullable=f.nullable, metadata=f.metadata)
        for i, f in enumerate(batch.schema)
    ]
    return pa.RecordBatch.from_arrays(
        columns, schema=pa.schema(fields, metadata=batch.schema.metadata)
    )


def _with_settings(schema: pa.Schema, settings: FilterSettings) -> pa.Schema:
    """The schema with these settings appended to its list of filterings applied."""
    metadata = dict(schema.metadata or {})
    applied = json.loads(metadata.get(METADATA_KEY.encode(), b"[]"))
    applied.append(settings.to_dict())
    metadata[METADATA_KEY.encode()] = json.dumps(applied).encode()
    return schema.with_metadata(metadata)


def filter_events(events: Any, settings: FilterSettings | None = None, **fields: Any) -> pa.Table:
    """The events (any in-memory event table `pecs.events.to_table` takes, sorted by t) that the
    on-chip filters pass: `pecs.filter_events(events, erc_rate_hz=20e6, stc_ms=10)`. Settings
    as `FilterSettings`, or its fields as keywords. The table keeps every column; its schema
    metadata records the settings (`pecs.filters`)."""
    stream = EventFilter(settings, **fields)
    # One batch: a call into the core per chunk would cost more than the filtering.
    batches = [stream.apply(to_table(events).combine_chunks()), stream.flush()]
    return pa.Table.from_batches(batches, schema=stream.schema)


def erc(events: Any, rate_hz: float, *, period_us: int = ERC_PERIOD_US) -> pa.Table:
    """The events the event rate controller passes at `rate_hz` events/s (see the module)."""
    return filter_events(events, erc_rate_hz=rate_hz, erc_period_us=period_us)


def stc(events: Any, threshold_ms: int, *, mode: str = "cut-trail") -> pa.Table:
    """The events the STC filter passes: the second of each burst ("cut-trail") or all but the
    first ("keep-trail"), bursts as `threshold_ms` (1-100) separates them."""
    return filter_events(events, stc_ms=threshold_ms, stc_mode=mode)


def trail(events: Any, threshold_ms: int) -> pa.Table:
    """The events the TRAIL filter passes: the first of each burst, bursts as `threshold_ms`
    (1-100) separates them."""
    return filter_events(events, trail_ms=threshold_ms)


def afk(
    events: Any,
    low_hz: int,
    high_hz: int,
    *,
    mode: str = "band-stop",
    start: int = 6,
    stop: int = 4,
) -> pa.Table:
    """The events the anti-flicker filter passes for a band of `low_hz`-`high_hz` (whole Hz
    within 50-520): those of regions not flickering in it ("band-stop"), or only those that are
    ("band-pass"). `start`, `stop`: the hysteresis counts (see `FilterSettings`)."""
    return filter_events(
        events, afk_band_hz=(low_hz, high_hz), afk_mode=mode, afk_start=start, afk_stop=stop
    )
