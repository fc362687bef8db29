"""Sony IMX636 (Prophesee EVK4) biases mapped to the pixel model's parameters.

The IMX636 biases are DAC offsets from the sensor's defaults (0 = default), in the ranges of
OpenEB's `imx636_bias_settings.h`. No bias -> threshold, bandwidth or refractory relation is
published for this sensor, so the mapping here is fitted to what has been measured and anchored to
the `imx636` preset at the defaults (every offset 0 gives the preset's values); sources and
uncertainty in docs/biases.md:

- thresholds: a DAC step multiplies a bias current by a constant ratio [assumed: subthreshold
  current], so theta = (C2/C1) ln(I_diff_on / I_diff) grows linearly with the code distance:
  theta_on = theta_on0 (1 + (diff_on - diff) / D), theta_off = theta_off0 (1 + (diff_off +
  diff) / D). D = 42 steps is fitted to an EVK4's measured ON thresholds at offsets 0, -10, -20,
  -30 (elerac/EventEllipsometer) and taken for OFF too (no OFF measurement). Below about -40
  steps the law puts a threshold at zero: such settings are refused, not extrapolated.
- refractory period: an EVK4's measured dead time against bias_refr (elerac/EventEllipsometer
  calib/refractory_period/table.py, 52 us at the default), scaled to the preset's 100 us.
- bandwidth: bias_fo's current times the per-step ratio that measurement shows near the default
  (1.03-1.05 per step) [assumed to hold for bias_fo]: cutoff = cutoff0 x ratio^fo.
- bias_hpf: the model has no high-pass stage; reported as unmapped.

Directions (Prophesee's bias documentation): a larger diff_on / diff_off offset, a higher ON /
OFF threshold; a larger fo, a faster front end; a larger refr, a shorter dead time (as
measured).
"""

from __future__ import annotations

import math
from collections.abc import Mapping
from typing import Any

from pecs.biases._mapping import BiasMapping, Estimate

#: Offset ranges (OpenEB hal_psee_plugins/include/devices/imx636/imx636_bias_settings.h).
IMX636_RANGES: dict[str, tuple[int, int]] = {
    "bias_diff_on": (-85, 140),
    "bias_diff_off": (-35, 190),
    "bias_diff": (-25, 23),
    "bias_fo": (-35, 55),
    "bias_hpf": (0, 120),
    "bias_refr": (-20, 235),
}
IMX636_DEFAULTS: dict[str, int] = dict.fromkeys(IMX636_RANGES, 0)

#: An EVK4's mean ON threshold against bias_diff_on (= bias_diff_off) offset, measured by
#: ramps (elerac/EventEllipsometer, its threshold table).
MEASURED_THETA_ON = ((0, 0.27), (-10, 0.18), (-20, 0.15), (-30, 0.08))
#: Absolute default codes [secondary source: Prophesee's defaults as quoted]: diff_on 115, diff 80,
#: diff_off 52; their distances from diff, 35 and 28 steps, bound D from below (a D of 28 would
#: put the OFF threshold at zero inside OpenEB's diff_off range, so 28 is not taken as D_off).
DEFAULT_CODE_DISTANCE_ON, DEFAULT_CODE_DISTANCE_OFF = 35.0, 28.0
#: An EVK4's measured refractory period (us) against bias_refr, at the knots of its table
#: (elerac/EventEllipsometer calib/refractory_period/table.py; other biases diff 0, diff_on and
#: diff_off -35, fo 55, hpf 0). Interpolated linearly in log between knots.
MEASURED_REFRACTORY_US = (
    (-20, 364.0), (-19, 271.0), (-18, 216.0), (-17, 181.0), (-16, 157.0), (-15, 138.0),
    (-12, 102.0), (-10, 87.0), (-5, 65.0), (0, 52.0), (5, 44.0), (10, 38.0), (15, 33.0),
    (20, 30.0), (30, 25.0), (40, 22.0), (50, 19.0), (60, 18.0), (80, 15.0), (100, 14.0),
    (120, 12.0), (140, 12.0), (172, 11.0), (200, 10.0), (235, 9.0),
)  # fmt: skip

# Ranges, as factors on the value at the defaults (docs/biases.md):
#: ON threshold at the defaults: the preset's 0.3 (PECS paper) against the measured 0.27.
THETA_ON_FACTORS = (0.9, 1.1)
#: OFF threshold at the defaults: the measurement above takes OFF as 1.8x ON, 0.49 (x1.62).
THETA_OFF_FACTORS = (0.9, 1.65)
#: D between the default-code distances (35 ON, 28 x 42/35 = 33.6 OFF) and as far above the fit.
D_ON_RANGE = (DEFAULT_CODE_DISTANCE_ON, 49.0)
D_OFF_RANGE = (DEFAULT_CODE_DISTANCE_OFF * 42.0 / DEFAULT_CODE_DISTANCE_ON, 49.0)
#: The preset's 100 us against the measured 52 us at the defaults; 1.5 [assumed].
REFRACTORY_FACTORS = (0.52, 1.5)
#: Bandwidth at the defaults: the PECS paper's tau 300 us fitted per scene; x0.5-2 [assumed].
CUTOFF_FACTORS = (0.5, 2.0)


def fitted_d() -> float:
    """D: least squares of theta(x) / theta(0) = 1 + x / D over the measured ON thresholds,
    for u = 1 / D: u = sum x (r - 1) / sum x^2 (42.0 for the table above)."""
    theta0 = MEASURED_THETA_ON[0][1]
    num = sum(x * (theta / theta0 - 1.0) for x, theta in MEASURED_THETA_ON)
    den = sum(x * x for x, _ in MEASURED_THETA_ON)
    return den / num


def measured_refractory_us(refr: float) -> float:
    """The measured EVK4 refractory period at a bias_refr offset, log-linearly interpolated."""
    knots = MEASURED_REFRACTORY_US
    for (x0, t0), (x1, t1) in zip(knots, knots[1:]):
        if x0 <= refr <= x1:
            w = (refr - x0) / (x1 - x0)
            return math.exp((1 - w) * math.log(t0) + w * math.log(t1))
    raise ValueError(f"bias_refr {refr} is out of range {knots[0][0]}..{knots[-1][0]}")


def fo_step_ratios() -> tuple[float, float, float]:
    """Current ratio per DAC step near the default, from the refractory measurement (T ~ 1/I):
    (low: 0 to +10, value: -10 to +10, high: -10 to 0)."""
    t = measured_refractory_us
    return (
        (t(0) / t(10)) ** 0.1,
        (t(-10) / t(10)) ** 0.05,
        (t(-10) / t(0)) ** 0.1,
    )


def imx636_biases(biases: Mapping[str, Any]) -> dict[str, int]:
    """The defaults (every offset 0) with the given offsets over them, each checked."""
    merged = dict(IMX636_DEFAULTS)
    for name, value in biases.items():
        if name not in IMX636_RANGES:
            known = ", ".join(IMX636_RANGES)
            raise ValueError(f"{name}: not an IMX636 bias; biases: {known}")
        low, high = IMX636_RANGES[name]
        if isinstance(value, bool) or not isinstance(value, int):
            raise ValueError(
                f"{name}: {value!r} is not a whole number (an offset in {low}..{high})"
            )
        if not low <= value <= high:
            raise ValueError(f"{name}: {value} is out of its range {low}..{high}")
        merged[name] = value
    return merged


def imx636_mapping(biases: Mapping[str, Any]) -> BiasMapping:
    """IMX636 bias offsets ({"bias_diff_on": 20, ...}; the rest 0) mapped to theta_on, theta_off,
    cutoff_hz and refractory_us, each with its range; bias_hpf reported as unmapped."""
    from pecs.config import SensorConfig

    preset = SensorConfig.preset("imx636")
    b = imx636_biases(biases)
    d = fitted_d()
    on_steps = b["bias_diff_on"] - b["bias_diff"]
    off_steps = b["bias_diff_off"] + b["bias_diff"]
    parameters = {
        "theta_on": _threshold(
            "ON", "bias_diff_on - bias_diff", on_steps, preset.theta_on, d,
            THETA_ON_FACTORS, D_ON_RANGE,
        ),
        "theta_off": _threshold(
            "OFF", "bias_diff_off + bias_diff", off_steps, preset.theta_off, d,
            THETA_OFF_FACTORS, D_OFF_RANGE,
        ),
        "cutoff_hz": _cutoff(b["bias_fo"], preset.cutoff_hz),
        "refractory_us": _refractory(b["bias_refr"], preset.refractory_us),
    }  # fmt: skip
    return BiasMapping("imx636", b, parameters, _unmapped(b["bias_hpf"]))


def _threshold(
    polarity: str,
    steps_name: str,
    steps: int,
    theta0: float,
    d: float,
    factors: tuple[float, float],
    d_range: tuple[float, float],
) -> Estimate:
    value = theta0 * (1.0 + steps / d)
    if value < 0.01:
        limit = math.ceil(d * (0.01 / theta0 - 1.0))
        raise ValueError(
            f"{steps_name} = {steps} maps to an {polarity} threshold below 0.01 (the pixel would "
            f"fire on noise); the mapping holds for {steps_name} >= {limit}"
        )
    corners = [theta0 * f * (1.0 + steps / dd) for f in factors for dd in d_range]
    corners.append(value)
    relation = f"theta0 (1 + ({steps_name}) / D), theta0 = {theta0:g}, D = {d:.3g} steps"
    set_by = steps_name.replace(" - ", ", ").replace(" + ", ", ")
    return Estimate(value, max(min(corners), 0.0), max(corners), relation, set_by)


def _cutoff(fo: int, cutoff0_hz: float) -> Estimate:
    low_r, r, high_r = fo_step_ratios()
    value = cutoff0_hz * r**fo
    corners = [cutoff0_hz * f * rr**fo for f in CUTOFF_FACTORS for rr in (low_r, high_r)]
    relation = f"cutoff0 x {r:.3g}^bias_fo, cutoff0 = {cutoff0_hz:.3g} Hz [ratio assumed]"
    return Estimate(value, min(corners + [value]), max(corners + [value]), relation, "bias_fo")


def _refractory(refr: int, refractory0_us: float) -> Estimate:
    value = refractory0_us * measured_refractory_us(refr) / measured_refractory_us(0)
    low, high = value * REFRACTORY_FACTORS[0], value * REFRACTORY_FACTORS[1]
    relation = f"{refractory0_us:g} us x T_measured(bias_refr) / T_measured(0), an EVK4's table"
    return Estimate(value, low, high, relation, "bias_refr")


def _unmapped(hpf: int) -> dict[str, str]:
    effect = (
        "at 0, the chip's high-pass is at its lowest"
        if hpf == 0
        else f"at {hpf}, the fewer events from slow light changes are not simulated"
    )
    return {"bias_hpf": f"the model has no high-pass stage (no SensorConfig field); {effect}"}
