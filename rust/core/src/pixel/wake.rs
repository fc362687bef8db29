//! When a pixel next needs stepping while its input stays constant: a lower bound on its next
//! crossing, reset release or noise event (`PixelModel::wake_s`), without root solving, so that
//! a frame with the same input can skip it until then.

use super::{PixelModel, PixelState};
use crate::crossing::{lesser, Difference};
use crate::exp::exp;
use crate::noise;

impl PixelModel {
    /// A lower bound on when this pixel next needs attention if its input stays constant (its
    /// next crossing, reset release or noise event). Before then a frame with the same input
    /// changes nothing. A bound, not the exact time, keeps root solving off the per-frame path.
    pub fn wake_s(&self, st: &PixelState) -> f64 {
        let mut wake = st.hot_next_s;
        if self.params.shot_rate_hz > 0.0 {
            let shot_s = noise::shot_budget_lower_bound_s(&self.params, st.shot_budget, st.x);
            wake = lesser(wake, st.t_s + shot_s);
        }
        let tau = self.receptor.tau_s(st.x);
        if self.is_blind(st) {
            // A time-invariant pixel's quiet band holds only until the reference is memorised
            // again, so it is stepped then. Any other pixel is stepped at its next input change
            // anyway, which runs the release; until then only a crossing after it matters.
            if self.is_time_invariant() {
                return wake.min(st.refractory_mark_s);
            }
            let d = self.difference_after_release(st, tau);
            return wake.min(st.refractory_mark_s + first_reach_either(&d, st));
        }
        let d = self.difference(st, 0.0, tau, 1.0 / tau);
        lesser(wake, st.t_s + first_reach_either(&d, st))
    }

    /// v - ref from the end of the refractory period on, with constant input: the reference is
    /// then memorised at v, which has relaxed towards u since the state's time.
    fn difference_after_release(&self, st: &PixelState, tau: f64) -> Difference {
        let v_release = if tau > 0.0 {
            st.u + (st.v - st.u) * exp(-(st.refractory_mark_s - st.t_s) / tau)
        } else {
            st.u
        };
        Difference::new(
            st.u - v_release,
            st.leak_drift,
            if tau > 0.0 { v_release - st.u } else { 0.0 },
            tau,
        )
    }
}

/// A lower bound on when `d` first reaches the ON threshold or falls to the OFF one.
fn first_reach_either(d: &Difference, st: &PixelState) -> f64 {
    lesser(
        first_reach_lower_bound(d, st.theta_on),
        first_reach_lower_bound(&d.negated(), st.theta_off),
    )
}

/// A lower bound on the first s >= 0 with d(s) >= level, without root solving. While
/// d <= a + m s + max(c, 0) keeps d below the level only drift (leak) can take it there, and
/// is bounded linearly. Otherwise c < 0 and the low-pass settles towards a past the level:
/// over a horizon of a few time constants d <= a + max(m, 0) horizon + c e^{-s/tau}, whose
/// crossing has a closed form (exact without drift); a pixel that has not crossed by the
/// horizon is looked at again then.
fn first_reach_lower_bound(d: &Difference, level: f64) -> f64 {
    if d.at(0.0) >= level {
        return 0.0;
    }
    let room = level - d.a - d.c.max(0.0);
    if room > 0.0 {
        return if d.m > 0.0 { room / d.m } else { f64::INFINITY };
    }
    if d.tau == 0.0 {
        // Without a low-pass c = 0, so room <= 0 meant d(0) >= level, returned above.
        return 0.0;
    }
    let horizon_s = SETTLING_TIME_CONSTANTS * d.tau;
    let a_max = d.a + d.m.max(0.0) * horizon_s;
    if a_max <= level {
        return horizon_s;
    }
    let drift_free = Difference {
        a: a_max,
        m: 0.0,
        ..*d
    };
    let s = drift_free.settling_time(level) - WAKE_MARGIN_S;
    s.clamp(0.0, horizon_s)
}

/// The horizon of the settling bound: after 4 time constants the low-pass has covered 98 %.
const SETTLING_TIME_CONSTANTS: f64 = 4.0;
/// How much earlier than its closed-form crossing a pixel is woken: 10 times the tolerance of
/// the solver that times the crossing when the pixel is stepped.
pub(super) const WAKE_MARGIN_S: f64 = 1e-9;

#[cfg(test)]
mod tests {
    use super::*;
    use crate::crossing::brute_first_reach;
    use crate::rng::{Draw, Stream};

    /// Settling and drifting curves of every sign, as the pixel meets them.
    fn differences() -> impl Iterator<Item = (Difference, f64)> {
        (0..3000u64).map(|i| {
            let u = |k: u64| Draw::new(1, i, k).uniform(Stream::Theta);
            let tau = [0.0, 1e-4, 2e-3, 5e-2][i as usize % 4];
            let d = Difference::new(
                0.6 * (2.0 * u(0) - 1.0),
                [0.0, 0.02, -0.02, 40.0, -40.0][(i / 4) as usize % 5] * u(1),
                if tau > 0.0 {
                    0.6 * (2.0 * u(2) - 1.0)
                } else {
                    0.0
                },
                tau,
            );
            (d, 0.05 + 0.3 * u(3))
        })
    }

    #[test]
    fn the_wake_bound_never_comes_after_the_crossing() {
        let mut settling = 0;
        for (d, level) in differences() {
            let bound = first_reach_lower_bound(&d, level);
            let s_max = if d.tau > 0.0 { 20.0 * d.tau } else { 1.0 };
            if let Some(exact) = brute_first_reach(&d, level, s_max) {
                assert!(
                    bound <= exact + 1e-12,
                    "{d:?} level {level}: {bound} > {exact}"
                );
                if d.m == 0.0 && d.c < 0.0 && exact > 0.0 && exact < SETTLING_TIME_CONSTANTS * d.tau
                {
                    // Without drift the settling bound is the crossing itself (within its horizon).
                    settling += 1;
                    assert!(
                        exact - bound < 1e-8 + 1e-9 * exact,
                        "{d:?}: {bound} vs {exact}"
                    );
                }
            }
        }
        assert!(settling > 50, "only {settling} settling cases");
    }
}
