"""APS exposure: a camera frame is the light averaged over its exposure, not the light at one
instant; `exposure_deconvolved` recovers the light at the frames' times from such frames.

A frame timed at its exposure midpoint t_k, exposed for E_k, holds
F_k = (1 / E_k) * integral of L(t) over [t_k - E_k / 2, t_k + E_k / 2]. If the light is linear
between the frame times (the sensor's own rule between the frames it is fed), L is the sum of
hat functions through its values L_j at the t_j, and each frame is a weighted mean of three
of them: F_k = a_k L_(k-1) + b_k L_k + c_k L_(k+1), with a_k = E_k / (8 (t_k - t_(k-1))) and
c_k = E_k / (8 (t_(k+1) - t_k)) for an exposure within both intervals, b_k = 1 - a_k - c_k.
Solving this tridiagonal system per pixel (deconvolution) gives the light L_k the sensor is
fed in place of F_k. Before the first and after the last frame the light is taken constant.
The system is diagonally dominant for exposures up to the frame interval (b_k >= 3/4): an
exposure of the whole interval amplifies frame-to-frame noise at most 2x (at the alternating
pattern, the inverse of 1 - E / 2T), half the interval 1.33x; a constant pixel stays constant
(every row sums to 1), so a pixel whose input noise is held back stays held.

The inverse sharpens a change that fell inside an exposure, and can overshoot a step: it is
kept within `CLAMP_FACTOR` of the range of the three frames it is solved from, which keeps the
light positive and a step's ringing from reaching far below the darkest frame around it in log
(the sensor's view). The system is solved in blocks of frames with an overlap on either side
(`OVERLAP` frames, over which the inverse's influence falls below 1e-9: its ratio from one
frame to the next is -3 + 2 sqrt(2) = -0.17 at the worst, an exposure of the whole interval),
so a sequence streams with bounded memory.
"""

from __future__ import annotations

from collections.abc import Iterable, Iterator, Sequence

import numpy as np

#: The light at a frame time is kept within [min / CLAMP_FACTOR, max * CLAMP_FACTOR] of the
#: three frames around it: ln 2 = 0.69, three davis346 thresholds, either way.
CLAMP_FACTOR = 2.0
#: Frames solved on either side of a block (and not emitted): the inverse's weight falls as
#: 0.17^k at the worst, below 1e-12 at 16 frames.
OVERLAP = 16
#: Frames emitted per block solve.
BLOCK = 64


def check_exposure(
    exposure_us: float | Sequence[float] | np.ndarray, times_us: np.ndarray
) -> np.ndarray:
    """The exposures as float64 per frame (one number: the same for every frame), checked:
    finite, >= 0, and no longer than either frame interval next to its frame."""
    times = np.asarray(times_us, np.int64)
    given = np.asarray(exposure_us)
    if (
        given.dtype.kind not in "iuf"
        or given.ndim > 1
        or (given.ndim == 1 and len(given) != len(times))
    ):
        raise ValueError(
            f"exposure_us: one exposure in us, or one per frame ({len(times)}), got "
            f"{given.dtype} of shape {given.shape}"
        )
    exposure = np.broadcast_to(given.astype(np.float64), times.shape).copy()
    bad = np.flatnonzero(~np.isfinite(exposure) | (exposure < 0))
    if bad.size:
        raise ValueError(
            f"exposure_us[{bad[0]}] is {exposure[bad[0]]}; an exposure is a finite time >= 0 us"
        )
    if len(times) >= 2:
        gaps = np.diff(times).astype(np.float64)
        shortest = np.minimum(np.r_[gaps[:1], gaps], np.r_[gaps, gaps[-1:]])
        long = np.flatnonzero(exposure > shortest)
        if long.size:
            k = int(long[0])
            raise ValueError(
                f"exposure_us: frame {k} is exposed for {exposure[k]:g} us, longer than its "
                f"frame interval ({shortest[k]:g} us); a frame cannot expose over its neighbour's"
            )
    return exposure


def exposure_weights(
    times_us: np.ndarray, exposure_us: np.ndarray
) -> tuple[np.ndarray, np.ndarray, np.ndarray]:
    """(a, b, c): frame k = a_k L_(k-1) + b_k L_k + c_k L_(k+1) for light linear between the
    frame times (module docstring); a_0 = c_(N-1) = 0, the light constant beyond the ends."""
    times = np.asarray(times_us, np.float64)
    a = np.zeros(len(times))
    c = np.zeros(len(times))
    if len(times) >= 2:
        gaps = np.diff(times)
        # Half the exposure, e, before t_k: the light there is L_k + (L_(k-1) - L_k) s / h for s
        # in [0, e], whose mean is L_k + (L_(k-1) - L_k) e / 2h; the frame averages both halves.
        a[1:] = exposure_us[1:] / (8.0 * gaps)
        c[:-1] = exposure_us[:-1] / (8.0 * gaps)
    return a, 1.0 - a - c, c


def deconvolve(frames: np.ndarray, times_us: np.ndarray, exposure_us: np.ndarray) -> np.ndarray:
    """The light at the frame times (N, ...) whose exposure averages are `frames`, clamped to
    CLAMP_FACTOR of the range of the frames around each (module docstring); float64."""
    a, b, c = exposure_weights(times_us, np.asarray(exposure_us, np.float64))
    values = np.asarray(frames, np.float64)
    light = _thomas(a, b, c, values)
    padded = np.concatenate([values[:1], values, values[-1:]])
    low = np.minimum(np.minimum(padded[:-2], padded[1:-1]), padded[2:])
    high = np.maximum(np.maximum(padded[:-2], padded[1:-1]), padded[2:])
    return np.clip(light, low / CLAMP_FACTOR, high * CLAMP_FACTOR)


def _thomas(a: np.ndarray, b: np.ndarray, c: np.ndarray, d: np.ndarray) -> np.ndarray:
    """The tridiagonal system a_k x_(k-1) + b_k x_k + c_k x_(k+1) = d_k, solved along axis 0
    (each pixel its own system); stable without pivoting for a diagonally dominant system."""
    n = len(d)
    c_prime = np.empty(n)
    d_prime = np.empty(d.shape)
    c_prime[0] = c[0] / b[0]
    d_prime[0] = d[0] / b[0]
    for k in range(1, n):
        pivot = b[k] - a[k] * c_prime[k - 1]
        c_prime[k] = c[k] / pivot
        d_prime[k] = (d[k] - a[k] * d_prime[k - 1]) / pivot
    x = np.empty(d.shape)
    x[-1] = d_prime[-1]
    for k in range(n - 2, -1, -1):
        x[k] = d_prime[k] - c_prime[k] * x[k + 1]
    return x


def exposure_deconvolved(
    pairs: Iterable[tuple[int, np.ndarray]],
    exposure_us: float | Sequence[float] | np.ndarray | None,
    *,
    block: int = BLOCK,
    overlap: int = OVERLAP,
) -> Iterator[tuple[int, np.ndarray]]:
    """(t_us, frame) pairs with each frame replaced by the light at its time (`deconvolve`),
    float32; the frames streamed in blocks of `block` with `overlap` frames either side.
    `exposure_us`: one exposure for all frames, or a sequence (one per frame, in order); None
    or 0 gives the pairs back as they are."""
    if exposure_us is None or (np.ndim(exposure_us) == 0 and float(exposure_us) == 0.0):  # type: ignore[arg-type]
        yield from pairs
        return
    per_frame = np.ndim(exposure_us) > 0
    if not per_frame:
        check_exposure(float(exposure_us), np.zeros(1, np.int64))  # type: ignore[arg-type]
    pending: list[tuple[int, np.ndarray]] = []
    start = 0  # index in the sequence of pending[0]
    emitted = 0  # frames of the sequence emitted so far
    for pair in pairs:
        pending.append(pair)
        if start + len(pending) - emitted >= block + overlap:
            yield from _solved(pending, start, emitted, emitted + block, exposure_us)
            emitted += block
            drop = max(0, emitted - overlap - start)
            del pending[:drop]
            start += drop
    if start + len(pending) > emitted:
        yield from _solved(pending, start, emitted, start + len(pending), exposure_us)


def _solved(
    pending: list[tuple[int, np.ndarray]],
    start: int,
    first: int,
    end: int,
    exposure_us: float | Sequence[float] | np.ndarray,
) -> Iterator[tuple[int, np.ndarray]]:
    """Frames first..end-1 of the sequence, deconvolved from all of `pending` (frames from
    `start` on)."""
    times = np.array([t for t, _ in pending], np.int64)
    if np.ndim(exposure_us) > 0:
        given = np.asarray(exposure_us, np.float64)
        if len(given) < start + len(pending):
            raise ValueError(
                f"exposure_us: {len(given)} exposures for more frames ({start + len(pending)})"
            )
        exposure = check_exposure(given[start : start + len(pending)], times)
    else:
        exposure = check_exposure(float(exposure_us), times)  # type: ignore[arg-type]
    frames = np.stack([np.asarray(frame) for _, frame in pending])
    if frames.dtype.kind not in "f":
        raise ValueError(
            f"exposure: frames must be linear light (float), got {frames.dtype}; decode them first"
        )
    light = deconvolve(frames, times, exposure)
    for k in range(first - start, end - start):
        yield int(times[k]), light[k].astype(np.float32)


def source_exposure_us(
    source: object, exposure_us: float | str | Sequence[float] | np.ndarray | None
) -> float | Sequence[float] | np.ndarray | None:
    """What a frame source's frames were exposed for, as `exposure_deconvolved` takes it:
    "auto" gives an AEDAT4 source's recorded exposures (a list it fills as its frames are read)
    and None for any other source or a file that records none; "none" and None give None; a
    number (us) is kept."""
    if isinstance(exposure_us, str):
        if exposure_us == "none":
            return None
        if exposure_us != "auto":
            raise ValueError(
                f"exposure: 'auto', 'none' or a number of microseconds, got {exposure_us!r}"
            )
        from pecs.footage.aedat4_frames import EXPOSURE_MIDPOINT, Aedat4FrameSource

        if isinstance(source, Aedat4FrameSource) and source.frame_times == EXPOSURE_MIDPOINT:
            return source.exposures_us
        return None
    return exposure_us
