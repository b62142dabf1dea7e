//! `camsim bench render`: Mitsuba 3's `cornell_box()` scene (five rectangles,
//! two boxes, one rectangular area light; 256×256; fov 39.3077° on the
//! smaller axis; Mitsuba max_depth 7 ≙ max_bounces 6) rendered with all 31
//! bands per path on a fixed thread count. Reports paths/s for BVH2 and
//! CWBVH and the RMSE of the timed render against a high-spp reference.
//!
//! Mitsuba's RGB reflectances and emission are upsampled to spectra with a
//! simple smooth three-band partition of unity (blue < 490 nm, red > 590 nm,
//! linear ramps of 30 nm), not Jakob–Hanika; this changes colours slightly,
//! not the cost.

use super::RenderSettings;
use super::film::render_world;
use super::geometry::BvhKind;
use super::world::World;
use crate::Result;
use crate::optics::pinhole::Pinhole;
use crate::scene::shapes::{cuboid, quad};
use crate::scene::{
    CameraModel, CameraPose, CameraSpec, Emission, FilmSpec, Material, Scene, look_at_to_world,
};
use crate::spectrum::Spectrum;
use glam::{DMat4, DVec3};

fn rgb_spectrum(name: &str, rgb: [f64; 3]) -> Spectrum {
    let wl: Vec<f64> = (0..=80).map(|i| 380.0 + 5.0 * i as f64).collect();
    let v = wl
        .iter()
        .map(|&l| {
            let b = ((505.0 - l) / 30.0).clamp(0.0, 1.0);
            let r = ((l - 575.0) / 30.0).clamp(0.0, 1.0);
            let g = (1.0 - b - r).max(0.0);
            rgb[0] * r + rgb[1] * g + rgb[2] * b
        })
        .collect();
    Spectrum::new(name, wl, v)
        .expect("valid spectrum")
        .with_extrapolation(crate::spectrum::Extrapolation::Clamp)
}

/// Mitsuba 3 `cornell_box()` as a camsim scene, with its film.
pub fn mitsuba_cornell_box() -> (Scene, FilmSpec) {
    let mut s = Scene::default();
    let white = s.material(
        "white",
        Material::Diffuse {
            reflectance: rgb_spectrum("white", [0.885809, 0.698859, 0.666422]),
        },
    );
    let green = s.material(
        "green",
        Material::Diffuse {
            reflectance: rgb_spectrum("green", [0.105421, 0.37798, 0.076425]),
        },
    );
    let red = s.material(
        "red",
        Material::Diffuse {
            reflectance: rgb_spectrum("red", [0.570068, 0.0430135, 0.0443706]),
        },
    );
    let deg = f64::to_radians;
    let t = DMat4::from_translation;
    let rect = |s: &mut Scene, name: &str, m: DMat4, mat: u32, e: Option<Emission>| {
        let o = s.object(name);
        let c = m.transform_point3(DVec3::ZERO);
        s.meshes.push(quad(
            c,
            m.transform_vector3(DVec3::X),
            m.transform_vector3(DVec3::Y),
            mat,
            o,
            e,
        ));
    };
    let le = Emission {
        radiance: rgb_spectrum("light", [18.387, 13.9873, 6.75357]),
        two_sided: false,
    };
    rect(
        &mut s,
        "light",
        t(DVec3::new(0.0, 0.99, 0.01))
            * DMat4::from_rotation_x(deg(90.0))
            * DMat4::from_scale(DVec3::new(0.23, 0.19, 0.19)),
        white,
        Some(le),
    );
    rect(
        &mut s,
        "floor",
        t(DVec3::new(0.0, -1.0, 0.0)) * DMat4::from_rotation_x(deg(-90.0)),
        white,
        None,
    );
    rect(
        &mut s,
        "ceiling",
        t(DVec3::new(0.0, 1.0, 0.0)) * DMat4::from_rotation_x(deg(90.0)),
        white,
        None,
    );
    rect(&mut s, "back", t(DVec3::new(0.0, 0.0, -1.0)), white, None);
    rect(
        &mut s,
        "green-wall",
        t(DVec3::new(1.0, 0.0, 0.0)) * DMat4::from_rotation_y(deg(-90.0)),
        green,
        None,
    );
    rect(
        &mut s,
        "red-wall",
        t(DVec3::new(-1.0, 0.0, 0.0)) * DMat4::from_rotation_y(deg(90.0)),
        red,
        None,
    );
    let o = s.object("small-box");
    s.meshes.push(cuboid(
        DVec3::ONE,
        t(DVec3::new(0.335, -0.7, 0.38))
            * DMat4::from_rotation_y(deg(-17.0))
            * DMat4::from_scale(DVec3::splat(0.3)),
        false,
        white,
        o,
        None,
    ));
    let o = s.object("large-box");
    s.meshes.push(cuboid(
        DVec3::ONE,
        t(DVec3::new(-0.33, -0.4, -0.28))
            * DMat4::from_rotation_y(deg(18.25))
            * DMat4::from_scale(DVec3::new(0.3, 0.61, 0.3)),
        false,
        white,
        o,
        None,
    ));
    let to_world = look_at_to_world(&CameraPose {
        position: DVec3::new(0.0, 0.0, 3.9),
        look_at: DVec3::ZERO,
        up: DVec3::Y,
    })
    .expect("pose");
    s.camera = Some(CameraSpec {
        to_world,
        model: CameraModel::Pinhole {
            fov_deg: 39.3077,
            f_number: 1.0,
        },
    });
    let film = FilmSpec {
        width_px: 256,
        height_px: 256,
        pixel_pitch_m: 1e-5,
        crop_window: None,
    };
    s.film = Some(film.clone());
    (s, film)
}

/// Process CPU time (user + system) in seconds, from /proc (Linux); None elsewhere.
fn cpu_time_s() -> Option<f64> {
    let s = std::fs::read_to_string("/proc/self/stat").ok()?;
    // Fields after the command name (which is in parentheses): utime is field 14, stime 15.
    let rest = &s[s.rfind(')')? + 2..];
    let f: Vec<&str> = rest.split_whitespace().collect();
    let ut: f64 = f.get(11)?.parse().ok()?;
    let st: f64 = f.get(12)?.parse().ok()?;
    Some((ut + st) / 100.0) // USER_HZ is 100 on Linux
}

/// Run the benchmark and return a printable report.
pub fn run(spp: u32, ref_spp: u32, threads: usize, bands: usize) -> Result<String> {
    let (scene, film) = mitsuba_cornell_box();
    let cam = Pinhole::new(39.3077, 1.0, &film)?;
    let to_world = scene
        .camera
        .as_ref()
        .map(|c| c.to_world)
        .unwrap_or(DMat4::IDENTITY);
    let names: Vec<String> = scene.objects.iter().map(|o| o.name.clone()).collect();
    let settings = RenderSettings {
        spp,
        max_bounces: 6,
        threads,
        seed: 1,
        grid: crate::spectrum::WavelengthGrid {
            start_nm: 400.0,
            step_nm: if bands > 1 {
                300.0 / (bands - 1) as f64
            } else {
                10.0
            },
            count: bands.max(1),
        },
        ..Default::default()
    };
    let mut out = format!(
        "Mitsuba 3 cornell_box(): 256×256, {} bands per path, max_bounces 6 (Mitsuba max_depth 7), {threads} threads\n",
        settings.grid.len()
    );
    let mut timed = None;
    for kind in [BvhKind::Bvh4, BvhKind::Bvh2, BvhKind::Cwbvh] {
        let world = World::build(&scene, &settings.grid, kind)?;
        let cpu0 = cpu_time_s();
        let img = render_world(&world, &cam, &to_world, &film, &settings, names.clone())?;
        let cpu = cpu_time_s()
            .zip(cpu0)
            .map(|(b, a)| b - a)
            .unwrap_or(f64::NAN);
        let paths = film.width_px as f64 * film.height_px as f64 * spp as f64;
        out += &format!(
            "  {kind:?}: {spp} spp in {:.3} s = {:.3} M paths/s wall; {:.2} CPU s = {:.3} M paths per CPU-second ({} non-finite)\n",
            img.render_s,
            paths / img.render_s / 1e6,
            cpu,
            paths / cpu / 1e6,
            img.nan_count
        );
        if kind == BvhKind::Bvh4 {
            timed = Some(img);
        }
    }
    let timed = timed.expect("rendered");
    let world = World::build(&scene, &settings.grid, BvhKind::Bvh4)?;
    let rs = RenderSettings {
        spp: ref_spp,
        seed: 0xC0FFEE,
        ..settings.clone()
    };
    let reference = render_world(&world, &cam, &to_world, &film, &rs, names)?;
    let (mut se, mut sum) = (0.0f64, 0.0f64);
    for (a, r) in timed.irradiance.iter().zip(&reference.irradiance) {
        se += ((a - r) as f64).powi(2);
        sum += *r as f64;
    }
    let n = timed.irradiance.len() as f64;
    let rmse = (se / n).sqrt();
    // The reference has its own noise: subtract its expected contribution
    // (variance ∝ 1/spp) to estimate the RMSE against the converged image.
    let rmse_true = rmse / (1.0 + spp as f64 / ref_spp as f64).sqrt();
    out += &format!(
        "  reference: {ref_spp} spp in {:.1} s\n  RMSE of the {spp}-spp render ({:.3} s): {:.4e} W/(m²·nm) = {:.3} % of the mean (≈{:.3} % against the converged image)\n",
        reference.render_s,
        timed.render_s,
        rmse,
        100.0 * rmse / (sum / n),
        100.0 * rmse_true / (sum / n)
    );
    Ok(out)
}
