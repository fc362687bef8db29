"""Flow interpolation between frames (pecs.footage.flow_interpolation): a translating bar's edge reaches
each column when its motion says, static pixels stay silent, values stay >= 0."""

from __future__ import annotations

import numpy as np
import pecs
import pytest
from pecs.footage.flow_interpolation import DEFAULT_FLOW_SUBSTEPS, flow_subframes

PERIOD_US = 40_000
HEIGHT, WIDTH = 48, 96
DARK, BRIGHT = 0.1, 0.8
BAR_START, BAR_WIDTH, SPEED_PX = 12, 20, 8  # the bar moves 8 px per interval
BAR_ROWS = slice(8, HEIGHT - 8)  # a bar of 32 rows, well inside DIS's 8 x 8 patches


def bar_frame(start: int) -> np.ndarray:
    frame = np.full((HEIGHT, WIDTH), DARK, np.float32)
    frame[BAR_ROWS, start : start + BAR_WIDTH] = BRIGHT
    return frame


def bar_events(interpolation: str) -> dict[str, np.ndarray]:
    config = pecs.SensorConfig.preset("ideal", width=WIDTH, height=HEIGHT)
    frames = [bar_frame(BAR_START), bar_frame(BAR_START + SPEED_PX)]
    table = pecs.frames_to_events(
        frames, np.array([0, PERIOD_US], np.int64), config, interpolation=interpolation
    )
    return {name: table[name].to_numpy() for name in ("t", "x", "y", "p")}


def leading_edge_outside(events: dict[str, np.ndarray]) -> float:
    """Fraction of the leading edge's events outside the time the edge crosses their column.

    The bright edge starts at the bar's last column + 1/2 and moves SPEED_PX per interval: it
    covers column BAR_START + BAR_WIDTH + j (its samples at integer x, bilinear in between)
    from s = j / v to (j + 1) / v of the interval. The sensor sees sub-frames 1/16 of the
    interval apart, linear in log between them, so a crossing can come up to one sub-step
    later or earlier; the flow's own error of 1/2 px at most shifts it by 1/(2v)."""
    on = events["p"].astype(bool) & (events["x"] >= BAR_START + BAR_WIDTH)
    j = events["x"][on] - (BAR_START + BAR_WIDTH)
    s = events["t"][on] / PERIOD_US
    tolerance = 1 / DEFAULT_FLOW_SUBSTEPS + 0.5 / SPEED_PX
    outside = (s < j / SPEED_PX - tolerance) | (s > (j + 1) / SPEED_PX + tolerance)
    return float(np.mean(outside))


def test_a_moving_edge_reaches_each_column_when_its_motion_says() -> None:
    events = bar_events("flow")
    on = events["p"].astype(bool)
    # ON events only where the bar arrives, OFF only where it leaves: each such pixel goes
    # from DARK to BRIGHT (or back) once, so ln(8) / 0.2 = 10 crossings, in every row.
    assert set(np.unique(events["x"][on])) == set(range(32, 40))
    assert set(np.unique(events["x"][~on])) == set(range(12, 20))
    assert len(events["t"]) == 2 * SPEED_PX * 32 * int(np.log(BRIGHT / DARK) / 0.2)
    assert leading_edge_outside(events) == 0.0
    # Per column, the mean time follows x / v: slope 1 / v of the interval per column.
    columns = np.arange(32, 40)
    means = [events["t"][on & (events["x"] == x)].mean() / PERIOD_US for x in columns]
    slope = np.polyfit(columns, means, 1)[0]
    assert abs(slope - 1 / SPEED_PX) < 0.2 / SPEED_PX, slope


def test_transitions_put_the_edge_at_random_times() -> None:
    # The same bar through "transition": each pixel's change at a uniform time of the
    # interval, so most of the edge's events fall outside their column's crossing time
    # (a column's window of 1/8 + 2 tolerances holds about 1/3 of uniform times).
    events = bar_events("transition")
    assert leading_edge_outside(events) > 0.5


def test_constant_frames_give_no_events() -> None:
    config = pecs.SensorConfig.preset("ideal", width=WIDTH, height=HEIGHT)
    frames = [bar_frame(BAR_START)] * 3
    times = np.array([0, PERIOD_US, 2 * PERIOD_US], np.int64)
    table = pecs.frames_to_events(frames, times, config, interpolation="flow")
    assert table.num_rows == 0


def test_only_changed_pixels_move_and_values_stay_non_negative() -> None:
    # A bright square on black (zeros) moving diagonally, plus a textured static patch: the
    # warp samples across sharp edges, yet no sub-frame goes below 0 and every pixel equal
    # in both frames holds its value exactly in every sub-frame.
    rng = np.random.default_rng(4)
    before = np.zeros((HEIGHT, WIDTH), np.float32)
    before[:, 48:] = rng.uniform(0, 1, (HEIGHT, WIDTH - 48))
    after = before.copy()
    before[2:6, 4:10], after[5:9, 9:15] = 1.0, 1.0
    pairs = list(flow_subframes(zip([0, PERIOD_US], [before, after])))
    assert len(pairs) == 1 + DEFAULT_FLOW_SUBSTEPS
    assert [t for t, _ in pairs] == [round(j * PERIOD_US / 16) for j in range(17)]
    static = before == after
    for _, frame in pairs:
        assert np.all(frame >= 0) and np.all(np.isfinite(frame))
        assert np.array_equal(frame[static], before[static])


def test_substeps_are_checked() -> None:
    with pytest.raises(ValueError, match="substeps"):
        list(flow_subframes(zip([0, 1], [bar_frame(0)] * 2), substeps=0))
