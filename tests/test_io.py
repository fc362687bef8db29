"""pecs.io: every format round-trips 1e6 events, checked by readers that are not pecs's own."""

from __future__ import annotations

import os
import subprocess
import sys
import textwrap
import zipfile

import evt_reference
import h5py
import numpy as np
import pecs
import pecs.events
import pecs.io
import pyarrow as pa
import pyarrow.parquet as pq
import pytest

WIDTH, HEIGHT = 640, 480
N_EVENTS = 1_000_000


@pytest.fixture(scope="module")
def events() -> pa.Table:
    """1e6 events with the edge cases: x = W - 1 and y = H - 1, bursts sharing one timestamp,
    both polarities, and a span of 40 s, past the 2^24 µs (16.8 s) EVT3 time wrap, twice."""
    rng = np.random.default_rng(7)
    t = np.sort(rng.integers(1_000, 40_000_000, N_EVENTS))
    t[5_000:5_400] = t[5_000]  # a burst: 400 events at one time
    t[N_EVENTS // 2 : N_EVENTS // 2 + 1000] = t[N_EVENTS // 2]
    t.sort()
    x = rng.integers(0, WIDTH, N_EVENTS)
    y = rng.integers(0, HEIGHT, N_EVENTS)
    x[::1000], y[1::1000] = WIDTH - 1, HEIGHT - 1
    x[-1], y[-1] = WIDTH - 1, HEIGHT - 1
    p = rng.integers(0, 2, N_EVENTS)
    columns = {"t": t, "x": x, "y": y, "p": p}
    table = pa.Table.from_batches(
        [pecs.events.record_batch(columns, pecs.events.schema(WIDTH, HEIGHT))]
    )
    assert table.column("t").to_numpy()[-1] > 2 * (1 << 24)
    return table


def columns_of(table: pa.Table) -> dict[str, np.ndarray]:
    return {name: table.column(name).to_numpy() for name in ("t", "x", "y", "p")}


def assert_same_events(expected: pa.Table, t, x, y, p) -> None:
    want = columns_of(expected)
    np.testing.assert_array_equal(np.asarray(t, dtype=np.int64), want["t"])
    np.testing.assert_array_equal(np.asarray(x, dtype=np.int64), want["x"])
    np.testing.assert_array_equal(np.asarray(y, dtype=np.int64), want["y"])
    np.testing.assert_array_equal((np.asarray(p) > 0).astype(np.int64), want["p"])


def assert_pecs_reads_back(expected: pa.Table, path) -> None:
    back = pecs.read_events(path)
    assert_same_events(expected, *(back.column(n).to_numpy() for n in ("t", "x", "y", "p")))


# --- round trips, each read by an independent library ------------------------------------------


def test_parquet_keeps_events_and_metadata(events, tmp_path):
    tagged = events.replace_schema_metadata(
        {**events.schema.metadata, b"pecs.sensor": b'{"preset": "davis346"}'}
    )
    path = pecs.write_events(tagged, tmp_path / "e.parquet")
    table = pq.read_table(path)
    assert_same_events(events, *(table.column(n).to_numpy() for n in ("t", "x", "y", "p")))
    assert table.schema.metadata[b"width"] == b"640"
    assert table.schema.metadata[b"pecs.sensor"] == b'{"preset": "davis346"}'
    assert table.schema.field("t").type == pa.int64()
    assert pecs.events.sensor_config_json(pecs.read_events(path).schema) == {"preset": "davis346"}


def test_hdf5_dsec_layout_read_by_h5py(events, tmp_path):
    path = pecs.write_events(events, tmp_path / "e.h5")
    t = columns_of(events)["t"]
    with h5py.File(path, "r") as file:
        t_offset = int(file["t_offset"][()])
        stored_t = file["events/t"][:]
        assert_same_events(
            events,
            stored_t + t_offset,
            file["events/x"][:],
            file["events/y"][:],
            file["events/p"][:],
        )
        assert file["events/x"].dtype == np.uint16 and file["events/p"].dtype == np.uint8
        # ms_to_idx[k] is the first event at or after k ms (relative): brute force from t.
        ms_to_idx = file["ms_to_idx"][:]
        relative = t - t_offset
        expected = np.searchsorted(relative, np.arange(len(ms_to_idx)) * 1000, side="left")
        np.testing.assert_array_equal(ms_to_idx, expected)
        assert len(ms_to_idx) == relative[-1] // 1000 + 1
    assert_pecs_reads_back(events, path)


def test_hdf5_v2e_layout_read_by_h5py(events, tmp_path):
    path = pecs.write_events(events, tmp_path / "e.h5", format="v2e")
    with h5py.File(path, "r") as file:
        rows = file["events"][:]
    assert rows.dtype == np.uint32 and rows.shape == (N_EVENTS, 4)
    assert_same_events(events, rows[:, 0], rows[:, 1], rows[:, 2], rows[:, 3])
    assert_pecs_reads_back(events, path)


def test_aedat4_read_by_dv_processing_and_faery(events, tmp_path):
    import faery

    path = pecs.write_events(events, tmp_path / "e.aedat4")
    back = np.concatenate(list(faery.events_stream_from_file(path)))
    assert_same_events(events, back["t"], back["x"], back["y"], back["on"])
    dv = pytest.importorskip("dv_processing")
    recording = dv.io.MonoCameraRecording(str(path))
    assert recording.getEventResolution() == (WIDTH, HEIGHT)
    parts = []
    while (batch := recording.getNextEventBatch()) is not None:
        parts.append(batch.numpy())
    read = np.concatenate(parts)
    assert_same_events(events, read["timestamp"], read["x"], read["y"], read["polarity"])
    assert_pecs_reads_back(events, path)


def test_evt3_read_by_specification_decoder_and_faery(events, tmp_path):
    import faery

    path = pecs.write_events(events, tmp_path / "e.raw")
    data = path.read_bytes()
    assert data.startswith(b"% evt 3.0")
    decoded = evt_reference.decode(data)
    assert_same_events(events, decoded["t"], decoded["x"], decoded["y"], decoded["p"])
    back = np.concatenate(list(faery.events_stream_from_file(path)))
    assert_same_events(events, back["t"], back["x"], back["y"], back["on"])
    assert_pecs_reads_back(events, path)


@pytest.mark.parametrize("fmt, suffix", [("evt2", ".raw"), ("dat", ".dat")])
def test_evt2_and_dat_read_by_expelliarmus(events, tmp_path, fmt, suffix):
    from expelliarmus import Wizard

    path = pecs.write_events(events, tmp_path / f"e{suffix}", format=fmt)
    read = Wizard(encoding=fmt).read(path)
    assert_same_events(events, read["t"], read["x"], read["y"], read["p"])
    assert_pecs_reads_back(events, path)


def test_npz_is_tonic_structured_array_read_by_numpy(events, tmp_path):
    path = pecs.write_events(events, tmp_path / "e.npz")
    with np.load(path) as archive:
        array = archive["events"]
        size = archive["sensor_size"]
    assert array.dtype == np.dtype([("x", "<i2"), ("y", "<i2"), ("t", "<i8"), ("p", "?")])
    assert size.tolist() == [WIDTH, HEIGHT, 2]
    assert_same_events(events, array["t"], array["x"], array["y"], array["p"])
    assert_pecs_reads_back(events, path)


def test_text_is_rpg_seconds_read_by_numpy(events, tmp_path):
    path = pecs.write_events(events, tmp_path / "e.txt")
    header, first_line = path.read_text().split("\n", 2)[:2]
    assert header == f"# width {WIDTH} height {HEIGHT}"
    first = first_line.split()
    t0 = int(columns_of(events)["t"][0])
    assert first[0] == f"{t0 // 1_000_000}.{t0 % 1_000_000:06d}"
    rows = np.loadtxt(path)
    assert_same_events(events, np.rint(rows[:, 0] * 1e6), rows[:, 1], rows[:, 2], rows[:, 3])
    assert_pecs_reads_back(events, path)


# --- recordings written by other tools ---------------------------------------------------------


def small_events(n=5_000, seed=3, width=WIDTH, height=HEIGHT):
    rng = np.random.default_rng(seed)
    t = np.sort(rng.integers(0, 2 * (1 << 24) + 5_000, n))
    return t, rng.integers(0, width, n), rng.integers(0, height, n), rng.integers(0, 2, n)


def test_reads_camera_style_evt3_with_vectors_triggers_and_time_wrap(tmp_path):
    t, x, y, p = small_events()
    # Runs of neighbouring pixels at one time, as sensors emit them (vector words).
    t = np.concatenate([t, np.full(11, t[100]), np.full(5, t[200])])
    x = np.concatenate([x, 100 + np.arange(11), 300 + np.arange(5)])
    y = np.concatenate([y, np.full(11, 7), np.full(5, 9)])
    p = np.concatenate([p, np.ones(11, int), np.zeros(5, int)])
    order = np.argsort(t, kind="stable")
    t, x, y, p = t[order], x[order], y[order], p[order]
    data = evt_reference.header(WIDTH, HEIGHT) + evt_reference.encode(t, x, y, p)
    path = tmp_path / "camera.raw"
    path.write_bytes(data)
    assert b"\x00\x40" in data or any(w >> 12 == 4 for w in np.frombuffer(data[60:], "<u2"))
    table = pecs.read_events(path)
    expected = pecs.events.record_batch({"t": t, "x": x, "y": y, "p": p}, pecs.events.schema())
    assert_same_events(
        pa.Table.from_batches([expected]), *(table.column(n).to_numpy() for n in "txyp")
    )
    assert pecs.events.sensor_size(table.schema) == (WIDTH, HEIGHT)


@pytest.mark.parametrize("fmt, suffix", [("evt2", ".raw"), ("dat", ".dat")])
def test_reads_expelliarmus_written_files(tmp_path, fmt, suffix):
    from expelliarmus import Wizard

    t, x, y, p = small_events()
    array = np.zeros(len(t), dtype=[("t", "<i8"), ("x", "<i2"), ("y", "<i2"), ("p", "u1")])
    array["t"], array["x"], array["y"], array["p"] = t, x, y, p
    path = tmp_path / f"other{suffix}"
    Wizard(encoding=fmt).save(path, array)
    table = pecs.read_events(path, format=fmt if fmt == "dat" else None)
    want = pa.table({"t": t, "x": x, "y": y, "p": p})
    assert_same_events(want, *(table.column(n).to_numpy() for n in "txyp"))


def test_reads_dv_processing_written_aedat4(tmp_path):
    dv = pytest.importorskip("dv_processing")
    t, x, y, p = small_events(2_000)
    path = tmp_path / "dv.aedat4"
    writer = dv.io.MonoCameraWriter(
        str(path), dv.io.MonoCameraWriter.EventOnlyConfig("pecs-test", (WIDTH, HEIGHT))
    )
    store = dv.EventStore()
    for row in zip(t.tolist(), x.tolist(), y.tolist(), p.tolist(), strict=True):
        store.push_back(row[0], row[1], row[2], bool(row[3]))
    writer.writeEvents(store)
    del writer  # closes the file
    table = pecs.read_events(path)
    assert_same_events(
        pa.table({"t": t, "x": x, "y": y, "p": p}), *(table.column(n) for n in "txyp")
    )
    assert pecs.events.sensor_size(table.schema) == (WIDTH, HEIGHT)


def test_reads_dsec_blosc_file_written_with_h5py(tmp_path):
    hdf5plugin = pytest.importorskip("hdf5plugin")
    t, x, y, p = small_events()
    t_offset = 123_456_789
    path = tmp_path / "dsec.h5"
    with h5py.File(path, "w") as file:
        blosc = hdf5plugin.Blosc(cname="zstd", clevel=5)
        file.create_dataset("events/t", data=t.astype(np.uint32), **blosc)
        file.create_dataset("events/x", data=x.astype(np.uint16), **blosc)
        file.create_dataset("events/y", data=y.astype(np.uint16), **blosc)
        file.create_dataset("events/p", data=p.astype(np.uint8), **blosc)
        file.create_dataset("t_offset", data=np.int64(t_offset))
    table = pecs.read_events(path)
    want = pa.table({"t": t + t_offset, "x": x, "y": y, "p": p})
    assert_same_events(want, *(table.column(n).to_numpy() for n in "txyp"))


def test_reads_rpg_vid2e_npz_and_ecd_text(tmp_path):
    t, x, y, p = small_events()
    # rpg_vid2e (esim_torch): int64 t in ns, p as -1/1; read as the nearest µs.
    t_ns = t * 1000 + np.where(np.arange(len(t)) % 2, 499, -500)
    np.savez(tmp_path / "vid2e.npz", x=x, y=y, t=t_ns, p=np.where(p > 0, 1, -1))
    table = pecs.read_events(tmp_path / "vid2e.npz")
    want = pa.table({"t": t, "x": x, "y": y, "p": p})
    assert_same_events(want, *(table.column(n).to_numpy() for n in "txyp"))
    # ECD: seconds with 9 decimals (ns), rounded to the nearest µs on reading.
    lines = [
        f"{ti / 1e6 + 4e-9:.9f} {xi} {yi} {pi}" for ti, xi, yi, pi in zip(t, x, y, p, strict=True)
    ]
    (tmp_path / "ecd.txt").write_text(f"{WIDTH} {HEIGHT}\n" + "\n".join(lines) + "\n")
    table = pecs.read_events(tmp_path / "ecd.txt")
    assert_same_events(want, *(table.column(n).to_numpy() for n in "txyp"))
    assert pecs.events.sensor_size(table.schema) == (WIDTH, HEIGHT)


# --- streaming ---------------------------------------------------------------------------------


@pytest.mark.parametrize("suffix", [".parquet", ".h5", ".raw", ".npz"])
def test_streamed_writer_and_reader_match_whole_table(events, tmp_path, suffix):
    head = events.slice(0, 200_000)
    path = tmp_path / f"s{suffix}"
    with pecs.io.EventWriter(path, width=WIDTH, height=HEIGHT) as writer:
        for batch in head.to_batches(max_chunksize=7_777):
            writer.write(batch)
    batches = list(pecs.io.iter_events(path, batch_size=50_000))
    assert all(batch.num_rows <= 50_000 for batch in batches)
    assert sum(batch.num_rows for batch in batches) == head.num_rows
    whole = pa.Table.from_batches(batches)
    assert_same_events(head, *(whole.column(n).to_numpy() for n in "txyp"))


@pytest.mark.parametrize("suffix", [".parquet", ".h5", ".raw"])
def test_writing_5e7_events_streams_under_1_gib(tmp_path, suffix):
    """A child process streams 5e7 events (50 batches of 1e6) to a file; its peak RSS is the
    measure. Python + numpy + pyarrow + one batch of columns is ~200 MiB; a writer that held the
    recording would need 5e7 * 13 bytes = 650 MiB more."""
    script = textwrap.dedent(
        f"""
        import numpy as np, pecs.events, pecs.io
        n, batches = 1_000_000, 50
        schema = pecs.events.schema({WIDTH}, {HEIGHT})
        rng = np.random.default_rng(0)
        with pecs.io.EventWriter(r"{tmp_path / ("big" + suffix)}") as writer:
            for k in range(batches):
                t = k * 1_000_000 + np.sort(rng.integers(0, 1_000_000, n))
                columns = {{"t": t, "x": rng.integers(0, {WIDTH}, n, dtype=np.uint16),
                           "y": rng.integers(0, {HEIGHT}, n, dtype=np.uint16),
                           "p": rng.integers(0, 2, n, dtype=np.int8)}}
                writer.write(pecs.events.record_batch(columns, schema))
        """
    )
    measure = textwrap.dedent(
        f"""
        import resource, subprocess, sys
        subprocess.run([sys.executable, "-c", {script!r}], check=True)
        print(resource.getrusage(resource.RUSAGE_CHILDREN).ru_maxrss)
        """
    )
    done = subprocess.run([sys.executable, "-c", measure], capture_output=True, text=True)
    assert done.returncode == 0, done.stderr
    peak_mib = int(done.stdout.split()[-1]) / 1024  # ru_maxrss is KiB on Linux
    assert peak_mib < 1024, f"peak RSS {peak_mib:.0f} MiB"
    if suffix == ".parquet":
        assert pq.ParquetFile(tmp_path / "big.parquet").metadata.num_rows == 50_000_000
    elif suffix == ".h5":
        with h5py.File(tmp_path / "big.h5", "r") as file:
            assert file["events/t"].shape == (50_000_000,)
    else:  # EVT3: at least one TIME_LOW + ADDR_Y + ADDR_X word per distinct event
        assert (tmp_path / "big.raw").stat().st_size > 50_000_000 * 2


# --- errors ------------------------------------------------------------------------------------


def small_table() -> pa.Table:
    t, x, y, p = small_events(4_000)
    batch = pecs.events.record_batch(
        {"t": t, "x": x, "y": y, "p": p}, pecs.events.schema(WIDTH, HEIGHT)
    )
    return pa.Table.from_batches([batch])


def header_end(data: bytes) -> int:
    offset = 0
    while data.startswith(b"%", offset):
        offset = data.index(b"\n", offset) + 1
    return offset


@pytest.mark.parametrize(
    "suffix, fmt, word",
    [(".raw", None, 2), (".raw", "evt2", 4), (".dat", None, 8)],
)
def test_truncated_word_stream_names_file_and_offset(tmp_path, suffix, fmt, word):
    path = pecs.write_events(small_table(), tmp_path / f"cut{suffix}", format=fmt)
    data = path.read_bytes()
    start = header_end(data) + (2 if suffix == ".dat" else 0)
    cut = start + word * 1000 + 1  # one byte into a word
    path.write_bytes(data[:cut])
    with pytest.raises(pecs.io.EventFileError, match=rf"cut{suffix}.*offset {cut - 1}\b"):
        pecs.read_events(path)


def test_corrupt_evt3_word_names_offset(tmp_path):
    path = pecs.write_events(small_table(), tmp_path / "bad.raw")
    data = bytearray(path.read_bytes())
    start = header_end(bytes(data))
    words = np.frombuffer(bytes(data[start:]), "<u2")
    k = int(np.flatnonzero(words >> 12 == 0)[500])  # an ADDR_Y word
    data[start + 2 * k : start + 2 * k + 2] = np.uint16(0x0000 | 2000).tobytes()  # y = 2000 >= H
    path.write_bytes(bytes(data))
    with pytest.raises(pecs.io.EventFileError, match=rf"bad\.raw at byte offset {start + 2 * k}:"):
        pecs.read_events(path)


def test_corrupt_dat_event_names_offset(tmp_path):
    path = pecs.write_events(small_table(), tmp_path / "bad.dat")
    data = bytearray(path.read_bytes())
    start = header_end(bytes(data)) + 2
    offset = start + 8 * 1234
    data[offset + 4 : offset + 8] = np.uint32(0x3FFF).tobytes()  # x = 16383 >= W
    path.write_bytes(bytes(data))
    with pytest.raises(pecs.io.EventFileError, match=rf"bad\.dat at byte offset {offset}:"):
        pecs.read_events(path)


def test_truncated_aedat4_names_packet_offset(tmp_path):
    table = small_table()
    path = tmp_path / "cut.aedat4"
    with pecs.io.EventWriter(path) as writer:
        for batch in table.to_batches(max_chunksize=1000):
            writer.write(batch)
    data = path.read_bytes()
    # Packet headers follow the IOHeader: walk them to know where the third one starts.
    offset = 14 + 4 + int.from_bytes(data[14:18], "little")
    for _ in range(2):
        offset += 8 + int.from_bytes(data[offset + 4 : offset + 8], "little")
    path.write_bytes(data[: offset + 20])
    with pytest.raises(pecs.io.EventFileError, match=rf"cut\.aedat4 at byte offset {offset}:"):
        pecs.read_events(path)


@pytest.mark.parametrize("declared, problem", [(0, "corrupt"), (1000, "truncated")])
def test_aedat4_with_a_bad_header_length_is_an_event_file_error(tmp_path, declared, problem):
    # faery panics on an empty header; a length past the end of file cannot be read either.
    path = tmp_path / "bad.aedat4"
    path.write_bytes(b"#!AER-DAT4.0\r\n" + declared.to_bytes(4, "little") + b"\0" * 40)
    with pytest.raises(pecs.io.EventFileError, match=rf"bad\.aedat4 at byte offset 14: {problem}"):
        pecs.read_events(path)


@pytest.mark.parametrize("suffix", [".parquet", ".h5", ".npz"])
def test_truncated_container_names_file_and_offset(tmp_path, suffix):
    path = pecs.write_events(small_table(), tmp_path / f"cut{suffix}")
    data = path.read_bytes()
    path.write_bytes(data[: len(data) // 2])
    with pytest.raises(pecs.io.EventFileError, match=rf"cut\{suffix} at byte offset \d+:"):
        pecs.read_events(path)


def test_bad_text_line_names_line_and_offset(tmp_path):
    path = tmp_path / "bad.txt"
    path.write_text("0.000001 1 2 1\n0.000002 3 4 0\n0.000003 five 6 1\n")
    with pytest.raises(pecs.io.EventFileError, match=r"bad\.txt at byte offset 30: line 3"):
        pecs.read_events(path)


def test_unknown_suffix_lists_supported_formats(tmp_path):
    (tmp_path / "e.bag").write_bytes(b"rosbag")
    for call in (
        lambda: pecs.read_events(tmp_path / "e.bag"),
        lambda: pecs.write_events(small_table(), tmp_path / "out.bag"),
    ):
        with pytest.raises(ValueError, match=r"'\.bag'") as error:
            call()
        for name in ("parquet", ".h5", "v2e", ".aedat4", ".raw", "evt2", ".dat", ".npz", ".txt"):
            assert name in str(error.value)
    assert not (tmp_path / "out.bag").exists()
    with pytest.raises(FileNotFoundError, match="missing.raw"):
        pecs.read_events(tmp_path / "missing.raw")


@pytest.mark.parametrize("suffix", [".parquet", ".h5", ".aedat4", ".raw", ".dat", ".npz", ".txt"])
def test_failed_write_leaves_nothing_half_written(tmp_path, suffix):
    table = small_table()
    target = tmp_path / f"out{suffix}"
    target.write_bytes(b"previous contents")
    with pytest.raises(ValueError, match="t order"):
        with pecs.io.EventWriter(target, width=WIDTH, height=HEIGHT) as writer:
            writer.write(table.slice(2_000))
            writer.write(table.slice(0, 2_000))  # goes back in time
    assert target.read_bytes() == b"previous contents"
    assert sorted(os.listdir(tmp_path)) == [target.name]


def test_writer_rejects_bad_events_with_named_field(tmp_path):
    t, x, y, p = small_events(10)
    with pytest.raises(ValueError, match="x = 700 outside the sensor"):
        pecs.write_events(
            pa.table({"t": t, "x": np.full(10, 700), "y": y, "p": p}),
            tmp_path / "e.raw",
            width=WIDTH,
            height=HEIGHT,
        )
    with pytest.raises(ValueError, match="polarity p must be 1"):
        pecs.write_events(pa.table({"t": t, "x": x, "y": y, "p": p + 4}), tmp_path / "e.parquet")
    with pytest.raises(ValueError, match="sorted by t: event 3"):
        pecs.write_events(
            pa.table({"t": t[[0, 1, 2, 0]], "x": x[:4], "y": y[:4], "p": p[:4]}), tmp_path / "e.h5"
        )
    with pytest.raises(ValueError, match="header; pass width= and height="):
        with pecs.io.EventWriter(tmp_path / "e.aedat4") as writer:
            writer.write(pa.table({"t": t, "x": x, "y": y, "p": p}))
    assert sorted(os.listdir(tmp_path)) == []


# --- tonic -------------------------------------------------------------------------------------


def test_to_tonic_runs_tonic_to_frame(events):
    tonic_transforms = pytest.importorskip("tonic.transforms")
    head = events.slice(0, 100_000)
    array, size = pecs.events.to_tonic(head)
    assert size == (WIDTH, HEIGHT, 2)
    assert array.dtype.names == ("x", "y", "t", "p") and array.dtype["p"] == np.bool_
    frames = tonic_transforms.ToFrame(sensor_size=size, event_count=25_000)(array)
    assert frames.shape == (4, 2, HEIGHT, WIDTH)
    # Frame k counts events [25000 k, 25000 (k + 1)) per polarity and pixel: brute force.
    cols = columns_of(head)
    for k in range(4):
        part = slice(25_000 * k, 25_000 * (k + 1))
        counts = np.zeros((2, HEIGHT, WIDTH), dtype=np.int64)
        np.add.at(counts, (cols["p"][part], cols["y"][part], cols["x"][part]), 1)
        np.testing.assert_array_equal(frames[k], counts)


def test_npz_member_is_a_zip_entry_tonic_loads(events, tmp_path):
    path = pecs.write_events(events.slice(0, 1000), tmp_path / "e.npz")
    with zipfile.ZipFile(path) as archive:
        assert sorted(archive.namelist()) == ["events.npy", "sensor_size.npy"]
    array, size = pecs.events.to_tonic(pecs.read_events(path))
    np.testing.assert_array_equal(array, np.load(path)["events"])
    assert size == tuple(np.load(path)["sensor_size"])


# --- command line ------------------------------------------------------------------------------


def run_command(*argv: str) -> None:
    """Run one pecs subcommand through its own parser (independent of the other commands)."""
    import argparse
    import importlib

    parser = argparse.ArgumentParser(prog="pecs")
    subparsers = parser.add_subparsers(dest="command", required=True)
    importlib.import_module(f"pecs.cli.{argv[0]}").register(subparsers)
    args = parser.parse_args(list(argv))
    assert args.func(args) == 0


def test_cli_convert_streams_between_formats(events, tmp_path):
    head = events.slice(0, 100_000)
    text = pecs.write_events(head, tmp_path / "in.txt")  # text carries no sensor size
    run_command("convert", str(text), str(tmp_path / "out.raw"), "--format", "evt2")
    data = (tmp_path / "out.raw").read_bytes()
    assert b"evt 2.0" in data[:200]
    cols = columns_of(head)
    size = (int(cols["x"].max()) + 1, int(cols["y"].max()) + 1)  # found by the first pass
    assert pecs.events.sensor_size(pecs.read_events(tmp_path / "out.raw").schema) == size
    from expelliarmus import Wizard

    read = Wizard(encoding="evt2").read(tmp_path / "out.raw")
    assert_same_events(head, read["t"], read["x"], read["y"], read["p"])


def test_cli_info_statistics(tmp_path, capsys):
    # 3 pixels of a 4 x 2 sensor over 2 s: pixel (0, 0) fires 6 times, (3, 1) 3 times, (1, 0) once.
    t = [
        0,
        100_000,
        200_000,
        400_000,
        800_000,
        1_000_000,
        1_200_000,
        1_500_000,
        1_900_000,
        2_000_000,
    ]
    x = [0, 0, 3, 0, 3, 0, 1, 0, 3, 0]
    y = [0, 0, 1, 0, 1, 0, 0, 0, 1, 0]
    p = [1, 0, 1, 1, 1, 0, 1, 1, 0, 1]
    batch = pecs.events.record_batch({"t": t, "x": x, "y": y, "p": p}, pecs.events.schema(4, 2))
    path = pecs.write_events(batch, tmp_path / "e.parquet")
    from pecs.cli.info import summarise

    info = summarise(path)
    assert info["events"] == 10 and info["duration_s"] == 2.0
    assert (info["width"], info["height"], info["resolution_from"]) == (4, 2, "file")
    assert info["event_rate_per_s"] == 5.0
    assert (info["on_events"], info["off_events"]) == (7, 3)
    rates = np.array([6, 1, 0, 0, 0, 0, 0, 3]) / 2.0  # per pixel, Hz, zeros included
    for q, value in info["pixel_rate_percentiles_hz"].items():
        assert value == pytest.approx(np.percentile(rates, float(q[1:])))
    assert info["pixel_rate_max_hz"] == 3.0 and info["active_pixels"] == 3
    run_command("info", str(path))
    out = capsys.readouterr().out
    assert "events:      10" in out and "4 x 2" in out and "ON fraction 0.700" in out


def test_label_column_kept_by_parquet_only(tmp_path):
    t, x, y, p = small_events(100)
    labels = np.arange(100) % 4
    schema = pecs.events.schema(WIDTH, HEIGHT, labels=True)
    batch = pecs.events.record_batch({"t": t, "x": x, "y": y, "p": p, "label": labels}, schema)
    parquet = pq.read_table(pecs.write_events(batch, tmp_path / "l.parquet"))
    np.testing.assert_array_equal(parquet.column("label").to_numpy(), labels)
    assert parquet.schema.field("label").type == pa.uint8()
    h5 = pecs.read_events(pecs.write_events(batch, tmp_path / "l.h5"))
    assert h5.column_names == ["t", "x", "y", "p"]
    assert_same_events(pa.table({"t": t, "x": x, "y": y, "p": p}), *(h5.column(n) for n in "txyp"))


def test_dsec_widens_t_past_uint32(tmp_path):
    t = np.array([0, 10, 2**32 - 1, 2**32 + 5, 2**33], dtype=np.int64) + 1_000
    x, y, p = np.arange(5), np.arange(5), np.array([1, 0, 1, 0, 1])
    path = tmp_path / "long.h5"
    with pecs.io.EventWriter(path, width=8, height=8) as writer:
        writer.write(pa.table({"t": t[:3], "x": x[:3], "y": y[:3], "p": p[:3]}))
        writer.write(pa.table({"t": t[3:], "x": x[3:], "y": y[3:], "p": p[3:]}))
    with h5py.File(path, "r") as file:
        assert file["events/t"].dtype == np.int64
        np.testing.assert_array_equal(file["events/t"][:] + file["t_offset"][()], t)
        assert len(file["ms_to_idx"]) == 2**33 // 1000 + 1


def test_iter_events_slices_an_oversized_batch_lazily(tmp_path, monkeypatch):
    """A reader's batch larger than batch_size is handed out slice by slice: taking the first
    few slices of a 1 M-event batch must not build all million slices first (about 1 GB)."""
    import itertools
    import tracemalloc
    import types

    import pecs.io as io_module

    n = 1_000_000
    big = pa.RecordBatch.from_pydict(
        {
            "t": np.arange(n, dtype=np.int64),
            "x": np.zeros(n, np.uint16),
            "y": np.zeros(n, np.uint16),
            "p": np.ones(n, np.int8),
        }
    )
    path = tmp_path / "e.parquet"
    io_module.write_events(big.slice(0, 10), path, width=4, height=4)
    one_big_batch = types.SimpleNamespace(read=lambda file, batch_size: iter([big]))
    monkeypatch.setattr(io_module, "format_for", lambda file, name: one_big_batch)
    tracemalloc.start()
    first = list(itertools.islice(io_module.iter_events(path, batch_size=1), 5))
    peak = tracemalloc.get_traced_memory()[1]
    tracemalloc.stop()
    assert [b.column("t")[0].as_py() for b in first] == [0, 1, 2, 3, 4]
    assert peak < 20 * 2**20, f"{peak / 2**20:.0f} MiB traced to hand out 5 slices"


def test_to_table_reads_paths_in_io_and_only_there(tmp_path, events):
    # pecs.events knows nothing of files (no import of pecs.io: no import cycle); pecs.io's
    # to_table takes what pecs.events.to_table takes and paths.
    path = tmp_path / "e.parquet"
    pecs.write_events(events, path)
    assert pecs.io.to_table(path).equals(pecs.read_events(path))
    assert pecs.io.to_table(events).equals(pecs.events.to_table(events))
    with pytest.raises(TypeError, match="read_events"):
        pecs.events.to_table(str(path))
