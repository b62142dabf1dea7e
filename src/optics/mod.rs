//! Optics: the camera interface used by the renderer, and camera models
//! (pinhole, thin lens, lens prescriptions, ray-transfer functions).
//!
//! Conventions (shared by every model):
//! - Camera space: +z forward (into the scene), +y up, +x to the right of the
//!   final, upright image (pbrt's left-handed camera frame). Metres.
//! - `film_m` is the film position in *image* coordinates: (0,0) on the optical
//!   axis, +x right and +y up in the upright image the user sees. A real lens
//!   forms an inverted image; each model maps `film_m` to the physical film point
//!   itself (physical = −film_m), so every camera yields an upright image.
//! - The returned `weight` turns scene radiance into film irradiance:
//!   E(film_m) = E[weight · L(ray)], in W/(m²·nm) for L in W/(sr·m²·nm).
//!   For an ideal lens of f-number N this gives E = πL/(4N²)·cos⁴θ.

pub mod pinhole;

use glam::{DVec2, DVec3};

/// A ray leaving the optics into the scene, in camera space.
#[derive(Clone, Copy, Debug, PartialEq)]
pub struct CameraRay {
    pub origin: DVec3,
    /// Unit direction.
    pub direction: DVec3,
    /// Radiance-to-irradiance weight of this sample (see module docs); ≥ 0, finite.
    pub weight: f64,
}

/// The camera interface: turn a film point into a weighted ray.
pub trait Camera: Send + Sync {
    /// Sample one ray for film point `film_m` (metres, image coordinates), using
    /// the two uniform numbers `u` ∈ [0,1)² for the pupil / aperture, at
    /// wavelength `lambda_nm` (only dispersive optics depend on it).
    /// Returns None when the sample is blocked (vignetted) — that is a zero
    /// contribution, not a missing sample.
    fn sample_ray(&self, film_m: DVec2, u: DVec2, lambda_nm: f64) -> Option<CameraRay>;
    /// `sample_ray` for several samples at once: `out[i]` is
    /// `sample_ray(film_m[i], u[i], lambda_nm[i])`, bit for bit (all four
    /// slices have one length). The renderer asks for the camera rays of a
    /// packet's idle lanes together; a camera whose ray is a long chain of
    /// dependent steps (the RTF) works on them side by side.
    fn sample_rays(
        &self,
        film_m: &[DVec2],
        u: &[DVec2],
        lambda_nm: &[f64],
        out: &mut [Option<CameraRay>],
    ) {
        for (((o, &f), &u), &l) in out.iter_mut().zip(film_m).zip(u).zip(lambda_nm) {
            *o = self.sample_ray(f, u, l);
        }
    }
    /// True when ray geometry depends on wavelength (then the renderer uses
    /// hero-wavelength sampling instead of carrying all bands on one path).
    fn is_dispersive(&self) -> bool {
        false
    }
    /// Human-readable description for sidecars and reports.
    fn describe(&self) -> String;
    /// Distance from the film to the optics it sits behind (pinhole, thin lens,
    /// rear vertex of a prescription, RTF input plane's reference), metres;
    /// None for test cameras that do not say.
    fn film_distance_m(&self) -> Option<f64> {
        None
    }
}

pub mod analysis;
pub mod camera;
pub mod fit;
pub mod lstsq;
pub mod pass_region;
pub mod prescription;
pub mod radiance;
pub mod rtf;
pub mod thin_lens;
