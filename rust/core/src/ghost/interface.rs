//! A ray meeting one surface of a lens: a sphere cap around its vertex (radius 0: a plane), the
//! point, the unit normal, and the ray's new direction, refracted (Snell's law in vector form,
//! pbrt's `Refract`) or reflected (d - 2 (d . n) n).

/// A 3-vector in lens space (mm, or a direction).
pub type Vec3 = [f64; 3];

fn dot(a: &Vec3, b: &Vec3) -> f64 {
    a[0] * b[0] + a[1] * b[1] + a[2] * b[2]
}

/// o + t d.
fn point_along(origin: &Vec3, direction: &Vec3, t: f64) -> Vec3 {
    [
        origin[0] + t * direction[0],
        origin[1] + t * direction[1],
        origin[2] + t * direction[2],
    ]
}

/// Where a ray meets a surface: the point, the unit normal (pointing away from the sphere's
/// centre divided by the signed radius, so along -z at the vertex; (0, 0, -1) for a plane).
#[derive(Clone, Copy, Debug, PartialEq)]
pub struct Hit {
    pub point_mm: Vec3,
    pub normal: Vec3,
}

/// The ray `origin + t direction` (t >= 0, to 1e-9) on the cap of the sphere of signed
/// `radius_mm` whose vertex is at z = `vertex_z_mm` on the axis (0: the plane z = vertex):
/// |o + t d - c|^2 = r^2, the root on the vertex's side (the nearer one when travelling
/// towards the centre). None where it misses.
pub fn intersect(origin: &Vec3, direction: &Vec3, vertex_z_mm: f64, radius_mm: f64) -> Option<Hit> {
    if radius_mm == 0.0 {
        let t = (vertex_z_mm - origin[2]) / direction[2];
        if !(t.is_finite() && t > -1e-9) {
            return None;
        }
        return Some(Hit {
            point_mm: point_along(origin, direction, t),
            normal: [0.0, 0.0, -1.0],
        });
    }
    let centre_z = vertex_z_mm + radius_mm;
    let oc = [origin[0], origin[1], origin[2] - centre_z];
    let b = dot(&oc, direction);
    let c = dot(&oc, &oc) - radius_mm * radius_mm;
    let disc = b * b - c;
    if disc.is_nan() || disc < 0.0 {
        return None;
    }
    let root = disc.sqrt();
    let closer = (direction[2] > 0.0) == (radius_mm > 0.0);
    let t = if closer { -b - root } else { -b + root };
    if !(t.is_finite() && t > -1e-9) {
        return None;
    }
    let point_mm = point_along(origin, direction, t);
    let normal = [
        point_mm[0] / radius_mm,
        point_mm[1] / radius_mm,
        (point_mm[2] - centre_z) / radius_mm,
    ];
    Some(Hit { point_mm, normal })
}

/// `direction` mirrored about the plane of `normal`: d - 2 (d . n) n.
pub fn reflect(direction: &Vec3, normal: &Vec3) -> Vec3 {
    let dn = dot(direction, normal);
    [
        direction[0] - 2.0 * dn * normal[0],
        direction[1] - 2.0 * dn * normal[1],
        direction[2] - 2.0 * dn * normal[2],
    ]
}

/// The unit direction refracted from index n_in into n_out (`eta` = n_in / n_out), the
/// normal of either orientation: eta d + (eta cos_i - cos_t) n, cos_t = sqrt(1 - eta^2 (1 -
/// cos_i^2)). None past total internal reflection.
pub fn refract(direction: &Vec3, normal: &Vec3, eta: f64) -> Option<Vec3> {
    let mut cos_i = -dot(direction, normal);
    let sign = if cos_i < 0.0 { -1.0 } else { 1.0 };
    cos_i = cos_i.abs();
    let sin2_t = eta * eta * (1.0 - cos_i * cos_i).max(0.0);
    if sin2_t.is_nan() || sin2_t > 1.0 {
        return None;
    }
    let cos_t = (1.0 - sin2_t).max(0.0).sqrt();
    let k = (eta * cos_i - cos_t) * sign;
    let out = [
        eta * direction[0] + k * normal[0],
        eta * direction[1] + k * normal[1],
        eta * direction[2] + k * normal[2],
    ];
    let norm = dot(&out, &out).sqrt();
    Some([out[0] / norm, out[1] / norm, out[2] / norm])
}

/// The cosine between a direction and a unit normal, unsigned.
pub fn cos_incidence(direction: &Vec3, normal: &Vec3) -> f64 {
    dot(direction, normal).abs()
}

#[cfg(test)]
mod tests {
    use super::*;

    fn close(a: &Vec3, b: &Vec3, tol: f64) -> bool {
        (0..3).all(|i| (a[i] - b[i]).abs() <= tol)
    }

    #[test]
    fn a_ray_along_the_axis_meets_the_vertex() {
        for radius in [25.0, -25.0, 0.0] {
            let hit = intersect(&[0.0, 0.0, -10.0], &[0.0, 0.0, 1.0], 3.0, radius).unwrap();
            assert!(close(&hit.point_mm, &[0.0, 0.0, 3.0], 1e-12), "{radius}");
            assert!(close(&hit.normal, &[0.0, 0.0, -1.0], 1e-12), "{radius}");
        }
    }

    #[test]
    fn an_offset_ray_meets_the_sag_of_the_sphere() {
        // Sag of a sphere of radius r at height h: r - sqrt(r^2 - h^2), signed with r.
        let (r, h, vertex) = (20.0_f64, 6.0_f64, 2.0);
        for radius in [r, -r] {
            let sag = radius - radius.signum() * (r * r - h * h).sqrt();
            let hit = intersect(&[h, 0.0, -5.0], &[0.0, 0.0, 1.0], vertex, radius).unwrap();
            assert!((hit.point_mm[2] - (vertex + sag)).abs() < 1e-12, "{radius}");
            // The normal points from the centre (vertex + radius) through the point, / radius.
            let centre = [0.0, 0.0, vertex + radius];
            let want = [
                (hit.point_mm[0] - centre[0]) / radius,
                0.0,
                (hit.point_mm[2] - centre[2]) / radius,
            ];
            assert!(close(&hit.normal, &want, 1e-12));
            assert!((dot(&hit.normal, &hit.normal) - 1.0).abs() < 1e-12);
        }
    }

    #[test]
    fn a_ray_travelling_back_meets_the_same_cap() {
        let hit = intersect(&[1.0, 0.0, 10.0], &[0.0, 0.0, -1.0], 0.0, 20.0).unwrap();
        let sag = 20.0 - (400.0_f64 - 1.0).sqrt();
        assert!((hit.point_mm[2] - sag).abs() < 1e-12);
    }

    #[test]
    fn a_ray_past_the_sphere_misses_and_a_parallel_ray_misses_a_plane() {
        assert!(intersect(&[30.0, 0.0, -5.0], &[0.0, 0.0, 1.0], 0.0, 20.0).is_none());
        assert!(intersect(&[0.0, 0.0, -5.0], &[1.0, 0.0, 0.0], 0.0, 0.0).is_none());
        // Behind the ray's origin.
        assert!(intersect(&[0.0, 0.0, 5.0], &[0.0, 0.0, 1.0], 0.0, 0.0).is_none());
    }

    #[test]
    fn refraction_obeys_snell_and_total_internal_reflection() {
        let theta = 0.4_f64;
        let d = [theta.sin(), 0.0, theta.cos()];
        let out = refract(&d, &[0.0, 0.0, -1.0], 1.0 / 1.5).unwrap();
        assert!((out[0] - theta.sin() / 1.5).abs() < 1e-12);
        assert!((dot(&out, &out) - 1.0).abs() < 1e-12);
        // The normal's orientation does not matter.
        assert_eq!(refract(&d, &[0.0, 0.0, 1.0], 1.0 / 1.5), Some(out));
        // From glass to air past the critical angle asin(1 / 1.5) = 0.73 rad.
        let steep = [0.8_f64.sin(), 0.0, 0.8_f64.cos()];
        assert!(refract(&steep, &[0.0, 0.0, -1.0], 1.5).is_none());
        let mirrored = reflect(&steep, &[0.0, 0.0, -1.0]);
        assert!(close(&mirrored, &[steep[0], 0.0, -steep[2]], 1e-15));
    }
}
