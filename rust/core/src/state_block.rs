//! Pixel states stored by field: one array per field for a block of `LANES` neighbouring pixels
//! (structure of arrays). The dense path steps a block's pixels together straight from these
//! arrays, with vector loads and stores, and reads only the fields it needs; a pixel stepped
//! alone is gathered into a `PixelState` and scattered back. 128 bytes a pixel, as one record.

use crate::pixel::PixelState;

/// Pixels in a block: the tile's blocks of 32 pixels that the scan tests together, and the
/// fewest for which the compiler vectorises a loop over a block's pixels (it leaves loops of 8
/// or 16 scalar).
pub const LANES: usize = 32;

/// Bit k set where `flags[k]`.
#[inline(always)]
pub fn bits_of(flags: &[bool; LANES]) -> u32 {
    let mut bits = 0;
    for (k, &flag) in flags.iter().enumerate() {
        bits |= (flag as u32) << k;
    }
    bits
}

/// `LANES` pixels' states, field by field (see `PixelState` for what each field means). The
/// first ten fields are those the dense path reads, and the next two those it reads where they
/// can matter (`dense::Inputs::gates`), so they can be fetched together.
#[derive(Clone, Copy, PartialEq)]
#[repr(C, align(64))]
pub struct StateBlock {
    pub t_s: [f64; LANES],
    pub u: [f64; LANES],
    pub x: [f64; LANES],
    pub v: [f64; LANES],
    pub ref0: [f64; LANES],
    pub t_ref_s: [f64; LANES],
    pub leak_drift: [f64; LANES],
    pub shot_budget: [f64; LANES],
    pub theta_on: [f64; LANES],
    pub theta_off: [f64; LANES],
    pub refractory_mark_s: [f64; LANES],
    pub hot_next_s: [f64; LANES],
    pub base_theta_on: [f64; LANES],
    pub base_theta_off: [f64; LANES],
    pub last_out_s: [f64; LANES],
    pub draws: [u64; LANES],
}

const _: () = assert!(std::mem::size_of::<StateBlock>() == LANES * 128);

impl StateBlock {
    /// A block whose states are yet to be made (all fields zero).
    pub fn empty() -> Self {
        let zeros = [0.0; LANES];
        Self {
            t_s: zeros,
            u: zeros,
            x: zeros,
            v: zeros,
            ref0: zeros,
            t_ref_s: zeros,
            leak_drift: zeros,
            shot_budget: zeros,
            theta_on: zeros,
            theta_off: zeros,
            refractory_mark_s: zeros,
            hot_next_s: zeros,
            base_theta_on: zeros,
            base_theta_off: zeros,
            last_out_s: zeros,
            draws: [0; LANES],
        }
    }

    /// Pixel `k`'s state.
    #[inline(always)]
    pub fn get(&self, k: usize) -> PixelState {
        PixelState {
            t_s: self.t_s[k],
            u: self.u[k],
            x: self.x[k],
            v: self.v[k],
            ref0: self.ref0[k],
            t_ref_s: self.t_ref_s[k],
            leak_drift: self.leak_drift[k],
            shot_budget: self.shot_budget[k],
            theta_on: self.theta_on[k],
            theta_off: self.theta_off[k],
            refractory_mark_s: self.refractory_mark_s[k],
            hot_next_s: self.hot_next_s[k],
            base_theta_on: self.base_theta_on[k],
            base_theta_off: self.base_theta_off[k],
            last_out_s: self.last_out_s[k],
            draws: self.draws[k],
        }
    }

    /// Pixel `k`'s state becomes `st`.
    #[inline(always)]
    pub fn set(&mut self, k: usize, st: &PixelState) {
        self.t_s[k] = st.t_s;
        self.u[k] = st.u;
        self.x[k] = st.x;
        self.v[k] = st.v;
        self.ref0[k] = st.ref0;
        self.t_ref_s[k] = st.t_ref_s;
        self.leak_drift[k] = st.leak_drift;
        self.shot_budget[k] = st.shot_budget;
        self.theta_on[k] = st.theta_on;
        self.theta_off[k] = st.theta_off;
        self.refractory_mark_s[k] = st.refractory_mark_s;
        self.hot_next_s[k] = st.hot_next_s;
        self.base_theta_on[k] = st.base_theta_on;
        self.base_theta_off[k] = st.base_theta_off;
        self.last_out_s[k] = st.last_out_s;
        self.draws[k] = st.draws;
    }
}

#[cfg(test)]
mod tests {
    use super::*;

    #[test]
    fn a_state_set_is_the_state_got_and_leaves_the_other_lanes_alone() {
        // Every field a different value, so a field written to or read from the wrong array
        // shows.
        let st = |base: f64| PixelState {
            t_s: base + 1.0,
            u: base + 2.0,
            x: base + 3.0,
            v: base + 4.0,
            ref0: base + 5.0,
            t_ref_s: base + 6.0,
            leak_drift: base + 7.0,
            theta_on: base + 8.0,
            theta_off: base + 9.0,
            base_theta_on: base + 10.0,
            base_theta_off: base + 11.0,
            refractory_mark_s: base + 12.0,
            last_out_s: base + 13.0,
            shot_budget: base + 14.0,
            hot_next_s: base + 15.0,
            draws: base as u64 + 16,
        };
        let mut block = StateBlock::empty();
        for k in 0..LANES {
            block.set(k, &st(100.0 * k as f64));
        }
        block.set(5, &st(-50.0));
        for k in 0..LANES {
            let want = if k == 5 {
                st(-50.0)
            } else {
                st(100.0 * k as f64)
            };
            assert_eq!(block.get(k), want, "lane {k}");
        }
    }
}
