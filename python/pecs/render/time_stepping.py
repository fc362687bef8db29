"""Frame times: a fixed rate, or adaptive steps from the motion measured between frames.

Adaptive rule (after ESIM, Rebecq et al., CoRL 2018): dt = fraction * theta / |dL/dt|, bounded by
1 / max_rate <= dt <= 1 / min_rate. A step whose change still exceeds fraction * theta is halved
and rendered again (renders are deterministic: the same sampler seed every frame).

ESIM takes the largest |Delta L| over pixels. On a path-traced scene that maximum is set by
Monte Carlo outliers (a pixel whose few samples switch between light and shadow jumps by several
log units) and by sharp edges, whose pixels jump by a share of the edge's whole contrast as each
of their few samples is crossed, whatever the speed: on the built-in room scene it sits at the
max rate at 4, 16 and 64 spp alike. pecs measures instead the motion that the frame pair shows
(`motion_px`, from many pixels at once, where outliers average out), and bounds the
change it makes at an edge of one threshold's contrast: fraction * theta, i.e. at most
`fraction` pixels of image motion per step. A change common to the whole image (light fading)
counts as it is.

A flickering lamp (`pecs.render.flicker`) changes the light every period whether anything moves
or not, and a step of a whole period would see no change at all: with one, steps are capped at
1 / (SAMPLES_PER_PERIOD f), 20 a period, whatever the measured change.

Exact motion (`AdaptiveStepper.exact_step`): a renderer that knows the scene's animation knows
how far each visible surface point moves in the image over any step (its object's and the
camera's motion, projected: the ground truth's motion field). A point moving at v px/s moves
k = `threshold_fraction` pixels in k / v seconds: that is the step, from the first frame on (no
ramp from the finest step) and without the Monte Carlo noise that inflates a measured motion at
low light or spp, so it needs no safety margin and no rejected renders. It sees surfaces only: a
shadow or a reflection moves with its caster, and a change common to the whole image is still
measured from the frames (`common_change`).
"""

from __future__ import annotations

import math
from collections.abc import Callable
from statistics import NormalDist

import numpy as np

from pecs.render.flicker import SAMPLES_PER_PERIOD
from pecs.render.scene_file import TimeStepping

US_PER_S = 1_000_000

#: Blocks (pixels a side) over which the motion is measured: an edge crossing one has 16 pixels
#: to average its Monte Carlo noise over.
BLOCK_PX = 16
#: The share of blocks whose motion bounds the step: an object in 1 % of the image still sets it,
#: a few outlier blocks (a firefly on a flat wall) do not.
BLOCK_PERCENTILE = 99.0
#: Blocks without an edge this many log units high across them hold nothing whose motion could
#: fire an event (1 %: the smallest threshold pecs accepts, `theta_min`).
MIN_EDGE_RISE = 0.01
#: |b|^2 of pure noise is exponential across blocks with mean s^2 trace(M): removing 7 times
#: that leaves e^-7 = 0.1 % of noise-only blocks moving, fewer than the percentile ignores.
NOISE_SHARE = 7.0
#: Motion per step beyond this is not measured (a step that long is rejected anyway).
MAX_SHIFT_PX = 2.0
#: Steps aim at this share of the limit, and grow at most by GROWTH per step, so that a
#: measurement's scatter (a few blocks decide the percentile) seldom costs a rejected render.
SAFETY = 0.8
GROWTH = 2.0
#: Exact motion is smooth, not linear: the motion over the step k / v (v from the finest step) is
#: checked, and where it speeds up the step is searched for (regula falsi between a step within
#: the limit and one beyond), with at most this many more evaluations.
EXACT_TRIES = 6

# 1.4826 * median |x| is the standard deviation of a normal x (1 / Phi^-1(3/4)).
_MAD_TO_SIGMA = 1.0 / NormalDist().inv_cdf(0.75)


def fixed_times_us(duration_s: float, rate_hz: float) -> np.ndarray:
    """0, 1/rate, 2/rate, ... and the duration itself as the last time, in integer µs."""
    end_us = round(duration_s * US_PER_S)
    count = math.floor(duration_s * rate_hz + 1e-9)
    times = np.round(np.arange(count + 1) * (US_PER_S / rate_hz)).astype(np.int64)
    times = times[times < end_us]
    return np.append(times, end_us)


def exact_step_us(motion_px: float, over_us: float, limit_px: float) -> float:
    """The step over which a point that moves `motion_px` pixels in `over_us` µs moves
    `limit_px`: k / v with v = motion_px / over_us (infinite for no motion)."""
    if motion_px <= 0.0:
        return math.inf
    return limit_px * over_us / motion_px


def log_intensity(frame: np.ndarray, dark_current: float) -> np.ndarray:
    """L = log(I + I_dark): what the pixel compares against its threshold."""
    return np.log(frame.astype(np.float64) + dark_current)


def max_log_change(previous: np.ndarray, current: np.ndarray) -> float:
    """Largest |Delta L| over pixels between two log frames (ESIM's statistic)."""
    return float(np.max(np.abs(current - previous)))


def common_change(previous: np.ndarray, current: np.ndarray) -> float:
    """The median Delta L: a change every pixel shares (light fading), not motion."""
    return float(np.median(current - previous))


def motion_px(previous: np.ndarray, current: np.ndarray) -> float:
    """Image motion in pixels between two log frames, at the BLOCK_PERCENTILE of blocks.

    Per block, the least-squares motion of brightness constancy (Lucas and Kanade, 1981):
    Delta L = -grad L . u, so b = sum grad L Delta L = -M u with M = sum grad L grad L^T, and the
    motion across the block's edges is |u| = |b| / lambda_max(M) (exact for one edge direction
    and for isotropic texture; the motion along an edge is invisible and fires nothing). grad L
    are central differences of the frames' mean. A grating of period P shifted by d gives
    sin(2 pi d / P) / sin(2 pi / P) = d (1 + O(P^-2)). Noise is no motion: for independent noise
    Delta L and the mean frame are uncorrelated, so b averages to 0 over the block (its expected
    square, from the noise level of Delta L, is removed), and a pixel's change is clipped to what
    MAX_SHIFT_PX of motion could give it, so a firefly counts like a pixel of moving texture.
    The sums also average the few-sample jumps of edges at low spp into their mean.
    """
    change = current - previous
    change = change - np.median(change)
    gy, gx = np.gradient(0.5 * (previous + current))
    noise = white_noise_sigma(change)
    # A pixel cannot change by more than MAX_SHIFT_PX pixels' worth of its gradient (plus noise)
    # by moving: a larger jump (a firefly) counts only as much.
    bound = MAX_SHIFT_PX * np.hypot(gx, gy) + 3.0 * noise
    change = np.clip(change, -bound, bound)
    bx, by = _block_sums(gx * change), _block_sums(gy * change)
    mxx, mxy, myy = _block_sums(gx * gx), _block_sums(gx * gy), _block_sums(gy * gy)
    half_trace = 0.5 * (mxx + myy)
    lambda_max = half_trace + np.sqrt((0.5 * (mxx - myy)) ** 2 + mxy**2)
    textured = lambda_max >= BLOCK_PX * MIN_EDGE_RISE**2
    if not np.any(textured):
        return 0.0
    # Noise of sigma s in Delta L gives E|b|^2 = s^2 trace(M): remove NOISE_SHARE of it.
    noise_b2 = NOISE_SHARE * noise**2 * (mxx + myy)
    signal_b = np.sqrt(np.maximum(bx**2 + by**2 - noise_b2, 0.0))
    motion = signal_b[textured] / lambda_max[textured]
    return float(np.percentile(motion, BLOCK_PERCENTILE))


def white_noise_sigma(image: np.ndarray) -> float:
    """Sigma of the pixel-independent noise in an image, from the median of its 4-neighbour
    Laplacian (variance 20 s^2 for white noise; small for smooth fields, and edges are too few
    to move the median): s = 1.4826 median |Laplacian| / sqrt(20)."""
    laplacian = (
        4.0 * image[1:-1, 1:-1]
        - image[:-2, 1:-1]
        - image[2:, 1:-1]
        - image[1:-1, :-2]
        - image[1:-1, 2:]
    )
    if laplacian.size == 0:
        return 0.0
    return _MAD_TO_SIGMA * float(np.median(np.abs(laplacian))) / math.sqrt(20.0)


def _block_sums(image: np.ndarray) -> np.ndarray:
    """Sums over BLOCK_PX x BLOCK_PX blocks (smaller ones at the right and bottom borders)."""
    rows = np.add.reduceat(image, np.arange(0, image.shape[0], BLOCK_PX), axis=0)
    return np.add.reduceat(rows, np.arange(0, image.shape[1], BLOCK_PX), axis=1)


class AdaptiveStepper:
    """Chooses each next frame time from the last step's change (`change`).

    `periodic_hz`: the fastest periodic light of the scene (a lamp's flicker), whose period
    the steps must sample SAMPLES_PER_PERIOD times (the step is capped at 1 / (20 f))."""

    def __init__(
        self, stepping: TimeStepping, theta: float, periodic_hz: float | None = None
    ) -> None:
        assert stepping.min_rate_hz is not None and stepping.max_rate_hz is not None
        self.theta = theta
        self.limit = stepping.threshold_fraction * theta
        #: Pixels of image motion a step may hold (the exact-motion rule's k).
        self.limit_px = stepping.threshold_fraction
        self.min_step_us = max(1, round(US_PER_S / stepping.max_rate_hz))
        self.max_step_us = max(self.min_step_us, round(US_PER_S / stepping.min_rate_hz))
        if periodic_hz is not None:
            sampled_us = math.floor(US_PER_S / (SAMPLES_PER_PERIOD * periodic_hz))
            self.max_step_us = max(self.min_step_us, min(self.max_step_us, sampled_us))

    def change(self, previous: np.ndarray, current: np.ndarray) -> float:
        """The step's log change: the common change, plus theta times the motion in pixels (the
        change that motion makes at an edge of one threshold's contrast)."""
        return abs(common_change(previous, current)) + self.theta * motion_px(previous, current)

    def first_step_us(self) -> int:
        """Nothing is known about the motion yet: start at the finest step."""
        return self.min_step_us

    def next_step_us(self, change: float, step_us: int) -> int:
        """ESIM's dt = limit / |dL/dt| (times SAFETY, at most GROWTH times the last step),
        clamped to the rate bounds."""
        wanted = GROWTH * step_us
        if change > 0.0:
            wanted = min(wanted, SAFETY * self.limit * step_us / change)
        return int(min(self.max_step_us, max(self.min_step_us, math.floor(wanted))))

    def exact_step(self, motion_px_over: Callable[[int], float]) -> int:
        """The longest step (within the rate bounds and the flicker cap) over which no visible
        surface point moves more than `limit_px` pixels, from the exact image motion
        `motion_px_over(step_us)` (the largest over the points seen now, for a step from now):
        k / v with the speed v from the finest step, then the motion over that step checked and,
        where the motion speeds up, the longest step within the limit searched for."""
        good_us = self.min_step_us
        good_px = motion_px_over(good_us)
        step_us = self._clamped(exact_step_us(good_px, good_us, self.limit_px))
        if good_px >= self.limit_px or step_us <= good_us:
            return good_us
        bad: tuple[int, float] | None = None
        for _ in range(EXACT_TRIES):
            moved_px = motion_px_over(step_us)
            if moved_px <= self.limit_px:
                good_us, good_px = step_us, moved_px
                if bad is None:  # as long as the rate bounds allow: nothing to search
                    return good_us
            else:
                bad = (step_us, moved_px)
            # the step at which the motion reaches the limit, on the line through the two
            bad_us, bad_px = bad
            share = (self.limit_px - good_px) / (bad_px - good_px)
            step_us = math.floor(good_us + share * (bad_us - good_us))
            if step_us <= good_us:
                break
        return good_us

    def exact_next_step_us(self, common: float, step_us: int, exact_us: int) -> int:
        """The step of the exact-motion rule: `exact_us` (`exact_step`), shorter where the
        last step's common change `common` (light fading; measured) asks for it as in
        `next_step_us`."""
        if common <= 0.0:
            return exact_us
        return min(exact_us, self._clamped(SAFETY * self.limit * step_us / common))

    def _clamped(self, step_us: float) -> int:
        """A step within the rate bounds (and the flicker cap), whole µs."""
        if not math.isfinite(step_us):
            return self.max_step_us
        return int(min(self.max_step_us, max(self.min_step_us, math.floor(step_us))))

    def accept(self, change: float, step_us: int) -> bool:
        """A step is kept when its change is within the limit or it is already the finest."""
        return change <= self.limit or step_us <= self.min_step_us

    def shorter(self, step_us: int) -> int:
        """The retry after a rejected step: half as long, never below the finest."""
        return max(self.min_step_us, step_us // 2)
