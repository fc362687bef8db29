//! Reflectance of a lens surface, bare or under one film of index n1 and thickness d between
//! media n0 (incident side) and n2: the Airy sum r = (r01 + r12 e^{i delta}) / (1 + r01 r12
//! e^{i delta}), delta = 4 pi n1 d cos(theta1) / lambda (Born & Wolf, Principles of Optics,
//! 1.6.4), with each interface's Fresnel coefficients for s and p light (Hecht, Optics, 4.42-4.43);
//! R = |r|^2, unpolarised light the mean of s and p. Where neither the film nor n2 totally
//! reflects, every coefficient is real and |r|^2 = (r01^2 + r12^2 + 2 r01 r12 cos delta) /
//! (1 + r01^2 r12^2 + 2 r01 r12 cos delta); past total internal reflection the cosines are
//! imaginary (evanescent waves) and the sum is taken in complex numbers.

use num_complex::Complex64;

/// Amplitude reflection coefficients (s, p) of one interface from n_i into n_t.
fn fresnel_rs_rp<T>(n_i: T, n_t: T, cos_i: T, cos_t: T) -> (T, T)
where
    T: Copy + std::ops::Mul<Output = T> + std::ops::Sub<Output = T> + std::ops::Add<Output = T>,
    T: std::ops::Div<Output = T>,
{
    let rs = (n_i * cos_i - n_t * cos_t) / (n_i * cos_i + n_t * cos_t);
    let rp = (n_t * cos_i - n_i * cos_t) / (n_t * cos_i + n_i * cos_t);
    (rs, rp)
}

/// (R_s, R_p) of a film of index `n1`, `thickness_nm` thick, between n0 (incident) and n2, at
/// incidence cos(theta0) = `cos0` and `wavelength_nm`; thickness 0 is the bare interface n0 | n2.
pub fn film_reflectance(
    n0: f64,
    n1: f64,
    n2: f64,
    thickness_nm: f64,
    wavelength_nm: f64,
    cos0: f64,
) -> (f64, f64) {
    let sin2_0 = (1.0 - cos0 * cos0).max(0.0);
    let s1 = (n0 / n1) * (n0 / n1) * sin2_0;
    let s2 = (n0 / n2) * (n0 / n2) * sin2_0;
    if !(s1 < 1.0 && s2 < 1.0) {
        return film_reflectance_complex(n0, n1, n2, thickness_nm, wavelength_nm, cos0, s1, s2);
    }
    let c1 = (1.0 - s1).sqrt();
    let c2 = (1.0 - s2).sqrt();
    let cos_delta = (4.0 * std::f64::consts::PI * n1 * thickness_nm * c1 / wavelength_nm).cos();
    // r01 = a / b and r12 = c / e (Fresnel's numerators and denominators): the Airy sum
    // multiplied through by b^2 e^2 takes one division a polarisation instead of three.
    let airy = |a: f64, b: f64, c: f64, e: f64| {
        let cross = 2.0 * a * b * c * e * cos_delta;
        let (ae, cb) = (a * e, c * b);
        (ae * ae + cb * cb + cross) / ((b * e) * (b * e) + (a * c) * (a * c) + cross)
    };
    let rs = airy(
        n0 * cos0 - n1 * c1,
        n0 * cos0 + n1 * c1,
        n1 * c1 - n2 * c2,
        n1 * c1 + n2 * c2,
    );
    let rp = airy(
        n1 * cos0 - n0 * c1,
        n1 * cos0 + n0 * c1,
        n2 * c1 - n1 * c2,
        n2 * c1 + n1 * c2,
    );
    (rs, rp)
}

/// The cosine of the refraction angle whose sine squared is `sin2`: real below 1, else the
/// imaginary root of the wave that decays away from the interface.
fn cos_refracted(sin2: f64) -> Complex64 {
    let x = 1.0 - sin2;
    if x >= 0.0 {
        Complex64::new(x.sqrt(), 0.0)
    } else {
        Complex64::new(0.0, (-x).sqrt())
    }
}

/// The Airy sum in complex numbers (past total internal reflection in the film or in n2).
#[allow(clippy::too_many_arguments)]
fn film_reflectance_complex(
    n0: f64,
    n1: f64,
    n2: f64,
    thickness_nm: f64,
    wavelength_nm: f64,
    cos0: f64,
    sin2_1: f64,
    sin2_2: f64,
) -> (f64, f64) {
    let (n0c, n1c, n2c) = (
        Complex64::from(n0),
        Complex64::from(n1),
        Complex64::from(n2),
    );
    let c0 = Complex64::from(cos0);
    let (c1, c2) = (cos_refracted(sin2_1), cos_refracted(sin2_2));
    let delta = n1c * c1 * (4.0 * std::f64::consts::PI * thickness_nm / wavelength_nm);
    let phase = (Complex64::i() * delta).exp();
    let (rs01, rp01) = fresnel_rs_rp(n0c, n1c, c0, c1);
    let (rs12, rp12) = fresnel_rs_rp(n1c, n2c, c1, c2);
    let airy = |r01: Complex64, r12: Complex64| {
        ((r01 + r12 * phase) / (Complex64::from(1.0) + r01 * r12 * phase)).norm_sqr()
    };
    (airy(rs01, rs12), airy(rp01, rp12))
}

/// Unpolarised reflectance (the mean of s and p) of a surface from n0 into n2 at incidence
/// cos(theta0), under a film (`film_index`, `thickness_nm`) or bare (thickness 0).
pub fn reflectance(
    n0: f64,
    n2: f64,
    cos0: f64,
    wavelength_nm: f64,
    film_index: f64,
    thickness_nm: f64,
) -> f64 {
    let (rs, rp) = film_reflectance(n0, film_index, n2, thickness_nm, wavelength_nm, cos0);
    0.5 * (rs + rp)
}

#[cfg(test)]
mod tests {
    use super::*;

    #[test]
    fn a_quarter_wave_film_at_normal_incidence_and_its_design_wavelength() {
        // ((n0 n2 - n1^2) / (n0 n2 + n1^2))^2 (Hecht, Optics, 9.9).
        for (n0, n1, n2) in [(1.0_f64, 1.38, 1.52), (1.0, 1.38, 1.9), (1.7, 1.45, 1.5)] {
            let lambda0 = 550.0;
            let d = lambda0 / (4.0 * n1);
            let want = ((n0 * n2 - n1 * n1) / (n0 * n2 + n1 * n1)).powi(2);
            let (rs, rp) = film_reflectance(n0, n1, n2, d, lambda0, 1.0);
            assert!(
                (rs - want).abs() < 1e-14 && (rp - want).abs() < 1e-14,
                "{n0} {n1} {n2}"
            );
        }
        // The ideal film sqrt(n0 n2) reflects nothing.
        let n1 = 1.52_f64.sqrt();
        assert!(reflectance(1.0, 1.52, 1.0, 550.0, n1, 550.0 / (4.0 * n1)) < 1e-30);
    }

    #[test]
    fn a_half_wave_film_is_absent_at_its_wavelength() {
        let (n0, n1, n2) = (1.0_f64, 1.38, 1.6);
        let bare = ((n0 - n2) / (n0 + n2)).powi(2);
        let r = reflectance(n0, n2, 1.0, 550.0, n1, 550.0 / (2.0 * n1));
        assert!((r - bare).abs() < 1e-14);
    }

    #[test]
    fn a_bare_interface_is_fresnel() {
        // Normal incidence: ((n0 - n2) / (n0 + n2))^2; Brewster's angle tan(theta) = n2 / n0: R_p = 0.
        assert!((reflectance(1.0, 1.5, 1.0, 550.0, 1.0, 0.0) - 0.04).abs() < 1e-15);
        let brewster = (1.5_f64).atan();
        let (rs, rp) = film_reflectance(1.0, 1.0, 1.5, 0.0, 550.0, brewster.cos());
        assert!(rp < 1e-30);
        // R_s = sin^2(theta_i - theta_t) / sin^2(theta_i + theta_t) (Hecht 4.42), theta_t = 90 deg - theta_i.
        let theta_t = std::f64::consts::FRAC_PI_2 - brewster;
        let want = ((brewster - theta_t).sin() / (brewster + theta_t).sin()).powi(2);
        assert!((rs - want).abs() < 1e-14);
    }

    #[test]
    fn past_total_internal_reflection_everything_reflects() {
        // Glass 1.5 to air past asin(1 / 1.5): bare or under any lossless film, R = 1.
        let cos0 = 0.5_f64; // 60 degrees
        for (n1, d) in [(1.0, 0.0), (1.38, 99.6), (1.2, 500.0)] {
            let (rs, rp) = film_reflectance(1.5, n1, 1.0, d, 550.0, cos0);
            assert!(
                (rs - 1.0).abs() < 1e-13 && (rp - 1.0).abs() < 1e-13,
                "{n1} {d}"
            );
        }
    }
}
