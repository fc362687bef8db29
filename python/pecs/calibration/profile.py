"""Which fitted parameters the data pinned down: a profile of the objective along each one.

After a fit, each parameter is moved alone, the others held at the fit, to STEPS of it (x 1/2,
x 1/sqrt 2, x sqrt 2, x 2 for the log-scale parameters; +-1/8 and +-1/4 of the bounds' range
for the linear ones), inside its bounds. Its interval is the values, walking out from the fit
on each side, whose objective stays within the threshold of the fit's; the walk stops at the
first step that rises more, and its ends are the first steps on each side that did rise (the
data rule them out), or where a side never rose, the outermost step tried. The threshold is the objective's noise: the fit's objective with
another simulation seed against the fit's own seed (two seeds of common random numbers; the
profile itself uses the fit's seed, so a rise above the difference between seeds is the
parameter's doing), and at least NOISE_FLOOR. A parameter is

- "pinned" when a step down and a step up both raise the objective past the threshold;
- "lower limit" / "upper limit" when only one side does (the other side: any value up to the
  outermost step, or to the bound, fits as well);
- "not pinned" when no step does: the data cannot tell its value within x 1/2 .. x 2.

A slice, not a full profile: the other parameters are not re-fitted at each step, so where two
parameters trade against each other (theta_sigma and the thresholds) the interval is narrower
than what the data allow together. It costs 1 + 4 evaluations a parameter.
"""

from __future__ import annotations

import math
from collections.abc import Callable, Sequence
from dataclasses import dataclass

__all__ = ["NOISE_FLOOR", "ParameterProfile", "profile", "steps"]

# Log-scale parameters are multiplied by these; linear ones moved by these fractions of range.
LOG_FACTORS = (1 / 2, 1 / math.sqrt(2), math.sqrt(2), 2.0)
LINEAR_FRACTIONS = (-1 / 4, -1 / 8, 1 / 8, 1 / 4)
# Least rise, in objective units (one unit: a term's tolerance), that counts as the data's say:
# where the seed moves nothing (a noiseless sensor) the noise measures 0, and a step that moves
# one event of thousands is no evidence either.
NOISE_FLOOR = 0.02

PINNED, LOWER_LIMIT, UPPER_LIMIT, NOT_PINNED = "pinned", "lower limit", "upper limit", "not pinned"


@dataclass(frozen=True)
class ParameterProfile:
    """One parameter's slice of the objective around the fit.

    `points`: (value, objective) of each step tried, ascending in value, the fit's included.
    The data allow the values between `low` and `high`: walking out from the fit, the first
    step whose objective rose more than `threshold` above the fit's (ruled out), or, where a
    side never did (`low_open` / `high_open`), the outermost step tried, and perhaps beyond."""

    name: str
    value: float
    objective: float
    threshold: float
    points: tuple[tuple[float, float], ...]
    low: float
    high: float
    low_open: bool
    high_open: bool

    @property
    def status(self) -> str:
        """PINNED, LOWER_LIMIT (only lower values are ruled out), UPPER_LIMIT or NOT_PINNED."""
        if not self.low_open and not self.high_open:
            return PINNED
        if not self.low_open:
            return LOWER_LIMIT
        if not self.high_open:
            return UPPER_LIMIT
        return NOT_PINNED

    def interval(self, fmt: str = "{:.3g}") -> str:
        """The values the data allow, e.g. "0.177 .. 0.354" (both ends ruled out) or
        "<= 8e-05 .. 0.0004" (nothing ruled out down to 8e-05)."""
        low = ("<= " if self.low_open else "") + fmt.format(self.low)
        high = (">= " if self.high_open else "") + fmt.format(self.high)
        return f"{low} .. {high}"


def steps(value: float, low: float, high: float, log: bool) -> list[float]:
    """The values a profile tries for a parameter at `value` with bounds low..high: STEPS of it,
    clipped into the bounds, without duplicates or the value itself, ascending."""
    if log:
        tried = [value * factor for factor in LOG_FACTORS]
    else:
        tried = [value + fraction * (high - low) for fraction in LINEAR_FRACTIONS]
    clipped = {min(max(v, low), high) for v in tried}
    return sorted(v for v in clipped if not math.isclose(v, value, rel_tol=1e-9, abs_tol=0.0))


def profile(
    objective: Callable[[dict[str, float]], float],
    fitted: dict[str, float],
    bounds: Sequence[tuple[str, float, float, bool]],
    fit_objective: float,
    threshold: float,
) -> list[ParameterProfile]:
    """The profile of each (name, low, high, log) of `bounds` around `fitted`: `objective`
    takes the parameter values (all of `fitted`, one moved) and returns the objective."""
    profiles = []
    for name, low, high, log in bounds:
        value = fitted[name]
        points = [(value, fit_objective)]
        for moved in steps(value, low, high, log):
            points.append((moved, objective({**fitted, name: moved})))
        points.sort()
        profiles.append(_slice(name, value, fit_objective, threshold, points))
    return profiles


def _slice(
    name: str,
    value: float,
    fit_objective: float,
    threshold: float,
    points: list[tuple[float, float]],
) -> ParameterProfile:
    """Walk out from the fit on each side while the rise stays within the threshold."""
    at = next(i for i, (v, _) in enumerate(points) if v == value)
    within = [objective - fit_objective <= threshold for _, objective in points]
    first = at - 1
    while first >= 0 and within[first]:
        first -= 1
    last = at + 1
    while last < len(points) and within[last]:
        last += 1
    low_open, high_open = first < 0, last >= len(points)
    return ParameterProfile(
        name=name,
        value=value,
        objective=fit_objective,
        threshold=threshold,
        points=tuple(points),
        low=points[0 if low_open else first][0],
        high=points[-1 if high_open else last][0],
        low_open=low_open,
        high_open=high_open,
    )
