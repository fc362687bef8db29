"""Frame times: a fixed rate, or adaptive steps from the predicted log-intensity change.

Adaptive rule (ESIM, Rebecq et al., CoRL 2018): dt = fraction * theta / max_pixels |dL/dt|, with
dL/dt the per-pixel rate seen over the last step, bounded by 1 / max_rate <= dt <= 1 / min_rate.
A step whose measured change still exceeds fraction * theta is halved and rendered again (renders
are deterministic: the same sampler seed every frame), so the bound holds, not only on average,
down to the max-rate step.
"""

from __future__ import annotations

import math

import numpy as np

from pecs.render.scene_file import TimeStepping

US_PER_S = 1_000_000


def fixed_times_us(duration_s: float, rate_hz: float) -> np.ndarray:
    """0, 1/rate, 2/rate, ... and the duration itself as the last time, in integer µs."""
    end_us = round(duration_s * US_PER_S)
    count = math.floor(duration_s * rate_hz + 1e-9)
    times = np.round(np.arange(count + 1) * (US_PER_S / rate_hz)).astype(np.int64)
    times = times[times < end_us]
    return np.append(times, end_us)


def log_intensity(frame: np.ndarray, dark_current: float) -> np.ndarray:
    """L = log(I + I_dark): what the pixel compares against its threshold."""
    return np.log(frame.astype(np.float64) + dark_current)


def max_log_change(previous: np.ndarray, current: np.ndarray) -> float:
    """Largest |Delta L| over pixels between two log frames."""
    return float(np.max(np.abs(current - previous)))


class AdaptiveStepper:
    """Chooses each next frame time from the last step's largest log-intensity rate."""

    def __init__(self, stepping: TimeStepping, theta: float) -> None:
        assert stepping.min_rate_hz is not None and stepping.max_rate_hz is not None
        self.limit = stepping.threshold_fraction * theta
        self.min_step_us = max(1, round(US_PER_S / stepping.max_rate_hz))
        self.max_step_us = max(self.min_step_us, round(US_PER_S / stepping.min_rate_hz))

    def first_step_us(self) -> int:
        """Nothing is known about the motion yet: start at the finest step."""
        return self.min_step_us

    def next_step_us(self, change: float, step_us: int) -> int:
        """ESIM's dt = limit / max |dL/dt|, clamped to the rate bounds."""
        if change <= 0.0:
            return self.max_step_us
        wanted = self.limit * step_us / change
        return int(min(self.max_step_us, max(self.min_step_us, math.floor(wanted))))

    def accept(self, change: float, step_us: int) -> bool:
        """A step is kept when its change is within the limit or it is already the finest."""
        return change <= self.limit or step_us <= self.min_step_us

    def shorter(self, step_us: int) -> int:
        """The retry after a rejected step: half as long, never below the finest."""
        return max(self.min_step_us, step_us // 2)
