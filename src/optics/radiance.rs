//! Radiance film: what pbrt's film records. Wraps any camera so that every
//! ray it lets through carries weight 1: the pixel value is then the mean
//! spectral radiance along the camera rays through the pixel, in
//! W/(sr·m²·nm) — no f-number, no cos⁴θ fall-off, no lens transmission
//! geometry. (For a pinhole or thin lens every ray passes, so this is the
//! radiance exactly; for a lens file a blocked pupil sample still counts as
//! zero, so a vignetted pixel reads radiance × the fraction of its pupil
//! samples that pass.) `camsim render --film radiance` uses it.

use super::{Camera, CameraRay};
use glam::DVec2;

/// What a rendered pixel records.
#[derive(Clone, Copy, Debug, PartialEq, Eq, Default, clap::ValueEnum)]
pub enum FilmQuantity {
    /// Physical irradiance at the sensor, W/(m²·nm) (camsim's default).
    #[default]
    Irradiance,
    /// Spectral radiance along the camera ray, W/(sr·m²·nm) (pbrt's film).
    Radiance,
}

impl FilmQuantity {
    /// The unit string written to sidecars.
    pub fn units(self) -> &'static str {
        match self {
            FilmQuantity::Irradiance => "irradiance W/(m²·nm)",
            FilmQuantity::Radiance => "radiance W/(sr·m²·nm)",
        }
    }
}

/// A camera whose passing rays all have weight 1.
pub struct RadianceCamera<C: Camera + ?Sized>(pub Box<C>);

impl<C: Camera + ?Sized> Camera for RadianceCamera<C> {
    fn sample_ray(&self, film_m: DVec2, u: DVec2, lambda_nm: f64) -> Option<CameraRay> {
        self.0
            .sample_ray(film_m, u, lambda_nm)
            .map(|r| CameraRay { weight: 1.0, ..r })
    }
    fn sample_rays(
        &self,
        film_m: &[DVec2],
        u: &[DVec2],
        lambda_nm: &[f64],
        out: &mut [Option<CameraRay>],
    ) {
        self.0.sample_rays(film_m, u, lambda_nm, out);
        for r in out.iter_mut().flatten() {
            r.weight = 1.0;
        }
    }
    fn is_dispersive(&self) -> bool {
        self.0.is_dispersive()
    }
    fn describe(&self) -> String {
        format!("{} (radiance film: ray weight 1)", self.0.describe())
    }
}

/// Wrap `camera` for the requested film quantity.
pub fn for_film(camera: Box<dyn Camera>, q: FilmQuantity) -> Box<dyn Camera> {
    match q {
        FilmQuantity::Irradiance => camera,
        FilmQuantity::Radiance => Box::new(RadianceCamera(camera)),
    }
}

#[cfg(test)]
mod tests {
    use super::*;
    use crate::optics::pinhole::Pinhole;
    use crate::scene::FilmSpec;

    #[test]
    fn radiance_film_drops_f_number_and_cos4() {
        let film = FilmSpec {
            width_px: 200,
            height_px: 100,
            pixel_pitch_m: 1e-5,
            crop_window: None,
        };
        let p = Pinhole::new(60.0, 2.0, &film).unwrap();
        let at = DVec2::new(0.0, 50.0 * 1e-5);
        let r0 = p.sample_ray(at, DVec2::ZERO, 550.0).unwrap();
        // Irradiance weight at 30°: π/(4·2²)·cos⁴30° = 0.1104…
        let want = std::f64::consts::PI / 16.0 * 30f64.to_radians().cos().powi(4);
        assert!((r0.weight - want).abs() < 1e-12);
        let c = for_film(Box::new(p), FilmQuantity::Radiance);
        let r = c.sample_ray(at, DVec2::ZERO, 550.0).unwrap();
        assert_eq!(r.weight, 1.0);
        assert_eq!((r.origin, r.direction), (r0.origin, r0.direction));
    }
}
