"""Background activity from a static-scene recording alone (`pecs.calibrate_noise`): for users
with events but no APS frames.

The laws fitted are those of the pixel model (docs/pixel-model.md, section 6), with the light constant:
- leak: ON events only, pixel i at rate r_i, log-normal over pixels (mean `leak_rate_hz`,
  standard deviation of log10 r_i `leak_spread_decades`);
- shot noise: Poisson events of random polarity at the scene's rate s (the law
  `shot_rate_hz * I_dark / (I + I_dark)` gives one rate for one light level), each one
  resetting the pixel, which restarts its leak drift: a leak event then needs 1/r_i seconds
  without a shot event, so a pixel's observed leak rate is the renewal rate
  l(r_i) = s / (exp(s / r_i) - 1) (-> r_i when s << r_i);
- hot pixels: a fraction firing at a high rate, both polarities.

Estimators, per-pixel ON and OFF counts over the recording's duration T:
1. hot pixels are the outliers: more than `min_hot_events` events and a rate above
   `hot_factor` times the 90th percentile of pixel rates (so the fraction must stay under 10 %;
   with a leak spread of 0.3 decades an ordinary pixel is 4.6 sigma from that bar);
   their rate is their mean rate less the other pixels' mean;
2. the other pixels' OFF events are half the shot noise: s = 2 mean(OFF) / T;
3. the leak law's two parameters match the ON counts' first two moments over pixels, mean
   T (s / 2 + E[l(r)]) and between-pixel variance T^2 Var[l(r)] (the count variance less its
   Poisson part, the mean), the expectations over the log-normal by Gauss-Hermite quadrature.

What it cannot separate: the leak's dark part from its light part (`leak_light_rate_hz`: one
scene gives one rate, fitted as `leak_rate_hz` with no light part); the shot-noise law's dark
rate from the light (one scene gives one
rate; `photocurrent` (the scene's frame value, at the configuration's `white_lux`) and its dark
current convert it, else the scene is taken as dark and `shot_rate_hz` is the scene's rate); the leak spread from Poisson scatter when
pixels see few leak events (T r << 10: the spread is then unreliable, and zero when the counts
scatter no more than Poisson); hot pixels slower than `hot_factor` times the ordinary ones
from the leak's log-normal tail; anything about thresholds, bandwidth or dark current.
"""

from __future__ import annotations

import math
from dataclasses import dataclass, field
from typing import Any

import numpy as np

from pecs.calibration.realism import count_map
from pecs.config import REFERENCE_WHITE_LUX, SensorConfig
from pecs.events import sensor_size as schema_sensor_size
from pecs.io import to_table

__all__ = ["NoiseFit", "calibrate_noise", "dark_shot_rate_hz"]

# Gauss-Hermite nodes for expectations over a standard normal (E f(z) = sum w f(sqrt2 x) / sqrtpi).
_NODES, _WEIGHTS = np.polynomial.hermite.hermgauss(40)


@dataclass
class NoiseFit:
    """Fitted background activity (rates in events per pixel per second)."""

    leak_rate_hz: float
    leak_spread_decades: float
    #: The shot-noise rate in this scene, and the law's rate in the dark it corresponds to.
    scene_shot_rate_hz: float
    shot_rate_hz: float
    hot_pixel_fraction: float
    hot_pixel_rate_hz: float
    #: The shot law's exponent n that `shot_rate_hz` is the dark rate of.
    shot_light_exponent: float
    duration_s: float
    pixels: int
    hot_pixels: np.ndarray = field(repr=False)

    def config(self, base: SensorConfig | None = None) -> SensorConfig:
        """`base` (default: SensorConfig()) with the fitted background activity."""
        return (base or SensorConfig()).replace(
            leak_rate_hz=self.leak_rate_hz,
            leak_light_rate_hz=0.0,  # one light level: the whole leak rate is fitted at it
            leak_spread_decades=self.leak_spread_decades,
            shot_rate_hz=self.shot_rate_hz,
            shot_light_exponent=self.shot_light_exponent,
            hot_pixel_fraction=self.hot_pixel_fraction,
            hot_pixel_rate_hz=self.hot_pixel_rate_hz,
        )


def calibrate_noise(
    events: Any,
    *,
    sensor_size: tuple[int, int] | None = None,
    window_us: tuple[int, int] | None = None,
    photocurrent: float | None = None,
    dark_current: float | None = None,
    white_lux: float | None = None,
    shot_light_exponent: float | None = None,
    hot_factor: float = 10.0,
    min_hot_events: int = 5,
) -> NoiseFit:
    """Fit leak, shot-noise and hot-pixel parameters to the events of a static scene (module
    docstring). `events`: a table, structured array or event file; `sensor_size` (width,
    height) defaults to the file's; `window_us` to the events' span. `photocurrent` (the
    scene's frame value, as frames2events would be fed it) with `white_lux`, `dark_current` and
    `shot_light_exponent` (defaults: SensorConfig's) converts the scene's shot rate to the law's
    dark rate.
    """
    table = to_table(events)
    width, height = _size(table, sensor_size)
    t = table.column("t").to_numpy().astype(np.int64)
    if len(t) < 2:
        raise ValueError("calibrate_noise: needs at least 2 events")
    start, end = window_us if window_us is not None else _span_us(t)
    keep = (t >= start) & (t < end)
    x, y = (table.column(n).to_numpy()[keep] for n in ("x", "y"))
    on = table.column("p").to_numpy()[keep].astype(bool)
    duration_s = (end - start) * 1e-6
    on_counts = count_map(x[on], y[on], width, height).ravel().astype(np.float64)
    off_counts = count_map(x[~on], y[~on], width, height).ravel().astype(np.float64)
    hot = _hot_pixels(on_counts + off_counts, hot_factor, min_hot_events)
    normal_on, normal_off = on_counts[~hot], off_counts[~hot]
    scene_shot_hz = 2.0 * normal_off.mean() / duration_s
    leak_hz, spread = _leak_law(normal_on, scene_shot_hz, duration_s)
    normal_rate_hz = (normal_on.mean() + normal_off.mean()) / duration_s
    hot_rate_hz = (
        float((on_counts + off_counts)[hot].mean()) / duration_s - normal_rate_hz
        if hot.any()
        else 0.0
    )
    defaults = SensorConfig()
    dark = dark_current if dark_current is not None else defaults.dark_current
    lux = white_lux if white_lux is not None else defaults.white_lux
    n = shot_light_exponent if shot_light_exponent is not None else defaults.shot_light_exponent
    return NoiseFit(
        leak_rate_hz=float(leak_hz),
        leak_spread_decades=float(spread),
        scene_shot_rate_hz=float(scene_shot_hz),
        shot_rate_hz=float(dark_shot_rate_hz(scene_shot_hz, photocurrent, dark, lux, n)),
        hot_pixel_fraction=float(hot.mean()),
        hot_pixel_rate_hz=float(max(hot_rate_hz, 0.0)),
        shot_light_exponent=float(n),
        duration_s=duration_s,
        pixels=width * height,
        hot_pixels=hot.reshape(height, width),
    )


def dark_shot_rate_hz(
    scene_rate_hz: float,
    photocurrent: float | None,
    dark_current: float,
    white_lux: float = REFERENCE_WHITE_LUX,
    shot_light_exponent: float = 1.0,
) -> float:
    """Invert the shot law r = shot_rate_hz (I_dark / (I + I_dark))^n at the scene's light
    (docs/pixel-model.md, section 6), I = photocurrent * white_lux / 1000 (a frame value at the stated
    light; config.py), n = shot_light_exponent; without the light the scene is taken as dark
    (I = 0)."""
    if photocurrent is None:
        return scene_rate_hz
    if shot_light_exponent not in (1, 2):
        raise ValueError(
            f"calibrate_noise: shot_light_exponent must be 1 or 2, got {shot_light_exponent}"
        )
    if not (0 <= photocurrent < np.inf and 0 < dark_current < np.inf and 0 < white_lux < np.inf):
        raise ValueError(
            "calibrate_noise: needs finite photocurrent >= 0, dark_current > 0 and white_lux > 0, "
            f"got {photocurrent}, {dark_current}, {white_lux}"
        )
    signal = photocurrent * white_lux / REFERENCE_WHITE_LUX
    return scene_rate_hz * ((signal + dark_current) / dark_current) ** shot_light_exponent


def _size(table: Any, given: tuple[int, int] | None) -> tuple[int, int]:
    size = given or schema_sensor_size(table.schema)
    if size is None:
        raise ValueError("calibrate_noise: pass sensor_size=(width, height); the events do not say")
    return int(size[0]), int(size[1])


def _span_us(t: np.ndarray) -> tuple[int, int]:
    """The events' span, widened by one mean interval so that the last event is inside and
    n events cover n intervals (the unbiased length of a Poisson stream's window)."""
    first, last = int(t.min()), int(t.max())
    return first, last + max((last - first) // max(len(t) - 1, 1), 1)


def _hot_pixels(counts: np.ndarray, hot_factor: float, min_hot_events: int) -> np.ndarray:
    ordinary = float(np.percentile(counts, 90))
    return (counts >= min_hot_events) & (counts > hot_factor * ordinary)


def _renewal_leak_hz(rate_hz: np.ndarray, shot_hz: float) -> np.ndarray:
    """Observed leak rate of a pixel with leak rate r when shot events (rate s) reset it:
    s / (exp(s / r) - 1), r itself when s = 0."""
    if shot_hz <= 0:
        return rate_hz
    return shot_hz / np.expm1(np.minimum(shot_hz / rate_hz, 700.0))


def _leak_moments(mean_hz: float, spread: float, shot_hz: float) -> tuple[float, float]:
    """Mean and variance over pixels of the observed leak rate, for the log-normal law."""
    sigma = spread * math.log(10.0)
    z = math.sqrt(2.0) * _NODES
    rates = mean_hz * np.exp(sigma * z - sigma**2 / 2.0)
    observed = _renewal_leak_hz(rates, shot_hz)
    weights = _WEIGHTS / math.sqrt(math.pi)
    mean = float(np.dot(weights, observed))
    return mean, float(np.dot(weights, (observed - mean) ** 2))


def _leak_law(on_counts: np.ndarray, shot_hz: float, duration_s: float) -> tuple[float, float]:
    """(leak_rate_hz, leak_spread_decades) whose observed-leak moments match the ON counts'."""
    target_mean = on_counts.mean() / duration_s - shot_hz / 2.0
    target_var = max(on_counts.var() - on_counts.mean(), 0.0) / duration_s**2
    if target_mean <= 0:
        return 0.0, 0.0

    def mean_for(spread: float) -> float:  # the leak mean whose observed mean is the target
        return _bisect(lambda m: _leak_moments(m, spread, shot_hz)[0] - target_mean, 1e-9, 1e6)

    def variance_gap(spread: float) -> float:
        return _leak_moments(mean_for(spread), spread, shot_hz)[1] - target_var

    if variance_gap(0.0) >= 0:
        return mean_for(0.0), 0.0
    spread = _bisect(variance_gap, 0.0, 3.0) if variance_gap(3.0) > 0 else 3.0
    return mean_for(spread), spread


def _bisect(function: Any, low: float, high: float) -> float:
    """A root of an increasing function on [low, high] (geometric steps when low > 0)."""
    for _ in range(60):
        middle = math.sqrt(low * high) if low > 0 else (low + high) / 2.0
        if function(middle) > 0:
            high = middle
        else:
            low = middle
    return (low + high) / 2.0
