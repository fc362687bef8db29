"""Property-based tests over sensor configurations, frames and times: every input either works
or raises ValueError, never another exception, never a hang, never a crash of the process.

Each example's work is bounded: sensors of at most 8 x 8 pixels, gaps of at most 1 ms (with
rates of at most 1 MHz, a few hundred thousand events), and a deadline per example. CI runs few
examples; PECS_HYPOTHESIS_EXAMPLES=5000 runs more by hand.
"""

from __future__ import annotations

import math
import os
import warnings
from typing import Any

import numpy as np
import pecs
import pytest
from hypothesis import HealthCheck, given, settings
from hypothesis import strategies as st
from pecs import SensorConfig

EXAMPLES = int(os.environ.get("PECS_HYPOTHESIS_EXAMPLES", "40"))
BOUNDED = settings(
    max_examples=EXAMPLES,
    deadline=5000,  # ms; a hang or runaway work fails the example instead of stalling the suite
    suppress_health_check=[HealthCheck.too_slow, HealthCheck.data_too_large],
    derandomize=EXAMPLES <= 40,  # CI: the same examples every run
)

# ---------------------------------------------------------------- strategies

EDGES = [0.0, -0.0, 1e-300, 5e-324, 1e-6, 0.01, 1.0, 10.0, 1e6, 1e300, -1.0, math.nan, math.inf]


def numbers() -> st.SearchStrategy[Any]:
    """Floats anywhere, edges of the ranges, as Python or numpy scalars, and some non-numbers."""
    plain = st.one_of(
        st.sampled_from(EDGES),
        st.floats(allow_nan=True, allow_infinity=True),
        st.floats(0.0, 2.0),
        st.integers(-5, 10**7),
    )
    as_numpy = st.one_of(
        plain.map(lambda v: np.float64(v) if isinstance(v, float) else np.int64(v)),
        st.floats(0.0, 2.0, width=32).map(np.float32),
    )
    wrong = st.sampled_from(["1", None, True, [1.0], b"1"])
    return st.one_of(plain, as_numpy, wrong)


FLOAT_FIELDS = [
    "theta_on",
    "theta_off",
    "theta_sigma",
    "theta_noise",
    "theta_min",
    "refractory_us",
    "cutoff_hz",
    "cutoff_half_photocurrent",
    "dark_current",
    "lin_log_knee",
    "latency_us",
    "jitter_us",
    "leak_rate_hz",
    "leak_spread_decades",
    "shot_rate_hz",
    "hot_pixel_fraction",
    "hot_pixel_rate_hz",
]


# Values inside or at the edges of the ranges, so that most configurations built from them work.
PLAUSIBLE = st.one_of(
    st.sampled_from([0.0, 1e-6, 0.01, 0.2, 1.0, 2.0, 10.0, 1e3, 1e6]),
    st.floats(0.0, 2.0),
    st.floats(0.0, 2.0, width=32).map(np.float32),
)


@st.composite
def configs(draw: st.DrawFn, plausible: bool = False) -> dict[str, Any]:
    """A preset's fields, some overridden by anything (or by plausible values, small sizes and
    valid choices, for tests that go on to feed the sensor); width and height small or wrong."""
    values: dict[str, Any] = {"preset_name": None}
    for field in draw(st.lists(st.sampled_from(FLOAT_FIELDS), max_size=6, unique=True)):
        values[field] = draw(PLAUSIBLE if plausible else numbers())
    side = st.integers(1, 8)
    if not plausible:
        side = st.one_of(side, st.sampled_from([0, -1, 2**70, 3.0, np.int16(4)]))
    values["width"], values["height"] = draw(side), draw(side)
    seeds = st.integers(0, 2**64 - 1)
    values["seed"] = draw(seeds if plausible else st.one_of(seeds, st.sampled_from([-1, 2**64])))
    values["labels"] = draw(st.sampled_from([True, False, np.bool_(True), *[1][plausible:]]))
    resets = ["refractory_end", "event", *["x"][plausible:]]
    values["reference_reset"] = draw(st.sampled_from(resets))
    preset = draw(st.sampled_from(SensorConfig.PRESETS))
    return {"preset": preset, **values}


def build(values: dict[str, Any]) -> SensorConfig | None:
    """The configuration, or None where it was refused with a ValueError."""
    preset = values.pop("preset")
    try:
        return SensorConfig.preset(preset, **values)
    except ValueError:
        return None


FRAME_VALUES = st.one_of(
    st.floats(0.0, 1.0, width=32),
    st.sampled_from([0.0, 1e-30, 3.4e38, -1.0, math.nan, math.inf, 255.0, 65535.0]),
)


@st.composite
def frames_for(draw: st.DrawFn, shape: tuple[int, int]) -> Any:
    """Mostly frames that fit, some of the wrong shape, dtype or type."""
    kind = draw(st.sampled_from(["float", "float", "float", "image", "shape", "dtype", "list"]))
    if kind == "shape":
        shape = (shape[0] + draw(st.integers(-1, 1)), shape[1] + 1)
        if 0 in shape:
            shape = (1, shape[1] + 1)
    values = draw(
        st.lists(FRAME_VALUES, min_size=shape[0] * shape[1], max_size=shape[0] * shape[1])
    )
    array = np.array(values, np.float64).reshape(shape)
    if kind == "image":
        dtype = draw(st.sampled_from(["u1", "<u2", ">u2"]))
        return np.nan_to_num(np.abs(array), posinf=0.0).clip(0, 255).astype(dtype)
    if kind == "dtype":
        dtype = draw(st.sampled_from(["f2", "i4", "i8", "bool", "c8", "u4"]))
        with warnings.catch_warnings():
            warnings.simplefilter("ignore")  # the cast of NaN to int warns; that is the test's
            return array.astype(dtype)
    if kind == "list":
        return array.tolist()
    return array.astype(draw(st.sampled_from(["f4", "f8", ">f4"])))


TIMES = st.one_of(
    st.integers(-(2**63), 2**63 - 1),
    st.integers(0, 1000),
    st.floats(allow_nan=True, allow_infinity=True),
    st.sampled_from([0, 1, 2**53, 2**53 + 1, 2**62, 2**70, -(2**53), np.int64(5), np.float32(7)]),
    st.sampled_from([np.uint64(2**63 + 1), "5", None, True]),
)

# ---------------------------------------------------------------- properties


def only_value_errors(call: Any) -> object | None:
    """Run `call`; a ValueError is an answer, any other exception or warning fails the test."""
    with warnings.catch_warnings():
        warnings.simplefilter("error")
        try:
            return call()
        except ValueError:
            return None


@BOUNDED
@given(values=configs())
def test_any_configuration_is_built_or_refused_with_a_value_error(values: dict[str, Any]) -> None:
    config = only_value_errors(lambda: build(values))
    if config is not None:
        assert config == SensorConfig.from_dict(config.to_dict())  # plain numbers: round trips
        pecs.EventSensor(config)


@BOUNDED
@given(values=configs(plausible=True), data=st.data())
def test_any_frames_fed_at_small_gaps_give_events_or_a_value_error(
    values: dict[str, Any], data: st.DataObject
) -> None:
    config = only_value_errors(lambda: build(values))
    if config is None:
        return
    sensor = pecs.EventSensor(config)
    shape = (config.height, config.width)
    t_us = 0
    for _ in range(3):
        frame = data.draw(frames_for(shape))
        t_us += data.draw(st.integers(-1, 1000))  # at most 1 ms: bounded work
        batch = only_value_errors(lambda f=frame, t=t_us: sensor.feed(f, t))
        if batch is not None:
            t = batch.column("t").to_numpy()
            assert np.all(np.diff(t) >= 0)
            assert np.all(batch.column("x").to_numpy() < config.width)
    only_value_errors(sensor.flush)


@BOUNDED
@given(times=st.lists(TIMES, min_size=1, max_size=4), data=st.data())
def test_any_times_are_taken_in_order_or_refused_with_a_value_error(
    times: list[Any], data: st.DataObject
) -> None:
    config = SensorConfig.preset("davis346", width=3, height=2)
    sensor = pecs.EventSensor(config)
    frame = np.full((2, 3), 0.5, np.float32)
    last = None
    for t in times:
        if only_value_errors(lambda t=t: sensor.feed(frame, t)) is not None:
            assert last is None or sensor.last_time_us > last
            last = sensor.last_time_us
        else:
            assert sensor.last_time_us == last  # a refused call changes nothing


@BOUNDED
@given(
    times=st.one_of(
        st.lists(TIMES, min_size=1, max_size=4),
        st.lists(st.floats(allow_nan=True, allow_infinity=True), min_size=1, max_size=4).map(
            np.array
        ),
        st.lists(st.integers(-(2**63), 2**63 - 1), min_size=1, max_size=4).map(np.array),
    )
)
def test_any_time_sequence_gives_a_table_or_a_value_error(times: Any) -> None:
    frames = np.full((len(times), 2, 2), 0.5, np.float32)
    config = SensorConfig.preset("ideal", width=2, height=2)
    table = only_value_errors(lambda: pecs.frames_to_events(frames, times, config))
    if table is not None:
        assert table.num_rows == 0  # a static scene, no noise


@pytest.mark.parametrize("unit", ["us", "ms", "s"])
@BOUNDED
@given(values=st.lists(st.floats(allow_nan=True, allow_infinity=True), min_size=1, max_size=5))
def test_any_timestamp_array_is_read_or_refused_with_a_value_error(
    unit: str, values: list[float]
) -> None:
    from pecs.footage.frames import times_us

    result = only_value_errors(lambda: times_us(np.array(values), unit, "timestamps"))
    if result is not None:
        assert result.dtype == np.int64 and np.all(np.diff(result) > 0)
