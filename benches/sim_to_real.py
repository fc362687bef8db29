"""Sim-to-real on a real DAVIS346 recording: simulate from its APS frames, score against its events.

The recording (../shared/data/davis346_road/, a static DAVIS346 over a road, 59 APS frames at
25 Hz and the same sensor's events; `--recording` for another AEDAT4 with frames) is split at
its middle APS frame; every simulation runs over all frames at the recording's absolute times
and is scored on the held-out second half (middle frame to last frame) with `pecs.calibration.realism`:
chamfer and Gaussian distances (both normalisations), count ratio, ON fraction, count-map
correlation (3 x 3 sum) and rate correlation (5 ms bins). Simulators: the presets `ideal`,
`esim`, `davis346`, a numpy ESIM written here, independent of pecs (log(I + 1e-3), one
reference per pixel advanced by theta = 0.2 per event, crossing times linearly interpolated in
log between frames), issue 13's hand setting, and davis346 calibrated by `pecs.calibrate` on
the first half (simulated as `pecs frames2events` simulates the recording: input noise held
back, and the light between frames the fit chose, transition or flow), from 0 ms, and with
`--warm-up` also after a 200 ms warm-up.
The preset rows are the preset on the frames as recorded (linear interpolation, no input-noise
handling); "davis346 frames2events" is what `pecs frames2events REC --preset davis346` writes, and "davis346
f2e 10,000 lux" the same with the recording's daylight stated (`--set white_lux=10000`).
Reference rows made of the real events themselves, pixels, polarities and counts exact: "real,
time in interval" (each pixel's burst in a frame interval redrawn at a uniform time of it: the
floor of a simulator that knows only the frames) and "real, jitter +-J ms" for J = 10, 5, 2.5
(each burst shifted whole by a uniform time in +-J ms: how well a simulator must know when a
change came to reach a given Gaussian distance; docs/calibration.md, "What limits...").

    python benches/sim_to_real.py [RECORDING] [-o sim_to_real/] [--diagnose] [--no-calibration]
        [--warm-up] [--max-evaluations 200] [--interpolation auto|linear|transition|flow]
        [--other RECORDING|none] [--exposure none|auto]

Both recordings (issue 38): the road and `--other` (default ../shared/data/davis346_emlb/, a
DAVIS346 on a Newton's cradle, indoors, dim, 13 frames; frames timed at their exposure
midpoints) are each calibrated on their first half, and a second table scores each with
davis346 defaults, calibrated on itself, and calibrated on the other recording, on its fitted
first half (simulated as the fit simulates it) and its held-out second half (the whole
recording simulated, as frames2events does).

`--interpolation` sets the light between frames of the frames2events and calibrated rows
(both fitted and scored with it; auto: frames2events' default, and the fit chooses between
transition and flow, scored with its choice); `--exposure auto` undoes each APS frame's
recorded exposure in those rows (`pecs.footage.exposure`: 0.5 ms on the road, 20 ms on emlb),
`none` (the default) takes the frames as the light at their times.

Run time on 2 cores: about 1 min without calibration, plus 5-10 min per calibration (two light
models searched; three with the defaults: both recordings, and --warm-up).

writes sim_to_real.png (count maps: real | each simulator; rate curves) into -o. `--diagnose`
adds the measurements of docs/realism-findings.md: where in each frame interval events fall
(late / early ratio) with model parts turned off one by one, background activity on constant
frames per preset, and events made by APS read noise; and diagnosis.png.
"""

from __future__ import annotations

import argparse
import lzma
import shutil
import tempfile
from collections.abc import Callable
from pathlib import Path

import numpy as np
import pecs
import pyarrow as pa
from pecs.calibration.fit import Recording, calibrate
from pecs.calibration.realism import RATE_BIN_US, blurred_count_map, rate_curve, score

# DAYLIGHT_WHITE_LUX: the road recording's white level as davis346's noise laws take it.
from pecs.config import DAYLIGHT_WHITE_LUX, NOISE_OFF
from pecs.footage.exposure import source_exposure_us
from pecs.footage.frame_interpolation import INTERPOLATIONS

DEFAULT_RECORDING = (
    Path(__file__).resolve().parents[1]
    / ".."
    / "shared"
    / "data"
    / "davis346_road"
    / "davis346_road.aedat4"
)
# The second shared recording: a DAVIS346 on a Newton's cradle, indoors and dim, 13 frames with
# 20 ms exposures (their AEDAT4 timestamps are exposure starts; pecs times frames at their
# exposure midpoints, pecs.footage.aedat4_frames).
OTHER_RECORDING = DEFAULT_RECORDING.parents[1] / "davis346_emlb" / "demo-01.aedat4"
PRESETS = ("ideal", "esim", "davis346")
ESIM_THETA, ESIM_EPS = 0.2, 1e-3
EDGE_US = 4_000  # the first and last 4 ms of a frame interval, for the late / early ratio
# Issue 13's hand setting: davis346 (with the datasheet thresholds it had then) on frames with a
# 4 DN per-pixel deadband, dark current 0.05, no leak (neither part), shot or hot-pixel noise
# (its reference point for the calibration targets).
HAND_DEADBAND_DN = 4.0
HAND = {
    "theta_on": float(np.log(1.143)),
    "theta_off": float(np.log(1.225)),
    "dark_current": 0.05,
    "leak_rate_hz": 0.0,
    "leak_light_rate_hz": 0.0,
    "shot_rate_hz": 0.0,
    "hot_pixel_fraction": 0.0,
}
# Calibrated rows: the first half is fitted from 0 ms ("calibrated", the issue's protocol), or
# from 200 ms ("calib. warm-up", --warm-up: the fit leaves out the first 5 frames' events).
WARMUP_MS = 200.0
# The figure's columns (the README's docs/sim-to-real.png): real, preset, defaults, calibrated.
FIGURE_ROWS = ("real", "davis346", "davis346 frames2events", "numpy ESIM", "calibrated")
# The real events with each burst shifted by a uniform +-J ms (docs/calibration.md, "What
# limits..."): how well a simulator must know when a change came to reach a Gaussian distance.
JITTERS_MS = (10.0, 5.0, 2.5)
EVENT_DTYPE = [("t", "<i8"), ("x", "<u2"), ("y", "<u2"), ("p", "i1")]
# A calibrated sensor and the light model (interpolation) it goes with.
Fitted = tuple[pecs.SensorConfig, str]


# ---- the recording ---------------------------------------------------------------------------


def recording_path(given: str | None, scratch: Path) -> Path:
    """The AEDAT4 file: as given, else the shared copy, decompressed from .xz when needed."""
    path = Path(given) if given else DEFAULT_RECORDING
    if path.exists() and path.suffix != ".xz":
        return path
    packed = path if path.suffix == ".xz" else path.with_name(path.name + ".xz")
    if not packed.exists():
        raise SystemExit(f"no recording at {path} (nor {packed}); give its path")
    unpacked = scratch / packed.stem
    with lzma.open(packed) as source, open(unpacked, "wb") as target:
        shutil.copyfileobj(source, target)
    return unpacked


def load(path: Path) -> tuple[np.ndarray, np.ndarray, pa.Table, np.ndarray | None]:
    """Frame times (exposure midpoints, us), frames (N, H, W) DN/255, the real events, and the
    frames' recorded exposures (us; None where the file records none)."""
    source = pecs.open_frames(path)
    pairs = list(source)
    times = np.array([t for t, _ in pairs], np.int64)
    frames = np.stack([f for _, f in pairs])
    exposures = source_exposure_us(source, "auto")
    recorded = None if exposures is None else np.asarray(exposures, np.float64)
    return times, frames, pecs.read_events(path), recorded


def held_out_window(times: np.ndarray) -> tuple[int, int]:
    """Middle APS frame to last frame: the second half, where every simulator has frames."""
    return int(times[len(times) // 2]), int(times[-1])


# ---- simulators --------------------------------------------------------------------------------


def simulate(preset: str, frames: np.ndarray, times: np.ndarray, **overrides: object) -> pa.Table:
    height, width = frames.shape[1:]
    config = pecs.SensorConfig.preset(preset, width=width, height=height, **overrides)
    return pecs.frames_to_events(frames, times, config)


def frames2events_defaults(
    recording: Path, scratch: Path, interpolation: str, exposure: str, **overrides: object
) -> pa.Table:
    """The events `pecs frames2events REC --preset davis346 --interpolation I --exposure E
    [--set K=V ...]` writes, through the same API."""
    output = scratch / "davis346_defaults.parquet"
    source = pecs.open_frames(recording)
    config = pecs.SensorConfig.preset(
        "davis346", width=source.width, height=source.height, **overrides
    )
    pecs.frames_to_file(source, output, config, interpolation=interpolation, exposure_us=exposure)
    return pecs.read_events(output)


def numpy_esim(
    frames: np.ndarray,
    times: np.ndarray,
    theta_on: float = ESIM_THETA,
    theta_off: float = ESIM_THETA,
) -> np.ndarray:
    """ESIM (Rebecq et al. 2018) on frames: events where log(I + eps), linear in time between
    frames, crosses reference + k theta_on or reference - k theta_off; the reference steps by
    the threshold per event."""
    log_frames = np.log(frames.astype(np.float64) + ESIM_EPS)
    reference = log_frames[0].copy()
    parts = []
    for k in range(1, len(frames)):
        start, end = log_frames[k - 1], log_frames[k]
        sign = np.sign(end - start)
        theta = np.where(sign > 0, theta_on, theta_off)
        counts = (
            np.where(sign != 0, np.floor(sign * (end - reference) / theta), 0)
            .clip(0)
            .astype(np.int64)
        )
        pixels = np.flatnonzero(counts)
        n = counts.ravel()[pixels]
        pixel = np.repeat(pixels, n)
        step = np.arange(n.sum()) - np.repeat(np.cumsum(n) - n, n) + 1
        level = reference.ravel()[pixel] + (sign * theta).ravel()[pixel] * step
        fraction = (level - start.ravel()[pixel]) / (end.ravel()[pixel] - start.ravel()[pixel])
        events = np.empty(len(pixel), EVENT_DTYPE)
        events["t"] = times[k - 1] + np.round(fraction * (times[k] - times[k - 1])).astype(np.int64)
        events["y"], events["x"] = np.divmod(pixel, frames.shape[2])
        events["p"] = sign.ravel()[pixel] > 0
        parts.append(events)
        reference += sign * theta * counts
    merged = np.concatenate(parts)
    return merged[np.argsort(merged["t"], kind="stable")]


def calibrated(
    recording: Recording, max_evaluations: int, warmup_ms: float, name: str = ""
) -> Fitted:
    """davis346 fitted by pecs.calibrate on the first half (first frame to middle frame) from
    `warmup_ms` on (the fit sees only that span's frames and events, its sensor starting fresh
    there: pecs.calibration.fit), and the light model it chose; prints the fit and what the
    data pinned down."""
    times = recording.times_us
    first_half_ms = (warmup_ms, (times[len(times) // 2] - times[0]) / 1e3)
    result = calibrate(recording, first_half_ms, holdout_ms=None, max_evaluations=max_evaluations)
    shown = ", ".join(
        f"{p.name} {p.value:.4g} ({p.status}: {p.interval()})" for p in result.profiles
    )
    verdict = "" if result.improved else " (no better candidate: the preset itself)"
    reached = ", ".join(f"{m} {v:.3f}" for m, v in result.light_models.items())
    print(
        f"{name} calibrated on {first_half_ms[0]:.0f}:{first_half_ms[1]:.0f} ms in "
        f"{result.evaluations} + {result.profile_evaluations} evaluations, "
        f"{result.seconds:.0f} s{verdict}; light model {result.interpolation} (best objective "
        f"per model: {reached}): {shown}"
    )
    return result.config, result.interpolation


def short_name(path: Path) -> str:
    """The table's name of a recording: its shared folder's (davis346_emlb/demo-01.aedat4.xz ->
    emlb), else its file's (davis346_road.aedat4 -> road)."""
    if path.parent.name.startswith("davis346_"):
        return path.parent.name.removeprefix("davis346_")
    return path.name.split(".")[0].removeprefix("davis346_")


def whole_simulation(
    recording: Recording, config: pecs.SensorConfig, interpolation: str | None = None
) -> pa.Table:
    """What `pecs frames2events REC --config [--interpolation I]` writes: the whole recording
    simulated (with the recording's own interpolation unless another is given)."""
    times = recording.times_us
    if interpolation is not None:
        recording = recording.with_interpolation(interpolation)
    return recording.simulate(config, recording.window_us((0.0, (times[-1] - times[0]) / 1e3)))


def first_half_us(recording: Recording) -> tuple[int, int]:
    times = recording.times_us
    return recording.window_us((0.0, (times[len(times) // 2] - times[0]) / 1e3))


def two_recordings_table(
    recordings: dict[str, Recording], fitted: dict[str, Fitted]
) -> dict[tuple[str, str, str], dict[str, float]]:
    """Each recording scored with davis346 (defaults), davis346 calibrated on its own first
    half, and davis346 calibrated on the other recording's first half: on the fitted span (the
    first half, simulated as the fit simulates it: what the calibration promises not to worsen)
    and on the held-out second half (of the whole recording simulated, as frames2events does)."""
    rows = {}
    for name, recording in recordings.items():
        width, height = recording.size
        (other,) = (o for o in recordings if o != name)
        here, there = fitted[name], fitted[other]
        sensors = {
            "davis346 defaults": (
                pecs.SensorConfig.preset("davis346", width=width, height=height, seed=0),
                recording.interpolation,
            ),
            f"calibrated here ({here[1]})": here,
            f"calib. on {other} ({there[1]})": (
                there[0].replace(width=width, height=height),
                there[1],
            ),
        }
        held_out = held_out_window(recording.times_us)
        for sensor, (config, interpolation) in sensors.items():
            simulated = recording.with_interpolation(interpolation)
            rows[name, "fitted", sensor] = simulated.score(config, first_half_us(recording))
            sim = whole_simulation(simulated, config)
            rows[name, "held out", sensor] = score(
                recording.events, sim, window_us=held_out, sensor_size=recording.size
            )
    return rows


def print_two_recordings(rows: dict[tuple[str, str, str], dict[str, float]]) -> None:
    shown = [c for c in COLUMNS if c[0] not in ("chamfer_pecs", "gaussian_pecs")]
    print("\nboth recordings: fitted = first half, held out = second half")
    print(
        f"{'recording':<10}{'span':<10}{'sensor':<30}{'real':>8}"
        + "".join(f"{label:>{len(fmt.format(0))}}" for _, label, fmt in shown)
    )
    for (name, span, sensor), row in rows.items():
        print(
            f"{name:<10}{span:<10}{sensor:<30}{row['events_real']:>8.0f}"
            + "".join(fmt.format(row[key]) for key, _, fmt in shown)
        )


def real_timing_unknown(real: pa.Table, times: np.ndarray, seed: int = 0) -> np.ndarray:
    """The real events with what frames cannot tell redrawn: each pixel's events of one frame
    interval (its burst, shape kept) moved to a uniform random time of the interval (wrapped
    inside it). Pixels, polarities and counts are exact; the score is the floor of any simulator
    that knows only the frames and places a change at a uniform time of its interval."""
    ev = columns(real)
    t, inside, which, first, k = real_bursts(ev, times)
    start, span = times[k], times[k + 1] - times[k]
    draw = np.random.default_rng(seed).uniform(size=len(first))
    moved = start + (t - first[which] + (draw[which] * span).astype(np.int64)) % span
    return events_at(ev, np.where(inside, moved, t))


def real_time_jittered(
    real: pa.Table, times: np.ndarray, jitter_us: float, seed: int = 0
) -> np.ndarray:
    """The real events with each burst (as in `real_timing_unknown`) shifted whole by a uniform
    random time in [-jitter_us, +jitter_us]: what a simulator that knows when each change came,
    within that error, could score at best."""
    ev = columns(real)
    t, inside, which, first, _ = real_bursts(ev, times)
    shift = np.random.default_rng(seed).uniform(-jitter_us, jitter_us, size=len(first))
    return events_at(ev, np.where(inside, t + np.round(shift[which]).astype(np.int64), t))


def real_bursts(
    ev: dict[str, np.ndarray], times: np.ndarray
) -> tuple[np.ndarray, np.ndarray, np.ndarray, np.ndarray, np.ndarray]:
    """(t, inside the frames' span, burst of each event, first time of each burst, frame
    interval of each event): a burst is one pixel's events of one frame interval."""
    t = ev["t"].astype(np.int64)
    k = np.clip(np.searchsorted(times, t, side="right") - 1, 0, len(times) - 2)
    inside = (t >= times[0]) & (t < times[-1])
    burst = (k * (int(ev["x"].max()) + 1) + ev["x"].astype(np.int64)) * (
        int(ev["y"].max()) + 1
    ) + ev["y"]
    _, which = np.unique(burst, return_inverse=True)
    first = np.full(which.max() + 1, np.iinfo(np.int64).max)
    np.minimum.at(first, which, t)
    return t, inside, which, first, k


def events_at(ev: dict[str, np.ndarray], t_us: np.ndarray) -> np.ndarray:
    """The events `ev` at new times, sorted by time."""
    events = np.empty(len(t_us), EVENT_DTYPE)
    events["t"], events["x"], events["y"], events["p"] = t_us, ev["x"], ev["y"], ev["p"]
    return events[np.argsort(events["t"], kind="stable")]


# ---- scoring and output ------------------------------------------------------------------------

COLUMNS = (
    ("events_sim", "events", "{:>9.0f}"),
    ("count_ratio", "count x", "{:>8.2f}"),
    ("on_fraction_sim", "ON frac", "{:>8.3f}"),
    ("chamfer_sensor", "CD sens", "{:>8.3f}"),
    ("gaussian_sensor", "GD sens", "{:>8.3f}"),
    ("chamfer_pecs", "CD pecs", "{:>8.3f}"),
    ("gaussian_pecs", "GD pecs", "{:>8.3f}"),
    ("count_map_correlation", "map r", "{:>7.3f}"),
    ("rate_correlation", "rate r", "{:>7.3f}"),
)


def print_table(
    real: pa.Table, window: tuple[int, int], scores: dict[str, dict[str, float]]
) -> None:
    first = next(iter(scores.values()))
    print(
        f"held-out half {window[0]}..{window[1]} us ({(window[1] - window[0]) / 1e3:.0f} ms): "
        f"{first['events_real']:.0f} real events, ON fraction {first['on_fraction_real']:.3f}"
    )
    print(
        f"{'simulator':<24}"
        + "".join(f"{label:>{len(fmt.format(0))}}" for _, label, fmt in COLUMNS)
    )
    for name, row in scores.items():
        print(f"{name:<24}" + "".join(fmt.format(row[key]) for key, _, fmt in COLUMNS))


def columns(events: pa.Table | np.ndarray) -> dict[str, np.ndarray]:
    table = pecs.events.to_table(events)
    return {name: table.column(name).to_numpy() for name in ("t", "x", "y", "p")}


def in_window(events: dict[str, np.ndarray], window: tuple[int, int]) -> dict[str, np.ndarray]:
    keep = (events["t"] >= window[0]) & (events["t"] < window[1])
    return {name: values[keep] for name, values in events.items()}


def figure(
    streams: dict[str, dict[str, np.ndarray]],
    window: tuple[int, int],
    size: tuple[int, int],
    path: Path,
) -> None:
    import matplotlib

    matplotlib.use("Agg")
    import matplotlib.pyplot as plt

    fig = plt.figure(figsize=(3.2 * len(streams), 6.0), layout="constrained")
    grid = fig.add_gridspec(2, len(streams))
    for column, (name, events) in enumerate(streams.items()):
        counts = blurred_count_map(events["x"], events["y"], *size) / 9
        axis = fig.add_subplot(grid[0, column])
        axis.imshow(np.log1p(counts), cmap="magma")
        axis.set_title(f"{name}: {len(events['t'])} events", fontsize=9)
        axis.set_axis_off()
    rates = fig.add_subplot(grid[1, :])
    for name, events in streams.items():
        curve = rate_curve(events["t"], *window, RATE_BIN_US) / (RATE_BIN_US * 1e-6)
        t_ms = (np.arange(len(curve)) * RATE_BIN_US) / 1e3
        rates.plot(t_ms, curve, label=name, lw=1.5 if name == "real" else 0.8)
    rates.set_yscale("log")
    rates.set_xlabel("time in the held-out half (ms)")
    rates.set_ylabel("events / s (5 ms bins)")
    rates.legend(fontsize=8, ncols=len(streams))
    fig.suptitle("count maps on the held-out half (log(1 + events per pixel), 3 x 3 mean); rates")
    fig.savefig(path, dpi=110)
    plt.close(fig)


# ---- diagnosis ---------------------------------------------------------------------------------


def interval_phase_us(t_us: np.ndarray, times: np.ndarray) -> np.ndarray:
    """Time of each event since the start of its frame interval (t_k-1, t_k], the interval that
    a frame-fed sensor emits it in: an event at exactly t_k ends interval k (phase = period).
    Events outside the frames are dropped."""
    t = t_us[(t_us > times[0]) & (t_us <= times[-1])]
    return t - times[np.searchsorted(times, t, side="left") - 1]


def late_early_ratio(t_us: np.ndarray, times: np.ndarray) -> float:
    """Events in the last EDGE_US of the frame intervals over those in the first EDGE_US."""
    phase = interval_phase_us(t_us, times)
    period_us = float(np.median(np.diff(times)))
    early = np.count_nonzero(phase <= EDGE_US)
    late = np.count_nonzero(phase > period_us - EDGE_US)
    return late / early if early else float("nan")


_NO_LOW_PASS: dict[str, object] = {"cutoff_hz": 0.0}
_NO_LATENCY: dict[str, object] = {"latency_us": 0.0, "jitter_us": 0.0}
_NO_REFRACTORY: dict[str, object] = {"refractory_us": 0.0}
_NO_NOISE: dict[str, object] = dict(NOISE_OFF)
ABLATIONS: dict[str, dict[str, object]] = {
    "davis346": {},
    "  no low-pass": _NO_LOW_PASS,
    "  no latency": _NO_LATENCY,
    "  no refractory": _NO_REFRACTORY,
    "  no noise": _NO_NOISE,
    "  none of these": {**_NO_LOW_PASS, **_NO_LATENCY, **_NO_REFRACTORY, **_NO_NOISE},
    "  only low-pass": {**_NO_LATENCY, **_NO_REFRACTORY, **_NO_NOISE},
}


def deadband(frames: np.ndarray, dn: float) -> np.ndarray:
    """Frames whose pixels keep their last value until it moves more than `dn` DN (APS noise
    below that never reaches the sensor)."""
    held = frames.copy()
    for k in range(1, len(frames)):
        moved = np.abs(frames[k] - held[k - 1]) * 255.0 > dn
        held[k] = np.where(moved, frames[k], held[k - 1])
    return held


def by_interval_count(
    events: dict[str, np.ndarray], times: np.ndarray, low: int, high: int
) -> dict[str, np.ndarray]:
    """The events of pixels that fired low..high times in the frame interval holding them."""
    interval = np.searchsorted(times, events["t"], side="left") - 1
    key = (interval * 65536 + events["y"].astype(np.int64)) * 65536 + events["x"].astype(np.int64)
    _, inverse, counts = np.unique(key, return_inverse=True, return_counts=True)
    keep = (counts[inverse] >= low) & (counts[inverse] <= high)
    return {name: values[keep] for name, values in events.items()}


def on_pixels(events: dict[str, np.ndarray], mask: np.ndarray) -> dict[str, np.ndarray]:
    keep = mask[events["y"].astype(np.int64), events["x"].astype(np.int64)]
    return {name: values[keep] for name, values in events.items()}


def timing_rows(
    frames: np.ndarray, times: np.ndarray, streams: dict[str, dict[str, np.ndarray]]
) -> dict[str, dict[str, np.ndarray]]:
    """Late / early ratios (all, ON, OFF) of the scored streams, of davis346 with parts of the
    model turned off, of thresholds alone, of static and moving pixels, and of denoised frames."""
    rows = dict(streams)
    for name, overrides in ABLATIONS.items():
        if name != "davis346":
            rows[name] = columns(simulate("davis346", frames, times, **overrides))
    davis_theta = {"theta_on": np.log(1.143), "theta_off": np.log(1.225)}
    rows["ideal, davis346 theta"] = columns(simulate("ideal", frames, times, **davis_theta))
    rows["numpy ESIM, davis346 theta"] = columns(numpy_esim(frames, times, *davis_theta.values()))
    rows["ideal, theta 0.4"] = columns(
        simulate("ideal", frames, times, theta_on=0.4, theta_off=0.4)
    )
    static = static_pixels(frames)
    for name in ("real", "ideal", "davis346"):
        rows[f"{name}, static px"] = on_pixels(streams[name], static)
        rows[f"{name}, moving px"] = on_pixels(streams[name], ~static)
    for name in ("ideal, davis346 theta", "davis346"):
        for low, high in ((1, 1), (2, 3), (4, 1 << 30)):
            label = f"{low}" if low == high else (f"{low}-{high}" if high < 1 << 30 else f">={low}")
            rows[f"{name}, {label} ev/px/interval"] = by_interval_count(
                rows[name], times, low, high
            )
    for dn in (2.0, 4.0):
        rows[f"davis346, {dn:.0f} DN deadband"] = columns(
            simulate("davis346", deadband(frames, dn), times)
        )
    print(
        f"\nwhere events fall in the 40 ms frame intervals: last {EDGE_US // 1000} ms / first {EDGE_US // 1000} ms"
    )
    print(f"{'stream':<42}{'all':>7}{'ON':>7}{'OFF':>7}{'events':>9}")
    for name, events in rows.items():
        ratios = [
            late_early_ratio(events["t"][mask], times) for mask in _polarity_masks(events["p"])
        ]
        print(f"{name:<42}" + "".join(f"{r:>7.2f}" for r in ratios) + f"{len(events['t']):>9}")
    return rows


def _polarity_masks(p: np.ndarray) -> list[np.ndarray]:
    return [np.ones(len(p), bool), p == 1, p == 0]


def static_pixels(frames: np.ndarray, max_dn: float = 4.0) -> np.ndarray:
    """Pixels whose APS value never moves more than `max_dn` from its median (sky, roofs)."""
    dn = frames * 255.0
    return np.max(np.abs(dn - np.median(dn, axis=0)), axis=0) <= max_dn


def rate_hz_per_pixel(events: dict[str, np.ndarray], mask: np.ndarray, span_us: float) -> float:
    at = mask[events["y"].astype(np.int64), events["x"].astype(np.int64)]
    return np.count_nonzero(at) / mask.sum() / (span_us * 1e-6)


def constant_frame_rows(frames: np.ndarray, times: np.ndarray, real: dict[str, np.ndarray]) -> None:
    """Background activity per preset: on the real frames' static pixels, on the first APS frame
    repeated, and on that frame with read noise added (Gaussian, drawn anew each frame)."""
    static = static_pixels(frames)
    span = (int(times[1]), int(times[-1]))  # the first frame only initialises the pixels
    noise_dn = np.std(np.diff(frames * 255.0, axis=0)[:, static]) / np.sqrt(2)
    print(
        f"\nstatic pixels (APS within 4 DN of their median all along): {static.mean():.1%}; "
        f"APS temporal noise there {noise_dn:.2f} DN rms"
    )
    rng = np.random.default_rng(0)
    still = np.repeat(frames[:1], len(frames), axis=0)

    def noisy(sigma: np.ndarray | float) -> np.ndarray:
        return (still + rng.normal(0, 1, still.shape) * sigma).clip(0).astype(np.float32)

    inputs: dict[str, Callable[[], np.ndarray]] = {
        "real frames": lambda: frames,
        "first frame, constant": lambda: still,
        f"+ {noise_dn:.1f} DN (measured)": lambda: noisy(noise_dn / 255),
        "+ 1 % of full scale": lambda: noisy(0.01),
        "+ 3 % of full scale": lambda: noisy(0.03),
        "x (1 + 1 % noise)": lambda: noisy(0.01 * still),
        "x (1 + 3 % noise)": lambda: noisy(0.03 * still),
    }
    everywhere = np.ones(static.shape, bool)
    length_us = float(span[1] - span[0])
    print(f"{'source':<10}{'input':<26}{'Hz/pixel (all)':>15}{'(static px)':>13}")
    real_span = in_window(real, span)
    print(
        f"{'real':<10}{'events':<26}{rate_hz_per_pixel(real_span, everywhere, length_us):>15.4f}"
        f"{rate_hz_per_pixel(real_span, static, length_us):>13.4f}"
    )
    for preset in PRESETS[1:]:
        for label, make in inputs.items():
            events = in_window(columns(simulate(preset, make(), times)), span)
            print(
                f"{preset:<10}{label:<26}{rate_hz_per_pixel(events, everywhere, length_us):>15.4f}"
                f"{rate_hz_per_pixel(events, static, length_us):>13.4f}"
            )


DN_BANDS = ((0, 20), (20, 50), (50, 100), (100, 200), (200, 256))


def brightness_rows(
    frames: np.ndarray, times: np.ndarray, streams: dict[str, dict[str, np.ndarray]]
) -> None:
    """Event rate of static pixels by their APS brightness: real against each simulator on the
    real frames (APS noise is what drives the simulated ones)."""
    static = static_pixels(frames)
    median_dn = np.median(frames * 255.0, axis=0)
    span = (int(times[1]), int(times[-1]))
    noise = np.std(np.diff(frames * 255.0, axis=0), axis=0) / np.sqrt(2)
    print("\nstatic pixels by APS brightness: events / pixel / s on the real frames")
    names = [n for n in streams if n in ("real", "ideal", "davis346")]
    print(
        f"{'median DN':<11}{'pixels':>8}{'APS noise DN':>13}" + "".join(f"{n:>10}" for n in names)
    )
    for low, high in DN_BANDS:
        band = static & (median_dn >= low) & (median_dn < high)
        if not band.any():
            continue
        rates = [
            rate_hz_per_pixel(in_window(streams[n], span), band, span[1] - span[0]) for n in names
        ]
        print(
            f"{low:>3}-{high:<7}{band.sum():>8}{np.median(noise[band]):>13.2f}"
            + "".join(f"{r:>10.4f}" for r in rates)
        )


def rate_bin_rows(
    real: pa.Table, sim: pa.Table, window: tuple[int, int], size: tuple[int, int]
) -> None:
    """Rate correlation of the hand setting against bin length: what the 5 ms bins see inside
    the frame intervals, the frame-aligned 40 ms bins do not."""
    print("\nrate correlation of 'davis346 hand' by bin length (bins start at the middle frame)")
    for bin_us in (5_000, 10_000, 20_000, 40_000):
        got = score(
            real, sim, window_us=window, sensor_size=size, rate_bin_us=bin_us, distances=False
        )
        print(f"{bin_us // 1000:>3} ms  {got['rate_correlation']:.3f}")


def phase_figure(rows: dict[str, dict[str, np.ndarray]], times: np.ndarray, path: Path) -> None:
    import matplotlib

    matplotlib.use("Agg")
    import matplotlib.pyplot as plt

    fig, axis = plt.subplots(figsize=(7, 4), layout="constrained")
    period_us = float(np.median(np.diff(times)))
    bins = np.linspace(0, period_us, 21)
    for name, events in rows.items():
        phase = interval_phase_us(events["t"], times)
        density = np.histogram(phase, bins)[0] / max(len(phase), 1) * (len(bins) - 1)
        axis.step(bins[1:] / 1e3, density, label=name.strip(), lw=2 if name == "real" else 1)
    axis.set_xlabel("time since the last APS frame (ms)")
    axis.set_ylabel("events (relative to uniform)")
    axis.legend(fontsize=7, ncols=2)
    fig.savefig(path, dpi=110)
    plt.close(fig)


# ---- main --------------------------------------------------------------------------------------


def main() -> None:
    parser = argparse.ArgumentParser(description=__doc__.split("\n\n")[0])
    parser.add_argument("recording", nargs="?", help="AEDAT4 with APS frames (.xz accepted)")
    parser.add_argument("-o", "--output", default="sim_to_real", help="folder for the figures")
    parser.add_argument(
        "--diagnose", action="store_true", help="timing, background and noise measurements"
    )
    parser.add_argument(
        "--no-calibration", action="store_true", help="skip the calibrated rows (3-5 min each)"
    )
    parser.add_argument(
        "--warm-up", action="store_true", help="add a row calibrated on 200:1160 ms"
    )
    parser.add_argument(
        "--interpolation",
        default="auto",
        choices=("auto", *INTERPOLATIONS),
        help="light between frames in the frames2events and calibrated rows (auto: as "
        "frames2events does for camera footage)",
    )
    parser.add_argument(
        "--exposure",
        default="none",
        choices=("none", "auto"),
        help="undo the APS frames' recorded exposures in the frames2events and calibrated rows "
        "(auto) or take the frames as the light at their times (none)",
    )
    parser.add_argument("--max-evaluations", type=int, default=200, help="per calibration")
    parser.add_argument(
        "--other",
        help="the second recording of the two-recording table (default: the shared emlb "
        "recording; .xz accepted); none to leave the table out",
    )
    args = parser.parse_args()
    output = Path(args.output)
    output.mkdir(parents=True, exist_ok=True)
    with tempfile.TemporaryDirectory() as scratch:
        recording = recording_path(args.recording, Path(scratch))
        times, frames, real_table, recorded_exposures = load(recording)
        exposures = recorded_exposures if args.exposure == "auto" else None
        # What `pecs frames2events REC --preset davis346` writes: the defaults for camera
        # footage (input noise held back, transitions between frames).
        defaults = frames2events_defaults(
            recording, Path(scratch), args.interpolation, args.exposure
        )
        # The same with the recording's light stated: daylight, the white level davis346's
        # noise laws were measured at (`--set white_lux=10000`).
        daylight = frames2events_defaults(
            recording,
            Path(scratch),
            args.interpolation,
            args.exposure,
            white_lux=DAYLIGHT_WHITE_LUX,
        )
        others = {}
        if args.other != "none":
            given = Path(args.other) if args.other else OTHER_RECORDING
            others[short_name(given)] = Recording.load(
                recording_path(str(given), Path(scratch)),
                interpolation=args.interpolation,
                exposure=args.exposure,
            )
    size = (frames.shape[2], frames.shape[1])
    window = held_out_window(times)
    sims: dict[str, pa.Table | np.ndarray] = {
        name: simulate(name, frames, times) for name in PRESETS
    }
    sims["davis346 frames2events"] = defaults
    sims["davis346 f2e 10,000 lux"] = daylight
    sims["numpy ESIM"] = numpy_esim(frames, times)
    sims["real, time in interval"] = real_timing_unknown(real_table, times)
    for jitter_ms in JITTERS_MS:
        sims[f"real, jitter +-{jitter_ms:g} ms"] = real_time_jittered(
            real_table, times, jitter_ms * 1e3
        )
    sims["davis346 hand"] = simulate("davis346", deadband(frames, HAND_DEADBAND_DN), times, **HAND)
    fitted: dict[str, Fitted] = {}
    main_name = short_name(Path(args.recording) if args.recording else DEFAULT_RECORDING)
    if not args.no_calibration:
        main = Recording(
            frames,
            times,
            real_table,
            camera_footage=True,
            interpolation=args.interpolation,
            exposure_us=exposures,
        )
        spans = {"calibrated": 0.0} | ({"calib. warm-up": WARMUP_MS} if args.warm_up else {})
        for name, warmup_ms in spans.items():
            config, interpolation = calibrated(main, args.max_evaluations, warmup_ms, main_name)
            fitted.setdefault(main_name, (config, interpolation))
            sims[name] = whole_simulation(main, config, interpolation)
        for name, other in others.items():
            fitted[name] = calibrated(other, args.max_evaluations, 0.0, name)
        if others:
            both = {main_name: main, **others}
            print_two_recordings(two_recordings_table(both, fitted))
    scores = {
        name: score(real_table, sim, window_us=window, sensor_size=size)
        for name, sim in sims.items()
    }
    print_table(real_table, window, scores)
    print("late / early (events in the last 4 ms of a frame interval over the first 4 ms):")
    print(f"  {'real':<24}{late_early_ratio(columns(real_table)['t'], times):6.2f}")
    for name, sim in sims.items():
        print(f"  {name:<24}{late_early_ratio(columns(sim)['t'], times):6.2f}")
    streams = {"real": columns(real_table)} | {name: columns(sim) for name, sim in sims.items()}
    figure(
        {name: in_window(streams[name], window) for name in FIGURE_ROWS if name in streams},
        window,
        size,
        output / "sim_to_real.png",
    )
    print(f"figure: {output / 'sim_to_real.png'}")
    if args.diagnose:
        rows = timing_rows(frames, times, streams)
        shown = (
            "real",
            "ideal",
            "davis346",
            "  no low-pass",
            "  none of these",
            "ideal, davis346 theta",
        )
        shown += ("numpy ESIM, davis346 theta", "ideal, theta 0.4")
        phase_figure({name: rows[name] for name in shown}, times, output / "diagnosis.png")
        constant_frame_rows(frames, times, streams["real"])
        brightness_rows(frames, times, streams)
        rate_bin_rows(real_table, sims["davis346 hand"], window, size)
        print(f"figure: {output / 'diagnosis.png'}")


if __name__ == "__main__":
    main()
