"""The readout after the pixels (arbiter, bus, drops, timestamp step, rate controller) on whole
streams, against the same sensor without it and against rates worked out by hand."""

from __future__ import annotations

import json
import re
import subprocess
import sys

import numpy as np
import pecs
import pyarrow as pa
import pytest
from pecs import SensorConfig

#: Every readout stage off.
NO_READOUT = {
    "readout_row_service_ns": 0.0,
    "readout_bus_rate_meps": 0.0,
    "readout_overflow": "queue",
    "readout_queue_depth": 0,
    "timestamp_step_us": 0,
    "erc_rate_hz": 0.0,
}
SIDE = 32
FRAME_US = 1000
FRAMES = 11


def ramp_frames(side: int = SIDE, frames: int = FRAMES) -> tuple[list[np.ndarray], np.ndarray]:
    """Every pixel's light rising by e^2 a millisecond: 10 ON events a ms a pixel at theta 0.2,
    staggered by the thresholds' mismatch, so 32 x 32 pixels make about 10 M events/s."""
    rng = np.random.default_rng(3)
    base = rng.uniform(0.5, 1.0, (side, side))
    times = np.arange(frames, dtype=np.int64) * FRAME_US
    return [(base * np.exp(2.0 * k)).astype(np.float32) for k in range(frames)], times


def ramp_config(**readout: object) -> SensorConfig:
    return SensorConfig.preset(
        "ideal", width=SIDE, height=SIDE, theta_sigma=0.05, dark_current=1e-6, **readout
    )


def run(config: SensorConfig) -> tuple[pa.Table, dict[str, int] | None]:
    frames, times = ramp_frames(config.width, FRAMES)
    table = pecs.frames_to_events(frames, times, config)
    raw = (table.schema.metadata or {}).get(b"pecs.readout")
    return table, None if raw is None else json.loads(raw)


@pytest.fixture(scope="module")
def pixels_alone() -> pa.Table:
    """The ramp's events with no readout: what the pixels made."""
    table, counts = run(ramp_config())
    assert counts is None
    return table


def input_rate_meps(table: pa.Table) -> float:
    """Events per us over the ramp (the first frame only initialises)."""
    return table.num_rows / ((FRAMES - 1) * FRAME_US)


def rate_in(table: pa.Table, start_us: int, stop_us: int) -> float:
    t = table["t"].to_numpy()
    return np.count_nonzero((t >= start_us) & (t < stop_us)) / (stop_us - start_us)


# ---------------------------------------------------------------- below the limit


def gentle_frames(width: int, height: int) -> tuple[list[np.ndarray], np.ndarray]:
    """A soft bright bar drifting 2 px a frame over a dark field, 1 ms frames."""
    x = np.arange(width)
    frames = []
    for k in range(12):
        row = 0.05 + 0.9 * np.exp(-(((x - 5 - 2 * k) / 3.0) ** 2))
        frames.append(np.tile(row, (height, 1)).astype(np.float32))
    return frames, np.arange(12, dtype=np.int64) * 1000


@pytest.mark.parametrize("preset", ["davis346", "imx636"])
def test_below_the_limit_the_events_are_those_of_the_sensor_without_readout(preset: str) -> None:
    frames, times = gentle_frames(64, 48)
    config = SensorConfig.preset(preset, width=64, height=48, readout_delays=True)
    with_readout = pecs.frames_to_events(frames, times, config)
    without = pecs.frames_to_events(
        frames, times, config.replace(**NO_READOUT, readout_delays=False)
    )
    counts = json.loads(with_readout.schema.metadata[b"pecs.readout"])
    assert without.num_rows > 500
    assert counts["events_in"] == counts["events_out"] == without.num_rows
    assert counts["delayed"] == counts["dropped"] == counts["erc_dropped"] == 0
    assert np.all(with_readout["delay_us"].to_numpy() == 0)
    assert with_readout.drop_columns(["delay_us"]).to_pydict() == without.to_pydict()


# ---------------------------------------------------------------- above the limit


def test_at_three_times_the_bus_rate_the_output_holds_the_rate_and_no_event_is_lost(
    pixels_alone: pa.Table,
) -> None:
    rate_meps = input_rate_meps(pixels_alone) / 3
    table, counts = run(ramp_config(readout_bus_rate_meps=rate_meps, readout_delays=True))
    # The bus is busy from the first event to the last: n events take n / R.
    assert counts["events_in"] == counts["events_out"] == pixels_alone.num_rows
    assert counts["dropped"] == counts["held"] == 0
    end_us = FRAME_US + pixels_alone.num_rows / rate_meps
    assert rate_in(table, 2 * FRAME_US, int(end_us) - FRAME_US) == pytest.approx(rate_meps, 0.02)
    # A bus alone is a FIFO: each event out is the pixels' event at the same place, stamped
    # `delay_us` later.
    made = pixels_alone.to_pydict()
    out = table.to_pydict()
    assert out["x"] == made["x"] and out["y"] == made["y"] and out["p"] == made["p"]
    delay = np.array(out["delay_us"])
    assert np.array_equal(np.array(out["t"]) - delay, np.array(made["t"]))
    assert delay.min() >= 0 and counts["delay_max_us"] == delay.max() > 10 * FRAME_US
    assert counts["delayed"] == np.count_nonzero(delay)
    assert counts["delay_total_us"] == delay.sum()


def test_with_drop_on_a_full_queue_every_event_is_out_or_counted_as_dropped(
    pixels_alone: pa.Table,
) -> None:
    rate_meps = input_rate_meps(pixels_alone) / 3
    config = ramp_config(
        readout_bus_rate_meps=rate_meps,
        readout_overflow="drop",
        readout_queue_depth=64,
        readout_delays=True,
    )
    table, counts = run(config)
    assert counts["events_in"] == pixels_alone.num_rows
    assert counts["events_out"] == table.num_rows
    assert counts["events_out"] + counts["dropped"] == counts["events_in"]
    # The queue never empties while the pixels make 3x what the bus takes: about 2/3 dropped.
    assert counts["dropped"] / counts["events_in"] == pytest.approx(2 / 3, abs=0.02)
    assert rate_in(table, 2 * FRAME_US, 10 * FRAME_US) == pytest.approx(rate_meps, 0.02)
    # What is out is a subsequence of what the pixels made, each event at its made time.
    made = list(zip(*(pixels_alone[c].to_pylist() for c in "txyp"), strict=True))
    out = table.to_pydict()
    made_out = zip(
        np.array(out["t"]) - np.array(out["delay_us"]), out["x"], out["y"], out["p"], strict=True
    )
    position = iter(made)
    assert all(event in position for event in made_out)
    # No event waits behind more than the queue: 64 events at 1 / R each.
    assert max(out["delay_us"]) <= 65 / rate_meps + 1


def test_a_row_arbiter_under_load_sends_each_row_in_bursts(pixels_alone: pa.Table) -> None:
    # 1 us a grant and no time per event: 32 rows that always wait are granted in turn, one
    # cycle every 32 us, and each grant carries what its row made in a cycle: 1/32 of the
    # pixels' rate x 32 us. The arbiter then keeps up with the pixels, by bursts.
    table, counts = run(ramp_config(readout_row_service_ns=1000.0, readout_delays=True))
    assert counts["events_out"] == counts["events_in"] == pixels_alone.num_rows
    y, t, x = (table[name].to_numpy() for name in "ytx")
    # A burst leaves at once: a run of one row and one timestamp; bursts 1 us (a grant) apart.
    starts = np.flatnonzero(np.r_[True, (y[1:] != y[:-1]) | (t[1:] != t[:-1])])
    sizes = np.diff(np.r_[starts, len(y)])
    steady = (t[starts] > 2 * FRAME_US) & (t[starts] < 9 * FRAME_US)
    expected = input_rate_meps(pixels_alone) / SIDE * SIDE * 1.0
    assert sizes[steady].mean() == pytest.approx(expected, rel=0.1)
    assert np.all(np.diff(t[starts][steady]) == 1)
    # In a burst, the row's events in the order they were made.
    made_t = t - table["delay_us"].to_numpy()
    for start, size in zip(starts, sizes, strict=True):
        burst = slice(start, start + size)
        order = np.lexsort((x[burst], made_t[burst]))
        assert np.array_equal(order, np.arange(size))


# ---------------------------------------------------------------- timestamps, rate controller


def test_timestamps_floor_to_the_step(pixels_alone: pa.Table) -> None:
    table, counts = run(ramp_config(timestamp_step_us=100))
    made = pixels_alone.to_pydict()
    out = table.to_pydict()
    assert out["x"] == made["x"] and out["y"] == made["y"]
    assert np.array_equal(np.array(out["t"]), np.array(made["t"]) // 100 * 100)
    stamps = np.array(out["t"])
    assert counts["same_timestamp"] == np.count_nonzero(stamps[1:] == stamps[:-1])


def test_the_sensors_rate_controller_passes_what_the_filter_passes(pixels_alone: pa.Table) -> None:
    rate_hz = 2e6  # 400 events per 200 us period, against about 2,000 made
    table, counts = run(ramp_config(erc_rate_hz=rate_hz))
    expected = pecs.filters.erc(pixels_alone, rate_hz)
    assert (
        table.select(["t", "x", "y", "p"]).to_pydict()
        == expected.select(["t", "x", "y", "p"]).to_pydict()
    )
    assert counts["erc_dropped"] == pixels_alone.num_rows - table.num_rows > 0
    per_period = np.bincount(table["t"].to_numpy() // 200)
    assert per_period.max() == 400


# ---------------------------------------------------------------- determinism, presets, errors

_RUN = """
import hashlib, numpy as np, pecs
rng = np.random.default_rng(1)
base = rng.uniform(0.05, 1, (96, 128))
frames = [(base * np.exp(rng.normal(0, 0.5, base.shape))).astype(np.float32) for _ in range(8)]
cfg = pecs.SensorConfig.preset("imx636", width=128, height=96, erc_rate_hz=5e6,
                               readout_row_service_ns=200.0, readout_delays=True)
t = pecs.frames_to_events(frames, np.arange(8) * 1000, cfg)
h = hashlib.sha256()
for name in t.column_names:
    h.update(np.ascontiguousarray(t[name].to_numpy()).tobytes())
print(t.num_rows, t.schema.metadata[b"pecs.readout"].decode().replace(" ", ""), h.hexdigest())
"""


def test_the_same_events_on_one_and_two_threads() -> None:
    outputs = []
    for threads in (1, 2):
        env = {"RAYON_NUM_THREADS": str(threads), "PATH": "/usr/bin:/bin"}
        done = subprocess.run(
            [sys.executable, "-c", _RUN], env=env, capture_output=True, text=True, check=False
        )
        assert done.returncode == 0, done.stderr
        outputs.append(done.stdout.split())
    assert outputs[0] == outputs[1]
    counts = json.loads(outputs[0][1])
    assert counts["delayed"] > 0 and counts["erc_dropped"] > 0  # the readout was at work


def test_ideal_and_esim_have_no_readout_and_real_sensors_their_cited_one() -> None:
    for name in ("ideal", "esim"):
        config = SensorConfig.preset(name)
        assert all(getattr(config, key) == value for key, value in NO_READOUT.items())
        assert pecs.EventSensor(config).readout_counts is None
    davis = SensorConfig.preset("davis346")
    assert (davis.readout_bus_rate_meps, davis.readout_overflow) == (12.0, "drop")
    dvx = SensorConfig.preset("dvxplorer")
    assert (dvx.readout_bus_rate_meps, dvx.timestamp_step_us) == (165.0, 100)
    imx = SensorConfig.preset("imx636")
    assert (imx.erc_rate_hz, imx.readout_bus_rate_meps, imx.timestamp_step_us) == (50e6, 1066.0, 0)
    assert pecs.EventSensor(imx).readout_counts["events_in"] == 0


def test_the_delay_column_is_zero_without_a_readout() -> None:
    frames, times = gentle_frames(16, 8)
    table = pecs.frames_to_events(frames, times, ramp_config().replace(width=16, height=8))
    with_column = pecs.frames_to_events(
        frames, times, ramp_config(readout_delays=True).replace(width=16, height=8)
    )
    assert "delay_us" not in table.column_names
    assert with_column.num_rows == table.num_rows > 0
    assert not with_column["delay_us"].to_numpy().any()


@pytest.mark.parametrize(
    ("fields", "named"),
    [
        ({"readout_overflow": "drop"}, "readout_overflow"),
        ({"readout_bus_rate_meps": 12.0, "readout_overflow": "drop"}, "readout_queue_depth"),
        ({"readout_bus_rate_meps": 12.0, "readout_queue_depth": 10}, "readout_queue_depth"),
        ({"readout_overflow": "block"}, "readout_overflow"),
        ({"readout_bus_rate_meps": -1.0}, "readout_bus_rate_meps"),
        ({"readout_row_service_ns": 1e9}, "readout_row_service_ns"),
        ({"timestamp_step_us": 2.5}, "timestamp_step_us"),
        ({"readout_queue_depth": -1}, "readout_queue_depth"),
        ({"erc_rate_hz": 100.0}, "erc_rate_hz"),
    ],
)
def test_readout_settings_that_cannot_work_are_refused_naming_the_field(
    fields: dict[str, object], named: str
) -> None:
    with pytest.raises(ValueError, match=f"^{named}: ") as error:
        SensorConfig(**fields)
    assert "\n" not in str(error.value)


def test_a_sensor_file_keeps_its_readout(tmp_path: pytest.TempPathFactory) -> None:
    path = tmp_path / "sensor.toml"
    config = SensorConfig.preset("davis346", readout_queue_depth=100, timestamp_step_us=10)
    config.to_file(path)
    assert SensorConfig.from_file(path) == config


def test_frames2events_reports_what_the_readout_dropped_and_delayed(
    tmp_path: pytest.TempPathFactory, capsys: pytest.CaptureFixture
) -> None:
    from cli_run import run_cli

    # 160 x 120 pixels brightening: 6 ON events each, some close enough to wait for the bus.
    ramp = np.linspace(0.2, 0.8, 4, dtype=np.float32)[:, None, None]
    frames = tmp_path / "frames.npy"
    np.save(frames, np.broadcast_to(ramp, (4, 120, 160)).copy())
    out = tmp_path / "events.parquet"
    code, stdout, err = run_cli(
        capsys, "frames2events", str(frames), "--fps", "100", "-o", str(out), "--preset", "davis346"
    )
    assert code == 0, err
    line = stdout.splitlines()[-1]
    pattern = r"(\d+) (?:events made|dropped|by the rate|delayed)"
    made, dropped, erc_dropped, delayed = (int(n) for n in re.findall(pattern, line))
    written = int(stdout.split()[0])
    assert line.startswith("readout: ") and delayed > 0
    assert made > 100_000 and written == made - dropped - erc_dropped
