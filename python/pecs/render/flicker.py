"""Mains flicker: the light of a lamp on alternating current, as a factor on its mean level.

A lamp on 50 Hz (60 Hz) mains draws power twice a mains period, so its light is modulated at
100 Hz (120 Hz): `frequency_hz` is that modulation frequency, not the mains frequency. How far
the light swings is its modulation depth, (max - min) / (max + min) over a period: the
"amplitude of fluctuation of the luminous flux" of the CIE International Lighting Vocabulary
(CIE S 017), which the IES Lighting Handbook and IEEE 1789-2015 give as percent flicker
= 100 x depth (the IES name; "modulation (%)" in IEEE 1789). 0: steady light; 1: the light goes out every period.

The factor has mean 1 over a period, so a lamp's stated level (the `illuminance_lux` of
`[light]`, a scale, a frame's value) is what a lux meter, which averages, reads:

    w(t) = c ((1 - depth) + 2 depth s(t)),   c = 1 / ((1 - depth) + 2 depth mean(s)),

with the period's shape s in [0, 1]: "sine", s = sin^2(pi f t) (the power of a sine current; a
filament's thermal inertia leaves the fundamental, a sine at f), or "rectified", s = |sin(pi f t)|
(the rectified mains current of a capacitor-less LED driver or a magnetic ballast). At t = 0 the
mains crosses zero: the light is at its least. `phase_deg` moves that (360 = one flicker period),
for lamps on the other phases of a three-phase supply.
"""

from __future__ import annotations

import math
from collections.abc import Iterable, Iterator
from dataclasses import dataclass

import numpy as np

WAVEFORMS = ("sine", "rectified")
#: Samples (frames) per flicker period that the renderer and the sub-frames take: the light of
#: a sine sampled at 20 points and interpolated linearly in log is within 1.3 % of the sine at
#: 30 % depth, and its 100 Hz line stands as the sine's (an 18-degree step).
SAMPLES_PER_PERIOD = 20
#: The finest frame step is 1 us (times are whole microseconds): 20 steps a period at most.
MAX_FREQUENCY_HZ = 1e6 / SAMPLES_PER_PERIOD

# Mean of s over a period, per waveform: sin^2 averages 1/2, |sin| averages 2/pi.
_SHAPE_MEAN = {"sine": 0.5, "rectified": 2.0 / math.pi}


@dataclass(frozen=True)
class Lamp:
    """A kind of lamp: its modulation depth and waveform at twice the mains frequency."""

    depth: float
    waveform: str
    source: str


#: Lamp presets: percent flicker / 100 at 100-120 Hz, from the survey of measured lamps in IEEE
#: 1789-2015 (section 4 and its references: Lehman et al., "Proposing measures of flicker in the
#: low frequencies for lighting applications", 2011; Poplawski and Miller, "Flicker in
#: solid-state lighting", PNNL / CIE 2013) and the DOE SSL fact sheet "Flicker" (PNNL, 2013).
#: Real lamps of one kind spread widely (the ranges below): these are typical, not a model.
LAMPS: dict[str, Lamp] = {
    # Incandescent lamps: about 5-15 %, less for high wattages (thick filaments cool slowly)
    # and more for low ones; the filament's thermal inertia leaves a near-sine.
    "incandescent": Lamp(0.07, "sine", "household incandescent lamp, 5-15 %"),
    # Linear fluorescent lamps on magnetic ballasts: about 30-40 %; the phosphor's persistence
    # keeps the light from going out at the zero crossing.
    "fluorescent_magnetic": Lamp(0.35, "rectified", "fluorescent on a magnetic ballast, 30-40 %"),
    # An LED whose driver has no storage capacitor follows the rectified mains current and goes
    # dark near every zero crossing: 100 %.
    "led_poor": Lamp(1.0, "rectified", "capacitor-less (AC) LED driver, 100 %"),
    # A good constant-current driver leaves a small ripple: IEEE 1789-2015's no-observable-effect
    # level (its recommended practices: percent flicker <= 0.0333 x f: 3.3 % at 100 Hz), rounded down.
    "led_good": Lamp(0.03, "sine", "constant-current LED driver, within IEEE 1789's NOEL"),
}


@dataclass(frozen=True)
class Flicker:
    """A light modulated at `frequency_hz` with modulation `depth` (see the module)."""

    frequency_hz: float
    depth: float
    waveform: str = "sine"
    phase_deg: float = 0.0

    def __post_init__(self) -> None:
        reason = frequency_problem(self.frequency_hz)
        if reason is not None:
            raise ValueError(f"frequency_hz: {reason}")
        reason = depth_problem(self.depth)
        if reason is not None:
            raise ValueError(f"depth: {reason}")
        if self.waveform not in WAVEFORMS:
            raise ValueError(
                f"waveform: expected one of {', '.join(WAVEFORMS)}, got {self.waveform!r}"
            )
        if not math.isfinite(self.phase_deg):
            raise ValueError(f"phase_deg: must be a finite number, got {self.phase_deg!r}")

    @classmethod
    def lamp(cls, name: str, frequency_hz: float, phase_deg: float = 0.0) -> Flicker:
        """A preset lamp (`LAMPS`) at `frequency_hz` (100 on 50 Hz mains, 120 on 60 Hz)."""
        if name not in LAMPS:
            raise ValueError(f"lamp: unknown lamp {name!r}; known: {', '.join(LAMPS)}")
        lamp = LAMPS[name]
        return cls(frequency_hz, lamp.depth, lamp.waveform, phase_deg)

    @property
    def period_us(self) -> float:
        return 1e6 / self.frequency_hz

    @property
    def min_rate_hz(self) -> float:
        """The frame rate that samples the light SAMPLES_PER_PERIOD times a period."""
        return SAMPLES_PER_PERIOD * self.frequency_hz

    def factor(self, t_s: float | np.ndarray) -> float | np.ndarray:
        """The light at `t_s` relative to its mean (see the module's formula)."""
        angle = np.pi * (
            self.frequency_hz * np.asarray(t_s, dtype=np.float64) + self.phase_deg / 360.0
        )
        shape = np.sin(angle) ** 2 if self.waveform == "sine" else np.abs(np.sin(angle))
        scale = 1.0 / ((1.0 - self.depth) + 2.0 * self.depth * _SHAPE_MEAN[self.waveform])
        value = scale * ((1.0 - self.depth) + 2.0 * self.depth * shape)
        return float(value) if np.ndim(value) == 0 else value

    def as_dict(self) -> dict[str, float | str]:
        return {
            "frequency_hz": self.frequency_hz,
            "depth": self.depth,
            "waveform": self.waveform,
            "phase_deg": self.phase_deg,
        }


def frequency_problem(frequency_hz: object) -> str | None:
    """Why a flicker frequency cannot be simulated, or None."""
    if isinstance(frequency_hz, bool) or not isinstance(frequency_hz, (int, float)):
        return f"must be a number of Hz, got {frequency_hz!r}"
    if not (math.isfinite(frequency_hz) and frequency_hz > 0):
        return f"must be a positive number of Hz, got {frequency_hz:g}"
    if frequency_hz > MAX_FREQUENCY_HZ:
        return (
            f"{frequency_hz:g} Hz needs samples {1e6 / (SAMPLES_PER_PERIOD * frequency_hz):.3g} "
            f"us apart ({SAMPLES_PER_PERIOD} a period); at most {MAX_FREQUENCY_HZ:g} Hz "
            "(timestamps are whole microseconds)"
        )
    return None


def depth_problem(depth: object) -> str | None:
    """Why a modulation depth is not one, or None."""
    if isinstance(depth, bool) or not isinstance(depth, (int, float)):
        return f"must be a number from 0 to 1, got {depth!r}"
    if not 0.0 <= depth <= 1.0:
        return f"must be from 0 (steady) to 1 (goes out every period), got {depth:g}"
    return None


def flickered(
    pairs: Iterable[tuple[int, np.ndarray]], flicker: Flicker, offset: float
) -> Iterator[tuple[int, np.ndarray]]:
    """(t_us, frame) pairs lit by `flicker`: each frame times the factor at its time, and between
    frames sub-frames at least SAMPLES_PER_PERIOD a period, each the frames interpolated as the
    sensor interpolates them (linearly in ln(frame + offset)) times the factor at its time.

    The sensor interpolates between the frames it is fed, so a light that changes between
    frames must be fed as frames: 2000 a second at 100 Hz, whatever the footage's rate."""
    previous: tuple[int, np.ndarray] | None = None
    for t_us, frame in pairs:
        if previous is not None:
            yield from _interval(previous, (t_us, frame), flicker, offset)
        yield t_us, _lit(frame, flicker.factor(t_us / 1e6))
        previous = (t_us, frame)


def _interval(
    start: tuple[int, np.ndarray], end: tuple[int, np.ndarray], flicker: Flicker, offset: float
) -> Iterator[tuple[int, np.ndarray]]:
    """The lit sub-frames strictly inside one interval."""
    (t0, frame0), (t1, frame1) = start, end
    steps = math.ceil((t1 - t0) * SAMPLES_PER_PERIOD / flicker.period_us - 1e-9)
    if steps <= 1:
        return
    u0 = np.log(np.maximum(frame0.astype(np.float64), 0.0) + offset)
    change = np.log(np.maximum(frame1.astype(np.float64), 0.0) + offset) - u0
    previous_us = t0
    for j in range(1, steps):
        t_us = t0 + round(j * (t1 - t0) / steps)
        if previous_us < t_us < t1:
            done = (t_us - t0) / (t1 - t0)  # the rounded time's own share of the interval
            light = np.maximum(np.exp(u0 + change * done) - offset, 0.0)
            yield t_us, _lit(light, flicker.factor(t_us / 1e6))
            previous_us = t_us


def _lit(frame: np.ndarray, factor: float) -> np.ndarray:
    """A frame's light times the flicker factor, as float32 photocurrent."""
    return (np.asarray(frame, dtype=np.float64) * factor).astype(np.float32)
