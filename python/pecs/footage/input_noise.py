"""Input noise of real footage: the read and shot noise of a frame camera, held back before its
frames reach the DVS model.

A camera frame carries temporal noise that the DVS pixel does not see (its photoreceptor is a
different circuit, and integrates nothing per frame): about 1.5 DN rms frame to frame on a
DAVIS346's APS, the photon shot noise of a video. Fed as light, it makes events: a 1.5 DN
difference on a 10 DN pixel is a log change of 0.14, above davis346's ON threshold
(docs/realism-findings.md: ~2 Hz per pixel of events on constant frames with 1.5 DN of noise,
~20 Hz in dark pixels, against 0.003 Hz real).

The remedy here is a per-pixel deadband of k sigma: a pixel's input is held until a frame moves
more than k sigma(level) away from it, sigma(level) the frames' temporal noise at that level.
The band is centred on the mean of the frames since the last move, so that it gets better with
time rather than sitting on the first noisy sample. A change that leaves the band is
passed at once and whole, at its own frame: an edge or step well above the noise keeps the
timing and size it has without the filter. A temporal low-pass would instead smear and delay
every real change to quieten the noise, and no filter of that kind reaches zero events on a
constant scene. What the deadband loses is changes smaller than k sigma (for 1.5 DN and k = 5,
7.5 % contrast on a 100 DN pixel, under the DAVIS's 14 % threshold; more in the dark, where a
real pixel is also slow and noisy).

sigma(level) is the noise-level function sigma^2 = read^2 + gain * level (read noise plus photon
shot noise, linear in the signal), estimated from the frames themselves: frame-to-frame
differences, binned by level, with a robust spread (moving pixels are outliers), fitted by the
line in sigma^2. Or stated by the user (`InputNoise(read_sigma, shot_gain)`).
"""

from __future__ import annotations

import warnings
from collections.abc import Iterable, Iterator
from dataclasses import dataclass

import numpy as np

#: Deadband half-width in standard deviations of (frame - mean of the n frames held), which is
#: sigma sqrt(1 + 1 / n). A still pixel leaves its band on 5.7e-7 of frames at 5 sigma: once in
#: 20 hours at 25 Hz (at 4 sigma, 6e-5: every 11 minutes, each a jump of 4 sigma, an event in a
#: dark pixel). On the DAVIS346 road recording 4 and 5 differ by 4 % in count (benches/
#: sim_to_real.py); the contrast lost, 5 x 1.5 DN = 7.5 % at 100 DN, is under davis346's 14 %.
DEFAULT_DEADBAND_SIGMAS = 5.0
#: Frames read ahead to estimate the noise when it is not given.
ESTIMATE_FRAMES = 16
_LEVEL_BINS = 16
_MIN_SAMPLES_PER_BIN = 200


#: Widest deadband. A still pixel leaves a band of 8 sigma on 1e-15 of its frames: past that a
#: wider band holds back nothing but real changes, and at 100 sigma a pixel with 1 % noise is held
#: through a change of all its light.
MAX_DEADBAND_SIGMAS = 100.0
#: Largest stated noise (read_sigma, and shot_gain per unit of level): frames are float32, so a
#: noise past their range describes no frame (and its square overflowed into warnings).
MAX_NOISE = float(np.finfo(np.float32).max)


def check_at_least_zero(name: str, value: float) -> None:
    """A ValueError naming `name` unless `value` is a finite number >= 0."""
    if not (isinstance(value, (int, float)) and np.isfinite(value) and value >= 0):
        raise ValueError(f"{name}: must be a finite number >= 0, got {value!r}")


def check_deadband_sigmas(name: str, value: float) -> None:
    """A ValueError naming `name` unless `value` is a deadband in sigmas, 0 to
    MAX_DEADBAND_SIGMAS."""
    check_at_least_zero(name, value)
    if value > MAX_DEADBAND_SIGMAS:
        raise ValueError(
            f"{name}: {value:g} sigma holds back every real change; at most "
            f"{MAX_DEADBAND_SIGMAS:g} (5 is the default, 8 is never left by noise alone)"
        )


def check_noise(name: str, value: float) -> None:
    """A ValueError naming `name` unless `value` is a noise figure (read sigma or shot gain) of
    float32 frames: 0 to MAX_NOISE."""
    check_at_least_zero(name, value)
    if value > MAX_NOISE:
        raise ValueError(
            f"{name}: {value:g} is past float32's range ({MAX_NOISE:.3g}), the frames' type"
        )


@dataclass(frozen=True)
class InputNoise:
    """Temporal noise of the frames, in frame units: sigma(level)^2 = read_sigma^2 +
    shot_gain * level, and the deadband half-width in sigmas."""

    read_sigma: float
    shot_gain: float = 0.0
    deadband_sigmas: float = DEFAULT_DEADBAND_SIGMAS

    def __post_init__(self) -> None:
        check_noise("read_sigma", self.read_sigma)
        check_noise("shot_gain", self.shot_gain)
        check_deadband_sigmas("deadband_sigmas", self.deadband_sigmas)

    def sigma(self, level: np.ndarray) -> np.ndarray:
        """Noise standard deviation at each level (frame units), float64: the largest noise
        squared is past float32's range."""
        level = np.maximum(np.asarray(level, np.float64), 0.0)
        return np.sqrt(np.float64(self.read_sigma) ** 2 + self.shot_gain * level)

    @classmethod
    def estimate(
        cls, frames: np.ndarray, deadband_sigmas: float = DEFAULT_DEADBAND_SIGMAS
    ) -> InputNoise:
        """The noise-level function of a stack of frames (N >= 2, H, W) of a mostly still scene
        or a static camera: sigma per level from frame differences, the line in sigma^2 fitted."""
        stack = np.asarray(frames, np.float32)
        if stack.ndim != 3 or len(stack) < 2:
            raise ValueError(
                f"need at least 2 frames (N, H, W) to estimate noise, got {stack.shape}"
            )
        levels, variances, weights = _binned_variances(stack)
        if not len(levels):
            warnings.warn(
                f"frames {stack.shape} hold {stack[0].size * (len(stack) - 1)} frame-to-frame "
                f"differences, fewer than the {_MIN_SAMPLES_PER_BIN} needed to estimate their "
                "noise: no input noise is held back",
                stacklevel=2,
            )
            return cls(0.0, 0.0, deadband_sigmas)
        read_var, gain = _fit_variance_line(levels, variances, weights)
        return cls(float(np.sqrt(read_var)), float(gain), deadband_sigmas)


def _binned_variances(stack: np.ndarray) -> tuple[np.ndarray, np.ndarray, np.ndarray]:
    """Per-frame noise variance by level: half the robust variance of consecutive differences
    (each difference holds two frames' noise), in level bins with enough samples (fewer bins
    where a small sensor or few frames cannot fill them all)."""
    differences = np.diff(stack, axis=0).ravel()
    levels = (0.5 * (stack[1:] + stack[:-1])).ravel()
    bins = max(1, min(_LEVEL_BINS, len(levels) // _MIN_SAMPLES_PER_BIN))
    edges = np.quantile(levels, np.linspace(0.0, 1.0, bins + 1))
    which = np.clip(np.searchsorted(edges, levels, side="right") - 1, 0, bins - 1)
    centres, variances, counts = [], [], []
    for b in range(bins):
        in_bin = differences[which == b]
        if len(in_bin) < _MIN_SAMPLES_PER_BIN:
            continue
        centres.append(float(np.median(levels[which == b])))
        variances.append(_robust_variance(in_bin) / 2.0)
        counts.append(len(in_bin))
    return np.array(centres), np.array(variances), np.array(counts, float)


def _robust_variance(d: np.ndarray) -> float:
    """Variance of the bulk of `d`, with outliers (moving pixels) cut at 4 robust sigmas. The
    MAD sets the cut; the variance inside it is what is returned, since on 8-bit frames the
    MAD itself is quantised to whole DN."""
    centred = d - np.median(d)
    mad_sigma = 1.4826 * float(np.median(np.abs(centred)))
    nonzero = np.abs(centred[centred != 0])
    quantum = float(nonzero.min()) if len(nonzero) else 0.0
    cut = 4.0 * max(mad_sigma, quantum)
    inside = centred[np.abs(centred) <= cut]
    # A Gaussian cut at 4 sigma keeps 99.9 % of its variance: no correction needed.
    return float(np.mean(inside**2)) if len(inside) else 0.0


def _fit_variance_line(
    levels: np.ndarray, variances: np.ndarray, weights: np.ndarray
) -> tuple[float, float]:
    """Weighted least squares of variance = read^2 + gain * level, both >= 0."""
    if len(levels) == 1 or np.ptp(levels) == 0:
        return float(np.average(variances, weights=weights)), 0.0
    design = np.stack([np.ones_like(levels), levels], axis=1) * np.sqrt(weights)[:, None]
    (read_var, gain), *_ = np.linalg.lstsq(design, variances * np.sqrt(weights), rcond=None)
    if gain < 0:  # noise not growing with light: read noise alone
        return float(np.average(variances, weights=weights)), 0.0
    if read_var < 0:  # shot noise alone: the line through the origin
        return 0.0, float(np.sum(weights * levels * variances) / np.sum(weights * levels**2))
    return float(read_var), float(gain)


class InputDeadband:
    """Frame by frame: each pixel's input held until a frame leaves the band of
    deadband_sigmas * sigma around the mean of the frames since the last move; it then takes
    that frame's value. The output does not follow the mean (a still pixel's input stays exactly
    constant: in the dark, where the log is steep, even the mean's small steps make events);
    the mean only centres the band, so that a first noisy sample does not bias it."""

    def __init__(self, noise: InputNoise) -> None:
        self.noise = noise
        self._held: np.ndarray | None = None
        self._mean: np.ndarray | None = None
        self._count: np.ndarray | None = None

    def __call__(self, frame: np.ndarray) -> np.ndarray:
        value = np.asarray(frame, np.float32)
        if self._held is None or self._mean is None or self._count is None:
            # The mean and the band in float64: a frame's value less the mean, and a band of
            # up to 100 sigma, are past float32's range where the frames are near its ends.
            self._held, self._mean = value.copy(), value.astype(np.float64)
            self._count = np.ones(value.shape, np.float32)
            return self._held.copy()
        # frame - mean of n frames has variance sigma^2 (1 + 1 / n).
        spread = self.noise.sigma(self._mean) * np.sqrt(1.0 + 1.0 / self._count, dtype=np.float64)
        band = self.noise.deadband_sigmas * spread
        moved = np.abs(value - self._mean) > band
        self._count = np.where(moved, 1.0, self._count + 1.0).astype(np.float32)
        self._mean = np.where(moved, value, self._mean + (value - self._mean) / self._count)
        self._held = np.where(moved, value, self._held).astype(np.float32)
        return self._held.copy()


def suppress_input_noise(
    pairs: Iterable[tuple[int, np.ndarray]],
    noise: InputNoise | None = None,
    *,
    deadband_sigmas: float | None = None,
) -> Iterator[tuple[int, np.ndarray]]:
    """(t_us, frame) pairs with the frames' own noise held back by `InputDeadband`. Without
    `noise`, it is estimated from the first ESTIMATE_FRAMES frames (read ahead, then replayed),
    with a deadband of `deadband_sigmas` (None: DEFAULT_DEADBAND_SIGMAS)."""
    if deadband_sigmas is None:
        deadband_sigmas = DEFAULT_DEADBAND_SIGMAS
    stream = iter(pairs)
    ahead: list[tuple[int, np.ndarray]] = []
    if noise is None:
        for pair in stream:
            ahead.append(pair)
            if len(ahead) == ESTIMATE_FRAMES:
                break
        if len(ahead) >= 2:
            noise = InputNoise.estimate(np.stack([f for _, f in ahead]), deadband_sigmas)
        else:
            noise = InputNoise(0.0, 0.0, deadband_sigmas)
    deadband = InputDeadband(noise)
    for t_us, frame in _chain(ahead, stream):
        yield t_us, deadband(frame)


def _chain(
    first: list[tuple[int, np.ndarray]], rest: Iterator[tuple[int, np.ndarray]]
) -> Iterator[tuple[int, np.ndarray]]:
    yield from first
    yield from rest


def is_camera_footage(kind: str) -> bool:
    """Whether frames of this source kind come from a real camera (with read and shot noise):
    AEDAT4 APS frames and videos. Images, EXR and arrays may be rendered: no filter by default."""
    return kind in ("aedat4", "video")
