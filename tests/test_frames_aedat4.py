"""APS frames of an AEDAT4 recording as frame input, checked against dv-processing's reading of a
real DAVIS346 excerpt (tests/data/davis346_excerpt, MIT): pixels as DN / 255 (0 DN as half a DN:
light below one DN, not darkness) and times as the exposure midpoint, which dv-processing gives as
its exposure start plus half the exposure."""

from datetime import timedelta
from pathlib import Path

import dv_processing as dv
import numpy as np
import pecs
import pytest
from pecs.cli import main as pecs_main

EXCERPT = Path(__file__).parent / "data" / "davis346_excerpt" / "davis346_road_3frames.aedat4"


def dv_frames(path):
    """(exposure midpoint in us, uint8 image) of every frame, as dv-processing reads them."""
    recording = dv.io.MonoCameraRecording(str(path))
    frames = []
    while (frame := recording.getNextFrame()) is not None:
        half_exposure_us = frame.exposure // timedelta(microseconds=1) // 2
        frames.append((frame.timestamp + half_exposure_us, frame.image.copy()))
    return frames


def test_aps_frames_are_dn_over_255_at_the_exposure_midpoint_black_as_half_a_dn():
    expected = dv_frames(EXCERPT)
    source = pecs.open_frames(EXCERPT)
    assert (source.width, source.height, len(source)) == (346, 260, 3)
    got = list(source)
    assert [t for t, _ in got] == [t for t, _ in expected]
    # The excerpt's first frame: exposure 1589163147364965 + 500 us, midpoint ...365215.
    assert got[0][0] == 1589163147364965 + 250
    for (_, frame), (_, image) in zip(got, expected, strict=True):
        assert frame.dtype == np.float32 and frame.shape == (260, 346)
        dn = np.maximum(image.astype(np.float32), np.float32(0.5))
        np.testing.assert_array_equal(frame, dn / np.float32(255))
    assert any((image == 0).any() for _, image in expected)  # the excerpt has black pixels


def test_frame_times_and_size_come_from_the_recording():
    with pytest.raises(ValueError, match="its own frame times"):
        pecs.open_frames(EXCERPT, fps=25)


def test_an_aedat4_without_frames_is_a_value_error(tmp_path):
    events_only = tmp_path / "events.aedat4"
    pecs.write_events(pecs.read_events(EXCERPT), events_only)
    with pytest.raises(ValueError, match="no frame stream"):
        pecs.open_frames(events_only)


def test_frames2events_simulates_the_recording_at_its_own_times(tmp_path, capsys):
    output = tmp_path / "sim.parquet"
    assert (
        pecs_main(
            [
                "frames2events",
                str(EXCERPT),
                "--preset",
                "ideal",
                "--input-noise",
                "off",  # the raw frames' crossings, counted below
                "-o",
                str(output),
                "--quiet",
            ]
        )
        == 0
    )
    assert "from 3 frames (346 x 260)" in capsys.readouterr().out
    events = pecs.read_events(output)
    times = [t for t, _ in dv_frames(EXCERPT)]
    t_us = events.column("t").to_numpy()
    assert len(t_us) > 0
    # An ideal sensor's events lie strictly after the first frame, at or before the last.
    assert times[0] < t_us.min() and t_us.max() <= times[-1]
    # Independent check of the count at one pixel: ideal log crossings of theta = 0.2 between
    # the frames' DN / 255 (0 DN as 0.5; + dark current 1e-3) values, as a brute-force count.
    frames = [np.maximum(image.astype(np.float64), 0.5) / 255 for _, image in dv_frames(EXCERPT)]
    log_frames = np.log(np.stack(frames) + 1e-3)
    changes = np.abs(log_frames[-1] - log_frames[0])
    y, x = np.unravel_index(np.argmax(changes), changes.shape)
    at_pixel = (events.column("x").to_numpy() == x) & (events.column("y").to_numpy() == y)
    reference, crossings = log_frames[0, y, x], 0
    for value in log_frames[1:, y, x]:
        steps = int(abs(value - reference) // 0.2)
        crossings += steps
        reference += np.sign(value - reference) * steps * 0.2
    assert at_pixel.sum() == crossings
