"""AEDAT4 APS frames are timed at their exposure midpoint, the mean of the frame's own exposure
start and end, whatever the packet's `timestamp` holds: in the E-MLB DAVIS346 recording
(tests/data/davis346_emlb_excerpt, MIT) `timestamp` is the exposure start, in the road recording
(tests/data/davis346_excerpt) it is the midpoint. Hand values are from the recordings' frames.txt
and SOURCES.md; dv-processing, an independent reader, gives the exposure start and length."""

import lzma
import shutil
from datetime import timedelta
from pathlib import Path
from types import SimpleNamespace

import dv_processing as dv
import numpy as np
import pecs
import pytest
from pecs.cli import main as pecs_main
from pecs.footage.aedat4_frames import (
    EXPOSURE_MIDPOINT,
    TIMESTAMP,
    Aedat4FrameSource,
    frame_time_us,
)

DATA = Path(__file__).parent / "data"
EMLB = DATA / "davis346_emlb_excerpt" / "davis346_emlb_3frames.aedat4"
ROAD = DATA / "davis346_excerpt" / "davis346_road_3frames.aedat4"
# The shared recordings, where a checkout has them beside it (CI does); skipped elsewhere.
SHARED = Path(__file__).resolve().parents[1].parent / "shared" / "data"

# frames.txt of davis346_emlb, first 3 rows: exposure start and end (us); 20 ms exposures whose
# `timestamp` is the start, so the midpoints are start + 10,000 us.
EMLB_EXPOSURES_US = [
    (1643243628757800, 1643243628777800),
    (1643243628797800, 1643243628817800),
    (1643243628837800, 1643243628857800),
]
EMLB_MIDPOINTS_US = [1643243628767800, 1643243628807800, 1643243628847800]
# The road excerpt's frames: 500 us exposures from ...364965, ...404965, ...444965 (its README).
ROAD_MIDPOINTS_US = [1589163147365215, 1589163147405215, 1589163147445215]


def dv_midpoints_us(path: Path) -> list[int]:
    """Exposure start + half the exposure of every frame, as dv-processing reads them."""
    recording = dv.io.MonoCameraRecording(str(path))
    midpoints = []
    while (frame := recording.getNextFrame()) is not None:
        midpoints.append(frame.timestamp + frame.exposure // timedelta(microseconds=1) // 2)
    return midpoints


def test_emlb_frames_are_timed_at_their_exposure_midpoints_not_their_timestamps():
    assert [(start + end) // 2 for start, end in EMLB_EXPOSURES_US] == EMLB_MIDPOINTS_US
    source = pecs.open_frames(EMLB)
    assert (source.width, source.height, len(source)) == (346, 260, 3)
    assert [t_us for t_us, _ in source] == EMLB_MIDPOINTS_US
    assert dv_midpoints_us(EMLB) == EMLB_MIDPOINTS_US
    assert source.frame_times == EXPOSURE_MIDPOINT
    assert "exposure midpoint from exposure start/end" in repr(source)  # seen when printed


def test_road_frames_keep_their_times_where_timestamp_is_already_the_midpoint():
    source = pecs.open_frames(ROAD)
    assert [t_us for t_us, _ in source] == ROAD_MIDPOINTS_US
    # The road file's exposure fields agree with its timestamps (dv-processing's reading).
    assert dv_midpoints_us(ROAD) == ROAD_MIDPOINTS_US
    assert source.frame_times == EXPOSURE_MIDPOINT


def test_a_frame_without_exposure_times_falls_back_to_its_timestamp():
    # AEDAT4 leaves absent fields at 0.
    assert frame_time_us(SimpleNamespace(t=500, exposure_start_t=0, exposure_end_t=0)) == 500
    assert frame_time_us(SimpleNamespace(t=500, exposure_start_t=100, exposure_end_t=301)) == 200
    # An exposure that ends before it starts is not a time to trust.
    assert frame_time_us(SimpleNamespace(t=500, exposure_start_t=300, exposure_end_t=100)) == 500


def test_a_stream_that_stops_recording_exposure_times_is_refused(monkeypatch):
    pixels = np.zeros((2, 2), np.uint8)
    frames = [
        SimpleNamespace(t=100, exposure_start_t=100, exposure_end_t=120),
        SimpleNamespace(t=140, exposure_start_t=0, exposure_end_t=0),
    ]
    for frame in frames:
        frame.__dict__.update(format="L", pixels=pixels, offset_x=0, offset_y=0)
    source = Aedat4FrameSource(
        Path("mixed.aedat4"), "aedat4", 2, 2, None, None, 2, frame_times=EXPOSURE_MIDPOINT
    )
    monkeypatch.setattr(Aedat4FrameSource, "_packets", lambda self: iter(frames))
    with pytest.raises(
        ValueError, match="frame 1 has no exposure times where the first frame has them"
    ):
        list(source)
    timestamped = Aedat4FrameSource(
        Path("mixed.aedat4"), "aedat4", 2, 2, None, None, 2, frame_times=TIMESTAMP
    )
    with pytest.raises(
        ValueError, match="frame 0 has exposure times where the first frame has none"
    ):
        list(timestamped)


def test_frames2events_on_emlb_simulates_between_the_exposure_midpoints(tmp_path):
    output = tmp_path / "sim.parquet"
    args = ["frames2events", str(EMLB), "--preset", "ideal", "--input-noise", "off"]
    assert pecs_main([*args, "--interpolation", "linear", "-o", str(output), "--quiet"]) == 0
    t_us = pecs.read_events(output).column("t").to_numpy()
    assert len(t_us) > 0
    # An ideal sensor's events lie after the first frame's time, at or before the last's; timed
    # by `timestamp` they would end 10 ms early, at ...837800.
    assert EMLB_MIDPOINTS_US[0] < t_us.min() and t_us.max() <= EMLB_MIDPOINTS_US[-1]
    assert t_us.max() > EMLB_EXPOSURES_US[-1][0]


def shared_recording(name: str, tmp_path: Path) -> Path:
    """The shared recording `name` decompressed into tmp_path, or the test is skipped."""
    packed = SHARED / name / f"{name}.aedat4.xz"
    if name == "davis346_emlb":
        packed = SHARED / name / "demo-01.aedat4.xz"
    if not packed.is_file():
        pytest.skip(f"shared recording {name} not beside this checkout")
    target = tmp_path / packed.name.removesuffix(".xz")
    with lzma.open(packed) as source, target.open("wb") as sink:
        shutil.copyfileobj(source, sink)
    return target


def test_the_whole_emlb_recording_is_timed_as_its_frames_txt_says(tmp_path):
    recording = shared_recording("davis346_emlb", tmp_path)
    table = np.loadtxt(SHARED / "davis346_emlb" / "frames.txt", dtype=np.int64, ndmin=2)
    midpoints_us = (table[:, 2] + table[:, 3]) // 2
    assert np.all(midpoints_us - table[:, 1] == 10_000)  # timestamp = exposure start here
    assert [t_us for t_us, _ in pecs.open_frames(recording)] == midpoints_us.tolist()


def test_the_whole_road_recording_keeps_its_timestamps(tmp_path):
    recording = shared_recording("davis346_road", tmp_path)
    times_us = [t_us for t_us, _ in pecs.open_frames(recording)]
    assert len(times_us) == 59
    assert times_us == dv_midpoints_us(recording)
    assert times_us[:3] == ROAD_MIDPOINTS_US
