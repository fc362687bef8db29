//! Sensor parameters, in the units their names carry, and their validation.

use std::fmt;
use std::str::FromStr;

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
    pub hot_pixel_fraction: f64,
    pub hot_pixel_rate_hz: f64,
    pub seed: u64,
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
            hot_pixel_fraction: 0.0,
            hot_pixel_rate_hz: 0.0,
            seed: 0,
        }
    }

    /// Check every field; the error names the first bad one.
    pub fn validate(&self) -> Result<(), ParamError> {
        fn check(ok: bool, field: &'static str, what: &str, value: f64) -> Result<(), ParamError> {
            if ok {
                Ok(())
            } else {
                Err(ParamError::new(field, format!("{what}, got {value}")))
            }
        }
        let size_ok = |n: usize| n > 0 && n <= u16::MAX as usize + 1;
        check(
            size_ok(self.width),
            "width",
            "must be in 1..=65536",
            self.width as f64,
        )?;
        check(
            size_ok(self.height),
            "height",
            "must be in 1..=65536",
            self.height as f64,
        )?;
        let positive = |v: f64| v.is_finite() && v > 0.0;
        let non_negative = |v: f64| v.is_finite() && v >= 0.0;
        check(
            positive(self.theta_min),
            "theta_min",
            "must be > 0",
            self.theta_min,
        )?;
        let above_min = |v: f64| v.is_finite() && v >= self.theta_min;
        check(
            above_min(self.theta_on),
            "theta_on",
            "must be finite and >= theta_min",
            self.theta_on,
        )?;
        check(
            above_min(self.theta_off),
            "theta_off",
            "must be finite and >= theta_min",
            self.theta_off,
        )?;
        let fields_non_negative = [
            ("theta_sigma", self.theta_sigma),
            ("theta_noise", self.theta_noise),
            ("refractory_us", self.refractory_us),
            ("cutoff_hz", self.cutoff_hz),
            ("cutoff_half_photocurrent", self.cutoff_half_photocurrent),
            ("dark_current", self.dark_current),
            ("lin_log_knee", self.lin_log_knee),
            ("latency_us", self.latency_us),
            ("jitter_us", self.jitter_us),
            ("leak_rate_hz", self.leak_rate_hz),
            ("leak_spread_decades", self.leak_spread_decades),
            ("leak_light_rate_hz", self.leak_light_rate_hz),
            ("shot_rate_hz", self.shot_rate_hz),
            ("hot_pixel_rate_hz", self.hot_pixel_rate_hz),
        ];
        for (field, value) in fields_non_negative {
            check(non_negative(value), field, "must be finite and >= 0", value)?;
        }
        check(
            positive(self.white_lux),
            "white_lux",
            "must be > 0",
            self.white_lux,
        )?;
        check(
            (0.0..=1.0).contains(&self.hot_pixel_fraction),
            "hot_pixel_fraction",
            "must be in [0, 1]",
            self.hot_pixel_fraction,
        )?;
        check(
            self.dark_current > 0.0 || self.lin_log_knee > 0.0,
            "dark_current",
            "must be > 0 (log of zero photocurrent) unless lin_log_knee is set",
            self.dark_current,
        )?;
        check(
            self.shot_rate_hz == 0.0 || self.dark_current > 0.0,
            "shot_rate_hz",
            "needs dark_current > 0 (the rate law is scaled by it)",
            self.shot_rate_hz,
        )?;
        Ok(())
    }
}
