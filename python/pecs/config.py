"""Sensor configuration: every parameter of the pixel model, with units in its name, and presets.

Photocurrents (`dark_current`, `lin_log_knee`, `cutoff_half_photocurrent`, the noise laws) are
in units of the photocurrent of a white surface at 1000 lux. A frame value v is the photocurrent
v * white_lux / 1000: `white_lux` states how bright the white (1.0) of the frames is, 1000 lux by
default, so frames decoded to linear [0, 1] and rendered photocurrent are taken as they are.
"""

from __future__ import annotations

import dataclasses
import json
import math
import os
from dataclasses import dataclass, field
from typing import Any, ClassVar

import numpy as np

from pecs import _core
from pecs.config_file import BIASES_TABLE, read_config, write_config

_RESETS = ("refractory_end", "event")
_OVERFLOWS = ("queue", "drop")
#: Fields a sensor file may leave out without a preset: TOML has no null, so absent is None.
_NONE_WHERE_LEFT_OUT = frozenset({"lin_log_knee", "preset_name", "cfa"})
#: Illuminance of the white whose photocurrent is the unit of every photocurrent field.
REFERENCE_WHITE_LUX = 1000.0


@dataclass(frozen=True)
class SensorConfig:
    """Parameters of a DVS sensor. Build one directly or with `SensorConfig.preset(name, ...)`.

    Every numeric field has a physical range, checked at construction (a ValueError names the
    field and its range): thresholds 0.01-10 log units, event rates up to 1 MHz (a pixel's
    handshake with the arbiter takes about 1 us), delays up to 1 s, photocurrents 1e-6-1e3 frame
    units. numpy scalars are taken and stored as Python numbers.
    """

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
    #: Illuminance (lux) of the white that frame value 1.0 shows; bandwidth and noise follow it.
    white_lux: float = REFERENCE_WHITE_LUX
    #: Photocurrent below which the response is linear instead of log (frame units); None or 0 =
    #: pure log.
    lin_log_knee: float | None = None
    latency_us: float = 0.0
    #: Standard deviation of Gaussian timing jitter added to the latency.
    jitter_us: float = 0.0
    #: Mean leak-event rate over pixels in the dark; per-pixel rates are log-normal around it.
    leak_rate_hz: float = 0.0
    #: Standard deviation of log10 of the per-pixel leak rate.
    leak_spread_decades: float = 0.0
    #: Leak rate added per unit photocurrent: the rate is leak_rate_hz + leak_light_rate_hz * x.
    leak_light_rate_hz: float = 0.0
    #: Shot-noise event rate in the dark; it falls as (dark_current / x)^shot_light_exponent (x
    #: the total photocurrent).
    shot_rate_hz: float = 0.0
    #: How steeply shot noise falls with light: 1 or 2.
    shot_light_exponent: float = 1.0
    hot_pixel_fraction: float = 0.0
    hot_pixel_rate_hz: float = 0.0
    #: The readout, after the pixels (docs/readout.md); every stage off by default. The row
    #: arbiter's service time per row grant (ns; a grant sends all of a row's waiting events);
    #: 0 = no arbiter.
    readout_row_service_ns: float = 0.0
    #: Events per second the bus carries, in millions; 0 = no limit.
    readout_bus_rate_meps: float = 0.0
    #: Events the readout cannot send at once: "queue" (they wait; timestamps fall behind) or
    #: "drop" (an event that finds `readout_queue_depth` events waiting is lost).
    readout_overflow: str = "queue"
    #: Events that may wait before "drop" drops (0 with "queue": no bound).
    readout_queue_depth: int = 0
    #: Timestamp clock step (us): stamps are floored to it; 0 or 1 = the 1 us clock.
    timestamp_step_us: int = 0
    #: Prophesee's event rate controller, last on the chip (events/s in 200 us periods,
    #: pecs.filters); 0 = off.
    erc_rate_hz: float = 0.0
    #: Add the `delay_us` column: each event's readout delay (us, before the timestamp step).
    readout_delays: bool = False
    #: Add the `label` column (0 signal, 1 leak, 2 shot, 3 hot pixel).
    labels: bool = False
    #: Colour filter array over the pixels, libcaer's pattern name ("RGBG": the Color-DAVIS346's
    #: Bayer pattern; pecs.render.cfa), or None for a monochrome sensor. The channel of an event
    #: is given by its pixel (`pecs.render.cfa.ColourFilterArray.channel_of`).
    cfa: str | None = None
    seed: int = 0
    #: The preset this configuration started from, for the record.
    preset_name: str | None = field(default=None, compare=False)

    PRESETS: ClassVar[tuple[str, ...]] = (
        "ideal",
        "esim",
        "davis346",
        "color_davis346",
        "dvxplorer",
        "imx636",
    )

    @property
    def known_preset(self) -> str | None:
        """The preset this configuration started from, where it is one of `PRESETS` (a file may
        record any name)."""
        return self.preset_name if self.preset_name in self.PRESETS else None

    def __post_init__(self) -> None:
        for name, value in _as_python_numbers(self).items():
            object.__setattr__(self, name, value)
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
        """A configuration from a TOML file of `field = value` lines (`pecs.config_file`): the
        preset it names (`preset_name`) with the file's fields over it. A file that names no
        preset of `PRESETS` must give every field (but `lin_log_knee`, None where left out); an
        empty file is refused. A `[biases]` table (`sensor = "davis346"` or `"imx636"` and its
        biases; pecs.biases, docs/biases.md) stands for that preset with the fields its biases
        map to, under the file's own fields. A ValueError names the file and, where fields are
        missing, them."""
        return read_config(path, {f.name for f in dataclasses.fields(cls)}, cls._from_file_values)

    @classmethod
    def _from_file_values(cls, values: dict[str, Any]) -> SensorConfig:
        """A file's values as a configuration: no field is filled in from the class defaults,
        which are the ideal sensor's, so a partial file cannot pass for the camera it names."""
        presets = ", ".join(cls.PRESETS)
        if BIASES_TABLE in values:
            values = _with_biases(values)
        if not values:
            raise ValueError(
                f'no sensor fields; name a preset (preset_name = "davis346"; presets: {presets}) '
                "and give the fields that differ from it, or give every field"
            )
        name = values.get("preset_name")
        if name in _PRESETS:
            return cls.preset(name, **values)
        config = cls.from_dict(values)  # a bad value first: it is what the file says
        fields = [f.name for f in dataclasses.fields(cls) if f.name not in _NONE_WHERE_LEFT_OUT]
        missing = [field_name for field_name in fields if field_name not in values]
        if not missing:
            return config
        if name is None:
            why = (
                "names no preset, so it must give every field (or name one: "
                f'preset_name = "davis346"; presets: {presets})'
            )
        else:
            why = f"preset_name {name!r} is not a pecs preset ({presets}), so it must give every field"
        raise ValueError(f"{why}; missing: {', '.join(missing)}")

    def to_file(self, path: str | os.PathLike[str]) -> None:
        """Write the configuration as a TOML file that `from_file` reads back exactly."""
        write_config(self.to_dict(), path)

    def replace(self, **overrides: Any) -> SensorConfig:
        """A copy with the given fields changed, checked as a new configuration is."""
        return self.from_dict({**self.to_dict(), **overrides})

    def to_dict(self) -> dict[str, Any]:
        """Every field by name, as `from_dict` takes them."""
        return dataclasses.asdict(self)

    def to_json(self) -> str:
        """The fields as JSON with sorted keys: what event files carry as `pecs.sensor`."""
        return json.dumps(self.to_dict(), sort_keys=True)

    def cfa_array(self) -> Any:
        """The colour filter array (`pecs.render.cfa.ColourFilterArray`, the shipped generic
        filter curves) of `cfa`, or None for a monochrome sensor."""
        from pecs.render.cfa import load_cfa

        return None if self.cfa is None else load_cfa(self.cfa)

    def core_params(self) -> dict[str, Any]:
        """The parameters as the Rust core takes them."""
        params = self.to_dict()
        params.pop("labels")
        params.pop("readout_delays")  # a column of the output, not a parameter of the chip
        params.pop("preset_name")
        params.pop("cfa")  # the filters act on light, before the pixel circuit
        params["lin_log_knee"] = self.lin_log_knee or 0.0
        return params


def _as_python_numbers(c: SensorConfig) -> dict[str, Any]:
    """numpy scalars among the fields, as the Python numbers they hold (so to_json works)."""
    converted: dict[str, Any] = {}
    for f in dataclasses.fields(c):
        value = getattr(c, f.name)
        if isinstance(value, np.bool_):
            converted[f.name] = bool(value)
        elif isinstance(value, np.integer):
            converted[f.name] = int(value)
        elif isinstance(value, np.floating):
            converted[f.name] = float(value)
    return converted


def _with_biases(values: dict[str, Any]) -> dict[str, Any]:
    """A file's fields with its `[biases]` table mapped (pecs.biases) under them: the table's
    sensor is the preset, the mapped fields go over it and the file's own fields over those."""
    from pecs.biases import BIAS_SENSORS, map_biases

    fields = {key: value for key, value in values.items() if key != BIASES_TABLE}
    biases = dict(values[BIASES_TABLE])
    sensor = biases.pop("sensor", None)
    if sensor not in BIAS_SENSORS:
        choices = " or ".join(f'sensor = "{name}"' for name in BIAS_SENSORS)
        raise ValueError(f"[biases]: name the sensor whose biases these are ({choices})")
    named = fields.get("preset_name", sensor)
    if named != sensor:
        raise ValueError(
            f'[biases] are the {sensor} biases but preset_name is "{named}"; '
            f'biases map over their own sensor (preset_name = "{sensor}" or leave it out)'
        )
    try:
        mapped = map_biases(sensor, biases).fields
    except ValueError as error:
        raise ValueError(f"[biases]: {error}") from error
    return {"preset_name": sensor, **mapped, **fields}


def _validate(c: SensorConfig) -> None:
    """Types here; the ranges of the numbers in the core (`SensorParams::validate`), which
    refuses them too when it is called from Rust."""
    for name in ("width", "height"):
        value = getattr(c, name)
        if isinstance(value, bool) or not isinstance(value, int) or not 1 <= value <= 65536:
            raise ValueError(f"{name}: must be an integer in 1..65536, got {value!r}")
    if isinstance(c.seed, bool) or not isinstance(c.seed, int) or not 0 <= c.seed < 2**64:
        raise ValueError(f"seed: must be an integer in [0, 2**64), got {c.seed!r}")
    if c.reference_reset not in _RESETS:
        raise ValueError(f"reference_reset: must be one of {_RESETS}, got {c.reference_reset!r}")
    for name in ("labels", "readout_delays"):
        if not isinstance(getattr(c, name), bool):
            raise ValueError(f"{name}: must be True or False, got {getattr(c, name)!r}")
    if c.readout_overflow not in _OVERFLOWS:
        raise ValueError(
            f"readout_overflow: must be one of {_OVERFLOWS}, got {c.readout_overflow!r}"
        )
    for name, most in (("readout_queue_depth", 2**32), ("timestamp_step_us", 10**6)):
        value = getattr(c, name)
        if isinstance(value, bool) or not isinstance(value, int) or not 0 <= value <= most:
            raise ValueError(f"{name}: must be an integer in 0..{most}, got {value!r}")
    _validate_cfa(c.cfa)
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
    _core.check_sensor_params(c.core_params())


def _validate_cfa(cfa: object) -> None:
    from pecs.render.cfa import PATTERNS  # here: pecs.render imports this module

    if cfa is not None and cfa not in PATTERNS:
        raise ValueError(
            f"cfa: unknown colour filter pattern {cfa!r}; choose one of {', '.join(PATTERNS)} "
            "(libcaer's names: the 2 x 2 cell clockwise from its top-left pixel)"
        )


def _cutoff_hz(tau_us: float) -> float:
    """First-order cutoff of a time constant: f = 1 / (2 pi tau)."""
    return 1.0 / (2.0 * math.pi * tau_us * 1e-6)


#: Overrides that turn a preset's random noise off (leak, shot noise, hot pixels, threshold
#: noise) and keep its circuit: `SensorConfig.preset(name, **NOISE_OFF)`.
NOISE_OFF: dict[str, float] = {
    "leak_rate_hz": 0.0,
    "leak_light_rate_hz": 0.0,
    "shot_rate_hz": 0.0,
    "hot_pixel_fraction": 0.0,
    "theta_noise": 0.0,
}

# Background activity measured by IEBCS on a DVS (Joubert et al., Front. Neurosci. 2021; the
# per-pixel inter-event histograms of its data/noise_*.npy at 0.1, 161 and 3000 lux), for
# sensors without their own data:
_IEBCS_NOISE: dict[str, float] = {
    # Dense bipolar noise of 5-8 Hz per pixel at 0.1 lux and almost none (5 OFF pixels of 2500)
    # at 161 lux: a fall of over 500x for 1600x the light, which the square law follows and 1 / x
    # does not (it would leave 9 % OFF events at 161 lux). Shot 24 Hz x (1e-4 / (1e-4 + 1e-4))^2
    # = 6 Hz with a 0.1-lux dark current (1e-4 of the 1000-lux unit); 9e-6 Hz at 161 lux.
    "dark_current": 1e-4,
    "shot_rate_hz": 24.0,
    "shot_light_exponent": 2.0,
    # ON-only activity of about 0.1 Hz on 34 % of pixels at 161 lux and on 95 % at 3 klux: mean
    # leak 0.034 Hz at x = 0.16 and 0.095 Hz at x = 3, the line 0.031 + 0.021 x.
    "leak_rate_hz": 0.031,
    "leak_light_rate_hz": 0.021,
    "leak_spread_decades": 0.3,  # v2e's per-pixel spread (Hu, Liu, Delbruck 2021)
    # Hot pixels: a generic 1e-4 of pixels at 5 Hz, as measured on the DAVIS346 road recording.
    "hot_pixel_fraction": 1e-4,
    "hot_pixel_rate_hz": 5.0,
}

# The white level of a daylight recording whose APS frames set the DAVIS346 noise laws: "full
# daylight (not direct sun)" is 10,000-25,000 lux (P. Schlyter, Radiometry and photometry in
# astronomy, illuminance table), its lower end taken. Daylight frames given with white_lux at
# this level get the recording's background activity; frames at the default 1000 lux get the
# leak of a ten times dimmer scene and its shot noise.
DAYLIGHT_WHITE_LUX = 10_000.0

_PRESETS: dict[str, dict[str, Any]] = {
    # A perfect logarithmic sensor: exact thresholds, infinite bandwidth, no noise, no latency.
    "ideal": {},
    # ESIM (Rebecq et al., CoRL 2018): log(I + eps) with eps = 1e-3 for [0, 1] intensities,
    # reference advanced by the threshold at each crossing; thresholds 0.2 as in its frame-input
    # (vid2e) use; no refractory period, bandwidth or noise unless overridden.
    "esim": {"reference_reset": "event", "dark_current": 1e-3},
    # iniVation DAVIS346, 346 x 260, 18.5 um pixels. Thresholds 0.2 ON and OFF: v2e's DAVIS346
    # parameter sets (`--dvs_params clean` and `noisy`, SensorsINI/v2e v2ecore/emulator.py).
    # The datasheet's 14.3 % ON / 22.5 % OFF (ln 1.143,
    # ln 1.225) is the minimum contrast sensitivity (50 % of pixels responding, biases set for
    # it), not the operating point: on the road recording below they give 1.63x the real count
    # and ON fraction 0.58 (real 0.52) on its second half; 0.2 / 0.2 give 1.32x and 0.49, and
    # pecs.calibrate on the first half alone finds 0.22 / 0.23 (benches/sim_to_real.py,
    # docs/calibration.md). Mismatch sigma 0.03,
    # refractory 0.5 ms and 300 Hz are v2e's defaults for a DAVIS (Hu, Liu, Delbruck, CVPRW
    # 2021); latency 20 us is the datasheet's minimum; bandwidth half-photocurrent (10 % of
    # white) generic. Background activity: measured on a DAVIS346 in daylight (the road
    # recording of github.com/neuromorphicsystems/aedat, tests/data/test_data.aedat4, MIT;
    # benches/sim_to_real.py --diagnose):
    # 0.0028 Hz per static pixel, 94 % ON (leak, not bipolar shot noise), rising with the APS
    # level from 0.0022 Hz (20-50 DN) to 0.0046 Hz (200-255 DN). The recording is in daylight,
    # so its frames' white is taken as DAYLIGHT_WHITE_LUX, and the laws below are these rates
    # at x = DN / 255 * DAYLIGHT_WHITE_LUX / 1000.
    "davis346": {
        "width": 346,
        "height": 260,
        "theta_on": 0.2,
        "theta_off": 0.2,
        "theta_sigma": 0.03,
        # IEBCS's example sensor (neuromorphicsystems/IEBCS README): threshold noise 0.01.
        "theta_noise": 0.01,
        "refractory_us": 500.0,
        "cutoff_hz": 300.0,
        # Assumed, no published figure: the bandwidth falls with light below a tenth of white.
        "cutoff_half_photocurrent": 0.1,
        # Dynamic range 120 dB down to 0.1 lux (iniVation DAVIS346 specification):
        # a dark current of about 0.1 lux, 1e-4 of the 1000-lux white unit.
        "dark_current": 1e-4,
        "latency_us": 20.0,
        # Assumed, no published figure: a quarter of the 20 us minimum latency.
        "jitter_us": 5.0,
        # Leak r(x) = 0.001 + 0.0004 x Hz: the recording's static-pixel rates per APS level
        # (0.0022, 0.0026, 0.0033, 0.0046 Hz at DN / 255 = 0.14, 0.29, 0.59, 0.89, x ten times
        # that) less the shot part below, fitted by a line (Nozaki and Delbruck 2017: leak
        # rises with light): 0.001 + 0.004 DN / 255.
        "leak_rate_hz": 0.001,
        "leak_light_rate_hz": 0.004 * REFERENCE_WHITE_LUX / DAYLIGHT_WHITE_LUX,
        # v2e's per-pixel leak spread (log-normal; Hu, Liu, Delbruck 2021), kept from before.
        "leak_spread_decades": 0.3,
        # Shot noise 10 x 1e-4 / x Hz: 6 % OFF events in static pixels of the recording is about
        # 0.0003 Hz of bipolar noise at DN / 255 ~ 0.3 (x ~ 3). In the dark that is 10 Hz, and
        # 5 Hz at 0.1 lux (x = 2e-4): iniVation quotes ~10 Hz in low light, IEBCS measured 5-8 Hz
        # at 0.1 lux.
        "shot_rate_hz": 1.0 * DAYLIGHT_WHITE_LUX / REFERENCE_WHITE_LUX,
        # The recording's static pixels above 1 Hz: 9e-5 of them, a few Hz each.
        "hot_pixel_fraction": 1e-4,
        "hot_pixel_rate_hz": 5.0,
        # Readout: the chip's AER bus carries about 12 M events/s (iniVation, "Biasing",
        # docs.inivation.com/hardware/hardware-advanced-usage/biasing.html). A row grant is
        # ACK_DELAY_ROW + ACK_EXTENSION_ROW = 4 + 1 logic cycles (libcaer's default FPGA
        # configuration), 50 ns at an assumed 100 MHz logic clock. libcaer's default
        # DROP_DVS_ON_TRANSFER_STALL drops DVS events, instead of stalling the chip, when the
        # buffers to the host are full: their size in events is assumed (no published figure).
        "readout_row_service_ns": 50.0,
        "readout_bus_rate_meps": 12.0,
        "readout_overflow": "drop",
        "readout_queue_depth": 4096,
    },
    # iniVation Color-DAVIS346 (DAVIS346 "color" variant, libcaer: "RGBG" colour filter, the
    # CED dataset's camera): the DAVIS346 circuit under a Bayer filter. No filter spectra are
    # published: the generic curves of pecs/scenes/cfa, labelled as assumed.
    "color_davis346": {},  # filled in below, from "davis346"
    # iniVation DVXplorer, 640 x 480, 9 um pixels. No threshold figure is published in the same
    # form: thresholds 0.2 and mismatch 0.03 are the typical values of sensor-models.md (0.15-0.5,
    # sigma 0.02-0.05), refractory and bandwidth v2e's defaults; noise from IEBCS's measurements.
    "dvxplorer": {
        "width": 640,
        "height": 480,
        "theta_on": 0.2,
        "theta_off": 0.2,
        "theta_sigma": 0.03,
        "theta_noise": 0.01,  # IEBCS's example sensor (neuromorphicsystems/IEBCS README)
        "refractory_us": 500.0,
        "cutoff_hz": 300.0,
        "cutoff_half_photocurrent": 0.1,  # assumed, as davis346's
        # Assumed, no published figure: latency between the DAVIS346's 20 us minimum and the
        # IEBCS example's 100 us; jitter the IEBCS example's 10 us.
        "latency_us": 50.0,
        "jitter_us": 10.0,
        **_IEBCS_NOISE,
        # Readout: about 165 M events/s (iniVation, "Biasing", docs.inivation.com), and the
        # Samsung Gen3 sensor's timestamps in steps of about 100 us (better-flow/evimo#32: at
        # 6 Mev/s some 600 events share one timestamp). No arbiter figure is published: none.
        "readout_bus_rate_meps": 165.0,
        "timestamp_step_us": 100,
    },
    # Sony IMX636 (Prophesee EVK4), 1280 x 720, 4.86 um pixels, us timestamps. The PECS paper's
    # values for this sensor (ECCV 2024, after IEBCS): threshold 0.3, sigma 0.01, refractory
    # 100 us, latency 10 us, photoreceptor tau 300 us (cutoff 1 / (2 pi tau) = 531 Hz), jitter
    # 10 us (the low end of its per-scene range). Noise from IEBCS's measurements.
    "imx636": {
        "width": 1280,
        "height": 720,
        "theta_on": 0.3,
        "theta_off": 0.3,
        "theta_sigma": 0.01,
        "refractory_us": 100.0,
        "cutoff_hz": _cutoff_hz(300.0),
        "cutoff_half_photocurrent": 0.1,  # assumed, as davis346's
        "latency_us": 10.0,
        "jitter_us": 10.0,
        **_IEBCS_NOISE,
        # Readout: a row arbiter whose requests wait under load ("backpressure": timestamps then
        # stop following real time; Prophesee KB, "How saturation and backpressure affect
        # timestamping precision"), 1 us timestamps, 1.066 G events/s out of the array (Sony's
        # IMX636 slides). The grant time, 50 ns, is inferred: one event per grant saturates at
        # 20 Mev/s, where real EVK4 recordings start to show empty 1 us bins (openeb#75). Then
        # the event rate controller at OpenEB's default, 10,000 events per 200 us period =
        # 50 Mev/s (gen41_erc.cpp).
        "readout_row_service_ns": 50.0,
        "readout_bus_rate_meps": 1066.0,
        "erc_rate_hz": 50e6,
    },
}
_PRESETS["color_davis346"] = {**_PRESETS["davis346"], "cfa": "RGBG"}
