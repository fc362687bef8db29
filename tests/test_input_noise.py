"""Input noise of real footage (pecs.footage.input_noise) and the transitions between frames
(pecs.footage.frame_interpolation: each pixel's change a short transition at a random time of the
interval), against numbers set independently: known noise levels, the analytic crossing times
of an ideal log sensor, and a uniform spread of event times over the interval."""

import math

import numpy as np
import pecs
import pytest
from pecs.footage.frame_interpolation import transition_subframes
from pecs.footage.input_noise import InputDeadband, InputNoise, suppress_input_noise

SIZE = (60, 80)  # (H, W)
PERIOD_US = 40_000


def noisy_frames(levels: np.ndarray, n: int, read: float, gain: float, seed: int) -> np.ndarray:
    """n frames of `levels` (H, W) with Gaussian noise of variance read^2 + gain * level, drawn
    anew in every frame."""
    rng = np.random.default_rng(seed)
    sigma = np.sqrt(read**2 + gain * levels)
    return (levels + sigma * rng.standard_normal((n, *levels.shape))).astype(np.float32)


def test_the_noise_level_function_is_recovered_from_the_frames() -> None:
    levels = np.tile(np.linspace(0.02, 0.9, SIZE[1], dtype=np.float32), (SIZE[0], 1))
    read, gain = 0.006, 0.0004  # 1.5 DN of read noise; shot noise sigma^2 = gain * level
    noise = InputNoise.estimate(noisy_frames(levels, 16, read, gain, seed=1))
    assert abs(noise.read_sigma / read - 1) < 0.1
    assert abs(noise.shot_gain / gain - 1) < 0.1
    for level in (0.05, 0.5):
        truth = math.sqrt(read**2 + gain * level)
        assert abs(noise.sigma(np.array([level]))[0] / truth - 1) < 0.05


def test_moving_pixels_do_not_inflate_the_estimate() -> None:
    # Every tenth column, at every level, jumps by 0.3 each frame (edges passing): outliers in
    # each level bin, cut off by the robust spread.
    levels = np.tile(np.linspace(0.02, 0.6, SIZE[1], dtype=np.float32), (SIZE[0], 1))
    frames = noisy_frames(levels, 16, 0.005, 0.0, seed=2)
    frames[:, :, ::10] += 0.3 * (np.arange(16) % 2)[:, None, None]
    noise = InputNoise.estimate(frames)
    assert abs(noise.sigma(np.array([0.3]))[0] / 0.005 - 1) < 0.1


def test_a_small_sensor_still_gets_its_noise_estimated() -> None:
    # 8 x 8 pixels over 16 frames: 960 differences, too few for 16 level bins of 200, enough
    # for 4. Before, no bin was filled and the estimate came out as no noise at all.
    levels = np.tile(np.linspace(0.1, 0.8, 8, dtype=np.float32), (8, 1))
    noise = InputNoise.estimate(noisy_frames(levels, 16, 0.01, 0.0, seed=4))
    assert abs(noise.sigma(np.array([0.4]))[0] / 0.01 - 1) < 0.15
    # So a band of 100 sigma (1.0 and more, past the 0.7 span of the levels) holds every pixel
    # still: the sensor sees no change at all.
    config = pecs.SensorConfig.preset("esim", width=8, height=8, theta_on=0.01, theta_off=0.01)
    frames = noisy_frames(levels, 20, 0.01, 0.0, seed=5)
    times = np.arange(20, dtype=np.int64) * PERIOD_US
    assert pecs.frames_to_events(frames, times, config).num_rows > 100  # the raw noise fires
    assert pecs.frames_to_events(frames, times, config, deadband_sigmas=100.0).num_rows == 0


def test_too_few_pixels_to_estimate_the_noise_is_said_not_passed_over() -> None:
    frames = noisy_frames(np.full((4, 4), 0.5, np.float32), 3, 0.01, 0.0, seed=6)  # 32 diffs
    with pytest.warns(UserWarning, match="fewer than the 200 needed"):
        noise = InputNoise.estimate(frames)
    assert noise.read_sigma == 0.0 and noise.shot_gain == 0.0


def events_of(frames: np.ndarray, config: pecs.SensorConfig) -> np.ndarray:
    times = np.arange(len(frames), dtype=np.int64) * PERIOD_US
    return pecs.frames_to_events(frames, times, config)


def test_constant_frames_with_noise_give_no_events_once_held_back() -> None:
    # Dark pixels (0.05) with noise of 0.01: log changes of ~0.3, beyond theta = 0.2.
    config = pecs.SensorConfig.preset("ideal", width=SIZE[1], height=SIZE[0])
    frames = noisy_frames(np.full(SIZE, 0.05, np.float32), 50, 0.01, 0.0, seed=3)
    assert events_of(frames, config).num_rows > 1000  # what the noise does unfiltered
    times = np.arange(len(frames)) * PERIOD_US
    held = np.stack([f for _, f in suppress_input_noise(zip(times, frames))])
    assert events_of(held, config).num_rows == 0
    assert np.all(held == held[0])


def test_a_step_above_the_noise_keeps_its_events_and_their_times() -> None:
    # 0.2 -> 0.7 between frames 9 and 10, noise 0.002 (1 % of 0.2): an ideal log sensor
    # crosses ln(0.7 / 0.2) / theta = 6.26 (+-0.05) -> 6 levels, the k-th at k theta / ln(3.5)
    # of the interval.
    theta = 0.2
    levels = np.full((10, *SIZE), 0.2, np.float32)
    step = np.concatenate([levels, np.full((10, *SIZE), 0.7, np.float32)])
    frames = step + np.random.default_rng(4).normal(0, 0.002, step.shape).astype(np.float32)
    stated = InputNoise(read_sigma=0.002)
    times = np.arange(len(frames)) * PERIOD_US
    held = np.stack([f for _, f in suppress_input_noise(zip(times, frames), stated)])
    config = pecs.SensorConfig.preset("ideal", width=SIZE[1], height=SIZE[0], dark_current=1e-6)
    table = events_of(held, config)
    t = table["t"].to_numpy()
    per_pixel = np.bincount(table["y"].to_numpy().astype(int) * SIZE[1] + table["x"].to_numpy())
    assert np.all(per_pixel == 6), np.unique(per_pixel, return_counts=True)
    assert np.all(table["p"].to_numpy() == 1)
    phase = (t - 9 * PERIOD_US) / PERIOD_US  # all within the step's interval
    k = np.tile(np.arange(1, 7), SIZE[0] * SIZE[1])
    order = np.lexsort((t, table["x"].to_numpy(), table["y"].to_numpy()))
    expected = k * theta / math.log(3.5)
    # The frames' noise moves the step D = ln 3.5 by d, at most 4.5 sqrt(0.01^2 + 0.0029^2) =
    # 0.047 over 28,800 events, and the k-th crossing by (k theta / D) d / D <= 0.036.
    assert np.max(np.abs(phase[order] - expected)) < 0.036


def test_the_deadband_follows_the_level_dependent_sigma() -> None:
    # Band: 4 sigma(level) sqrt(1 + 1/n) around the mean of the n frames held (n = 1 here),
    # sigma^2 = 0.01^2 + 0.01 level.
    deadband = InputDeadband(InputNoise(read_sigma=0.01, shot_gain=0.01, deadband_sigmas=4.0))
    first = np.array([[0.1, 0.99]], np.float32)
    band = 4 * np.sqrt(0.01**2 + 0.01 * first) * math.sqrt(2)
    deadband(first)
    assert np.array_equal(deadband(first + 0.9 * band), first)  # inside both bands: held
    # Now n = 2 and the mean is first + 0.45 band: leaving it by 1.1 of the new band moves.
    mean = first + 0.45 * band
    new_band = 4 * np.sqrt(0.01**2 + 0.01 * mean) * math.sqrt(1.5)
    moved = (mean + 1.1 * new_band).astype(np.float32)
    np.testing.assert_array_equal(deadband(moved), moved)


@pytest.mark.parametrize("bad", [-1.0, float("nan")])
def test_a_stated_noise_must_be_a_number_at_least_zero(bad: float) -> None:
    with pytest.raises(ValueError, match="read_sigma"):
        InputNoise(read_sigma=bad)


def test_input_noise_is_on_by_default_for_camera_footage_only(tmp_path) -> None:  # noqa: ANN001
    # An .npy array may be rendered: no filter unless asked; asked, the noise goes.
    frames = noisy_frames(np.full(SIZE, 0.05, np.float32), 20, 0.01, 0.0, seed=5)
    path = tmp_path / "frames.npy"
    np.save(path, frames)
    config = pecs.SensorConfig.preset("ideal", width=SIZE[1], height=SIZE[0])
    raw = pecs.frames_to_file(path, tmp_path / "raw.parquet", config, fps=25.0)
    held = pecs.frames_to_file(path, tmp_path / "h.parquet", config, fps=25.0, input_noise=True)
    assert raw["events"] > 1000 and held["events"] == 0


@pytest.mark.parametrize(
    ("options", "message"),
    [
        ({"input_noise": False}, "cannot go with input_noise=False"),
        ({"input_noise": InputNoise(0.01)}, "a stated InputNoise carries its own"),
        ({"deadband_sigmas_value": -1.0}, "deadband_sigmas: must be a finite number >= 0"),
        ({"deadband_sigmas_value": float("nan")}, "deadband_sigmas: must be a finite number >= 0"),
    ],
)
def test_a_deadband_where_it_cannot_apply_is_refused(options: dict, message: str, tmp_path) -> None:  # noqa: ANN001
    frames = np.full((3, *SIZE), 0.05, np.float32)
    config = pecs.SensorConfig.preset("ideal", width=SIZE[1], height=SIZE[0])
    k = options.get("deadband_sigmas_value", 3.0)
    options = {name: value for name, value in options.items() if name != "deadband_sigmas_value"}
    with pytest.raises(ValueError, match=message):
        pecs.frames_to_events(frames, [0, 40_000, 80_000], config, deadband_sigmas=k, **options)
    path = tmp_path / "frames.npy"
    np.save(path, frames)
    out = tmp_path / "events.parquet"
    with pytest.raises(ValueError, match=message):
        pecs.frames_to_file(path, out, config, fps=25.0, deadband_sigmas=k, **options)
    assert not out.exists()


def test_camera_footage_in_8_bit_has_its_black_lifted_as_the_readers_do() -> None:
    # Code 0 of an 8-bit sRGB frame is light below one code: half a code, 0.5 / 255, decoded by
    # IEC 61966-2-1's linear segment (/ 12.92), as videos and AEDAT4 frames are read. A pixel
    # going from code 0 to code 2 (6.07e-4) then steps by ln((6.07e-4 + d) / (1.52e-4 + d)) =
    # 0.33 in log with the ideal preset's dark current d = 1e-3 (one 0.2 event), not by
    # ln((6.07e-4 + d) / d) = 0.47 (two) from its dark current alone.
    codes = np.zeros((2, *SIZE), np.uint8)
    codes[1, :, : SIZE[1] // 2] = 2
    times = [0, 40_000]
    config = pecs.SensorConfig.preset("ideal", width=SIZE[1], height=SIZE[0])
    linear = codes.astype(np.float32) / np.float32(255.0 * 12.92)
    lifted = np.maximum(linear, np.float32(0.5 / 255.0 / 12.92))
    as_footage = pecs.frames_to_events(
        codes, times, config, camera_footage=True, input_noise=False, interpolation="linear"
    )
    expected = pecs.frames_to_events(lifted, times, config)
    assert as_footage.num_rows == expected.num_rows > 0
    for name in ("t", "x", "y", "p"):
        np.testing.assert_array_equal(as_footage[name].to_numpy(), expected[name].to_numpy())
    rendered = pecs.frames_to_events(codes, times, config)  # not footage: zeros stay zeros
    assert rendered.num_rows > as_footage.num_rows


# ---------------------------------------------------------------- transitions between frames


def log_of(pairs: list, offset: float) -> tuple[np.ndarray, np.ndarray]:
    t = np.array([p[0] for p in pairs], np.int64)
    return t, np.log(np.stack([p[1] for p in pairs]).astype(np.float64) + offset)


def test_a_transition_lasts_its_fraction_and_is_centred_anywhere_in_the_interval() -> None:
    # 0.1 -> 0.4: each pixel moves monotonically from 0.1 to 0.4 within a quarter of the
    # interval (4 sub-steps of 16); the time it passes half way (in log) is uniform over it.
    offset, n = 1e-3, 4000
    frames = [np.full((1, n), 0.1, np.float32), np.full((1, n), 0.4, np.float32)]
    pairs = list(transition_subframes(zip([0, 16_000], frames), offset, transition=0.25, seed=3))
    t, u = log_of(pairs, offset)
    assert len(pairs) == 17
    u = u[:, 0, :]  # (17 times, n pixels)
    assert np.all(np.diff(u, axis=0) >= -1e-9)
    moving = (u > u[0] + 1e-9) & (u < u[-1] - 1e-9)
    assert np.all(moving.sum(axis=0) <= 4)
    half = 0.5 * (u[0] + u[-1])
    centres = np.array([np.interp(h, u[:, i], t) for i, h in enumerate(half)]) / 16_000
    counts = np.histogram(centres, bins=8, range=(0, 1))[0]
    assert np.all(np.abs(counts / (n / 8) - 1) < 0.15), counts


def test_transitions_spread_events_evenly_over_the_interval() -> None:
    # Pixels whose change only just crosses a level (d / delta = 0.95): linear interpolation
    # puts every event in the last 5 % of the interval; transitions spread them out.
    theta, offset, n = 0.2, 1e-3, 4000
    config = pecs.SensorConfig.preset("ideal", width=n, height=1, dark_current=offset)
    before = np.full((1, n), 0.2, np.float32)
    after = ((0.2 + offset) * math.exp(theta / 0.95) - offset) * np.ones((1, n), np.float32)
    times = np.array([0, PERIOD_US], np.int64)
    linear = pecs.frames_to_events([before, after], times, config)["t"].to_numpy()
    pairs = list(transition_subframes(zip(times, [before, after]), offset, seed=1))
    spread = pecs.frames_to_events(
        [p[1] for p in pairs], np.array([p[0] for p in pairs], np.int64), config
    )["t"].to_numpy()
    assert len(linear) == len(spread) == n  # the same crossings
    assert np.all(linear > 0.94 * PERIOD_US)
    # The crossing comes at 0.95 of a transition of 0.25 centred on c ~ U(0, 1): at
    # c + 0.1125, uniform on [0.1125, 1], with the 11 % of c > 0.8875 cut to the interval's
    # last sub-step (1/16).
    phase = spread / PERIOD_US
    assert phase.min() > 0.1125 - 0.01
    assert abs(np.mean(phase > 15 / 16) - (0.1125 + 1 / 16)) < 0.03
    counts = np.histogram(phase, bins=3, range=(0.1125, 0.8875))[0]
    assert np.all(np.abs(counts / n - 0.775 / 3) < 0.025), counts
