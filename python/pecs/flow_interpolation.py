"""How the light moves between two frames of camera footage: along the optical flow, so that a
moving edge reaches neighbouring pixels one after another at the times its motion says.

v2e (Hu et al. 2021) makes slow-motion frames with a learned interpolator (Super SloMo) for
the same reason. Here the flow is classical (OpenCV's DIS, Kroeger et al. 2016), estimated
both ways between frames k and k+1, and it says *when* each pixel's change comes; how the
change goes is a transition, linear in log, as in `pecs.frame_interpolation`:

1. The flow-based interpolation under brightness constancy (backward warping, the flow at the
   target pixel standing in for the flow at the source), in linear intensity,

       I(p, s) = (1 - s) I_k(p - s v_fwd(p)) + s I_{k+1}(p - (1 - s) v_bwd(p)),

   sampled at the sub-frames, gives the time s* at which I(p, s) is halfway from I_k(p) to
   I_{k+1}(p): when the edge's middle passes the pixel.
2. The pixel's change is a transition centred on s*, lasting EDGE_PX / |v| of the interval
   (an edge blurred over EDGE_PX crosses the pixel at |v| pixels per interval), at least
   MIN_TRANSITION. Where the flow is under MIN_SPEED_PX (a change of light, not motion: the
   warp is then a crossfade, whose halfway time says nothing) it is centred on a uniform random
   time and lasts DEFAULT_TRANSITION, as in "transition".

Using the warped frames themselves as the light (the first version) put the OFF events late:
a crossfade in linear intensity falls in log mostly at its end, and most changed pixels of real
footage move a pixel or less per frame. On the DAVIS346 road recording, held-out half,
calibrated on the first: Gaussian distance 1.372 -> 1.363, chamfer 2.20 -> 2.20, late / early
1.50 -> 1.31 (real 1.08); with the davis346 defaults the count went from 1.66x to 1.42x the
real (docs/realism-findings.md).

Only pixels whose value differs between the two frames change; the others hold theirs exactly,
so the flow's errors on a static background give no events.
"""

from __future__ import annotations

import hashlib
from collections import OrderedDict
from collections.abc import Iterable, Iterator

import numpy as np

from pecs.frame_interpolation import DEFAULT_TRANSITION, transition_frames, with_subframes

#: DIS's preset. Farneback (OpenCV's example parameters) scored the same on the DAVIS346 road
#: recording (Gaussian 1.307 against 1.312, davis346 defaults, held-out half) but finds no
#: motion at all on a uniform bar moving 2-8 px (its polynomial expansion sees nothing in flat
#: regions); DIS's fast and ultrafast presets scored 1.364 and 1.333.
DIS_PRESET = "MEDIUM"
#: Flows kept for intervals seen again (a calibration simulates the same frames hundreds of
#: times; the flow is most of the cost): 64 intervals of 346 x 260 take 46 MB.
_FLOW_CACHE_INTERVALS = 64
_flow_cache: OrderedDict[bytes, tuple[np.ndarray, np.ndarray]] = OrderedDict()

#: Sub-frames per interval: 2.5 ms apart at 25 Hz, a pixel's crossing by an edge moving a few
#: pixels per frame interval spans several.
DEFAULT_FLOW_SUBSTEPS = 16
#: Below this flow (pixels per interval, the larger of the two directions) a change is taken
#: for a change of light, at a random time (road recording, davis346 defaults: 0.5 px gave
#: Gaussian 1.366 and late / early 1.92, 1 px 1.355 and 1.59, 2 px 1.357 and 1.51).
MIN_SPEED_PX = 1.0
#: The width of an edge, in pixels, that sets a moving pixel's transition: 1.5 px (optics and
#: pixel) at 3 px per interval, the road recording's median, is half the interval, 20 ms at
#: 25 Hz (real bursts: 10 ms median, 8-14 ms interquartile, first to last event). Road
#: recording, held-out half, at the first half's calibration: 0.75 px gave Gaussian 1.375 at
#: 1.17x the count, 1.5 px 1.356 at 1.22x, 3 px 1.371 at 1.23x.
EDGE_PX = 1.5
#: The shortest transition, as a fraction of the interval (a fast edge's).
MIN_TRANSITION = 0.15


def flow_subframes(
    pairs: Iterable[tuple[int, np.ndarray]],
    offset: float,
    *,
    substeps: int = DEFAULT_FLOW_SUBSTEPS,
    seed: int = 0,
) -> Iterator[tuple[int, np.ndarray]]:
    """(t_us, frame) pairs with `substeps - 1` sub-frames inserted in each interval, each
    pixel's change timed by the optical flow (module docstring); `offset` as in
    `pecs.frame_interpolation.transition_subframes`, `seed` for the changes of light."""
    if substeps < 1:
        raise ValueError(f"substeps: must be >= 1, got {substeps}")
    rng = np.random.default_rng(seed)
    return with_subframes(pairs, lambda start, end: _interval(start, end, offset, substeps, rng))


def _interval(
    start: tuple[int, np.ndarray],
    end: tuple[int, np.ndarray],
    offset: float,
    substeps: int,
    rng: np.random.Generator,
) -> Iterator[tuple[int, np.ndarray]]:
    """The sub-frames of one interval, then its end frame as given."""
    (_, frame0), (t1, frame1) = start, end
    if not (frame0 != frame1).any():
        return iter([(t1, frame1)])
    image0 = np.maximum(frame0.astype(np.float32), 0.0)
    image1 = np.maximum(frame1.astype(np.float32), 0.0)
    forward, backward = _cached_flows(image0, image1)
    halfway = _halfway_times(image0, image1, forward, backward, substeps)
    speed_px = np.maximum(
        np.hypot(*np.moveaxis(forward, -1, 0)), np.hypot(*np.moveaxis(backward, -1, 0))
    )
    moving = (speed_px >= MIN_SPEED_PX) & np.isfinite(halfway)
    centres = np.where(moving, halfway, rng.uniform(0.0, 1.0, frame0.shape))
    widths = np.where(
        moving,
        np.clip(EDGE_PX / np.maximum(speed_px, 1e-6), MIN_TRANSITION, 1.0),
        DEFAULT_TRANSITION,
    )
    return transition_frames(start, end, offset, centres, widths, substeps)


def _halfway_times(
    image0: np.ndarray,
    image1: np.ndarray,
    forward: np.ndarray,
    backward: np.ndarray,
    samples: int,
) -> np.ndarray:
    """Per pixel, the first fraction s of the interval at which the flow-based interpolation
    I(p, s) is halfway from image0 to image1 (linear between `samples` points in s; NaN where
    it never gets there)."""
    half = 0.5 * (image0 + image1)
    towards = np.where(image1 >= image0, 1.0, -1.0)
    before = towards * (image0 - half)  # < 0 until halfway
    halfway = np.full(image0.shape, np.nan)
    for j in range(1, samples + 1):
        s = j / samples
        if j < samples:
            warped = (1 - s) * _warp(image0, forward, s) + s * _warp(image1, backward, 1 - s)
        else:
            warped = image1
        after = towards * (warped - half)
        reached = np.isnan(halfway) & (after >= 0) & (before < 0)
        part = -before / np.maximum(after - before, 1e-12)
        halfway = np.where(reached, (j - 1 + np.clip(part, 0.0, 1.0)) / samples, halfway)
        before = after
    return halfway


def _cached_flows(image0: np.ndarray, image1: np.ndarray) -> tuple[np.ndarray, np.ndarray]:
    """`_flows`, from the cache where these two images were seen before."""
    digest = hashlib.blake2b(digest_size=16)
    for image in (image0, image1):
        digest.update(repr(image.shape).encode())
        digest.update(np.ascontiguousarray(image).tobytes())
    key = digest.digest()
    if key in _flow_cache:
        _flow_cache.move_to_end(key)
        return _flow_cache[key]
    flows = _flows(image0, image1)
    _flow_cache[key] = flows
    if len(_flow_cache) > _FLOW_CACHE_INTERVALS:
        _flow_cache.popitem(last=False)
    return flows


def _flows(image0: np.ndarray, image1: np.ndarray) -> tuple[np.ndarray, np.ndarray]:
    """Flow (H, W, 2; dx, dy in pixels per interval) from image 0 to 1 and from 1 to 0, on the
    images scaled together to 8 bits (DIS takes 8-bit images)."""
    import cv2

    scale = max(float(image0.max()), float(image1.max()))
    if scale <= 0:
        zero = np.zeros((*image0.shape, 2), np.float32)
        return zero, zero
    eight0 = np.clip(image0 * (255.0 / scale), 0, 255).astype(np.uint8)
    eight1 = np.clip(image1 * (255.0 / scale), 0, 255).astype(np.uint8)
    estimator = cv2.DISOpticalFlow_create(getattr(cv2, f"DISOPTICAL_FLOW_PRESET_{DIS_PRESET}"))
    forward = estimator.calc(eight0, eight1, None)
    backward = estimator.calc(eight1, eight0, None)
    return forward, backward


def _warp(image: np.ndarray, flow: np.ndarray, fraction: float) -> np.ndarray:
    """image(p - fraction * flow(p)), bilinear, edges replicated."""
    import cv2

    height, width = image.shape
    xs, ys = np.meshgrid(np.arange(width, dtype=np.float32), np.arange(height, dtype=np.float32))
    map_x = xs - np.float32(fraction) * flow[..., 0]
    map_y = ys - np.float32(fraction) * flow[..., 1]
    return cv2.remap(
        image, map_x, map_y, interpolation=cv2.INTER_LINEAR, borderMode=cv2.BORDER_REPLICATE
    )
