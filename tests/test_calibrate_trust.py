"""What a calibration may depend on, what it scores, and what it promises before it starts:
nothing outside the fitted span reaches the fit, the default held-out span is the rest of the
recording on both sides, the evaluation budget holds, progress stays off stdout, and a bad
output or budget is refused before any work."""

from __future__ import annotations

import os
import subprocess
import sys
from pathlib import Path

import numpy as np
import pecs
import pyarrow as pa
import pytest
from pecs.calibration._nelder_mead import minimize
from pecs.calibration.fit import Recording, calibrate
from pecs.calibration.report import write_report
from pecs.cli import main as cli_main
from pecs.config import SensorConfig

EXCERPT = Path(__file__).parent / "data" / "davis346_excerpt" / "davis346_road_3frames.aedat4"
PYTHON_PATH = str(Path(__file__).resolve().parents[1] / "python")
ORIGIN_US = 1_000_000
FRAME_US = 40_000
SIZE = 24


def camera_frames(seed: int, count: int = 14, noise: float = 0.01) -> np.ndarray:
    """A log-intensity random walk per pixel (changes of every size) with read noise on top,
    as a real camera's frames carry it, in (0, 1]."""
    rng = np.random.default_rng(seed)
    log_i = rng.uniform(np.log(0.05), np.log(0.9), (SIZE, SIZE))
    steps = rng.normal(0.0, 0.4, (count, SIZE, SIZE)) * rng.uniform(0.1, 1.5, (SIZE, SIZE))
    light = np.exp(np.clip(log_i + np.cumsum(steps, axis=0), np.log(0.02), 0.0))
    noisy = light + rng.normal(0.0, noise, light.shape)
    return np.clip(noisy, 1e-3, 1.0).astype(np.float32)


def frame_times(count: int) -> np.ndarray:
    return ORIGIN_US + FRAME_US * np.arange(count, dtype=np.int64)


def recorded_events(frames: np.ndarray, times: np.ndarray, seed: int = 5) -> pa.Table:
    """The "recording's" events: pecs's own, from an ideal sensor with known thresholds."""
    truth = SensorConfig.preset(
        "ideal", width=SIZE, height=SIZE, theta_on=0.25, theta_off=0.3, seed=seed
    )
    return pecs.frames_to_events(frames, times, truth)


def events_table(t: np.ndarray, x: np.ndarray, y: np.ndarray, p: np.ndarray) -> pa.Table:
    order = np.argsort(t, kind="stable")
    return pa.table(
        {
            "t": pa.array(t[order], pa.int64()),
            "x": pa.array(x[order], pa.uint16()),
            "y": pa.array(y[order], pa.uint16()),
            "p": pa.array(p[order], pa.int8()),
        }
    )


def columns(table: pa.Table) -> tuple[np.ndarray, ...]:
    return tuple(table.column(name).to_numpy() for name in ("t", "x", "y", "p"))


def fitted_file(recording: Recording, fit_ms: tuple[float, float], path: Path) -> bytes:
    result = calibrate(
        recording,
        fit_ms,
        parameters=("theta_on", "theta_off", "dark_current"),
        max_evaluations=8,
    )
    result.config.to_file(path)
    return path.read_bytes()


# ---- item 4: nothing outside the fitted span reaches the fit ---------------------------------


def test_frames_and_events_outside_the_fitted_span_do_not_change_the_fit(tmp_path):
    # Fit 100:300 ms. The frames used are those inside the span and the one bracketing each end
    # (at 80 and 320 ms: the light inside the span is interpolated from them): indices 2..8.
    # Everything else is replaced: frames 0-1 and 9-13 by another scene with 5x the noise (the
    # noise estimate read the first 16 frames), events before 100 ms and from 300 ms by others.
    frames, times = camera_frames(seed=1), frame_times(14)
    events = recorded_events(frames, times)
    original = Recording(frames, times, events, camera_footage=True)

    changed_frames = frames.copy()
    outside = np.r_[0:2, 9:14]
    changed_frames[outside] = camera_frames(seed=2, noise=0.05)[outside]
    start_us, end_us = ORIGIN_US + 100_000, ORIGIN_US + 300_000
    t, x, y, p = columns(events)
    inside = (t >= start_us) & (t < end_us)
    rng = np.random.default_rng(3)
    other_t = np.r_[
        rng.integers(ORIGIN_US, start_us, 3000), rng.integers(end_us, times[-1] + 1, 5000)
    ]
    changed_events = events_table(
        np.r_[t[inside], other_t],
        np.r_[x[inside], rng.integers(0, SIZE, len(other_t))],
        np.r_[y[inside], rng.integers(0, SIZE, len(other_t))],
        np.r_[p[inside], rng.integers(0, 2, len(other_t))],
    )
    changed = Recording(changed_frames, times, changed_events, camera_footage=True)

    a = fitted_file(original, (100, 300), tmp_path / "a.toml")
    b = fitted_file(changed, (100, 300), tmp_path / "b.toml")
    assert a == b

    # ... and the comparison can fail: a frame inside the span does change the fit.
    inner = frames.copy()
    inner[5] = camera_frames(seed=2, noise=0.05)[5]
    c = fitted_file(
        Recording(inner, times, events, camera_footage=True), (100, 300), tmp_path / "c.toml"
    )
    assert c != a


# ---- item 5: the held-out span is the rest on both sides, and must hold events ------------------


def count_inside(events: pa.Table, *windows: tuple[int, int]) -> int:
    t = events.column("t").to_numpy()
    return int(sum(((t >= a) & (t < b)).sum() for a, b in windows))


def test_default_held_out_span_is_the_rest_on_both_sides(tmp_path):
    frames, times = camera_frames(seed=1, count=16), frame_times(16)
    events = recorded_events(frames, times)
    recording = Recording(frames, times, events)
    result = calibrate(
        recording, (200, 400), preset="ideal", parameters=("theta_on",), max_evaluations=3
    )
    before, after = (ORIGIN_US, ORIGIN_US + 200_000), (ORIGIN_US + 400_000, int(times[-1]))
    assert result.holdout is not None
    # 200 ms before, 200 ms after: whole 5 ms bins, every real event of both counted.
    assert result.holdout["events_real"] == count_inside(events, before, after) > 1000
    assert result.holdout_windows_us == (before, after)
    report, png = write_report(result, recording, tmp_path / "report")
    assert "held out 1000000..1200000 us + 1400000..1600000 us." in report.read_text()
    assert png.read_bytes()[:4] == b"\x89PNG"


def test_a_reverse_split_scores_the_first_part_not_a_sliver_at_the_end():
    # The road recording's last frame lies 1 us after a whole ms (2320.001 ms): --fit-ms
    # 1160:2320 left a 1 us held-out span with no events (objective 500, NaN).
    frames = camera_frames(seed=1, count=16)
    times = frame_times(16)
    times[-1] += 1
    events = recorded_events(frames, times)
    recording = Recording(frames, times, events)
    result = calibrate(
        recording, (300, 600), preset="ideal", parameters=("theta_on",), max_evaluations=3
    )
    first_part = (ORIGIN_US, ORIGIN_US + 300_000)
    assert result.holdout is not None
    assert result.holdout["events_real"] == count_inside(events, first_part) > 1000
    assert np.isfinite(result.holdout["chamfer_sensor"])
    assert result.holdout_windows_us == (first_part,)


def test_a_held_out_span_without_events_to_score_is_refused():
    frames, times = camera_frames(seed=1, count=16), frame_times(16)
    events = recorded_events(frames, times)
    t = events.column("t").to_numpy()
    quiet_end = Recording(frames, times, events.filter(pa.array(t < ORIGIN_US + 400_000)))
    with pytest.raises(ValueError, match=r"held-out.*400:600 ms.*0 recorded events.*--holdout-ms"):
        calibrate(quiet_end, (0, 400), preset="ideal", parameters=("theta_on",))
    with pytest.raises(ValueError, match=r"fitted span.*400:600 ms.*0 recorded events.*--fit-ms"):
        calibrate(quiet_end, (400, 600), holdout_ms=None, preset="ideal", parameters=("theta_on",))


def test_cli_reverse_split_on_the_excerpt_scores_the_first_interval(tmp_path, capsys):
    output = tmp_path / "sensor.toml"
    args = ["calibrate", str(EXCERPT), "--fit-ms", "40:80", "--parameters", "theta_on"]
    assert cli_main([*args, "--max-evaluations", "2", "--quiet", "-o", str(output)]) == 0
    out = capsys.readouterr().out
    recording = Recording.load(EXCERPT)
    origin = int(recording.times_us[0])
    real = count_inside(recording.events, (origin, origin + 40_000))
    assert f"held out {origin}..{origin + 40_000} us" in out
    row = next(line for line in out.splitlines() if line.startswith("| events |"))
    cells = [cell.strip() for cell in row.strip("|").split("|")]
    # measure | real, start, calibrated (fitted span) | real, start, calibrated (held out)
    assert cells[4] == str(real) and real > 1000
    assert "nan" not in out


# ---- item 12: progress on stderr ---------------------------------------------------------------


def test_progress_goes_to_stderr_and_a_closed_stdout_does_not_stop_the_fit(tmp_path):
    output = tmp_path / "sensor.toml"
    argv = ["calibrate", str(EXCERPT), "--fit-ms", "0:40", "--parameters", "theta_on,theta_off"]
    argv += ["--max-evaluations", "6", "-o", str(output)]
    env = {**os.environ, "PYTHONPATH": PYTHON_PATH}
    process = subprocess.Popen(
        [sys.executable, "-m", "pecs", *argv],
        env=env,
        stdout=subprocess.PIPE,
        stderr=subprocess.PIPE,
    )
    assert process.stdout is not None and process.stderr is not None
    first = process.stdout.readline()  # what `| head -1` reads, then it goes away
    process.stdout.close()
    err = process.stderr.read().decode()
    process.stderr.close()
    process.wait(timeout=120)
    assert first.startswith(b"# pecs calibration")
    assert output.exists() and SensorConfig.from_file(output).width == 346
    assert err.count("] ") >= 6 and "[  1]" in err  # one progress line an evaluation
    assert "Traceback" not in err


# ---- item 13i: the budget holds; a bad budget or output is refused first --------------------------


@pytest.mark.parametrize("n", [1, 2, 4, 6])
def test_nelder_mead_never_evaluates_more_than_its_budget(n):
    target = np.linspace(0.2, 0.8, n)

    def bowl(u: np.ndarray) -> float:
        calls.append(1)
        return float(np.sum(np.abs(u - target)) + 0.1 * np.sin(20 * u).sum())

    for budget in range(n + 1, 6 * n + 12):
        calls: list[int] = []
        _, _, count = minimize(bowl, np.full(n, 0.5), max_evaluations=budget, tolerance=0.0)
        assert len(calls) == count <= budget, (n, budget)


def test_a_budget_below_the_first_simplex_is_refused():
    with pytest.raises(ValueError, match=r"max_evaluations.*3.*4"):
        minimize(lambda u: 0.0, np.full(3, 0.5), max_evaluations=3)
    frames, times = camera_frames(seed=1), frame_times(14)
    recording = Recording(frames, times, recorded_events(frames, times))
    with pytest.raises(ValueError, match=r"max_evaluations 1.*6 parameters.*at least 7"):
        calibrate(recording, (0, 200), max_evaluations=1)


def refuse_to_load(*args: object, **kwargs: object) -> Recording:
    raise AssertionError("the recording was read before the options were checked")


def test_cli_refuses_a_small_budget_before_any_work(capsys, monkeypatch, tmp_path):
    monkeypatch.setattr(Recording, "load", staticmethod(refuse_to_load))
    args = ["calibrate", str(EXCERPT), "--fit-ms", "0:40", "--max-evaluations", "1"]
    assert cli_main([*args, "-o", str(tmp_path / "s.toml")]) == 2
    err = capsys.readouterr().err
    assert "--max-evaluations 1" in err and "at least 7" in err
    assert len(err.strip().splitlines()) == 1


@pytest.mark.parametrize("where", ["a folder", "under a file"])
def test_cli_refuses_an_unwritable_output_before_any_work(capsys, monkeypatch, tmp_path, where):
    monkeypatch.setattr(Recording, "load", staticmethod(refuse_to_load))
    (tmp_path / "file.txt").write_text("not a folder")
    output = tmp_path if where == "a folder" else tmp_path / "file.txt" / "sensor.toml"
    args = ["calibrate", str(EXCERPT), "--fit-ms", "0:40", "-o", str(output)]
    assert cli_main(args) == 2
    err = capsys.readouterr().err
    assert err.startswith("pecs calibrate: error: -o ") and len(err.strip().splitlines()) == 1
    # --noise-only writes the same file: checked before the events are read, too.
    assert cli_main(["calibrate", "--noise-only", "missing.parquet", "-o", str(output)]) == 2
    assert capsys.readouterr().err.startswith("pecs calibrate: error: -o ")
