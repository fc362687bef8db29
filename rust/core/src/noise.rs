//! Background activity: leak events, shot-noise events and hot pixels.

use crate::exp::{exp, exp_in_range, in_exp_range};
use crate::params::SensorParams;
use crate::photoreceptor::inverse_current;
use crate::rng::{Draw, Stream};

/// Per-pixel leak-rate factor, log-normal across pixels with mean 1:
/// f_i = 10^(s z - s^2 ln(10) / 2), z ~ N(0, 1), since E[10^(s z)] = exp((s ln 10)^2 / 2).
/// `frozen` is the pixel's draw 0. Zero when the sensor has no leak.
pub fn leak_factor(p: &SensorParams, frozen: Draw) -> f64 {
    if !has_leak(p) {
        return 0.0;
    }
    exp(leak_factor_exponent(p, frozen.normal(Stream::LeakRate)))
}

/// ln f_i of `leak_factor` at the pixel's normal draw `z`.
#[inline(always)]
pub(crate) fn leak_factor_exponent(p: &SensorParams, z: f64) -> f64 {
    let s = p.leak_spread_decades;
    let ln10 = std::f64::consts::LN_10;
    ln10 * (s * z - s * s * ln10 / 2.0)
}

/// Whether any pixel leaks at any light level.
#[inline]
pub fn has_leak(p: &SensorParams) -> bool {
    p.leak_rate_hz > 0.0 || p.leak_light_rate_hz > 0.0
}

/// Mean leak-event rate over pixels at total photocurrent x: r(x) = leak_rate_hz +
/// leak_light_rate_hz x. Leak events come from junction leakage in the reset switch, which
/// discharges the differencing amplifier's input (the reference drifts); in light the switch's
/// parasitic photocurrent adds a part proportional to the photocurrent (Nozaki and Delbruck,
/// IEEE Trans. Electron Devices 64(8), 2017: leak rate rising with illumination).
#[inline]
pub fn leak_law_hz(p: &SensorParams, total_current: f64) -> f64 {
    p.leak_rate_hz + p.leak_light_rate_hz * total_current
}

/// A pixel's leak rate at total photocurrent x: its factor times the law.
pub fn leak_rate_hz(p: &SensorParams, frozen: Draw, total_current: f64) -> f64 {
    leak_factor(p, frozen) * leak_law_hz(p, total_current)
}

/// Whether a pixel is hot: a fraction `hot_pixel_fraction` of pixels, chosen by the seed.
pub fn is_hot(p: &SensorParams, frozen: Draw) -> bool {
    p.hot_pixel_fraction > 0.0
        && p.hot_pixel_rate_hz > 0.0
        && frozen.uniform(Stream::HotSelect) < p.hot_pixel_fraction
}

/// Shot-noise event rate at total photocurrent x: r = shot_rate_hz (I_dark / x)^n, n =
/// `shot_light_exponent` (1 or 2), the rate in the dark falling with light. Photon shot noise
/// makes the relative fluctuation of the photocurrent fall with light; the measured fall is
/// steeper than its 1/sqrt(x): IEBCS's DVS recordings (Joubert et al. 2021, data/noise_*.npy)
/// have dense bipolar noise at 5-8 Hz per pixel at 0.1 lux and almost no OFF events at 161 lux
/// (5 of 2500 pixels), a fall of more than 500x over 1600x the light, which n = 2 follows; a
/// DAVIS346 in daylight keeps some bipolar noise, which n = 1 follows (config.py's presets).
#[inline]
pub fn shot_rate_hz(p: &SensorParams, total_current: f64) -> f64 {
    shot_rate_at_inverse_hz(p, inverse_current(total_current))
}

/// `shot_rate_hz` at the photocurrent whose inverse is `inv_current` (`inverse_current`):
/// r = (shot_rate_hz I_dark) (1 / x) [(I_dark (1 / x))], products, since a step holds 1 / x for
/// its time constant.
#[inline(always)]
pub fn shot_rate_at_inverse_hz(p: &SensorParams, inv_current: f64) -> f64 {
    if p.shot_light_exponent == 2.0 {
        shot_rate_of_law_hz::<true>(p, inv_current)
    } else {
        shot_rate_of_law_hz::<false>(p, inv_current)
    }
}

/// `shot_rate_at_inverse_hz` for the law n = 2 (`SQUARE`) or n = 1, chosen by the caller: the
/// dense path picks it once a block, so that its vector loop does not compute both laws.
#[inline(always)]
pub fn shot_rate_of_law_hz<const SQUARE: bool>(p: &SensorParams, inv_current: f64) -> f64 {
    if p.shot_rate_hz == 0.0 {
        return 0.0;
    }
    let rate = p.shot_rate_hz * p.dark_current * inv_current;
    if SQUARE {
        rate * (p.dark_current * inv_current)
    } else {
        rate
    }
}

/// A lower bound on when a shot-noise budget h runs out at a constant photocurrent x (shot
/// noise on): h / r(x) = h x^n / (shot_rate_hz I_dark^n), products by a constant rather than a
/// division. It rounds otherwise than the run that finds the event (h / r, `GeometricRate`):
/// four roundings each for n = 1, six for n = 2, within 5 and 9 ulps of each other, so it is
/// shortened by 8 or 16 ulps to stay before it; a wake-up a hair late could let the event be
/// found a frame late.
#[inline(always)]
pub fn shot_budget_lower_bound_s(p: &SensorParams, budget: f64, total_current: f64) -> f64 {
    let per_rate = p.shot_rate_hz * p.dark_current;
    if p.shot_light_exponent == 2.0 {
        let scale = (1.0 - 16.0 * f64::EPSILON) / (per_rate * p.dark_current);
        budget * total_current * total_current * scale
    } else {
        budget * total_current * ((1.0 - 8.0 * f64::EPSILON) / per_rate)
    }
}

/// A Poisson rate that changes geometrically over an interval, r(s) = r_a e^{g s}, as it does
/// when the photocurrent is interpolated geometrically (linearly in log) between frames.
#[derive(Clone, Copy, Debug)]
pub struct GeometricRate {
    pub r_a: f64,
    pub g: f64,
}

impl GeometricRate {
    /// The same rate seen from `s` seconds later: r_a e^{g s}.
    #[inline]
    pub fn later_by(&self, s: f64) -> Self {
        if self.g == 0.0 || s == 0.0 {
            *self
        } else {
            Self {
                r_a: self.r_a * exp(self.g * s),
                g: self.g,
            }
        }
    }

    /// Integrated hazard H(s) = r_a (e^{g s} - 1) / g = r_a s (e^{g s} - 1) / (g s).
    #[inline]
    pub fn hazard(&self, s: f64) -> f64 {
        let gs = self.g * s;
        if in_hazard_range(gs) {
            self.r_a * s * exp_m1_over_x(gs)
        } else {
            self.r_a * (self.g * s).exp_m1() / self.g
        }
    }

    /// The s at which H(s) = h, if the hazard ever gets there.
    #[inline]
    pub fn time_to(&self, h: f64) -> Option<f64> {
        if self.r_a <= 0.0 {
            return None;
        }
        if self.g == 0.0 {
            return Some(h / self.r_a);
        }
        let arg = h * self.g / self.r_a;
        (arg > -1.0).then(|| arg.ln_1p() / self.g)
    }
}

/// Whether `exp_m1_over_x_series` takes x.
#[inline(always)]
pub fn in_hazard_series_range(x: f64) -> bool {
    x.abs() < HAZARD_SERIES_MAX
}

/// Whether `exp_m1_over_x` takes x (its exponential's range).
#[inline(always)]
pub fn in_hazard_range(x: f64) -> bool {
    in_exp_range(x)
}

/// (e^x - 1) / x for |x| < 708: the series below 0.5, else from the exponential, where e^x - 1
/// loses at most a bit or two to cancellation (e^x is 0.61 or 1.65 at the ends). Both worked
/// out and one picked, branch-free, so that the dense path's vector loop and the one-pixel path
/// take the same bits: a shot-noise rate may change by more than e^0.5 over a frame (a
/// high-contrast pattern moving fast), and such pixels stay on the dense path.
#[inline(always)]
pub fn exp_m1_over_x(x: f64) -> f64 {
    let series = exp_m1_over_x_series(x);
    let from_exp = (exp_in_range(x) - 1.0) / x;
    if in_hazard_series_range(x) {
        series
    } else {
        from_exp
    }
}

/// The largest |x| the hazard's series takes: a shot-noise rate that changes by up to e^0.5 over
/// a frame interval, n |ln(x1 / x0)| < 0.5. A pixel whose log input moves 0.05 to 0.25 in a
/// frame (a moving pattern, not grain) stays on the dense path (`dense::step_quiet`), which
/// takes the series alone: with 0.05 here, a drifting sinusoid (0.15 events a pixel a frame)
/// sent 60 % of its pixel updates one at a time, half of them for the library's expm1; with
/// 0.5, 28 %, the events and the resets they leave.
pub const HAZARD_SERIES_MAX: f64 = 0.5;

/// (e^x - 1) / x = 1 + x/2 + x^2/6 + ... + x^15/16! for |x| < 0.5 (truncation x^16/17! < 5e-20),
/// branch-free where the library's expm1 would be a call, so that the dense path's vector loop
/// and the one-pixel path take the same bits. Estrin's scheme: a shallow tree of products, not
/// a chain of 15 dependent ones.
#[inline(always)]
pub fn exp_m1_over_x_series(x: f64) -> f64 {
    // 1 / (k + 1)!, k = 0..15.
    const C: [f64; 16] = [
        1.0,
        1.0 / 2.0,
        1.0 / 6.0,
        1.0 / 24.0,
        1.0 / 120.0,
        1.0 / 720.0,
        1.0 / 5040.0,
        1.0 / 40320.0,
        1.0 / 362880.0,
        1.0 / 3628800.0,
        1.0 / 39916800.0,
        1.0 / 479001600.0,
        1.0 / 6227020800.0,
        1.0 / 87178291200.0,
        1.0 / 1307674368000.0,
        1.0 / 20922789888000.0,
    ];
    let x2 = x * x;
    let x4 = x2 * x2;
    let x8 = x4 * x4;
    let pair = |k: usize| C[k] + x * C[k + 1];
    let low = (pair(0) + x2 * pair(2)) + x4 * (pair(4) + x2 * pair(6));
    let high = (pair(8) + x2 * pair(10)) + x4 * (pair(12) + x2 * pair(14));
    low + x8 * high
}

#[cfg(test)]
mod tests {
    use super::*;

    #[test]
    fn leak_rates_have_the_requested_mean_and_spread() {
        let mut p = SensorParams::ideal(1, 1);
        p.leak_rate_hz = 0.5;
        p.leak_spread_decades = 0.3;
        let n = 200_000u64;
        let rates: Vec<f64> = (0..n)
            .map(|i| leak_rate_hz(&p, Draw::new(p.seed, i, 0), 0.3))
            .collect();
        let mean = rates.iter().sum::<f64>() / n as f64;
        let logs: Vec<f64> = rates.iter().map(|r| r.log10()).collect();
        let lmean = logs.iter().sum::<f64>() / n as f64;
        let lsd = (logs.iter().map(|l| (l - lmean).powi(2)).sum::<f64>() / n as f64).sqrt();
        assert!((mean / 0.5 - 1.0).abs() < 0.01, "mean {mean}");
        assert!((lsd / 0.3 - 1.0).abs() < 0.01, "spread {lsd}");
    }

    #[test]
    fn leak_rates_follow_the_light_with_the_same_spread() {
        // Mean over pixels a + b x at every light level; each pixel keeps its factor.
        let mut p = SensorParams::ideal(1, 1);
        p.leak_rate_hz = 0.2;
        p.leak_light_rate_hz = 3.0;
        p.leak_spread_decades = 0.3;
        let n = 200_000u64;
        for x in [1e-4, 0.1, 1.0, 10.0] {
            let mean = (0..n)
                .map(|i| leak_rate_hz(&p, Draw::new(p.seed, i, 0), x))
                .sum::<f64>()
                / n as f64;
            let law = 0.2 + 3.0 * x;
            assert!((mean / law - 1.0).abs() < 0.01, "x {x}: {mean} vs {law}");
        }
        let frozen = Draw::new(p.seed, 7, 0);
        let ratio = leak_rate_hz(&p, frozen, 2.0) / leak_rate_hz(&p, frozen, 0.5);
        assert!((ratio - 6.2 / 1.7).abs() < 1e-12);
    }

    #[test]
    fn shot_rate_falls_in_inverse_proportion_to_light() {
        let mut p = SensorParams::ideal(1, 1);
        p.shot_rate_hz = 10.0;
        p.dark_current = 1e-4;
        assert!((shot_rate_hz(&p, 1e-4) - 10.0).abs() < 1e-12);
        assert!((shot_rate_hz(&p, 0.161) - 10.0 * 1e-4 / 0.161).abs() < 1e-15);
    }

    #[test]
    fn the_shot_wake_bound_comes_just_before_the_event_the_run_finds() {
        // At constant light the run finds the event at h / r (`GeometricRate::time_to`); the
        // wake-up bound, a product rounded otherwise, must never be later, and only just earlier.
        let mut p = SensorParams::ideal(1, 1);
        for i in 0..300_000u64 {
            let u = |k: u64| Draw::new(3, i, k).uniform(Stream::ShotTime);
            p.shot_light_exponent = [1.0, 2.0][i as usize % 2];
            p.shot_rate_hz = 10f64.powf(4.0 * u(0) - 2.0);
            p.dark_current = 10f64.powf(4.0 * u(1) - 6.0);
            let x = p.dark_current + 10f64.powf(9.0 * u(2) - 6.0);
            let budget = Draw::new(3, i, 9).exponential(Stream::ShotTime);
            let rate = GeometricRate {
                r_a: shot_rate_hz(&p, x),
                g: 0.0,
            };
            let event_s = rate.time_to(budget).unwrap();
            let bound_s = shot_budget_lower_bound_s(&p, budget, x);
            assert!(
                bound_s <= event_s && bound_s >= event_s * (1.0 - 1e-14),
                "{p:?} x {x} budget {budget}: {bound_s} vs {event_s}"
            );
        }
    }

    #[test]
    fn geometric_hazard_inverts_and_matches_quadrature() {
        let rate = GeometricRate { r_a: 3.0, g: -20.0 };
        let s = 0.04;
        let steps = 100_000;
        let quad: f64 = (0..steps)
            .map(|i| {
                let t = (i as f64 + 0.5) * s / steps as f64;
                3.0 * (-20.0 * t).exp() * s / steps as f64
            })
            .sum();
        assert!((rate.hazard(s) - quad).abs() < 1e-9);
        assert!((rate.time_to(rate.hazard(s)).unwrap() - s).abs() < 1e-12);
        assert_eq!(rate.time_to(1.0), None); // total hazard is only 0.15
    }

    #[test]
    fn the_hazard_factor_agrees_with_the_library_beyond_the_series() {
        // From the series' end out to rates changing by e^40 over an interval, either sign.
        for i in 0..=20_000 {
            let magnitude = HAZARD_SERIES_MAX + 40.0 * (i as f64 / 20_000.0).powi(2);
            for x in [magnitude, -magnitude] {
                let exact = x.exp_m1() / x;
                let got = exp_m1_over_x(x);
                // e^x - 1 cancels a little near the series' end (e^-0.5 - 1 = -0.39): within 4
                // ulps of the value.
                assert!(
                    (got - exact).abs() <= 4.0 * f64::EPSILON * exact,
                    "{x}: {got} vs {exact}"
                );
            }
        }
        // Below the series' end it is the series.
        assert_eq!(exp_m1_over_x(0.3), exp_m1_over_x_series(0.3));
    }

    #[test]
    fn the_hazard_series_agrees_with_the_library_where_it_is_used() {
        // Over the whole range, up to its ends, where (e^x - 1) / x is 0.787 and 1.297.
        for i in -10_000..=10_000 {
            let x = (HAZARD_SERIES_MAX - 1e-12) * i as f64 / 10_000.0;
            let exact = if x == 0.0 { 1.0 } else { x.exp_m1() / x };
            let got = exp_m1_over_x_series(x);
            // Both sides carry rounding (the reference its division too): within 3 ulps of the
            // value.
            assert!(
                (got - exact).abs() <= 3.0 * f64::EPSILON * exact,
                "{x}: {got} vs {exact}"
            );
        }
    }
}
