"""pecs.io on the inputs and outputs a user meets at the edges (issue 12, items 5, 7, 9, 10, 11):
a full disk, malformed text, Blosc without hdf5plugin, empty streams, values past a format's
limits. Expected values come from the formats' specifications, not from pecs's own output."""

from __future__ import annotations

import contextlib
import errno
import json
import os
import subprocess
import sys
import textwrap
from collections.abc import Iterator
from pathlib import Path

import h5py
import numpy as np
import pecs
import pecs.events
import pecs.io
import pyarrow as pa
import pytest

# Every writable format: (format name, suffix).
WRITABLE = [
    ("parquet", ".parquet"),
    ("hdf5", ".h5"),
    ("v2e", ".h5"),
    ("aedat4", ".aedat4"),
    ("evt3", ".raw"),
    ("evt2", ".raw"),
    ("dat", ".dat"),
    ("npz", ".npz"),
    ("text", ".txt"),
]


def table_of(t, x, y, p, width: int | None = None, height: int | None = None) -> pa.Table:
    columns = {
        "t": np.asarray(t, np.int64),
        "x": np.asarray(x, np.uint16),
        "y": np.asarray(y, np.uint16),
        "p": np.asarray(p, np.int8),
    }
    schema = pecs.events.schema(width, height)
    return pa.Table.from_batches([pecs.events.record_batch(columns, schema)])


# --- item 5: a full disk -----------------------------------------------------------------------


@contextlib.contextmanager
def small_tmpfs(folder: Path) -> Iterator[bool]:
    """A 128 KiB tmpfs at `folder` (True), or False where mounting is not permitted."""
    folder.mkdir()
    mounted = (
        subprocess.run(
            ["mount", "-t", "tmpfs", "-o", "size=128k", "tmpfs", str(folder)],
            capture_output=True,
        ).returncode
        == 0
    )
    try:
        yield mounted
    finally:
        if mounted:
            subprocess.run(["umount", str(folder)], check=True)


# The child writes 100 000 events (well over 128 KiB in every format) with the API and with
# `pecs convert`, one format after the other, and prints one JSON line per attempt. It runs in
# its own process so that a crash inside a native library fails the test instead of pytest.
FULL_DISK_CHILD = textwrap.dedent(
    """
    import contextlib, io, json, os, resource, signal, sys
    import numpy as np, pecs, pecs.events, pecs.io
    from pecs.cli import main

    source, out, limit, formats = sys.argv[1], sys.argv[2], int(sys.argv[3]), sys.argv[4:]
    if limit:  # no tmpfs: the file size limit fails writes with EFBIG instead of ENOSPC
        signal.signal(signal.SIGXFSZ, signal.SIG_IGN)
        resource.setrlimit(resource.RLIMIT_FSIZE, (limit, limit))
    for item in formats:
        name, suffix = item.split(":")
        target = os.path.join(out, "api_" + name + suffix)
        try:
            pecs.io.write_events(source, target, format=name, width=640, height=480)
            report = {"how": "api", "format": name, "error": None}
        except OSError as error:
            report = {"how": "api", "format": name, "error": error.errno,
                      "filename": error.filename, "message": str(error)}
        except Exception as error:
            report = {"how": "api", "format": name, "error": repr(error)}
        report["left"] = sorted(os.listdir(out))
        print(json.dumps(report), flush=True)
        target = os.path.join(out, "cli_" + name + suffix)
        stderr = io.StringIO()
        with contextlib.redirect_stderr(stderr), contextlib.redirect_stdout(io.StringIO()):
            code = main(["convert", source, target, "--format", name])
        print(json.dumps({"how": "cli", "format": name, "code": code,
                          "stderr": stderr.getvalue(), "left": sorted(os.listdir(out))}),
              flush=True)
    """
)


@pytest.fixture(scope="module")
def full_disk_reports(tmp_path_factory: pytest.TempPathFactory) -> dict[tuple[str, str], dict]:
    root = tmp_path_factory.mktemp("full")
    rng = np.random.default_rng(5)
    n = 100_000
    source = root / "source.parquet"
    pecs.write_events(
        table_of(
            np.sort(rng.integers(0, 10_000_000, n)),
            rng.integers(0, 640, n),
            rng.integers(0, 480, n),
            rng.integers(0, 2, n),
            640,
            480,
        ),
        source,
    )
    with small_tmpfs(root / "disk") as mounted:
        limit = 0 if mounted else 128 * 1024
        formats = [f"{name}:{suffix}" for name, suffix in WRITABLE]
        done = subprocess.run(
            [sys.executable, "-c", FULL_DISK_CHILD, str(source), str(root / "disk"), str(limit)]
            + formats,
            capture_output=True,
            text=True,
            timeout=120,
        )
    assert done.returncode == 0, f"child crashed ({done.returncode}): {done.stderr[-2000:]}"
    reports = [json.loads(line) for line in done.stdout.splitlines()]
    return {(report["how"], report["format"]): report for report in reports} | {
        ("errno", ""): {"expected": errno.ENOSPC if mounted else errno.EFBIG}
    }


@pytest.mark.parametrize("name, suffix", WRITABLE)
def test_full_disk_api_raises_oserror_naming_target_and_leaves_nothing(
    full_disk_reports, name, suffix
):
    report = full_disk_reports[("api", name)]
    expected = full_disk_reports[("errno", "")]["expected"]
    assert report["error"] == expected, report
    assert Path(report["filename"]).name == f"api_{name}{suffix}"
    assert report["left"] == [], report


@pytest.mark.parametrize("name, suffix", WRITABLE)
def test_full_disk_cli_convert_one_line_exit_1_nothing_left(full_disk_reports, name, suffix):
    report = full_disk_reports[("cli", name)]
    expected = full_disk_reports[("errno", "")]["expected"]
    lines = report["stderr"].splitlines()
    assert report["code"] == 1, report
    assert len(lines) == 1, report
    assert lines[0].startswith("pecs convert: error: ")
    assert lines[0].endswith(f"cli_{name}{suffix}: {os.strerror(expected)}")
    assert report["left"] == [], report


# --- item 7: malformed text ----------------------------------------------------------------------


GOOD_LINES = "0.000001 1 2 1\n0.000002 3 4 0\n"


@pytest.mark.parametrize(
    "bad_line, problem",
    [
        ("0.000003 5", "2 fields, not 4"),  # cut mid-line (was an IndexError)
        ("0.000003", "1 fields, not 4"),
        ("0.000003 5 6 1 7", "5 fields, not 4"),
        ("0.000003 5  6 1", "5 fields, not 4"),
        ("abc 5 6 1", "t 'abc' is not a number"),
        ("-0.5 5 6 1", "t '-0.5' is not a time >= 0 s"),
        ("nan 5 6 1", "t 'nan' is not a time >= 0 s"),
        ("0.000003 -5 6 1", "x '-5' is not an integer in 0..65535"),
        ("0.000003 5 -6 1", "y '-6' is not an integer in 0..65535"),
        ("0.000003 5.5 6 1", "x '5.5' is not an integer in 0..65535"),
        ("0.000003 70000 6 1", "x '70000' is not an integer in 0..65535"),
        ("0.000003 5 6 2", "p '2' is not 1, 0 or -1"),
        ("0.000003 5 6 on", "p 'on' is not a number"),
    ],
)
def test_malformed_text_line_is_event_file_error_naming_line(tmp_path, bad_line, problem):
    path = tmp_path / "bad.txt"
    path.write_text(GOOD_LINES + bad_line)
    offset = len(GOOD_LINES)  # the bad line starts after the two good ones
    with pytest.raises(pecs.io.EventFileError) as caught:
        pecs.read_events(path)
    assert str(caught.value).startswith(f"{path} at byte offset {offset}: line 3: {problem}")


def test_text_with_minus_one_polarity_and_trailing_newline_reads(tmp_path):
    path = tmp_path / "ok.txt"
    path.write_text("0.5 1 2 -1\n1.25 3 4 1\n\n")
    table = pecs.read_events(path)
    assert table.column("t").to_pylist() == [500_000, 1_250_000]
    assert table.column("p").to_pylist() == [0, 1]


def test_text_time_survives_float64_below_its_limit():
    """The writer's limit (2^31 s) is where t in decimal seconds, read as float64, still gives
    every µs back: brute force over the top of the range and its neighbourhood."""
    from pecs.io.text import MAX_T_US

    rng = np.random.default_rng(0)
    t_us = np.concatenate(
        [rng.integers(MAX_T_US // 2, MAX_T_US, 500_000), MAX_T_US - 1 - np.arange(1000)]
    )
    text = [f"{t // 1_000_000}.{t % 1_000_000:06d}" for t in t_us.tolist()]
    back = np.rint(np.array(text, dtype=np.float64) * 1e6).astype(np.int64)
    np.testing.assert_array_equal(back, t_us)


# --- item 9: portable HDF5 ---------------------------------------------------------------------


WITHOUT_HDF5PLUGIN = textwrap.dedent(
    """
    import sys
    sys.modules["hdf5plugin"] = None  # importing it now raises ImportError
    import h5py, pecs
    path = sys.argv[1]
    try:
        table = pecs.read_events(path)
        print("read", table.num_rows, table.column("t")[-1].as_py())
    except Exception as error:
        print(type(error).__name__, error)
    """
)


def read_without_hdf5plugin(path: Path) -> str:
    done = subprocess.run(
        [sys.executable, "-c", WITHOUT_HDF5PLUGIN, str(path)],
        capture_output=True,
        text=True,
        timeout=60,
    )
    assert done.returncode == 0, done.stderr
    return done.stdout.strip()


def dataset_filters(path: Path) -> set[int]:
    with h5py.File(path, "r") as file:
        plist = file["events/t"].id.get_create_plist()
        return {plist.get_filter(i)[0] for i in range(plist.get_nfilters())}


def test_hdf5_default_is_gzip_and_reads_without_hdf5plugin(tmp_path):
    path = pecs.write_events(
        table_of([1, 5, 2_000], [0, 1, 2], [0, 0, 1], [1, 0, 1]), tmp_path / "e.h5"
    )
    assert h5py.h5z.FILTER_DEFLATE in dataset_filters(path)
    assert 32001 not in dataset_filters(path)  # Blosc's registered HDF5 filter id
    assert read_without_hdf5plugin(path) == "read 3 2000"


def test_hdf5_blosc_on_request_and_named_when_plugin_missing(tmp_path):
    path = pecs.write_events(
        table_of([1, 5, 2_000], [0, 1, 2], [0, 0, 1], [1, 0, 1]),
        tmp_path / "e.h5",
        compression="blosc",
    )
    assert 32001 in dataset_filters(path)
    assert pecs.read_events(path).num_rows == 3  # hdf5plugin is importable here
    message = read_without_hdf5plugin(path)
    assert message.startswith("EventFileError")
    assert "compressed with Blosc" in message and "install hdf5plugin" in message


@pytest.mark.parametrize("compression", ["lzf", "none", "gzip"])
def test_hdf5_other_compressions_round_trip(tmp_path, compression):
    table = table_of([1, 5, 2_000], [0, 1, 2], [0, 0, 1], [1, 0, 1], 4, 2)
    path = pecs.write_events(table, tmp_path / "e.h5", compression=compression)
    assert pecs.read_events(path).column("t").to_pylist() == [1, 5, 2_000]


def test_compression_refused_where_the_format_has_none(tmp_path):
    with pytest.raises(ValueError, match="parquet offers no compression 'blosc'"):
        pecs.write_events(table_of([1], [0], [0], [1]), tmp_path / "e.parquet", compression="blosc")
    with pytest.raises(ValueError, match="offers no compression 'zip'"):
        pecs.write_events(table_of([1], [0], [0], [1]), tmp_path / "e.h5", compression="zip")


# --- item 10: empty streams keep their size ------------------------------------------------------


@pytest.mark.parametrize("name, suffix", [w for w in WRITABLE if w[0] not in ("evt3", "evt2")])
def test_empty_stream_round_trips_with_its_size(tmp_path, name, suffix):
    path = tmp_path / f"empty{suffix}"
    pecs.io.write_events(pecs.events.schema(346, 260).empty_table(), path, format=name)
    table = pecs.io.read_events(path, format=name)
    assert table.num_rows == 0
    assert pecs.events.sensor_size(table.schema) == (346, 260)


def test_empty_text_without_size_reads_as_no_events(tmp_path):
    (tmp_path / "empty.txt").write_bytes(b"")
    table = pecs.read_events(tmp_path / "empty.txt")
    assert table.num_rows == 0 and pecs.events.sensor_size(table.schema) is None


def test_cli_info_and_convert_of_an_empty_stream(tmp_path, capsys):
    from pecs.cli import main

    source = tmp_path / "empty.parquet"
    pecs.write_events(pecs.events.schema(346, 260).empty_table(), source)
    assert main(["info", str(source)]) == 0
    assert "346 x 260" in capsys.readouterr().out
    assert main(["convert", str(source), str(tmp_path / "empty.aedat4")]) == 0
    assert main(["info", str(tmp_path / "empty.aedat4")]) == 0
    out = capsys.readouterr().out
    assert "346 x 260" in out and "events:      0" in out


# --- item 11: what a format cannot hold ----------------------------------------------------------


@pytest.mark.parametrize(
    "name, suffix, events, size, message",
    [
        # DSEC indexes every ms of the span: t = 2^40 µs would need 1.1e9 entries (8.8 GB).
        ("hdf5", ".h5", ([0, 1 << 40], [0, 1], [0, 1], [1, 0]), (4, 4), "limit of 86400000000"),
        (
            "v2e",
            ".h5",
            ([0, 1 << 32], [0, 1], [0, 1], [1, 0]),
            (4, 4),
            r"uint32 µs \(0 to 4294967295\)",
        ),
        ("aedat4", ".aedat4", ([0, 1], [40000, 1], [0, 1], [1, 0]), None, "up to 32767"),
        ("aedat4", ".aedat4", ([0, 1], [0, 1], [0, 1], [1, 0]), (40000, 4), "up to 32767"),
        ("npz", ".npz", ([0, 1], [0, 1], [32768, 1], [1, 0]), None, "up to 32767"),
        ("dat", ".dat", ([0, 1], [16384, 1], [0, 1], [1, 0]), None, "up to 16383"),
        ("dat", ".dat", ([0, 1 << 32], [0, 1], [0, 1], [1, 0]), (4, 4), "uint32 µs"),
        ("text", ".txt", ([0, (1 << 31) * 10**6], [0, 1], [0, 1], [1, 0]), (4, 4), "2\\^31 s"),
        ("text", ".txt", ([-1, 1], [0, 1], [0, 1], [1, 0]), (4, 4), "0 <= t"),
    ],
)
def test_values_past_a_format_limit_are_refused_naming_it(
    tmp_path, name, suffix, events, size, message
):
    target = tmp_path / f"out{suffix}"
    width, height = size or (None, None)
    with pytest.raises(ValueError, match=message):
        pecs.io.write_events(table_of(*events), target, format=name, width=width, height=height)
    assert os.listdir(tmp_path) == []


def test_dsec_ms_to_idx_over_a_long_gap_matches_brute_force(tmp_path):
    # Two hours of silence between two bursts: ms_to_idx has 7.2 M entries, built in pieces.
    t = np.array([0, 10, 999, 1_000, 1_001, 7_200_000_000, 7_200_000_500, 7_200_002_000])
    path = pecs.io.write_events(
        table_of(t + 123, [0] * 8, [0] * 8, [1] * 8, 2, 2), tmp_path / "gap.h5"
    )
    with h5py.File(path, "r") as file:
        ms_to_idx = file["ms_to_idx"][:]
        assert int(file["t_offset"][()]) == 123
        assert file["events/t"].dtype == np.int64  # past 2^32 µs
    assert len(ms_to_idx) == 7_200_002 + 1
    # DSEC: ms_to_idx[k] is the index of the first event with t >= 1000 k.
    for k in [0, 1, 2, 3, 5_000, 7_199_999, 7_200_000, 7_200_001, 7_200_002]:
        assert ms_to_idx[k] == next(i for i, ti in enumerate(t) if ti >= 1000 * k), k
    assert pecs.read_events(path).column("t").to_pylist() == (t + 123).tolist()


def test_cli_convert_writes_blosc_hdf5_on_request(tmp_path):
    from pecs.cli import main

    source = pecs.write_events(
        table_of([1, 5], [0, 1], [0, 1], [1, 0], 2, 2), tmp_path / "a.parquet"
    )
    assert main(["convert", str(source), str(tmp_path / "b.h5"), "--compression", "blosc"]) == 0
    assert 32001 in dataset_filters(tmp_path / "b.h5")
    assert main(["convert", str(source), str(tmp_path / "c.h5")]) == 0
    assert 32001 not in dataset_filters(tmp_path / "c.h5")


def test_parquet_from_another_tool_reads_with_the_pecs_types(tmp_path):
    """int32 x, y, t and p as -1/1 (a fuzz finding: p came back int32) read as the pecs schema."""
    import pyarrow.parquet as pq

    columns = {"t": [5, 9], "x": [1, 300], "y": [2, 7], "p": [-1, 1]}
    pq.write_table(
        pa.table({k: pa.array(v, pa.int32()) for k, v in columns.items()}), tmp_path / "o.parquet"
    )
    table = pecs.read_events(tmp_path / "o.parquet")
    assert table.schema.types == [pa.int64(), pa.uint16(), pa.uint16(), pa.int8()]
    assert table.to_pydict() == {"t": [5, 9], "x": [1, 300], "y": [2, 7], "p": [0, 1]}
