//! Exact threshold-crossing times of the first-order photoreceptor driven by a linear input.
//!
//! Over an interval where the input is u(s) = u_a + g s and the reference drifts down at k per
//! second (leak), the low-pass dv/ds = (u - v) / tau has the closed-form solution
//!   v(s) = u(s) - g tau + (v_a - u_a + g tau) e^{-s/tau},
//! so the difference to the reference is d(s) = a + m s + c e^{-s/tau} with m = g + k. Its
//! derivative changes sign at most once, which brackets every crossing for a safe Newton solve.

use crate::exp::exp;

/// d(s) = a + m s + c e^{-s/tau} (c = 0 when tau = 0).
#[derive(Clone, Copy, Debug, PartialEq)]
pub struct Difference {
    pub a: f64,
    pub m: f64,
    pub c: f64,
    pub tau: f64,
    /// 1 / tau (infinite for tau = 0): the curve's every exponential and slope divide by tau,
    /// and a product is several times cheaper than a division.
    pub inv_tau: f64,
}

impl Difference {
    /// The curve with these terms.
    #[inline(always)]
    pub fn new(a: f64, m: f64, c: f64, tau: f64) -> Self {
        Self {
            a,
            m,
            c,
            tau,
            inv_tau: 1.0 / tau,
        }
    }

    /// v - ref of a pixel from now on: input u and photoreceptor output v now, the reference
    /// now and its downward drift, the input's slope and the low-pass time constant and its
    /// inverse (the closed form above with a = u - g tau - ref, c = v - u + g tau, m = g + k).
    #[inline(always)]
    pub fn of_pixel(
        u: f64,
        v: f64,
        reference: f64,
        drift: f64,
        slope: f64,
        tau: f64,
        inv_tau: f64,
    ) -> Self {
        Self {
            a: u - slope * tau - reference,
            m: slope + drift,
            c: if tau > 0.0 { v - u + slope * tau } else { 0.0 },
            tau,
            inv_tau,
        }
    }

    #[inline]
    pub fn at(&self, s: f64) -> f64 {
        if self.c == 0.0 || s == 0.0 {
            self.a + self.c + self.m * s
        } else {
            self.a + self.m * s + self.c * exp(-s * self.inv_tau)
        }
    }

    /// A bound on d over [0, s_max] without an exponential, to rule crossings out cheaply.
    /// d <= a + max(m s_max, 0) + max(c, 0) always. For c < 0, d is concave, so it also lies
    /// below its tangent at 0, d(0) + d'(0) s: much tighter when the low-pass lags far behind
    /// a slow input (a dark pixel), where the first bound counts the whole lag |c|.
    #[inline]
    fn upper_bound(&self, s_max: f64) -> f64 {
        let loose = self.a + (self.m * s_max).max(0.0) + self.c.max(0.0);
        if self.c >= 0.0 {
            return loose;
        }
        let tangent = self.a + self.c + ((self.m - self.c * self.inv_tau) * s_max).max(0.0);
        lesser(loose, tangent)
    }

    /// The same curve upside down: OFF crossings are ON crossings of -d.
    #[inline]
    pub fn negated(&self) -> Self {
        Self {
            a: -self.a,
            m: -self.m,
            c: -self.c,
            ..*self
        }
    }

    /// The earliest s in [0, s_max] with d(s) >= level, if any (s_max may be infinite).
    pub fn first_reach(&self, level: f64, s_max: f64) -> Option<f64> {
        if self.at(0.0) >= level {
            return Some(0.0);
        }
        if s_max.is_finite() && self.upper_bound(s_max) < level {
            return None;
        }
        if self.c == 0.0 {
            return self.first_reach_linear(level, s_max);
        }
        // The only extremum, where m = (c / tau) e^{-s/tau}.
        let ratio = self.m * self.tau / self.c;
        let s_turn = if ratio > 0.0 && ratio < 1.0 {
            -self.tau * ratio.ln()
        } else {
            f64::INFINITY
        };
        let first_end = s_turn.min(s_max);
        if first_end.is_finite() {
            let d_end = self.at(first_end);
            if d_end >= level {
                return Some(self.solve_monotone(level, 0.0, first_end, d_end));
            }
        }
        if s_turn >= s_max {
            // One monotone piece: a finite end was checked above, an infinite one is a tail.
            return self.first_reach_asymptotic(level, s_max, 0.0);
        }
        // Second monotone piece [s_turn, s_max].
        if s_max.is_finite() {
            let d_max = self.at(s_max);
            return (d_max >= level).then(|| self.solve_monotone(level, s_turn, s_max, d_max));
        }
        self.first_reach_asymptotic(level, s_max, s_turn)
    }

    fn first_reach_linear(&self, level: f64, s_max: f64) -> Option<f64> {
        if self.m <= 0.0 {
            return None;
        }
        let s = (level - self.a) / self.m;
        (s <= s_max).then_some(s)
    }

    /// A monotone tail from `from` to s_max = infinity (or a finite end already ruled out).
    fn first_reach_asymptotic(&self, level: f64, s_max: f64, from: f64) -> Option<f64> {
        if s_max.is_finite() {
            return None;
        }
        if self.m > 0.0 {
            // d(s) >= a + m s - |c| for s >= 0, so this end is already past the level.
            let end = ((level - self.a + self.c.abs()) / self.m).max(from) + self.tau;
            return Some(self.solve_monotone(level, from.max(0.0).min(end), end, self.at(end)));
        }
        if self.m == 0.0 && self.a > level && self.c < 0.0 {
            return Some(self.settling_time(level));
        }
        None
    }

    /// When a + c e^{-s/tau}, d without its drift, reaches `level`: s = tau ln(c / (level - a)),
    /// for a low-pass settling (c < 0) towards an a past the level.
    pub fn settling_time(&self, level: f64) -> f64 {
        self.tau * (self.c / (level - self.a)).ln()
    }

    /// Root of d(s) = level on [lo, hi] where d is increasing through it, given d(hi): Halley
    /// steps from the secant's guess, kept inside a shrinking bracket (bisection when they
    /// leave it), to `TOLERANCE_S`. One exponential per step gives d and both its derivatives,
    /// and the convergence is cubic, so two or three steps are the rule.
    fn solve_monotone(&self, level: f64, mut lo: f64, mut hi: f64, d_hi: f64) -> f64 {
        let f_lo = self.at(lo) - level;
        if f_lo >= 0.0 {
            return lo;
        }
        let f_hi = d_hi - level;
        let mut s = if f_hi > 0.0 {
            lo + (hi - lo) * (-f_lo / (f_hi - f_lo))
        } else {
            hi
        };
        for _ in 0..100 {
            // decay = c e^{-s/tau}: d = a + m s + decay, d' = m - decay/tau, d'' = decay/tau^2.
            let decay = if self.c == 0.0 {
                0.0
            } else {
                self.c * exp(-s * self.inv_tau)
            };
            let f = self.a + self.m * s + decay - level;
            if f >= 0.0 {
                hi = s;
            } else {
                lo = s;
            }
            let (slope, curvature) = if self.c == 0.0 {
                (self.m, 0.0)
            } else {
                (
                    self.m - decay * self.inv_tau,
                    decay * self.inv_tau * self.inv_tau,
                )
            };
            let step = 2.0 * f * slope / (2.0 * slope * slope - f * curvature);
            let next = s - step;
            let converging = slope > 0.0 && next >= lo && next <= hi;
            if hi - lo <= TOLERANCE_S || (converging && step.abs() <= TOLERANCE_S) {
                // Within the tolerance of the root; on its far side when f >= 0 already.
                return if f >= 0.0 { s } else { next };
            }
            s = if converging { next } else { 0.5 * (lo + hi) };
        }
        hi
    }
}

/// The smaller of a and b in one vector instruction (a comparison that picks), where f64::min
/// takes three to also return b for a NaN a; here a NaN a stays. The pixel's bounds and wake-up
/// times take it, in the dense path and the one-pixel path alike, so both round the same.
#[inline(always)]
pub(crate) fn lesser(a: f64, b: f64) -> f64 {
    if b < a {
        b
    } else {
        a
    }
}

/// The larger of a and b in one vector instruction, as `lesser`.
#[inline(always)]
pub(crate) fn greater(a: f64, b: f64) -> f64 {
    if b > a {
        b
    } else {
        a
    }
}

/// How close to the true crossing a solved time is: far below the microsecond of the output.
pub(crate) const TOLERANCE_S: f64 = 1e-10;

/// Brute force, for tests: scan finely and refine the first sign change by bisection.
#[cfg(test)]
pub(crate) fn brute_first_reach(d: &Difference, level: f64, s_max: f64) -> Option<f64> {
    let n = 200_000;
    let mut prev = 0.0;
    for i in 1..=n {
        let s = s_max * i as f64 / n as f64;
        if d.at(s) >= level {
            let (mut lo, mut hi) = (prev, s);
            for _ in 0..100 {
                let mid = 0.5 * (lo + hi);
                if d.at(mid) >= level {
                    hi = mid
                } else {
                    lo = mid
                }
            }
            return Some(hi);
        }
        prev = s;
    }
    None
}

#[cfg(test)]
mod tests {
    use super::*;

    #[test]
    fn matches_brute_force_on_every_shape() {
        let cases = [
            Difference::new(0.0, 2.0, 0.0, 0.0),
            Difference::new(0.1, 0.0, -0.1, 0.01),
            Difference::new(0.5, 0.0, -0.5, 0.01),
            Difference::new(-0.3, 40.0, 0.3, 0.005),
            Difference::new(0.4, -10.0, -0.4, 0.01),
            Difference::new(0.05, 3.0, -0.05, 0.002),
        ];
        for d in cases {
            for level in [0.1, 0.2, 0.35] {
                let fast = d.first_reach(level, 0.1);
                let slow = brute_first_reach(&d, level, 0.1);
                match (fast, slow) {
                    (Some(f), Some(s)) => {
                        assert!((f - s).abs() < 1e-8, "{d:?} {level}: {f} vs {s}")
                    }
                    (None, None) => {}
                    _ => panic!("{d:?} level {level}: {fast:?} vs {slow:?}"),
                }
            }
        }
    }

    #[test]
    fn the_cheap_bound_is_above_the_curve() {
        for (a, m, c, tau) in [
            (0.1, 3.0, -0.8, 0.05),
            (-0.2, -1.0, 0.5, 0.01),
            (0.0, 40.0, -0.3, 0.005),
            (0.3, -10.0, -0.4, 0.01),
        ] {
            let d = Difference::new(a, m, c, tau);
            for s_max in [1e-4, 5e-4, 1e-2] {
                let bound = d.upper_bound(s_max);
                for i in 0..=1000 {
                    let s = s_max * i as f64 / 1000.0;
                    assert!(
                        d.at(s) <= bound + 1e-12,
                        "{d:?} at {s}: {} > {bound}",
                        d.at(s)
                    );
                }
            }
        }
    }

    #[test]
    fn infinite_horizon_has_closed_forms() {
        // Settling towards an asymptote above the level: s = tau ln(c / (level - a)).
        let d = Difference::new(0.5, 0.0, -0.5, 0.01);
        let s = d.first_reach(0.2, f64::INFINITY).unwrap();
        assert!((s - 0.01 * (0.5f64 / 0.3).ln()).abs() < 1e-12);
        // An asymptote below the level is never reached.
        let d = Difference::new(0.1, 0.0, -0.1, 0.01);
        assert_eq!(d.first_reach(0.2, f64::INFINITY), None);
        // A drift always gets there.
        let d = Difference::new(0.0, 0.5, 0.0, 0.0);
        assert!((d.first_reach(0.2, f64::INFINITY).unwrap() - 0.4).abs() < 1e-12);
        let d = Difference::new(0.0, 0.5, -0.1, 0.01);
        let s = d.first_reach(0.2, f64::INFINITY).unwrap();
        assert!((d.at(s) - 0.2).abs() < 1e-9);
    }
}
