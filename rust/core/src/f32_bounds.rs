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

/// A quiet band (lo, hi) as a tile keeps it: the f32s inside it (lo rounded up, hi down), so
/// that no input outside the f64 band passes the scan.
#[inline(always)]
pub fn band_inside_f32((lo, hi): (f64, f64)) -> (f32, f32) {
    (round_up_f32(lo), round_down_f32(hi))
}

/// The smallest f32 not below `v` (NaN stays NaN), without a branch as `round_down_f32`.
#[inline(always)]
pub fn round_up_f32(v: f64) -> f32 {
    let f = v as f32;
    let bits = f.to_bits();
    let up = if f == 0.0 {
        1
    } else if bits >> 31 == 0 {
        bits.wrapping_add(1)
    } else {
        bits.wrapping_sub(1)
    };
    if (f as f64) < v {
        f32::from_bits(up)
    } else {
        f
    }
}

#[cfg(test)]
mod tests {
    use super::*;

    #[test]
    fn rounding_gives_the_nearest_f32_on_the_safe_side() {
        // Against the definitions by the standard library's next_up and next_down, on values
        // that round up, down and exactly, of both signs, near zero, subnormal, huge and
        // infinite, and random bit patterns of every exponent (NaN included).
        let down = |v: f64| {
            let f = v as f32;
            if (f as f64) > v {
                f.next_down()
            } else {
                f
            }
        };
        let up = |v: f64| {
            let f = v as f32;
            if (f as f64) < v {
                f.next_up()
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
            f32::from_bits(1) as f64 * 0.5,
            -(f32::from_bits(1) as f64) * 0.75,
            f32::MIN_POSITIVE as f64,
            f32::MAX as f64,
            f32::MAX as f64 * (1.0 + 1e-9),
            -(f32::MAX as f64) * (1.0 + 1e-9),
            1e300,
            -1e300,
            f64::INFINITY,
            f64::NEG_INFINITY,
            f64::NAN,
        ];
        let mut z = 0x9e37_79b9_7f4a_7c15u64;
        for _ in 0..200_000 {
            z = z.wrapping_mul(6_364_136_223_846_793_005).wrapping_add(1);
            values.push(f64::from_bits(z.rotate_right(1)));
        }
        let same = |a: f32, b: f32| a.to_bits() == b.to_bits() || (a.is_nan() && b.is_nan());
        for v in values {
            let (low, high) = (round_down_f32(v), round_up_f32(v));
            assert!(
                same(low, down(v)),
                "{v:e}: down {low:e} against {:e}",
                down(v)
            );
            assert!(same(high, up(v)), "{v:e}: up {high:e} against {:e}", up(v));
            assert!(v.is_nan() || (low as f64 <= v && high as f64 >= v), "{v:e}");
        }
    }
}
