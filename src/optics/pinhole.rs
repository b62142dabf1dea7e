//! Ideal pinhole camera.
//!
//! The pinhole sits at the camera-space origin; the film is a plane at
//! distance `d` behind it, chosen so that the full field of view `fov_deg`
//! spans the shorter film side (pbrt's convention). Every ray passes through
//! the pinhole, so everything is in focus. `f_number` N only sets the
//! irradiance scale: the weight is π/(4N²)·cos⁴θ, the on-axis irradiance of an
//! ideal lens of f-number N times the natural fall-off (θ = angle of the ray to
//! the optical axis).

// `!(x > 0.0)` is deliberate throughout: it also rejects NaN.
#![allow(clippy::neg_cmp_op_on_partial_ord)]

use super::{Camera, CameraRay};
use crate::scene::FilmSpec;
use crate::{Error, Result};
use glam::{DVec2, DVec3};

#[derive(Clone, Debug, PartialEq)]
pub struct Pinhole {
    pub fov_deg: f64,
    pub f_number: f64,
    /// Pinhole-to-film distance, metres.
    pub film_distance_m: f64,
    /// Weight the irradiance by cos⁴θ (natural vignetting); false: the
    /// on-axis irradiance πL/(4N²) everywhere.
    pub cos4: bool,
}

impl Pinhole {
    /// Pinhole for a film (its shorter side spans `fov_deg`).
    pub fn new(fov_deg: f64, f_number: f64, film: &FilmSpec) -> Result<Self> {
        if !(fov_deg > 0.0 && fov_deg < 180.0) {
            return Err(Error::invalid(format!(
                "pinhole fov-deg must be in (0, 180), got {fov_deg}"
            )));
        }
        if !(f_number > 0.0) || !f_number.is_finite() {
            return Err(Error::invalid(format!(
                "pinhole f-number must be > 0, got {f_number}"
            )));
        }
        let short_m = film.width_px.min(film.height_px) as f64 * film.pixel_pitch_m;
        if !(short_m > 0.0) || !short_m.is_finite() {
            return Err(Error::invalid(
                "pinhole needs a film with positive size and pixel pitch",
            ));
        }
        let film_distance_m = 0.5 * short_m / (0.5 * fov_deg.to_radians()).tan();
        Ok(Self {
            fov_deg,
            f_number,
            film_distance_m,
            cos4: true,
        })
    }

    /// With or without the cos⁴θ fall-off.
    pub fn with_cos4(self, cos4: bool) -> Self {
        Self { cos4, ..self }
    }
}

impl Camera for Pinhole {
    fn sample_ray(&self, film_m: DVec2, _u: DVec2, _lambda_nm: f64) -> Option<CameraRay> {
        let v = DVec3::new(film_m.x, film_m.y, self.film_distance_m);
        let len = v.length();
        let cos = self.film_distance_m / len;
        let c2 = cos * cos;
        let falloff = if self.cos4 { c2 * c2 } else { 1.0 };
        let weight = std::f64::consts::PI / (4.0 * self.f_number * self.f_number) * falloff;
        Some(CameraRay {
            origin: DVec3::ZERO,
            direction: v / len,
            weight,
        })
    }
    fn film_distance_m(&self) -> Option<f64> {
        Some(self.film_distance_m)
    }
    fn describe(&self) -> String {
        format!(
            "pinhole fov {}° f/{} (film distance {:.6} m){}",
            self.fov_deg,
            self.f_number,
            self.film_distance_m,
            if self.cos4 {
                ""
            } else {
                ", no cos⁴ fall-off"
            }
        )
    }
}

#[cfg(test)]
mod tests {
    use super::*;
    #[test]
    fn fov_spans_shorter_side_and_weight_on_axis() {
        let film = FilmSpec {
            width_px: 200,
            height_px: 100,
            pixel_pitch_m: 1e-5,
            crop_window: None,
        };
        let p = Pinhole::new(60.0, 2.0, &film).unwrap();
        // Ray to the top edge centre is at 30° from the axis.
        let r = p
            .sample_ray(DVec2::new(0.0, 50.0 * 1e-5), DVec2::ZERO, 550.0)
            .unwrap();
        assert!((r.direction.z.acos().to_degrees() - 30.0).abs() < 1e-9);
        let r0 = p.sample_ray(DVec2::ZERO, DVec2::ZERO, 550.0).unwrap();
        assert!((r0.weight - std::f64::consts::PI / 16.0).abs() < 1e-15);
        assert!(Pinhole::new(0.0, 2.0, &film).is_err());
    }

    /// The film distance follows from the field of view alone: the shorter
    /// side (1 mm) subtends 60°, so d = 0.5 mm / tan 30° (analytic).
    #[test]
    fn film_distance_is_half_short_side_over_tan_half_fov() {
        let film = FilmSpec {
            width_px: 200,
            height_px: 100,
            pixel_pitch_m: 1e-5,
            crop_window: None,
        };
        let p = Pinhole::new(60.0, 2.0, &film).unwrap();
        let d = 0.5e-3 / 30f64.to_radians().tan();
        let from_trait = Camera::film_distance_m(&p).unwrap();
        assert!((from_trait - d).abs() < 1e-15, "{from_trait} vs {d}");
    }

    /// Without the fall-off every ray carries the on-axis weight π/(4N²);
    /// with it, a ray at 30° carries cos⁴30° = 9/16 of that.
    #[test]
    fn cos4_switch_sets_the_off_axis_weight() {
        let film = FilmSpec {
            width_px: 200,
            height_px: 100,
            pixel_pitch_m: 1e-5,
            crop_window: None,
        };
        let on_axis = std::f64::consts::PI / 16.0;
        let edge = DVec2::new(0.0, 50.0 * 1e-5);
        let p = Pinhole::new(60.0, 2.0, &film).unwrap();
        let w = p.sample_ray(edge, DVec2::ZERO, 550.0).unwrap().weight;
        assert!((w - on_axis * 9.0 / 16.0).abs() < 1e-15, "{w}");
        let flat = p.with_cos4(false);
        assert!(!flat.cos4);
        let w = flat.sample_ray(edge, DVec2::ZERO, 550.0).unwrap().weight;
        assert!((w - on_axis).abs() < 1e-15, "{w}");
        assert!(flat.describe().contains("no cos⁴"));
    }
}
