"""E2VID's event voxel grid (Rebecq et al., "High Speed and High Dynamic Range Video with an
Event Camera", TPAMI 2019, eq. 1): B temporal bins over a window [t0, t1], each event's
polarity (+1 ON, -1 OFF) split between its two nearest bins by linear weights in time,

    V(b, y, x) = sum_k p_k max(0, 1 - |b - t*_k|),   t*_k = (B - 1) (t_k - t0) / (t1 - t0),

then normalised as E2VID does: its non-zero cells to mean 0 and standard deviation 1."""

from __future__ import annotations

import numpy as np

BINS = 5


def voxel_grid(
    t_us: np.ndarray,
    x: np.ndarray,
    y: np.ndarray,
    p: np.ndarray,
    window_us: tuple[int, int],
    width: int,
    height: int,
    bins: int = BINS,
) -> np.ndarray:
    """(bins, height, width) float32, not normalised; `p` 1/0 (ON/OFF) or +1/-1; events outside
    the window count at its nearest end."""
    t0, t1 = window_us
    if t1 <= t0:
        raise ValueError(f"window_us: the end {t1} must come after the start {t0}")
    grid = np.zeros(bins * height * width, np.float64)
    if len(t_us) == 0:
        return grid.reshape(bins, height, width).astype(np.float32)
    polarity = np.where(np.asarray(p) > 0, 1.0, -1.0)
    t_star = (bins - 1) * (np.asarray(t_us, np.float64) - t0) / (t1 - t0)
    t_star = np.clip(t_star, 0.0, bins - 1)
    left = np.minimum(np.floor(t_star).astype(np.int64), bins - 2) if bins > 1 else 0 * t_star
    left = np.asarray(left, np.int64)
    weight_right = t_star - left
    pixel = np.asarray(y, np.int64) * width + np.asarray(x, np.int64)
    np.add.at(grid, left * height * width + pixel, polarity * (1.0 - weight_right))
    if bins > 1:
        np.add.at(grid, (left + 1) * height * width + pixel, polarity * weight_right)
    return grid.reshape(bins, height, width).astype(np.float32)


def normalised(grid: np.ndarray) -> np.ndarray:
    """E2VID's normalisation: non-zero cells to mean 0, standard deviation 1 (zeros stay 0)."""
    nonzero = grid != 0
    count = int(nonzero.sum())
    if count < 2:
        return grid
    values = grid[nonzero]
    std = float(values.std())
    out = np.zeros_like(grid)
    out[nonzero] = (values - values.mean()) / (std if std > 0 else 1.0)
    return out
