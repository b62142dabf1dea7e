//! `camsim bench render`: Mitsuba 3's `cornell_box()` scene (five rectangles,
//! two boxes, one rectangular area light; 256×256; fov 39.3077° on the
//! smaller axis; Mitsuba max_depth 7 ≙ max_bounces 6) rendered with all 31
//! bands per path on a fixed thread count. Reports paths/s (BVH2 and/or
//! CWBVH) and the RMSE of the timed render's CIE Y luminance against a
//! reference: camsim's own high-spp render by default, or a given reference
//! image (`--reference Y.pfm`, e.g. Mitsuba's converged render written by
//! `bench/mitsuba_compare.sh`).
//!
//! ## Same scene as Mitsuba, spectrally
//! Mitsuba's spectral variants upsample the scene's RGB values with the
//! Jakob–Hanika (2019) sigmoid model: ρ(λ) = ½ + x/(2√(1+x²)) with
//! x = (c₀λ + c₁)λ + c₂ (λ in nm). Reflectances use the coefficients of the
//! RGB itself; an emitter's RGB is divided by `scale = 2·max(rgb)`, upsampled,
//! and multiplied by `scale` and by D65 normalised to unit luminance
//! (Y = ∫ D65·ȳ / ∫ȳ = 1). The coefficients below are Mitsuba 3.9.1's own
//! (`mi.srgb_model_fetch`, printed again by the compare script), so camsim
//! renders exactly Mitsuba's spectra, not a look-alike.
//!
//! ## Compared quantity
//! Mitsuba's film holds radiance (its perspective camera has importance
//! weight 1, no cos⁴θ) converted to linear sRGB from the CIE 1931 CMFs over
//! 360–830 nm. camsim renders spectral radiance on 400–700 nm (31 bands), so
//! the bench uses a pinhole whose weight is 1 (film value = radiance) and
//! compares **CIE Y luminance** normalised as Mitsuba does,
//! Y = Σ L(λᵢ)·ȳ(λᵢ)·Δλ / ∫ȳ: ȳ is < 0.5 % of its peak outside 400–700 nm,
//! so truncating the band range changes Y by < 0.1 % whereas X and Z (and so
//! sRGB R and B) would lose several per cent. From Mitsuba's sRGB,
//! Y = 0.212671 R + 0.715160 G + 0.072169 B (the inverse of its XYZ→sRGB).
//! The pixel filter is a box on both sides (Mitsuba's default Gaussian
//! spreads samples over neighbouring pixels and lowers per-pixel noise at the
//! cost of blur; the script switches it to `box`).
//!
//! ## RMSE
//! RMSE = √(mean over pixels of (Y − Y_ref)²), reported relative to the mean
//! reference Y. A reference has noise of its own: when its per-pixel
//! variance is known (`--reference-var`, from independent batches) its mean
//! is subtracted from the squared error, giving the RMSE against the
//! converged image; for camsim's own reference the variance is estimated
//! from the spp ratio (variance ∝ 1/spp).
//!
//! Images are exchanged as PFM (grey `Pf`, little-endian, rows bottom to top).
//!
//! ## Camera frame
//! Mitsuba's world is right-handed (red wall at x = −1 on the image's left).
//! camsim's camera frame is pbrt's, and `look_at_to_world` is pbrt's LookAt,
//! which mirrors such a scene left–right; the bench writes Mitsuba's camera
//! matrix out instead (see `mitsuba_cornell_box`).
//!
//! ## Measured (`bench/mitsuba_compare.sh`, 2 threads)
//! Current figures per machine are in the README (*Performance by
//! machine*). `--batches` and `--sampler` set the timed render's batches and
//! sampler (the compare script uses one batch of the Sobol sampler, one
//! image as Mitsuba renders it). Method notes from the first runs (load ≈
//! 6–7, independent sampling):
//! - Converged images agree: camsim 512 spp vs Mitsuba 1024 spp, mean Y
//!   ratio 0.9999; 16×16-pixel block means differ by 0.47 % RMS (max 1.6 %),
//!   which is their Monte Carlo noise; no systematic per-pixel difference.
//! - Mitsuba must be timed to kernel completion (`dr.sync_thread()`): timing
//!   `mi.render()` + `dr.eval()` alone times the asynchronous launch and
//!   reports tens of M paths/s; the issue's 3.4 M paths/s is not
//!   reproducible with a synchronised timer on this machine.
//! - ~85 % of the all-pixel MSE is pixel-coverage noise on the emitter's
//!   edge (identical for both, heavy-tailed: one image's RMSE scatters ±5 %),
//!   hence the separate light-transport figure (emitter ±2 px excluded).
//! - camsim's extra per-sample noise was its Russian roulette (from the 2nd
//!   bounce, survival = max-band throughput, as pbrt-v4), not NEE/MIS: with
//!   Mitsuba's policy (from depth 5, survival min(max β, 0.95)) camsim's
//!   transport RMSE at 32 spp is 16.19 % = Mitsuba's 16.2 %, at 23 % more CPU
//!   time; efficiency 1/(RMSE²·t) for RR from depth 2/3/4/5: 5.21, 5.21,
//!   5.04, 5.01 (transport), 3.76, 3.52, 3.24, 3.15 (all pixels), so the
//!   current early roulette is the better equal-time choice. The excess sits on
//!   the green wall (block RMSE 19 % vs 14 %), where β after the green bounce
//!   is ≤ 0.5 and early roulette kills most indirect paths. Since 2026-11-28
//!   survival is relative to the throughput after the first bounce
//!   (`path::roulette`): the green wall's 32-px blocks went from 1.4–2.2× to
//!   0.75–1.0× Mitsuba's MSE, light transport at equal spp 0.834 → 0.798.
//! - Almost all of the light-transport noise is indirect light: with the
//!   light's position stratified (`World::choose_light` reuses the draw),
//!   the relative MSE at 32 spp is 0.7 % of the total with one bounce
//!   (direct light only), 39 % from paths with one indirect bounce, 60 % from
//!   longer ones.

use super::accel::BvhKind;
use super::film::render_world;
use super::sampler::SamplerKind;
use super::settings::RenderSettings;
use super::world::World;
use crate::optical_image::OpticalImage;
use crate::optics::pinhole::Pinhole;
use crate::optics::{Camera, CameraRay};
use crate::scene::shapes::{cuboid, quad};
use crate::scene::{CameraModel, CameraSpec, Emission, FilmSpec, Material, Scene};
use crate::spectrum::{Extrapolation, Spectrum, library};
use crate::{Error, Result};
use glam::{DMat4, DVec2, DVec3};
use std::path::{Path, PathBuf};

/// Jakob–Hanika sigmoid polynomial coefficients (c₀, c₁, c₂), λ in nm, as
/// Mitsuba 3.9.1's `srgb_model_fetch` returns them.
pub const JH_WHITE: [f64; 3] = [
    3.450432632234879e-05,
    -0.033416666090488434,
    8.416033744812012,
];
pub const JH_GREEN: [f64; 3] = [
    -0.00015634791634511203,
    0.16951896250247955,
    -46.169395446777344,
];
pub const JH_RED: [f64; 3] = [
    0.0001366714423056692,
    -0.13359785079956055,
    30.404735565185547,
];
/// The light's RGB (18.387, 13.9873, 6.75357) divided by its scale 2·18.387.
pub const JH_LIGHT: [f64; 3] = [
    -1.8160400941269472e-05,
    0.023512836545705795,
    -7.659915924072266,
];
pub const LIGHT_SCALE: f64 = 36.774;

/// The Jakob–Hanika sigmoid spectrum at `lambda_nm`.
pub fn jakob_hanika(c: [f64; 3], lambda_nm: f64) -> f64 {
    let x = (c[0] * lambda_nm + c[1]) * lambda_nm + c[2];
    0.5 + x / (2.0 * (1.0 + x * x).sqrt())
}

/// ∫ȳ dλ of the CIE 1931 table (trapezoid on its 5 nm samples), nm.
pub fn cie_y_integral_nm() -> f64 {
    let y = &library::cie1931_cmfs()[1];
    integrate_table(|l| y.eval(l))
}

fn integrate_table(f: impl Fn(f64) -> f64) -> f64 {
    // The CIE tables shipped are 380–780 nm in 5 nm steps.
    (0..=80)
        .map(|i| {
            let l = 380.0 + 5.0 * i as f64;
            let w = if i == 0 || i == 80 { 2.5 } else { 5.0 };
            f(l) * w
        })
        .sum()
}

/// Factor that normalises CIE D65 (relative table) to unit luminance, as
/// Mitsuba's `d65` spectrum does: ∫ȳ / ∫D65·ȳ (≈ 0.0101).
pub fn d65_unit_luminance_scale() -> f64 {
    let y = &library::cie1931_cmfs()[1];
    let d65 = library::named("cie-d65").expect("embedded D65");
    cie_y_integral_nm() / integrate_table(|l| d65.eval(l) * y.eval(l))
}

fn sampled(name: &str, f: impl Fn(f64) -> f64) -> Spectrum {
    let wl: Vec<f64> = (0..=90).map(|i| 360.0 + 5.0 * i as f64).collect();
    let v = wl.iter().map(|&l| f(l)).collect();
    Spectrum::new(name, wl, v)
        .expect("valid spectrum")
        .with_extrapolation(Extrapolation::Clamp)
}

/// Mitsuba's reflectance spectrum for an RGB with coefficients `c`.
pub fn reflectance_spectrum(name: &str, c: [f64; 3]) -> Spectrum {
    sampled(name, |l| jakob_hanika(c, l))
}

/// Mitsuba's area-light radiance spectrum, W/(sr·m²·nm) in Mitsuba's units.
pub fn light_spectrum() -> Spectrum {
    let d65 = library::named("cie-d65").expect("embedded D65");
    let k = d65_unit_luminance_scale();
    sampled("light", |l| {
        LIGHT_SCALE * jakob_hanika(JH_LIGHT, l) * k * d65.eval(l)
    })
}

/// A pinhole whose samples carry weight 1: the film holds radiance, like
/// Mitsuba's perspective camera (no π/(4N²), no cos⁴θ).
struct RadiancePinhole(Pinhole);

impl Camera for RadiancePinhole {
    fn sample_ray(&self, film_m: DVec2, u: DVec2, lambda_nm: f64) -> Option<CameraRay> {
        self.0
            .sample_ray(film_m, u, lambda_nm)
            .map(|r| CameraRay { weight: 1.0, ..r })
    }
    fn film_distance_m(&self) -> Option<f64> {
        Some(self.0.film_distance_m)
    }
    fn describe(&self) -> String {
        format!("radiance {}", self.0.describe())
    }
}

/// Mitsuba 3 `cornell_box()` as a camsim scene, with its film.
pub fn mitsuba_cornell_box() -> (Scene, FilmSpec) {
    let mut s = Scene::default();
    let white = s.material(
        "white",
        Material::Diffuse {
            reflectance: reflectance_spectrum("white", JH_WHITE),
        },
    );
    let green = s.material(
        "green",
        Material::Diffuse {
            reflectance: reflectance_spectrum("green", JH_GREEN),
        },
    );
    let red = s.material(
        "red",
        Material::Diffuse {
            reflectance: reflectance_spectrum("red", JH_RED),
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
        radiance: light_spectrum(),
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
    // Mitsuba's sensor: at (0, 0, 3.9) looking down −z, up +y, in a
    // right-handed world where the red wall (x = −1) appears on the image's
    // left. camsim's camera frame is pbrt's (left-handed: +x = image right),
    // and `look_at_to_world` builds pbrt's LookAt, whose +x would be world −x
    // here (a mirrored image, as pbrt gives without `Scale -1 1 1`). So the
    // camera matrix is written out: camera +x → world +x, +y → +y, +z → −z.
    let to_world = DMat4::from_cols(
        DVec3::X.extend(0.0),
        DVec3::Y.extend(0.0),
        DVec3::NEG_Z.extend(0.0),
        DVec3::new(0.0, 0.0, 3.9).extend(1.0),
    );
    s.camera = Some(CameraSpec {
        to_world,
        model: CameraModel::Pinhole {
            fov_deg: 39.3077,
            f_number: 1.0,
            cos4: true,
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

/// CIE Y luminance per pixel (row-major, top row first), normalised as
/// Mitsuba's film: Y = Σ L(λᵢ)·ȳ(λᵢ)·Δλ / ∫ȳ.
pub fn luminance_y(img: &OpticalImage) -> Vec<f32> {
    let nb = img.bands();
    let y = &library::cie1931_cmfs()[1];
    let norm = cie_y_integral_nm();
    let w: Vec<f64> = (0..nb)
        .map(|b| y.eval(img.grid.wavelength(b)) * img.grid.step_nm / norm)
        .collect();
    img.irradiance
        .chunks_exact(nb)
        .map(|p| p.iter().zip(&w).map(|(&l, &k)| l as f64 * k).sum::<f64>() as f32)
        .collect()
}

/// Write a grey PFM (`Pf`, little-endian, rows bottom to top); `data` is
/// row-major with the top row first.
pub fn write_pfm(path: &Path, width: usize, height: usize, data: &[f32]) -> Result<()> {
    if data.len() != width * height {
        return Err(Error::invalid(format!(
            "{}: {} values for a {width}×{height} image",
            path.display(),
            data.len()
        )));
    }
    let mut bytes = format!("Pf\n{width} {height}\n-1.0\n").into_bytes();
    for row in data.chunks_exact(width).rev() {
        for v in row {
            bytes.extend_from_slice(&v.to_le_bytes());
        }
    }
    crate::diag::write_atomic(path, &bytes)
}

/// Read a grey PFM; returns (width, height, data with the top row first).
pub fn read_pfm(path: &Path) -> Result<(usize, usize, Vec<f32>)> {
    let bad = |m: &str| Error::Io {
        path: path.to_path_buf(),
        message: m.to_string(),
    };
    let bytes = std::fs::read(path).map_err(|e| bad(&e.to_string()))?;
    // Header: three whitespace-separated tokens after "Pf", then one whitespace byte.
    let mut tokens = Vec::new();
    let mut i = 0;
    while tokens.len() < 4 {
        while i < bytes.len() && bytes[i].is_ascii_whitespace() {
            i += 1;
        }
        let s = i;
        while i < bytes.len() && !bytes[i].is_ascii_whitespace() {
            i += 1;
        }
        if s == i {
            return Err(bad("truncated PFM header"));
        }
        tokens.push(String::from_utf8_lossy(&bytes[s..i]).into_owned());
    }
    i += 1;
    if tokens[0] != "Pf" {
        return Err(bad("not a grey PFM (expected 'Pf')"));
    }
    let w: usize = tokens[1].parse().map_err(|_| bad("bad PFM width"))?;
    let h: usize = tokens[2].parse().map_err(|_| bad("bad PFM height"))?;
    let scale: f64 = tokens[3].parse().map_err(|_| bad("bad PFM scale"))?;
    if !(scale < 0.0) {
        return Err(bad("big-endian PFM (positive scale) is not supported"));
    }
    let n = w * h;
    if bytes.len() < i + 4 * n {
        return Err(bad(&format!(
            "{w}×{h} PFM needs {} data bytes, file has {}",
            4 * n,
            bytes.len().saturating_sub(i)
        )));
    }
    let flat: Vec<f32> = bytes[i..i + 4 * n]
        .chunks_exact(4)
        .map(|c| f32::from_le_bytes([c[0], c[1], c[2], c[3]]))
        .collect();
    if flat.iter().any(|v| !v.is_finite()) {
        return Err(bad("non-finite pixel values"));
    }
    let data = flat.chunks_exact(w).rev().flatten().copied().collect();
    Ok((w, h, data))
}

/// RMSE of `y` against `reference`: (raw, against the converged image),
/// the latter subtracting the reference's mean variance `ref_var_mean`.
pub fn rmse(y: &[f32], reference: &[f32], ref_var_mean: f64) -> (f64, f64) {
    let n = y.len().max(1) as f64;
    let mse: f64 = y
        .iter()
        .zip(reference)
        .map(|(&a, &r)| (a as f64 - r as f64).powi(2))
        .sum::<f64>()
        / n;
    (mse.sqrt(), (mse - ref_var_mean).max(0.0).sqrt())
}

fn mean(v: &[f32]) -> f64 {
    v.iter().map(|&x| x as f64).sum::<f64>() / v.len().max(1) as f64
}

/// Options of `camsim bench render`.
#[derive(Clone, Debug)]
pub struct BenchOptions {
    /// Samples per pixel of the timed render.
    pub spp: u32,
    /// Samples per pixel of camsim's own reference (0: none); ignored with `reference`.
    pub ref_spp: u32,
    pub threads: usize,
    /// Bands on 400–700 nm.
    pub bands: usize,
    /// Bounce limit (pbrt's count; Mitsuba's `max_depth` is one more). The
    /// comparison with Mitsuba is at 6; other limits split a path's time by
    /// depth (`bench/mitsuba_depths.sh`).
    pub max_bounces: u32,
    pub seed: u64,
    /// Acceleration structures to time (the first one's image is kept).
    pub bvh: Vec<BvhKind>,
    /// Reference CIE Y image (PFM, 256×256).
    pub reference: Option<PathBuf>,
    /// Per-pixel variance of the reference's mean (PFM).
    pub reference_var: Option<PathBuf>,
    /// Write the timed render's CIE Y image here (PFM).
    pub y_out: Option<PathBuf>,
    /// Independent sample batches of the timed render (`RenderSettings::batches`).
    pub batches: u32,
    /// The timed render's sampler.
    pub sampler: SamplerKind,
}

impl Default for BenchOptions {
    fn default() -> Self {
        Self {
            spp: 16,
            ref_spp: 256,
            threads: 2,
            bands: 31,
            max_bounces: 6,
            seed: 1,
            bvh: vec![BvhKind::Bvh4, BvhKind::Bvh2, BvhKind::Cwbvh],
            reference: None,
            reference_var: None,
            y_out: None,
            batches: RenderSettings::default().batches,
            sampler: SamplerKind::default(),
        }
    }
}

/// Run the benchmark and return a printable report. Its last line is
/// machine-readable: `camsim-bench key=value …`.
pub fn run(o: &BenchOptions) -> Result<String> {
    if o.bvh.is_empty() {
        return Err(Error::invalid("bench render: no BVH kind to time"));
    }
    let (scene, film) = mitsuba_cornell_box();
    let cam = RadiancePinhole(Pinhole::new(39.3077, 1.0, &film)?);
    let to_world = scene
        .camera
        .as_ref()
        .map(|c| c.to_world)
        .unwrap_or(DMat4::IDENTITY);
    let names: Vec<String> = scene.objects.iter().map(|x| x.name.clone()).collect();
    if o.bands == 0 {
        return Err(Error::invalid(
            "bench render: --bands 0: expected at least 1 band",
        ));
    }
    let bands = o.bands;
    let settings = RenderSettings {
        spp: o.spp,
        max_bounces: o.max_bounces,
        threads: o.threads,
        seed: o.seed,
        batches: o.batches,
        sampler: o.sampler,
        grid: crate::spectrum::WavelengthGrid {
            start_nm: 400.0,
            step_nm: if bands > 1 {
                300.0 / (bands - 1) as f64
            } else {
                10.0
            },
            count: bands,
        },
        ..Default::default()
    };
    let mut out = format!(
        "Mitsuba 3 cornell_box(): 256×256, {} bands per path, max_bounces {} (Mitsuba max_depth {}), {} threads, film = radiance, box filter\n",
        settings.grid.len(),
        o.max_bounces,
        o.max_bounces as u64 + 1,
        o.threads
    );
    let paths = film.width_px as f64 * film.height_px as f64 * o.spp as f64;
    let mut timed: Option<(OpticalImage, f64)> = None;
    for &kind in &o.bvh {
        let world = World::build(&scene, &settings.grid, kind)?;
        super::stages::reset();
        let cpu0 = cpu_time_s();
        let img = render_world(&world, &cam, &to_world, &film, &settings, names.clone())?;
        let cpu = cpu_time_s()
            .zip(cpu0)
            .map(|(b, a)| b - a)
            .unwrap_or(f64::NAN);
        out += &format!(
            "  {kind:?}: {} spp in {:.3} s = {:.3} M paths/s wall; {:.2} CPU s = {:.3} M paths per CPU-second ({} non-finite)\n",
            o.spp,
            img.render_s,
            paths / img.render_s / 1e6,
            cpu,
            paths / cpu / 1e6,
            img.nan_count
        );
        if timed.is_none() {
            if let Some(r) = super::stages::report() {
                out += &r;
            }
            timed = Some((img, cpu));
        }
    }
    let (timed, cpu) = timed.expect("rendered");
    let y = luminance_y(&timed);
    let kernel = super::film::Kernel::detect();
    let isa = kernel.isa.name();
    out += &format!("render kernel: {isa}\n");
    out += &if kernel.packets {
        format!(
            "render paths: 16 at a time, {} packets in flight per run of rows, rays regrouped before each cast (CAMSIM_RENDER_PACKETS=0 for one at a time, CAMSIM_PACKETS_IN_FLIGHT to change)\n",
            kernel.in_flight
        )
    } else {
        "render paths: one at a time (CAMSIM_RENDER_PACKETS=1 for 16 at a time)\n".to_string()
    };
    let mut kv = format!(
        "camsim-bench spp={} wall_s={:.4} cpu_s={:.4} paths_per_s={:.1} mean_y={:.6} render_isa={isa} packets={} batches={} sampler={} in_flight={} max_bounces={}",
        o.spp,
        timed.render_s,
        cpu,
        paths / timed.render_s,
        mean(&y),
        kernel.packets,
        settings.batches.clamp(1, o.spp),
        o.sampler.name(),
        kernel.reported_in_flight(),
        o.max_bounces
    );
    if let Some(p) = &o.y_out {
        write_pfm(p, film.width_px as usize, film.height_px as usize, &y)?;
        out += &format!("  CIE Y image written to {}\n", p.display());
    }
    let reference = if let Some(p) = &o.reference {
        let (w, h, r) = read_pfm(p)?;
        if (w, h) != (film.width_px as usize, film.height_px as usize) {
            return Err(Error::invalid(format!(
                "{}: reference is {w}×{h}, the bench renders {}×{}",
                p.display(),
                film.width_px,
                film.height_px
            )));
        }
        let var = match &o.reference_var {
            Some(pv) => {
                let (wv, hv, v) = read_pfm(pv)?;
                if (wv, hv) != (w, h) {
                    return Err(Error::invalid(format!(
                        "{}: variance image is {wv}×{hv}, reference {w}×{h}",
                        pv.display()
                    )));
                }
                mean(&v)
            }
            None => 0.0,
        };
        Some((r, var, format!("reference {}", p.display())))
    } else if o.ref_spp > 0 {
        let world = World::build(&scene, &settings.grid, BvhKind::Bvh4)?;
        let rs = RenderSettings {
            spp: o.ref_spp,
            seed: 0xC0FFEE,
            ..settings.clone()
        };
        let reference = render_world(&world, &cam, &to_world, &film, &rs, names)?;
        let r = luminance_y(&reference);
        // Variance ∝ 1/spp: the reference adds spp/ref_spp of the timed render's MSE.
        let (raw, _) = rmse(&y, &r, 0.0);
        let var = raw * raw * (o.spp as f64 / (o.spp as f64 + o.ref_spp as f64));
        Some((
            r,
            var,
            format!(
                "camsim's own {}-spp reference ({:.1} s)",
                o.ref_spp, reference.render_s
            ),
        ))
    } else {
        None
    };
    if let Some((r, var, what)) = reference {
        let (raw, conv) = rmse(&y, &r, var);
        let m = mean(&r);
        out += &format!(
            "  CIE Y RMSE of the {}-spp render ({:.3} s) against {what}: {:.4e} = {:.3} % of the mean Y {:.4} (≈{:.3} % against the converged image); mean Y ratio {:.4}\n",
            o.spp,
            timed.render_s,
            raw,
            100.0 * raw / m,
            m,
            100.0 * conv / m,
            mean(&y) / m
        );
        kv += &format!(" rmse_y={raw:.6e} rmse_y_converged={conv:.6e} ref_mean_y={m:.6}");
    }
    out += &kv;
    Ok(out)
}

#[cfg(test)]
mod tests {
    use super::*;

    #[test]
    fn d65_normalisation_matches_mitsuba() {
        // Mitsuba 3.9.1's `d65` spectrum evaluates to 1.01013 at 560 nm where
        // the CIE table holds 100.0: scale 0.0101013. Our tables (5 nm,
        // 380–780) integrate slightly differently; 0.2 % covers that.
        let k = d65_unit_luminance_scale();
        assert!((k / 0.0101013 - 1.0).abs() < 2e-3, "{k}");
        // Mitsuba's CIE_Y_integral is 106.856895.
        assert!((cie_y_integral_nm() / 106.856895 - 1.0).abs() < 2e-3);
    }

    #[test]
    fn spectra_match_mitsuba_samples() {
        // Values printed by Mitsuba 3.9.1 (`scalar_spectral`) for the white
        // reflectance and the light at 400, 550 and 700 nm.
        let w = reflectance_spectrum("w", JH_WHITE);
        for (l, v) in [(400.0, 0.747621), (550.0, 0.714317), (700.0, 0.944019)] {
            assert!((w.eval(l) / v - 1.0).abs() < 1e-4, "{l}: {}", w.eval(l));
        }
        let le = light_spectrum();
        for (l, v) in [(400.0, 3.72677), (550.0, 15.1478), (700.0, 11.9829)] {
            // D65 table differences (Mitsuba interpolates its own copy): 0.5 %.
            assert!((le.eval(l) / v - 1.0).abs() < 5e-3, "{l}: {}", le.eval(l));
        }
    }

    #[test]
    fn pfm_round_trip_keeps_rows_and_rejects_garbage() {
        let dir = tempfile::tempdir().unwrap();
        let p = dir.path().join("a.pfm");
        let data: Vec<f32> = (0..6).map(|i| i as f32 * 0.5).collect();
        write_pfm(&p, 3, 2, &data).unwrap();
        let (w, h, d) = read_pfm(&p).unwrap();
        assert_eq!((w, h), (3, 2));
        assert_eq!(d, data);
        std::fs::write(&p, b"P6\n3 2\n255\n").unwrap();
        let e = read_pfm(&p).unwrap_err().to_string();
        assert!(e.contains("a.pfm"), "{e}");
        std::fs::write(&p, b"Pf\n3 2\n-1.0\n\0\0").unwrap();
        assert!(read_pfm(&p).unwrap_err().to_string().contains("data bytes"));
    }

    #[test]
    fn luminance_of_unit_d65_radiance_is_one() {
        // A film holding D65 normalised to unit luminance has Y = 1 (up to
        // the 10 nm, 400–700 nm quadrature: < 0.5 %).
        let grid = crate::spectrum::WavelengthGrid {
            start_nm: 400.0,
            step_nm: 10.0,
            count: 31,
        };
        let d65 = library::named("cie-d65").unwrap();
        let k = d65_unit_luminance_scale();
        let mut img = OpticalImage::new(
            1,
            1,
            crate::optical_image::Rect::new(0, 0, 1, 1),
            1e-5,
            grid.clone(),
        );
        for b in 0..31 {
            img.irradiance[b] = (k * d65.eval(grid.wavelength(b))) as f32;
        }
        let y = luminance_y(&img)[0];
        assert!((y - 1.0).abs() < 5e-3, "{y}");
    }

    /// Y = ∫ s(λ)·w(λ)·ȳ(λ) dλ / ∫ȳ on the CIE table's 5 nm samples.
    fn y_of(s: &Spectrum, under_d65: bool) -> f64 {
        let y = &library::cie1931_cmfs()[1];
        let d65 = library::named("cie-d65").unwrap();
        let k = d65_unit_luminance_scale();
        integrate_table(|l| {
            let w = if under_d65 { k * d65.eval(l) } else { 1.0 };
            s.eval(l) * w * y.eval(l)
        }) / cie_y_integral_nm()
    }

    #[test]
    fn upsampled_spectra_reproduce_the_scene_rgb_luminance() {
        // The Jakob–Hanika fit reproduces an sRGB colour (under D65 for a
        // reflectance), so Y must equal 0.212671 R + 0.715160 G + 0.072169 B
        // of the scene's RGB numbers. The model's fit residual and our 5 nm
        // tables vs Mitsuba's allow ~1 %.
        let y_rgb = |c: [f64; 3]| 0.212671 * c[0] + 0.715160 * c[1] + 0.072169 * c[2];
        for (c, rgb) in [
            (JH_WHITE, [0.885809, 0.698859, 0.666422]),
            (JH_GREEN, [0.105421, 0.37798, 0.076425]),
            (JH_RED, [0.570068, 0.0430135, 0.0443706]),
        ] {
            let y = y_of(&reflectance_spectrum("r", c), true);
            assert!((y / y_rgb(rgb) - 1.0).abs() < 0.01, "{y} vs {}", y_rgb(rgb));
        }
        let y = y_of(&light_spectrum(), false);
        let want = y_rgb([18.387, 13.9873, 6.75357]);
        assert!((y / want - 1.0).abs() < 0.01, "{y} vs {want}");
    }
}
