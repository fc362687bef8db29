//! Sensor parameters, in the units their names carry, and their validation.

use std::fmt;
use std::str::FromStr;

use crate::readout::ReadoutSettings;

/// When the change detector memorises a new reference after an event.
#[derive(Clone, Copy, Debug, PartialEq, Eq)]
pub enum ReferenceReset {
    /// The real circuit: the pixel is held in reset for the refractory period and memorises the
    /// photoreceptor level when it is released.
    RefractoryEnd,
    /// ESIM: the reference advances by the threshold at each crossing; crossings inside the
    /// refractory period are dropped but still advance it.
    Event,
}

impl FromStr for ReferenceReset {
    type Err = ParamError;
    fn from_str(s: &str) -> Result<Self, ParamError> {
        match s {
            "refractory_end" => Ok(Self::RefractoryEnd),
            "event" => Ok(Self::Event),
            _ => Err(ParamError::new(
                "reference_reset",
                format!("must be 'refractory_end' or 'event', got {s:?}"),
            )),
        }
    }
}

/// A parameter that cannot be used, with the field it names.
#[derive(Clone, Debug, PartialEq)]
pub struct ParamError {
    pub field: &'static str,
    pub message: String,
}

impl ParamError {
    pub fn new(field: &'static str, message: String) -> Self {
        Self { field, message }
    }
}

impl fmt::Display for ParamError {
    fn fmt(&self, f: &mut fmt::Formatter<'_>) -> fmt::Result {
        write!(f, "{}: {}", self.field, self.message)
    }
}

impl std::error::Error for ParamError {}

/// Everything the pixel model needs. Log quantities are natural-log units; photocurrents are in
/// the units of the frames fed to the sensor ("frame units").
#[derive(Clone, Debug, PartialEq)]
pub struct SensorParams {
    pub width: usize,
    pub height: usize,
    pub theta_on: f64,
    pub theta_off: f64,
    /// Standard deviation of the frozen per-pixel threshold mismatch (log units).
    pub theta_sigma: f64,
    /// Standard deviation of the threshold redrawn after every event (log units).
    pub theta_noise: f64,
    /// Smallest threshold a pixel may draw (log units): keeps a pixel from firing continuously.
    pub theta_min: f64,
    pub refractory_us: f64,
    pub reference_reset: ReferenceReset,
    /// Photoreceptor bandwidth in bright light; 0 means infinite bandwidth.
    pub cutoff_hz: f64,
    /// Photocurrent at which the bandwidth is half of `cutoff_hz`; 0 = independent of light.
    pub cutoff_half_photocurrent: f64,
    pub dark_current: f64,
    /// Illuminance (lux) of the white that frame value 1.0 shows; the photocurrent unit is white
    /// at `photoreceptor::REFERENCE_WHITE_LUX` (1000 lux), so 1000 keeps frames as they are.
    pub white_lux: f64,
    /// Photocurrent below which the response is linear instead of logarithmic; 0 = pure log.
    pub lin_log_knee: f64,
    pub latency_us: f64,
    pub jitter_us: f64,
    /// Mean leak-event rate over pixels in the dark (junction leakage of the reset switch).
    pub leak_rate_hz: f64,
    /// Leak rate added per unit photocurrent (parasitic photocurrent in the reset switch); see
    /// `noise::leak_rate_hz`.
    pub leak_light_rate_hz: f64,
    /// Standard deviation of log10 of the per-pixel leak rate.
    pub leak_spread_decades: f64,
    /// Shot-noise event rate of a pixel in the dark (see `noise::shot_rate_hz`).
    pub shot_rate_hz: f64,
    /// How steeply the shot-noise rate falls with light: r ~ x^-n, n 1 or 2.
    pub shot_light_exponent: f64,
    pub hot_pixel_fraction: f64,
    pub hot_pixel_rate_hz: f64,
    pub seed: u64,
    /// How events leave the chip after the pixels made them (`crate::readout`); off by default.
    pub readout: ReadoutSettings,
}

impl SensorParams {
    /// An ideal sensor of the given size: thresholds 0.2, no non-idealities.
    pub fn ideal(width: usize, height: usize) -> Self {
        Self {
            width,
            height,
            theta_on: 0.2,
            theta_off: 0.2,
            theta_sigma: 0.0,
            theta_noise: 0.0,
            theta_min: 0.01,
            refractory_us: 0.0,
            reference_reset: ReferenceReset::RefractoryEnd,
            cutoff_hz: 0.0,
            cutoff_half_photocurrent: 0.0,
            dark_current: 1e-3,
            white_lux: 1000.0,
            lin_log_knee: 0.0,
            latency_us: 0.0,
            jitter_us: 0.0,
            leak_rate_hz: 0.0,
            leak_spread_decades: 0.0,
            leak_light_rate_hz: 0.0,
            shot_rate_hz: 0.0,
            shot_light_exponent: 1.0,
            hot_pixel_fraction: 0.0,
            hot_pixel_rate_hz: 0.0,
            seed: 0,
            readout: ReadoutSettings::default(),
        }
    }

    /// Check every field against its range (see `RANGES` for why each is bounded); the error
    /// names the first bad field and its allowed range. Beyond these ranges a sensor could be
    /// asked for more events than memory holds, and an allocation failure aborts the process.
    pub fn validate(&self) -> Result<(), ParamError> {
        for (field, value) in [("width", self.width), ("height", self.height)] {
            if !(1..=MAX_SIDE).contains(&value) {
                let message = format!("must be an integer in 1..={MAX_SIDE}, got {value}");
                return Err(ParamError::new(field, message));
            }
        }
        for range in RANGES {
            range.check(self.value_of(range.field))?;
        }
        for (field, value) in [("theta_on", self.theta_on), ("theta_off", self.theta_off)] {
            if value < self.theta_min {
                let message = format!("must be >= theta_min ({}), got {value}", self.theta_min);
                return Err(ParamError::new(field, message));
            }
        }
        if self.dark_current == 0.0 && self.lin_log_knee == 0.0 {
            let message = "must be > 0 (the log of zero photocurrent) unless lin_log_knee is set";
            return Err(ParamError::new("dark_current", message.to_string()));
        }
        if self.shot_light_exponent != 1.0 && self.shot_light_exponent != 2.0 {
            let message = format!("must be 1 or 2, got {}", self.shot_light_exponent);
            return Err(ParamError::new("shot_light_exponent", message));
        }
        if self.shot_rate_hz > 0.0 && self.dark_current == 0.0 {
            let message = "needs dark_current > 0 (its rate law is scaled by it)";
            return Err(ParamError::new("shot_rate_hz", message.to_string()));
        }
        self.readout.validate()
    }

    fn value_of(&self, field: &str) -> f64 {
        match field {
            "theta_on" => self.theta_on,
            "theta_off" => self.theta_off,
            "theta_sigma" => self.theta_sigma,
            "theta_noise" => self.theta_noise,
            "theta_min" => self.theta_min,
            "refractory_us" => self.refractory_us,
            "cutoff_hz" => self.cutoff_hz,
            "cutoff_half_photocurrent" => self.cutoff_half_photocurrent,
            "dark_current" => self.dark_current,
            "lin_log_knee" => self.lin_log_knee,
            "latency_us" => self.latency_us,
            "jitter_us" => self.jitter_us,
            "leak_rate_hz" => self.leak_rate_hz,
            "leak_spread_decades" => self.leak_spread_decades,
            "leak_light_rate_hz" => self.leak_light_rate_hz,
            "white_lux" => self.white_lux,
            "shot_rate_hz" => self.shot_rate_hz,
            "hot_pixel_fraction" => self.hot_pixel_fraction,
            "hot_pixel_rate_hz" => self.hot_pixel_rate_hz,
            _ => unreachable!("RANGES names a field SensorParams lacks: {field}"),
        }
    }
}

/// Largest width or height: event coordinates are u16.
pub const MAX_SIDE: usize = 1 << 16;

/// The values a numeric field may take: `min..=max`, or exactly 0 where 0 switches it off.
#[derive(Clone, Copy, Debug)]
pub struct Range {
    pub field: &'static str,
    pub min: f64,
    pub max: f64,
    /// 0 is allowed below `min` (it means "off": no knee, infinite bandwidth).
    pub zero_is_off: bool,
}

impl Range {
    const fn new(field: &'static str, min: f64, max: f64) -> Self {
        Self {
            field,
            min,
            max,
            zero_is_off: false,
        }
    }

    const fn or_off(field: &'static str, min: f64, max: f64) -> Self {
        Self {
            field,
            min,
            max,
            zero_is_off: true,
        }
    }

    pub fn contains(&self, value: f64) -> bool {
        (self.min..=self.max).contains(&value) || (self.zero_is_off && value == 0.0)
    }

    fn check(&self, value: f64) -> Result<(), ParamError> {
        if self.contains(value) {
            return Ok(());
        }
        let (min, max) = (self.min, self.max);
        let message = if self.zero_is_off {
            format!("must be 0 (off) or in [{min:?}, {max:?}], got {value:?}")
        } else {
            format!("must be in [{min:?}, {max:?}], got {value:?}")
        };
        Err(ParamError::new(self.field, message))
    }
}

/// A pixel cannot fire faster than about 1 MHz (each event is a request/acknowledge handshake
/// with the arbiter of about 1 us), so no event rate may exceed it.
pub const MAX_RATE_HZ: f64 = 1e6;
/// One second: no sensor holds a reset, delays an event or jitters by more (real ones: us-ms).
pub const MAX_DELAY_US: f64 = 1e6;
/// The frames' white may be lit from a moonless night sky (1e-4 lux) to direct sun (about
/// 1e5 lux), with a decade of margin above.
pub const MIN_WHITE_LUX: f64 = 1e-4;
pub const MAX_WHITE_LUX: f64 = 1e6;

/// Every numeric field's range. Thresholds: 1 % contrast (ln 1.01 ~ 0.01) is below any
/// published DVS sensitivity, and e^10 a contrast no sensor is set to; with photocurrents from
/// 1e-6 of white, a pixel crosses at most ln(1e6) / 0.01 ~ 1,400 times going from black to white.
/// Spreads beyond 1 log unit (a factor e) or 2 decades describe no sensor. A bandwidth below
/// 1 mHz is a time constant of minutes (and 1 / (2 pi f) overflows for tiny f); above 1 MHz no
/// photoreceptor follows. Photocurrents are in frame units (1 = white): 1e-6..1e3 spans any
/// dark current or knee against a white of 1.
pub const RANGES: &[Range] = &[
    Range::new("theta_min", 0.01, 1.0),
    Range::new("theta_on", 0.01, 10.0),
    Range::new("theta_off", 0.01, 10.0),
    Range::new("theta_sigma", 0.0, 1.0),
    Range::new("theta_noise", 0.0, 1.0),
    Range::new("refractory_us", 0.0, MAX_DELAY_US),
    Range::or_off("cutoff_hz", 1e-3, MAX_RATE_HZ),
    Range::new("cutoff_half_photocurrent", 0.0, 1e3),
    Range::or_off("dark_current", 1e-6, 1e3),
    Range::or_off("lin_log_knee", 1e-6, 1e3),
    Range::new("latency_us", 0.0, MAX_DELAY_US),
    Range::new("jitter_us", 0.0, MAX_DELAY_US),
    Range::new("leak_rate_hz", 0.0, MAX_RATE_HZ),
    Range::new("leak_spread_decades", 0.0, 2.0),
    Range::new("leak_light_rate_hz", 0.0, MAX_RATE_HZ),
    Range::new("shot_rate_hz", 0.0, MAX_RATE_HZ),
    Range::new("hot_pixel_fraction", 0.0, 1.0),
    Range::new("hot_pixel_rate_hz", 0.0, MAX_RATE_HZ),
    Range::new("white_lux", MIN_WHITE_LUX, MAX_WHITE_LUX),
];

#[cfg(test)]
mod tests {
    use super::*;

    /// Values that once reached the pixel model and aborted the process allocating their events.
    #[test]
    fn values_out_of_range_name_their_field_and_range() {
        type Spoil = fn(&mut SensorParams);
        let cases: [(&str, Spoil); 8] = [
            ("theta_on", |p| p.theta_on = 1e-300),
            ("theta_min", |p| p.theta_min = 1e-300),
            ("shot_rate_hz", |p| p.shot_rate_hz = 1e300),
            ("hot_pixel_rate_hz", |p| p.hot_pixel_rate_hz = 1e300),
            ("leak_rate_hz", |p| p.leak_rate_hz = 1e12),
            ("latency_us", |p| p.latency_us = 1e300),
            ("cutoff_hz", |p| p.cutoff_hz = 5e-324),
            ("lin_log_knee", |p| p.lin_log_knee = -1.0),
        ];
        for (field, spoil) in cases {
            let mut params = SensorParams::ideal(4, 4);
            spoil(&mut params);
            let error = params.validate().unwrap_err();
            assert_eq!(error.field, field);
            assert!(error.to_string().contains(" in ["), "{error}");
        }
    }

    #[test]
    fn every_range_refuses_just_outside_and_nan_and_takes_its_ends() {
        for range in RANGES {
            let set = |value: f64| {
                let mut p = SensorParams::ideal(4, 4);
                p.theta_min = 0.01;
                match range.field {
                    "theta_on" => p.theta_on = value,
                    "theta_off" => p.theta_off = value,
                    "theta_sigma" => p.theta_sigma = value,
                    "theta_noise" => p.theta_noise = value,
                    "theta_min" => {
                        p.theta_min = value;
                        (p.theta_on, p.theta_off) = (10.0, 10.0);
                    }
                    "refractory_us" => p.refractory_us = value,
                    "cutoff_hz" => p.cutoff_hz = value,
                    "cutoff_half_photocurrent" => p.cutoff_half_photocurrent = value,
                    "dark_current" => p.dark_current = value,
                    "lin_log_knee" => p.lin_log_knee = value,
                    "latency_us" => p.latency_us = value,
                    "jitter_us" => p.jitter_us = value,
                    "leak_rate_hz" => p.leak_rate_hz = value,
                    "leak_spread_decades" => p.leak_spread_decades = value,
                    "shot_rate_hz" => p.shot_rate_hz = value,
                    "hot_pixel_fraction" => p.hot_pixel_fraction = value,
                    "hot_pixel_rate_hz" => p.hot_pixel_rate_hz = value,
                    "leak_light_rate_hz" => p.leak_light_rate_hz = value,
                    "white_lux" => p.white_lux = value,
                    other => panic!("untested field {other}"),
                }
                p.validate()
            };
            assert!(set(range.min).is_ok(), "{}", range.field);
            assert!(set(range.max).is_ok(), "{}", range.field);
            for bad in [range.max * 1.001, f64::NAN, f64::INFINITY, -1.0] {
                assert_eq!(set(bad).unwrap_err().field, range.field, "{bad}");
            }
            if range.min > 0.0 && !range.zero_is_off {
                assert_eq!(set(range.min * 0.999).unwrap_err().field, range.field);
            }
        }
    }

    #[test]
    fn sizes_beyond_u16_coordinates_are_refused() {
        assert!(SensorParams::ideal(65536, 1).validate().is_ok());
        assert_eq!(
            SensorParams::ideal(65537, 1).validate().unwrap_err().field,
            "width"
        );
        assert_eq!(
            SensorParams::ideal(1, 0).validate().unwrap_err().field,
            "height"
        );
    }
}
