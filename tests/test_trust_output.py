"""Where event output goes, and what a user reads when it cannot go there (Trust, round two:
items 1, 13a-d, 14). Special targets (FIFOs, /dev/null, symlinks, stdout) are made in tmp_path
or checked to survive: no test may replace a real /dev entry, even if the fix regresses, so
every rename onto /dev or /proc fails the test instead of happening. Expected values are worked
out by hand from the formats' specifications (text: `t x y p` lines, t in seconds with six
decimals), not taken from pecs's own output."""

from __future__ import annotations

import contextlib
import os
import pty
import stat
import struct
import subprocess
import sys
import textwrap
import threading
import time
from collections.abc import Iterator
from pathlib import Path

import numpy as np
import pecs.events
import pecs.io
import pyarrow as pa
import pytest
from cli_run import PYTHON_SYNTAX, run_cli

EXCERPT = Path(__file__).parent / "data" / "davis346_excerpt" / "davis346_road_3frames.aedat4"
# DV's clock in the excerpt: absolute Unix µs (2020), far past every clocked format's range.
UNIX_T0_US = 1_600_000_000_000_000

# Three events on a 4 x 4 sensor, and the text file the rpg/ECD format makes of them.
T_US, X, Y, P = [0, 1_500_000, 2_000_001], [0, 3, 1], [0, 2, 3], [1, 0, 1]
TEXT = "# width 4 height 4\n0.000000 0 0 1\n1.500000 3 2 0\n2.000001 1 3 1\n"


def events(t_us: list[int] | np.ndarray = T_US, width: int = 4, height: int = 4) -> pa.Table:
    n = len(t_us)
    columns = {
        "t": np.asarray(t_us, np.int64),
        "x": np.asarray((X * n)[:n], np.uint16),
        "y": np.asarray((Y * n)[:n], np.uint16),
        "p": np.asarray((P * n)[:n], np.int8),
    }
    return pa.Table.from_batches(
        [pecs.events.record_batch(columns, pecs.events.schema(width, height))]
    )


def assert_same_events(table: pa.Table, t_us: list[int]) -> None:
    assert table.column("t").to_pylist() == list(t_us)
    n = len(t_us)
    assert table.column("x").to_pylist() == (X * n)[:n]
    assert table.column("y").to_pylist() == (Y * n)[:n]
    assert table.column("p").to_pylist() == (P * n)[:n]


@pytest.fixture
def no_dev_renames(monkeypatch: pytest.MonkeyPatch) -> None:
    """Make a rename onto /dev or /proc an assertion failure, not a replaced system file."""
    for name in ("replace", "rename"):
        real = getattr(os, name)

        def guarded(src: object, dst: object, *args: object, _real=real, **kwargs: object) -> None:
            if os.path.abspath(os.fsdecode(dst)).startswith(("/dev/", "/proc/")):  # type: ignore[arg-type]
                raise AssertionError(f"would replace {dst}")
            _real(src, dst, *args, **kwargs)

        monkeypatch.setattr(os, name, guarded)


# `pecs ARGV` in a child process with the same guard, its stdout wherever the test points it.
GUARDED_CLI = textwrap.dedent(
    """
    import os, sys
    def guard(real):
        def guarded(src, dst, *args, **kwargs):
            if os.path.abspath(os.fsdecode(dst)).startswith(("/dev/", "/proc/")):
                raise AssertionError(f"would replace {dst}")
            return real(src, dst, *args, **kwargs)
        return guarded
    os.replace, os.rename = guard(os.replace), guard(os.rename)
    from pecs.cli import main
    sys.exit(main(sys.argv[1:]))
    """
)


def cli_child(
    folder: Path, *argv: str, stdout: object = subprocess.PIPE
) -> subprocess.CompletedProcess:
    """Run in `folder`: a regression that writes a file named `-` leaves it there."""
    return subprocess.run(
        [sys.executable, "-c", GUARDED_CLI, *argv],
        stdout=stdout,
        stderr=subprocess.PIPE,
        cwd=folder,
        timeout=60,
    )


@contextlib.contextmanager
def fifo_reader(fifo: Path) -> Iterator[list[bytes]]:
    """Read everything written to `fifo` (made here) by the end of the block. The read end is
    open before the block starts, so a writer never waits for a reader, and a FIFO that nobody
    opens for writing reads as empty instead of hanging the test."""
    os.mkfifo(fifo)
    descriptor = os.open(fifo, os.O_RDONLY | os.O_NONBLOCK)
    got: list[bytes] = []
    finished = threading.Event()

    def read() -> None:
        chunks, seen_writer = [], False
        with open(descriptor, "rb", buffering=0) as stream:
            while True:
                chunk = stream.read(1 << 16)
                if chunk:
                    chunks.append(chunk)
                    seen_writer = True
                elif chunk is None:  # a writer holds it open, nothing to read yet
                    seen_writer = True
                    time.sleep(0.002)
                elif seen_writer or finished.is_set():  # end of file: the writer is done
                    break
                else:  # no writer yet
                    time.sleep(0.002)
        got.append(b"".join(chunks))

    thread = threading.Thread(target=read, daemon=True)
    thread.start()
    try:
        yield got
    finally:
        finished.set()
        thread.join(10)
    assert not thread.is_alive()


# --- item 1: special output paths ---------------------------------------------------------------


def test_fifo_target_gets_the_text_streamed_and_stays_a_fifo(tmp_path: Path) -> None:
    fifo = tmp_path / "events.txt"
    with fifo_reader(fifo) as got:
        pecs.io.write_events(events(), fifo)
    assert got == [TEXT.encode()]
    assert stat.S_ISFIFO(os.lstat(fifo).st_mode)
    assert sorted(os.listdir(tmp_path)) == ["events.txt"]


@pytest.mark.parametrize(
    "name, suffix",
    # EVT3 streams (written front to back); HDF5 seeks back, so it is built aside and copied.
    [("evt3", ".raw"), ("parquet", ".parquet"), ("hdf5", ".h5"), ("npz", ".npz")],
)
def test_fifo_target_gets_a_readable_binary_file(tmp_path: Path, name: str, suffix: str) -> None:
    fifo = tmp_path / f"events{suffix}"
    with fifo_reader(fifo) as got:
        pecs.io.write_events(events(), fifo, format=name)
    assert stat.S_ISFIFO(os.lstat(fifo).st_mode)
    copy = tmp_path / f"copy{suffix}"
    copy.write_bytes(got[0])
    assert_same_events(pecs.io.read_events(copy, format=name), T_US)


def test_cli_convert_into_a_fifo(tmp_path: Path, capsys: pytest.CaptureFixture) -> None:
    source = tmp_path / "in.parquet"
    pecs.io.write_events(events(), source)
    fifo = tmp_path / "out.txt"
    with fifo_reader(fifo) as got:
        code, out, err = run_cli(capsys, "convert", str(source), str(fifo), "--quiet")
    assert code == 0, err
    assert got == [TEXT.encode()]
    assert stat.S_ISFIFO(os.lstat(fifo).st_mode)


def test_symlink_target_keeps_its_link_and_the_file_it_points_to_is_replaced(
    tmp_path: Path,
) -> None:
    (tmp_path / "data").mkdir()
    (tmp_path / "links").mkdir()
    real = tmp_path / "data" / "events.txt"
    real.write_text("old\n")
    link = tmp_path / "links" / "latest.txt"
    link.symlink_to(Path("..") / "data" / "events.txt")  # relative, as `ln -s` makes them
    pecs.io.write_events(events(), link)
    assert link.is_symlink() and os.readlink(link) == os.path.join("..", "data", "events.txt")
    assert real.read_text() == TEXT
    assert sorted(os.listdir(tmp_path / "data")) == ["events.txt"]  # no .part left beside it
    assert sorted(os.listdir(tmp_path / "links")) == ["latest.txt"]


def test_dangling_symlink_target_creates_the_file_it_names(tmp_path: Path) -> None:
    link = tmp_path / "latest.txt"
    link.symlink_to("events.txt")
    pecs.io.write_events(events(), link)
    assert link.is_symlink()
    assert (tmp_path / "events.txt").read_text() == TEXT


@pytest.mark.usefixtures("no_dev_renames")
def test_dev_null_is_written_to_and_stays_a_character_device(
    capsys: pytest.CaptureFixture, tmp_path: Path
) -> None:
    source = tmp_path / "in.parquet"
    pecs.io.write_events(events(), source)
    for name in ("text", "evt3", "hdf5", "parquet"):
        pecs.io.write_events(events(), os.devnull, format=name)
        code, out, err = run_cli(
            capsys, "convert", str(source), os.devnull, "--format", name, "--quiet"
        )
        assert code == 0, err
        assert out == f"{os.devnull}: 3 events, 4 x 4\n"
    assert stat.S_ISCHR(os.lstat(os.devnull).st_mode)
    assert not [entry for entry in os.listdir("/dev") if entry.endswith(".part")]


@pytest.mark.parametrize("format_args", [[], ["--format", "txt"]])
def test_dash_writes_text_to_stdout(tmp_path: Path, format_args: list[str]) -> None:
    """`-` is stdout, text unless --format says otherwise; the summary goes to stderr so that
    stdout holds the events alone."""
    source = tmp_path / "in.parquet"
    pecs.io.write_events(events(), source)
    done = cli_child(tmp_path, "convert", str(source), "-", "--quiet", *format_args)
    assert done.returncode == 0, done.stderr
    assert done.stdout.decode() == TEXT
    assert done.stderr.decode() == "-: 3 events, 4 x 4\n"


def test_dev_stdout_appends_to_a_redirected_file(tmp_path: Path) -> None:
    """`pecs convert IN /dev/stdout >> log`: the events follow what the file held (the shell's
    append), /dev/stdout is not replaced."""
    source = tmp_path / "in.parquet"
    pecs.io.write_events(events(), source)
    log = tmp_path / "log.txt"
    log.write_text("before\n")
    with open(log, "ab") as stdout:
        done = cli_child(
            tmp_path, "convert", str(source), "/dev/stdout", "--format", "txt", stdout=stdout
        )
    assert done.returncode == 0, done.stderr
    assert log.read_text() == "before\n" + TEXT
    assert Path("/dev/stdout").is_symlink() or stat.S_ISCHR(os.lstat("/dev/stdout").st_mode)


def test_dash_streams_binary_formats_into_a_pipe(tmp_path: Path) -> None:
    source = tmp_path / "in.parquet"
    pecs.io.write_events(events(), source)
    for name, suffix in (("evt3", ".raw"), ("hdf5", ".h5")):
        done = cli_child(tmp_path, "convert", str(source), "-", "--format", name, "--quiet")
        assert done.returncode == 0, done.stderr
        copy = tmp_path / f"copy{suffix}"
        copy.write_bytes(done.stdout)
        assert_same_events(pecs.io.read_events(copy), T_US)


def test_binary_to_a_terminal_is_refused_in_one_line(tmp_path: Path) -> None:
    source = tmp_path / "in.parquet"
    pecs.io.write_events(events(), source)
    leader, follower = pty.openpty()
    try:
        done = cli_child(tmp_path, "convert", str(source), "-", "--format", "evt3", stdout=follower)
        os.set_blocking(leader, False)
        with contextlib.suppress(OSError):
            assert os.read(leader, 1 << 16) == b""  # no binary sent to the terminal
    finally:
        os.close(leader)
        os.close(follower)
    assert done.returncode == 2
    message = done.stderr.decode()
    assert message.count("\n") == 1 and "Traceback" not in message
    assert "terminal" in message and "--format txt" in message


def test_frames2events_dash_writes_events_to_stdout_and_its_summary_to_stderr(
    tmp_path: Path,
) -> None:
    frames = np.ones((3, 4, 5), np.float32)
    frames[1:, :, 2:] = 4.0  # a step: every pixel of the right part brightens at once
    np.save(tmp_path / "frames.npy", frames)
    done = cli_child(
        tmp_path,
        "frames2events",
        str(tmp_path / "frames.npy"),
        "--fps",
        "100",
        "-o",
        "-",
        "--quiet",
    )
    assert done.returncode == 0, done.stderr
    lines = done.stdout.decode().splitlines()
    assert lines[0] == "# width 5 height 4"
    count = int(done.stderr.decode().split()[0])
    assert count > 0 and len(lines) == 1 + count  # stdout holds the events alone


# --- item 13a: an unwritable target is named, with why ------------------------------------------


def test_target_under_a_file_names_the_target_and_the_file(
    tmp_path: Path, capsys: pytest.CaptureFixture
) -> None:
    (tmp_path / "afile").write_text("")
    target = tmp_path / "afile" / "out.txt"
    with pytest.raises(NotADirectoryError) as raised:
        pecs.io.write_events(events(), target)
    assert raised.value.filename == str(target)
    assert f"{tmp_path / 'afile'} is a file" in str(raised.value)
    source = tmp_path / "in.parquet"
    pecs.io.write_events(events(), source)
    code, _, err = run_cli(capsys, "convert", str(source), str(target))
    assert code == 2
    assert str(target) in err and "is a file" in err and ".part" not in err


def test_unwritable_folder_names_the_target_not_its_temporary(
    tmp_path: Path, monkeypatch: pytest.MonkeyPatch, capsys: pytest.CaptureFixture
) -> None:
    """A folder this user may not write to (simulated: tests may run as root, whom permissions
    do not stop) is reported for the target, not for the hidden `.NAME....part`."""
    import pecs._atomic

    real_open = os.open

    def denied(path: object, flags: int, *args: object) -> int:
        if os.fsdecode(path).endswith(".part"):  # type: ignore[arg-type]
            raise PermissionError(13, "Permission denied", os.fsdecode(path))  # type: ignore[arg-type]
        return real_open(path, flags, *args)  # type: ignore[arg-type]

    monkeypatch.setattr(pecs._atomic.os, "open", denied)
    target = tmp_path / "out" / "events.txt"
    with pytest.raises(PermissionError) as raised:
        pecs.io.write_events(events(), target)
    assert raised.value.filename == str(target)
    assert "permission denied" in str(raised.value).lower()
    assert f"folder {tmp_path / 'out'}" in str(raised.value)
    assert ".part" not in str(raised.value)


@pytest.mark.skipif(os.name != "posix" or os.geteuid() == 0, reason="root ignores permissions")
def test_read_only_folder_names_the_target(tmp_path: Path) -> None:
    folder = tmp_path / "locked"
    folder.mkdir()
    folder.chmod(0o500)
    try:
        with pytest.raises(PermissionError) as raised:
            pecs.io.write_events(events(), folder / "events.txt")
    finally:
        folder.chmod(0o700)
    assert raised.value.filename == str(folder / "events.txt")
    assert ".part" not in str(raised.value)


# --- item 13b: a missing input is "no such file" ------------------------------------------------


@pytest.mark.parametrize(
    "argv",
    [
        ["convert", "{missing}", "{tmp}/out.txt"],
        ["info", "{missing}"],
        ["view", "{missing}", "-o", "{tmp}/out.png"],
        ["compare", "{missing}", "{present}"],
        ["compare", "{present}", "{missing}"],
    ],
)
def test_a_missing_input_says_no_such_file(
    tmp_path: Path, capsys: pytest.CaptureFixture, argv: list[str]
) -> None:
    present = tmp_path / "present.parquet"
    pecs.io.write_events(events(), present)
    missing = tmp_path / "missing.parquet"
    names = {"missing": missing, "present": present, "tmp": tmp_path}
    code, _, err = run_cli(capsys, *(part.format(**names) for part in argv))
    assert code == 2
    assert err == f"pecs {argv[0]}: error: no such file: {missing}\n"


def test_missing_frames_say_no_such_file_or_folder(
    tmp_path: Path, capsys: pytest.CaptureFixture
) -> None:
    """Frames may be a folder of images: the message says either."""
    missing = tmp_path / "missing.npy"
    code, _, err = run_cli(capsys, "frames2events", str(missing), "-o", str(tmp_path / "o.txt"))
    assert code == 2
    assert err == f"pecs frames2events: error: no such file or folder: {missing}\n"


def test_missing_frame_inputs_say_no_such_file(
    tmp_path: Path, capsys: pytest.CaptureFixture
) -> None:
    np.save(tmp_path / "frames.npy", np.ones((2, 4, 5), np.float32))
    frames, out = str(tmp_path / "frames.npy"), str(tmp_path / "out.parquet")
    for option, more in (("--timestamps", []), ("--config", ["--fps", "10"])):
        missing = tmp_path / f"missing{option}.txt"
        argv = ["frames2events", frames, "-o", out, option, str(missing), *more]
        code, _, err = run_cli(capsys, *argv)
        assert code == 2
        assert err.startswith(f"pecs frames2events: error: no such file: {missing}"), err


def test_a_folder_given_as_an_event_file_is_named_as_a_folder(tmp_path: Path) -> None:
    with pytest.raises(IsADirectoryError, match=f"{tmp_path} is a folder, not an event file"):
        pecs.io.read_events(tmp_path)
    with pytest.raises(FileNotFoundError, match=f"^no such file: {tmp_path / 'x.h5'}$"):
        pecs.io.read_events(tmp_path / "x.h5")


# --- item 13c: a truncated AEDAT4 file says it is truncated -------------------------------------


def packet_runs_past(data: bytes, offset: int, end: int) -> bool:
    """Whether an AEDAT4 packet (int32 stream id, int32 size, data) starts at `offset` and runs
    past `end` (AEDAT 4.0 specification)."""
    stream_id, size = struct.unpack_from("<ii", data, offset)
    return 0 <= stream_id < 16 and offset + 8 + size > end


@pytest.mark.parametrize("cut", [1_750, 50_000, 150_000, 236_000])
def test_aedat4_cut_inside_its_packets_is_reported_truncated_where_it_ends(
    tmp_path: Path, cut: int
) -> None:
    data = EXCERPT.read_bytes()
    truncated = tmp_path / "cut.aedat4"
    truncated.write_bytes(data[:cut])
    with pytest.raises(pecs.io.EventFileError) as raised:
        pecs.io.read_events(truncated)
    message = str(raised.value)
    assert "truncated" in message and "corrupt" not in message
    assert f"ends at byte {cut}" in message
    # Where: the packet the cut runs through (or the end, when the cut falls between packets).
    offset = raised.value.offset
    assert offset is not None and 18 < offset <= cut
    assert offset == cut or packet_runs_past(data, offset, cut)


def test_aedat4_cut_inside_its_header_is_reported_truncated(tmp_path: Path) -> None:
    data = EXCERPT.read_bytes()
    header_bytes = struct.unpack_from("<i", data, 14)[0]  # after the 14-byte magic line
    truncated = tmp_path / "cut.aedat4"
    truncated.write_bytes(data[:100])
    with pytest.raises(pecs.io.EventFileError, match="truncated") as raised:
        pecs.io.read_events(truncated)
    assert f"{header_bytes}-byte header" in str(raised.value)
    assert "ends at byte 100" in str(raised.value)


def test_cli_reports_a_truncated_recording_for_events_and_frames(
    tmp_path: Path, capsys: pytest.CaptureFixture
) -> None:
    truncated = tmp_path / "cut.aedat4"
    truncated.write_bytes(EXCERPT.read_bytes()[:150_000])
    out = str(tmp_path / "o.parquet")
    for argv in (["info", str(truncated)], ["frames2events", str(truncated), "-o", out]):
        code, _, err = run_cli(capsys, *argv)
        assert code == 2
        assert "truncated" in err and "ends at byte 150000" in err, err
        assert "offset 0:" not in err
    assert not (tmp_path / "o.parquet").exists()


# --- items 13d and 14: Unix times in a clocked format -------------------------------------------

CLOCKED = [("evt3", ".raw"), ("evt2", ".raw"), ("dat", ".dat"), ("v2e", ".h5")]


@pytest.mark.parametrize("name, suffix", CLOCKED)
def test_unix_times_are_refused_by_every_clocked_format_naming_zero_time(
    tmp_path: Path, name: str, suffix: str
) -> None:
    """EVT2 wrote 95 MB of TIME_HIGH padding for these three events; every clocked format now
    refuses them the same way and says how to start them at 0."""
    target = tmp_path / f"out{suffix}"
    with pytest.raises(ValueError) as raised:
        pecs.io.write_events(events([UNIX_T0_US + t for t in T_US]), target, format=name)
    message = str(raised.value)
    assert "--zero-time" in message and "zero_time" in message  # the CLI's and the API's
    assert "Unix" in message
    assert os.listdir(tmp_path) == []


@pytest.mark.parametrize("name, suffix", CLOCKED)
def test_zero_time_starts_the_events_at_zero(tmp_path: Path, name: str, suffix: str) -> None:
    target = tmp_path / f"out{suffix}"
    unix = events([UNIX_T0_US + 5 + t for t in T_US])
    pecs.io.write_events(unix, target, format=name, zero_time=True)
    assert_same_events(pecs.io.read_events(target, format=name), T_US)
    # The very file the events make when recorded from 0: no time padding (EVT2 wrote 95 MB).
    from_zero = tmp_path / f"from_zero{suffix}"
    pecs.io.write_events(events(), from_zero, format=name)
    assert target.read_bytes() == from_zero.read_bytes()


def test_a_span_longer_than_the_format_holds_is_not_sent_to_zero_time(tmp_path: Path) -> None:
    """Two events 2^33 µs (2.4 h) apart: DAT's uint32 µs cannot hold them even from 0, so the
    message names the formats that can."""
    with pytest.raises(ValueError) as raised:
        pecs.io.write_events(events([0, 1 << 33]), tmp_path / "long.dat")
    message = str(raised.value)
    assert "8589934592 µs" in message and "EVT3" in message and "Parquet" in message
    assert os.listdir(tmp_path) == []


@pytest.mark.parametrize(
    "out_name, format_args", [("o.raw", []), ("o.raw", ["--format", "evt2"]), ("o.dat", [])]
)
def test_cli_convert_of_a_dv_recording_names_zero_time(
    tmp_path: Path, capsys: pytest.CaptureFixture, out_name: str, format_args: list[str]
) -> None:
    target = tmp_path / out_name
    code, _, err = run_cli(capsys, "convert", str(EXCERPT), str(target), "--quiet", *format_args)
    assert code == 2 and not target.exists()
    assert err.count("\n") == 1 and "--zero-time" in err and not PYTHON_SYNTAX.search(err)
    code, _, err = run_cli(
        capsys, "convert", str(EXCERPT), str(target), "--quiet", "--zero-time", *format_args
    )
    assert code == 0, err
    real = pecs.io.read_events(EXCERPT).column("t").to_numpy()
    written = pecs.io.read_events(target).column("t").to_numpy()
    assert np.array_equal(written, real - real[0])


def test_frames2events_has_zero_time_for_dv_recordings(
    tmp_path: Path, capsys: pytest.CaptureFixture
) -> None:
    target = tmp_path / "o.dat"
    code, _, err = run_cli(capsys, "frames2events", str(EXCERPT), "-o", str(target), "--quiet")
    assert code == 2 and "--zero-time" in err and not target.exists()
    code, _, err = run_cli(
        capsys, "frames2events", str(EXCERPT), "-o", str(target), "--quiet", "--zero-time"
    )
    assert code == 0, err
    t = pecs.io.read_events(target).column("t").to_numpy()
    assert len(t) and t[0] == 0
