"""Nelder-Mead simplex minimisation inside the unit cube, for a few parameters and a costly,
deterministic, non-smooth objective (event counts change in steps).

Nelder and Mead, Computer Journal 7 (1965), with the standard coefficients (reflection 1,
expansion 2, contraction 1/2, shrink 1/2); points are clipped to [0, 1]^n, which keeps every
trial inside the parameters' bounds. scipy's `minimize(method="Nelder-Mead", bounds=...)`
does the same, but scipy is not a runtime dependency of pecs, for sixty lines.
"""

from __future__ import annotations

import math
from collections.abc import Callable

import numpy as np

__all__ = ["minimize", "minimum_evaluations"]


def minimum_evaluations(dimensions: int) -> int:
    """The evaluations the method needs before it can take a step: the first simplex's n + 1."""
    return dimensions + 1


class _BudgetSpent(Exception):
    """Raised in place of an evaluation past `max_evaluations`."""


def minimize(
    objective: Callable[[np.ndarray], float],
    start: np.ndarray,
    *,
    step: float = 0.15,
    max_evaluations: int = 150,
    tolerance: float = 1e-3,
) -> tuple[np.ndarray, float, int]:
    """Minimise `objective` over [0, 1]^n from `start`: (best point, its value, evaluations).

    The first simplex is `start` and `start` moved by `step` along each axis (inwards where the
    step would leave the cube). Stops when the simplex's values agree within `tolerance` and its
    points within `tolerance` on every axis, or when the next evaluation would exceed
    `max_evaluations` (a step cut short keeps what it evaluated: a better reflection counts even
    when its expansion is not tried). `max_evaluations` must cover the first simplex (n + 1).
    """
    n = len(start)
    if max_evaluations < minimum_evaluations(n):
        raise ValueError(
            f"max_evaluations {max_evaluations}: {n} parameters need at least "
            f"{minimum_evaluations(n)} (the first simplex)"
        )
    count = 0
    # The best point evaluated: the simplex's best at convergence, or what a step cut short by
    # the budget found.
    best: tuple[float, np.ndarray] = (math.inf, np.clip(np.asarray(start, np.float64), 0.0, 1.0))

    def value(point: np.ndarray) -> float:
        nonlocal count, best
        if count >= max_evaluations:
            raise _BudgetSpent
        count += 1
        result = float(objective(point))
        if result < best[0]:
            best = (result, point.copy())
        return result

    try:
        _search(value, start, step, tolerance)
    except _BudgetSpent:
        pass
    return best[1], best[0], count


def _search(
    value: Callable[[np.ndarray], float],
    start: np.ndarray,
    step: float,
    tolerance: float,
) -> None:
    """Nelder-Mead iterations until the simplex converges; `value` keeps the best point, and
    ends the search by raising once the budget is spent."""
    n = len(start)
    points = [np.clip(np.asarray(start, np.float64), 0.0, 1.0)]
    for axis in range(n):
        moved = points[0].copy()
        moved[axis] += step if moved[axis] + step <= 1.0 else -step
        points.append(moved)
    values = [value(p) for p in points]
    while True:
        order = np.argsort(values, kind="stable")
        points = [points[i] for i in order]
        values = [values[i] for i in order]
        spread = np.max(np.abs(np.array(points[1:]) - points[0]))
        if values[-1] - values[0] <= tolerance and spread <= tolerance:
            break
        centroid = np.mean(points[:-1], axis=0)
        worst = points[-1]

        def toward(
            factor: float, centroid: np.ndarray = centroid, worst: np.ndarray = worst
        ) -> np.ndarray:
            return np.clip(centroid + factor * (centroid - worst), 0.0, 1.0)

        reflected = toward(1.0)
        f_reflected = value(reflected)
        if f_reflected < values[0]:
            expanded = toward(2.0)
            f_expanded = value(expanded)
            points[-1], values[-1] = (
                (expanded, f_expanded) if f_expanded < f_reflected else (reflected, f_reflected)
            )
        elif f_reflected < values[-2]:
            points[-1], values[-1] = reflected, f_reflected
        else:
            outside = f_reflected < values[-1]
            contracted = toward(0.5 if outside else -0.5)
            f_contracted = value(contracted)
            if f_contracted < min(f_reflected, values[-1]):
                points[-1], values[-1] = contracted, f_contracted
            else:  # shrink toward the best point
                for i in range(1, n + 1):
                    points[i] = points[0] + 0.5 * (points[i] - points[0])
                    values[i] = value(points[i])
