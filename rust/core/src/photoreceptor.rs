//! The photoreceptor: logarithmic (optionally lin-log) response and its light-dependent bandwidth.

use crate::exp::{exp, ln};
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
        }
    }

    /// Total photocurrent: the signal (the frame value at the stated light level) plus the dark
    /// current that keeps the log defined.
    #[inline]
    pub fn total_current(&self, frame_value: f64) -> f64 {
        frame_value * self.frame_scale + self.dark_current
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
        if self.cutoff_hz == 0.0 {
            return 0.0;
        }
        let x = total_current.max(f64::MIN_POSITIVE);
        let two_pi_cutoff_hz = std::f64::consts::TAU * self.cutoff_hz;
        if self.cutoff_half_photocurrent > 0.0 {
            // The same tau in one division rather than two: every pixel update takes it twice.
            (x + self.cutoff_half_photocurrent) / (two_pi_cutoff_hz * x)
        } else {
            1.0 / two_pi_cutoff_hz
        }
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
