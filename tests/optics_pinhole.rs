//! The ideal pinhole's ray weight against its closed form: the irradiance of
//! an ideal lens of f-number N on a Lambertian scene of radiance 1,
//! E(θ)/L = π/(4N²)·cos⁴θ (natural vignetting), at field points off both
//! axes; and its ray direction through the pinhole.

use camsim::optics::Camera;
use camsim::optics::pinhole::Pinhole;
use camsim::scene::FilmSpec;
use glam::DVec2;

#[test]
fn pinhole_weight_is_the_cos4_law_at_every_field_point() {
    let film = FilmSpec {
        width_px: 400,
        height_px: 300,
        pixel_pitch_m: 2e-6,
        crop_window: None,
    };
    let p = Pinhole::new(70.0, 2.8, &film).unwrap();
    let d = p.film_distance_m;
    // Shorter side (300 px) spans 70°: d = 0.5·300·2 µm / tan 35°.
    assert!((d - 3e-4 / 35f64.to_radians().tan()).abs() < 1e-15);
    for (fx, fy) in [
        (0.0, 0.0),
        (2e-4, 0.0),
        (0.0, -3e-4),
        (-3.9e-4, 2.9e-4),
        (1e-4, 1e-4),
    ] {
        let r = p
            .sample_ray(DVec2::new(fx, fy), DVec2::ZERO, 550.0)
            .unwrap();
        let theta = f64::sqrt(fx * fx + fy * fy).atan2(d);
        let want = std::f64::consts::PI / (4.0 * 2.8 * 2.8) * theta.cos().powi(4);
        // f64 throughout: 1e-12 relative.
        assert!(
            (r.weight / want - 1.0).abs() < 1e-12,
            "field ({fx}, {fy}): weight {} vs π/(4N²)cos⁴θ = {want}",
            r.weight
        );
        // The ray leaves the pinhole towards the scene point imaged at f
        // (direction (f, d)/|…|, the image is not flipped in camera space).
        assert!((r.direction.z - theta.cos()).abs() < 1e-12);
        assert!(r.origin.length() == 0.0);
    }
}
