//! Ideal thin lens (paraxial, aberration-free).
//!
//! Geometry (camera space, metres): the lens is the disk of radius
//! `R = f/(2N)` in the plane z = 0, the film is the plane z = −d_i with
//! 1/d_i = 1/f − 1/z_f (z_f = focus distance, measured from the lens plane).
//! The image is inverted: the physical film point of `film_m` is −film_m.
//!
//! Radiometry: with lens points sampled uniformly on the aperture
//! (pdf 1/(πR²)), the irradiance at a film point is
//! E = ∫ L cosθ dω = ∫ L cos θ cos θ' dA / r² = ∫ L d_i² / r⁴ dA, so the
//! weight is πR²·d_i²/r⁴ with r the film-point-to-lens-point distance.
//! On axis the integral is exactly E = πL·R²/(d_i² + R²); off axis, in the
//! small-aperture limit, E = πL·R²/d_i²·cos⁴θ. For focus at infinity
//! (d_i = f) this is the ideal-lens law E = πL/(4N²)·cos⁴θ up to a relative
//! O(1/(4N²)) aperture correction; for a finite focus distance the working
//! f-number N·d_i/f applies (E scaled by (f/d_i)²), which is physically right.

use super::{Camera, CameraRay};
use crate::{Error, Result};
use glam::{DVec2, DVec3};

/// Ideal thin lens focused at `focus_distance_m` (use `f64::INFINITY` for infinity).
#[derive(Clone, Debug, PartialEq)]
pub struct ThinLens {
    pub focal_length_m: f64,
    pub f_number: f64,
    pub focus_distance_m: f64,
}

impl ThinLens {
    /// Validate and build.
    pub fn new(focal_length_m: f64, f_number: f64, focus_distance_m: f64) -> Result<Self> {
        if !(focal_length_m.is_finite() && focal_length_m > 0.0) {
            return Err(Error::Invalid(format!(
                "thin lens: focal length must be > 0 m, got {focal_length_m}"
            )));
        }
        if !(f_number.is_finite() && f_number > 0.0) {
            return Err(Error::Invalid(format!(
                "thin lens: f-number must be > 0, got {f_number}"
            )));
        }
        if focus_distance_m.is_nan() || focus_distance_m <= focal_length_m {
            return Err(Error::Invalid(format!(
                "thin lens: focus distance ({focus_distance_m} m) must exceed the focal length ({focal_length_m} m)"
            )));
        }
        Ok(Self {
            focal_length_m,
            f_number,
            focus_distance_m,
        })
    }

    /// Aperture radius R = f/(2N), metres.
    pub fn aperture_radius_m(&self) -> f64 {
        self.focal_length_m / (2.0 * self.f_number)
    }

    /// Lens-to-film distance d_i (thin-lens equation), metres.
    pub fn film_distance_m(&self) -> f64 {
        image_distance_m(self.focal_length_m, self.focus_distance_m)
    }
}

/// Thin-lens image distance for an object at `object_m` (∞ allowed).
pub fn image_distance_m(f_m: f64, object_m: f64) -> f64 {
    if object_m.is_infinite() {
        f_m
    } else {
        f_m * object_m / (object_m - f_m)
    }
}

/// Shirley–Chiu concentric map of the unit square onto the unit disk
/// (area-preserving, so uniform in → uniform out).
pub fn concentric_disk(u: DVec2) -> DVec2 {
    let a = 2.0 * u.x - 1.0;
    let b = 2.0 * u.y - 1.0;
    if a == 0.0 && b == 0.0 {
        return DVec2::ZERO;
    }
    let (r, phi) = if a.abs() > b.abs() {
        (a, std::f64::consts::FRAC_PI_4 * (b / a))
    } else {
        (
            b,
            std::f64::consts::FRAC_PI_2 - std::f64::consts::FRAC_PI_4 * (a / b),
        )
    };
    DVec2::new(r * phi.cos(), r * phi.sin())
}

impl Camera for ThinLens {
    fn sample_ray(&self, film_m: DVec2, u: DVec2, _lambda_nm: f64) -> Option<CameraRay> {
        let d_i = self.film_distance_m();
        let r_ap = self.aperture_radius_m();
        let p_film = DVec3::new(-film_m.x, -film_m.y, -d_i);
        let l = concentric_disk(u) * r_ap;
        let lens = DVec3::new(l.x, l.y, 0.0);
        // Every ray from p_film converges, after the lens, on the conjugate point
        // of p_film, which the undeviated chief ray through the centre reaches.
        let chief = -p_film / d_i; // direction scaled so that z = 1
        let dir = if self.focus_distance_m.is_infinite() {
            chief.normalize()
        } else {
            (chief * self.focus_distance_m - lens).normalize()
        };
        let to_lens = lens - p_film;
        let r2 = to_lens.length_squared();
        let weight = std::f64::consts::PI * r_ap * r_ap * d_i * d_i / (r2 * r2);
        if !(weight.is_finite() && dir.is_finite()) {
            return None;
        }
        Some(CameraRay {
            origin: lens,
            direction: dir,
            weight,
        })
    }

    fn film_distance_m(&self) -> Option<f64> {
        Some(ThinLens::film_distance_m(self))
    }
    fn describe(&self) -> String {
        format!(
            "thin lens f={} mm, f/{}, focus {} m",
            self.focal_length_m * 1e3,
            self.f_number,
            self.focus_distance_m
        )
    }
}

#[cfg(test)]
mod tests {
    use super::*;

    /// Closed-form blur-circle diameter on the film for a point at `z_o`
    /// when focused at `z_f`: c = A·|d_o − d_i|/d_o.
    fn blur_closed_form(lens: &ThinLens, z_o: f64) -> f64 {
        let d_i = lens.film_distance_m();
        let d_o = image_distance_m(lens.focal_length_m, z_o);
        2.0 * lens.aperture_radius_m() * (d_o - d_i).abs() / d_o
    }

    /// Ray hits of film point `x` in the plane z = z_o, traced through the
    /// aperture rim (u on the boundary of the square maps to the disk rim).
    fn rim_hits(lens: &ThinLens, x: f64, z_o: f64) -> Vec<DVec2> {
        let n = 512;
        (0..n)
            .filter_map(|i| {
                let t = i as f64 / n as f64;
                let u = match i % 4 {
                    0 => DVec2::new(t, 0.0),
                    1 => DVec2::new(1.0, t),
                    2 => DVec2::new(t, 1.0),
                    _ => DVec2::new(0.0, t),
                };
                let r = lens.sample_ray(DVec2::new(x, 0.0), u, 550.0)?;
                let s = (z_o - r.origin.z) / r.direction.z;
                Some((r.origin + r.direction * s).truncate())
            })
            .collect()
    }

    /// The film blur radius is *measured*: the film point at offset x sees the
    /// point source (on axis at z_o) iff the source lies inside the traced rim
    /// of its ray bundle. Bisection on x finds the edge of the blur circle.
    #[test]
    fn thin_lens_blur_circle_matches_closed_form() {
        let lens = ThinLens::new(0.05, 2.0, 2.0).unwrap();
        for &z_o in &[0.5, 1.0, 1.5, 3.0, 10.0] {
            let sees = |x: f64| {
                let hits = rim_hits(&lens, x, z_o);
                let c = hits.iter().fold(DVec2::ZERO, |a, &h| a + h) / hits.len() as f64;
                let rad = hits.iter().map(|h| (*h - c).length()).fold(0.0, f64::max);
                c.length() <= rad
            };
            let (mut lo, mut hi) = (0.0, 0.01);
            assert!(sees(lo) && !sees(hi));
            for _ in 0..50 {
                let mid = 0.5 * (lo + hi);
                if sees(mid) { lo = mid } else { hi = mid }
            }
            let measured = 2.0 * lo;
            let truth = blur_closed_form(&lens, z_o);
            // 512 rim samples: the polygonal rim underestimates the circle radius by
            // 1−cos(π/512·4) ≈ 8e-5 relative, far below the 1 % tolerance.
            assert!(
                (measured / truth - 1.0).abs() < 0.01,
                "z_o={z_o}: measured {measured}, closed form {truth}"
            );
        }
    }

    /// Shirley–Chiu's map at points where it is known in closed form: the
    /// square's edge midpoints go to the disk's axis points, its corners to
    /// the 45° diagonals, and a point at b/a = ½ on the right edge to angle
    /// π/8 (φ = π/4 · b/a), at a/b = ½ on the top edge to 3π/8.
    #[test]
    fn concentric_disk_at_closed_form_points() {
        use std::f64::consts::{FRAC_1_SQRT_2, FRAC_PI_8};
        let cases = [
            ((0.5, 0.5), (0.0, 0.0)),
            ((1.0, 0.5), (1.0, 0.0)),
            ((0.5, 1.0), (0.0, 1.0)),
            ((0.0, 0.5), (-1.0, 0.0)),
            ((0.5, 0.0), (0.0, -1.0)),
            ((1.0, 1.0), (FRAC_1_SQRT_2, FRAC_1_SQRT_2)),
            ((1.0, 0.0), (FRAC_1_SQRT_2, -FRAC_1_SQRT_2)),
            ((1.0, 0.75), (FRAC_PI_8.cos(), FRAC_PI_8.sin())),
            (
                (0.75, 1.0),
                ((3.0 * FRAC_PI_8).cos(), (3.0 * FRAC_PI_8).sin()),
            ),
            ((0.75, 0.5), (0.5, 0.0)),
            // Inside the square (|a| < 1, so b/a differs from b·a and b % a):
            // a = 0.75, b = 0.25 → r = 0.75, φ = π/12; swapped → φ = 5π/12.
            (
                (0.875, 0.625),
                (
                    0.75 * (FRAC_PI_8 * 2.0 / 3.0).cos(),
                    0.75 * (FRAC_PI_8 * 2.0 / 3.0).sin(),
                ),
            ),
            (
                (0.625, 0.875),
                (
                    0.75 * (FRAC_PI_8 * 10.0 / 3.0).cos(),
                    0.75 * (FRAC_PI_8 * 10.0 / 3.0).sin(),
                ),
            ),
        ];
        for ((ux, uy), (x, y)) in cases {
            let p = concentric_disk(DVec2::new(ux, uy));
            assert!(
                (p - DVec2::new(x, y)).length() < 1e-12,
                "u = ({ux}, {uy}): {p} vs ({x}, {y})"
            );
        }
    }

    /// The map is area-preserving: a uniform midpoint grid of the square
    /// lands equally in the 64 equal-area cells of the disk (16 sectors of
    /// π/8 × 4 rings with r² in [k/4, (k+1)/4)). A cell's boundary in the
    /// square is a few straight segments of total length < 2, so the
    /// midpoint grid misplaces at most ~2n of its n² points per cell: 2/n.
    #[test]
    fn concentric_disk_is_uniform_on_the_disk() {
        let n = 400;
        let mut cells = [0usize; 64];
        for i in 0..n {
            for j in 0..n {
                let u = DVec2::new((i as f64 + 0.5) / n as f64, (j as f64 + 0.5) / n as f64);
                let p = concentric_disk(u);
                let r2 = p.length_squared();
                assert!(r2 <= 1.0 + 1e-12);
                let phi = p.y.atan2(p.x).rem_euclid(std::f64::consts::TAU);
                let sector = ((phi / std::f64::consts::FRAC_PI_8) as usize).min(15);
                let ring = ((r2 * 4.0) as usize).min(3);
                cells[sector * 4 + ring] += 1;
            }
        }
        for (k, &c) in cells.iter().enumerate() {
            let f = c as f64 / (n * n) as f64;
            assert!((f - 1.0 / 64.0).abs() < 2.0 / n as f64, "cell {k}: {f}");
        }
    }

    /// The image is inverted like a pinhole's: the chief ray (through the
    /// lens centre) from film point (x, y) leaves along (x, y, d_i), the
    /// pinhole's direction for the same film point and film distance.
    #[test]
    fn chief_ray_has_the_pinhole_direction() {
        let lens = ThinLens::new(0.05, 2.0, 2.0).unwrap();
        let d = lens.film_distance_m();
        for (x, y) in [(0.004, 0.0), (0.0, -0.003), (0.002, 0.001)] {
            let r = lens
                .sample_ray(DVec2::new(x, y), DVec2::new(0.5, 0.5), 550.0)
                .unwrap();
            let want = DVec3::new(x, y, d).normalize();
            assert!(r.origin.length() < 1e-15);
            assert!(
                (r.direction - want).length() < 1e-12,
                "{} vs {want}",
                r.direction
            );
        }
    }

    /// One sample's weight in closed form: the physical film point of
    /// film_m = (x, 0) is (−x, 0, −d); the lens point of u = (1, ½) is
    /// (R, 0, 0), at r² = (R + x)² + d², so w = πR²d²/r⁴. Every ray from
    /// one film point passes through its conjugate point at the focus
    /// distance, the chief ray's point there.
    #[test]
    fn sample_weight_and_focus_in_closed_form() {
        let lens = ThinLens::new(0.05, 2.0, 2.0).unwrap();
        let (r_ap, d) = (lens.aperture_radius_m(), lens.film_distance_m());
        let x = 0.004;
        let ray = lens
            .sample_ray(DVec2::new(x, 0.0), DVec2::new(1.0, 0.5), 550.0)
            .unwrap();
        assert!((ray.origin - DVec3::new(r_ap, 0.0, 0.0)).length() < 1e-15);
        let r2 = (r_ap + x).powi(2) + d * d;
        let want = std::f64::consts::PI * r_ap * r_ap * d * d / (r2 * r2);
        assert!(
            (ray.weight / want - 1.0).abs() < 1e-12,
            "{} vs {want}",
            ray.weight
        );
        // The camera reports the thin-lens equation's d = f·z/(z − f).
        let d_eq = 0.05 * 2.0 / (2.0 - 0.05);
        assert!((Camera::film_distance_m(&lens).unwrap() - d_eq).abs() < 1e-15);
        let conjugate = DVec3::new(x, 0.0, d) * (2.0 / d);
        for u in [(0.1, 0.2), (0.9, 0.5), (0.5, 0.95), (0.3, 0.7)] {
            let ray = lens
                .sample_ray(DVec2::new(x, 0.0), DVec2::new(u.0, u.1), 550.0)
                .unwrap();
            let hit = ray.origin + ray.direction * ((2.0 - ray.origin.z) / ray.direction.z);
            assert!(
                (hit - conjugate).length() < 1e-12,
                "u = {u:?}: {hit} vs {conjugate}"
            );
        }
    }

    /// The weight integrates to the exact irradiance of a uniform field:
    /// on axis E/L = π R²/(d² + R²) (exact disk solid-angle integral).
    #[test]
    fn thin_lens_irradiance_on_axis_and_cos4() {
        let lens = ThinLens::new(0.05, 4.0, f64::INFINITY).unwrap();
        let n = 200;
        let mean = |x: f64| {
            let mut s = 0.0;
            for i in 0..n {
                for j in 0..n {
                    let u = DVec2::new((i as f64 + 0.5) / n as f64, (j as f64 + 0.5) / n as f64);
                    s += lens
                        .sample_ray(DVec2::new(x, 0.0), u, 550.0)
                        .unwrap()
                        .weight;
                }
            }
            s / (n * n) as f64
        };
        let (r, d) = (lens.aperture_radius_m(), lens.film_distance_m());
        let e0 = mean(0.0);
        let exact = std::f64::consts::PI * r * r / (d * d + r * r);
        // Midpoint rule on a smooth integrand: error ≪ 1e-4 relative.
        assert!((e0 / exact - 1.0).abs() < 1e-4, "{e0} vs {exact}");
        // Within 1.6 % of π/(4N²) (the O(1/(4N)²) aperture correction).
        let ideal = std::f64::consts::PI / (4.0 * 16.0);
        assert!((e0 / ideal - 1.0).abs() < 0.016);
        // Off axis: cos⁴θ falloff within the aperture correction (f/4: ≤ 2 %).
        let x = 0.03;
        let cos = d / (d * d + x * x).sqrt();
        let ratio = mean(x) / e0;
        assert!(
            (ratio / cos.powi(4) - 1.0).abs() < 0.02,
            "{ratio} vs {}",
            cos.powi(4)
        );
    }
}
