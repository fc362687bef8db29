"""How much a simulated event stream looks like a real one over the same time window.

`score(real, sim, window_us=(start, end))` measures, over start <= t < end:
- the count ratio (simulated / real events) and each stream's ON fraction;
- the count-map correlation: Pearson r of the per-pixel event counts, each map first summed over
  3 x 3 neighbourhoods (pixels outside the sensor count 0), so a one-pixel offset still matches;
- the rate correlation: Pearson r of the event counts in consecutive bins (5 ms by default)
  from `start`;
- the PECS chamfer and Gaussian distances (`pecs.metrics`) with both normalisations.
Correlations of a constant series (no events, or the same count everywhere) are NaN; the
distances are NaN when either stream is empty. The calibration objective is built from these.
"""

from __future__ import annotations

from typing import Any

import numpy as np

from pecs.metrics import MetricOptions, _prepare, _sensor_size, compare

__all__ = [
    "blurred_count_map",
    "count_map",
    "on_fraction",
    "pearson",
    "rate_curve",
    "score",
]

RATE_BIN_US = 5_000


def count_map(x: np.ndarray, y: np.ndarray, width: int, height: int) -> np.ndarray:
    """Events per pixel, (height, width) int64."""
    if len(x) and (int(np.max(x)) >= width or int(np.max(y)) >= height):
        raise ValueError(f"count_map: events lie outside the {width} x {height} sensor")
    flat = np.asarray(y, np.int64) * width + np.asarray(x, np.int64)
    return np.bincount(flat, minlength=width * height).reshape(height, width)


def blurred_count_map(x: np.ndarray, y: np.ndarray, width: int, height: int) -> np.ndarray:
    """The count map summed over each pixel's 3 x 3 neighbourhood, zero outside the sensor."""
    padded = np.pad(count_map(x, y, width, height), 1)
    return sum(padded[dy : dy + height, dx : dx + width] for dy in range(3) for dx in range(3))  # type: ignore[return-value]


def rate_curve(
    t_us: np.ndarray, start_us: int, end_us: int, bin_us: int = RATE_BIN_US
) -> np.ndarray:
    """Events per bin of `bin_us` from `start_us`; the last bin may be shorter (ends at end_us)."""
    if bin_us <= 0 or end_us <= start_us:
        raise ValueError(
            f"rate_curve: needs bin_us > 0 and end > start, got {bin_us}, ({start_us}, {end_us})"
        )
    bins = -(-(end_us - start_us) // bin_us)
    t = np.asarray(t_us, np.int64)
    t = t[(t >= start_us) & (t < end_us)]
    return np.bincount((t - start_us) // bin_us, minlength=bins)


def on_fraction(p: np.ndarray) -> float:
    """Share of ON events (p = 1); NaN without events."""
    return float(np.mean(np.asarray(p) == 1)) if len(p) else float("nan")


def pearson(a: np.ndarray, b: np.ndarray) -> float:
    """Pearson correlation of two equal-size arrays; NaN when either is constant."""
    a = np.asarray(a, np.float64).ravel() - np.mean(a)
    b = np.asarray(b, np.float64).ravel() - np.mean(b)
    norm = float(np.sqrt(np.dot(a, a) * np.dot(b, b)))
    return float(np.dot(a, b) / norm) if norm > 0 else float("nan")


def score(
    real: Any,
    sim: Any,
    *,
    window_us: tuple[int, int],
    sensor_size: tuple[int, int] | None = None,
    rate_bin_us: int = RATE_BIN_US,
    distances: bool = True,
) -> dict[str, float]:
    """Realism measures of `sim` against `real` over window_us = (start, end) (see the module).

    `real` and `sim`: anything `pecs.metrics.compare` takes (tables, structured arrays, paths).
    `sensor_size` (width, height) defaults to the streams' schema metadata.
    """
    options = MetricOptions(
        window_us=(int(window_us[0]), int(window_us[1])), sensor_size=sensor_size
    )
    a, b = _prepare(real, "real", options), _prepare(sim, "sim", options)
    width, height = _sensor_size(a, b, options)
    start, end = options.window_us  # type: ignore[misc]
    result = {
        "events_real": float(len(a)),
        "events_sim": float(len(b)),
        "count_ratio": len(b) / len(a) if len(a) else float("nan"),
        "on_fraction_real": on_fraction(a.p),
        "on_fraction_sim": on_fraction(b.p),
        "count_map_correlation": pearson(
            blurred_count_map(a.x, a.y, width, height), blurred_count_map(b.x, b.y, width, height)
        ),
        "rate_correlation": pearson(
            rate_curve(a.t_us, start, end, rate_bin_us), rate_curve(b.t_us, start, end, rate_bin_us)
        ),
    }
    for normalize in ("pecs", "sensor"):
        chamfer = gaussian = float("nan")
        if distances and len(a) and len(b):
            comparison = compare(
                real, sim, window_us=(start, end), normalize=normalize, sensor_size=(width, height)
            )
            chamfer, gaussian = comparison.chamfer, comparison.gaussian
        result[f"chamfer_{normalize}"] = chamfer
        result[f"gaussian_{normalize}"] = gaussian
    return result
