"""How the light moves between two frames of camera footage: as a short transition at a random
time of the interval, fed to the sensor as sub-frames.

The sensor takes its input as linear in log between the frames it is fed (ESIM's rule, exact
for rendered ramps). Between two frames of a 25 Hz camera the light did not ramp: an edge
passed the pixel, at some time in the interval, in the few ms it takes to cross a pixel. Under
linear interpolation a change that only just crosses a level puts its event at the end of the
interval (the crossing lies at d / delta of it, d the distance to the level, delta the change),
so events bunch before each frame: 3.3x more in the last 4 ms of a 40 ms interval than in the
first on the DAVIS346 road recording, against 1.08 for the real sensor
(docs/realism-findings.md). A monotone cubic in log (PCHIP) does not help (1.60 against 1.88
for davis346, and the 5 ms rate correlation falls to -0.18): any fixed curve puts a just-crossing
change at the same late point of it.

Here each pixel's change in each interval is a transition, linear in log, lasting
`transition` of the interval and centred on a time drawn uniformly over it (seeded, per pixel
and interval; a transition that would reach past either end is cut there): when in the interval
the change came is unknown, so every time is equally likely, and the events of one change come
together, as an edge's do on a real sensor. Counts are those of linear interpolation for an
ideal sensor (the same levels are crossed). On the road recording (davis346, input noise held
back): late / early 1.88 -> 1.16 (real 1.08), rate correlation 0.09 -> 0.28 at transition
0.25. (Transitions kept inside the interval, starting uniformly in [0, 1 - transition], make
a trapezoid instead: few events at either end, rate correlation -0.15.)
"""

from __future__ import annotations

from collections.abc import Callable, Iterable, Iterator

import numpy as np

#: "flow": pecs.footage.flow_interpolation (sub-frames warped along the optical flow).
INTERPOLATIONS = ("linear", "transition", "flow")
#: Duration of a pixel's change as a fraction of the frame interval: 10 ms at 25 Hz. The real
#: DAVIS346 road recording's bursts (a pixel's events less than 5 ms apart) with 3 or more
#: events last 10 ms (median; 8-14 ms interquartile) from first to last event. On that
#: recording (davis346): 0.1 gives 1.36x the real count, rate correlation 0.23, Gaussian
#: distance 1.46; 0.25 gives 1.63x, 0.28, 1.40; 0.5 gives 1.77x, 0.19, 1.37.
DEFAULT_TRANSITION = 0.25
#: Sub-frames per interval: 4 across a transition of a quarter of it.
DEFAULT_SUBSTEPS = 16


def transition_subframes(
    pairs: Iterable[tuple[int, np.ndarray]],
    offset: float,
    *,
    transition: float = DEFAULT_TRANSITION,
    substeps: int = DEFAULT_SUBSTEPS,
    seed: int = 0,
) -> Iterator[tuple[int, np.ndarray]]:
    """(t_us, frame) pairs with `substeps - 1` sub-frames inserted in each interval: each pixel
    goes from its value in one frame to the next, linearly in ln(frame + offset), over
    `transition` of the interval, centred on a uniform random time of it."""
    if not 0 < transition <= 1:
        raise ValueError(f"transition: must be in (0, 1], got {transition}")
    if substeps < 1:
        raise ValueError(f"substeps: must be >= 1, got {substeps}")
    rng = np.random.default_rng(seed)
    return with_subframes(
        pairs, lambda start, end: _interval(start, end, offset, transition, substeps, rng)
    )


def with_subframes(
    pairs: Iterable[tuple[int, np.ndarray]],
    interval: Callable[
        [tuple[int, np.ndarray], tuple[int, np.ndarray]], Iterator[tuple[int, np.ndarray]]
    ],
) -> Iterator[tuple[int, np.ndarray]]:
    """The first pair, then for each next one `interval(previous, pair)`: the sub-frames of the
    interval up to and including its end frame."""
    previous: tuple[int, np.ndarray] | None = None
    for t_us, frame in pairs:
        if previous is not None:
            yield from interval(previous, (t_us, frame))
        else:
            yield t_us, frame
        previous = (t_us, frame)


def _interval(
    start: tuple[int, np.ndarray],
    end: tuple[int, np.ndarray],
    offset: float,
    transition: float,
    substeps: int,
    rng: np.random.Generator,
) -> Iterator[tuple[int, np.ndarray]]:
    """The sub-frames of one interval, then its end frame as given."""
    (t0, frame0), (t1, frame1) = start, end
    u0 = np.log(np.maximum(frame0.astype(np.float64), 0.0) + offset)
    change = np.log(np.maximum(frame1.astype(np.float64), 0.0) + offset) - u0
    # The change is centred on a uniform time of the interval; the part of it that would fall
    # outside is done at the interval's end (or already done after its start), as the frames
    # show it done: the crossing times are then spread evenly over the interval.
    begins = rng.uniform(0.0, 1.0, frame0.shape) - 0.5 * transition
    previous_us = t0
    for j in range(1, substeps):
        t_us = t0 + round(j * (t1 - t0) / substeps)
        if t_us <= previous_us or t_us >= t1:
            continue
        done = np.clip((j / substeps - begins) / transition, 0.0, 1.0)
        yield t_us, np.maximum(np.exp(u0 + change * done) - offset, 0.0).astype(np.float32)
        previous_us = t_us
    yield t1, frame1
