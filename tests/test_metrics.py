"""pecs.metrics against independent evaluations of the PECS definitions.

The reference here is written from the paper's formulas with numpy (all pairs) and with scipy's
cKDTree; nothing is taken from pecs' own code.
"""

from __future__ import annotations

import json

import numpy as np
import pecs.metrics as metrics
import pyarrow as pa
import pytest
from pecs.io import write_events
from scipy.spatial import cKDTree

SIGMA = 0.4


# ---- independent reference ---------------------------------------------------------------


def table(t, x, y, p, width=None, height=None) -> pa.Table:
    meta = {b"width": str(width).encode(), b"height": str(height).encode()} if width else None
    return pa.table(
        {
            "t": np.asarray(t, dtype=np.int64),
            "x": np.asarray(x, dtype=np.uint16),
            "y": np.asarray(y, dtype=np.uint16),
            "p": np.asarray(p, dtype=np.int8),
        }
    ).replace_schema_metadata(meta)


def columns(events: pa.Table) -> list[np.ndarray]:
    return [events.column(c).to_numpy().astype(np.float64) for c in ("x", "y", "p", "t")]


def points_pecs(events: pa.Table) -> np.ndarray:
    """(x, y, p, t), each min-max normalised over this stream: 100, 100, 100, 1000."""
    out = []
    for values, scale in zip(columns(events), (100, 100, 100, 1000)):
        out.append(scale * (values - values.min()) / (values.max() - values.min() + 1e-8))
    return np.stack(out, axis=1)


def points_sensor(events: pa.Table, width, height, t0, span) -> np.ndarray:
    x, y, p, t = columns(events)
    return np.stack([100 * x / width, 100 * y / height, 100 * p, 1000 * (t - t0) / span], axis=1)


def brute_nearest(u: np.ndarray, v: np.ndarray, separate: bool = False) -> np.ndarray:
    """All-pairs nearest distance from each row of u to the rows of v (4-D, or 3-D within one
    polarity when `separate`)."""
    out = np.empty(len(u))
    for start in range(0, len(u), 256):
        block = u[start : start + 256]
        diff = block[:, None, :] - v[None, :, :]
        if separate:
            d2 = diff[..., 0] ** 2 + diff[..., 1] ** 2 + diff[..., 3] ** 2
            d2[block[:, None, 2] != v[None, :, 2]] = np.inf
        else:
            d2 = (diff**2).sum(axis=-1)
        out[start : start + 256] = np.sqrt(d2.min(axis=1))
    return out


def reference(pa_, pb, nearest=brute_nearest, **kwargs) -> tuple[float, float]:
    d_ab, d_ba = nearest(pa_, pb, **kwargs), nearest(pb, pa_, **kwargs)
    chamfer = d_ab.mean() + d_ba.mean()
    gaussian = (1 - np.exp(-(d_ab**2) / SIGMA)).mean() + (1 - np.exp(-(d_ba**2) / SIGMA)).mean()
    return chamfer, gaussian


def kdtree_nearest(u: np.ndarray, v: np.ndarray) -> np.ndarray:
    return cKDTree(v).query(u, k=1, workers=-1)[0]


def random_stream(rng, n, *, width=346, height=260, duration_us=10_000, polarities=(0, 1)):
    return table(
        np.sort(rng.integers(0, duration_us, n)),
        rng.integers(0, width, n),
        rng.integers(0, height, n),
        rng.choice(polarities, n),
    )


def clumpy_stream(rng, n, polarities=(0, 1)):
    """Few distinct values per axis and repeated events: duplicates and exact ties everywhere."""
    base = table(
        rng.integers(0, 6, max(n // 3, 1)) * 50,
        rng.integers(0, 4, max(n // 3, 1)),
        rng.integers(0, 3, max(n // 3, 1)),
        rng.choice(polarities, max(n // 3, 1)),
    )
    return base.take(rng.integers(0, base.num_rows, n))


def close(value: float, expected: float) -> bool:
    return value == pytest.approx(expected, rel=1e-9, abs=1e-12)


# ---- equality with brute force -----------------------------------------------------------

SIZES = [(1, 1), (1, 7), (2, 3), (40, 17), (300, 260), (1500, 1200), (5, 2000), (2000, 3)]


@pytest.mark.parametrize("n_a, n_b", SIZES)
@pytest.mark.parametrize("kind", ["random", "clumpy", "one polarity", "polarity mismatch"])
def test_equals_brute_force(n_a, n_b, kind):
    rng = np.random.default_rng(n_a * 7919 + n_b)
    if kind == "random":
        a, b = random_stream(rng, n_a), random_stream(rng, n_b)
    elif kind == "clumpy":
        a, b = clumpy_stream(rng, n_a), clumpy_stream(rng, n_b)
    elif kind == "one polarity":
        a, b = random_stream(rng, n_a, polarities=(1,)), random_stream(rng, n_b, polarities=(1,))
    else:  # ON only against both polarities: p~ differs between the streams
        a, b = random_stream(rng, n_a, polarities=(1,)), clumpy_stream(rng, n_b)
    result = metrics.compare(a, b)
    chamfer, gaussian = reference(points_pecs(a), points_pecs(b))
    assert close(result.chamfer, chamfer) and close(result.gaussian, gaussian)
    assert (result.events_a, result.events_b) == (n_a, n_b)
    per_event = metrics.nearest_distances(a, b).column("distance").to_numpy()
    np.testing.assert_allclose(
        per_event, brute_nearest(points_pecs(a), points_pecs(b)), rtol=1e-9, atol=1e-12
    )


@pytest.mark.parametrize("n_a, n_b", [(1, 1), (40, 17), (800, 900), (5, 2000)])
def test_separate_polarity_equals_brute_force_within_polarity(n_a, n_b):
    rng = np.random.default_rng(n_a + 31 * n_b)
    a, b = clumpy_stream(rng, n_a), random_stream(rng, n_b)
    # Both polarities must exist on both sides, or some distances are infinite (tested below).
    a = pa.concat_tables([a, table([0, 1], [0, 0], [0, 0], [0, 1])])
    b = pa.concat_tables([b, table([0, 1], [0, 0], [0, 0], [0, 1])])
    result = metrics.compare(a, b, polarity="separate")
    chamfer, gaussian = reference(points_pecs(a), points_pecs(b), separate=True)
    assert close(result.chamfer, chamfer) and close(result.gaussian, gaussian)


def test_separate_polarity_without_a_match_is_infinite():
    rng = np.random.default_rng(3)
    a, b = random_stream(rng, 50), random_stream(rng, 60, polarities=(1,))
    result = metrics.compare(a, b, polarity="separate")
    d_ab = brute_nearest(points_pecs(a), points_pecs(b), separate=True)
    d_ba = brute_nearest(points_pecs(b), points_pecs(a), separate=True)
    assert np.isinf(d_ab).any() and result.chamfer == np.inf
    expected = (1 - np.exp(-(d_ab**2) / SIGMA)).mean() + (1 - np.exp(-(d_ba**2) / SIGMA)).mean()
    assert close(result.gaussian, expected)


def test_sensor_normalisation_equals_brute_force():
    rng = np.random.default_rng(11)
    a = random_stream(rng, 700, width=346, height=260)
    b = table(*(a.column(c).to_numpy() for c in ("t", "x", "y", "p")), width=346, height=260)
    b = pa.concat_tables([b.slice(0, 500), random_stream(rng, 300)]).replace_schema_metadata(
        b.schema.metadata
    )
    t_all = np.concatenate([a.column("t").to_numpy(), b.column("t").to_numpy()])
    t0, span = t_all.min(), t_all.max() - t_all.min()
    result = metrics.compare(a, b, normalize="sensor")
    chamfer, gaussian = reference(
        points_sensor(a, 346, 260, t0, span), points_sensor(b, 346, 260, t0, span)
    )
    assert close(result.chamfer, chamfer) and close(result.gaussian, gaussian)
    assert result.options.normalize == "sensor"
    # A window gives the origin and the length of the time axis.
    windowed = metrics.compare(a, b, normalize="sensor", window_us=(1000, 9000))
    keep = lambda s: s.filter(  # noqa: E731
        (s.column("t").to_numpy() >= 1000) & (s.column("t").to_numpy() < 9000)
    )
    chamfer, gaussian = reference(
        points_sensor(keep(a), 346, 260, 1000, 8000), points_sensor(keep(b), 346, 260, 1000, 8000)
    )
    assert close(windowed.chamfer, chamfer) and close(windowed.gaussian, gaussian)


def test_equals_scipy_kdtree_on_1e5_events():
    rng = np.random.default_rng(2024)
    a = edge_stream(rng, 100_000, duration_us=100_000)
    b = edge_stream(rng, 100_000, duration_us=100_000)
    result = metrics.compare(a, b)
    chamfer, gaussian = reference(points_pecs(a), points_pecs(b), nearest=kdtree_nearest)
    assert close(result.chamfer, chamfer) and close(result.gaussian, gaussian)


# ---- properties ------------------------------------------------------------------------------


def test_identical_streams_give_zero():
    rng = np.random.default_rng(5)
    a = edge_stream(rng, 20_000)
    copy = table(*(a.column(c).to_numpy().copy() for c in ("t", "x", "y", "p")))
    for options in (
        {},
        {"polarity": "separate"},
        {"normalize": "sensor", "sensor_size": (346, 260)},
    ):
        result = metrics.compare(a, copy, **options)
        assert result.chamfer == 0.0 and result.gaussian == 0.0


def test_symmetric():
    rng = np.random.default_rng(6)
    a, b = edge_stream(rng, 5000), random_stream(rng, 3000)
    ab, ba = metrics.compare(a, b), metrics.compare(b, a)
    assert ab.chamfer == pytest.approx(ba.chamfer, rel=1e-12)
    assert ab.gaussian == pytest.approx(ba.gaussian, rel=1e-12)
    assert ab.chamfer > 0 and 0 < ab.gaussian < 2


def edge_stream(rng, n, *, duration_us=20_000, width=346, height=260, noise=0.05):
    """An edge sweeping left to right over the sensor (ON events within a pixel of it), plus a
    share of uniform background noise of both polarities; sorted by t."""
    n_noise = int(n * noise)
    t_edge = rng.uniform(0, duration_us, n - n_noise)
    x_edge = np.clip(t_edge / duration_us * width + rng.normal(0, 0.7, len(t_edge)), 0, width - 1)
    t = np.concatenate([t_edge, rng.uniform(0, duration_us, n_noise)]).astype(np.int64)
    x = np.concatenate([x_edge, rng.uniform(0, width, n_noise)]).astype(np.uint16)
    y = rng.integers(0, height, n)
    p = np.concatenate([np.ones(n - n_noise, np.int8), rng.integers(0, 2, n_noise)])
    order = np.argsort(t, kind="stable")
    return table(t[order], x[order], y[order], p[order], width, height)


def stretch(events: pa.Table, bias_us: float) -> pa.Table:
    """Fig. S1 time bias: event i gets t += bias * i / N."""
    t = events.column("t").to_numpy()
    shifted = t + np.floor(bias_us * np.arange(len(t)) / len(t)).astype(np.int64)
    return events.set_column(0, "t", pa.array(shifted))


def with_noise(events: pa.Table, n: int, rng, width=346, height=260) -> pa.Table:
    """Fig. S1 noise: n events, uniform x, y, times of real events at a stride, alternating p."""
    if n == 0:
        return events
    t = events.column("t").to_numpy()
    times = t[np.linspace(0, len(t) - 1, n).astype(np.int64)]
    noise = table(times, rng.integers(0, width, n), rng.integers(0, height, n), np.arange(n) % 2)
    merged = pa.concat_tables([events.replace_schema_metadata(None), noise])
    return merged.take(np.argsort(merged.column("t").to_numpy(), kind="stable"))


def test_fig_s1_sweeps_grow_and_gaussian_resists_noise():
    rng = np.random.default_rng(7)
    events = edge_stream(rng, 60_000, duration_us=40_000)
    levels = [0, 10, 100, 1_000, 10_000, 100_000]
    bias = [metrics.compare(events, stretch(events, b), first_us=10_000) for b in levels]
    noise = [metrics.compare(events, with_noise(events, n, rng), first_us=10_000) for n in levels]
    for sweep in (bias, noise):
        assert sweep[0].chamfer == 0 and sweep[0].gaussian == 0
        chamfer = [r.chamfer for r in sweep]
        gaussian = [r.gaussian for r in sweep]
        assert all(np.diff(chamfer) > 0), chamfer
        assert all(np.diff(gaussian) > 0), gaussian
    for b, n in zip(bias[1:], noise[1:]):
        assert n.gaussian < b.gaussian


# ---- options, inputs, edge cases -----------------------------------------------------------


def test_window_and_first_us_select_events():
    rng = np.random.default_rng(8)
    a, b = random_stream(rng, 2000), random_stream(rng, 1500)
    a = a.set_column(0, "t", pa.array(a.column("t").to_numpy() + 5_000))
    result = metrics.compare(a, b, window_us=(6_000, 12_000))

    def window(s, start, end):
        t = s.column("t").to_numpy()
        return s.filter((t >= start) & (t < end))

    chamfer, _ = reference(
        points_pecs(window(a, 6_000, 12_000)), points_pecs(window(b, 6_000, 12_000))
    )
    assert close(result.chamfer, chamfer)
    assert result.events_a == window(a, 6_000, 12_000).num_rows
    first = metrics.compare(a, b, first_us=3_000)
    t_a0, t_b0 = a.column("t").to_numpy().min(), b.column("t").to_numpy().min()
    chamfer, _ = reference(
        points_pecs(window(a, t_a0, t_a0 + 3_000)), points_pecs(window(b, t_b0, t_b0 + 3_000))
    )
    assert close(first.chamfer, chamfer)
    assert first.options.first_us == 3_000


def test_inputs_table_batch_structured_and_file(tmp_path):
    rng = np.random.default_rng(9)
    a, b = random_stream(rng, 500), random_stream(rng, 400)
    expected = metrics.compare(a, b)
    structured = np.zeros(400, dtype=[("t", "<i8"), ("x", "<u2"), ("y", "<u2"), ("p", "i1")])
    for c in ("t", "x", "y", "p"):
        structured[c] = b.column(c).to_numpy()
    path = write_events(a, tmp_path / "a.parquet", width=346, height=260)
    for left, right in [(a.to_batches()[0], structured), (path, b), (str(path), b.to_reader())]:
        result = metrics.compare(left, right)
        assert (result.chamfer, result.gaussian) == (expected.chamfer, expected.gaussian)
    assert metrics.chamfer_distance(a, b) == expected.chamfer
    assert metrics.gaussian_distance(a, b) == expected.gaussian
    assert metrics.gaussian_distance(a, b, sigma=1.0) != expected.gaussian


def test_nearest_distances_table():
    rng = np.random.default_rng(10)
    a, b = random_stream(rng, 300), random_stream(rng, 200)
    a = a.set_column(0, "t", pa.array(a.column("t").to_numpy() + 70_000))
    out = metrics.nearest_distances(a, b, first_us=5_000)
    t = a.column("t").to_numpy()
    kept = a.filter(t - t.min() < 5_000)
    assert out.column_names == ["t", "x", "y", "p", "distance"]
    assert out.column("t").to_pylist() == kept.column("t").to_pylist()  # original times
    tb = b.column("t").to_numpy()
    expected = brute_nearest(points_pecs(kept), points_pecs(b.filter(tb - tb.min() < 5_000)))
    np.testing.assert_allclose(out.column("distance").to_numpy(), expected, rtol=1e-9)
    assert json.loads(out.schema.metadata[b"pecs.metrics"])["first_us"] == 5_000
    empty = metrics.nearest_distances(a.slice(0, 0), b)
    assert empty.num_rows == 0 and empty.column_names[-1] == "distance"


def test_single_event_streams():
    one = table([5], [10], [20], [1])
    other = table([9], [200], [3], [0])
    # Each single event is normalised to the origin of its own stream: both at distance 0.
    assert metrics.compare(one, other).chamfer == 0.0
    # Against the sensor frame the offset shows: (190/346, 17/260, 1, 1) x (100, 100, 100, 1000).
    result = metrics.compare(one, other, normalize="sensor", sensor_size=(346, 260))
    d = np.hypot.reduce([100 * 190 / 346, 100 * 17 / 260, 100.0, 1000.0])
    assert close(result.chamfer, 2 * d)


@pytest.mark.parametrize(
    "a, b, options, error, message",
    [
        ("empty", "ok", {}, ValueError, "stream a has no events"),
        ("ok", "empty", {}, ValueError, "stream b has no events"),
        ("ok", "late", {"window_us": (0, 100)}, ValueError, "stream b has no events in the window"),
        ("ok", "p2", {}, ValueError, "polarity at event 0 is 2"),
        ("ok", "no_p", {}, ValueError, "no column p"),
        ("ok", "ok", {"first_us": 5, "window_us": (0, 5)}, ValueError, "not both"),
        ("ok", "ok", {"first_us": 0}, ValueError, "first_us"),
        ("ok", "ok", {"window_us": (5, 5)}, ValueError, "end > start"),
        ("ok", "ok", {"normalize": "minmax"}, ValueError, "normalize"),
        ("ok", "ok", {"polarity": "both"}, ValueError, "polarity"),
        ("ok", "ok", {"sigma": 0.0}, ValueError, "sigma"),
        ("ok", "ok", {"normalize": "sensor"}, ValueError, "sensor size"),
        ("ok", "ok", {"normalize": "sensor", "sensor_size": (10, 10)}, ValueError, "outside"),
        ("ok", "missing", {}, FileNotFoundError, "missing.parquet"),
        ("ok", 42, {}, TypeError, "stream b"),
    ],
)
def test_bad_input_raises_a_clear_error(a, b, options, error, message, tmp_path):
    rng = np.random.default_rng(12)
    streams = {
        "ok": random_stream(rng, 50),
        "empty": random_stream(rng, 0),
        "late": table([500, 600], [1, 2], [1, 2], [0, 1]),
        "p2": table([1], [1], [1], [2]),
        "no_p": pa.table({"t": [1], "x": [1], "y": [1]}),
        "missing": tmp_path / "missing.parquet",
    }
    with pytest.raises(error, match=message):
        metrics.compare(streams.get(a, a), streams.get(b, b), **options)


def test_cli_compare_prints_json(tmp_path, capsys):
    from pecs.cli import main

    rng = np.random.default_rng(13)
    a, b = random_stream(rng, 400), random_stream(rng, 300)
    path_a = write_events(a, tmp_path / "a.parquet", width=346, height=260)
    path_b = write_events(b, tmp_path / "b.parquet", width=346, height=260)
    assert main(["compare", str(path_a), str(path_b), "--first-us", "4000", "--json"]) == 0
    printed = json.loads(capsys.readouterr().out)
    expected = metrics.compare(a, b, first_us=4000)
    assert printed["chamfer"] == expected.chamfer and printed["gaussian"] == expected.gaussian
    assert printed["options"]["first_us"] == 4000
    assert main(["compare", str(path_a), str(path_b), "--normalize", "sensor"]) == 0
    assert "chamfer" in capsys.readouterr().out
    assert main(["compare", str(path_a), str(tmp_path / "none.parquet")]) == 2
    assert "none.parquet" in capsys.readouterr().err


def test_two_corner_events_move_the_paper_normalisation_not_the_sensor_one():
    """Why `normalize="sensor"` is recommended: the paper's per-stream min-max rescales a whole
    stream when one event lands far out. A car in one part of the sensor (x 100-180, y 80-140),
    simulated with 1-pixel and 100 us errors, then the same simulation plus one event at each
    sensor corner: with per-stream normalisation the chamfer distance jumps, since the two
    corners stretch the simulation's x and y over the whole sensor; with sensor normalisation
    only the two events' own distances enter (brute force over the same points, below)."""
    rng = np.random.default_rng(5)
    n = 4000
    t = np.sort(rng.integers(0, 10_000, n))
    real = table(t, rng.integers(100, 181, n), rng.integers(80, 141, n), rng.integers(0, 2, n))
    sim = table(
        np.clip(t + rng.integers(-100, 101, n), 0, 9_999),
        real.column("x").to_numpy() + rng.integers(-1, 2, n),
        real.column("y").to_numpy() + rng.integers(-1, 2, n),
        real.column("p").to_numpy(),
    )
    corners = table([0, 9_999], [0, 345], [0, 259], [1, 0])
    sim_corners = pa.concat_tables([sim, corners])
    window = (0, 10_000)
    paper = [metrics.compare(real, s, window_us=window).chamfer for s in (sim, sim_corners)]
    sensor = [
        metrics.compare(real, s, window_us=window, normalize="sensor", sensor_size=(346, 260))
        for s in (sim, sim_corners)
    ]
    # Brute force: the paper's jump is far beyond the two events' share of the mean...
    assert close(paper[1], reference(points_pecs(real), points_pecs(sim_corners))[0])
    assert abs(paper[1] / paper[0] - 1) > 0.5
    # ...while with the sensor's frame of reference the 4,000 matched events keep their
    # distances and the two corners add their own, 2 of 4,002 in the mean.
    for result, stream in zip(sensor, (sim, sim_corners)):
        expected = reference(
            points_sensor(real, 346, 260, 0, 10_000), points_sensor(stream, 346, 260, 0, 10_000)
        )
        assert close(result.chamfer, expected[0]) and close(result.gaussian, expected[1])
    assert abs(sensor[1].chamfer / sensor[0].chamfer - 1) < 0.05
