//! The photoreceptor: logarithmic (optionally lin-log) response and its light-dependent bandwidth.

use crate::exp::{exp, in_ln_range, ln};
use crate::params::SensorParams;

/// The illuminance of the white whose photocurrent is 1.0, the unit of every photocurrent
/// parameter (`dark_current`, `lin_log_knee`, `cutoff_half_photocurrent`, the noise laws): a
/// frame value v is the photocurrent v * white_lux / REFERENCE_WHITE_LUX.
pub const REFERENCE_WHITE_LUX: f64 = 1000.0;

/// Static response and low-pass time constant of one sensor's photoreceptors.
#[derive(Clone, Copy, Debug)]
pub struct Photoreceptor {
    dark_current: f64,
    /// Photocurrent of frame value 1.0: white_lux / REFERENCE_WHITE_LUX.
    frame_scale: f64,
    knee: f64,
    ln_knee: f64,
    cutoff_hz: f64,
    cutoff_half_photocurrent: f64,
    /// 1 / (2 pi cutoff_hz), the time constant in bright light (0 without a low-pass).
    tau_bright_s: f64,
}

impl Photoreceptor {
    pub fn new(p: &SensorParams) -> Self {
        Self {
            dark_current: p.dark_current,
            frame_scale: p.white_lux / REFERENCE_WHITE_LUX,
            knee: p.lin_log_knee,
            ln_knee: if p.lin_log_knee > 0.0 {
                p.lin_log_knee.ln()
            } else {
                0.0
            },
            cutoff_hz: p.cutoff_hz,
            cutoff_half_photocurrent: p.cutoff_half_photocurrent,
            tau_bright_s: if p.cutoff_hz > 0.0 {
                1.0 / (std::f64::consts::TAU * p.cutoff_hz)
            } else {
                0.0
            },
        }
    }

    /// Total photocurrent: the signal (the frame value at the stated light level) plus the dark
    /// current that keeps the log defined.
    #[inline]
    pub fn total_current(&self, frame_value: f64) -> f64 {
        frame_value * self.frame_scale + self.dark_current
    }

    /// Whether `response(x)` is `ln_in_range(x)`: x at or above the knee, positive, normal and
    /// finite.
    #[inline(always)]
    pub fn response_is_ln_in_range(&self, x: f64) -> bool {
        (x >= self.knee) & in_ln_range(x)
    }

    /// The frame value whose total photocurrent is `total_current` (inverse of `total_current`).
    #[inline]
    pub fn frame_value(&self, total_current: f64) -> f64 {
        (total_current - self.dark_current) / self.frame_scale
    }

    /// u = ln(x) above the knee, the tangent line ln(k) + (x - k) / k below it (lin-log, C1).
    #[inline]
    pub fn response(&self, total_current: f64) -> f64 {
        if total_current >= self.knee {
            ln(total_current)
        } else {
            self.ln_knee + (total_current - self.knee) / self.knee
        }
    }

    /// The total photocurrent whose response is `u` (inverse of `response`).
    #[inline]
    pub fn inverse_response(&self, u: f64) -> f64 {
        if self.knee <= 0.0 || u >= self.ln_knee {
            exp(u)
        } else {
            self.knee * (1.0 + u - self.ln_knee)
        }
    }

    /// Whether u = ln(x) everywhere (no lin-log knee).
    #[inline]
    pub fn is_logarithmic(&self) -> bool {
        self.knee <= 0.0
    }

    /// Whether the response is instantaneous (infinite bandwidth).
    #[inline]
    pub fn is_instantaneous(&self) -> bool {
        self.cutoff_hz == 0.0
    }

    /// tau = 1 / (2 pi f_c), f_c = cutoff_hz * x / (x + x_half): bandwidth proportional to
    /// photocurrent in the dark, saturating at cutoff_hz in bright light (Delbruck and Mead's
    /// adaptive photoreceptor; v2e and IEBCS scale it likewise).
    #[inline]
    pub fn tau_s(&self, total_current: f64) -> f64 {
        self.tau_at_inverse_s(inverse_current(total_current))
    }

    /// `tau_s` at the photocurrent whose inverse is `inv_current` (`inverse_current`):
    /// tau = (1 + x_half / x) / (2 pi cutoff_hz), without a division, since a pixel update
    /// already holds 1 / x for its shot-noise rate (a division is the costliest single operation
    /// of a step).
    #[inline(always)]
    pub fn tau_at_inverse_s(&self, inv_current: f64) -> f64 {
        if self.cutoff_half_photocurrent > 0.0 && self.tau_bright_s > 0.0 {
            (1.0 + self.cutoff_half_photocurrent * inv_current) * self.tau_bright_s
        } else {
            self.tau_bright_s
        }
    }

    /// The time constant over a segment from photocurrent x0 to x1, held at their geometric
    /// mean sqrt(x0 x1), whose inverse is sqrt((1 / x0) (1 / x1)): from the two inverses a step
    /// holds anyway, without a division. At most 1 / MIN_POSITIVE, as `inverse_current`.
    #[inline(always)]
    pub fn segment_tau_s(&self, inv_current0: f64, inv_current1: f64) -> f64 {
        let inv_mean = (inv_current0 * inv_current1).sqrt();
        // A comparison, not f64::min: one instruction, and NaN goes to the limit the same.
        let limit = 1.0 / f64::MIN_POSITIVE;
        self.tau_at_inverse_s(if inv_mean < limit { inv_mean } else { limit })
    }
}

/// 1 / x for a total photocurrent x, at least the smallest normal number (x = 0 is possible
/// only with a lin-log response and no dark current): the one division of a photocurrent that
/// the time constant and the shot-noise rate share.
#[inline(always)]
pub fn inverse_current(total_current: f64) -> f64 {
    // A comparison, not f64::max: one instruction, and NaN goes to the limit the same.
    let x = total_current;
    1.0 / if x > f64::MIN_POSITIVE {
        x
    } else {
        f64::MIN_POSITIVE
    }
}

#[cfg(test)]
mod tests {
    use super::*;

    fn receptor(knee: f64, cutoff_hz: f64, half: f64) -> Photoreceptor {
        let mut p = SensorParams::ideal(1, 1);
        p.lin_log_knee = knee;
        p.cutoff_hz = cutoff_hz;
        p.cutoff_half_photocurrent = half;
        Photoreceptor::new(&p)
    }

    #[test]
    fn lin_log_is_continuous_with_continuous_slope_at_the_knee() {
        let r = receptor(0.1, 0.0, 0.0);
        let h = 1e-7;
        assert!((r.response(0.1 - h) - r.response(0.1 + h)).abs() < 1e-5);
        let slope_below = (r.response(0.1 - h) - r.response(0.1 - 2.0 * h)) / h;
        let slope_above = (r.response(0.1 + 2.0 * h) - r.response(0.1 + h)) / h;
        assert!((slope_below - 10.0).abs() < 1e-3 && (slope_above - 10.0).abs() < 1e-3);
        for x in [0.0, 0.05, 0.1, 0.3, 2.0] {
            assert!((r.inverse_response(r.response(x)) - x).abs() < 1e-12);
        }
    }

    #[test]
    fn bandwidth_halves_at_the_half_photocurrent() {
        let r = receptor(0.0, 100.0, 0.5);
        let tau_bright = 1.0 / (std::f64::consts::TAU * 100.0);
        assert!((r.tau_s(0.5) / tau_bright - 2.0).abs() < 1e-12);
        assert!((r.tau_s(1e9) / tau_bright - 1.0).abs() < 1e-6);
        assert_eq!(receptor(0.0, 0.0, 0.5).tau_s(1.0), 0.0);
    }
}
