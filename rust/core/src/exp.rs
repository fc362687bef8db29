//! The exponential and logarithm the pixel model evaluates millions of times a second (the
//! low-pass decay, the crossing solver, shot-noise rates, the photoreceptor's response), inlined
//! and without the C library's call and error-handling wrapper, which cost half again as much as
//! the function itself. Branch-free in their range, so a loop over pixels vectorises them: the
//! dense path (`dense`) and the one-pixel path compute the same bits.
//!
//! e^x = 2^(k/32) e^r with k = round(32 x / ln 2) and |r| <= ln 2 / 64 (Tang, "Table-driven
//! implementation of the exponential function in IEEE floating-point arithmetic", ACM TOMS 1989):
//! 2^(k/32) is 2^(k div 32) times one of 32 tabulated values, e^r a degree-6 Taylor polynomial
//! (truncation error r^7/7! < 4e-18). Never more than 1 ulp from the C library's value.

/// 2^(j/32) for j = 0..31, correctly rounded (as bit patterns).
const TWO_TO_J_OVER_32: [u64; 32] = [
    0x3ff0000000000000,
    0x3ff059b0d3158574,
    0x3ff0b5586cf9890f,
    0x3ff11301d0125b51,
    0x3ff172b83c7d517b,
    0x3ff1d4873168b9aa,
    0x3ff2387a6e756238,
    0x3ff29e9df51fdee1,
    0x3ff306fe0a31b715,
    0x3ff371a7373aa9cb,
    0x3ff3dea64c123422,
    0x3ff44e086061892d,
    0x3ff4bfdad5362a27,
    0x3ff5342b569d4f82,
    0x3ff5ab07dd485429,
    0x3ff6247eb03a5585,
    0x3ff6a09e667f3bcd,
    0x3ff71f75e8ec5f74,
    0x3ff7a11473eb0187,
    0x3ff82589994cce13,
    0x3ff8ace5422aa0db,
    0x3ff93737b0cdc5e5,
    0x3ff9c49182a3f090,
    0x3ffa5503b23e255d,
    0x3ffae89f995ad3ad,
    0x3ffb7f76f2fb5e47,
    0x3ffc199bdd85529c,
    0x3ffcb720dcef9069,
    0x3ffd5818dcfba487,
    0x3ffdfc97337b9b5f,
    0x3ffea4afa2a490da,
    0x3fff50765b6e4540,
];
/// 32 / ln 2.
const INV_LN2_32: f64 = 46.166_241_308_446_83;
/// ln 2 / 32 split in two: the high part has 20 trailing zero bits, so k times it is exact.
const LN2_32_HI: u64 = 0x3f96_2e42_fef0_0000;
const LN2_32_LO: u64 = 0x3d84_73de_6af2_78ed;
/// 1.5 * 2^52: adding it rounds to an integer, which then sits in the low bits.
const ROUNDER: f64 = 6_755_399_441_055_744.0;

/// e^x; NaN, infinities and results that overflow or are subnormal go to the C library.
#[inline]
pub fn exp(x: f64) -> f64 {
    if !in_exp_range(x) {
        return x.exp();
    }
    exp_in_range(x)
}

/// Whether `exp_in_range` takes x: |x| < 708 (not NaN).
#[inline(always)]
pub fn in_exp_range(x: f64) -> bool {
    x.abs() < 708.0
}

/// e^x for |x| < 708, without a branch (any other x gives a wrong value, not a fault).
#[inline(always)]
pub fn exp_in_range(x: f64) -> f64 {
    let shifted = x * INV_LN2_32 + ROUNDER;
    let k = shifted.to_bits().wrapping_sub(ROUNDER.to_bits()) as i64;
    let kf = shifted - ROUNDER;
    let r = (x - kf * f64::from_bits(LN2_32_HI)) - kf * f64::from_bits(LN2_32_LO);
    // 2^(k div 32) goes straight into the exponent field of 2^(j/32): |x| < 708 keeps it normal.
    let table = TWO_TO_J_OVER_32[(k & 31) as usize];
    let scale = f64::from_bits(table.wrapping_add(((k >> 5) as u64) << 52));
    let r2 = r * r;
    // e^r - 1, Estrin-style so the terms are not one long chain.
    let e_r_minus_1 = r + r2
        * ((0.5 + r * (1.0 / 6.0)) + r2 * ((1.0 / 24.0 + r * (1.0 / 120.0)) + r2 * (1.0 / 720.0)));
    scale + scale * e_r_minus_1
}

/// ln x; zero, negative, subnormal, infinite and NaN x go to the C library.
#[inline]
pub fn ln(x: f64) -> f64 {
    if !in_ln_range(x) {
        return x.ln();
    }
    ln_in_range(x)
}

/// Whether `ln_in_range` takes x: a positive normal finite number.
#[inline(always)]
pub fn in_ln_range(x: f64) -> bool {
    (f64::MIN_POSITIVE..=f64::MAX).contains(&x)
}

// ln(1 + f) = f - f^2/2 + s (f^2/2 + R(s^2)) with s = f / (2 + f) and R the minimax polynomial
// of fdlibm's e_log.c (Sun Microsystems 1993; error below 1 ulp), on x = 2^k (1 + f) with
// sqrt(2)/2 <= 1 + f < sqrt(2).
const LG: [u64; 7] = [
    0x3fe5_5555_5555_5593,
    0x3fd9_9999_9997_fa04,
    0x3fd2_4924_9422_9359,
    0x3fcc_71c5_1d8e_78af,
    0x3fc7_4664_96cb_03de,
    0x3fc3_9a09_d078_c69f,
    0x3fc2_f112_df3e_5244,
];
/// ln 2 split in two: the high part has 32 trailing zero bits, so k times it is exact.
const LN2_HI: u64 = 0x3fe6_2e42_fee0_0000;
const LN2_LO: u64 = 0x3dea_39ef_3579_3c76;

/// ln x for a positive normal finite x, without a branch (any other x gives a wrong value).
#[inline(always)]
pub fn ln_in_range(x: f64) -> f64 {
    // The mantissa moved to [sqrt(2)/2, sqrt(2)) by adding the distance of 1 to sqrt(2)/2 to
    // the high word before the exponent is read off.
    let bits = x.to_bits();
    let high = (bits >> 32) as u32;
    let shifted = high.wrapping_add(0x3ff0_0000 - 0x3fe6_a09e);
    let k = (shifted >> 20) as i32 - 0x3ff;
    let high = (shifted & 0x000f_ffff) + 0x3fe6_a09e;
    let m = f64::from_bits(((high as u64) << 32) | (bits & 0xffff_ffff));
    let f = m - 1.0;
    let half_f2 = 0.5 * f * f;
    let s = f / (2.0 + f);
    let z = s * s;
    let w = z * z;
    let lg = LG.map(f64::from_bits);
    let t1 = w * (lg[1] + w * (lg[3] + w * lg[5]));
    let t2 = z * (lg[0] + w * (lg[2] + w * (lg[4] + w * lg[6])));
    let r = t2 + t1;
    let dk = k as f64;
    s * (half_f2 + r) + dk * f64::from_bits(LN2_LO) - half_f2 + f + dk * f64::from_bits(LN2_HI)
}

#[cfg(test)]
mod tests {
    use super::*;

    /// Distance in units in the last place between two positive finite values.
    fn ulps(a: f64, b: f64) -> u64 {
        a.to_bits().abs_diff(b.to_bits())
    }

    #[test]
    fn within_one_ulp_of_the_library_everywhere() {
        // A million points over the whole fast range, and as many where the pixel model lives.
        let n = 1_000_000;
        let mut worst = 0;
        for i in 0..=n {
            let x = -707.9 + 1415.8 * i as f64 / n as f64;
            worst = worst.max(ulps(exp(x), x.exp()));
        }
        for i in 0..=n {
            let x = -1.0 + 2.0 * i as f64 / n as f64;
            worst = worst.max(ulps(exp(x), x.exp()));
        }
        assert!(worst <= 1, "{worst} ulps");
    }

    #[test]
    fn ln_within_one_ulp_of_the_library_everywhere() {
        // Geometric steps over the whole normal range, and linear ones where photocurrents live.
        let mut worst = 0;
        let n = 1_000_000;
        for i in 0..=n {
            let x = f64::MIN_POSITIVE * (f64::MAX / f64::MIN_POSITIVE).powf(i as f64 / n as f64);
            worst = worst.max(ulps(ln(x).abs(), x.ln().abs()));
        }
        for i in 1..=n {
            let x = 2.0 * i as f64 / n as f64;
            worst = worst.max(ulps(ln(x).abs(), x.ln().abs()));
        }
        assert!(worst <= 1, "{worst} ulps");
        assert_eq!(ln(1.0), 0.0);
        assert_eq!(ln(std::f64::consts::E), 1.0);
        assert_eq!(ln(0.0), f64::NEG_INFINITY);
        assert!(ln(-1.0).is_nan() && ln(f64::NAN).is_nan());
        assert_eq!(ln(f64::INFINITY), f64::INFINITY);
        assert_eq!(ln(1e-310), 1e-310f64.ln()); // subnormal: the library's
    }

    #[test]
    fn exact_points_and_special_values() {
        assert_eq!(exp(0.0), 1.0);
        assert_eq!(exp(-0.0), 1.0);
        assert_eq!(exp(1.0), std::f64::consts::E);
        assert_eq!(exp(std::f64::consts::LN_2), 2.0);
        assert_eq!(exp(f64::NEG_INFINITY), 0.0);
        assert_eq!(exp(f64::INFINITY), f64::INFINITY);
        assert_eq!(exp(1000.0), f64::INFINITY);
        assert_eq!(exp(-1000.0), 0.0);
        assert!(exp(f64::NAN).is_nan());
        assert_eq!(exp(-740.0), (-740.0f64).exp()); // subnormal: the library's
    }
}
