"""Calibration: fit sensor parameters so that pecs, fed a recording's APS frames, gives events
like the same sensor's recorded events (`pecs.calibrate`).

The recording (an AEDAT4 file with APS frames and DVS events from one DAVIS, or a `Recording`
built from arrays) is simulated over a span of its frames at their absolute times, and scored
against its events over that span with `pecs.calibration.realism.score`. The objective is a sum of terms,
each divided by its tolerance (issue 13's calibration targets), so that one unit of any term
is equally bad:

    |ln(N_sim / N_real)| / ln(1.15)       event count            (target: within 15 %)
  + |ON_sim - ON_real| / 0.05              ON fraction            (target: within 0.05)
  + (1 - r_map) / 0.05                     3 x 3 count maps       (target: r >= 0.95)
  + (1 - r_rate) / 0.5                     5 ms event rates       (see below)
  + chamfer_sensor / 2.9                   PECS chamfer distance  (target: <= 2.9)
  + gaussian_sensor / 1.35                 PECS Gaussian distance (target: <= 1.35)

Why all of them: the distances alone are fooled. Minimising the Gaussian distance alone floods
the sensor (low thresholds, 43x the real count: every real event has a simulated one nearby),
and the chamfer distance alone skews the polarities (ON fraction 0.1 against the real 0.52);
the count and ON-fraction terms pin both down, the count maps say where events happen and the
rate curves when. The rate term gets a wide tolerance (0.5): frames at 25 Hz do not say when in
a 40 ms interval a change came, so no sensor parameter brings the 5 ms rate correlation near 1
(the real events themselves, each pixel's burst moved to a uniform time of its interval, score
0.5 on the road recording; benches/sim_to_real.py), and a tight tolerance would let that limit
of frame input outweigh the rest. The distances use `normalize="sensor"` (the paper's
per-stream normalisation moves with a few outlying events).

Never worse than the reference: the objective is a sum, and a sum can buy one term with
another (on the emlb recording the unconstrained fit bought the count with both distances,
chamfer 3.42 -> 3.50 on the very span it fitted). So the reference, the starting sensor as
`frames2events` simulates it by default (interpolation "auto": what the user has without
calibrating), is scored first, and a candidate counts only if it is no worse than the reference
on each of chamfer, Gaussian distance, |ln count ratio|, count-map r and rate r over the fitted
span (`NO_WORSE`); among those the objective is minimised.

The light between frames is chosen too, as a discrete choice (`Recording.light_models`: for
camera footage, transition and flow): each light model gets its own simplex from the start, with
the same budget and the same reference, and the result is the lowest objective over all of them
(`CalibrationResult.interpolation` says which, for `frames2events --interpolation`). Holding
each model to its own start instead stalls the better one: on the road recording flow at the
preset's thresholds gives 1.44x the real count on the fitted half and a Gaussian distance (1.28)
no fit at the real count can keep, so every candidate near the real count was "worse than the
start", while against the default run flow reaches objective 3.52 against transition's 4.16.

Each simplex minimises the objective plus PENALTY x how much worse a candidate is than the
reference (in the terms' units), so it is steered toward what the reference does well but may
cross worse ground on the way (a strict wall around the start stalls it: on a simulated recording
whose true thresholds are no worse than the start on anything, nearly every step from the
start toward them first worsens the Gaussian distance); the result is the best candidate it
evaluated that is no worse than the reference on any of the five, and the start itself (with
the default light model) where none beat it (`improved` False).

Determinism: every evaluation simulates with the same seed (common random numbers), so the
objective is a deterministic function of the parameters and the simplex compares like with
like. The optimiser is Nelder-Mead (`pecs.calibration._nelder_mead`) in a transformed space: each
parameter mapped to [0, 1] between its bounds, on a log scale for the positive scale
parameters. `PARAMETERS` lists what can be fitted; adding a model parameter is one line there.
"""

from __future__ import annotations

import math
import os
import sys
import time
from collections.abc import Callable, Sequence
from dataclasses import dataclass, field, replace
from pathlib import Path

import numpy as np
import pyarrow as pa

from pecs.calibration import _nelder_mead
from pecs.calibration._nelder_mead import minimize
from pecs.calibration.profile import NOISE_FLOOR, ParameterProfile
from pecs.calibration.profile import profile as profile_parameters
from pecs.calibration.realism import RATE_BIN_US, score
from pecs.config import SensorConfig
from pecs.footage.frame_interpolation import INTERPOLATIONS
from pecs.footage.input_noise import ESTIMATE_FRAMES, InputNoise
from pecs.sensor import frames_to_events

__all__ = [
    "DEFAULT_FIT",
    "NO_WORSE",
    "PARAMETERS",
    "TOLERANCES",
    "CalibrationResult",
    "Parameter",
    "Recording",
    "calibrate",
    "check_budget",
    "objective_terms",
    "worsening",
]


@dataclass(frozen=True)
class Parameter:
    """A fittable `SensorConfig` field: its bounds, and whether it is searched in log scale."""

    name: str
    low: float
    high: float
    log: bool = True

    def to_unit(self, value: float) -> float:
        """The value's place in [0, 1] between the bounds (clipped into them)."""
        value = min(max(float(value), self.low), self.high)
        if self.log:
            return math.log(value / self.low) / math.log(self.high / self.low)
        return (value - self.low) / (self.high - self.low)

    def from_unit(self, unit: float) -> float:
        unit = min(max(float(unit), 0.0), 1.0)
        if self.log:
            return self.low * (self.high / self.low) ** unit
        return self.low + unit * (self.high - self.low)


# What the calibration may fit. Bounds span every plausible DVS (thresholds 0.1-0.5 in the
# published sensors and simulators, v2e's and ESIM's included; background activity 0.003 Hz
# per pixel on a DAVIS346 in daylight to several Hz in the dark, IEBCS) with a wide margin.
PARAMETERS: dict[str, Parameter] = {
    p.name: p
    for p in (
        Parameter("theta_on", 0.02, 1.5),
        Parameter("theta_off", 0.02, 1.5),
        Parameter("theta_sigma", 0.0, 0.2, log=False),
        Parameter("dark_current", 1e-4, 0.5),
        Parameter("cutoff_hz", 5.0, 5000.0),
        Parameter("cutoff_half_photocurrent", 1e-3, 1.0),
        Parameter("refractory_us", 1.0, 20_000.0),
        Parameter("leak_rate_hz", 1e-5, 10.0),
        Parameter("shot_rate_hz", 1e-5, 100.0),
        Parameter("hot_pixel_fraction", 1e-6, 0.05),
        Parameter("hot_pixel_rate_hz", 0.1, 1000.0),
        # The frames' white in lux: night (1 lux) to direct sunlight (1e5).
        Parameter("white_lux", 1.0, 100_000.0),
    )
}

# Fitted by default: what frames at video rate (25 Hz) and a few seconds of events identify.
# The thresholds set how many events each change gives, and the ON/OFF balance; dark_current
# is the dark pixels' deadband (APS read noise in dark pixels becomes events unless it is
# large); leak and shot noise are the events of static pixels, ON only and both polarities;
# the refractory period how many events a strong change gives in a burst, the limit the
# thresholds alone get wrong: on the road recording (fit on 0:1160 ms, scored on the rest)
# fitting it moved the held-out count from 1.151x to 1.133x and the chamfer distance from
# 2.26 to 2.20 (64 us, against v2e's 0.5 ms). Not by default: cutoff_hz (fitting it changed
# nothing there: 1.151x) and theta_sigma, which trades against the thresholds; nor white_lux
# (with flow chosen on the road's first half: 1650 lux, fitted objective 3.52 -> 3.56).
DEFAULT_FIT = (
    "theta_on",
    "theta_off",
    "dark_current",
    "leak_rate_hz",
    "shot_rate_hz",
    "refractory_us",
)

# One unit of each objective term: issue 13's calibration targets (see the module).
TOLERANCES = {
    "count": math.log(1.15),
    "on_fraction": 0.05,
    "count_map": 0.05,
    "rate": 0.5,
    "chamfer": 2.9,
    "gaussian": 1.35,
}
# What an undefined term (no simulated events: no correlation, no distance) costs.
UNDEFINED_TERM = 100.0
# The measures a fit must not worsen over its span (`worsening`): chamfer and Gaussian distances,
# |ln count ratio|, count-map r and rate r (issue 38: every distance and correlation; on emlb the
# flow fit without the rate bought count and maps with the rate r, 0.946 -> 0.934).
NO_WORSE = ("chamfer", "gaussian", "count", "count_map", "rate")
# Objective units the search adds per unit of worsening (in the terms' units): steers the
# simplex toward what the start does well; the promise itself is kept by picking the result
# only among candidates no worse than the start.
PENALTY = 3.0
# The light models a calibration of camera footage chooses among (`Recording.light_models`): the
# frames2events default and the optical-flow sub-frames, each searched from the start.
CAMERA_LIGHT_MODELS = ("transition", "flow")
# Fewest recorded events a span is scored on: a count of N scatters by 1 / sqrt(N) (Poisson),
# 10 % at 100, so fewer cannot tell the count target (15 %) from chance.
MIN_SCORED_EVENTS = 100

#: (start, end) in absolute us, or several of them (a held-out span on both sides of the fit).
Window = tuple[int, int]
Windows = Window | Sequence[Window]


@dataclass
class Recording:
    """APS frames (N, H, W) of photocurrent, their times (us, exposure midpoints) and the same
    sensor's events (a pyarrow table with t, x, y, p).

    `exposure_us`: each frame's exposure (one number, or one per frame), undone before the
    sensor sees the frames (`pecs.frames_to_events`'s `exposure_us`); None: not undone.
    `camera_footage`: the frames are a real camera's (True for `load`), simulated as
    `pecs frames2events` simulates them: their input noise held back, transitions between
    frames (`pecs.frames_to_events(..., camera_footage=True)`), so that a fitted config file
    gives with `--config` the events it was fitted on. `interpolation`: the light between
    frames, as `pecs.frames_to_events` takes it; with "auto" `calibrate` chooses among
    `light_models`.

    A span of time is simulated from its own frames alone (`frame_range`): the frames inside
    it and the one bracketing each end, whose light the span's first and last intervals are
    interpolated from; nothing earlier or later, so that no frame outside a fitted span can
    move a fit. The input noise is estimated from the first ESTIMATE_FRAMES of those frames,
    as `frames2events` estimates it from the first frames of a file holding just them."""

    frames: np.ndarray
    times_us: np.ndarray
    events: pa.Table
    camera_footage: bool = False
    interpolation: str = "auto"
    exposure_us: float | np.ndarray | None = None
    # Input noise per (first, last) frame of a span: it does not depend on the sensor.
    _noise: dict[tuple[int, int], InputNoise] = field(
        default_factory=dict, init=False, repr=False, compare=False
    )

    @classmethod
    def load(
        cls, path: str | os.PathLike[str], interpolation: str = "auto", exposure: str = "none"
    ) -> Recording:
        """An AEDAT4 recording with APS frames (`pecs.open_frames`) and events; `exposure`
        "auto": the frames' recorded exposures undone (`exposure_us`), "none": not."""
        from pecs.footage.exposure import source_exposure_us
        from pecs.footage.frames import open_frames
        from pecs.io import read_events

        source = open_frames(Path(path))
        pairs = list(source)
        exposure_us = source_exposure_us(source, exposure)
        if len(pairs) < 2:
            raise ValueError(f"{path}: needs at least 2 APS frames to calibrate, has {len(pairs)}")
        times = np.array([t for t, _ in pairs], np.int64)
        frames = np.stack([frame for _, frame in pairs])
        return cls(
            frames,
            times,
            read_events(path),
            camera_footage=True,
            interpolation=interpolation,
            exposure_us=None if exposure_us is None else np.asarray(exposure_us, np.float64),
        )

    def light_model(self) -> str:
        """The interpolation `simulate` uses, "auto" resolved as `pecs.frames_to_events`
        resolves it: transition for camera footage, linear otherwise."""
        if self.interpolation != "auto":
            return self.interpolation
        return "transition" if self.camera_footage else "linear"

    def light_models(self) -> tuple[str, ...]:
        """The light models a calibration chooses among (`calibrate`'s `interpolations`): the
        one asked for; with "auto", for camera footage, transition and flow."""
        if self.interpolation == "auto" and self.camera_footage:
            return CAMERA_LIGHT_MODELS
        return (self.light_model(),)

    def with_interpolation(self, interpolation: str) -> Recording:
        """The same recording simulated with another interpolation (its input noise shared)."""
        other = replace(self, interpolation=interpolation)
        other._noise = self._noise
        return other

    @property
    def size(self) -> tuple[int, int]:
        """(width, height)."""
        return int(self.frames.shape[2]), int(self.frames.shape[1])

    def window_us(self, span_ms: tuple[float, float]) -> tuple[int, int]:
        """Absolute (start, end) in us of a span counted in ms from the first frame's time."""
        start_ms, end_ms = (float(v) for v in span_ms)
        length_ms = (self.times_us[-1] - self.times_us[0]) / 1e3
        if not 0 <= start_ms < end_ms <= length_ms + 1e-9:
            raise ValueError(
                f"span {start_ms:g}:{end_ms:g} ms: needs 0 <= start < end <= {length_ms:g} ms "
                "(the frames' length, counted from the first frame)"
            )
        origin = int(self.times_us[0])
        return origin + round(start_ms * 1e3), origin + round(end_ms * 1e3)

    def frame_range(self, window_us: tuple[int, int]) -> tuple[int, int]:
        """(first, last) indices of the frames a window is simulated from: the last frame at or
        before its start to the first at or after its end (at least two frames)."""
        count = len(self.times_us)
        first = int(np.searchsorted(self.times_us, window_us[0], side="right")) - 1
        last = int(np.searchsorted(self.times_us, window_us[1], side="left"))
        first = min(max(first, 0), count - 2)
        return first, max(min(last, count - 1), first + 1)

    def input_noise(self, first: int, last: int) -> InputNoise:
        """The input noise of frames first..last, from the first ESTIMATE_FRAMES of them."""
        if (first, last) not in self._noise:
            end = min(first + ESTIMATE_FRAMES, last + 1)
            self._noise[first, last] = InputNoise.estimate(self.frames[first:end])
        return self._noise[first, last]

    def simulate(self, config: SensorConfig, window_us: tuple[int, int]) -> pa.Table:
        """pecs's events from the window's own frames (`frame_range`) at the recording's
        absolute times: what `frames2events --config` gives on the recording cut to them.

        The sensor starts fresh at the frame before the window: every reference at its pixel's
        level, so its first changes give ON and OFF events in the changes' own proportions, where
        with a history a pixel's ON and OFF steps balance (N_on theta_on ~ N_off theta_off). With
        input noise held back and transitions between frames that costs little: on the road
        recording's second half davis346 gives 1.348x the real count, ON 0.496, chamfer 2.514
        started fresh, against 1.329x, 0.494, 2.496 with the first half simulated before it
        (and the 0:1160 and 200:1160 fits agree, docs/calibration.md)."""
        first, last = self.frame_range(window_us)
        return frames_to_events(
            self.frames[first : last + 1],
            self.times_us[first : last + 1],
            config,
            camera_footage=self.camera_footage,
            input_noise=self.input_noise(first, last) if self.camera_footage else None,
            interpolation=self.interpolation,
            exposure_us=self._exposure_us(first, last),
        )

    def _exposure_us(self, first: int, last: int) -> float | np.ndarray | None:
        """The exposures of frames first..last."""
        if self.exposure_us is None or np.ndim(self.exposure_us) == 0:
            return self.exposure_us
        return np.asarray(self.exposure_us)[first : last + 1]

    def scored_streams(
        self, config: SensorConfig, windows_us: Windows
    ) -> tuple[pa.Table, pa.Table, tuple[int, int]]:
        """The recorded and simulated events that `score` compares, and their window.

        Each window is trimmed to whole 5 ms rate bins (`scored_window`) and simulated from its
        own frames. Several windows (a held-out span on both sides of the fitted one) are put
        end to end: each one's events moved back in time by the gaps before it, in both streams
        alike, so that one score covers them all."""
        pieces = [scored_window(w) for w in as_windows(windows_us)]
        origin = at = pieces[0][0]
        real, sim = [], []
        for start, end in pieces:
            real.append(_events_inside(self.events, start, end, at - start))
            sim.append(_events_inside(self.simulate(config, (start, end)), start, end, at - start))
            at += end - start
        return pa.concat_tables(real), pa.concat_tables(sim), (origin, at)

    def recorded_events(self, windows_us: Windows) -> int:
        """How many recorded events `score` compares over the windows."""
        t = self.events.column("t").to_numpy()
        pieces = [scored_window(w) for w in as_windows(windows_us)]
        return int(sum(np.count_nonzero((t >= a) & (t < b)) for a, b in pieces))

    def score(self, config: SensorConfig, windows_us: Windows) -> dict[str, float]:
        """`pecs.calibration.realism.score` of the simulation against the events, plus the objective, over
        one window or several put end to end (`scored_streams`)."""
        real, sim, window_us = self.scored_streams(config, windows_us)
        measures = score(real, sim, window_us=window_us, sensor_size=self.size)
        terms = objective_terms(measures)
        return {
            **measures,
            **{f"term_{k}": v for k, v in terms.items()},
            "objective": sum(terms.values()),
        }


def objective_terms(measures: dict[str, float]) -> dict[str, float]:
    """The objective's terms (module docstring) from `pecs.calibration.realism.score`'s measures."""
    count = abs(math.log((measures["events_sim"] + 1) / (measures["events_real"] + 1)))
    raw = {
        "count": count,
        "on_fraction": abs(measures["on_fraction_sim"] - measures["on_fraction_real"]),
        "count_map": 1.0 - measures["count_map_correlation"],
        "rate": 1.0 - measures["rate_correlation"],
        "chamfer": measures["chamfer_sensor"],
        "gaussian": measures["gaussian_sensor"],
    }
    return {
        name: value / TOLERANCES[name] if math.isfinite(value) else UNDEFINED_TERM
        for name, value in raw.items()
    }


def worsening(measures: dict[str, float], start: dict[str, float]) -> dict[str, float]:
    """How much worse than `start` the measures are on each of NO_WORSE, in objective units
    (0 where no worse). A measure undefined for the start (no events) constrains nothing; one
    undefined for the candidate alone is UNDEFINED_TERM worse."""
    mine, theirs = _no_worse_measures(measures), _no_worse_measures(start)
    worse = {}
    for name in NO_WORSE:
        if not math.isfinite(theirs[name]):
            worse[name] = 0.0
        elif not math.isfinite(mine[name]):
            worse[name] = UNDEFINED_TERM
        else:
            worse[name] = max(0.0, mine[name] - theirs[name]) / TOLERANCES[name]
    return worse


def _no_worse_measures(measures: dict[str, float]) -> dict[str, float]:
    """NO_WORSE's measures, each lower is better: the distances, |ln count ratio| (the ratio
    itself, not the objective's (N + 1) one, so that the report's ratios show the promise
    kept), 1 - count-map r and 1 - rate r; NaN where undefined."""
    ratio = measures["count_ratio"]
    return {
        "chamfer": measures["chamfer_sensor"],
        "gaussian": measures["gaussian_sensor"],
        "count": abs(math.log(ratio)) if ratio > 0 else math.nan,
        "count_map": 1.0 - measures["count_map_correlation"],
        "rate": 1.0 - measures["rate_correlation"],
    }


def penalised(objective: float, worse: dict[str, float], penalty: float = PENALTY) -> float:
    """The value the search minimises: the objective plus `penalty` x the worsening."""
    return objective + penalty * sum(worse.values())


def as_windows(windows_us: Windows) -> list[Window]:
    """One (start, end) window or a sequence of them, as a list of (int, int)."""
    if len(windows_us) == 2 and all(isinstance(v, (int, np.integer)) for v in windows_us):
        return [(int(windows_us[0]), int(windows_us[1]))]  # type: ignore[arg-type]
    return [(int(a), int(b)) for a, b in windows_us]  # type: ignore[misc]


def scored_window(window_us: Window) -> Window:
    """The window trimmed to whole 5 ms rate bins: a last bin a sliver long is a near-empty
    point in both rate curves that inflates their correlation (a first half 1 us longer,
    1160.001 ms, sent the road fit down another path). A window under one bin is kept whole."""
    start, end = window_us
    if end - start < RATE_BIN_US:
        return window_us
    return start, start + (end - start) // RATE_BIN_US * RATE_BIN_US


def _events_inside(events: pa.Table, start: int, end: int, shift_us: int) -> pa.Table:
    """The t, x, y, p of the events in start <= t < end, moved by shift_us."""
    t = events.column("t").to_numpy()
    keep = (t >= start) & (t < end)
    return pa.table(
        {
            "t": pa.array(t[keep] + shift_us, pa.int64()),
            **{
                name: pa.array(events.column(name).to_numpy()[keep], kind)
                for name, kind in (("x", pa.uint16()), ("y", pa.uint16()), ("p", pa.int8()))
            },
        }
    )


@dataclass
class CalibrationResult:
    """The fitted configuration, and every measure of it (with its light model) and of the
    starting preset as frames2events runs it by default (the reference) on the fitted span and
    the held-out span (`Recording.score`'s keys; the held-out span is one or
    two windows, none when nothing is held out)."""

    config: SensorConfig
    start_config: SensorConfig
    fitted: dict[str, float]
    fit_window_us: Window
    holdout_windows_us: tuple[Window, ...]
    fit: dict[str, float]
    holdout: dict[str, float] | None
    start_fit: dict[str, float]
    start_holdout: dict[str, float] | None
    evaluations: int
    seconds: float
    history: list[tuple[dict[str, float], float]] = field(default_factory=list, repr=False)
    # False: nothing the search tried beat the start without worsening one of NO_WORSE, and the
    # result is the start itself.
    improved: bool = True
    # Which parameters the data pinned down (`pecs.calibration.profile`), with the objective's
    # difference between two simulation seeds at the result and the evaluations it took.
    profiles: list[ParameterProfile] = field(default_factory=list)
    objective_noise: float = math.nan
    profile_evaluations: int = 0
    # The light model the fitted sensor goes with (`frames2events --interpolation`), and the
    # lowest objective each model tried reached among candidates no worse than the reference
    # (inf where none was).
    interpolation: str = "linear"
    light_models: dict[str, float] = field(default_factory=dict)


def calibrate(
    recording: Recording | str | os.PathLike[str],
    fit_ms: tuple[float, float] | None = None,
    *,
    holdout_ms: tuple[float, float] | None | str = "rest",
    preset: str = "davis346",
    start: SensorConfig | None = None,
    parameters: Sequence[str | Parameter] = DEFAULT_FIT,
    max_evaluations: int = 300,
    seed: int = 0,
    progress: bool = False,
    profile: bool = True,
    interpolations: Sequence[str] | None = None,
) -> CalibrationResult:
    """Fit `parameters` of a sensor to a recording with APS frames and events (module docstring).

    `fit_ms` = (start, end) in ms from the first APS frame (default: the whole recording). Only
    the frames and events of that span reach the fit (`Recording.simulate`: plus the frame
    bracketing each end). `holdout_ms`: the span scored but not fitted; "rest" (default) is the
    rest of the recording on both sides of the fit (parts shorter than one 5 ms rate bin left
    out), None for none. A fitted or held-out span with fewer than MIN_SCORED_EVENTS recorded
    events, or shorter than two rate bins, is refused. The fit starts from `start`, else the
    preset `preset`, with the recording's size and `seed` (the same seed for every evaluation);
    `max_evaluations` bounds the search's evaluations, at least one per parameter plus one
    (the start's score is the first; where a starting value lies outside its parameter's
    bounds it is one more), per light model. `interpolations`: the light models to choose
    among, each searched from the start (default: `Recording.light_models`). The result is
    never worse than the start as `frames2events` runs it by default (interpolation "auto") on
    NO_WORSE's measures over the fitted span, and is that start itself where nothing better was
    found (module docstring). `profile`: then say which parameters the data pinned down
    (`pecs.calibration.profile`: 1 + 4 evaluations a parameter). `progress`: a line per
    evaluation on stderr.
    """
    chosen = [p if isinstance(p, Parameter) else _parameter(p) for p in parameters]
    check_budget(len(chosen), max_evaluations)
    if not isinstance(recording, Recording):
        recording = Recording.load(recording)
    models = tuple(interpolations) if interpolations is not None else recording.light_models()
    for model in models:
        if model not in INTERPOLATIONS:
            raise ValueError(
                f"interpolations: {model!r} is not a light model; choose from "
                f"{', '.join(INTERPOLATIONS)}"
            )
    if not models:
        raise ValueError("interpolations: give at least one light model")
    width, height = recording.size
    base = (start or SensorConfig.preset(preset)).replace(width=width, height=height, seed=seed)
    length_ms = (recording.times_us[-1] - recording.times_us[0]) / 1e3
    fit_window = recording.window_us(fit_ms if fit_ms is not None else (0.0, length_ms))
    _check_scorable(recording, [fit_window], "fitted span", "--fit-ms START:END")
    holdout_windows = _holdout_windows(recording, fit_window, holdout_ms)
    if holdout_windows:
        option = "--holdout-ms START:END, or --holdout-ms none"
        _check_scorable(recording, holdout_windows, "held-out span", option)
    history: list[tuple[dict[str, float], float]] = []
    began = time.perf_counter()
    # The reference: the start as frames2events simulates it by default.
    reference = recording.with_interpolation("auto")
    reference_model = reference.light_model()

    def measured(rec: Recording, values: dict[str, float], label: str = "") -> dict[str, float]:
        measures = rec.score(base.replace(**values), fit_window)
        history.append((values, measures["objective"]))
        if progress:
            shown = ", ".join(f"{k}={v:.4g}" for k, v in values.items())
            print(
                f"  [{len(history):>3}] {measures['objective']:8.3f}  {shown}{label}",
                file=sys.stderr,
                flush=True,
            )
        return measures

    start_values = {p.name: float(getattr(base, p.name)) for p in chosen}
    start_fit = measured(reference, start_values, f"  (start, {reference_model}: the reference)")
    # The best candidate no worse than the reference on NO_WORSE, over every light model:
    # (objective, parameters, measures, light model).
    best = (start_fit["objective"], start_values, start_fit, reference_model)
    evaluations = 1
    reached: dict[str, float] = {}
    for model in models:
        rec = recording.with_interpolation(model)
        found, used = _search(
            rec,
            chosen,
            start_values,
            start_fit,
            model == reference_model,
            max_evaluations,
            measured,
            progress,
        )
        evaluations += used
        reached[model] = found[0] if found is not None else math.inf
        if found is not None and found[0] < best[0]:
            best = (*found, model)
    _, fitted, fit, chosen_model = best
    improved = fitted is not start_values
    config = base.replace(**fitted)
    chosen_recording = recording.with_interpolation(chosen_model)
    profiles, noise, profile_evaluations = [], math.nan, 0
    if profile:
        profiles, noise, profile_evaluations = _profile(
            chosen_recording, config, chosen, fit, fit_window
        )
    seconds = time.perf_counter() - began
    return CalibrationResult(
        config=config,
        start_config=base,
        fitted=fitted,
        fit_window_us=fit_window,
        holdout_windows_us=tuple(holdout_windows),
        fit=fit,
        holdout=chosen_recording.score(config, holdout_windows) if holdout_windows else None,
        start_fit=start_fit,
        start_holdout=reference.score(base, holdout_windows) if holdout_windows else None,
        evaluations=evaluations,
        seconds=seconds,
        history=history,
        improved=improved,
        profiles=profiles,
        objective_noise=noise,
        profile_evaluations=profile_evaluations,
        interpolation=chosen_model,
        light_models=reached,
    )


def _search(
    recording: Recording,
    chosen: Sequence[Parameter],
    start_values: dict[str, float],
    reference: dict[str, float],
    start_is_reference: bool,
    max_evaluations: int,
    measured: Callable[..., dict[str, float]],
    progress: bool,
) -> tuple[tuple[float, dict[str, float], dict[str, float]] | None, int]:
    """One light model's simplex from the start (module docstring): the best candidate no worse
    than `reference` on NO_WORSE, as (objective, parameters, measures), or None where none
    was; and the evaluations made. `start_is_reference`: the start under this light model is
    the reference itself, already scored."""
    initial = np.array([p.to_unit(v) for p, v in zip(chosen, start_values.values())])
    # The first vertex is the start itself unless a starting value lies outside its bounds.
    served = all(
        math.isclose(p.from_unit(u), v, rel_tol=1e-9)
        for p, u, v in zip(chosen, initial, start_values.values())
    )
    best: tuple[float, dict[str, float], dict[str, float]] | None = None
    # Every candidate scored, by its place in the unit cube (clipping lands trials on the same
    # faces of the cube).
    seen: dict[bytes, tuple[float, dict[str, float]]] = {}
    label = f"  ({recording.interpolation})"
    made = 0

    def evaluate(unit: np.ndarray) -> float:
        nonlocal best, made
        key = unit.tobytes()
        if key not in seen:
            if start_is_reference and served and np.array_equal(unit, initial):
                seen[key] = (reference["objective"], dict.fromkeys(NO_WORSE, 0.0))
            else:
                values = {p.name: p.from_unit(u) for p, u in zip(chosen, unit)}
                measures = measured(recording, values, label)
                made += 1
                worse = worsening(measures, reference)
                if any(worse.values()):
                    if progress:
                        names = ", ".join(name for name, w in worse.items() if w > 0)
                        print(f"        worse than the reference: {names}", file=sys.stderr)
                elif best is None or measures["objective"] < best[0]:
                    best = (measures["objective"], values, measures)
                seen[key] = (measures["objective"], worse)
        objective, worse = seen[key]
        return penalised(objective, worse)

    minimize(evaluate, initial, max_evaluations=max_evaluations)
    return best, made


def _profile(
    recording: Recording,
    config: SensorConfig,
    chosen: Sequence[Parameter],
    fit: dict[str, float],
    fit_window: Window,
) -> tuple[list[ParameterProfile], float, int]:
    """`pecs.calibration.profile` around the result: (profiles, the objective's difference
    between two seeds, evaluations made)."""
    other_seed = recording.score(config.replace(seed=config.seed + 1), fit_window)["objective"]
    noise = abs(other_seed - fit["objective"])
    count = 1

    def objective(values: dict[str, float]) -> float:
        nonlocal count
        count += 1
        return recording.score(config.replace(**values), fit_window)["objective"]

    profiles = profile_parameters(
        objective,
        {p.name: float(getattr(config, p.name)) for p in chosen},
        [(p.name, p.low, p.high, p.log) for p in chosen],
        fit["objective"],
        max(noise, NOISE_FLOOR),
    )
    return profiles, noise, count


def _parameter(name: str) -> Parameter:
    if name not in PARAMETERS:
        raise ValueError(
            f"parameters: {name!r} cannot be fitted; choose from {', '.join(PARAMETERS)}"
        )
    return PARAMETERS[name]


def minimum_evaluations(parameter_count: int) -> int:
    """The fewest evaluations a fit of that many parameters can make: its first simplex."""
    return _nelder_mead.minimum_evaluations(parameter_count)


def check_budget(parameter_count: int, max_evaluations: int, name: str = "max_evaluations") -> None:
    """A ValueError naming `name` unless `max_evaluations` covers the first simplex."""
    needed = minimum_evaluations(parameter_count)
    if max_evaluations < needed:
        raise ValueError(
            f"{name} {max_evaluations}: fitting {parameter_count} parameters needs at "
            f"least {needed} (one a parameter and one more: the first simplex)"
        )


def _holdout_windows(
    recording: Recording, fit_window: Window, holdout_ms: tuple[float, float] | None | str
) -> list[Window]:
    if holdout_ms is None:
        return []
    if isinstance(holdout_ms, str) and holdout_ms != "rest":
        raise ValueError(f"holdout_ms: (start, end) in ms, 'rest' or None, got {holdout_ms!r}")
    if holdout_ms != "rest":
        return [recording.window_us(holdout_ms)]  # type: ignore[arg-type]
    # The rest on both sides; a part under one rate bin (the road recording's last frame lies
    # 1 us after 2320 ms) holds nothing to score.
    first, last = int(recording.times_us[0]), int(recording.times_us[-1])
    rest = [(first, fit_window[0]), (fit_window[1], last)]
    return [(a, b) for a, b in rest if b - a >= RATE_BIN_US]


def _check_scorable(recording: Recording, windows: list[Window], what: str, option: str) -> None:
    """A ValueError naming the span and `option` unless it can be scored: two whole rate bins
    (a rate correlation needs two points) and MIN_SCORED_EVENTS recorded events."""
    origin = int(recording.times_us[0])
    shown = " + ".join(f"{(a - origin) / 1e3:g}:{(b - origin) / 1e3:g} ms" for a, b in windows)
    length_us = sum(b - a for a, b in (scored_window(w) for w in windows))
    if length_us < 2 * RATE_BIN_US:
        raise ValueError(
            f"{what} {shown} is shorter than two {RATE_BIN_US // 1000} ms rate bins, too short "
            f"to score; choose another with {option}"
        )
    count = recording.recorded_events(windows)
    if count < MIN_SCORED_EVENTS:
        raise ValueError(
            f"{what} {shown} holds {count} recorded events, too few to score (at least "
            f"{MIN_SCORED_EVENTS}); choose another with {option}"
        )
