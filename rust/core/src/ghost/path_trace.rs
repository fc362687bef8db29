//! A ghost ray following its path from the entrance plane to the film: at each step it meets
//! its surface (`interface`), is clipped by the surface's semi-aperture, refracts or reflects,
//! and its weight in each band is multiplied by R where it reflects and 1 - R where it crosses
//! (`thin_film`, at its angle, the band's wavelength and the media on the two sides); a ray
//! that misses, leaves the aperture or is totally reflected where it should cross is lost.
//! Rays are independent: blocks of them run on rayon's threads, the same on any thread count.

use std::fmt;

use rayon::prelude::*;

use super::interface::{cos_incidence, intersect, reflect, refract, Vec3};
use super::thin_film::reflectance;

/// Rays a block: enough work per task that the threads' hand-over does not show.
const BLOCK_RAYS: usize = 256;

/// The surfaces in the order light meets them (lens, then cover glass and die), each with
/// its coating, and the media between them per band.
pub struct Surfaces<'a> {
    pub vertex_z_mm: &'a [f64],
    /// Signed radius of curvature; 0: flat.
    pub radius_mm: &'a [f64],
    /// Squared semi-aperture: a ray farther from the axis where it meets the surface is lost.
    pub semi_aperture2_mm2: &'a [f64],
    /// A reflectance that does not depend on angle or wavelength (the die); < 0: the film's.
    pub fixed_reflectance: &'a [f64],
    pub film_index: &'a [f64],
    /// 0: bare.
    pub film_thickness_nm: &'a [f64],
    /// Refractive index in front of surface 0, then behind each surface: (surfaces + 1, bands).
    pub media: &'a [f64],
    pub wavelength_nm: &'a [f64],
    pub film_z_mm: f64,
}

/// Each path's steps, (paths, steps) row by row: the surface met (< 0: the path has ended),
/// whether the ray reflects there, and whether it travels forward (+z) when it meets it.
pub struct Steps<'a> {
    pub surface: &'a [i64],
    pub reflect: &'a [bool],
    pub forward: &'a [bool],
    pub steps: usize,
}

/// The rays: origin and direction (N, 3), the path each follows, the band whose media bend it,
/// and the bands its weights are kept at, (N, bands_per_ray) (0 a ray: geometry only).
pub struct Rays<'a> {
    pub origin_mm: &'a [f64],
    pub direction: &'a [f64],
    pub path: &'a [i64],
    pub band: &'a [i64],
    pub weight_band: &'a [i64],
    pub bands_per_ray: usize,
}

/// Film position (N, 2) in mm, weight (N, bands_per_ray), whether the ray reached the film;
/// a lost ray has position and weight 0.
#[derive(Debug, Default, Clone, PartialEq)]
pub struct Traced {
    pub film_mm: Vec<f64>,
    pub weight: Vec<f64>,
    pub alive: Vec<bool>,
}

/// Inputs whose sizes or indices do not fit together.
#[derive(Debug, Clone, PartialEq, Eq)]
pub struct GhostError(String);

impl fmt::Display for GhostError {
    fn fmt(&self, f: &mut fmt::Formatter<'_>) -> fmt::Result {
        f.write_str(&self.0)
    }
}

impl std::error::Error for GhostError {}

fn check(ok: bool, message: impl FnOnce() -> String) -> Result<(), GhostError> {
    if ok {
        Ok(())
    } else {
        Err(GhostError(message()))
    }
}

fn check_index(values: &[i64], below: usize, what: &str) -> Result<(), GhostError> {
    match values.iter().find(|&&v| v < 0 || v as usize >= below) {
        Some(v) => Err(GhostError(format!(
            "ghost trace: {what} index {v} out of range 0..{below}"
        ))),
        None => Ok(()),
    }
}

fn validate(s: &Surfaces, steps: &Steps, rays: &Rays) -> Result<(), GhostError> {
    let count = s.vertex_z_mm.len();
    let per_surface = [
        s.radius_mm.len(),
        s.semi_aperture2_mm2.len(),
        s.fixed_reflectance.len(),
        s.film_index.len(),
        s.film_thickness_nm.len(),
    ];
    check(per_surface.iter().all(|&n| n == count), || {
        format!("ghost trace: per-surface arrays of lengths {count} and {per_surface:?}")
    })?;
    let bands = s.wavelength_nm.len();
    check(s.media.len() == (count + 1) * bands, || {
        format!(
            "ghost trace: media has {} values, not (surfaces + 1) x bands = {}",
            s.media.len(),
            (count + 1) * bands
        )
    })?;
    let table = steps.surface.len();
    check(
        steps.reflect.len() == table
            && steps.forward.len() == table
            && (steps.steps == 0 || table.is_multiple_of(steps.steps)),
        || "ghost trace: the step tables differ in shape".to_string(),
    )?;
    let paths = table.checked_div(steps.steps).unwrap_or(0);
    check(steps.surface.iter().all(|&k| k < count as i64), || {
        format!("ghost trace: a step's surface is not below the {count} surfaces")
    })?;
    let n = rays.path.len();
    check(
        rays.origin_mm.len() == 3 * n
            && rays.direction.len() == 3 * n
            && rays.band.len() == n
            && rays.weight_band.len() == n * rays.bands_per_ray,
        || format!("ghost trace: the per-ray arrays do not all hold {n} rays"),
    )?;
    check_index(rays.path, paths, "path")?;
    check_index(rays.band, bands, "band")?;
    check_index(rays.weight_band, bands, "weight band")
}

/// Every ray along its path to the film.
pub fn trace(surfaces: &Surfaces, steps: &Steps, rays: &Rays) -> Result<Traced, GhostError> {
    validate(surfaces, steps, rays)?;
    let n = rays.path.len();
    let b = rays.bands_per_ray;
    let mut film_mm = vec![0.0; 2 * n];
    let mut alive = vec![false; n];
    let weights: Vec<Vec<f64>> = film_mm
        .par_chunks_mut(2 * BLOCK_RAYS)
        .zip(alive.par_chunks_mut(BLOCK_RAYS))
        .enumerate()
        .map(|(block, (film, alive))| {
            let mut weight = vec![1.0; alive.len() * b];
            trace_block(
                surfaces,
                steps,
                rays,
                block * BLOCK_RAYS,
                film,
                alive,
                &mut weight,
            );
            weight
        })
        .collect();
    Ok(Traced {
        film_mm,
        weight: weights.concat(),
        alive,
    })
}

/// The rays from `start` on (as many as `alive` holds), a step at a time for all of them:
/// one ray's steps depend on each other, different rays' do not, so the processor overlaps
/// the rays of a step where one ray alone would wait on its divisions and square roots.
fn trace_block(
    s: &Surfaces,
    steps: &Steps,
    rays: &Rays,
    start: usize,
    film: &mut [f64],
    alive: &mut [bool],
    weight: &mut [f64],
) {
    let b = rays.bands_per_ray;
    let ray = |a: &[f64], j: usize| [a[3 * j], a[3 * j + 1], a[3 * j + 2]];
    let mut o: Vec<Vec3> = (start..start + alive.len())
        .map(|i| ray(rays.origin_mm, i))
        .collect();
    let mut d: Vec<Vec3> = (start..start + alive.len())
        .map(|i| ray(rays.direction, i))
        .collect();
    let mut live: Vec<usize> = (0..alive.len()).collect();
    for step in 0..steps.steps {
        let mut kept = 0;
        for next in 0..live.len() {
            let j = live[next];
            let i = start + j;
            let entry = rays.path[i] as usize * steps.steps + step;
            // A surface < 0: the ray's path has ended, it goes on to the film as it is.
            let keep = usize::try_from(steps.surface[entry]).map_or(true, |k| {
                let weight_band = &rays.weight_band[i * b..(i + 1) * b];
                let at = Step {
                    surface: k,
                    mirror: steps.reflect[entry],
                    forward: steps.forward[entry],
                    band: rays.band[i] as usize,
                };
                let w = &mut weight[j * b..(j + 1) * b];
                advance(s, &at, weight_band, &mut o[j], &mut d[j], w)
            });
            if keep {
                live[kept] = j;
                kept += 1;
            }
        }
        live.truncate(kept);
    }
    for &j in &live {
        // On to the film plane: only a ray going forward reaches it.
        let t = (s.film_z_mm - o[j][2]) / d[j][2];
        if d[j][2] > 0.0 && t >= -1e-9 {
            film[2 * j] = o[j][0] + t * d[j][0];
            film[2 * j + 1] = o[j][1] + t * d[j][1];
            alive[j] = true;
        }
    }
    for (j, _) in alive.iter().enumerate().filter(|(_, &reached)| !reached) {
        weight[j * b..(j + 1) * b].fill(0.0);
    }
}

/// One step of a ray's path: the surface met, whether the ray reflects there, whether it
/// travels forward (+z), the band whose media bend it.
struct Step {
    surface: usize,
    mirror: bool,
    forward: bool,
    band: usize,
}

/// The ray (o, d) through one step, its weights (at `weight_band`) multiplied by the
/// surface's R or 1 - R; false where it is lost.
fn advance(
    s: &Surfaces,
    at: &Step,
    weight_band: &[i64],
    o: &mut Vec3,
    d: &mut Vec3,
    weight: &mut [f64],
) -> bool {
    let bands = s.wavelength_nm.len();
    let k = at.surface;
    let Some(hit) = intersect(o, d, s.vertex_z_mm[k], s.radius_mm[k]) else {
        return false;
    };
    let p = hit.point_mm;
    let r2 = p[0] * p[0] + p[1] * p[1];
    if r2.is_nan() || r2 > s.semi_aperture2_mm2[k] {
        return false;
    }
    // The media on the side the ray comes from and the side it goes to.
    let (incident, beyond) = if at.forward { (k, k + 1) } else { (k + 1, k) };
    let cos0 = cos_incidence(d, &hit.normal);
    for (w, &wb) in weight.iter_mut().zip(weight_band) {
        let wb = wb as usize;
        let r = if s.fixed_reflectance[k] >= 0.0 {
            s.fixed_reflectance[k]
        } else {
            reflectance(
                s.media[incident * bands + wb],
                s.media[beyond * bands + wb],
                cos0,
                s.wavelength_nm[wb],
                s.film_index[k],
                s.film_thickness_nm[k],
            )
        };
        *w *= if at.mirror { r } else { 1.0 - r };
    }
    if at.mirror {
        *d = reflect(d, &hit.normal);
    } else {
        let eta = s.media[incident * bands + at.band] / s.media[beyond * bands + at.band];
        match refract(d, &hit.normal, eta) {
            Some(refracted) => *d = refracted,
            None => return false,
        }
    }
    *o = p;
    true
}

#[cfg(test)]
mod tests {
    use super::*;

    /// A flat glass plate (n 1.5, bare faces at z 0 and 2) and the film at z 10.
    fn plate<'a>(media: &'a [f64], film_z_mm: f64) -> Surfaces<'a> {
        Surfaces {
            vertex_z_mm: &[0.0, 2.0],
            radius_mm: &[0.0, 0.0],
            semi_aperture2_mm2: &[100.0, 100.0],
            fixed_reflectance: &[-1.0, -1.0],
            film_index: &[1.0, 1.0],
            film_thickness_nm: &[0.0, 0.0],
            media,
            wavelength_nm: &[550.0],
            film_z_mm,
        }
    }

    #[test]
    fn a_ray_through_a_plate_and_its_double_reflection() {
        let media = [1.0, 1.5, 1.0];
        let s = plate(&media, 10.0);
        // Path 0: straight through; path 1: reflect at the back face, then at the front.
        let steps = Steps {
            surface: &[0, 1, -1, -1, 0, 1, 0, 1],
            reflect: &[false, false, false, false, false, true, true, false],
            forward: &[true, true, true, true, true, true, false, true],
            steps: 4,
        };
        let theta = 0.3_f64;
        let d = [theta.sin(), 0.0, theta.cos()];
        let rays = Rays {
            origin_mm: &[0.0, 0.0, -1.0, 0.0, 0.0, -1.0],
            direction: &[d[0], d[1], d[2], d[0], d[1], d[2]],
            path: &[0, 1],
            band: &[0, 0],
            weight_band: &[0, 0],
            bands_per_ray: 1,
        };
        let out = trace(&s, &steps, &rays).unwrap();
        assert_eq!(out.alive, vec![true, true]);
        // A plate shifts a ray sideways but keeps its direction: x = 11 tan(theta) - 2 tan(theta)
        // + 2 tan(theta_glass), the ghost crosses the glass twice more.
        let tan_glass = (theta.sin() / 1.5).asin().tan();
        let straight = 9.0 * theta.tan() + 2.0 * tan_glass;
        assert!((out.film_mm[0] - straight).abs() < 1e-12);
        assert!((out.film_mm[2] - (straight + 4.0 * tan_glass)).abs() < 1e-12);
        // Weights: (1 - R_in)(1 - R_out) and (1 - R_in) R_out R_in (1 - R_out), R the same at
        // both faces (the same angle pair, reflectance reciprocal).
        let r = reflectance(1.0, 1.5, theta.cos(), 550.0, 1.0, 0.0);
        assert!((out.weight[0] - (1.0 - r) * (1.0 - r)).abs() < 1e-12);
        assert!((out.weight[1] - (1.0 - r) * (1.0 - r) * r * r).abs() < 1e-12);
    }

    #[test]
    fn lost_rays_and_bad_indices() {
        let media = [1.0, 1.5, 1.0];
        let s = plate(&media, 10.0);
        let steps = Steps {
            surface: &[0, 1],
            reflect: &[false, false],
            forward: &[true, true],
            steps: 2,
        };
        // Outside the semi-aperture (10 mm).
        let rays = Rays {
            origin_mm: &[11.0, 0.0, -1.0],
            direction: &[0.0, 0.0, 1.0],
            path: &[0],
            band: &[0],
            weight_band: &[],
            bands_per_ray: 0,
        };
        let out = trace(&s, &steps, &rays).unwrap();
        assert_eq!((out.alive, out.film_mm), (vec![false], vec![0.0, 0.0]));
        let bad = Rays { path: &[1], ..rays };
        let error = trace(&s, &steps, &bad).unwrap_err().to_string();
        assert!(error.contains("path index 1"), "{error}");
    }
}
