"""The ranges of a simulation's numbers, checked before any work (docs/scene-files.md, "Limits").

Beyond them a run cannot be done right, or would fail late with an error from numpy, Mitsuba or
Dr.Jit: timestamps are whole microseconds, so frames or IMU samples closer than 1 us would share
a time; the frame and IMU times are arrays allocated up front; Mitsuba counts samples per pixel
in 32 bits and renders at most 2^32 - 1 samples in one pass (beyond that it splits the frame into
passes, with a warning, each of them a wavefront of 2^32 samples: far more memory than a frame
needs).
"""

from __future__ import annotations

import math

#: Frames and IMU samples at least 1 us apart: event and frame times are integer microseconds.
MAX_RATE_HZ = 1e6
#: A run lasts at least one timestamp step...
MIN_DURATION_S = 1e-6
#: ...and at most about 11.6 days of scene time (frame times stay far inside int64 us).
MAX_DURATION_S = 1e6
#: Frames of one run (fixed steps; adaptive runs: at their minimum rate). Ten million frames
#: is hours of rendering at the smallest film and spp; more is a mistyped number.
MAX_FRAMES = 10_000_000
#: IMU samples of one run (each is three pose evaluations in Python; 1e7 take minutes).
MAX_IMU_SAMPLES = 10_000_000
#: Samples of one frame, width x height x spp: Mitsuba's 32-bit sample count and one pass.
MAX_SAMPLES_PER_FRAME = 2**32 - 1


class SettingError(ValueError):
    """A value given to `Simulation` (or read from a scene file) outside its range.

    `setting` is the keyword argument (`rate_hz`, `sensor`), or for a scene file's value its key
    (`time.rate_hz`) with `source` the file; `field` names the sensor field of a `sensor` value.
    The CLI and the dataset runner use them to name their own option or spec field."""

    def __init__(
        self,
        setting: str,
        value: object,
        reason: str,
        *,
        source: str | None = None,
        field: str | None = None,
    ) -> None:
        self.setting, self.value, self.reason = setting, value, reason
        self.source, self.field = source, field
        prefix = f"{source}: " if source else ""
        super().__init__(f"{prefix}{setting}: {reason}")


def rate_problem(rate_hz: float) -> str | None:
    """Why a frame or IMU rate cannot be used, or None."""
    if not (math.isfinite(rate_hz) and rate_hz > 0):
        return f"must be a positive number of Hz, got {rate_hz!r}"
    if rate_hz > MAX_RATE_HZ:
        return (
            f"{rate_hz:g} Hz puts samples {1e6 / rate_hz:.3g} us apart; at most {MAX_RATE_HZ:g} "
            "Hz (timestamps are whole microseconds)"
        )
    return None


def duration_problem(duration_s: float) -> str | None:
    """Why a duration cannot be simulated, or None."""
    if not (math.isfinite(duration_s) and duration_s > 0):
        return f"must be a positive number of seconds, got {duration_s!r}"
    if not MIN_DURATION_S <= duration_s <= MAX_DURATION_S:
        return (
            f"{duration_s:g} s is outside {MIN_DURATION_S:g} s (one timestamp step) to "
            f"{MAX_DURATION_S:g} s"
        )
    return None


def frames_problem(duration_s: float, rate_hz: float, adaptive: bool) -> str | None:
    """Why `duration_s` at `rate_hz` (the minimum rate of adaptive steps) is too many frames."""
    frames = duration_s * rate_hz
    if frames <= MAX_FRAMES:
        return None
    kind = "at least " if adaptive else ""
    return (
        f"{duration_s:g} s at {rate_hz:g} Hz is {kind}{frames:.3g} frames; at most "
        f"{MAX_FRAMES:.0e} a run: shorten the run or lower the frame rate"
    )


def imu_samples_problem(duration_s: float, imu_rate_hz: float) -> str | None:
    samples = duration_s * imu_rate_hz
    if samples <= MAX_IMU_SAMPLES:
        return None
    return (
        f"{duration_s:g} s at {imu_rate_hz:g} Hz is {samples:.3g} IMU samples; at most "
        f"{MAX_IMU_SAMPLES:.0e} a run: lower the IMU rate or shorten the run"
    )


def spp_problem(spp: int, pixels: int = 1) -> str | None:
    """Why `spp` samples per pixel of a film of `pixels` cannot be rendered, or None."""
    if isinstance(spp, bool) or not isinstance(spp, int) or spp < 1:
        return f"must be an integer >= 1, got {spp!r}"
    if spp > MAX_SAMPLES_PER_FRAME:
        return f"{spp} is more than Mitsuba's 32-bit sample count takes (2^32 - 1)"
    if spp * pixels > MAX_SAMPLES_PER_FRAME:
        return (
            f"{spp} samples per pixel of {pixels} pixels is {spp * pixels:.3g} samples a frame; "
            f"Mitsuba renders at most 2^32 - 1 in one pass: at most {MAX_SAMPLES_PER_FRAME // pixels}"
            " for this film"
        )
    return None
