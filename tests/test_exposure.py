"""APS exposure undone (pecs.footage.exposure): frames that are box averages of a light linear
between the frame times give back its values there, a sinusoid comes back with the gain the
linear model predicts in closed form; exposure 0 leaves the events unchanged, bit for bit; the
recorded exposures of an AEDAT4 file are those dv-processing reads."""

import math
from datetime import timedelta
from pathlib import Path

import dv_processing as dv
import numpy as np
import pecs
import pytest
from pecs.cli import main as pecs_main
from pecs.footage.exposure import CLAMP_FACTOR, deconvolve, exposure_deconvolved

DATA = Path(__file__).parent / "data"
EMLB = DATA / "davis346_emlb_excerpt" / "davis346_emlb_3frames.aedat4"


def piecewise_linear_box_mean(
    times: np.ndarray, nodes: np.ndarray, start: float, end: float
) -> np.ndarray:
    """Mean over [start, end] of the light linear between (times, nodes), constant beyond the
    ends: the trapezoid rule on a grid holding every breakpoint, exact for such a function."""
    inside = times[(times > start) & (times < end)]
    grid = np.concatenate([[start], inside, [end]]).astype(np.float64)
    values = np.stack([np.interp(grid, times, node) for node in nodes.reshape(len(times), -1).T])
    integral = np.sum((values[:, 1:] + values[:, :-1]) * np.diff(grid) / 2, axis=1)
    return (integral / (end - start)).reshape(nodes.shape[1:])


def test_the_light_at_the_frame_times_comes_back_from_exposures_of_a_piecewise_linear_light():
    rng = np.random.default_rng(3)
    times = np.cumsum(rng.integers(30_000, 50_000, size=12)).astype(np.int64)
    # Values within a factor 2 of their neighbours: the clamp does not bind.
    nodes = rng.uniform(1.0, 1.9, size=(12, 3, 4))
    gaps = np.diff(times)
    shortest = np.minimum(np.r_[gaps[:1], gaps], np.r_[gaps, gaps[-1:]])
    exposures = shortest * rng.uniform(0.0, 1.0, size=12)  # up to the whole frame interval
    frames = np.stack(
        [
            piecewise_linear_box_mean(times, nodes, t - e / 2, t + e / 2)
            for t, e in zip(times, exposures, strict=True)
        ]
    )
    assert np.max(np.abs(frames - nodes)) > 0.05  # the exposure moved the frames
    np.testing.assert_allclose(deconvolve(frames, times, exposures), nodes, rtol=1e-12)


def test_a_sinusoid_comes_back_with_the_gain_of_its_box_average_over_the_linear_model():
    # L = 1 + 0.3 sin(w t). A frame exposed for E averages it to 1 + 0.3 sinc(w E / 2) sin(w t_k).
    # Linear in time between frames h apart, a sinusoid of the nodes has box averages
    # 1 - (E / 4h)(1 - cos(w h)) times its amplitude (the hat weights E/8h, 1 - E/4h, E/8h):
    # the nodes are the frames' sinusoid divided by that gain, far from the sequence's ends.
    h, count = 40_000, 80
    times = np.arange(count, dtype=np.int64) * h
    for period_frames, fraction in ((10.0, 1.0), (6.0, 0.5), (25.0, 0.25)):
        w = 2 * math.pi / (period_frames * h)
        e = fraction * h
        sinc = math.sin(w * e / 2) / (w * e / 2)
        frames = 1.0 + 0.3 * sinc * np.sin(w * times)
        gain = 1.0 - fraction / 4 * (1.0 - math.cos(w * h))
        light = deconvolve(frames[:, None], times, np.full(count, e))[:, 0]
        expected = 1.0 + 0.3 * sinc / gain * np.sin(w * times)
        np.testing.assert_allclose(light[20:-20], expected[20:-20], atol=1e-10)


def test_constant_light_stays_constant_whatever_the_exposure():
    times = np.arange(10, dtype=np.int64) * 40_000
    frames = np.full((10, 2, 2), 0.37)
    out = deconvolve(frames, times, np.full(10, 40_000.0))
    np.testing.assert_allclose(out, 0.37, rtol=1e-14)


def test_a_step_is_kept_within_the_clamp_of_the_frames_around_it():
    # Dark then bright: the inverse rings below the dark level before the step; the clamp keeps
    # every value within CLAMP_FACTOR of the range of the three frames around it.
    times = np.arange(8, dtype=np.int64) * 40_000
    frames = np.array([0.01] * 4 + [1.0] * 4)[:, None]
    out = deconvolve(frames, times, np.full(8, 40_000.0))[:, 0]
    assert np.all(out > 0)
    assert out[3] >= 0.01 / CLAMP_FACTOR - 1e-15 and out[4] <= 1.0 * CLAMP_FACTOR + 1e-15
    # The exact inverse (dense solve of the hat weights 1/8, 3/4, 1/8; 7/8 at the ends, the
    # light constant beyond them) goes negative before the step: the clamp holds it there.
    matrix = (
        np.diag(np.full(8, 0.75)) + np.diag(np.full(7, 0.125), 1) + np.diag(np.full(7, 0.125), -1)
    )
    matrix[0, 0] = matrix[-1, -1] = 0.875
    exact = np.linalg.solve(matrix, frames[:, 0])
    assert exact[3] < 0 < exact[2]
    assert out[3] == pytest.approx(0.01 / CLAMP_FACTOR)
    # Everywhere: the exact inverse held within the range of the frames k-1..k+1 (k-1 and k+1
    # taken as k at the ends), widened by CLAMP_FACTOR.
    f = frames[:, 0]
    around = [f[max(k - 1, 0) : k + 2] for k in range(8)]
    low = np.array([a.min() for a in around]) / CLAMP_FACTOR
    high = np.array([a.max() for a in around]) * CLAMP_FACTOR
    np.testing.assert_allclose(out, np.clip(exact, low, high), rtol=1e-12)


def test_streaming_in_blocks_gives_the_whole_solve():
    rng = np.random.default_rng(5)
    times = np.arange(150, dtype=np.int64) * 40_000
    frames = rng.uniform(0.4, 0.6, size=(150, 3, 5)).astype(np.float32)
    whole = deconvolve(frames, times, np.full(150, 30_000.0)).astype(np.float32)
    streamed = list(exposure_deconvolved(zip(times.tolist(), frames), 30_000.0, block=7))
    assert [t for t, _ in streamed] == times.tolist()
    np.testing.assert_allclose(np.stack([f for _, f in streamed]), whole, rtol=1e-6)


def moving_edge(count: int = 12) -> tuple[np.ndarray, np.ndarray]:
    times = np.arange(count, dtype=np.int64) * 40_000
    x = np.arange(16)[None, None, :]
    frames = 0.1 + 0.8 / (1 + np.exp(-(x - 2.0 - np.arange(count)[:, None, None])))
    return times, np.broadcast_to(frames, (count, 8, 16)).astype(np.float32).copy()


def test_exposure_zero_or_none_gives_todays_events_bit_for_bit():
    times, frames = moving_edge()
    config = pecs.SensorConfig.preset("davis346", width=16, height=8, seed=1)
    today = pecs.frames_to_events(frames, times, config)
    assert today.num_rows > 0
    for given in (None, 0, 0.0):
        assert pecs.frames_to_events(frames, times, config, exposure_us=given).equals(today)
    # A real exposure changes the light the sensor sees.
    exposed = pecs.frames_to_events(frames, times, config, exposure_us=20_000)
    assert not exposed.equals(today)


def test_bad_exposures_are_refused_with_the_reason():
    times, frames = moving_edge()
    config = pecs.SensorConfig.preset("ideal", width=16, height=8)
    with pytest.raises(ValueError, match="longer than its frame interval"):
        pecs.frames_to_events(frames, times, config, exposure_us=40_001)
    with pytest.raises(ValueError, match="finite time >= 0"):
        pecs.frames_to_events(frames, times, config, exposure_us=-5)
    with pytest.raises(ValueError, match="finite time >= 0"):
        pecs.frames_to_events(frames, times, config, exposure_us=float("nan"))
    with pytest.raises(ValueError, match="one per frame"):
        pecs.frames_to_events(frames, times, config, exposure_us=[10_000] * 3)
    with pytest.raises(TypeError, match="exposure_us"):
        pecs.frames_to_events(frames, times, config, exposure_us="auto")


def test_an_aedat4_files_recorded_exposures_are_read_as_dv_processing_reads_them(tmp_path):
    recording = dv.io.MonoCameraRecording(str(EMLB))
    expected = []
    while (frame := recording.getNextFrame()) is not None:
        expected.append(frame.exposure // timedelta(microseconds=1))
    assert expected == [20_000] * 3
    source = pecs.open_frames(EMLB)
    list(source)
    assert source.exposures_us == expected
    config = pecs.SensorConfig.preset("davis346", width=346, height=260, seed=0)
    none = pecs.frames_to_file(EMLB, tmp_path / "none.parquet", config, exposure_us="none")
    auto = pecs.frames_to_file(EMLB, tmp_path / "auto.parquet", config, exposure_us="auto")
    stated = pecs.frames_to_file(EMLB, tmp_path / "stated.parquet", config, exposure_us=20_000)
    assert auto["events"] == stated["events"] != none["events"]
    assert pecs.read_events(tmp_path / "auto.parquet").equals(
        pecs.read_events(tmp_path / "stated.parquet")
    )
    with pytest.raises(ValueError, match="'auto', 'none' or a number"):
        pecs.frames_to_file(EMLB, tmp_path / "bad.parquet", config, exposure_us="sometimes")


def test_frames2events_exposure_auto_writes_what_the_api_gives(tmp_path, capsys):
    config = pecs.SensorConfig.preset("davis346", width=346, height=260)
    pecs.frames_to_file(EMLB, tmp_path / "api.parquet", config, exposure_us=20_000)
    cli = tmp_path / "cli.parquet"
    args = ["frames2events", str(EMLB), "--preset", "davis346", "-o", str(cli), "--quiet"]
    assert pecs_main([*args, "--exposure", "auto"]) == 0
    assert pecs.read_events(cli).equals(pecs.read_events(tmp_path / "api.parquet"))
    with pytest.raises(SystemExit):
        pecs_main([*args, "--exposure", "-3"])
    assert "expected none, auto or a number of microseconds" in capsys.readouterr().err


def test_a_recording_for_calibration_carries_the_exposures_asked_for(tmp_path, monkeypatch):
    from pecs.calibration.fit import Recording

    assert Recording.load(EMLB).exposure_us is None
    auto = Recording.load(EMLB, exposure="auto")
    np.testing.assert_array_equal(auto.exposure_us, [20_000.0] * 3)
    window = (int(auto.times_us[0]), int(auto.times_us[-1]))
    config = pecs.SensorConfig.preset("davis346", width=346, height=260, seed=0)
    stated = pecs.frames_to_events(
        auto.frames,
        auto.times_us,
        config,
        camera_footage=True,
        input_noise=auto.input_noise(0, 2),
        exposure_us=20_000,
    )
    assert auto.simulate(config, window).equals(stated)
    # `pecs calibrate --exposure auto` fits on the same recording.
    seen = []
    load = Recording.load

    def recording(path, interpolation="auto", exposure="none"):
        seen.append(exposure)
        return load(path, interpolation=interpolation, exposure=exposure)

    monkeypatch.setattr(Recording, "load", staticmethod(recording))
    args = ["calibrate", str(EMLB), "--fit-ms", "0:80", "--parameters", "theta_on", "--quiet"]
    args += ["--max-evaluations", "2", "--no-profile", "--exposure", "auto"]
    assert pecs_main([*args, "-o", str(tmp_path / "sensor.toml")]) == 0
    assert seen == ["auto"]
