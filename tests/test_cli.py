"""The `pecs` command as a user meets it: stopping it (signals, closed pipes), its messages and
help, its progress bars and its memory. Signals, exit codes and pipes are checked on a real
process (`python -m pecs`); the rest calls `pecs.cli.main` in-process."""

from __future__ import annotations

import argparse
import os
import signal
import subprocess
import sys
import textwrap
import time
from collections.abc import Iterator
from pathlib import Path

import numpy as np
import pecs.io
import pyarrow as pa
import pyarrow.parquet as pq
import pytest
from cli_run import PYTHON_SYNTAX, run_cli
from pecs._atomic import atomic_path
from pecs.cli import build_parser, main
from pecs.events import record_batch, schema
from pecs.render import Simulation
from pecs.render.simulation import Frame

PYTHON_PATH = str(Path(__file__).resolve().parents[1] / "python")
WIDTH, HEIGHT = 64, 48


def write_stream(path: Path, count: int, width: int = WIDTH, height: int = HEIGHT) -> Path:
    """`count` events, 1 us apart, sweeping the sensor; ON for even t."""
    t = np.arange(count, dtype=np.int64)
    columns = {
        "t": t,
        "x": (t % width).astype(np.uint16),
        "y": ((t // width) % height).astype(np.uint16),
        "p": (t % 2 == 0).astype(np.int8),
    }
    pecs.io.write_events(record_batch(columns, schema(width, height)), path)
    return path


def pecs_process(*argv: str, **popen: object) -> subprocess.Popen:
    env = {**os.environ, "PYTHONPATH": PYTHON_PATH}
    return subprocess.Popen(
        [sys.executable, "-m", "pecs", *argv],
        env=env,
        stdout=popen.pop("stdout", subprocess.PIPE),
        stderr=subprocess.PIPE,
        **popen,  # type: ignore[arg-type]
    )


def parts_of(target: Path) -> list[Path]:
    """The hidden temporaries of `target` in its folder (any naming after `.NAME.`)."""
    return sorted(p for p in target.parent.iterdir() if p.name.startswith(f".{target.name}."))


def wait_for_part(target: Path, process: subprocess.Popen, timeout_s: float = 30.0) -> Path:
    """Block until `process` has opened its temporary for `target` (it is then mid-write)."""
    deadline = time.monotonic() + timeout_s
    while time.monotonic() < deadline:
        found = parts_of(target)
        if found:
            return found[0]
        assert process.poll() is None, process.communicate()
        time.sleep(0.01)
    raise AssertionError(f"no temporary for {target} within {timeout_s} s")


@pytest.fixture(scope="module")
def long_input(tmp_path_factory: pytest.TempPathFactory) -> Path:
    """A stream that `convert --batch-size 1` takes tens of seconds over: any signal sent once
    its output's temporary exists lands mid-write."""
    return write_stream(tmp_path_factory.mktemp("long") / "in.parquet", 200_000)


def slow_convert(source: Path, target: Path) -> subprocess.Popen:
    return pecs_process("convert", str(source), str(target), "--batch-size", "1")


# -- items 12 and 13: stopping -------------------------------------------------------------


@pytest.mark.parametrize(
    ("sig", "code", "word"),
    [(signal.SIGTERM, 143, "terminated"), (signal.SIGINT, 130, "interrupted")],
)
def test_a_signal_mid_write_leaves_nothing_and_says_one_line(
    long_input: Path, tmp_path: Path, sig: signal.Signals, code: int, word: str
) -> None:
    target = tmp_path / "out.h5"
    process = slow_convert(long_input, target)
    wait_for_part(target, process)
    process.send_signal(sig)
    _, err = process.communicate(timeout=60)
    assert process.returncode == code
    assert err.decode() == f"pecs convert: {word}\n"
    assert list(tmp_path.iterdir()) == []


def test_a_killed_writers_part_goes_on_the_next_run_and_a_live_writers_stays(
    long_input: Path, tmp_path: Path
) -> None:
    target = tmp_path / "out.h5"
    # A concurrent writer of the same target, alive (holding its temporary) until told to stop.
    writer_code = textwrap.dedent(
        f"""
        import sys
        from pecs._atomic import atomic_path
        with atomic_path({str(target)!r}) as tmp:
            tmp.write_bytes(b"live")
            print("ready", flush=True)
            sys.stdin.readline()
            raise SystemExit("told to stop")
        """
    )
    live = subprocess.Popen(
        [sys.executable, "-c", writer_code],
        env={**os.environ, "PYTHONPATH": PYTHON_PATH},
        stdin=subprocess.PIPE,
        stdout=subprocess.PIPE,
    )
    assert live.stdout is not None and live.stdout.readline() == b"ready\n"
    [live_part] = parts_of(target)

    killed = slow_convert(long_input, target)
    deadline = time.monotonic() + 30
    while len(parts_of(target)) < 2 and time.monotonic() < deadline:
        time.sleep(0.01)
    killed.kill()
    killed.communicate()  # reaps it and closes its pipes
    stale = set(parts_of(target)) - {live_part}
    assert len(stale) == 1  # SIGKILL left it

    rerun = pecs_process("convert", str(long_input), str(target))
    _, err = rerun.communicate(timeout=60)
    assert rerun.returncode == 0, err
    assert parts_of(target) == [live_part] and live_part.read_bytes() == b"live"
    assert pecs.io.read_events(target).num_rows == 200_000

    live.communicate(b"stop\n", timeout=30)
    assert parts_of(target) == []


def test_stale_parts_are_those_whose_writer_is_gone_on_this_host(tmp_path: Path) -> None:
    from pecs._atomic import _HOST, remove_stale_parts

    gone = subprocess.Popen([sys.executable, "-c", ""])
    gone.wait()  # reaped: no process has this id now (until the system reuses it)
    other_host = "0" * 8 if _HOST != "0" * 8 else "1" * 8
    names = {
        f".a.h5.{gone.pid}.{_HOST}.0123456789ab.part": False,  # dead writer
        f".v.mp4.{gone.pid}.{_HOST}.0123456789ab.part.mp4": False,  # its OpenCV sidecar
        f".out.{gone.pid}.{_HOST}.0123456789ab.part": False,  # a simulate folder
        f".a.h5.{os.getpid()}.{_HOST}.0123456789ab.part": False,  # ours, not an open write
        f".a.h5.{os.getppid()}.{_HOST}.0123456789ab.part": True,  # a live process
        f".a.h5.{gone.pid}.{other_host}.0123456789ab.part": True,  # another machine's
        f".a.h5.{gone.pid}.{_HOST}.0123456789ab.tmp": True,  # not a pecs temporary
        "a.h5": True,
    }
    for name in names:
        if name.startswith(".out."):
            (tmp_path / name).mkdir()
            (tmp_path / name / "events.parquet").write_bytes(b"x")
        else:
            (tmp_path / name).write_bytes(b"x")
    # A first write into the folder sweeps it; its own part is open, so a second sweep keeps it.
    with atomic_path(tmp_path / "b.h5") as open_part:
        assert remove_stale_parts(tmp_path) == []
        kept = {p.name for p in tmp_path.iterdir()}
    assert kept == {name for name, stays in names.items() if stays} | {open_part.name}


def test_a_closed_stdout_ends_quietly(tmp_path: Path) -> None:
    events = write_stream(tmp_path / "in.parquet", 1000)
    process = pecs_process("info", str(events))
    assert process.stdout is not None
    process.stdout.close()  # the reader is gone before pecs writes: `pecs info f | head -0`
    _, err = process.communicate(timeout=60)
    assert err == b""
    assert process.returncode == 141


def test_an_interrupted_simulation_leaves_no_folder(
    tmp_path: Path, monkeypatch: pytest.MonkeyPatch
) -> None:
    out = tmp_path / "out"
    simulation = fake_simulation(monkeypatch, interrupt_after_frames=2)
    with pytest.raises(KeyboardInterrupt):
        simulation.run(out)
    assert list(tmp_path.iterdir()) == []

    # A complete run makes the folder; a rerun replaces it whole (no file of the first survives).
    simulation = fake_simulation(monkeypatch)
    summary = simulation.run(out)
    assert summary.out_dir == out and summary.events == 3 and summary.frames == 3
    assert sorted(p.name for p in out.iterdir()) == [
        "events.parquet",
        "ground_truth.parquet",
        "preview.png",
    ]
    (out / "events.parquet").write_bytes(b"old")
    simulation.run(out)
    assert pq.read_table(out / "events.parquet").num_rows == 3
    assert [p.name for p in tmp_path.iterdir()] == ["out"]


def test_a_simulation_will_not_replace_a_folder_with_other_files(
    tmp_path: Path, monkeypatch: pytest.MonkeyPatch
) -> None:
    (tmp_path / "notes.txt").write_text("mine")
    simulation = fake_simulation(monkeypatch)
    with pytest.raises(ValueError, match=r"notes\.txt"):
        simulation.run(tmp_path)
    assert [p.name for p in tmp_path.iterdir()] == ["notes.txt"]


def fake_simulation(monkeypatch: pytest.MonkeyPatch, interrupt_after_frames: int = 0) -> Simulation:
    """The checkerboard scene with Mitsuba replaced: three 4 x 3 frames, one event after each
    (and a Ctrl-C after `interrupt_after_frames` frames, when given)."""

    def frames_and_events(self: Simulation) -> Iterator[tuple[Frame | None, pa.RecordBatch]]:
        for index in range(3):
            if interrupt_after_frames and index == interrupt_after_frames:
                raise KeyboardInterrupt
            frame = Frame(index, 1000 * index, np.ones((3, 4), np.float32), np.eye(4))
            columns = {"t": [1000 * index + 1], "x": [index], "y": [1], "p": [1]}
            yield frame, record_batch(columns, schema(4, 3))
        empty = {name: np.zeros(0) for name in ("t", "x", "y", "p")}
        yield None, record_batch(empty, schema(4, 3))

    monkeypatch.setattr(Simulation, "renderer", property(lambda self: None))
    monkeypatch.setattr(Simulation, "_frames_and_events", frames_and_events)
    return Simulation("checkerboard", spp=1, sensor={"width": 4, "height": 3})


# -- items 15 and 16: refusing what would mislead -------------------------------------------


@pytest.fixture
def frames_npy(tmp_path: Path) -> Path:
    """Four 160 x 120 frames that brighten, so every pixel fires ON events."""
    ramp = np.linspace(0.2, 0.8, 4, dtype=np.float32)[:, None, None]
    path = tmp_path / "frames.npy"
    np.save(path, np.broadcast_to(ramp, (4, 120, 160)).copy())
    return path


def test_set_parses_each_field_as_its_type(
    frames_npy: Path, tmp_path: Path, capsys: pytest.CaptureFixture
) -> None:
    out = tmp_path / "events.parquet"
    argv = ["frames2events", str(frames_npy), "--fps", "100", "-o", str(out), "--preset", "ideal"]
    code, _, err = run_cli(capsys, *argv, "--set", "labels=TRUE", "--set", "seed=1e3")
    assert code == 0, err
    events = pq.read_table(out)
    assert "label" in events.column_names
    # 0.2 -> 0.8 in log steps of 0.2 (the ideal preset's threshold): floor(ln 4 / 0.2) = 6 ON
    # events per pixel, all signal.
    assert events.num_rows == 6 * 160 * 120
    assert set(events.column("label").to_pylist()) == {0}
    code, _, err = run_cli(capsys, *argv, "--set", "labels=no")
    assert code == 0 and "label" not in pq.read_table(out).column_names


@pytest.mark.parametrize(
    ("setting", "message"),
    [
        ("width=50", "--set width=50: the sensor size is the frames' size (160 x 120)"),
        ("height=7", "--set height=7: the sensor size is the frames' size (160 x 120)"),
        ("labels=maybe", "--set labels=maybe: labels takes true or false"),
        ("seed=1.5", "--set seed=1.5: seed takes a whole number"),
        ("theta_on=high", "--set theta_on=high: theta_on takes a number"),
        ("theta_onn=0.3", "--set theta_onn: unknown sensor field; known fields: "),
        ("theta_on", "--set theta_on: expected FIELD=VALUE"),
    ],
)
def test_set_refuses_what_it_cannot_apply_naming_the_field(
    frames_npy: Path, tmp_path: Path, capsys: pytest.CaptureFixture, setting: str, message: str
) -> None:
    out = tmp_path / "events.parquet"
    argv = ["frames2events", str(frames_npy), "--fps", "100", "-o", str(out), "--set", setting]
    code, stdout, err = run_cli(capsys, *argv)
    assert code == 2 and stdout == ""
    assert err.startswith(f"pecs frames2events: error: {message}")
    assert err.count("\n") == 1 and not PYTHON_SYNTAX.search(err)
    assert not out.exists()


@pytest.mark.parametrize(
    ("options", "message"),
    [
        (["--window-ms", "0"], "argument --window-ms: 0: expected a number > 0"),
        (["--window-ms", "-5"], "argument --window-ms: -5: expected a number > 0"),
        (["--window-ms", "0.0001"], "--window-ms 0.0001: shorter than the 1 us time resolution"),
        (["--start-ms", "2"], "--start-ms 2 is past the last event (t = 0.999 ms)"),
        (["--start-ms", "0.5", "--end-ms", "0.5"], "--end-ms 0.5 is not after --start-ms 0.5"),
    ],
)
@pytest.mark.parametrize("suffix", [".png", ".gif"])
def test_view_refuses_a_window_with_nothing_to_show(
    tmp_path: Path, capsys: pytest.CaptureFixture, options: list[str], message: str, suffix: str
) -> None:
    events = write_stream(tmp_path / "in.parquet", 1000)  # t = 0 .. 999 us
    picture = tmp_path / f"view{suffix}"
    code, _, err = run_cli(capsys, "view", str(events), "-o", str(picture), *options)
    assert code == 2 and message in err and not PYTHON_SYNTAX.search(err)
    assert not picture.exists() and parts_of(picture) == []


def test_view_refuses_a_time_surface_video(tmp_path: Path, capsys: pytest.CaptureFixture) -> None:
    events = write_stream(tmp_path / "in.parquet", 1000)
    video = tmp_path / "view.gif"
    code, _, err = run_cli(capsys, "view", str(events), "-o", str(video), "--time-surface")
    assert code == 2 and "--time-surface draws one PNG" in err
    assert not video.exists()


@pytest.mark.parametrize(
    "options",
    [["--f-number", "-2"], ["--f-number", "0"], ["--efl-mm", "-8"], ["--focus-m", "0"]]
    + [["--f-number", "nan"], ["--sensor", "ideal"]],
)
def test_lens_info_refuses_impossible_arguments(
    capsys: pytest.CaptureFixture, options: list[str]
) -> None:
    code, out, err = run_cli(capsys, "lens", "info", "dgauss50", *options)
    assert code == 2 and out == ""
    assert f"argument {options[0]}: {options[1]}: " in err and not PYTHON_SYNTAX.search(err)


def test_a_lens_refuses_a_negative_f_number() -> None:
    from pecs.lens import Lens

    with pytest.raises(ValueError, match="f_number must be > 0"):
        Lens.builtin("dgauss50").with_f_number(-2.0, clamp=True)


# -- item 18: help -------------------------------------------------------------------------


def all_parsers() -> Iterator[tuple[str, argparse.ArgumentParser]]:
    """Every parser of the command, `pecs` and each (sub)subcommand, by its usage name."""
    pending = [build_parser()]
    while pending:
        parser = pending.pop()
        yield parser.prog, parser
        for action in parser._actions:
            if isinstance(action, argparse._SubParsersAction):
                pending.extend(action.choices.values())


def test_every_subcommand_has_a_description_and_shows_its_defaults() -> None:
    names = [name for name, _ in all_parsers()]
    assert {"pecs view", "pecs lens info", "pecs lens plot", "pecs lens ghosts"} <= set(names)
    assert "pecs info" in names
    # pecs, 12 subcommands, lens info, plot and ghosts, dataset card, example, run
    assert len(names) == 19
    for name, parser in all_parsers():
        text = parser.format_help()
        assert parser.description, f"{name} has no description"
        assert not PYTHON_SYNTAX.search(text), f"{name} --help: {PYTHON_SYNTAX.search(text)}"
        assert "(default: True)" not in text, f"{name} --help shows a flag's default"
        for action in parser._actions:
            shown = action.default not in (None, False, [], argparse.SUPPRESS)
            flag = action.nargs == 0  # --quiet, --no-card: no value, so no default to show
            if action.option_strings and shown and not flag and action.help != argparse.SUPPRESS:
                assert "default" in parser._get_formatter()._get_help_string(action), (
                    f"{name} {action.option_strings[0]} hides its default {action.default}"
                )


def test_lens_info_offers_every_sensor_with_a_film() -> None:
    from pecs.lens import SENSOR_FILM_MM

    parser = dict(all_parsers())["pecs lens info"]
    [sensor] = [a for a in parser._actions if "--sensor" in a.option_strings]
    assert set(sensor.choices) == set(SENSOR_FILM_MM) == {"davis346", "dvxplorer", "imx636"}


# -- item 17: progress and memory ----------------------------------------------------------


def test_convert_shows_progress_only_when_asked_or_on_a_terminal(
    tmp_path: Path, capsys: pytest.CaptureFixture
) -> None:
    events = write_stream(tmp_path / "in.parquet", 700)
    out = tmp_path / "out.raw"
    code, stdout, err = run_cli(capsys, "convert", str(events), str(out))
    assert code == 0 and err == ""  # stderr is not a terminal here: quiet
    assert stdout == f"{out}: 700 events, {WIDTH} x {HEIGHT}\n"
    code, _, err = run_cli(capsys, "convert", str(events), str(out), "--progress")
    assert code == 0 and "700/700" in err  # the total comes from the Parquet footer
    code, _, err = run_cli(capsys, "view", str(events), "-o", str(tmp_path / "v.gif"), "--progress")
    assert code == 0 and "700/700" in err


def peak_rss_growth_mb(*argv: str) -> float:
    """Peak resident memory of `pecs ARGV` in a fresh process, less what its imports took."""
    code = textwrap.dedent(
        f"""
        import resource
        import pecs.cli, pecs.io, pecs.viz, pyarrow.parquet, h5py, cv2
        before = resource.getrusage(resource.RUSAGE_SELF).ru_maxrss
        assert pecs.cli.main({list(argv)!r}) == 0
        after = resource.getrusage(resource.RUSAGE_SELF).ru_maxrss
        print((after - before) / 1024)
        """
    )
    env = {**os.environ, "PYTHONPATH": PYTHON_PATH}
    result = subprocess.run(
        [sys.executable, "-c", code], env=env, capture_output=True, text=True, timeout=120
    )
    assert result.returncode == 0, result.stderr
    return float(result.stdout.split()[-1])


@pytest.mark.skipif(sys.platform != "linux", reason="ru_maxrss is in kB on Linux")
def test_convert_and_view_memory_does_not_grow_with_a_parquet_row_group(tmp_path: Path) -> None:
    # 2 M events make two full row groups of 1 M rows. Reading the first event to learn the
    # sensor size sliced a whole row group into one-event batches: 1.2 GB, whatever the file's
    # size. Streaming needs one batch (1 M events, 17 MB) and the writer's buffers.
    events = write_stream(tmp_path / "in.parquet", 2_000_000, 640, 480)
    assert pq.ParquetFile(events).metadata.num_row_groups == 2
    assert peak_rss_growth_mb("convert", str(events), str(tmp_path / "out.raw")) < 250
    assert peak_rss_growth_mb("view", str(events), "-o", str(tmp_path / "view.png")) < 250


def test_convert_asks_for_the_size_in_the_commands_words(
    tmp_path: Path, capsys: pytest.CaptureFixture
) -> None:
    empty = {name: np.zeros(0) for name in ("t", "x", "y", "p")}
    source = tmp_path / "empty.parquet"
    pecs.io.write_events(record_batch(empty, schema()), source)  # no size, no events
    code, _, err = run_cli(capsys, "convert", str(source), str(tmp_path / "out.raw"))
    assert code == 2 and err.endswith("needs one: pass --width and --height\n")
    code, out, err = run_cli(
        capsys, "convert", str(source), str(tmp_path / "out.raw"), "--width", "4", "--height", "3"
    )
    assert code == 0, err
    assert out == f"{tmp_path / 'out.raw'}: 0 events, 4 x 3\n"


def test_an_error_message_that_wraps_is_printed_on_one_line(monkeypatch, capsys) -> None:
    import pecs.cli.info as info

    def fail(args: argparse.Namespace) -> int:
        raise ValueError("first part\n  second part")

    monkeypatch.setattr(info, "run", fail)
    assert main(["info", "x.parquet"]) == 2
    assert capsys.readouterr().err == "pecs info: error: first part second part\n"


def test_convert_zero_time_takes_a_dv_recording_to_evt3(tmp_path: Path, capsys) -> None:
    """A DV recording's times are Unix microseconds (1.6e15), which EVT3's clock (from 0) cannot
    hold: plain convert refuses, --zero-time starts them at 0 and keeps every event."""
    import numpy as np
    import pecs

    recording = Path(__file__).parent / "data" / "davis346_excerpt" / "davis346_road_3frames.aedat4"
    target = tmp_path / "road.raw"
    assert main(["convert", str(recording), str(target), "--quiet"]) == 2
    assert "--zero-time" in capsys.readouterr().err and not target.exists()
    assert main(["convert", str(recording), str(target), "--quiet", "--zero-time"]) == 0
    real, written = pecs.read_events(recording), pecs.read_events(target)
    t = real.column("t").to_numpy()
    assert t[0] > 1.5e15
    assert np.array_equal(written.column("t").to_numpy(), t - t[0])
    for name in ("x", "y", "p"):
        assert np.array_equal(written.column(name).to_numpy(), real.column(name).to_numpy())
