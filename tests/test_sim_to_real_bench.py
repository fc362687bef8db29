"""benches/sim_to_real.py's reference rows built from the real events (the Gaussian-distance
limit of docs/calibration.md): each pixel's burst in a frame interval shifted whole by a
uniform random time, checked on made-up bursts against the uniform law's moments."""

from __future__ import annotations

import importlib.util
from pathlib import Path
from types import ModuleType

import numpy as np
import pecs
import pytest

BENCH = Path(__file__).resolve().parents[1] / "benches" / "sim_to_real.py"
TIMES_US = np.array([0, 40_000, 80_000], np.int64)


@pytest.fixture(scope="module")
def bench() -> ModuleType:
    spec = importlib.util.spec_from_file_location("sim_to_real", BENCH)
    assert spec is not None and spec.loader is not None
    module = importlib.util.module_from_spec(spec)
    spec.loader.exec_module(module)
    return module


def bursts(n: int) -> np.ndarray:
    """n pixels, each one burst of 3 events 1 ms apart from 15 ms, OFF, ON, ON."""
    events = np.zeros(3 * n, [("t", "<i8"), ("x", "<u2"), ("y", "<u2"), ("p", "i1")])
    pixel = np.repeat(np.arange(n), 3)
    events["t"] = 15_000 + 1_000 * np.tile(np.arange(3), n)
    events["x"], events["y"] = pixel % 100, pixel // 100
    events["p"] = np.tile([0, 1, 1], n)
    return events[np.argsort(events["t"], kind="stable")]


@pytest.mark.parametrize("jitter_ms", [10.0, 5.0, 2.5])
def test_each_burst_moves_whole_by_a_uniform_shift(bench: ModuleType, jitter_ms: float) -> None:
    n = 3000
    real = bursts(n)
    moved = bench.real_time_jittered(pecs.events.to_table(real), TIMES_US, jitter_ms * 1e3)
    assert np.all(np.diff(moved["t"]) >= 0)
    pixel = moved["y"].astype(np.int64) * 100 + moved["x"]
    order = np.lexsort((moved["t"], pixel))
    t = moved["t"][order].reshape(n, 3)
    # the shape of each burst and its polarities are kept; only its time moves
    assert np.all(np.diff(t, axis=1) == 1_000)
    assert np.array_equal(moved["p"][order].reshape(n, 3), np.tile([0, 1, 1], (n, 1)))
    shift_ms = (t[:, 0] - 15_000) / 1e3
    assert np.all(np.abs(shift_ms) <= jitter_ms)
    # uniform on [-J, J]: mean 0 (standard error J / sqrt(3 n) = 0.01 J), std J / sqrt(3)
    assert abs(shift_ms.mean()) < 0.05 * jitter_ms
    assert shift_ms.std() == pytest.approx(jitter_ms / np.sqrt(3), rel=0.05)


def test_each_burst_moves_whole_to_a_uniform_time_of_its_interval(bench: ModuleType) -> None:
    # One burst per pixel in the first 40 ms interval: its start goes to a uniform time of the
    # interval, the burst wrapped inside it (1 ms steps modulo 40 ms), polarities kept.
    n = 3000
    moved = bench.real_timing_unknown(pecs.events.to_table(bursts(n)), TIMES_US)
    assert np.all(np.diff(moved["t"]) >= 0)
    assert np.all((moved["t"] >= 0) & (moved["t"] < 40_000))
    pixel = moved["y"].astype(np.int64) * 100 + moved["x"]
    order = np.lexsort((moved["p"], pixel))  # per pixel: the OFF event first, then the two ON
    t = moved["t"][order].reshape(n, 3)
    assert np.array_equal(moved["p"][order].reshape(n, 3), np.tile([0, 1, 1], (n, 1)))
    start_ms = t[:, 0] / 1e3
    assert np.all(np.sort((t[:, 1:] - t[:, :1]) % 40_000, axis=1) == [1_000, 2_000])
    # uniform on [0, 40) ms: mean 20 (standard error 40 / sqrt(12 n) = 0.2), std 40 / sqrt(12)
    assert start_ms.mean() == pytest.approx(20.0, abs=1.0)
    assert start_ms.std() == pytest.approx(40 / np.sqrt(12), rel=0.05)
