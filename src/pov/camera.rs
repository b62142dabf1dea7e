//! The pinhole equivalent of a camsim camera, as POV-Ray's `perspective`
//! camera sees it.
//!
//! camsim's label pass traces one ray per pixel: through the pixel centre and
//! the pupil centre (`u = ½, ½`), the chief ray. The pinhole equivalent is the
//! pinhole whose rays best match those chief rays:
//!
//! - film distance `d`: least-squares fit of r = d·tan θ over chief rays along
//!   the film's horizontal and vertical half-axes (10 points each, out to the
//!   film edge; vignetted points are skipped). Exact for the pinhole and the
//!   thin lens; for a real lens the residual is its distortion.
//! - centre of projection: where those chief rays cross the optical axis (the
//!   entrance pupil; the origin for a pinhole or a thin lens).
//! - orientation and handedness: taken from the scene's `to_world` (camera +x =
//!   image right, +y = image up, +z = forward), *not* from the rays, so a camera
//!   model that mirrors or flips its image disagrees with POV-Ray.
//!
//! POV-Ray's perspective camera shoots `direction + x·right + y·up` for image
//! coordinates x ∈ [−½, ½] (left → right) and y ∈ [½, −½] (top → bottom)
//! through pixel centres (no antialiasing). With `direction` = the camera's +z,
//! `right` = +x · W/d and `up` = +y · H/d (W × H the film in metres) this is
//! camsim's pinhole ray (x·W, y·H, d) mapped by `to_world`, vector for vector,
//! so no handedness flag or angle convention is involved.

// `!(x > 0.0)` is deliberate: it also rejects NaN.
#![allow(clippy::neg_cmp_op_on_partial_ord)]

use crate::optics::Camera;
use crate::scene::FilmSpec;
use crate::{Error, Result};
use glam::{DMat4, DVec2, DVec3};

/// A pinhole camera in world space, ready to be written as a POV-Ray camera.
#[derive(Clone, Debug, PartialEq)]
pub struct PinholeEquivalent {
    /// World-from-camera transform (the scene camera's pose).
    pub to_world: DMat4,
    /// Centre of projection in camera space (metres; on the optical axis).
    pub centre: DVec3,
    /// tan of the half field of view across the film width.
    pub tan_half_width: f64,
    /// tan of the half field of view across the film height.
    pub tan_half_height: f64,
}

impl PinholeEquivalent {
    /// The pinhole equivalent of `camera` on `film` (physical size width ×
    /// height × pitch), posed by `to_world`. Fails when no chief ray leaves the
    /// camera or the fitted film distance is not positive.
    pub fn of_camera(to_world: DMat4, camera: &dyn Camera, film: &FilmSpec) -> Result<Self> {
        let half_w = 0.5 * film.width_px as f64 * film.pixel_pitch_m;
        let half_h = 0.5 * film.height_px as f64 * film.pixel_pitch_m;
        if !(half_w > 0.0 && half_h > 0.0 && half_w.is_finite() && half_h.is_finite()) {
            return Err(Error::invalid(format!(
                "film {}×{} px with pitch {} m has no area",
                film.width_px, film.height_px, film.pixel_pitch_m
            )));
        }
        let chief = |p: DVec2| camera.sample_ray(p, DVec2::splat(0.5), 550.0);
        // r = d·tan θ, fitted through the origin: d = Σ r·t / Σ t².
        let (mut srt, mut stt) = (0.0, 0.0);
        // Axis crossings of the chief rays (z where the ray meets x = y = 0).
        let (mut sz, mut nz) = (0.0, 0usize);
        for k in 1..=10 {
            let f = k as f64 / 10.0;
            for (p, r) in [
                (DVec2::new(f * half_w, 0.0), f * half_w),
                (DVec2::new(-f * half_w, 0.0), -f * half_w),
                (DVec2::new(0.0, f * half_h), f * half_h),
                (DVec2::new(0.0, -f * half_h), -f * half_h),
            ] {
                let Some(ray) = chief(p) else { continue };
                let d = ray.direction;
                if !(d.z > 0.0) {
                    continue;
                }
                let (t, o, dl) = if p.y == 0.0 {
                    (d.x / d.z, ray.origin.x, d.x)
                } else {
                    (d.y / d.z, ray.origin.y, d.y)
                };
                // Magnitudes only: a camera whose image is mirrored must not
                // get a mirrored POV-Ray camera (see module docs).
                srt += r.abs() * t.abs();
                stt += t * t;
                if dl.abs() > 1e-12 {
                    let z = ray.origin.z - o / dl * d.z;
                    if z.is_finite() {
                        sz += z;
                        nz += 1;
                    }
                }
            }
        }
        let d = srt / stt;
        if !(stt > 0.0) || !(d > 0.0) || !d.is_finite() {
            return Err(Error::invalid(format!(
                "camera '{}' sends no usable chief ray across the film; no pinhole equivalent",
                camera.describe()
            )));
        }
        let z = if nz > 0 { sz / nz as f64 } else { 0.0 };
        Ok(Self {
            to_world,
            centre: DVec3::new(0.0, 0.0, z),
            tan_half_width: half_w / d,
            tan_half_height: half_h / d,
        })
    }

    /// This camera with its field of view scaled by `factor` (both tangents):
    /// what a wrong field of view looks like.
    pub fn with_fov_scaled(&self, factor: f64) -> Self {
        Self {
            tan_half_width: self.tan_half_width * factor,
            tan_half_height: self.tan_half_height * factor,
            ..self.clone()
        }
    }

    /// Full field of view across the shorter image side, degrees.
    pub fn fov_short_deg(&self) -> f64 {
        2.0 * self
            .tan_half_width
            .min(self.tan_half_height)
            .atan()
            .to_degrees()
    }

    /// The POV-Ray `camera { … }` block (see module docs).
    pub fn to_pov(&self) -> String {
        let m = self.to_world;
        let loc = m.transform_point3(self.centre);
        let dir = m.transform_vector3(DVec3::Z);
        let right = m.transform_vector3(DVec3::X) * (2.0 * self.tan_half_width);
        let up = m.transform_vector3(DVec3::Y) * (2.0 * self.tan_half_height);
        format!(
            "camera {{ perspective location {} direction {} right {} up {} }}",
            pov_vec(loc),
            pov_vec(dir),
            pov_vec(right),
            pov_vec(up)
        )
    }
}

/// A POV-Ray vector with every digit of the f64 (shortest round-trip form).
pub(crate) fn pov_vec(p: glam::DVec3) -> String {
    format!("<{:?},{:?},{:?}>", p.x, p.y, p.z)
}

#[cfg(test)]
mod tests {
    use super::*;
    use crate::optics::pinhole::Pinhole;
    use crate::optics::thin_lens::ThinLens;

    fn film() -> FilmSpec {
        FilmSpec {
            width_px: 400,
            height_px: 300,
            pixel_pitch_m: 1e-5,
            crop_window: None,
        }
    }

    #[test]
    fn pinhole_equivalent_of_a_pinhole_is_itself() {
        let cam = Pinhole::new(50.0, 2.0, &film()).unwrap();
        let p = PinholeEquivalent::of_camera(DMat4::IDENTITY, &cam, &film()).unwrap();
        // fov 50° spans the shorter (300 px) side; the width is 4/3 of it.
        let t = 25f64.to_radians().tan();
        assert!((p.tan_half_height - t).abs() < 1e-12, "{p:?}");
        assert!((p.tan_half_width - t * 4.0 / 3.0).abs() < 1e-12, "{p:?}");
        assert!(p.centre.length() < 1e-12);
        assert!((p.fov_short_deg() - 50.0).abs() < 1e-9);
    }

    #[test]
    fn pinhole_equivalent_of_a_thin_lens_uses_its_film_distance() {
        // f = 10 mm focused at 1 m: film distance f·s/(s − f) = 10·1000/990 mm.
        let cam = ThinLens::new(0.010, 2.0, 1.0).unwrap();
        let p = PinholeEquivalent::of_camera(DMat4::IDENTITY, &cam, &film()).unwrap();
        let d = 0.010 * 1.0 / (1.0 - 0.010);
        assert!((p.tan_half_width - 2e-3 / d).abs() < 1e-9, "{p:?}");
        assert!((p.tan_half_height - 1.5e-3 / d).abs() < 1e-9, "{p:?}");
        assert!(p.centre.length() < 1e-9);
    }
}
