"""Realism measures (pecs.calibration.realism) against values worked out by hand."""

import math

import numpy as np
import pytest
from pecs.calibration import realism

DTYPE = [("t", "<i8"), ("x", "<u2"), ("y", "<u2"), ("p", "i1")]


def events(t, x, y, p):
    out = np.zeros(len(t), DTYPE)
    out["t"], out["x"], out["y"], out["p"] = t, x, y, p
    return out


def test_count_map_and_its_3x3_sum():
    x, y = np.array([0, 0, 2]), np.array([0, 0, 1])
    np.testing.assert_array_equal(realism.count_map(x, y, 3, 2), [[2, 0, 0], [0, 0, 1]])
    # Each pixel sums its in-sensor neighbours: e.g. (x=1, y=0) sees all of the 3 x 2 map.
    np.testing.assert_array_equal(realism.blurred_count_map(x, y, 3, 2), [[2, 3, 1], [2, 3, 1]])
    with pytest.raises(ValueError, match="outside the 3 x 2 sensor"):
        realism.count_map(np.array([3]), np.array([0]), 3, 2)


def test_pearson_on_known_series():
    # a - mean = (-1, 0, 1), b - mean = (-7, -1, 8) / 3: r = 5 / sqrt(2 * 114 / 9) = 15 / sqrt(228).
    assert realism.pearson([1, 2, 3], [2, 4, 7]) == pytest.approx(15 / math.sqrt(228), rel=1e-12)
    assert math.isnan(realism.pearson([1, 1, 1], [1, 2, 3]))


def test_rate_curve_bins_from_the_window_start_and_drops_events_outside():
    t = [-1, 0, 4_999, 5_000, 12_000, 14_000]
    np.testing.assert_array_equal(realism.rate_curve(t, 0, 14_000, 5_000), [2, 1, 1])
    np.testing.assert_array_equal(realism.rate_curve(t, 0, 15_000, 5_000), [2, 1, 2])


def test_on_fraction():
    assert realism.on_fraction(np.array([1, 0, 1, 1])) == 0.75
    assert math.isnan(realism.on_fraction(np.array([])))


def test_score_of_a_stream_against_itself():
    i = np.arange(200)
    real = events(i**2 // 2, i % 17, i % 13, i % 2)  # a rate that falls over time
    got = realism.score(real, real, window_us=(0, 20_000), sensor_size=(20, 15))
    assert got["count_ratio"] == 1 and got["on_fraction_real"] == got["on_fraction_sim"] == 0.5
    assert got["count_map_correlation"] == pytest.approx(1) and got[
        "rate_correlation"
    ] == pytest.approx(1)
    for key in ("chamfer_pecs", "gaussian_pecs", "chamfer_sensor", "gaussian_sensor"):
        assert got[key] == 0


def test_score_of_a_shifted_bunched_stream():
    # Real: 10 ON events at (5, 5), 1 ms apart from t = 0; sim: 20 OFF events one pixel right,
    # all in the first 5 ms bin; only the window 0 <= t < 15 ms counts (a real event at 20 ms
    # does not).
    real = events(list(range(0, 10_000, 1_000)) + [20_000], [5] * 11, [5] * 11, [1] * 11)
    sim = events(np.arange(0, 4_000, 200), [6] * 20, [5] * 20, [0] * 20)
    got = realism.score(real, sim, window_us=(0, 15_000), sensor_size=(20, 10), distances=False)
    assert (got["events_real"], got["events_sim"], got["count_ratio"]) == (10, 20, 2)
    assert (got["on_fraction_real"], got["on_fraction_sim"]) == (1, 0)
    # Blurred maps: 3 x 3 blocks of 10 and of 20 overlapping on 6 of 200 pixels; r is scale-free,
    # so with blocks of 1: (6 - 200 m^2) / (9 - 200 m^2), m = 9 / 200.
    m = 9 / 200
    assert got["count_map_correlation"] == pytest.approx((6 - 200 * m**2) / (9 - 200 * m**2))
    # Rates (5, 5, 0) and (20, 0, 0): r = (150 / 9) / sqrt(150 / 9 * 2400 / 9) = 0.5.
    assert got["rate_correlation"] == pytest.approx(0.5)
    assert math.isnan(got["chamfer_sensor"])
