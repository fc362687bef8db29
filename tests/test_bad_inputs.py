"""Bad frames, times and sensor configurations, each with the exception and the fragment of its
message that it must raise; and numpy scalars, whole-number float times and 8/16-bit frames,
which must be taken. The ranges are the physical ones documented in SensorConfig."""

from __future__ import annotations

import warnings
from typing import Any

import numpy as np
import pecs
import pytest
from pecs import SensorConfig
from pecs.footage.frames import open_frames

# ---------------------------------------------------------------- configurations

# Every field just outside its range (and NaN, infinity, wrong types), with the message fragment.
BAD_CONFIGS: list[tuple[dict[str, Any], str]] = [
    ({"width": 0}, "width: must be an integer in 1..65536"),
    ({"width": 65537}, "width: must be an integer in 1..65536"),
    ({"width": 3.0}, "width: must be an integer"),
    ({"height": True}, "height: must be an integer"),
    ({"theta_on": 1e-300}, "theta_on: must be in [0.01, 10.0]"),
    ({"theta_on": 10.5}, "theta_on: must be in [0.01, 10.0]"),
    ({"theta_off": 0.005}, "theta_off: must be in [0.01, 10.0]"),
    ({"theta_on": 0.05, "theta_min": 0.1}, "theta_on: must be >= theta_min (0.1)"),
    ({"theta_min": 1e-300}, "theta_min: must be in [0.01, 1.0]"),
    ({"theta_min": 2.0, "theta_on": 3.0, "theta_off": 3.0}, "theta_min: must be in [0.01, 1.0]"),
    ({"theta_sigma": 1.5}, "theta_sigma: must be in [0.0, 1.0]"),
    ({"theta_noise": -0.1}, "theta_noise: must be in [0.0, 1.0]"),
    ({"refractory_us": 2e6}, "refractory_us: must be in [0.0, 1000000.0]"),
    ({"refractory_us": -1}, "refractory_us: must be in [0.0, 1000000.0]"),
    ({"cutoff_hz": 5e-324}, "cutoff_hz: must be 0 (off) or in [0.001, 1000000.0]"),
    ({"cutoff_hz": 2e6}, "cutoff_hz: must be 0 (off) or in [0.001, 1000000.0]"),
    ({"cutoff_half_photocurrent": 1e4}, "cutoff_half_photocurrent: must be in [0.0, 1000.0]"),
    ({"dark_current": 1e-300}, "dark_current: must be 0 (off) or in [1e-6, 1000.0]"),
    ({"dark_current": 1e4}, "dark_current: must be 0 (off) or in [1e-6, 1000.0]"),
    ({"dark_current": 0.0}, "dark_current: must be > 0"),
    ({"lin_log_knee": -1.0}, "lin_log_knee: must be 0 (off) or in [1e-6, 1000.0]"),
    ({"lin_log_knee": 1e-300}, "lin_log_knee: must be 0 (off) or in [1e-6, 1000.0]"),
    ({"latency_us": 1e300}, "latency_us: must be in [0.0, 1000000.0]"),
    ({"jitter_us": 1e7}, "jitter_us: must be in [0.0, 1000000.0]"),
    ({"leak_rate_hz": 1e12}, "leak_rate_hz: must be in [0.0, 1000000.0]"),
    ({"leak_spread_decades": 3.0}, "leak_spread_decades: must be in [0.0, 2.0]"),
    ({"shot_rate_hz": 1e300}, "shot_rate_hz: must be in [0.0, 1000000.0]"),
    ({"shot_rate_hz": 1.0, "dark_current": 0.0, "lin_log_knee": 0.1}, "shot_rate_hz: needs"),
    ({"shot_light_exponent": 1.5}, "shot_light_exponent: must be 1 or 2, got 1.5"),
    ({"shot_light_exponent": float("nan")}, "shot_light_exponent: must be"),
    ({"hot_pixel_fraction": 1.5}, "hot_pixel_fraction: must be in [0.0, 1.0]"),
    ({"hot_pixel_rate_hz": 1e300}, "hot_pixel_rate_hz: must be in [0.0, 1000000.0]"),
    ({"leak_rate_hz": float("nan")}, "leak_rate_hz: must be a finite number"),
    ({"jitter_us": float("inf")}, "jitter_us: must be a finite number"),
    ({"latency_us": "20"}, "latency_us: must be a finite number"),
    ({"seed": -1}, "seed: must be an integer in [0, 2**64)"),
    ({"seed": 2**64}, "seed: must be an integer in [0, 2**64)"),
    ({"reference_reset": "never"}, "reference_reset: must be one of"),
    ({"labels": "true"}, "labels: must be True or False"),
    ({"colour": 1}, "colour: unknown sensor field"),
]


@pytest.mark.parametrize(("overrides", "message"), BAD_CONFIGS, ids=lambda v: str(v)[:40])
def test_bad_configs_name_the_field_and_its_range(overrides: dict[str, Any], message: str) -> None:
    with pytest.raises(ValueError) as raised:
        SensorConfig.from_dict(overrides)
    assert message in str(raised.value)


def test_the_core_refuses_what_the_config_refuses() -> None:
    """The Rust core checks the same ranges when it is given parameters directly."""
    params = SensorConfig().core_params()
    for field, value in [("theta_on", 1e-300), ("shot_rate_hz", 1e300), ("latency_us", 1e300)]:
        with pytest.raises(ValueError, match=f"^{field}: must be in"):
            pecs._core.EventSensor({**params, field: value})


def test_every_range_takes_its_ends() -> None:
    ends = {
        "theta_on": (0.01, 10.0),
        "theta_min": (0.01, 0.2),
        "theta_sigma": (0.0, 1.0),
        "refractory_us": (0.0, 1e6),
        "cutoff_hz": (1e-3, 1e6),
        "cutoff_half_photocurrent": (0.0, 1e3),
        "dark_current": (1e-6, 1e3),
        "lin_log_knee": (1e-6, 1e3),
        "latency_us": (0.0, 1e6),
        "leak_rate_hz": (0.0, 1e6),
        "leak_spread_decades": (0.0, 2.0),
        "shot_rate_hz": (0.0, 1e6),
        "hot_pixel_fraction": (0.0, 1.0),
        "hot_pixel_rate_hz": (0.0, 1e6),
    }
    for field, values in ends.items():
        for value in values:
            assert getattr(SensorConfig(**{field: value}), field) == value


def test_numpy_scalars_are_taken_as_python_numbers() -> None:
    config = SensorConfig(
        width=np.int64(346),
        height=np.uint16(260),
        theta_on=np.float32(0.3),
        refractory_us=np.int32(500),
        labels=np.bool_(True),
        seed=np.uint64(7),
        lin_log_knee=np.float64(0.01),
    )
    python = SensorConfig(
        width=346,
        height=260,
        theta_on=float(np.float32(0.3)),
        refractory_us=500,
        labels=True,
        seed=7,
        lin_log_knee=0.01,
    )
    assert config == python
    assert config.to_json() == python.to_json()
    assert type(config.width) is int and type(config.theta_on) is float


def test_a_zero_knee_is_a_pure_log_response_as_its_message_says() -> None:
    zero, unset = SensorConfig(lin_log_knee=0.0), SensorConfig(lin_log_knee=None)
    frames = np.array([[[0.0]], [[0.5]]], np.float32)
    config = {"width": 1, "height": 1}
    a = pecs.frames_to_events(frames, [0, 10], zero.replace(**config))
    b = pecs.frames_to_events(frames, [0, 10], unset.replace(**config))
    assert a.num_rows == b.num_rows == 31  # ln(0.501 / 0.001) / 0.2 = 31.08


# ---------------------------------------------------------------- frames and times fed


def _sensor() -> pecs.EventSensor:
    sensor = pecs.EventSensor(SensorConfig(width=4, height=3))
    sensor.feed(np.full((3, 4), 0.5, np.float32), 0)
    return sensor


def _with(value: float) -> np.ndarray:
    frame = np.full((3, 4), 0.5, np.float32)
    frame[1, 2] = value
    return frame


BAD_FEEDS: list[tuple[Any, Any, type[Exception], str]] = [
    (_with(np.nan), 10, ValueError, "non-finite value (NaN) at x=2, y=1"),
    (_with(np.inf), 10, ValueError, "non-finite value (inf) at x=2, y=1"),
    (_with(-np.inf), 10, ValueError, "non-finite value (-inf) at x=2, y=1"),
    (_with(-0.5), 10, ValueError, "negative photocurrent (-0.5) at x=2, y=1"),
    (np.full((4, 3), 0.5), 10, ValueError, "does not match the sensor's (height, width)"),
    (np.full((3, 4, 3), 0.5), 10, ValueError, "does not match the sensor's"),
    (np.full(12, 0.5), 10, ValueError, "does not match the sensor's"),
    (np.zeros((0, 4)), 10, ValueError, "frame is empty"),
    (np.full((3, 4), 1, np.int32), 10, ValueError, "frame dtype is int32"),
    (np.full((3, 4), 0.5, np.float16), 10, ValueError, "frame dtype is float16"),
    (np.full((3, 4), 1 + 1j), 10, ValueError, "frame dtype is complex128"),
    ([[0.5] * 4] * 3, 10, ValueError, "frame must be a numpy array"),
    (np.full((3, 4), 0.5), 0, ValueError, "t_us must increase from frame to frame: got 0 after 0"),
    (np.full((3, 4), 0.5), -5, ValueError, "t_us must increase"),
    (np.full((3, 4), 0.5), 10.5, ValueError, "whole number of microseconds, got 10.5"),
    (np.full((3, 4), 0.5), float("nan"), ValueError, "whole number of microseconds, got nan"),
    (np.full((3, 4), 0.5), "10", ValueError, "integer number of microseconds"),
    (np.full((3, 4), 0.5), True, ValueError, "integer number of microseconds"),
    (np.full((3, 4), 0.5), 2**53 + 1, ValueError, "within +-2^53 us"),
    (np.full((3, 4), 0.5), 2**62, ValueError, "within +-2^53 us"),
    (np.full((3, 4), 0.5), 2**70, ValueError, "within +-2^53 us"),
    (np.full((3, 4), 0.5), np.uint64(2**63 + 5), ValueError, "within +-2^53 us"),
]


@pytest.mark.parametrize(("frame", "t_us", "error", "message"), BAD_FEEDS, ids=str)
def test_bad_frames_and_times_raise_and_leave_the_sensor_unchanged(
    frame: Any, t_us: Any, error: type[Exception], message: str
) -> None:
    sensor = _sensor()
    with warnings.catch_warnings():
        warnings.simplefilter("error")
        with pytest.raises(error) as raised:
            sensor.feed(frame, t_us)
    assert message in str(raised.value)
    assert sensor.last_time_us == 0
    # ln(1.001 / 0.501) / 0.2 = 3.46: three events a pixel, as from a sensor never refused.
    assert sensor.feed(np.full((3, 4), 1.0, np.float32), 10).num_rows == 12 * 3


def srgb_decode(code: int, bits: int) -> float:
    """IEC 61966-2-1, written out here."""
    v = code / (2**bits - 1)
    return v / 12.92 if v <= 0.04045 else ((v + 0.055) / 1.055) ** 2.4


@pytest.mark.parametrize(("dtype", "code", "bits"), [("u1", 128, 8), ("<u2", 40000, 16)])
def test_8_and_16_bit_frames_are_decoded_like_image_files(dtype: str, code: int, bits: int) -> None:
    level = srgb_decode(code, bits)
    # The number of events from dark to the decoded level: floor(ln((L + eps) / eps) / theta).
    expected = 12 * int(np.log((level + 1e-3) / 1e-3) / 0.2)
    for order in ("<", ">"):
        sensor = pecs.EventSensor(SensorConfig(width=4, height=3))
        sensor.feed(np.zeros((3, 4), np.uint8), 0)
        image = np.full((3, 4), code, np.dtype(dtype).newbyteorder(order))
        assert sensor.feed(image, 100).num_rows == expected


def test_8_bit_npy_frames_are_decoded_like_image_files(tmp_path: Any) -> None:
    array = np.full((2, 3, 4), 128, np.uint8)
    np.save(tmp_path / "frames.npy", array)
    frames = [f for _, f in open_frames(tmp_path / "frames.npy", fps=10)]
    np.testing.assert_allclose(frames[0], srgb_decode(128, 8), rtol=1e-6)
    linear = [f for _, f in open_frames(tmp_path / "frames.npy", fps=10, encoding="linear")]
    np.testing.assert_allclose(linear[1], 128 / 255, rtol=1e-6)
    np.save(tmp_path / "ints.npy", array.astype(np.int32))
    with pytest.raises(ValueError, match="frames of dtype int32"):
        open_frames(tmp_path / "ints.npy", fps=10)


# ---------------------------------------------------------------- sequences of times

F = np.full((3, 2, 2), 0.5, np.float32)

BAD_TIMES: list[tuple[Any, str]] = [
    ([0, 10, 10], "timestamps must increase: t_us[2] = 10 follows 10"),
    ([0, 10, 5], "t_us[2] = 5 follows 10"),
    (np.array([0.0, 0.033, 0.066]), "t_us[1] = 0.033 is not a whole number of microseconds; "),
    (np.array([0.0, 0.033, 0.066]), "look like seconds: give their unit as s"),
    (np.array([0.0, 10.5, 20.0]), "t_us[1] = 10.5 is not a whole number of microseconds"),
    (np.array([0.0, np.nan, 20.0]), "t_us[1] is nan; times must be finite"),
    (np.array([0.0, np.inf, 20.0]), "t_us[1] is inf; times must be finite"),
    (np.array([0.0, 10.0, 1e300]), "t_us[2] = 1e+300 is out of range"),
    (np.array([0, 10, 2**62]), "t_us[2] = 4611686018427387904 is out of range"),
    (np.array([[0, 10, 20]]), "1-D sequence of times, got shape (1, 3)"),
    (np.array(["0", "1", "2"]), "must be numbers of us, got dtype <U1"),
    (np.array([True, False, True]), "must be numbers of us, got dtype bool"),
]


@pytest.mark.parametrize(("times", "message"), BAD_TIMES, ids=str)
def test_bad_time_sequences_name_the_first_bad_value(times: Any, message: str) -> None:
    with warnings.catch_warnings():
        warnings.simplefilter("error")  # a numpy warning must not leak out of the checks
        with pytest.raises(ValueError) as raised:
            pecs.frames_to_events(F, times, SensorConfig(width=2, height=2))
    assert message in str(raised.value)


@pytest.mark.parametrize(
    "times", [[0, 10, 20], np.array([0.0, 10.0, 20.0]), np.array([0, 10, 20], np.uint16)]
)
def test_whole_number_times_of_any_numeric_dtype_are_taken(times: Any) -> None:
    frames = np.array([np.full((2, 2), v, np.float32) for v in (0.5, 1.0, 0.5)])
    table = pecs.frames_to_events(frames, times, SensorConfig(width=2, height=2))
    # ln(1.001 / 0.501) / 0.2 = 3.46: 3 ON events a pixel up, 3 OFF down (reference at +0.6).
    assert table.num_rows == 4 * 6
    assert set(table.column("t").to_pylist()) <= set(range(1, 21))


TIMESTAMP_FILES: list[tuple[str, str, str]] = [
    ("0\n0.033\n0.066\n", "us", "line 2 = 0.033 is not a whole number of microseconds"),
    ("0\n0.033\n0.066\n", "us", "look like seconds: give their unit as s"),
    ("0\n1e-7\n2e-7\n", "s", "line 2 = 1e-07 follows 0.0 at the same microsecond"),
    ("0\nnan\n2\n", "us", "line 2 is nan; times must be finite"),
    ("0\n1e20\n", "s", "line 2 = 1e+20 is out of range"),
]


@pytest.mark.parametrize(("text", "unit", "message"), TIMESTAMP_FILES, ids=str)
def test_timestamp_files_name_the_cause(tmp_path: Any, text: str, unit: str, message: str) -> None:
    np.save(tmp_path / "frames.npy", np.zeros((3, 2, 2), np.float32))
    (tmp_path / "t.txt").write_text(text)
    with warnings.catch_warnings():
        warnings.simplefilter("error")
        with pytest.raises(ValueError) as raised:
            open_frames(tmp_path / "frames.npy", timestamps=tmp_path / "t.txt", timestamp_unit=unit)
    assert message in str(raised.value)


def test_timestamp_arrays_of_whole_float_microseconds_are_taken(tmp_path: Any) -> None:
    np.save(tmp_path / "frames.npy", np.zeros((3, 2, 2), np.float32))
    stamps = np.array([0.0, 33333.0, 66667.0])
    source = open_frames(tmp_path / "frames.npy", timestamps=stamps)
    assert [t for t, _ in source] == [0, 33333, 66667]
    with pytest.raises(ValueError, match=r"timestamps\[1\] = 33333.5 is not a whole number"):
        open_frames(tmp_path / "frames.npy", timestamps=stamps + [0, 0.5, 0])


@pytest.mark.parametrize(
    ("fps", "message"),
    [
        (3e9, "fps: 3e+09 frames per second puts frames 0.000333 us apart"),
        (1e6 + 1, "fps must be at most 1e+06"),
        (0, "fps: must be > 0"),
        (-1.0, "fps: must be > 0"),
        (float("nan"), "fps: must be > 0"),
        ("30", "fps: must be a number"),
    ],
)
def test_frame_rates_pecs_cannot_time_are_refused(tmp_path: Any, fps: Any, message: str) -> None:
    np.save(tmp_path / "frames.npy", np.zeros((3, 2, 2), np.float32))
    with pytest.raises(ValueError) as raised:
        open_frames(tmp_path / "frames.npy", fps=fps)
    assert message in str(raised.value)


def test_the_fastest_frame_rate_gives_increasing_whole_microseconds(tmp_path: Any) -> None:
    np.save(tmp_path / "frames.npy", np.zeros((5, 2, 2), np.float32))
    times = [t for t, _ in open_frames(tmp_path / "frames.npy", fps=np.float32(1e6))]
    assert times == [0, 1, 2, 3, 4]
