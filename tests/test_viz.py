"""pecs.viz: event frames, time surfaces, videos, checked on pixel values."""

from __future__ import annotations

import numpy as np
import pecs.events
import pecs.viz
import pyarrow as pa
import pyarrow.compute as pc
import pytest

WHITE, BLUE, RED = (255, 255, 255), (33, 102, 172), (214, 39, 40)


def moving_bar_events(width=64, height=16, bar_px=8, speed_px_per_s=1000.0, duration_s=0.03):
    """Ideal DVS events of a bright bar moving right over a dark background.

    The bar covers [x0 + v t, x0 + v t + bar_px). Column c brightens (ON) when the leading edge
    reaches it, t = (c - x0 - bar_px) / v, and darkens (OFF) when the trailing edge passes,
    t = (c + 1 - x0) / v. Every row behaves the same.
    """
    x0 = 0
    rows = []
    for c in range(width):
        t_on = (c - x0 - bar_px + 1) / speed_px_per_s
        t_off = (c + 1 - x0) / speed_px_per_s
        for t_s, p in ((t_on, 1), (t_off, 0)):
            if 0 < t_s <= duration_s:
                for r in range(height):
                    rows.append((round(t_s * 1e6), c, r, p))
    rows.sort()
    t, x, y, p = (np.array(column) for column in zip(*rows, strict=True))
    columns = {"t": t, "x": x, "y": y, "p": p}
    return pa.Table.from_batches(
        [pecs.events.record_batch(columns, pecs.events.schema(width, height))]
    )


def test_bar_moving_right_shows_on_leading_and_off_trailing_edge():
    events = moving_bar_events()
    # At 20 ms the bar spans [20, 28); in the 3 ms before, the leading edge fully covered columns
    # 25..27 (ON) and the trailing edge fully uncovered columns 17..19 (OFF).
    image = pecs.viz.event_frame(events, t_start_us=17_001, t_end_us=20_001)
    assert image.shape == (16, 64, 3) and image.dtype == np.uint8
    for column in range(64):
        expected = BLUE if 25 <= column <= 27 else RED if 17 <= column <= 19 else WHITE
        assert np.all(image[:, column] == expected), column
    # Leading edge is to the right of the trailing edge.
    on_cols = np.flatnonzero(np.all(image[0] == BLUE, axis=1))
    off_cols = np.flatnonzero(np.all(image[0] == RED, axis=1))
    assert on_cols.min() > off_cols.max()


def test_frame_shows_latest_polarity_and_black_background():
    columns = {"t": [0, 5, 10], "x": [1, 1, 2], "y": [0, 0, 1], "p": [1, 0, 1]}
    events = pecs.events.record_batch(columns, pecs.events.schema(4, 2))
    image = pecs.viz.event_frame(events, background="black")
    assert tuple(image[0, 1]) == (255, 80, 60)  # ON then OFF: latest is OFF
    assert tuple(image[1, 2]) == (86, 180, 233)
    assert image[0, 0].tolist() == [0, 0, 0]
    with pytest.raises(ValueError, match="background"):
        pecs.viz.event_frame(events, background="grey")


def test_frame_rejects_addresses_outside_sensor():
    events = pecs.events.record_batch(
        {"t": [0], "x": [5], "y": [0], "p": [1]}, pecs.events.schema(4, 2)
    )
    with pytest.raises(ValueError, match="outside"):
        pecs.viz.event_frame(events)


def test_time_surface_decays_exponentially():
    columns = {"t": [0, 1_000, 3_000], "x": [0, 1, 0], "y": [0, 0, 0], "p": [1, 0, 0]}
    events = pecs.events.record_batch(columns, pecs.events.schema(2, 1))
    surface = pecs.viz.time_surface(events, t_us=5_000, tau_us=2_000.0)
    assert surface.shape == (2, 1, 2)
    np.testing.assert_allclose(surface[1, 0, 0], np.exp(-5_000 / 2_000), rtol=1e-6)
    np.testing.assert_allclose(surface[0, 0, 0], np.exp(-2_000 / 2_000), rtol=1e-6)
    np.testing.assert_allclose(surface[0, 0, 1], np.exp(-4_000 / 2_000), rtol=1e-6)
    assert surface[1, 0, 1] == 0.0
    image = pecs.viz.time_surface_image(events, t_us=3_000, tau_us=2_000.0)
    assert tuple(image[0, 0]) == RED  # OFF at the current time: full colour


def test_streamed_frames_match_whole_table_frames():
    events = moving_bar_events()
    batches = events.to_batches(max_chunksize=37)
    streamed = list(pecs.viz.event_frames(batches, window_us=4_000, t_start_us=0))
    t_last = int(pc.max(events.column("t")).as_py())
    assert len(streamed) == t_last // 4_000 + 1
    for k, frame in enumerate(streamed):
        whole = pecs.viz.event_frame(events, t_start_us=4_000 * k, t_end_us=4_000 * (k + 1))
        np.testing.assert_array_equal(frame, whole)


def test_save_image_and_video_round_trip(tmp_path):
    import cv2
    from PIL import Image

    events = moving_bar_events()
    image = pecs.viz.event_frame(events)
    png = pecs.viz.save_image(image, tmp_path / "frame.png")
    np.testing.assert_array_equal(cv2.imread(str(png))[..., ::-1], image)
    frames = list(pecs.viz.event_frames(events, window_us=5_000))
    gif = pecs.viz.save_video(frames, tmp_path / "bar.gif", fps=20)
    with Image.open(gif) as opened:
        assert opened.n_frames == len(frames)
    mp4 = pecs.viz.save_video(iter(frames), tmp_path / "bar.mp4", fps=20)
    capture = cv2.VideoCapture(str(mp4))
    assert int(capture.get(cv2.CAP_PROP_FRAME_COUNT)) == len(frames)
    capture.release()
    assert sorted(p.name for p in tmp_path.iterdir()) == ["bar.gif", "bar.mp4", "frame.png"]
    with pytest.raises(ValueError, match=".avi"):
        pecs.viz.save_video(frames, tmp_path / "bar.avi")


def test_cli_view_writes_png_and_gif(tmp_path):
    import argparse

    import pecs.cli.view
    import pecs.io
    from PIL import Image

    events = moving_bar_events()
    path = pecs.io.write_events(events, tmp_path / "bar.parquet")
    parser = argparse.ArgumentParser()
    pecs.cli.view.register(parser.add_subparsers(dest="command"))
    png = tmp_path / "bar.png"
    args = parser.parse_args(
        ["view", str(path), "-o", str(png), "--start-ms", "17.001", "--window-ms", "3"]
        + ["--absolute-times"]  # the bar's first event is at 1 ms
    )
    assert args.func(args) == 0
    with Image.open(png) as opened:
        image = np.asarray(opened.convert("RGB"))
    np.testing.assert_array_equal(
        image, pecs.viz.event_frame(events, t_start_us=17_001, t_end_us=20_001)
    )
    gif = tmp_path / "bar.gif"
    args = parser.parse_args(["view", str(path), "-o", str(gif), "--window-ms", "5"])
    assert args.func(args) == 0
    with Image.open(gif) as opened:
        assert opened.size == (64, 16) and opened.n_frames == 6  # 30 ms of events / 5 ms


def test_engine_preview_of_bar_moving_right():
    """The event engine on a rendered bar: ON pixels lead, OFF pixels trail, on pixel values."""
    import pecs

    width, height, bar_px = 64, 8, 8
    columns = np.arange(width) + 0.5

    def frame(left: float) -> np.ndarray:
        # Area coverage of each pixel by the bar [left, left + bar_px): smooth sub-pixel edges.
        cover = np.clip(
            np.minimum(columns + 0.5, left + bar_px) - np.maximum(columns - 0.5, left), 0, 1
        )
        return np.tile((0.05 + 0.95 * cover).astype(np.float32), (height, 1))

    t_us = np.arange(0, 21_000, 250)  # 1 px per ms, 4 frames per px
    frames = np.stack([frame(t / 1000.0) for t in t_us])
    config = pecs.SensorConfig.preset(
        "ideal", width=width, height=height, theta_on=0.25, theta_off=0.25
    )
    events = pecs.frames_to_events(frames, t_us, config)
    image = pecs.viz.event_frame(events, t_start_us=17_000, t_end_us=20_001)
    on = np.all(image == BLUE, axis=2)
    off = np.all(image == RED, axis=2)
    assert np.all(on | off | np.all(image == WHITE, axis=2))
    on_cols, off_cols = np.flatnonzero(on.any(axis=0)), np.flatnonzero(off.any(axis=0))
    # At 17-20 ms the bar's leading edge sweeps [25, 28) and its trailing edge [17, 20).
    assert len(on_cols) and len(off_cols)
    assert set(on_cols) <= set(range(24, 29)) and set(off_cols) <= set(range(16, 21))
    assert np.all(on[:, on_cols] == on[:1, on_cols])  # every row alike


def test_cli_view_time_surface_matches_api(tmp_path):
    import argparse

    import pecs.cli.view
    import pecs.io
    from PIL import Image

    events = moving_bar_events()
    path = pecs.io.write_events(events, tmp_path / "bar.h5")
    parser = argparse.ArgumentParser()
    pecs.cli.view.register(parser.add_subparsers(dest="command"))
    png = tmp_path / "surface.png"
    # 9 ms after the bar's first event (at 1 ms): from t = 10 ms.
    argv = ["view", str(path), "-o", str(png), "--start-ms", "9", "--window-ms", "6"]
    args = parser.parse_args([*argv, "--time-surface", "--background", "black"])
    assert args.func(args) == 0
    t = events.column("t").to_numpy()
    before = events.filter(pa.array(t < 16_000))
    expected = pecs.viz.time_surface_image(before, t_us=15_999, tau_us=2_000.0, background="black")
    with Image.open(png) as opened:
        np.testing.assert_array_equal(np.asarray(opened.convert("RGB")), expected)
