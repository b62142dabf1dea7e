//! Stability cases of the path tracer: a 10⁸ dynamic range, grazing light
//! and view over a seam, and 1 mm / 1 km scene scales. Small scenes built in
//! code, rendered through [`crate::render::render`] with a pinhole camera;
//! the references are closed forms (the pinhole's E = L·w(pixel), w its
//! πcos⁴θ/(4N²) weight) or the 1 m render with the same random numbers.

use super::{Check, nonfinite};
use crate::optical_image::OpticalImage;
use crate::optics::Camera;
use crate::optics::pinhole::Pinhole;
use crate::render::{RenderSettings, render};
use crate::scene::shapes::{cuboid, quad};
use crate::scene::{
    CameraModel, CameraPose, CameraSpec, Emission, FilmSpec, Light, Material, Scene,
    look_at_to_world,
};
use crate::spectrum::{Spectrum, WavelengthGrid};
use crate::{Error, Result};
use glam::{DMat4, DVec2, DVec3};
use std::f64::consts::PI;

fn constant(v: f64) -> Spectrum {
    Spectrum::constant("c", v)
}

fn settings(spp: u32, max_bounces: u32, seed: u64) -> RenderSettings {
    RenderSettings {
        spp,
        max_bounces,
        grid: WavelengthGrid::new(400.0, 700.0, 50.0).unwrap_or_default(),
        seed,
        batches: 8,
        threads: 0,
        roi: None,
        stderr_weights: vec![],
        sampler: Default::default(),
    }
}

/// Put a pinhole at `from` looking at `to` and return it with its film.
fn pinhole(
    scene: &mut Scene,
    from: DVec3,
    to: DVec3,
    fov_deg: f64,
    film: &FilmSpec,
) -> Result<Pinhole> {
    let to_world = look_at_to_world(&CameraPose {
        position: from,
        look_at: to,
        up: DVec3::Y,
    })
    .ok_or_else(|| Error::invalid("stability: degenerate camera pose"))?;
    scene.camera = Some(CameraSpec {
        to_world,
        model: CameraModel::Pinhole {
            fov_deg,
            f_number: 2.0,
            cos4: true,
        },
    });
    Pinhole::new(fov_deg, 2.0, film)
}

/// The pinhole's irradiance weight w at the centre of film pixel (x, y):
/// a surface of radiance L seen there gives E = L·w.
fn weight(cam: &Pinhole, film: &FilmSpec, x: u32, y: u32) -> Result<f64> {
    let f = DVec2::new(
        (x as f64 + 0.5 - film.width_px as f64 / 2.0) * film.pixel_pitch_m,
        (film.height_px as f64 / 2.0 - (y as f64 + 0.5)) * film.pixel_pitch_m,
    );
    cam.sample_ray(f, DVec2::splat(0.5), 550.0)
        .map(|r| r.weight)
        .ok_or_else(|| Error::invalid(format!("stability: pixel ({x}, {y}) has no camera ray")))
}

/// Non-finite samples, irradiance values and standard errors of an image.
fn nonfinite_of(img: &OpticalImage) -> usize {
    img.nan_count as usize + nonfinite(&img.irradiance) + nonfinite(&img.stderr)
}

/// E/(L·w) over `pixels` (every band): mean, its standard error (from the
/// renderer's per-pixel standard errors) and the largest |E/(L·w) − 1|.
fn ratios(
    img: &OpticalImage,
    cam: &Pinhole,
    film: &FilmSpec,
    pixels: &[(u32, u32)],
    radiance: f64,
) -> Result<(f64, f64, f64)> {
    let nb = img.bands();
    let (mut s, mut v, mut n, mut worst) = (0.0, 0.0, 0.0, 0.0f64);
    for &(x, y) in pixels {
        let e0 = radiance * weight(cam, film, x, y)?;
        let i = (y * img.width() + x) as usize * nb;
        for b in 0..nb {
            let r = img.irradiance[i + b] as f64 / e0;
            s += r;
            v += (img.stderr[i + b] as f64 / e0).powi(2);
            n += 1.0;
            worst = worst.max((r - 1.0).abs());
        }
    }
    if n == 0.0 {
        return Err(Error::invalid("stability: no pixel to compare"));
    }
    Ok((s / n, v.sqrt() / n, worst))
}

/// `dynamic-range`: an emitting wall whose two halves differ by 10⁸ in
/// radiance, seen straight on. Checks: no non-finite value; the dim and the
/// bright half each at E = L·w; no dim pixel (two pixels or more from the
/// bright half) deviating from its closed form (a bleed of 10⁻¹² of the
/// bright level would be 10⁻⁴ of the dim one).
///
/// Tolerance 10⁻⁴ (relative): the radiance is deterministic (no scattering:
/// black emitters), so the only deviations are f32 storage (6·10⁻⁸) and the
/// cos⁴ variation over a pixel footprint at ≤ 1° off axis (≈ 10⁻⁶); 10⁻⁴ is
/// ≥ 100× those and still catches a 10⁻¹² leak of the bright half.
pub fn dynamic_range(seed: u64) -> Result<Vec<Check>> {
    const DIM: f64 = 1.0;
    const BRIGHT: f64 = 1e8;
    let mut scene = Scene::default();
    let black = scene.material("black", Material::Black);
    for (name, x, le) in [("bright", -5.0, BRIGHT), ("dim", 5.0, DIM)] {
        let o = scene.object(name);
        // u × v = Y × X = −Z: faces the camera at the origin.
        scene.meshes.push(quad(
            DVec3::new(x, 0.0, 1.0),
            DVec3::Y * 10.0,
            DVec3::X * 5.0,
            black,
            o,
            Some(Emission {
                radiance: constant(le),
                two_sided: false,
            }),
        ));
    }
    let film = FilmSpec {
        width_px: 32,
        height_px: 16,
        pixel_pitch_m: 1e-5,
        crop_window: None,
    };
    let cam = pinhole(&mut scene, DVec3::ZERO, DVec3::Z, 1.0, &film)?;
    let img = render(&scene, &cam, &film, &settings(16, 2, seed))?;
    let (w, h) = (img.width(), img.height());
    let id = |n: &str| img.label_id(n);
    let (bright, dim) = (id("bright"), id("dim"));
    let label = |x: i64, y: i64| -> Option<u32> {
        (x >= 0 && y >= 0 && x < w as i64 && y < h as i64)
            .then(|| img.labels[(y as u32 * w + x as u32) as usize])
    };
    // interior pixels: every pixel within two columns/rows has the same label
    let interior = |want: Option<u32>| -> Vec<(u32, u32)> {
        let mut v = vec![];
        for y in 0..h {
            for x in 0..w {
                let same = (-2..=2).all(|dx: i64| {
                    (-2..=2).all(|dy: i64| match label(x as i64 + dx, y as i64 + dy) {
                        Some(l) => Some(l) == want,
                        None => true,
                    })
                });
                if same {
                    v.push((x, y));
                }
            }
        }
        v
    };
    let (pd, pb) = (interior(dim), interior(bright));
    let at_d = format!("{} interior pixels of the dim half (L = {DIM})", pd.len());
    let at_b = format!(
        "{} interior pixels of the bright half (L = {BRIGHT:e})",
        pb.len()
    );
    let mut checks = vec![Check::count(
        "nonfinite",
        nonfinite_of(&img),
        0,
        "every pixel, band and standard error of the 32×16 render",
    )];
    if pd.is_empty() || pb.is_empty() {
        return Err(Error::invalid(
            "dynamic-range: the camera does not see both halves",
        ));
    }
    let (md, sd, wd) = ratios(&img, &cam, &film, &pd, DIM)?;
    let (mb, sb, _) = ratios(&img, &cam, &film, &pb, BRIGHT)?;
    checks.push(Check::new("dim/irradiance_ratio", md, 1.0, 1e-4, &at_d).with_stderr(sd));
    checks.push(Check::new("bright/irradiance_ratio", mb, 1.0, 1e-4, &at_b).with_stderr(sb));
    checks.push(Check::new("dim/max_deviation", wd, 0.0, 1e-4, &at_d));
    Ok(checks)
}

/// `grazing`: a Lambertian floor (ρ = 0.5) of two coplanar quads meeting at
/// a seam, lit by a distant light 89.9° and 89.99° from the normal and seen
/// 0.1°–0.3° above the horizon by a camera 1 mm over it, across the seam.
/// Its radiance is exactly ρ·E⊥·cos θᵢ/π (a delta light: no Monte Carlo
/// noise). Checks per angle: no non-finite value; every pixel sees the floor
/// (no ray slips through the seam); E/(L·w) = 1 on average and per pixel
/// (a grazing shadow ray that re-hit the floor or its neighbour quad would
/// darken a pixel completely).
///
/// Tolerance 10⁻⁴ (relative): the floor's normal is exact (axis-aligned
/// f32 vertices) so cos θᵢ is an f64 dot product (relative error
/// ≈ 10⁻¹⁶/cos θᵢ ≈ 10⁻¹²); the rest is f32 storage (6·10⁻⁸) and cos⁴
/// variation over a pixel of a 0.2° field (< 10⁻⁸).
pub fn grazing(seed: u64) -> Result<Vec<Check>> {
    const RHO: f64 = 0.5;
    const E_PERP: f64 = 3.0;
    let mut checks = vec![];
    for theta_deg in [89.9f64, 89.99] {
        let mut scene = Scene::default();
        let m = scene.material(
            "floor",
            Material::Diffuse {
                reflectance: constant(RHO),
            },
        );
        let o = scene.object("floor");
        let half = 100.0;
        for x in [-half / 2.0, half / 2.0] {
            // u × v = Z × X = +Y: faces up; the two quads share the x = 0 edge.
            scene.meshes.push(quad(
                DVec3::new(x, 0.0, half),
                DVec3::Z * half,
                DVec3::X * (half / 2.0),
                m,
                o,
                None,
            ));
        }
        let t = theta_deg.to_radians();
        // travels along +x, grazing the floor
        scene.lights.push(Light::Distant {
            direction: DVec3::new(t.sin(), -t.cos(), 0.0),
            irradiance: constant(E_PERP),
        });
        let film = FilmSpec {
            width_px: 16,
            height_px: 16,
            pixel_pitch_m: 1e-5,
            crop_window: None,
        };
        // 1 mm above the floor, 0.13 mm off the seam, looking 0.2° down
        let from = DVec3::new(1.3e-4, 1e-3, 0.0);
        let down = 0.2f64.to_radians();
        let to = from + DVec3::new(0.0, -down.sin(), down.cos());
        let cam = pinhole(&mut scene, from, to, 0.2, &film)?;
        let img = render(&scene, &cam, &film, &settings(8, 1, seed))?;
        let tag = format!("{theta_deg}deg");
        let at = format!("16×16 pixels of the floor, light {theta_deg}° from the normal");
        checks.push(Check::count(
            &format!("{tag}/nonfinite"),
            nonfinite_of(&img),
            0,
            &at,
        ));
        let floor = img.label_id("floor");
        let off = img.labels.iter().filter(|&&l| Some(l) != floor).count();
        checks.push(Check::count(
            &format!("{tag}/pixels_missing_the_floor"),
            off,
            0,
            "the seam at x = 0 runs through the view",
        ));
        let pixels: Vec<(u32, u32)> = (0..img.height())
            .flat_map(|y| (0..img.width()).map(move |x| (x, y)))
            .collect();
        let l = RHO * E_PERP * t.cos() / PI;
        let (mean, se, worst) = ratios(&img, &cam, &film, &pixels, l)?;
        checks.push(
            Check::new(&format!("{tag}/irradiance_ratio"), mean, 1.0, 1e-4, &at).with_stderr(se),
        );
        checks.push(Check::new(
            &format!("{tag}/max_deviation"),
            worst,
            0.0,
            1e-4,
            &at,
        ));
    }
    Ok(checks)
}

/// The scale case's scene: a closed diffuse box with a lamp, a rotated cube
/// and a camera inside, every length × `s`.
fn box_scene(s: f64) -> Result<(Scene, Pinhole, FilmSpec)> {
    let mut scene = Scene::default();
    let white = scene.material(
        "white",
        Material::Diffuse {
            reflectance: constant(0.6),
        },
    );
    let grey = scene.material(
        "grey",
        Material::Diffuse {
            reflectance: constant(0.3),
        },
    );
    let black = scene.material("black", Material::Black);
    let (walls, cube, lamp) = (
        scene.object("walls"),
        scene.object("cube"),
        scene.object("lamp"),
    );
    scene.meshes.push(cuboid(
        DVec3::splat(0.5 * s),
        DMat4::IDENTITY,
        true,
        white,
        walls,
        None,
    ));
    let rot =
        DMat4::from_translation(DVec3::new(-0.15, -0.35, 0.15) * s) * DMat4::from_rotation_y(0.5);
    scene
        .meshes
        .push(cuboid(DVec3::splat(0.15 * s), rot, false, grey, cube, None));
    scene.meshes.push(quad(
        DVec3::new(0.0, 0.499, 0.0) * s,
        DVec3::X * 0.1 * s,
        DVec3::Z * 0.1 * s,
        black,
        lamp,
        Some(Emission {
            radiance: constant(50.0),
            two_sided: false,
        }),
    ));
    let film = FilmSpec {
        width_px: 24,
        height_px: 20,
        pixel_pitch_m: 2e-6,
        crop_window: None,
    };
    let cam = pinhole(
        &mut scene,
        DVec3::new(0.0, 0.0, -0.45) * s,
        DVec3::new(0.0, 0.0, 1.0) * s,
        70.0,
        &film,
    )?;
    Ok((scene, cam, film))
}

/// `scale`: the same box at 1 mm, 1 m and 1 km, same seed. Radiance does
/// not depend on scale, so each image must equal the 1 m one path for path.
/// Checks: no non-finite value at either scale; the image sum's ratio to
/// the 1 m image = 1.
///
/// Tolerance 10⁻⁴ (relative): the same random numbers drive the same paths
/// at every scale; they part only where f32 rounding of the scaled geometry
/// flips a hit (measured |ratio − 1| ≈ 10⁻⁵ in the renderer's own test of a
/// similar box). A scale bug (an epsilon in metres, a unit error) moves
/// whole paths: of the order of the 16-spp image sum's standard error,
/// ≈ 10⁻², far above 10⁻⁴.
pub fn scale(seed: u64) -> Result<Vec<Check>> {
    let run = |s: f64| -> Result<OpticalImage> {
        let (scene, cam, film) = box_scene(s)?;
        render(&scene, &cam, &film, &settings(16, 4, seed))
    };
    let sum = |img: &OpticalImage| img.irradiance.iter().map(|&x| x as f64).sum::<f64>();
    let metre = run(1.0)?;
    let m_sum = sum(&metre);
    let mut checks = vec![Check::count(
        "1m/nonfinite",
        nonfinite_of(&metre),
        0,
        "the 1 m box",
    )];
    for (tag, s) in [("1mm", 1e-3), ("1km", 1e3)] {
        let img = run(s)?;
        let at = format!("the box scaled × {s} against the 1 m box (same seed)");
        checks.push(Check::count(
            &format!("{tag}/nonfinite"),
            nonfinite_of(&img),
            0,
            &at,
        ));
        // same random numbers: the ratio has no Monte Carlo error of its own
        checks.push(Check::new(
            &format!("{tag}/sum_ratio"),
            sum(&img) / m_sum,
            1.0,
            1e-4,
            &at,
        ));
    }
    Ok(checks)
}
