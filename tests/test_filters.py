"""The on-chip filters (pecs.filters; rules in rust/core/src/filters and docs/filters.md) against
streams whose kept events are worked out by hand in each case, at the rules' boundaries: exactly
at a threshold, 1 us inside, 1 us outside. Then: a stream filtered whole or in batches gives the
same events, the settings are checked, and `pecs filter` does what the API does."""

from __future__ import annotations

import json
from pathlib import Path

import numpy as np
import pecs
import pecs.io
import pyarrow as pa
import pytest
from cli_run import PYTHON_SYNTAX, run_cli
from pecs.filters import EventFilter, FilterSettings

ON, OFF = 1, 0


def table(rows: list[tuple[int, int, int, int]]) -> pa.Table:
    """Events from (t_us, x, y, p) rows, as pecs types them, on a 32 x 32 sensor."""
    columns = list(zip(*rows, strict=True)) if rows else [[], [], [], []]
    arrays = [
        pa.array(columns[0], pa.int64()),
        pa.array(columns[1], pa.uint16()),
        pa.array(columns[2], pa.uint16()),
        pa.array(columns[3], pa.int8()),
    ]
    return pa.Table.from_arrays(arrays, schema=pecs.events.schema(32, 32))


def at_pixel(
    rows: list[tuple[int, int]], x: int = 0, y: int = 0
) -> list[tuple[int, int, int, int]]:
    """(t_us, p) rows at one pixel."""
    return [(t, x, y, p) for t, p in rows]


def kept_times(rows: list[tuple[int, int, int, int]], **settings: object) -> list[int]:
    return pecs.filter_events(table(rows), **settings).column("t").to_pylist()


# -- TRAIL: the first event of each burst ------------------------------------------------------
# A burst: a pixel's same-polarity events, each less than the threshold after the one before.

TRAIL_CASES = {
    # 1 ms threshold. The second event exactly 1000 us later starts a new burst.
    "exactly at the threshold: a new burst": (at_pixel([(0, ON), (1000, ON)]), [0, 1000]),
    "1 us inside: trail, dropped": (at_pixel([(0, ON), (999, ON)]), [0]),
    "1 us outside: a new burst": (at_pixel([(0, ON), (1001, ON)]), [0, 1001]),
    # Every polarity change starts a burst, however soon.
    "a polarity change starts a burst": (at_pixel([(0, ON), (10, OFF), (20, ON)]), [0, 10, 20]),
    # Each gap is measured from the previous event, dropped or not: 900 us steps stay one burst
    # though the trail lasts 2.7 ms.
    "gaps are measured event to event": (
        at_pixel([(0, ON), (900, ON), (1800, ON), (2700, ON)]),
        [0],
    ),
    # Pixel (0, 0) at 0 and 10 (10 is trail), pixel (1, 0) at 5: its own first event.
    "pixels are independent": ([(0, 0, 0, ON), (5, 1, 0, ON), (10, 0, 0, ON)], [0, 5]),
}


@pytest.mark.parametrize("case", TRAIL_CASES)
def test_trail_keeps_the_first_event_of_each_burst(case: str) -> None:
    rows, expected = TRAIL_CASES[case]
    assert kept_times(rows, trail_ms=1) == expected


def test_trail_threshold_is_in_whole_milliseconds() -> None:
    # 5 ms: gaps of 4999 (trail), 5000 (new burst), 5001 (new burst).
    rows = at_pixel([(0, ON), (4999, ON), (9999, ON), (15000, ON)])
    assert kept_times(rows, trail_ms=5) == [0, 9999, 15000]


# -- STC: the second event of each burst (cut-trail), or all but the first (keep-trail) -------

# name: (rows, kept with cut-trail, kept with keep-trail); threshold 1 ms.
STC_CASES = {
    "an isolated event is dropped": (at_pixel([(0, ON)]), [], []),
    "second event 1 us inside the threshold: kept": (at_pixel([(0, ON), (999, ON)]), [999], [999]),
    # Exactly 1000 us: the second event starts a burst of its own, so both are first events.
    "second event exactly at the threshold: a new burst": (
        at_pixel([(0, ON), (1000, ON)]),
        [],
        [],
    ),
    "second event 1 us outside: a new burst": (at_pixel([(0, ON), (1001, ON)]), [], []),
    # One burst of four: cut-trail keeps its second, keep-trail its second, third and fourth.
    "a burst of four": (
        at_pixel([(0, ON), (100, ON), (200, ON), (300, ON)]),
        [100],
        [100, 200, 300],
    ),
    # ON burst (0, 100), then an OFF burst (200, 300, 400): second of each.
    "a polarity change starts a burst": (
        at_pixel([(0, ON), (100, ON), (200, OFF), (300, OFF), (400, OFF)]),
        [100, 300],
        [100, 300, 400],
    ),
    # Two ON bursts 4.9 ms apart: each has its second event kept (the documentation's rule;
    # the Metavision SDK's software STC would cut the second burst until a polarity change).
    "a same-polarity burst after a gap is a burst of its own": (
        at_pixel([(0, ON), (100, ON), (5000, ON), (5100, ON)]),
        [100, 5100],
        [100, 5100],
    ),
    # Pixel (0, 0): ON at 0 and 20 (20 kept); pixel (1, 0): ON at 10, OFF at 30 (two bursts of one).
    "pixels are independent": (
        [(0, 0, 0, ON), (10, 1, 0, ON), (20, 0, 0, ON), (30, 1, 0, OFF)],
        [20],
        [20],
    ),
}


@pytest.mark.parametrize("case", STC_CASES)
def test_stc_cut_trail_keeps_only_the_second_event_of_each_burst(case: str) -> None:
    rows, cut, _ = STC_CASES[case]
    assert kept_times(rows, stc_ms=1, stc_mode="cut-trail") == cut


@pytest.mark.parametrize("case", STC_CASES)
def test_stc_keep_trail_keeps_all_of_a_burst_but_its_first(case: str) -> None:
    rows, _, keep = STC_CASES[case]
    assert kept_times(rows, stc_ms=1, stc_mode="keep-trail") == keep


# -- ERC: at most rate x 200 us events a period, spread evenly --------------------------------
# 10,000 events/s is 2 events per 200 us period. Above it, of a period's N events the i-th
# (from 0) passes when (i x count) mod N < count.


def pixels(times: list[int]) -> list[tuple[int, int, int, int]]:
    """ON events at the given times, each at its own pixel (so only the rate matters)."""
    return [(t, i % 32, i // 32, ON) for i, t in enumerate(times)]


ERC_CASES = {
    "below the rate: one event a period": (10_000, pixels([0, 200, 400]), [0, 200, 400]),
    "at the rate: two a period": (10_000, pixels([0, 199, 200, 399]), [0, 199, 200, 399]),
    # N = 3: i = 0 (0 < 2) and i = 2 (4 mod 3 = 1 < 2) pass, i = 1 (2) does not.
    "above: three in a period": (10_000, pixels([0, 50, 100]), [0, 100]),
    # N = 5: i x 2 mod 5 = 0, 2, 4, 1, 3: i = 0 and 3 pass.
    "above: five in a period": (10_000, pixels([0, 10, 20, 30, 199]), [0, 30]),
    # 199 ends period 0 and 200 opens period 1: three events each, two of each kept.
    "periods are [0, 200), [200, 400)": (
        10_000,
        pixels([0, 100, 199, 200, 201, 399]),
        [0, 199, 200, 399],
    ),
    # 25,000 events/s is 5 a period; 10 events: i x 5 mod 10 < 5 for even i.
    "another rate: every other event": (25_000, pixels(list(range(10))), [0, 2, 4, 6, 8]),
    # 12,500 events/s is 2.5 a period: the chip counts whole events, 2.
    "a rate of a fractional count is floored": (12_500, pixels([0, 1, 2]), [0, 2]),
    # 5,000 events/s is 1 a period; -150 and -1 are both in [-200, 0).
    "negative times: periods still [k x 200, (k + 1) x 200)": (
        5_000,
        pixels([-150, -1, 0, 150]),
        [-150, 0],
    ),
}


@pytest.mark.parametrize("case", ERC_CASES)
def test_erc_keeps_at_most_the_rate_per_period_spread_evenly(case: str) -> None:
    rate_hz, rows, expected = ERC_CASES[case]
    assert kept_times(rows, erc_rate_hz=rate_hz) == expected


def test_erc_counts_only_what_the_filters_before_it_pass() -> None:
    # Trail (1 ms) drops 10 and 20 (trail of pixel (0, 0)); the ERC then sees 0, 30 and 40 in
    # period 0: N = 3, count 2, so 0 and 40 pass (i = 0 and 2). Had it counted all five, 30
    # would pass (i = 3: 6 mod 5 = 1 < 2) and 40 would not (i = 4: 8 mod 5 = 3).
    rows = [(0, 0, 0, ON), (10, 0, 0, ON), (20, 0, 0, ON), (30, 1, 0, ON), (40, 2, 0, ON)]
    stream = EventFilter(trail_ms=1, erc_rate_hz=10_000)
    kept = pa.Table.from_batches([stream.apply(table(rows)), stream.flush()])
    assert kept.column("t").to_pylist() == [0, 40]
    counts = stream.counts
    assert counts == {
        "events_in": 5,
        "afk_dropped": 0,
        "trail_dropped": 2,
        "erc_dropped": 1,
        "events_out": 2,
    }


# -- AFK: 4 x 4 regions flickering in the band ------------------------------------------------
# Band 50-520 Hz: periods of 15-156 units of 128 us, i.e. 1920-20095 us measure inside it. A
# region's runs alternate ON and OFF; from its third run on, each run's start measures a period
# (since the last run of its polarity): inside the band the counter rises, outside it falls.
# Counter 6 (start): flickering; 4 (stop): no longer. A region whose last run started more than
# 20095 us ago is reset.


def runs(starts: list[int], x: tuple[int, int] = (0, 3), y: tuple[int, int] = (0, 3)) -> list:
    """One event per run, alternating ON (at pixel x[0], y[0]) and OFF (at x[1], y[1]): two
    pixels of one region, as a flickering lamp lights them."""
    return [(t, x[i % 2], y[i % 2], ON if i % 2 == 0 else OFF) for i, t in enumerate(starts)]


HUNDRED_HZ = runs([5000 * k for k in range(10)])  # 0, 5000, ..., 45000
# In band: counter 1 at 10000 (third run), ..., 6 at 35000 (eighth): dropped from there.
HUNDRED_HZ_PASSED = [0, 5000, 10000, 15000, 20000, 25000, 30000]
HUNDRED_HZ_FLICKER = [35000, 40000, 45000]


def period_runs(period_us: int, offset_us: int, count: int) -> list:
    """ON runs every `period_us`, OFF runs `offset_us` after each."""
    return runs(
        sorted(
            [k * period_us for k in range(count)]
            + [k * period_us + offset_us for k in range(count)]
        )
    )


# 100 Hz flagged at 35000 (counter 6), 40000 (7); then runs every 11 ms: periods of 22 ms (out of
# the band) from 62000 on (51000's OFF period, 51000 - 35000 = 16000, is still inside: 7).
# 62000: 6, 73000: 5 (still flickering: above stop), 84000: 4 (stop: no longer), 95000: 3.
HYSTERESIS = runs([5000 * k for k in range(9)] + [51000, 62000, 73000, 84000, 95000])
# Flagged at 35000; next run at 55095 (20095 after: not stale), an ON period of 25095 (out): 5.
QUIET_LONGEST = runs([5000 * k for k in range(8)] + [55095])
# 55096: 20096 after the last run, longer than any period in the band: reset, passes.
QUIET_LONGER = runs([5000 * k for k in range(8)] + [55096])
# The 100 Hz region, and one event of the next region (x 4..7) at 37000.
TWO_REGIONS = sorted(HUNDRED_HZ + [(37000, 4, 0, ON)])

# name: (rows, band, kept in band-stop, kept in band-pass)
AFK_CASES = {
    "100 Hz, inside the band": (HUNDRED_HZ, (50, 520), HUNDRED_HZ_PASSED, HUNDRED_HZ_FLICKER),
    # Runs every 12.5 ms: a 25 ms period, 195 units, outside: the counter stays 0.
    "40 Hz, outside the band": (runs([12500 * k for k in range(10)]), (50, 520), None, []),
    # Periods of 20095 us: 156 units, the longest inside: flagged at the eighth run, 70285.
    "the longest period inside (20095 us)": (
        period_runs(20095, 10000, 5),
        (50, 520),
        [0, 10000, 20095, 30095, 40190, 50190, 60285],
        [70285, 80380, 90380],
    ),
    "1 us longer (20096 us): outside": (period_runs(20096, 10000, 5), (50, 520), None, []),
    # Periods of 1920 us: 15 units, the shortest inside; 1919 us: 14 units, outside.
    "the shortest period inside (1920 us)": (
        period_runs(1920, 900, 5),
        (50, 520),
        [0, 900, 1920, 2820, 3840, 4740, 5760],
        [6660, 7680, 8580],
    ),
    "1 us shorter (1919 us): outside": (period_runs(1919, 900, 5), (50, 520), None, []),
    # 90-110 Hz is 71-78 units: 100 Hz (10000 us, 78) inside; 120 Hz (8333 us, 65) outside.
    "a narrow band: 100 Hz inside": (HUNDRED_HZ, (90, 110), HUNDRED_HZ_PASSED, HUNDRED_HZ_FLICKER),
    "a narrow band: 120 Hz outside": (
        period_runs(8333, 4166, 5),
        (90, 110),
        None,
        [],
    ),
    "hysteresis: flickering until the counter falls to stop": (
        HYSTERESIS,
        (50, 520),
        [0, 5000, 10000, 15000, 20000, 25000, 30000, 84000, 95000],
        [35000, 40000, 51000, 62000, 73000],
    ),
    "quiet for the longest period: still flickering": (
        QUIET_LONGEST,
        (50, 520),
        HUNDRED_HZ_PASSED,
        [35000, 55095],
    ),
    "quiet 1 us longer: reset": (QUIET_LONGER, (50, 520), [*HUNDRED_HZ_PASSED, 55096], [35000]),
    "another region is judged on its own": (
        TWO_REGIONS,
        (50, 520),
        [*HUNDRED_HZ_PASSED, 37000],
        HUNDRED_HZ_FLICKER,
    ),
}


@pytest.mark.parametrize("case", AFK_CASES)
def test_afk_band_stop_drops_the_regions_flickering_in_the_band(case: str) -> None:
    rows, band, stop_kept, _ = AFK_CASES[case]
    expected = [row[0] for row in rows] if stop_kept is None else stop_kept
    assert kept_times(rows, afk_band_hz=band, afk_mode="band-stop") == expected


@pytest.mark.parametrize("case", AFK_CASES)
def test_afk_band_pass_keeps_only_the_regions_flickering_in_the_band(case: str) -> None:
    rows, band, _, pass_kept = AFK_CASES[case]
    assert kept_times(rows, afk_band_hz=band, afk_mode="band-pass") == pass_kept


def test_afk_hysteresis_thresholds_are_settings() -> None:
    # Start 2, stop 1: the 100 Hz region flickers from its fourth run (counter 2, at 15000).
    assert pecs.filters.afk(table(HUNDRED_HZ), 50, 520, start=2, stop=1).column(
        "t"
    ).to_pylist() == [0, 5000, 10000]


# -- streaming ---------------------------------------------------------------------------------


def busy_stream(seed: int = 0) -> pa.Table:
    """3000 events on 16 x 16 pixels over 80 ms: random events (with labels), and a 100 Hz
    flicker in the top-left 8 x 8 pixels, so that every filter has work."""
    rng = np.random.default_rng(seed)
    n = 2000
    t = rng.integers(0, 80_000, n)
    x, y = rng.integers(0, 16, n), rng.integers(0, 16, n)
    p = rng.integers(0, 2, n)
    flicker_t = np.repeat(np.arange(0, 80_000, 5000), 64)[:1000]
    flicker_p = (flicker_t // 5000) % 2 == 0
    fx, fy = rng.integers(0, 8, len(flicker_t)), rng.integers(0, 8, len(flicker_t))
    order = np.argsort(np.concatenate([t, flicker_t]), kind="stable")
    columns = {
        "t": np.concatenate([t, flicker_t])[order],
        "x": np.concatenate([x, fx])[order],
        "y": np.concatenate([y, fy])[order],
        "p": np.concatenate([p, flicker_p])[order],
        "label": np.arange(n + len(flicker_t))[order] % 4,
    }
    return pa.Table.from_batches(
        [pecs.events.record_batch(columns, pecs.events.schema(16, 16, labels=True))]
    )


ALL_ON = {"afk_band_hz": (50, 520), "stc_ms": 2, "stc_mode": "keep-trail", "erc_rate_hz": 10_000}


@pytest.mark.parametrize("batch_size", [1, 7, 333, 3000])
def test_a_stream_filtered_in_batches_gives_the_events_it_gives_whole(batch_size: int) -> None:
    events = busy_stream()
    whole = pecs.filter_events(events, **ALL_ON)
    stream = EventFilter(**ALL_ON)
    parts = [stream.apply(batch) for batch in events.to_batches(max_chunksize=batch_size)]
    parts.append(stream.flush())
    batched = pa.Table.from_batches(parts)
    assert batched.equals(whole)  # every column, labels too, and the schema with its metadata
    counts = stream.counts
    assert counts["events_in"] == events.num_rows
    assert counts["events_out"] == whole.num_rows
    dropped = counts["afk_dropped"] + counts["trail_dropped"] + counts["erc_dropped"]
    assert counts["events_in"] - dropped == counts["events_out"]
    # Each filter did drop events here (else the comparison would prove little).
    assert counts["afk_dropped"] > 0 and counts["trail_dropped"] > 0 and counts["erc_dropped"] > 0


def test_the_erc_holds_back_only_its_current_period() -> None:
    stream = EventFilter(erc_rate_hz=10_000)
    first = stream.apply(table(pixels([0, 50, 100])))
    assert first.num_rows == 0  # period [0, 200) is still open
    second = stream.apply(table(pixels([200])))
    assert second.column("t").to_pylist() == [0, 100]
    assert stream.flush().column("t").to_pylist() == [200]


def test_the_output_keeps_the_columns_and_records_the_settings() -> None:
    events = busy_stream()
    kept = pecs.filter_events(events, trail_ms=3)
    assert kept.schema.names == ["t", "x", "y", "p", "label"]
    assert pecs.events.sensor_size(kept.schema) == (16, 16)
    [applied] = json.loads(kept.schema.metadata[b"pecs.filters"])
    assert applied["trail_ms"] == 3 and applied["stc_ms"] is None
    twice = pecs.filter_events(kept, erc_rate_hz=1e6)
    assert len(json.loads(twice.schema.metadata[b"pecs.filters"])) == 2


def test_plain_integer_tables_and_boolean_polarity_are_taken() -> None:
    # int64 x and y, bool p. 999 is trail; 1999 is 1000 us after 999, a new burst.
    rows = pa.table({"t": [0, 999, 1999], "x": [0, 0, 0], "y": [0, 0, 0], "p": [True, True, True]})
    assert pecs.filters.trail(rows, 1).column("t").to_pylist() == [0, 1999]


def test_frames_to_events_runs_the_filters_on_the_sensors_events(tmp_path: Path) -> None:
    rng = np.random.default_rng(1)
    base = rng.uniform(0.2, 1.0, (16, 16)).astype(np.float32)
    t = np.arange(800) * 250  # 4 kHz frames for 200 ms of 100 Hz light at 30 % depth
    frames = base[None] * (1 + 0.3 * np.sin(2 * np.pi * 100 * t / 1e6))[:, None, None]
    config = pecs.SensorConfig.preset("imx636", width=16, height=16, seed=2)
    settings = FilterSettings(afk_band_hz=(50, 520), erc_rate_hz=1e7)
    frames = frames.astype(np.float32)
    raw = pecs.frames_to_events(frames, t, config)
    filtered = pecs.frames_to_events(frames, t, config, filters=settings)
    assert filtered.equals(pecs.filter_events(raw, settings))
    assert 0 < filtered.num_rows < raw.num_rows / 2  # the flicker is found and dropped
    # Streamed to a file, frame by frame (the ERC holding its period across frames): the same.
    np.save(tmp_path / "frames.npy", frames)
    out = tmp_path / "events.parquet"
    counts = pecs.frames_to_file(tmp_path / "frames.npy", out, config, fps=4000, filters=settings)
    streamed = pecs.read_events(out)
    assert streamed.column("t").to_pylist() == filtered.column("t").to_pylist()
    assert streamed.column("x").to_pylist() == filtered.column("x").to_pylist()
    assert counts["events"] == filtered.num_rows
    assert counts["afk_dropped"] + counts["erc_dropped"] == raw.num_rows - filtered.num_rows


# -- bad input and settings -----------------------------------------------------------------


@pytest.mark.parametrize(
    ("settings", "words"),
    [
        ({"erc_rate_hz": 0}, "erc_rate_hz"),
        ({"erc_rate_hz": -5e6}, "erc_rate_hz"),
        ({"erc_rate_hz": 4999}, "5000"),  # below one event per 200 us period
        ({"erc_rate_hz": float("nan")}, "erc_rate_hz"),
        ({"stc_ms": 2.5}, "whole"),
        ({"stc_ms": 0}, "1-100"),
        ({"trail_ms": 101}, "1-100"),
        ({"trail_ms": True}, "trail_ms"),
        ({"afk_band_hz": (100, 90)}, "low < high"),
        ({"afk_band_hz": (100, 100)}, "low < high"),
        ({"afk_band_hz": (40, 100)}, "50-520"),
        ({"afk_band_hz": (100, 600)}, "50-520"),
        ({"afk_band_hz": 100}, "(low, high)"),
        ({"afk_mode": "notch"}, "band-stop, band-pass"),
        ({"stc_mode": "cut"}, "cut-trail, keep-trail"),
        ({"afk_start": 4, "afk_stop": 4}, "afk_stop"),
        ({"afk_start": 8}, "0-7"),
        ({"stc_ms": 5, "trail_ms": 5}, "not both"),
    ],
)
def test_settings_outside_the_chips_are_refused_in_one_line(settings: dict, words: str) -> None:
    with pytest.raises(ValueError, match=None) as error:
        FilterSettings(**settings)
    message = str(error.value)
    assert words in message and "\n" not in message


def test_events_out_of_time_order_are_refused_and_change_nothing() -> None:
    stream = EventFilter(trail_ms=1)
    stream.apply(table(at_pixel([(10, ON)])))
    with pytest.raises(ValueError, match=r"t = 5 us comes after t = 20 us") as error:
        stream.apply(table(at_pixel([(20, ON), (5, ON)])))
    assert "\n" not in str(error.value)
    with pytest.raises(ValueError, match="t = 9 us comes after t = 10 us"):
        stream.apply(table(at_pixel([(9, ON)])))  # before the last event of an earlier batch
    # The refused batches left no trace: 1010 is 1000 us after 10, a new burst.
    assert stream.apply(table(at_pixel([(1010, ON)]))).column("t").to_pylist() == [1010]


def test_missing_columns_and_non_integer_columns_are_refused() -> None:
    with pytest.raises(ValueError, match="missing p"):
        pecs.filter_events(pa.table({"t": [0], "x": [0], "y": [0]}), trail_ms=1)
    with pytest.raises(ValueError, match="column t is double"):
        pecs.filter_events(pa.table({"t": [0.5], "x": [0], "y": [0], "p": [1]}), trail_ms=1)
    with pytest.raises(ValueError, match="column x holds values outside uint16"):
        pecs.filter_events(pa.table({"t": [0], "x": [-1], "y": [0], "p": [1]}), trail_ms=1)
    stream = EventFilter(trail_ms=1)
    stream.apply(pa.table({"t": [0], "x": [0], "y": [0], "p": [1]}))
    with pytest.raises(ValueError, match="column t has 1 missing values"):
        stream.apply(pa.table({"t": [5, None], "x": [0, 0], "y": [0, 0], "p": [1, 1]}))


# -- pecs filter ------------------------------------------------------------------------------


def test_pecs_filter_writes_what_the_api_gives_and_says_what_it_dropped(
    tmp_path: Path, capsys: pytest.CaptureFixture
) -> None:
    events = busy_stream()
    source = tmp_path / "in.parquet"
    pecs.write_events(events, source)
    out = tmp_path / "out.parquet"
    argv = ["filter", str(source), "-o", str(out), "--afk", "50-520", "--stc", "2"]
    argv += ["--stc-mode", "keep-trail", "--erc", "10000", "--batch-size", "100"]
    code, stdout, stderr = run_cli(capsys, *argv)
    assert code == 0, stderr
    expected = pecs.filter_events(events, **ALL_ON)
    written = pecs.read_events(out)
    for name in ("t", "x", "y", "p", "label"):
        assert written.column(name).to_pylist() == expected.column(name).to_pylist(), name
    counts = EventFilter(**ALL_ON)
    counts.apply(events.combine_chunks().to_batches()[0])
    counts.flush()
    dropped = counts.counts
    assert f"{expected.num_rows} of {events.num_rows} events kept" in stdout
    assert f"AFK {dropped['afk_dropped']}, STC {dropped['trail_dropped']}" in stdout
    assert f"ERC {dropped['erc_dropped']}" in stdout


@pytest.mark.parametrize(
    ("options", "words"),
    [
        (["--stc", "2.5"], "--stc: 2.5: expected a whole number of milliseconds, 1 to 100"),
        (["--trail", "0"], "--trail: 0: expected a whole number of milliseconds"),
        (["--stc", "101"], "--stc: 101: expected"),
        (["--afk", "130-90"], "--afk: 130-90: expected LO-HI in whole Hz with 50 <= LO < HI"),
        (["--afk", "40-100"], "--afk: 40-100: expected"),
        (["--afk", "100"], "--afk: 100: expected"),
        (["--erc", "0"], "--erc: 0: expected a number > 0"),
        (["--erc", "1000"], "--erc 1000: below one event per 200 us period"),
        (["--stc", "5", "--trail", "5"], "--stc and --trail"),
        (["--afk", "90-130", "--afk-thresholds", "3", "4"], "--afk-thresholds 3 4: STOP"),
        ([], "no filter asked for"),
    ],
)
def test_pecs_filter_refuses_bad_options_in_a_line_naming_them(
    tmp_path: Path, capsys: pytest.CaptureFixture, options: list[str], words: str
) -> None:
    source = tmp_path / "in.parquet"
    pecs.write_events(table(at_pixel([(0, ON)])), source)
    code, stdout, stderr = run_cli(
        capsys, "filter", str(source), "-o", str(tmp_path / "out.parquet"), *options
    )
    assert code == 2
    assert words in stderr
    assert "Traceback" not in stderr and not PYTHON_SYNTAX.search(stderr)
    assert not (tmp_path / "out.parquet").exists()


def test_pecs_filter_refuses_an_unsorted_file_in_one_line(
    tmp_path: Path, capsys: pytest.CaptureFixture
) -> None:
    source = tmp_path / "in.txt"
    source.write_text("0.000020 0 0 1\n0.000005 0 0 1\n")  # rpg text: t in seconds
    code, _, stderr = run_cli(
        capsys, "filter", str(source), "-o", str(tmp_path / "o.txt"), "--trail", "1"
    )
    assert code == 2
    assert stderr.strip().count("\n") == 0 and "comes after t = 20 us" in stderr


def test_a_simulation_filters_its_events_as_the_filters_do_on_its_file(tmp_path) -> None:
    # Inside a 3D simulation (Simulation(filters=...)) the chip's filters see the sensor's
    # batches as they come; the events must be those filter_events gives on the unfiltered
    # run's file, whole: the filters' state carried across the frames' batches.
    from pecs.filters import FilterSettings

    small = dict(duration_s=0.02, spp=1, rate_hz=1000, sensor={"width": 32, "height": 24})
    settings = FilterSettings(trail_ms=1, erc_rate_hz=2e6)
    pecs.Simulation("checkerboard", **small).run(tmp_path / "raw")
    pecs.Simulation("checkerboard", filters=settings, **small).run(tmp_path / "chip")
    raw = pecs.read_events(tmp_path / "raw" / "events.parquet")
    chip = pecs.read_events(tmp_path / "chip" / "events.parquet")
    expected = pecs.filter_events(raw, settings)
    assert 0 < chip.num_rows < raw.num_rows
    for name in "txyp":
        np.testing.assert_array_equal(chip[name].to_numpy(), expected[name].to_numpy())
    assert b"pecs.filters" in chip.schema.metadata
