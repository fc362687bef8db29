"""Background activity against measured and documented numbers.

1. The IEBCS-based presets (dvxplorer, imx636: config.py's `_IEBCS_NOISE`) against the points
   they were set from: IEBCS's measured per-pixel inter-event histograms (Joubert et al.,
   Front. Neurosci. 2021, data/noise_{pos,neg}_{lux}.npy; read in
   ../shared/reference/sensor-characterisation.md): dense bipolar noise of 5-8 Hz per pixel at
   0.1 lux, ~0.1 Hz ON on 34 % of pixels (mean 0.034 Hz) at 161 lux and on 95 % (0.095 Hz) at
   3 klux, and (almost) no OFF events in bright light: 5 of 2500 pixels at 161 lux, none at 3 klux.
2. The laws themselves on a generic sensor (not a preset): shot noise r = shot_rate_hz
   (I_dark / x)^n for n = 1 and 2, and leak r = leak_rate_hz + leak_light_rate_hz x, x the total
   photocurrent
   (value * white_lux / 1000 + dark_current; config.py), at three light levels.

Frames are constant 1.0, so the light is `white_lux` itself (0.1 lux = photocurrent 1e-4).

Tolerance for (1): the measured rates are medians of per-pixel instantaneous rates read from
histograms of 70 log-spaced bins over 1 mHz-90 kHz, 0.114 decades each: a rate is known to half
a bin, +-14 %; the simulated mean's own error (Poisson over >= 3000 events, 1.8 %; the leak's
log-normal spread over 4096 pixels, 0.78 / 64 = 1.2 %) adds 3 sigma = 6.5 %: 20 % in all.
"""

from __future__ import annotations

import numpy as np
import pecs
import pytest
from pecs.config import SensorConfig

IEBCS_PRESETS = ("dvxplorer", "imx636")
SIDE = 64  # pixels per side: 4096 pixels


def constant_scene(config: SensorConfig, duration_s: float) -> dict[str, np.ndarray]:
    """Events of constant white frames (value 1.0, so x = white_lux / 1000 + dark) as arrays,
    10 s apart at most (one call may not span a gap whose dark noise would be too many events)."""
    count = int(np.ceil(duration_s / 10.0)) + 1
    frames = np.ones((count, config.height, config.width), np.float32)
    times_us = np.round(np.linspace(0.0, duration_s * 1e6, count)).astype(np.int64)
    events = pecs.frames_to_events(frames, times_us, config)
    return {name: events.column(name).to_numpy() for name in events.column_names}


def per_pixel_hz(mask: np.ndarray, pixels: int, duration_s: float) -> float:
    """Mean rate per pixel of the events `mask` selects."""
    return float(mask.sum()) / pixels / duration_s


def iebcs_scene(name: str, lux: float, duration_s: float) -> tuple[float, float, float]:
    """(mean ON Hz, mean OFF Hz, fraction of pixels with any event) of a preset at `lux`."""
    config = SensorConfig.preset(name, width=SIDE, height=SIDE, white_lux=lux, seed=1)
    events = constant_scene(config, duration_s)
    on = events["p"].astype(bool)
    pixels = SIDE * SIDE
    fired = len(np.unique(events["y"].astype(np.int64) * SIDE + events["x"])) / pixels
    return (
        per_pixel_hz(on, pixels, duration_s),
        per_pixel_hz(~on, pixels, duration_s),
        fired,
    )


@pytest.mark.parametrize("name", IEBCS_PRESETS)
def test_dark_noise_at_0_1_lux_is_dense_bipolar_and_5_to_8_hz(name: str) -> None:
    # 2 s: ~49 k events. Measured: 2499 of 2500 pixels fire; ON 55.4 and OFF 41.7 events per
    # pixel (ON fraction 0.57), median rates 8 Hz ON and 5 Hz OFF; config.py reads the pair
    # as 5-8 Hz of bipolar noise per pixel.
    on_hz, off_hz, fired = iebcs_scene(name, 0.1, 2.0)
    assert 5.0 <= on_hz + off_hz <= 8.0
    assert 0.4 <= on_hz / (on_hz + off_hz) <= 0.6
    assert fired == 1.0


@pytest.mark.parametrize(("lux", "measured_on_hz"), [(161.0, 0.034), (3000.0, 0.095)])
@pytest.mark.parametrize("name", IEBCS_PRESETS)
def test_bright_light_leak_matches_the_measured_on_rate(
    name: str, lux: float, measured_on_hz: float
) -> None:
    on_hz, _, _ = iebcs_scene(name, lux, 20.0)  # >= 3000 ON events
    assert on_hz == pytest.approx(measured_on_hz, rel=0.20)


@pytest.mark.parametrize("name", IEBCS_PRESETS)
@pytest.mark.parametrize("lux", [161.0, 3000.0])
def test_almost_no_off_events_in_light(name: str, lux: float) -> None:
    # Measured: at 161 lux, 5 OFF pixels of 2500 against 850 ON pixels with 1.7 events each
    # (~0.1 % OFF); at 3 klux no OFF event against ~3.6 ON events per pixel. The square law
    # leaves 24 Hz x (1e-4 / x)^2 of OFF: 9e-6 Hz at 161 lux, 1e-8 Hz at 3 klux (1 / x would
    # leave 0.0037 Hz at 161 lux: 9 %).
    on_hz, off_hz, _ = iebcs_scene(name, lux, 20.0)
    assert off_hz < 0.01 * on_hz


# ---- the laws on a generic sensor ------------------------------------------------------------

DARK = 0.01
SHOT_DARK_HZ, LEAK_HZ, LEAK_LIGHT_HZ = 50.0, 0.5, 2.0
GENERIC_SIDE = 32


def generic(**noise: float) -> SensorConfig:
    """An ideal log sensor with one noise source: no spread, so each pixel has the law's rate."""
    return SensorConfig.preset(
        "ideal", width=GENERIC_SIDE, height=GENERIC_SIDE, dark_current=DARK, seed=2, **noise
    )


# white_lux 10, 100, 1000: x = 0.02, 0.11, 1.01
@pytest.mark.parametrize("white_lux", [10.0, 100.0, 1000.0])
@pytest.mark.parametrize("exponent", [1.0, 2.0])
def test_shot_rate_falls_as_a_power_of_dark_over_total_photocurrent(
    white_lux: float, exponent: float
) -> None:
    x = white_lux / 1000.0 + DARK
    # n = 1: 25, 4.5, 0.50 Hz; n = 2 (from 20 times the dark rate): 250, 8.3, 0.098 Hz
    dark_hz = SHOT_DARK_HZ * (1.0 if exponent == 1.0 else 20.0)
    expected_hz = dark_hz * (DARK / x) ** exponent
    duration_s = 20.0 / expected_hz  # ~20 events per pixel: 20 k events, Poisson 0.7 %
    config = generic(shot_rate_hz=dark_hz, shot_light_exponent=exponent)
    config = config.replace(white_lux=white_lux)
    events = constant_scene(config, duration_s)
    pixels = GENERIC_SIDE**2
    on = events["p"].astype(bool)
    assert len(on) / pixels / duration_s == pytest.approx(expected_hz, rel=0.03)  # 4 sigma
    assert on.mean() == pytest.approx(0.5, abs=0.02)  # bipolar


@pytest.mark.parametrize("white_lux", [10.0, 100.0, 1000.0])
def test_leak_rate_rises_linearly_with_total_photocurrent(white_lux: float) -> None:
    x = white_lux / 1000.0 + DARK
    expected_hz = LEAK_HZ + LEAK_LIGHT_HZ * x  # 0.54, 0.72, 2.52 Hz
    duration_s = 20.0 / expected_hz
    config = generic(leak_rate_hz=LEAK_HZ, leak_light_rate_hz=LEAK_LIGHT_HZ)
    events = constant_scene(config.replace(white_lux=white_lux), duration_s)
    pixels = GENERIC_SIDE**2
    assert len(events["p"]) / pixels / duration_s == pytest.approx(expected_hz, rel=0.03)
    assert events["p"].astype(bool).all()  # leak events are ON
