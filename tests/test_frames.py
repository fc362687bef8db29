"""Frame readers and the frames2events command, checked against independently computed values
(IEC 61966-2-1 sRGB decoding, Rec. 709 luminance) and files written by other libraries
(OpenCV for PNG and video, the OpenEXR package for EXR)."""

import subprocess
import sys

import cv2
import numpy as np
import OpenEXR
import pecs
import pyarrow.parquet as pq
import pytest
from pecs.footage.frames import open_frames


def srgb_decode(code, bits):
    v = code / (2**bits - 1)
    return v / 12.92 if v <= 0.04045 else ((v + 0.055) / 1.055) ** 2.4


def write_exr(path, channels):
    header = {"compression": OpenEXR.ZIP_COMPRESSION, "type": OpenEXR.scanlineimage}
    OpenEXR.File(header, channels).write(str(path))


def test_8_and_16_bit_images_are_decoded_from_srgb_to_linear(tmp_path):
    cv2.imwrite(str(tmp_path / "a.png"), np.full((4, 5), 128, np.uint8))
    cv2.imwrite(str(tmp_path / "b.png"), np.full((4, 5), 40000, np.uint16))
    frames = [f for _, f in open_frames(tmp_path, fps=10)]
    assert frames[0][0, 0] == pytest.approx(srgb_decode(128, 8), rel=1e-6)
    assert frames[1][0, 0] == pytest.approx(srgb_decode(40000, 16), rel=1e-6)
    linear = [f for _, f in open_frames(tmp_path, fps=10, encoding="linear")]
    assert linear[0][0, 0] == pytest.approx(128 / 255, rel=1e-6)


def test_colour_images_give_rec709_luminance_of_linear_rgb(tmp_path):
    bgr = np.zeros((3, 3, 3), np.uint8)
    bgr[..., 0], bgr[..., 1], bgr[..., 2] = 30, 200, 90  # OpenCV stores B, G, R
    cv2.imwrite(str(tmp_path / "c.png"), bgr)
    ((_, frame),) = list(open_frames(tmp_path, fps=1))
    expected = (
        0.2126 * srgb_decode(90, 8) + 0.7152 * srgb_decode(200, 8) + 0.0722 * srgb_decode(30, 8)
    )
    assert frame[1, 1] == pytest.approx(expected, rel=1e-5)


def test_frames_are_taken_in_natural_order_with_fps_timestamps(tmp_path):
    for k in (10, 2, 1):
        cv2.imwrite(str(tmp_path / f"f{k}.png"), np.full((2, 2), k * 20, np.uint8))
    got = list(open_frames(tmp_path, fps=250))
    assert [t for t, _ in got] == [0, 4000, 8000]
    assert [f[0, 0] for _, f in got] == pytest.approx(
        [srgb_decode(c, 8) for c in (20, 40, 200)], rel=1e-6
    )


def test_exr_sequences_read_half_and_float_channels_by_name(tmp_path):
    r = np.arange(12, dtype=np.float32).reshape(3, 4)
    g = np.full((3, 4), 0.5, np.float16)
    b = np.full((3, 4), 2.0, np.float32)
    for k in range(2):
        write_exr(tmp_path / f"render_{k:03d}.exr", {"R": r + k, "G": g, "B": b})
    frames = [f for _, f in open_frames(tmp_path, fps=30)]
    np.testing.assert_allclose(frames[1], 0.2126 * (r + 1) + 0.7152 * 0.5 + 0.0722 * 2.0, rtol=1e-6)
    green = [f for _, f in open_frames(tmp_path, fps=30, channel="G")]
    assert green[0].dtype == np.float32 and np.all(green[0] == 0.5)
    with pytest.raises(ValueError, match='no channel "Z"; it has B, G, R'):
        list(open_frames(tmp_path, fps=30, channel="Z"))


def test_videos_are_read_with_their_own_frame_rate(tmp_path):
    path = tmp_path / "clip.avi"
    writer = cv2.VideoWriter(str(path), cv2.VideoWriter_fourcc(*"MJPG"), 50.0, (32, 24))
    for k in range(10):
        writer.write(np.full((24, 32, 3), 20 * k, np.uint8))
    writer.release()
    source = open_frames(path)
    assert (source.width, source.height, source.fps) == (32, 24, 50.0)
    got = list(source)
    assert [t for t, _ in got] == [k * 20_000 for k in range(10)]
    assert got[5][1].mean() == pytest.approx(srgb_decode(100, 8), abs=0.01)
    # Black (code 0, frame 0) is light below one code: half a code, 0.5 / 255 / 12.92 linear;
    # an image file, which may be rendered, keeps its zeros.
    assert np.all(got[0][1] == np.float32(0.5 / 255 / 12.92))
    (tmp_path / "images").mkdir()
    cv2.imwrite(str(tmp_path / "images" / "black.png"), np.zeros((2, 2), np.uint8))
    assert np.all(next(iter(open_frames(tmp_path / "images", fps=1)))[1] == 0)


def test_timestamp_files_in_seconds_and_bad_ones(tmp_path):
    cv2.imwrite(str(tmp_path / "a.png"), np.zeros((2, 2), np.uint8))
    cv2.imwrite(str(tmp_path / "b.png"), np.zeros((2, 2), np.uint8))
    good = tmp_path.parent / "times.txt"
    good.write_text("# t\n0.5 a.png\n0.5125 b.png\n")
    assert [t for t, _ in open_frames(tmp_path, timestamps=good, timestamp_unit="s")] == [
        500_000,
        512_500,
    ]
    bad = tmp_path.parent / "bad_times.txt"
    bad.write_text("100\n100\n")
    with pytest.raises(ValueError, match="must increase: .*line 2"):
        open_frames(tmp_path, timestamps=bad)
    with pytest.raises(ValueError, match="fps"):
        open_frames(tmp_path)


def test_unreadable_inputs_name_the_file(tmp_path):
    with pytest.raises(FileNotFoundError, match="no such file or folder: "):
        open_frames(tmp_path / "missing", fps=1)
    (tmp_path / "broken.png").write_bytes(b"\x89PNG not really")
    with pytest.raises(ValueError, match="broken.png: not a readable image"):
        open_frames(tmp_path, fps=1)
    (tmp_path / "broken.png").unlink()
    (tmp_path / "x.exr").write_bytes(b"garbage")
    with pytest.raises(ValueError, match="x.exr: not a readable EXR"):
        open_frames(tmp_path, fps=1)


def run_cli(*args):
    return subprocess.run(
        [sys.executable, "-m", "pecs", *map(str, args)], capture_output=True, text=True
    )


def test_frames2events_writes_the_same_events_as_the_api(tmp_path):
    frames_dir = pecs.examples.write_quadrant_disk_frames(
        tmp_path / "frames", width=64, height=48, frames=12
    )
    out = tmp_path / "ev.parquet"
    result = run_cli(
        "frames2events",
        frames_dir,
        "-o",
        out,
        "--fps",
        1000,
        "--preset",
        "ideal",
        "--set",
        "theta_on=0.3",
        "--quiet",
    )
    assert result.returncode == 0, result.stderr
    table = pq.read_table(out)
    assert table.schema.metadata[b"width"] == b"64"
    assert pecs.events.sensor_config_json(table.schema)["theta_on"] == 0.3
    source = open_frames(frames_dir, fps=1000)
    frames, times = zip(*[(f, t) for t, f in source])
    expected = pecs.frames_to_events(
        frames, times, pecs.SensorConfig.preset("ideal", width=64, height=48, theta_on=0.3)
    )
    assert table.num_rows == expected.num_rows > 100
    assert table.select(["t", "x", "y", "p"]).equals(expected.select(["t", "x", "y", "p"]))


def test_frames2events_errors_are_clear_and_leave_no_file(tmp_path):
    frames_dir = pecs.examples.write_quadrant_disk_frames(
        tmp_path / "frames", width=16, height=12, frames=3
    )
    out = tmp_path / "ev.parquet"
    result = run_cli("frames2events", frames_dir, "-o", out, "--fps", 100, "--set", "theta_onn=0.3")
    assert result.returncode == 2 and "theta_onn: unknown sensor field" in result.stderr
    result = run_cli(
        "frames2events", frames_dir, "-o", out, "--fps", 100, "--set", "refractory_us=-1"
    )
    assert result.returncode == 2 and "refractory_us: must be in [0.0, 1000000.0]" in result.stderr
    (frames_dir / "frame_00001.png").write_bytes(b"corrupt")
    result = run_cli("frames2events", frames_dir, "-o", out, "--fps", 100, "--quiet")
    assert result.returncode == 2 and "frame_00001.png: not a readable image" in result.stderr
    assert list(tmp_path.iterdir()) == [frames_dir]


def test_sensor_config_validation_names_the_field():
    for field, value in [
        ("theta_on", -0.1),
        ("width", 0),
        ("reference_reset", "sometimes"),
        ("dark_current", float("nan")),
        ("hot_pixel_fraction", 2.0),
        ("seed", -1),
    ]:
        with pytest.raises(ValueError, match=field):
            pecs.SensorConfig.preset("ideal", **{field: value})
    with pytest.raises(ValueError, match="unknown sensor preset 'dvs9000'"):
        pecs.SensorConfig.preset("dvs9000")
    for name in pecs.SensorConfig.PRESETS:
        assert pecs.SensorConfig.preset(name).preset_name == name
