"""Prophesee RAW (.raw): EVT3 times after long gaps, camera-style streams, files that are not
RAW, empty streams. Checked against the specification decoder of `evt_reference` (independent
of pecs), expelliarmus for EVT2, and the numbers written."""

from __future__ import annotations

import json

import evt_reference
import numpy as np
import pecs
import pecs.events
import pecs.io
import pecs.viz
import pyarrow as pa
import pytest
from pecs.cli import main

WIDTH, HEIGHT = 640, 480
GAPS_US = [(1 << 24) - 1, 1 << 24, 20_000_000, 100_000_000, 1 << 33]


def table(t, x, y, p, width: int = WIDTH, height: int = HEIGHT) -> pa.Table:
    columns = {"t": t, "x": x, "y": y, "p": p}
    batch = pecs.events.record_batch(columns, pecs.events.schema(width, height))
    return pa.Table.from_batches([batch])


def sparse_events(gap_us: int) -> pa.Table:
    """Three bursts of events (a full row, a few pixels) separated by `gap_us` of silence."""
    t, x, y, p = [], [], [], []
    for k, start in enumerate([1_234, 1_234 + gap_us, 1_234 + 2 * gap_us]):
        if k == 2 and gap_us > 1 << 32:
            break  # two bursts are enough past 2^33 µs (2 M TIME_HIGH words each)
        for offset in range(3):
            t += [start + offset] * 6
            x += [100, 101, 102, 103, 104, 639]
            y += [7 + offset] * 6
            p += [1, 1, 1, 1, 1, 0]
    return table(np.array(t), np.array(x), np.array(y), np.array(p))


def columns(source) -> dict[str, np.ndarray]:
    return {name: np.asarray(source[name], dtype=np.int64) for name in ("t", "x", "y", "p")}


def assert_same(expected: pa.Table, got) -> None:
    want = columns({n: expected.column(n).to_numpy() for n in "txyp"})
    have = columns({n: np.asarray(got[n]) for n in "txyp"})
    for name in "txyp":
        np.testing.assert_array_equal(have[name], want[name], err_msg=name)


def words_of(data: bytes) -> np.ndarray:
    start = 0
    while data.startswith(b"%", start):
        line_end = data.index(b"\n", start) + 1
        if data[start:line_end].strip() == b"% end":
            start = line_end
            break
        start = line_end
    return np.frombuffer(data, dtype="<u2", offset=start)


# --- item 1: times after long gaps -------------------------------------------------------------


@pytest.mark.parametrize("gap_us", GAPS_US)
def test_evt3_gaps_read_back_exactly_by_pecs_and_the_spec_decoder(tmp_path, gap_us):
    events = sparse_events(gap_us)
    path = pecs.write_events(events, tmp_path / "sparse.raw")
    back = pecs.read_events(path)
    assert_same(events, {n: back.column(n).to_numpy() for n in "txyp"})
    assert pecs.events.sensor_size(back.schema) == (WIDTH, HEIGHT)
    data = path.read_bytes()
    assert_same(events, evt_reference.decode(data))
    # What a camera writes: one TIME_HIGH word per 4096 µs step, from 0 to the last event.
    words = words_of(data)
    t_last = int(events.column("t")[-1].as_py())
    assert np.count_nonzero(words >> 12 == 0x8) == t_last // 4096 + 1


@pytest.mark.parametrize("gap_us", GAPS_US)
def test_evt2_gaps_read_back_exactly_by_pecs_and_expelliarmus(tmp_path, gap_us):
    from expelliarmus import Wizard

    events = sparse_events(gap_us)
    path = pecs.write_events(events, tmp_path / "sparse.raw", format="evt2")
    back = pecs.read_events(path)
    assert_same(events, {n: back.column(n).to_numpy() for n in "txyp"})
    assert_same(events, Wizard(encoding="evt2").read(path))


def camera_stream(rng: np.random.Generator) -> pa.Table:
    """9.7 s of camera-like activity (TIME_LOW wraps every 4096 µs), then a 20 s and a 40 s
    silence, with rows of neighbouring pixels at one time (vector words)."""
    t = np.sort(rng.integers(0, 9_700_000, 6_000))
    t = np.concatenate([t, 9_700_000 + 20_000_000 + np.sort(rng.integers(0, 50_000, 500))])
    t = np.concatenate([t, t[-1] + 40_000_000 + np.arange(100)])
    n = len(t)
    x, y, p = rng.integers(0, WIDTH, n), rng.integers(0, HEIGHT, n), rng.integers(0, 2, n)
    for start in range(0, n - 40, 500):  # rows: 11 and 5 neighbours sharing t, y, p
        run = 11 if start % 1000 else 5
        t[start : start + run] = t[start]
        x[start : start + run] = 200 + np.arange(run)
        y[start : start + run], p[start : start + run] = y[start], p[start]
    return table(t, x, y, p)


def test_camera_style_evt3_with_vectors_triggers_and_gaps_reads_back_exactly(tmp_path):
    events = camera_stream(np.random.default_rng(5))
    c = {n: events.column(n).to_numpy() for n in "txyp"}
    data = evt_reference.header(WIDTH, HEIGHT) + evt_reference.encode(
        c["t"], c["x"], c["y"], c["p"]
    )
    words = words_of(data)
    kinds = set((words >> 12).tolist())
    assert {0x3, 0x4, 0x5, 0xA, 0xE} <= kinds  # vectors, triggers and OTHERS are in there
    path = tmp_path / "camera.raw"
    path.write_bytes(data)
    back = pecs.read_events(path)
    assert_same(events, {n: back.column(n).to_numpy() for n in "txyp"})
    # The same events written by pecs read back the same, by pecs and by the spec decoder.
    ours = pecs.write_events(events, tmp_path / "ours.raw")
    written = words_of(ours.read_bytes()) >> 12
    assert {0x3, 0x4, 0x5} <= set(written.tolist())  # rows written as vector patterns
    assert_same(events, evt_reference.decode(ours.read_bytes()))
    again = pecs.read_events(ours)
    assert_same(events, {n: again.column(n).to_numpy() for n in "txyp"})


def test_streamed_batches_stay_within_batch_size(tmp_path):
    events = camera_stream(np.random.default_rng(6))
    path = pecs.write_events(events, tmp_path / "s.raw")
    batches = list(pecs.io.iter_events(path, batch_size=1_000))
    assert all(0 < b.num_rows <= 1_000 for b in batches)
    whole = pa.Table.from_batches(batches)
    assert_same(events, {n: whole.column(n).to_numpy() for n in "txyp"})


def test_writer_refuses_times_evt3_cannot_hold(tmp_path):
    target = tmp_path / "late.raw"
    events = table(np.array([0, 1 << 36]), np.array([1, 2]), np.array([1, 2]), np.array([1, 0]))
    with pytest.raises(ValueError, match=r"2\^36"):
        pecs.write_events(events, target)
    assert not target.exists()


def test_cli_reads_exact_times_after_a_20_s_gap(tmp_path, capsys):
    events = sparse_events(20_000_000)
    raw = pecs.write_events(events, tmp_path / "gap.raw")
    t = events.column("t").to_numpy()
    # info
    assert main(["info", str(raw), "--json"]) == 0
    info = json.loads(capsys.readouterr().out)
    assert (info["t_first_us"], info["t_last_us"]) == (int(t[0]), int(t[-1]))
    assert (info["width"], info["height"]) == (WIDTH, HEIGHT)
    # convert to Parquet and back to RAW
    parquet = tmp_path / "gap.parquet"
    assert main(["convert", str(raw), str(parquet)]) == 0
    converted = pecs.read_events(parquet)
    assert_same(events, {n: converted.column(n).to_numpy() for n in "txyp"})
    again = tmp_path / "again.raw"
    assert main(["convert", str(parquet), str(again)]) == 0
    capsys.readouterr()  # convert's report
    assert again.read_bytes() == raw.read_bytes()
    # compare the RAW file with the Parquet file: the same events, distances 0
    assert main(["compare", str(raw), str(parquet), "--json"]) == 0
    compared = json.loads(capsys.readouterr().out)
    assert compared["chamfer"] == 0.0
    # view: a frame starting at the last burst shows it
    png = tmp_path / "last.png"
    start_us = int(t[-1]) - 2
    start_ms = f"{start_us / 1000}"
    assert main(["view", str(raw), "-o", str(png), "--start-ms", start_ms, "--absolute-times"]) == 0
    from PIL import Image

    with Image.open(png) as opened:
        image = np.asarray(opened.convert("RGB"))
    expected = pecs.viz.event_frame(events, t_start_us=start_us, t_end_us=start_us + 33_300)
    np.testing.assert_array_equal(image, expected)
    assert image.min() < 255  # the burst is drawn


# --- item 8: files that are not Prophesee RAW --------------------------------------------------


def test_random_bytes_are_not_a_raw_file(tmp_path):
    path = tmp_path / "random.raw"
    path.write_bytes(np.random.default_rng(0).integers(0, 256, 100_000, dtype=np.uint8).tobytes())
    with pytest.raises(pecs.io.EventFileError, match=r"random\.raw.*not a Prophesee RAW file"):
        pecs.read_events(path)


def test_aedat4_renamed_raw_is_refused(tmp_path):
    events = sparse_events(1_000)
    aedat = pecs.write_events(events, tmp_path / "e.aedat4")
    renamed = tmp_path / "e.raw"
    renamed.write_bytes(aedat.read_bytes())
    with pytest.raises(pecs.io.EventFileError, match="not a Prophesee RAW file"):
        pecs.read_events(renamed)


@pytest.mark.parametrize(
    "header, message",
    [
        (b"% date 2024-01-01\n% end\n", "names no encoding"),
        (b"% evt 4.0\n% end\n", r"unsupported RAW encoding '% evt 4.0'"),
        (b"% format EVT4;width=4;height=4\n", "unsupported RAW encoding"),
    ],
)
def test_header_must_name_an_encoding_pecs_reads(tmp_path, header, message):
    path = tmp_path / "h.raw"
    path.write_bytes(header + bytes(64))
    with pytest.raises(pecs.io.EventFileError, match=message):
        pecs.read_events(path)


def test_random_words_after_a_valid_header_are_reported_not_decoded(tmp_path):
    noise = np.random.default_rng(1).integers(0, 256, 100_000, dtype=np.uint8).tobytes()
    path = tmp_path / "noise.raw"
    path.write_bytes(evt_reference.header(WIDTH, HEIGHT) + noise)
    with pytest.raises(pecs.io.EventFileError, match=r"offset \d+: corrupt EVT3 data"):
        pecs.read_events(path)


def test_data_right_after_end_line_may_start_with_a_percent_byte(tmp_path):
    # TIME_HIGH 0x025 is the bytes 0x25 0x80: '%' then not a newline. `% end` ends the header.
    t0 = 0x025 << 12
    t, x, y, p = np.array([t0, t0 + 5]), np.array([1, 2]), np.array([3, 4]), np.array([1, 0])
    data = evt_reference.header(WIDTH, HEIGHT) + evt_reference.encode(t, x, y, p)
    assert data[len(evt_reference.header(WIDTH, HEIGHT))] == ord("%")
    path = tmp_path / "percent.raw"
    path.write_bytes(data)
    assert_same(table(t, x, y, p), pecs.read_events(path).to_pydict())


# --- item 10: empty streams keep their size ----------------------------------------------------


@pytest.mark.parametrize("fmt", ["evt3", "evt2"])
def test_empty_stream_keeps_its_sensor_size(tmp_path, fmt):
    empty = table(np.array([], np.int64), np.array([]), np.array([]), np.array([]), 346, 260)
    path = tmp_path / "empty.raw"
    pecs.write_events(empty, path, width=346, height=260, format=fmt)
    back = pecs.read_events(path)
    assert back.num_rows == 0
    assert pecs.events.sensor_size(back.schema) == (346, 260)
