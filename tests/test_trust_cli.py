"""Trust, round two: the viewer's bounds and times, the noise options' ranges, and CLI messages
that name what a user types. Each test works out its expectation by hand, not from pecs."""

from __future__ import annotations

import os
import re
import subprocess
import sys
import textwrap
from pathlib import Path

import cv2
import numpy as np
import pecs
import pecs.io
import pytest
from cli_run import PYTHON_SYNTAX, run_cli
from pecs.events import record_batch, schema
from PIL import Image

PYTHON_PATH = str(Path(__file__).resolve().parents[1] / "python")
# A DV AEDAT4 recording's first event (Unix time, us): 2022-01-27 00:33:48.7578 UTC.
T0_US = 1_643_243_628_757_800
WHITE = (255, 255, 255)
BLUE = (33, 102, 172)  # ON on white
RED = (214, 39, 40)  # OFF on white


def write_events(path: Path, t_us: list[int], xy: list[tuple[int, int]], p: list[int]) -> Path:
    """Events at the given times and pixels on a 16 x 8 sensor (size in the file)."""
    columns = {
        "t": np.asarray(t_us, np.int64),
        "x": np.asarray([a for a, _ in xy], np.uint16),
        "y": np.asarray([b for _, b in xy], np.uint16),
        "p": np.asarray(p, np.int8),
    }
    pecs.io.write_events(record_batch(columns, schema(16, 8)), path)
    return path


def unix_stream(path: Path) -> Path:
    """Four events on Unix time: (0, 0) ON at the start, (3, 2) ON at 42 ms, (5, 1) OFF at
    44 ms, (9, 6) ON at 100 ms; nothing between 1 ms and 42 ms."""
    offsets_us = [0, 42_000, 44_000, 100_000]
    return write_events(
        path, [T0_US + o for o in offsets_us], [(0, 0), (3, 2), (5, 1), (9, 6)], [1, 1, 0, 1]
    )


def read_png(path: Path) -> np.ndarray:
    with Image.open(path) as opened:
        return np.asarray(opened.convert("RGB"))


def hand_image(pixels: dict[tuple[int, int], tuple[int, int, int]]) -> np.ndarray:
    image = np.empty((8, 16, 3), np.uint8)
    image[:] = WHITE
    for (x, y), colour in pixels.items():
        image[y, x] = colour
    return image


def mp4_frames(path: Path) -> int:
    capture = cv2.VideoCapture(str(path))
    try:
        return int(capture.get(cv2.CAP_PROP_FRAME_COUNT))
    finally:
        capture.release()


# -- item 9: view times relative to the first event ----------------------------------------


@pytest.mark.filterwarnings("error")
def test_view_start_is_relative_to_the_first_event(
    tmp_path: Path, capsys: pytest.CaptureFixture
) -> None:
    # The README's command: 10 ms from 40 ms into the stream holds the events at 42 and 44 ms.
    events = unix_stream(tmp_path / "unix.parquet")
    png = tmp_path / "view.png"
    argv = ["view", str(events), "-o", str(png), "--window-ms", "10", "--start-ms", "40"]
    code, _, err = run_cli(capsys, *argv)
    assert code == 0 and err == ""
    np.testing.assert_array_equal(read_png(png), hand_image({(3, 2): BLUE, (5, 1): RED}))


def test_view_absolute_times_are_the_files_own(
    tmp_path: Path, capsys: pytest.CaptureFixture
) -> None:
    events = unix_stream(tmp_path / "unix.parquet")
    png = tmp_path / "view.png"
    start_ms = (T0_US + 43_000) / 1000  # 1643243628800.8: only the OFF event at 44 ms
    argv = ["view", str(events), "-o", str(png), "--window-ms", "10"]
    code, _, err = run_cli(capsys, *argv, "--start-ms", f"{start_ms}", "--absolute-times")
    assert code == 0 and err == ""
    np.testing.assert_array_equal(read_png(png), hand_image({(5, 1): RED}))


def test_view_warns_in_one_line_of_a_window_with_no_events(
    tmp_path: Path, capsys: pytest.CaptureFixture
) -> None:
    events = unix_stream(tmp_path / "unix.parquet")
    png = tmp_path / "view.png"
    argv = ["view", str(events), "-o", str(png), "--window-ms", "5", "--start-ms", "20"]
    code, out, err = run_cli(capsys, *argv)
    assert code == 0 and out.startswith(str(png))
    assert err.startswith("pecs view: warning: no events") and err.count("\n") == 1
    assert "20 .. 25 ms" in err and not PYTHON_SYNTAX.search(err)
    np.testing.assert_array_equal(read_png(png), hand_image({}))


def test_view_video_end_past_the_last_event_stops_there(
    tmp_path: Path, capsys: pytest.CaptureFixture
) -> None:
    # --end-ms 2000000 asked for 2000 s of 33.3 ms frames (60,060) on a 100 ms stream; the
    # events fill windows [0, 33.3), [33.3, 66.6), [66.6, 99.9), [99.9, 133.2): 4 frames.
    events = unix_stream(tmp_path / "unix.parquet")
    video = tmp_path / "view.mp4"
    code, _, err = run_cli(capsys, "view", str(events), "-o", str(video), "--end-ms", "2000000")
    assert code == 0 and mp4_frames(video) == 4
    assert err.startswith("pecs view: warning: --end-ms 2000000 is past the last event")
    assert err.count("\n") == 1


# -- item 8: a bound on the frames of a video ------------------------------------------------


def test_view_refuses_more_frames_than_max_frames_before_writing(
    tmp_path: Path, capsys: pytest.CaptureFixture
) -> None:
    # Events over 60 ms in 0.01 ms windows: 60,000 / 10 + 1 = 6,001 frames, past the default.
    events = write_events(tmp_path / "e.parquet", [T0_US, T0_US + 60_000], [(1, 1), (2, 2)], [1, 0])
    video = tmp_path / "view.gif"
    code, out, err = run_cli(capsys, "view", str(events), "-o", str(video), "--window-ms", "0.01")
    assert code == 2 and out == ""
    assert re.search(r"6,?001 frames", err) and "--max-frames" in err
    assert err.count("\n") == 1 and not video.exists()


def test_view_max_frames_raises_the_bound(tmp_path: Path, capsys: pytest.CaptureFixture) -> None:
    events = write_events(tmp_path / "e.parquet", [T0_US, T0_US + 60_000], [(1, 1), (2, 2)], [1, 0])
    video = tmp_path / "view.mp4"
    argv = ["view", str(events), "-o", str(video), "--window-ms", "0.01", "--max-frames", "6001"]
    code, _, err = run_cli(capsys, *argv)
    assert code == 0 and err == "" and mp4_frames(video) == 6001
    code, _, err = run_cli(capsys, *argv[:-1], "6000")
    assert code == 2 and "6,001 frames" in err


@pytest.mark.skipif(sys.platform != "linux", reason="ru_maxrss is in kB on Linux")
def test_a_gif_is_written_as_its_frames_come(tmp_path: Path) -> None:
    # 1,000 different 128 x 128 frames: Pillow's save_all kept each one (49 kB of RGB and 16 kB
    # as a palette image, 65 MB in all) until the end; streamed, a frame or two is held.
    code = textwrap.dedent(
        f"""
        import resource
        import numpy as np, pecs.viz, PIL.GifImagePlugin  # imported before the count
        def frames():
            for k in range(1000):
                frame = np.full((128, 128, 3), 255, np.uint8)
                frame[(k * 7) % 128, :] = (33, 102, 172)
                frame[:, (k * 13) % 128] = (214, 39, 40)
                yield frame
        before = resource.getrusage(resource.RUSAGE_SELF).ru_maxrss
        pecs.viz.save_video(frames(), {str(tmp_path / "v.gif")!r}, fps=50)
        print((resource.getrusage(resource.RUSAGE_SELF).ru_maxrss - before) / 1024)
        """
    )
    env = {**os.environ, "PYTHONPATH": PYTHON_PATH}
    result = subprocess.run(
        [sys.executable, "-c", code], env=env, capture_output=True, text=True, timeout=120
    )
    assert result.returncode == 0, result.stderr
    assert float(result.stdout.split()[-1]) < 20
    with Image.open(tmp_path / "v.gif") as gif:
        assert gif.n_frames == 1000 and gif.size == (128, 128)
        gif.seek(5)
        frame = np.asarray(gif.convert("RGB"))
    assert tuple(frame[35, 0]) == BLUE and tuple(frame[0, 65]) == RED  # row 5 * 7, column 5 * 13
    assert tuple(frame[100, 100]) == WHITE and tuple(frame[35, 65]) == RED


def test_a_gif_merges_repeated_frames_into_one_longer_frame(tmp_path: Path) -> None:
    blank = np.full((4, 6, 3), 255, np.uint8)
    marked = blank.copy()
    marked[1, 2] = BLUE
    gif = pecs.viz.save_video([blank, blank, blank, marked], tmp_path / "v.gif", fps=10)
    with Image.open(gif) as opened:
        assert opened.n_frames == 2
        assert opened.info["duration"] == 300  # three frames of 100 ms
        opened.seek(1)
        np.testing.assert_array_equal(np.asarray(opened.convert("RGB")), marked)


# -- item 11: the input-noise options' ranges -------------------------------------------------


@pytest.fixture
def png_folder(tmp_path: Path) -> Path:
    folder = tmp_path / "frames"
    folder.mkdir()
    for k in range(3):
        cv2.imwrite(str(folder / f"{k:02d}.png"), np.full((6, 8), 100 + 20 * k, np.uint8))
    return folder


@pytest.mark.filterwarnings("error")
@pytest.mark.parametrize(
    ("options", "said"),
    [
        # PNG frames are read as 0 to 1: a noise of 1e30 (or of 1.2 at full scale) is no noise
        # of theirs. 1e300 is past float32's 3.4e38, the frames' type, and K past 100 sigma.
        (["--input-noise-sigma", "1e30"], "--input-noise-sigma 1e+30,0: a noise of more than"),
        (["--input-noise-sigma", "1,0.44"], "--input-noise-sigma 1,0.44: a noise of more than"),
        (["--input-noise-sigma", "1,1e300"], "--input-noise-sigma: 1,1e300: past float32"),
        (["--input-noise-sigma", "1e300"], "--input-noise-sigma: 1e300: past float32"),
        (["--deadband-sigmas", "1e300"], "--deadband-sigmas: 1e300: expected at most 100"),
        (["--deadband-sigmas", "101"], "--deadband-sigmas: 101: expected at most 100"),
    ],
)
def test_frames2events_refuses_noise_options_out_of_range(
    png_folder: Path,
    tmp_path: Path,
    capsys: pytest.CaptureFixture,
    options: list[str],
    said: str,
) -> None:
    out = tmp_path / "events.parquet"
    argv = ["frames2events", str(png_folder), "--fps", "25", "-o", str(out), *options]
    code, stdout, err = run_cli(capsys, *argv)
    assert code == 2 and stdout == ""
    assert said in err and not PYTHON_SYNTAX.search(err)
    assert err.count("\n") == 1 or err.startswith("usage:")  # argparse: usage, then its line
    assert not out.exists()


@pytest.mark.filterwarnings("error")
def test_frames2events_takes_a_noise_within_the_full_scale(
    png_folder: Path, tmp_path: Path, capsys: pytest.CaptureFixture
) -> None:
    out = tmp_path / "events.parquet"
    argv = ["frames2events", str(png_folder), "--fps", "25", "-o", str(out)]
    code, _, err = run_cli(
        capsys, *argv, "--input-noise-sigma", "0.6,0.64", "--deadband-sigmas", "0"
    )
    assert code == 0 and err == ""  # 0.36 + 0.64 = 1: the full scale, the most allowed


@pytest.mark.filterwarnings("error")
def test_frames2events_holds_a_huge_stated_noise_without_warnings(
    tmp_path: Path, capsys: pytest.CaptureFixture
) -> None:
    # Float frames are in the user's own units: a noise of 1e30 of them is in range for the
    # API; every change is held back (no signal events) and no numpy warning may escape.
    # Band: 100 sigma sqrt(1 + 1/n) >= 1e32 about the mean; 3e30 and 1e31 stay inside it.
    frames = np.stack([np.full((6, 8), v, np.float32) for v in (1.0, 3e30, 1e31)])
    npy = tmp_path / "frames.npy"
    np.save(npy, frames)
    out = tmp_path / "events.parquet"
    argv = ["frames2events", str(npy), "--fps", "25", "-o", str(out), "--preset", "ideal"]
    code, _, err = run_cli(capsys, *argv, "--input-noise-sigma", "1e30", "--deadband-sigmas", "100")
    assert code == 0 and err == ""
    assert pecs.read_events(out).num_rows == 0


def test_input_noise_refuses_out_of_range_values_naming_them() -> None:
    from pecs.footage.input_noise import InputNoise

    with pytest.raises(ValueError, match="^read_sigma: .*float32"):
        InputNoise(1e300)
    with pytest.raises(ValueError, match="^shot_gain: .*float32"):
        InputNoise(0.01, 1e39)
    with pytest.raises(ValueError, match=r"^deadband_sigmas: .*at most 100"):
        InputNoise(0.01, 0.0, 1e300)


@pytest.mark.filterwarnings("error")
def test_input_deadband_at_the_largest_values_stays_finite() -> None:
    from pecs.footage.input_noise import InputDeadband, InputNoise

    big = float(np.finfo(np.float32).max)
    deadband = InputDeadband(InputNoise(big, big, 100.0))
    first = np.array([[0.0, 1.0], [big, 2.0]], np.float32)
    deadband(first)
    held = deadband(np.array([[5.0, -big, 0.0, 2.0]], np.float32).reshape(2, 2))
    np.testing.assert_array_equal(held, first)  # nothing leaves a band of 100 x 3.4e38


# -- 13e, 13g, 13h, 13j, 19: messages and help in the words a user types ------------------------


def test_compare_names_the_cli_option_for_the_sensor_size(
    tmp_path: Path, capsys: pytest.CaptureFixture
) -> None:
    columns = {
        "t": np.array([0, 10], np.int64),
        "x": np.array([1, 2], np.uint16),
        "y": np.array([1, 2], np.uint16),
        "p": np.array([1, 0], np.int8),
    }
    a = pecs.io.write_events(record_batch(columns, schema(16, 8)), tmp_path / "a.parquet")
    b = pecs.io.write_events(record_batch(columns, schema(20, 8)), tmp_path / "b.parquet")
    c = tmp_path / "c.txt"  # as other tools write text events: no sensor size
    c.write_text("0 1 1 1\n10 2 2 0\n")
    for pair in ((a, b), (c, c)):
        code, _, err = run_cli(capsys, "compare", *map(str, pair), "--normalize", "sensor")
        assert code == 2 and "--sensor-size WIDTH HEIGHT" in err, err
        assert "sensor_size" not in err and "normalize=" not in err and err.count("\n") == 1


@pytest.mark.filterwarnings("error")
def test_a_float64_frame_beyond_float32_says_so() -> None:
    sensor = pecs.EventSensor(pecs.SensorConfig.preset("ideal", width=4, height=3))
    frame = np.ones((3, 4))
    frame[1, 2] = 1e300
    with pytest.raises(ValueError, match=r"value \(1e\+300\) at x=2, y=1 past float32") as error:
        sensor.feed(frame, 0)
    assert "non-finite" not in str(error.value)
    frame[1, 2] = np.inf  # a real infinity is still non-finite
    with pytest.raises(ValueError, match=r"non-finite value \(inf\) at x=2, y=1"):
        sensor.feed(frame, 0)
    assert sensor.last_time_us is None


def test_a_refused_millisecond_gap_is_shown_in_milliseconds() -> None:
    # 1280 x 720 pixels of 1e5 Hz leak (+10 Hz shot) and 92.16 hot pixels at 5 Hz: 9.217e10
    # events a second, 9.2e7 in 1 ms, over the 5e7 one call may give. The longest gap is
    # 5e7 / 9.2169e10 s = 542.48 us.
    config = pecs.SensorConfig.preset("davis346", width=1280, height=720, leak_rate_hz=1e5)
    sensor = pecs.EventSensor(config)
    frame = np.ones((720, 1280), np.float32)
    sensor.feed(frame, 0)
    with pytest.raises(ValueError) as error:
        sensor.feed(frame, 1000)
    message = str(error.value)
    assert "a gap of 1.0 ms after 0" in message
    assert "feed frames at most 542.480 us apart" in message


@pytest.mark.filterwarnings("error")
@pytest.mark.parametrize(
    ("f_number", "said"),
    [
        # dgauss50 opens to f/2.03 (paraxial, from its prescription); 1.9 is 6 % faster.
        ("0.1", "--f-number 0.1: dgauss50 opens to f/2.03 at most; give f/2.03 to f/1000"),
        ("1.9", "--f-number 1.9: dgauss50 opens to f/2.03 at most; give f/2.03 to f/1000"),
        # Past f/1000 diffraction (2.44 lambda N = 1.4 mm) is larger than a sensor.
        ("1e300", "argument --f-number: 1e300: expected at most f/1000"),
        ("1001", "argument --f-number: 1001: expected at most f/1000"),
    ],
)
def test_lens_info_refuses_an_f_number_the_lens_cannot_have(
    capsys: pytest.CaptureFixture, f_number: str, said: str
) -> None:
    code, out, err = run_cli(capsys, "lens", "info", "dgauss50", "--f-number", f_number)
    assert code == 2 and out == "" and said in err and not PYTHON_SYNTAX.search(err)
    assert err.count("\n") == 1 or err.startswith("usage:")  # argparse: usage, then its line


@pytest.mark.filterwarnings("error")
def test_lens_info_takes_a_nominal_f_number_within_two_percent(
    capsys: pytest.CaptureFixture,
) -> None:
    code, out, err = run_cli(capsys, "lens", "info", "dgauss50", "--f-number", "2")
    assert code == 0 and err == "" and "f-number           2.030" in out


def test_lens_info_help_lists_its_lenses_and_sensors(capsys: pytest.CaptureFixture) -> None:
    code, out, _ = run_cli(capsys, "lens", "info", "--help")
    text = " ".join(out.split())
    assert code == 0
    for name in ("dgauss50", "fisheye10", "pecs4", "telephoto250", "wide22"):
        assert name in text
    # davis346: 346 x 260 pixels of 18.5 um.
    assert "davis346 (6.40 x 4.81 mm)" in text and "ideal and esim" in text


def test_convert_help_names_formats_as_options(capsys: pytest.CaptureFixture) -> None:
    code, out, _ = run_cli(capsys, "convert", "--help")
    text = " ".join(out.split())
    assert code == 0 and "format=" not in text
    assert "--format v2e" in text and "--format evt2" in text


@pytest.mark.filterwarnings("default")  # the suite turns warnings into errors; a user's does not
def test_a_warning_reaches_a_cli_user_as_one_line_without_source_paths(tmp_path, capsys) -> None:
    # 4 x 4 pixels over 3 frames: 32 differences, too few to estimate the frames' noise, which
    # the API says with a UserWarning (tests/test_input_noise.py); the CLI shows it as a notice.
    rng = np.random.default_rng(6)
    frames = np.clip(0.5 + 0.01 * rng.standard_normal((3, 4, 4)), 0, 1).astype(np.float32)
    np.save(tmp_path / "tiny.npy", frames)
    code, _, err = run_cli(
        capsys,
        *("frames2events", str(tmp_path / "tiny.npy"), "-o", str(tmp_path / "ev.parquet")),
        *("--fps", "100", "--input-noise", "on"),
    )
    assert code == 0, err
    notices = [line for line in err.splitlines() if "warning" in line.lower()]
    assert notices == [notices[0]] and notices[0].startswith("pecs frames2events: warning: ")
    assert "fewer than the 200 needed" in notices[0]
    assert ".py" not in err and "UserWarning" not in err and "warnings.warn" not in err


@pytest.mark.parametrize(
    ("spp", "says"),
    [
        ("1e12", "--spp 1000000000000: 1000000000000 is more than Mitsuba's 32-bit sample count"),
        ("4e9", "--spp 4000000000: 4000000000 samples per pixel"),
        ("1.5", "--spp: 1.5: expected an integer >= 1"),
    ],
)
def test_a_count_written_as_a_float_meets_its_range_not_the_parser(
    spp: str, says: str, tmp_path, capsys
) -> None:
    # 4e9 is a whole number: the CLI parsed it as "not an integer" and never said why it cannot be.
    code, _, err = run_cli(
        capsys, "simulate", "checkerboard", "-o", str(tmp_path / "x"), "--spp", spp
    )
    assert code == 2 and says in err
    assert not (tmp_path / "x").exists()
