"""Sensor configuration: every parameter of the pixel model, with units in its name, and presets.

Photocurrents (`dark_current`, `lin_log_knee`, `cutoff_half_photocurrent`) are in frame units:
the units of the frames fed to the sensor. The presets assume frames scaled so that 1.0 is a
bright white (images are decoded to linear [0, 1]); rendered photocurrent is scaled likewise.
"""

from __future__ import annotations

import dataclasses
import json
import math
import os
from dataclasses import dataclass, field
from typing import Any, ClassVar

_RESETS = ("refractory_end", "event")


@dataclass(frozen=True)
class SensorConfig:
    """Parameters of a DVS sensor. Build one directly or with `SensorConfig.preset(name, ...)`."""

    width: int = 346
    height: int = 260
    #: ON and OFF contrast thresholds (natural-log units of photocurrent).
    theta_on: float = 0.2
    theta_off: float = 0.2
    #: Frozen per-pixel threshold mismatch: standard deviation across pixels (log units).
    theta_sigma: float = 0.0
    #: Threshold noise redrawn after every event: standard deviation (log units).
    theta_noise: float = 0.0
    #: Smallest threshold any pixel may have (log units).
    theta_min: float = 0.01
    refractory_us: float = 0.0
    #: "refractory_end" (the real circuit: reference memorised when the reset is released) or
    #: "event" (ESIM: reference advanced by the threshold at every crossing).
    reference_reset: str = "refractory_end"
    #: Photoreceptor bandwidth in bright light (Hz); 0 = infinite bandwidth.
    cutoff_hz: float = 0.0
    #: Photocurrent at which the bandwidth halves (frame units); 0 = bandwidth independent of light.
    cutoff_half_photocurrent: float = 0.0
    #: Added to the photocurrent so its log is defined (frame units).
    dark_current: float = 1e-3
    #: Photocurrent below which the response is linear instead of log (frame units); None = pure log.
    lin_log_knee: float | None = None
    latency_us: float = 0.0
    #: Standard deviation of Gaussian timing jitter added to the latency.
    jitter_us: float = 0.0
    #: Mean leak-event rate over pixels; per-pixel rates are log-normal around it.
    leak_rate_hz: float = 0.0
    #: Standard deviation of log10 of the per-pixel leak rate.
    leak_spread_decades: float = 0.0
    #: Shot-noise event rate in the dark; it falls as sqrt(dark_current / (I + dark_current)).
    shot_rate_hz: float = 0.0
    hot_pixel_fraction: float = 0.0
    hot_pixel_rate_hz: float = 0.0
    #: Add the `label` column (0 signal, 1 leak, 2 shot, 3 hot pixel).
    labels: bool = False
    seed: int = 0
    #: The preset this configuration started from, for the record.
    preset_name: str | None = field(default=None, compare=False)

    PRESETS: ClassVar[tuple[str, ...]] = ("ideal", "esim", "davis346", "dvxplorer", "imx636")

    def __post_init__(self) -> None:
        _validate(self)

    @classmethod
    def preset(cls, name: str, **overrides: Any) -> SensorConfig:
        """A named sensor, with any field overridden: `SensorConfig.preset("davis346", seed=3)`."""
        if name not in _PRESETS:
            raise ValueError(
                f"preset: unknown sensor preset {name!r}; choose one of {', '.join(cls.PRESETS)}"
            )
        return cls.from_dict({**_PRESETS[name], "preset_name": name, **overrides})

    @classmethod
    def from_dict(cls, values: dict[str, Any]) -> SensorConfig:
        """A configuration from a plain dict; an unknown key is a ValueError naming it."""
        known = {f.name for f in dataclasses.fields(cls)}
        unknown = sorted(set(values) - known)
        if unknown:
            raise ValueError(
                f"{unknown[0]}: unknown sensor field; known fields: {', '.join(sorted(known))}"
            )
        return cls(**values)

    @classmethod
    def from_file(cls, path: str | os.PathLike[str]) -> SensorConfig:
        """A configuration from a TOML file of `field = value` lines (`pecs.config_file`)."""
        from pecs.config_file import read_config

        return read_config(path)

    def to_file(self, path: str | os.PathLike[str]) -> None:
        """Write the configuration as a TOML file that `from_file` reads back exactly."""
        from pecs.config_file import write_config

        write_config(self, path)

    def replace(self, **overrides: Any) -> SensorConfig:
        return self.from_dict({**self.to_dict(), **overrides})

    def to_dict(self) -> dict[str, Any]:
        return dataclasses.asdict(self)

    def to_json(self) -> str:
        return json.dumps(self.to_dict(), sort_keys=True)

    def core_params(self) -> dict[str, Any]:
        """The parameters as the Rust core takes them."""
        params = self.to_dict()
        params.pop("labels")
        params.pop("preset_name")
        params["lin_log_knee"] = self.lin_log_knee or 0.0
        return params


def _validate(c: SensorConfig) -> None:
    for name in ("width", "height"):
        value = getattr(c, name)
        if isinstance(value, bool) or not isinstance(value, int) or not 1 <= value <= 65536:
            raise ValueError(f"{name}: must be an integer in 1..65536, got {value!r}")
    if isinstance(c.seed, bool) or not isinstance(c.seed, int) or not 0 <= c.seed < 2**64:
        raise ValueError(f"seed: must be an integer in [0, 2**64), got {c.seed!r}")
    if c.reference_reset not in _RESETS:
        raise ValueError(f"reference_reset: must be one of {_RESETS}, got {c.reference_reset!r}")
    if not isinstance(c.labels, bool):
        raise ValueError(f"labels: must be True or False, got {c.labels!r}")
    floats = {f.name for f in dataclasses.fields(c) if f.type in ("float", "float | None")}
    for name in sorted(floats):
        value = getattr(c, name)
        if value is None and name == "lin_log_knee":
            continue
        if (
            isinstance(value, bool)
            or not isinstance(value, (int, float))
            or not math.isfinite(value)
        ):
            raise ValueError(f"{name}: must be a finite number, got {value!r}")
        if value < 0:
            raise ValueError(f"{name}: must be >= 0, got {value!r}")
    if c.theta_min <= 0:
        raise ValueError(f"theta_min: must be > 0, got {c.theta_min!r}")
    for name in ("theta_on", "theta_off"):
        if getattr(c, name) < c.theta_min:
            raise ValueError(
                f"{name}: must be >= theta_min ({c.theta_min}), got {getattr(c, name)!r}"
            )
    if c.lin_log_knee is not None and c.lin_log_knee <= 0:
        raise ValueError(f"lin_log_knee: must be > 0 or None, got {c.lin_log_knee!r}")
    if c.dark_current == 0 and c.lin_log_knee is None:
        raise ValueError(
            "dark_current: must be > 0 (the log of zero photocurrent) unless lin_log_knee is set"
        )
    if c.shot_rate_hz > 0 and c.dark_current == 0:
        raise ValueError("shot_rate_hz: needs dark_current > 0 (its rate law is scaled by it)")
    if c.hot_pixel_fraction > 1:
        raise ValueError(f"hot_pixel_fraction: must be in [0, 1], got {c.hot_pixel_fraction!r}")


def _cutoff_hz(tau_us: float) -> float:
    """First-order cutoff of a time constant: f = 1 / (2 pi tau)."""
    return 1.0 / (2.0 * math.pi * tau_us * 1e-6)


_PRESETS: dict[str, dict[str, Any]] = {
    # A perfect logarithmic sensor: exact thresholds, infinite bandwidth, no noise, no latency.
    "ideal": {},
    # ESIM (Rebecq et al., CoRL 2018): log(I + eps) with eps = 1e-3 for [0, 1] intensities,
    # reference advanced by the threshold at each crossing; thresholds 0.2 as in its frame-input
    # (vid2e) use; no refractory period, bandwidth or noise unless overridden.
    "esim": {"reference_reset": "event", "dark_current": 1e-3},
    # iniVation DAVIS346, 346 x 260, 18.5 um pixels. Thresholds from the datasheet's contrast
    # sensitivity, 14.3 % ON and 22.5 % OFF: ln(1.143) and ln(1.225). Mismatch sigma 0.03,
    # refractory 0.5 ms, 300 Hz bandwidth and leak 0.1 Hz are v2e's defaults for a DAVIS
    # (Hu, Liu, Delbruck, CVPRW 2021); latency 20 us is the datasheet's minimum. The bandwidth
    # half-photocurrent (10 % of white), shot and hot-pixel rates are generic choices inside the
    # 0.01-1 Hz background-activity range of reference/sensor-models.md, not measurements.
    "davis346": {
        "width": 346,
        "height": 260,
        "theta_on": math.log(1.143),
        "theta_off": math.log(1.225),
        "theta_sigma": 0.03,
        "theta_noise": 0.01,
        "refractory_us": 500.0,
        "cutoff_hz": 300.0,
        "cutoff_half_photocurrent": 0.1,
        "latency_us": 20.0,
        "jitter_us": 5.0,
        "leak_rate_hz": 0.1,
        "leak_spread_decades": 0.3,
        "shot_rate_hz": 2.0,
        "hot_pixel_fraction": 1e-4,
        "hot_pixel_rate_hz": 50.0,
    },
    # iniVation DVXplorer, 640 x 480, 9 um pixels. No threshold figure is published in the same
    # form: thresholds 0.2 and mismatch 0.03 are the typical values of sensor-models.md (0.15-0.5,
    # sigma 0.02-0.05), refractory and bandwidth v2e's defaults; noise generic, as for davis346.
    "dvxplorer": {
        "width": 640,
        "height": 480,
        "theta_on": 0.2,
        "theta_off": 0.2,
        "theta_sigma": 0.03,
        "theta_noise": 0.01,
        "refractory_us": 500.0,
        "cutoff_hz": 300.0,
        "cutoff_half_photocurrent": 0.1,
        "latency_us": 50.0,
        "jitter_us": 10.0,
        "leak_rate_hz": 0.1,
        "leak_spread_decades": 0.3,
        "shot_rate_hz": 2.0,
        "hot_pixel_fraction": 1e-4,
        "hot_pixel_rate_hz": 50.0,
    },
    # Sony IMX636 (Prophesee EVK4), 1280 x 720, 4.86 um pixels, us timestamps. The PECS paper's
    # values for this sensor (ECCV 2024, after IEBCS): threshold 0.3, sigma 0.01, refractory
    # 100 us, latency 10 us, photoreceptor tau 300 us (cutoff 1 / (2 pi tau) = 531 Hz), jitter
    # 10 us (the low end of its per-scene range). Leak, shot and hot pixels generic as above.
    "imx636": {
        "width": 1280,
        "height": 720,
        "theta_on": 0.3,
        "theta_off": 0.3,
        "theta_sigma": 0.01,
        "refractory_us": 100.0,
        "cutoff_hz": _cutoff_hz(300.0),
        "cutoff_half_photocurrent": 0.1,
        "latency_us": 10.0,
        "jitter_us": 10.0,
        "leak_rate_hz": 0.1,
        "leak_spread_decades": 0.3,
        "shot_rate_hz": 1.0,
        "hot_pixel_fraction": 1e-4,
        "hot_pixel_rate_hz": 50.0,
    },
}
