//! f32 bounds of f64 values: the gates a tile keeps per pixel (quiet bands, wake-up times) are
//! f32 to halve the memory a frame's scan reads, rounded outwards so that they never let a pixel
//! skip a step it needs.

/// The largest f32 not above `v` (NaN stays NaN). Without a branch, so loops over it vectorise:
/// `f32::next_down` of a rounded-up `f` is one step of its bits towards -inf, and from +-0 the
/// smallest negative subnormal.
#[inline(always)]
pub fn round_down_f32(v: f64) -> f32 {
    let f = v as f32;
    let bits = f.to_bits();
    let down = if f == 0.0 {
        0x8000_0001
    } else if bits >> 31 == 0 {
        bits.wrapping_sub(1)
    } else {
        bits.wrapping_add(1)
    };
    if (f as f64) > v {
        f32::from_bits(down)
    } else {
        f
    }
}

/// The smallest f32 not below `v` (NaN stays NaN).
pub fn round_up_f32(v: f64) -> f32 {
    let f = v as f32;
    if (f as f64) < v {
        f.next_up()
    } else {
        f
    }
}

#[cfg(test)]
mod tests {
    use super::*;

    #[test]
    fn round_down_f32_is_the_largest_f32_not_above() {
        // Against the definition by the standard library's next_down, on values that round
        // up, down and exactly, of both signs, near zero, subnormal, huge and infinite.
        let reference = |v: f64| {
            let f = v as f32;
            if (f as f64) > v {
                f.next_down()
            } else {
                f
            }
        };
        let mut values = vec![
            0.0,
            -0.0,
            1e-300,
            -1e-300,
            1e-45,
            -1e-45,
            f32::MIN_POSITIVE as f64,
            f32::MAX as f64,
            f32::MAX as f64 * (1.0 + 1e-9),
            -(f32::MAX as f64) * (1.0 + 1e-9),
            1e300,
            -1e300,
            f64::INFINITY,
            f64::NEG_INFINITY,
        ];
        let mut z = 0x9e37_79b9_7f4a_7c15u64;
        for _ in 0..100_000 {
            z = z.wrapping_mul(6_364_136_223_846_793_005).wrapping_add(1);
            values.push(f64::from_bits(z.rotate_right(1)));
        }
        for v in values {
            let (got, want) = (round_down_f32(v), reference(v));
            assert!(
                got.to_bits() == want.to_bits() || (got.is_nan() && want.is_nan()),
                "{v:e}: {got:e} against {want:e}"
            );
            assert!(v.is_nan() || got as f64 <= v, "{v:e}: {got:e} is above");
        }
    }
}
