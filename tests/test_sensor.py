"""The pixel model against numbers derived independently: analytic cases, an independent ESIM
implementation in numpy, and the statistics of the documented noise laws."""

import math
import re
import subprocess
import sys

import numpy as np
import pecs
import pytest
from pecs import SensorConfig


def ideal(width=1, height=1, **overrides):
    return SensorConfig.preset("ideal", width=width, height=height, **overrides)


def photocurrent_for_log(log_total, dark):
    """Frame value whose log(I + dark) is `log_total`."""
    return np.exp(log_total) - dark


def per_pixel(table):
    """{(x, y): [(t, p, label?), ...]} in time order."""
    d = table.to_pydict()
    out = {}
    for i in range(table.num_rows):
        out.setdefault((d["x"][i], d["y"][i]), []).append(
            (d["t"][i], d["p"][i], d.get("label", [None] * (i + 1))[i])
        )
    return out


# ---------------------------------------------------------------- exact timing


@pytest.mark.parametrize("direction", [+1, -1])
def test_ideal_log_ramp_gives_floor_d_over_theta_events_at_the_analytic_times(direction):
    theta_on, theta_off = 0.17, 0.23
    cfg = ideal(theta_on=theta_on, theta_off=theta_off)
    D, T_us, L0 = 1.37, 10_000, math.log(0.3)
    times = np.arange(0, T_us + 1, 1000)
    logs = L0 + direction * D * times / T_us  # linear in log at every frame: an exact ramp
    frames = [np.full((1, 1), photocurrent_for_log(L, cfg.dark_current), np.float32) for L in logs]
    table = pecs.frames_to_events(frames, times, cfg)
    theta = theta_on if direction > 0 else theta_off
    n = math.floor(D / theta)
    assert table.num_rows == n
    expected_t = np.array([k * theta / D * T_us for k in range(1, n + 1)])
    got = np.array(table["t"])
    # float32 frames carry ~1e-7 relative error in I: a few ns of timing at this slope.
    assert np.max(np.abs(got - expected_t)) <= 1.0
    assert set(np.array(table["p"])) == {1 if direction > 0 else 0}


def test_lin_log_below_the_knee_is_linear_in_photocurrent():
    knee = 0.2
    cfg = ideal(lin_log_knee=knee, dark_current=0.0, theta_on=0.1)
    # Response below the knee: ln(k) + (I - k) / k, so I rising by 0.95 k crosses
    # floor(0.95 / 0.1) = 9 thresholds, at equal steps of 0.1 k in I.
    times = np.arange(0, 9001, 100)
    values = 0.02 * knee + 0.95 * knee * times / 9000.0
    assert values.max() < knee
    frames = [np.full((1, 1), v, np.float32) for v in values]
    table = pecs.frames_to_events(frames, times, cfg)
    assert table.num_rows == 9
    expected_t = np.arange(1, 10) * 0.1 / 0.95 * 9000
    assert np.max(np.abs(np.array(table["t"]) - expected_t)) <= 1


# ---------------------------------------------------------------- ESIM equivalence


def esim_reference(frames, times_us, c_pos, c_neg, eps, refractory_us):
    """ESIM (Rebecq et al. 2018), written independently: linear interpolation of log(I + eps)
    between frames, each crossing of ref +- C emits at the interpolated time, the reference
    advances by C per crossing; inside the refractory period an event is dropped but the
    reference still advances."""
    log_frames = [np.log(f.astype(np.float64) + eps) for f in frames]
    ref = log_frames[0].copy()
    last_t = np.full(ref.shape, -np.inf)
    events = []
    for k in range(1, len(frames)):
        it, itdt = log_frames[k - 1], log_frames[k]
        t0, dt = times_us[k - 1], times_us[k] - times_us[k - 1]
        for (y, x), a in np.ndenumerate(it):
            b = itdt[y, x]
            if b == a:
                continue
            pol = 1 if b >= a else -1
            c = c_pos if pol > 0 else c_neg
            cross = ref[y, x]
            while True:
                cross += pol * c
                if (pol > 0 and a < cross <= b) or (pol < 0 and b <= cross < a):
                    t = t0 + (cross - a) * dt / (b - a)
                    if t - last_t[y, x] >= refractory_us:
                        events.append((t, x, y, 1 if pol > 0 else 0))
                        last_t[y, x] = t
                    ref[y, x] = cross
                else:
                    break
    return events


def test_esim_preset_matches_an_independent_esim_on_a_random_sequence():
    rng = np.random.default_rng(4)
    h, w, n = 12, 16, 25
    base = rng.uniform(0.05, 1.0, (h, w))
    frames = [
        np.clip(base * np.exp(rng.normal(0, 0.35, (h, w))), 0, None).astype(np.float32)
        for _ in range(n)
    ]
    frames[3][2:5, :] = 0.0  # exact zeros exercise eps
    times = np.cumsum(rng.integers(500, 4000, n))
    refractory_us = 700.0
    cfg = SensorConfig.preset(
        "esim", width=w, height=h, theta_on=0.2, theta_off=0.25, refractory_us=refractory_us
    )
    table = pecs.frames_to_events(frames, times, cfg)
    reference = esim_reference(frames, times, 0.2, 0.25, cfg.dark_current, refractory_us)
    assert table.num_rows == len(reference) > 1000
    ours = per_pixel(table)
    theirs = {}
    for t, x, y, p in sorted(reference):
        theirs.setdefault((x, y), []).append((t, p))
    assert ours.keys() == theirs.keys()
    for key, evs in theirs.items():
        got = ours[key]
        assert [p for _, p, _ in got] == [p for _, p in evs], key
        assert max(abs(g[0] - e[0]) for g, e in zip(got, evs)) <= 1.0, key


# ---------------------------------------------------------------- refractory, latency, order


def noisy_sequence(h=40, w=50, n=30, seed=0):
    rng = np.random.default_rng(seed)
    base = rng.uniform(0.05, 1.0, (h, w))
    frames = [(base * np.exp(rng.normal(0, 0.4, (h, w)))).astype(np.float32) for _ in range(n)]
    return frames, np.cumsum(rng.integers(200, 3000, n))


@pytest.mark.parametrize("reset", ["refractory_end", "event"])
def test_no_two_events_of_a_pixel_closer_than_the_refractory_period(reset):
    frames, times = noisy_sequence()
    cfg = SensorConfig.preset(
        "davis346",
        width=50,
        height=40,
        refractory_us=800.0,
        jitter_us=0.0,
        reference_reset=reset,
        shot_rate_hz=200.0,
    )
    table = pecs.frames_to_events(frames, times, cfg)
    assert table.num_rows > 500
    gaps = [np.diff([t for t, _, _ in evs]) for evs in per_pixel(table).values() if len(evs) > 1]
    assert min(g.min() for g in gaps) >= 800


def test_batches_are_sorted_and_latency_spills_into_flush():
    frames, times = noisy_sequence(seed=2)
    plain = SensorConfig.preset("davis346", width=50, height=40, latency_us=0.0, jitter_us=0.0)
    delayed = plain.replace(latency_us=2500.0, jitter_us=300.0)
    sensor = pecs.EventSensor(delayed)
    batches = [sensor.feed(f, int(t)) for f, t in zip(frames, times)]
    tail = sensor.flush()
    assert tail.num_rows > 0  # the last frame's events arrive after it
    last = -1
    for prev_t, batch in zip([None, *times], [*batches, tail]):
        t = np.array(batch["t"])
        keys = (
            np.array(batch["t"], np.int64) * 2**32
            + np.array(batch["y"], np.int64) * 2**16
            + np.array(batch["x"])
        )
        assert np.all(np.diff(keys) >= 0)
        if t.size:
            assert t[0] >= last
            last = t[-1]
        if prev_t is not None and t.size and batch is not tail:
            assert t[0] > prev_t
    total = sum(b.num_rows for b in batches) + tail.num_rows
    # Latency moves events, it does not change which events happen.
    assert total == pecs.frames_to_events(frames, times, plain).num_rows


# ---------------------------------------------------------------- noise laws


def static_run(cfg, value, duration_s, frames=11):
    times = np.linspace(0, duration_s * 1e6, frames).astype(np.int64)
    frame = np.full((cfg.height, cfg.width), value, np.float32)
    return pecs.frames_to_events([frame] * frames, times, cfg)


def test_leak_rate_matches_its_expectation_on_a_static_scene():
    cfg = ideal(200, 200, leak_rate_hz=1.0, leak_spread_decades=0.3, labels=True, seed=5)
    table = static_run(cfg, 0.5, 10.0)
    expected = 200 * 200 * 10.0 * 1.0  # leak_rate_hz is the mean over pixels
    assert abs(table.num_rows / expected - 1) < 0.03
    assert set(np.array(table["label"])) == {1}
    assert set(np.array(table["p"])) == {1}  # leakage drives the reference down: ON events


def light_columns(cfg, currents, duration_s, frames=5):
    """Events of a static scene whose columns of pixels sit at each of `currents` in turn."""
    frame = np.zeros((cfg.height, cfg.width), np.float32)
    for i, current in enumerate(currents):
        frame[:, i :: len(currents)] = current
    times = np.linspace(0, duration_s * 1e6, frames).astype(np.int64)
    return pecs.frames_to_events([frame] * frames, times, cfg)


def events_per_column(table, n_columns):
    return np.bincount(np.array(table["x"]) % n_columns, minlength=n_columns)


def test_shot_noise_follows_its_documented_law():
    # r(x) = shot_rate_hz * dark / x, x = I + dark: the inverse of the light (IEBCS's data).
    currents = (0.0, 0.009, 0.099, 0.999)
    cfg = ideal(200, 100, shot_rate_hz=100.0, dark_current=1e-3, labels=True, seed=9)
    table = light_columns(cfg, currents, 2.0)
    counts = events_per_column(table, len(currents))
    for count, current in zip(counts, currents):
        expected = 100.0 * 1e-3 / (current + 1e-3) * (200 * 100 / len(currents)) * 2.0
        assert abs(count - expected) < 4 * math.sqrt(expected) + 0.01 * expected, (current, count)
    assert set(np.array(table["label"])) == {2}
    assert abs(np.mean(np.array(table["p"])) - 0.5) < 0.02


@pytest.mark.parametrize("white_lux", [1000.0, 10_000.0])
def test_leak_rate_follows_the_light(white_lux):
    # Mean over pixels r(x) = leak_rate_hz + leak_light_rate_hz * x, x = I * white_lux / 1000
    # + dark: junction leakage plus the reset switch's parasitic photocurrent.
    currents = (0.0, 0.1, 0.4, 1.0)
    cfg = ideal(
        200, 200, leak_rate_hz=0.5, leak_light_rate_hz=4.0, leak_spread_decades=0.2,
        white_lux=white_lux, labels=True, seed=4,
    )  # fmt: skip
    duration_s = 10.0
    table = light_columns(cfg, currents, duration_s)
    counts = events_per_column(table, len(currents))
    for count, current in zip(counts, currents):
        x = current * white_lux / 1000 + cfg.dark_current
        expected = (0.5 + 4.0 * x) * (200 * 200 / len(currents)) * duration_s
        # Each pixel's count is floor(phase + rate * T): within one event per pixel of rate T.
        assert abs(count - expected) < 0.02 * expected + 0.5 * 200 * 200 / len(currents)
        assert abs(count / expected - 1) < 0.05, (current, count, expected)
    assert set(np.array(table["label"])) == {1}


def test_leak_period_changes_when_the_light_does():
    # A pixel leaking at r(x) crosses every 1 / r(x) seconds: 1 Hz in the dark part, then 9 Hz
    # after the light steps to x = 2 at 5 s (leak 1 + 4 x). Counts in each part follow the rate.
    cfg = ideal(100, 100, leak_rate_hz=1.0, leak_light_rate_hz=4.0, dark_current=1e-6, seed=2)
    dark = np.zeros((100, 100), np.float32)
    bright = np.full((100, 100), 2.0, np.float32)
    times = np.array([0, 5_000_000, 5_000_001, 10_000_000], np.int64)
    table = pecs.frames_to_events([dark, dark, bright, bright], times, cfg)
    t = np.array(table["t"])
    p = np.array(table["p"])
    before, after = (t <= 5_000_000) & (p == 1), (t > 5_000_001) & (p == 1)
    assert abs(np.count_nonzero(before) / (100 * 100 * 5 * 1.0) - 1) < 0.03
    assert abs(np.count_nonzero(after) / (100 * 100 * 5 * 9.0) - 1) < 0.03


def test_white_lux_scales_the_photocurrent_that_noise_and_bandwidth_see():
    # Frame value 0.05 at 10 klux white is photocurrent 0.5: the shot rate is that of x = 0.5.
    cfg = ideal(200, 100, shot_rate_hz=100.0, dark_current=1e-3, white_lux=10_000.0, seed=6)
    table = static_run(cfg, 0.05, 2.0)
    expected = 100.0 * 1e-3 / (0.5 + 1e-3) * 200 * 100 * 2.0
    assert abs(table.num_rows - expected) < 4 * math.sqrt(expected) + 0.01 * expected
    with pytest.raises(ValueError, match="white_lux"):
        ideal(white_lux=0.0)


def test_hot_pixels_follow_their_fraction_and_rate():
    cfg = ideal(200, 200, hot_pixel_fraction=0.01, hot_pixel_rate_hz=20.0, labels=True, seed=3)
    table = static_run(cfg, 0.5, 5.0)
    pixels = set(zip(np.array(table["x"]).tolist(), np.array(table["y"]).tolist()))
    n = 200 * 200
    assert abs(len(pixels) - 0.01 * n) < 4 * math.sqrt(n * 0.01 * 0.99)
    assert abs(table.num_rows / (len(pixels) * 20.0 * 5.0) - 1) < 0.03
    assert set(np.array(table["label"])) == {3}


# ---------------------------------------------------------------- mismatch and bandwidth


@pytest.mark.parametrize("polarity", ["on", "off"])
def test_threshold_mismatch_spread_matches_theta_sigma(polarity):
    # A log ramp of slope g reaches a pixel's threshold at t = theta_i / g: timing reads theta_i.
    sigma, slope_per_s = 0.03, 0.5
    cfg = ideal(200, 200, theta_sigma=sigma, seed=11)
    sign = 1 if polarity == "on" else -1
    f0 = np.full((200, 200), photocurrent_for_log(math.log(0.5), cfg.dark_current), np.float32)
    f1 = np.full(
        (200, 200),
        photocurrent_for_log(math.log(0.5) + sign * slope_per_s, cfg.dark_current),
        np.float32,
    )
    table = pecs.frames_to_events([f0, f1], [0, 1_000_000], cfg)
    first = {}
    for t, x, y in zip(np.array(table["t"]), np.array(table["x"]), np.array(table["y"])):
        first.setdefault((x, y), t)
    thetas = np.array(list(first.values())) * 1e-6 * slope_per_s
    assert len(thetas) == 200 * 200
    assert abs(thetas.std() / sigma - 1) < 0.05
    assert abs(thetas.mean() - 0.2) < 0.002


@pytest.mark.parametrize(("current", "white_lux"), [(0.04, 1000.0), (0.4, 1000.0), (0.4, 100.0)])
def test_first_event_after_a_step_comes_when_the_low_pass_predicts(current, white_lux):
    # The bandwidth follows the photocurrent current * white_lux / 1000 + dark.
    cutoff_hz, half, theta = 200.0, 0.5, 0.2
    cfg = ideal(
        theta_on=theta, cutoff_hz=cutoff_hz, cutoff_half_photocurrent=half, white_lux=white_lux
    )
    before = current / 4
    frames = [np.full((1, 1), v, np.float32) for v in (before, before, current, current)]
    times = [0, 200_000, 200_001, 400_000]
    table = pecs.frames_to_events(frames, times, cfg)
    scale = white_lux / 1000
    x0, x1 = before * scale + cfg.dark_current, current * scale + cfg.dark_current
    tau_s = 1 / (2 * math.pi * cutoff_hz * x1 / (x1 + half))
    jump = math.log(x1 / x0)
    # v(t) = L1 - (L1 - L0) e^{-t/tau} reaches L0 + theta at t = tau ln(jump / (jump - theta)).
    predicted_us = tau_s * math.log(jump / (jump - theta)) * 1e6
    measured_us = table["t"][0].as_py() - 200_001
    assert abs(measured_us / predicted_us - 1) < 0.02
    assert table.num_rows == math.floor(jump / theta)


# ---------------------------------------------------------------- reproducibility


_RUN = """
import hashlib, numpy as np, pecs
rng = np.random.default_rng(1)
base = rng.uniform(0.05, 1, (100, 200))
frames = [(base * np.exp(rng.normal(0, 0.3, base.shape))).astype(np.float32) for _ in range(12)]
cfg = pecs.SensorConfig.preset("davis346", width=200, height=100, seed={seed}, labels=True, shot_rate_hz=50.0)
t = pecs.frames_to_events(frames, np.arange(12) * 4000, cfg)
h = hashlib.sha256()
for name in t.column_names:
    h.update(np.ascontiguousarray(t[name].to_numpy()).tobytes())
print(t.num_rows, h.hexdigest())
"""


def run_with_threads(threads, seed):
    env = {"RAYON_NUM_THREADS": str(threads), "PATH": "/usr/bin:/bin"}
    out = subprocess.run(
        [sys.executable, "-c", _RUN.replace("{seed}", str(seed))],
        env=env,
        capture_output=True,
        text=True,
    )
    assert out.returncode == 0, out.stderr
    return out.stdout.split()


def test_same_seed_gives_identical_events_on_any_thread_count():
    one, two = run_with_threads(1, 7), run_with_threads(2, 7)
    assert int(one[0]) > 1000
    assert one == two
    assert run_with_threads(2, 8) != two


_RUN_IN_THREADS = """
import threading
results = []
def simulate():
    exec(RUN, {"print": lambda *args: results.append(" ".join(map(str, args)))})
threads = [threading.Thread(target=simulate) for _ in range(2)]
for t in threads: t.start()
for t in threads: t.join()
print(results[0]); print(results[1])
"""


def test_threads_other_than_the_importing_one_get_the_same_events():
    # The importing thread is one of rayon's workers (a frame's parallel work starts on it);
    # sensors fed from other threads, two at once, must run on the pool's other threads.
    script = "RUN = " + repr(_RUN.replace("{seed}", "7")) + "\nimport pecs\n" + _RUN_IN_THREADS
    out = subprocess.run(
        [sys.executable, "-c", script],
        env={"RAYON_NUM_THREADS": "2", "PATH": "/usr/bin:/bin"},
        capture_output=True,
        text=True,
        timeout=120,
    )
    assert out.returncode == 0, out.stderr
    first, second = (line.split() for line in out.stdout.splitlines())
    assert first == second == run_with_threads(2, 7)


# ---------------------------------------------------------------- bad input


def feed_sequence(sensor, frames, times):
    return [sensor.feed(f, t) for f, t in zip(frames, times)]


@pytest.mark.parametrize(
    "bad, message",
    [
        (
            lambda f: np.where(np.arange(f.size).reshape(f.shape) == 7, np.nan, f).astype(
                np.float32
            ),
            "non-finite",
        ),
        (
            lambda f: np.where(np.arange(f.size).reshape(f.shape) == 7, np.inf, f).astype(
                np.float32
            ),
            "non-finite",
        ),
        (
            lambda f: np.where(np.arange(f.size).reshape(f.shape) == 7, -0.5, f).astype(np.float32),
            "negative",
        ),
        (lambda f: f[:, :-1].copy(), "shape"),
        (lambda f: f.astype(np.int32), "dtype"),
        (lambda f: f[:0], "empty"),
        (lambda f: f.reshape(-1), "shape"),
    ],
)
def test_bad_frames_raise_and_leave_the_sensor_unchanged(bad, message):
    frames, times = noisy_sequence(h=10, w=12, n=6, seed=3)
    cfg = SensorConfig.preset("davis346", width=12, height=10)
    clean = pecs.EventSensor(cfg)
    probed = pecs.EventSensor(cfg)
    expected = feed_sequence(clean, frames, times)
    got = feed_sequence(probed, frames[:3], times[:3])
    with pytest.raises(ValueError, match=message):
        probed.feed(bad(frames[3]), int(times[3]))
    got += feed_sequence(probed, frames[3:], times[3:])
    assert [b.to_pydict() for b in got] == [b.to_pydict() for b in expected]


def test_non_increasing_time_raises_and_leaves_the_sensor_unchanged():
    cfg = ideal(2, 2)
    sensor = pecs.EventSensor(cfg)
    sensor.feed(np.full((2, 2), 0.5, np.float32), 100)
    with pytest.raises(ValueError, match="t_us must increase"):
        sensor.feed(np.full((2, 2), 0.9, np.float32), 100)
    with pytest.raises(ValueError, match="t_us"):
        sensor.feed(np.full((2, 2), 0.9, np.float32), 150.5)
    assert (
        sensor.feed(np.full((2, 2), 1.0, np.float32), 200).num_rows == 4 * 3
    )  # ln(1.001/0.501) / 0.2


@pytest.mark.parametrize("n_frames", [2, 4])
@pytest.mark.parametrize("as_generator", [False, True])
def test_frames_and_timestamps_of_different_counts_are_refused(n_frames, as_generator):
    frames = np.full((n_frames, 2, 2), 0.5, np.float32)
    source = (f for f in frames) if as_generator else frames
    with pytest.raises(ValueError, match="frames"):
        pecs.frames_to_events(source, [0, 10, 20], ideal(2, 2))


def test_nan_message_names_the_pixel():
    sensor = pecs.EventSensor(ideal(4, 3))
    frame = np.ones((3, 4), np.float32)
    frame[2, 1] = np.nan
    with pytest.raises(ValueError, match=r"x=1, y=2"):
        sensor.feed(frame, 0)


def test_float64_strided_and_big_endian_frames_and_numpy_times_are_accepted():
    sensor = pecs.EventSensor(ideal(4, 3))
    sensor.feed(np.full((3, 4), 0.5), np.int64(0))
    wide = np.full((3, 8), 1.0, np.float32)[:, ::2]
    assert sensor.feed(wide, 10).num_rows == 12 * 3  # ln(1.001/0.501) / 0.2 = 3 each
    assert sensor.feed(np.full((3, 4), 2.0, ">f4"), np.uint32(20)).num_rows == 12 * 3
    with pytest.raises(ValueError, match="t_us"):
        sensor.feed(np.full((3, 4), 2.0, np.float32), True)
    with pytest.raises(ValueError, match="dtype"):
        sensor.feed(np.full((3, 4), 2.0, np.float16), 30)


def test_reset_starts_over():
    sensor = pecs.EventSensor(ideal(2, 2))
    sensor.feed(np.full((2, 2), 0.5, np.float32), 0)
    sensor.reset()
    assert sensor.last_time_us is None
    assert sensor.feed(np.full((2, 2), 1.0, np.float32), 0).num_rows == 0


# ---------------------------------------------------------------- bounded work, threads


def test_a_huge_gap_is_refused_at_once_instead_of_hanging():
    """feed(frame, 2**62) with a noisy preset once ran forever, growing 80 MB/s; a child process
    with a time limit makes a hang a failure instead of a stuck suite."""
    code = (
        "import numpy as np, pecs\n"
        "s = pecs.EventSensor(pecs.SensorConfig.preset('davis346'))\n"
        "f = np.zeros((260, 346), np.float32)\n"
        "s.feed(f, 0)\n"
        "for t in (2**62, 2**53, 3_600_000_000):\n"
        "    try:\n"
        "        s.feed(f, t)\n"
        "    except ValueError as e:\n"
        "        print(e)\n"
        "print(s.last_time_us)\n"
    )
    out = subprocess.run(
        [sys.executable, "-c", code], capture_output=True, text=True, timeout=60, check=True
    )
    beyond, huge, hour, last = out.stdout.splitlines()
    assert "within +-2^53 us" in beyond
    assert "noise events" in huge and "noise events" in hour
    # Expected noise, worked out here: 346 x 260 pixels at 0.001 Hz leak + 10 Hz shot (in the
    # dark) and 1e-4 of them hot at 5 Hz; one call may give 5e7 events.
    rate_hz = 346 * 260 * (0.001 + 10.0 + 1e-4 * 5.0)
    expected = float(re.search(r"about (\S+) noise events", hour).group(1))
    assert expected == pytest.approx(rate_hz * 3600, rel=0.01)
    assert "a gap of 3600.0 s after 0" in hour
    assert f"feed frames at most {5e7 / rate_hz:.3f} s apart" in hour
    assert last == "0"


def test_a_gap_just_inside_the_bound_is_simulated():
    cfg = SensorConfig.preset("davis346", width=40, height=30, latency_us=0.0, jitter_us=0.0)
    rate_hz = 40 * 30 * (0.001 + 10.0 + 1e-4 * 5.0)
    sensor = pecs.EventSensor(cfg)
    frame = np.zeros((30, 40), np.float32)
    sensor.feed(frame, 0)
    with pytest.raises(ValueError, match="noise events"):
        sensor.feed(frame, round(5e7 / rate_hz * 1e6) + 10)
    # 20 s of noise: at most the dark rate (shot noise falls with light, refractory drops some).
    n = sensor.feed(frame, 20_000_000).num_rows
    assert 0.5 * rate_hz * 20 < n < rate_hz * 20 + 5 * math.sqrt(rate_hz * 20)


def test_a_frame_with_more_crossings_than_one_call_may_give_raises_instead_of_aborting():
    """A frame at 3e38 after a dark one, thresholds at 0.01: each pixel crosses
    floor(ln((3e38 + 1e-3) / 1e-3) / 0.01) = 9,550 times, 3.1e8 events on 256 x 128 pixels
    (5 GB). The process once aborted on the failed allocation; a child with its address space
    capped at 3 GB shows an abort as a failure instead of taking the machine's memory."""
    code = (
        "import resource\n"
        "resource.setrlimit(resource.RLIMIT_AS, (3 << 30, 3 << 30))\n"
        "import numpy as np, pecs\n"
        "cfg = pecs.SensorConfig.preset('ideal', width=256, height=128, theta_on=0.01,"
        " theta_off=0.01)\n"
        "s = pecs.EventSensor(cfg)\n"
        "dark = np.zeros((128, 256), np.float32)\n"
        "s.feed(dark, 0)\n"
        "for call in (lambda: s.feed(np.full((128, 256), 3e38, np.float32), 1000),\n"
        "             lambda: s.feed(dark, 2000), s.flush):\n"
        "    try:\n"
        "        call()\n"
        "    except ValueError as e:\n"
        "        print(e)\n"
        "s.reset()\n"
        "s.feed(dark, 0)\n"
        "print(s.feed(np.full((128, 256), 1e-3, np.float32), 1000).num_rows)\n"
    )
    out = subprocess.run([sys.executable, "-c", code], capture_output=True, text=True, timeout=60)
    assert out.returncode == 0, out.stderr[-2000:]
    stopped, refused_feed, refused_flush, after_reset = out.stdout.splitlines()
    assert "the light changed by more than the thresholds can follow in one call" in stopped
    assert "feed frames closer in time, or lower the light range, or raise the thresholds" in (
        stopped
    )
    # Tiles report every 65,536 events; 8 tiles, each past its report by at most one pixel.
    events = int(re.search(r"(\d+) events at t_us = 1000, more than the 5e\+?0?7", stopped)[1])
    assert 5e7 < events < 5e7 + 8 * (2**16 + 9550)
    for refused in (refused_feed, refused_flush):
        assert refused.startswith("the sensor stopped mid-call after ") and "reset()" in refused
    # After reset: floor(ln(2e-3 / 1e-3) / 0.01) = 69 events a pixel.
    assert int(after_reset) == 69 * 256 * 128


def test_threads_feeding_one_sensor_take_turns():
    """Two threads once got 'RuntimeError: Already borrowed'. Now the core's lock serialises
    them: every call either gives events or, fed out of order, the time-order ValueError."""
    import itertools
    import threading

    cfg = SensorConfig.preset("davis346", width=160, height=120, seed=4)
    sensor = pecs.EventSensor(cfg)
    rng = np.random.default_rng(1)
    frames = rng.uniform(0.05, 1.0, (8, 120, 160)).astype(np.float32)
    sensor.feed(frames[0], 0)
    clock = itertools.count(1)
    fed, errors = [], []
    start = threading.Barrier(2)

    def worker():
        start.wait()
        for _ in range(15):
            t_us = 1000 * next(clock)
            try:
                batch = sensor.feed(frames[t_us // 1000 % 8], t_us)
                fed.append((t_us, batch))
            except Exception as error:  # noqa: BLE001 (every exception is examined below)
                errors.append(error)

    threads = [threading.Thread(target=worker) for _ in range(2)]
    for thread in threads:
        thread.start()
    for thread in threads:
        thread.join()
    for error in errors:
        assert isinstance(error, ValueError) and "t_us must increase" in str(error), error
    assert len(fed) + len(errors) == 30 and len(fed) >= 15
    # Calls completed one at a time, in time order, each batch inside its own interval.
    times = [t for t, _ in fed]
    assert times == sorted(times) and sensor.last_time_us == times[-1]
    previous = 0
    for t_us, batch in fed:
        t = batch.column("t").to_numpy()
        assert np.all((t > previous - 1000) & (t <= t_us)) and np.all(np.diff(t) >= 0)
        previous = t_us


@pytest.mark.parametrize("white_lux", [1000.0, 10_000.0])
@pytest.mark.parametrize("level", [0.3, 0.9])
def test_davis346_background_in_daylight_is_the_real_sensors_order(level, white_lux):
    # The DAVIS346 road recording (daylight, its white taken as 10,000 lux): 0.0022-0.0046 Hz per
    # static pixel. The preset's laws at x = level * white_lux / 1000 + 1e-4: leak 0.001 +
    # 0.0004 x, shot 10 * 1e-4 / x; at a tenth of that light (1000 lux) the leak falls and the
    # shot noise rises, to the same order.
    cfg = SensorConfig.preset(
        "davis346", width=100, height=100, labels=True, seed=12, white_lux=white_lux
    )
    duration_s = 20.0
    table = static_run(cfg, level, duration_s, frames=3)
    labels = np.array(table["label"])
    x = level * white_lux / 1000 + cfg.dark_current
    leak_hz, shot_hz = 0.001 + 0.0004 * x, 10.0 * 1e-4 / x
    rate_hz = np.count_nonzero(labels != 3) / (100 * 100) / duration_s
    assert 0.002 < rate_hz < 0.006
    expected = leak_hz + shot_hz
    # Leak counts are floor(phase + rate T) per pixel (mean rate T); shot counts Poisson.
    assert abs(rate_hz / expected - 1) < 4 * math.sqrt(1 / (expected * 1e4 * duration_s)) + 0.05
