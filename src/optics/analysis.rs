//! Lens analysis through the camera interface: relative illumination and
//! geometric edge-spread functions use `Camera::sample_ray` exactly as the
//! renderer does, so they validate the rendering path itself.
//!
//! Conventions: field heights are image-side film radii (mm) along +y for
//! relative illumination and along +x for the ESF. Object distances for the
//! ESF are measured from the lens front vertex (Zemax "object thickness");
//! camera space has the film at the origin for prescriptions and RTFs.
//! Quadrature: an n×n midpoint grid over the pupil sample square
//! (deterministic, identical for every thread count).
//!
//! Relative illumination definition: E(h)/E(0) with E = L·(projected solid
//! angle of the rays that pass), the radiometry of a Lambertian scene of
//! uniform radiance L (object at infinity, no transmission losses) — the
//! quantity Zemax's "Relative Illumination" integrates over the exit pupil
//! in direction-cosine space; field height = real image height on the film.
//! Against the Zemax tables in `lenses/zemax-reference` see docs/optics.md:
//! Zemax's image plane (film distance), its max normalisation
//! (`RiNormalization::Max`) and its ray-aiming-off pupil explain the gap.

// `!(x > 0.0)` is used on purpose: it also rejects NaN.
#![allow(clippy::neg_cmp_op_on_partial_ord)]

use super::Camera;
use super::prescription::{Prescription, PrescriptionCamera};
use super::rtf::{Rtf, RtfCamera};
use crate::{Error, Result};
use glam::DVec2;
use rayon::prelude::*;
use serde_json::Value;
use std::path::Path;

/// A lens file: prescription or RTF.
#[derive(Clone, Debug)]
pub enum LensFile {
    Prescription(Prescription),
    Rtf(Rtf),
}

/// Default wavelength for monochromatic analysis (nm), as the paper (550 nm).
pub const DEFAULT_WAVELENGTH_NM: f64 = 550.0;

/// Load a lens file: `.dat` → prescription; JSON with `surfaces` →
/// prescription; JSON with `polynomials` → RTF.
pub fn load_lens(path: &Path) -> Result<LensFile> {
    if path
        .extension()
        .and_then(|e| e.to_str())
        .is_some_and(|e| e.eq_ignore_ascii_case("dat"))
    {
        return Ok(LensFile::Prescription(Prescription::load(path)?));
    }
    let text = std::fs::read_to_string(path).map_err(|e| Error::Io {
        path: path.to_path_buf(),
        message: e.to_string(),
    })?;
    let v: Value = crate::diag::parse_json(path, &text)?;
    if v.get("polynomials").is_some() {
        Ok(LensFile::Rtf(Rtf::from_value(&v, path)?))
    } else if v.get("surfaces").is_some() {
        Ok(LensFile::Prescription(Prescription::from_value(&v, path)?))
    } else {
        Err(Error::Invalid(format!(
            "{}: neither a lens prescription ('surfaces') nor an RTF ('polynomials')",
            path.display()
        )))
    }
}

/// A camera built from a lens file, with what analysis needs to know.
pub enum LensCamera {
    Prescription(PrescriptionCamera),
    Rtf(RtfCamera),
}

impl LensCamera {
    pub fn camera(&self) -> &dyn Camera {
        match self {
            LensCamera::Prescription(c) => c,
            LensCamera::Rtf(c) => c,
        }
    }
    /// Front vertex position in camera space (film at 0), mm.
    pub fn front_vertex_z_mm(&self) -> f64 {
        match self {
            LensCamera::Prescription(c) => c.film_distance_mm + c.lens.total_track_mm(),
            LensCamera::Rtf(c) => c.front_vertex_z_mm(),
        }
    }
    pub fn film_distance_mm(&self) -> f64 {
        match self {
            LensCamera::Prescription(c) => c.film_distance_mm,
            LensCamera::Rtf(c) => c.film_distance_mm,
        }
    }
}

/// Build the camera for a lens file. Film distance wins over focus distance
/// (measured from the film); prescriptions default to focus at infinity. An
/// RTF needs a film distance unless its file came from `fit-rtf`, which
/// records none: then `Error::Invalid` asks for one.
pub fn lens_camera(
    lens: LensFile,
    film_distance_mm: Option<f64>,
    focus_from_film_m: Option<f64>,
    wavelength_nm: f64,
) -> Result<LensCamera> {
    match lens {
        LensFile::Prescription(p) => {
            let d = prescription_film_distance_mm(
                &p,
                film_distance_mm,
                focus_from_film_m,
                wavelength_nm,
            )?;
            Ok(LensCamera::Prescription(PrescriptionCamera::new(
                p,
                d,
                wavelength_nm,
            )?))
        }
        LensFile::Rtf(r) => {
            let d = match (film_distance_mm, focus_from_film_m) {
                (Some(d), _) => d,
                (None, Some(_)) => {
                    return Err(Error::NotSupported(format!(
                        "RTF '{}': focus distance → film distance; give the film distance instead",
                        r.name
                    )));
                }
                (None, None) => rtf_infinity_film_distance_mm(&r, wavelength_nm)?,
            };
            Ok(LensCamera::Rtf(RtfCamera::new(r, d)?))
        }
    }
}

/// A prescription's film distance (mm behind the rear vertex): the one given,
/// else the one focusing `focus_from_film_m` (measured from the film), else
/// infinity focus.
pub fn prescription_film_distance_mm(
    p: &Prescription,
    film_distance_mm: Option<f64>,
    focus_from_film_m: Option<f64>,
    wavelength_nm: f64,
) -> Result<f64> {
    match (film_distance_mm, focus_from_film_m) {
        (Some(d), _) => Ok(d),
        (None, Some(z)) => p.film_distance_for_focus_mm(z * 1e3, wavelength_nm),
        (None, None) => p.film_distance_for_focus_mm(f64::INFINITY, wavelength_nm),
    }
}

/// A lens prescription rendered through an RTF fitted to it on the fly
/// (KDL `lens "file" rtf-degree=N`): the film distance is the
/// prescription's (given, or solved for `focus_distance_m` at 550 nm, or
/// infinity focus), so the RTF and the prescription it stands for are
/// focused alike. Fitted at 550 nm, or at 400–700 nm every 50 nm when the
/// prescription is dispersive (the RTF camera takes the nearest fitted
/// wavelength); other fit settings are `FitOptions::default()` with
/// `axis_weight`.
pub fn fitted_rtf_camera(
    path: &Path,
    film_distance_m: Option<f64>,
    focus_distance_m: Option<f64>,
    degree: usize,
    axis_weight: f64,
) -> Result<Box<dyn Camera>> {
    let LensFile::Prescription(p) = load_lens(path)? else {
        return Err(Error::Invalid(format!(
            "{}: rtf-degree needs a lens prescription to fit, and this file is an RTF",
            path.display()
        )));
    };
    let film_mm = prescription_film_distance_mm(
        &p,
        film_distance_m.map(|d| d * 1e3),
        focus_distance_m,
        DEFAULT_WAVELENGTH_NM,
    )?;
    let waves: Vec<f64> = if p.is_dispersive() {
        (0..=6).map(|k| 400.0 + 50.0 * k as f64).collect()
    } else {
        vec![DEFAULT_WAVELENGTH_NM]
    };
    let opts = crate::optics::fit::FitOptions {
        degree,
        axis_weight,
        ..Default::default()
    };
    let (rtf, _) = crate::optics::fit::fit_rtf(&p, &waves, &opts)
        .map_err(|e| Error::Invalid(format!("{}: fitting the RTF: {e}", path.display())))?;
    Ok(Box::new(RtfCamera::new(rtf, film_mm)?))
}

/// Film distance at which an RTF images infinity: rays from the on-axis film
/// point leave parallel. Found by minimising the spread of output directions
/// (golden-section search over the film distance).
pub fn rtf_infinity_film_distance_mm(rtf: &Rtf, wavelength_nm: f64) -> Result<f64> {
    let spread = |d: f64| -> f64 {
        let Ok(cam) = RtfCamera::new(rtf.clone(), d) else {
            return f64::INFINITY;
        };
        let n = 24;
        let mut s = 0.0;
        let mut k = 0;
        for i in 0..n {
            for j in 0..n {
                let u = DVec2::new((i as f64 + 0.5) / n as f64, (j as f64 + 0.5) / n as f64);
                if let Some(r) = cam.sample_ray(DVec2::ZERO, u, wavelength_nm) {
                    s += r.direction.x * r.direction.x + r.direction.y * r.direction.y;
                    k += 1;
                }
            }
        }
        if k == 0 { f64::INFINITY } else { s / k as f64 }
    };
    let (mut a, mut b) = (
        rtf.plane_offset_input_mm * 0.2 + 1e-6,
        rtf.plane_offset_input_mm * 3.0 + 1.0,
    );
    let g = 0.5 * (5f64.sqrt() - 1.0);
    for _ in 0..80 {
        let c = b - g * (b - a);
        let d = a + g * (b - a);
        if spread(c) < spread(d) { b = d } else { a = c }
    }
    let d = 0.5 * (a + b);
    if !spread(d).is_finite() {
        return Err(Error::Invalid(format!(
            "RTF '{}': no film distance lets on-axis rays through",
            rtf.name
        )));
    }
    Ok(d)
}

/// Mean weight at a film point (= E/L for a uniform field), n×n grid.
pub fn irradiance_factor(cam: &dyn Camera, film_m: DVec2, wavelength_nm: f64, n: usize) -> f64 {
    let mut s = 0.0;
    for i in 0..n {
        for j in 0..n {
            let u = DVec2::new((i as f64 + 0.5) / n as f64, (j as f64 + 0.5) / n as f64);
            if let Some(r) = cam.sample_ray(film_m, u, wavelength_nm) {
                s += r.weight;
            }
        }
    }
    s / (n * n) as f64
}

/// Relative illumination of a uniform Lambertian field at infinity (every
/// ray sees the same radiance) at film heights along +y, normalised on axis.
pub fn relative_illumination(
    cam: &dyn Camera,
    field_heights_mm: &[f64],
    wavelength_nm: f64,
    n: usize,
) -> Result<Vec<f64>> {
    let e0 = irradiance_factor(cam, DVec2::ZERO, wavelength_nm, n);
    if !(e0 > 0.0) {
        return Err(Error::Invalid("no light reaches the film on axis".into()));
    }
    Ok(field_heights_mm
        .par_iter()
        .map(|&h| irradiance_factor(cam, DVec2::new(0.0, h * 1e-3), wavelength_nm, n) / e0)
        .collect())
}

/// How a relative-illumination curve is normalised.
#[derive(Clone, Copy, Debug, PartialEq, Eq, clap::ValueEnum)]
pub enum RiNormalization {
    /// The on-axis value is 1 (E(h)/E(0)).
    Axis,
    /// The largest value on the curve is 1 (Zemax's tables: lenses whose
    /// illumination rises off axis, such as the 200° wide angle, read < 1 on axis).
    Max,
}

/// Renormalise an on-axis-normalised RI curve.
pub fn normalize_ri(mut ri: Vec<f64>, how: RiNormalization) -> Vec<f64> {
    if how == RiNormalization::Max {
        let m = ri.iter().cloned().fold(0.0, f64::max);
        if m > 0.0 {
            ri.iter_mut().for_each(|v| *v /= m);
        }
    }
    ri
}

/// Geometric ESF/LSF of a straight edge (parallel to y) in the plane
/// `object_z_mm` (camera space, film at 0), imaged around film height
/// `field_mm` on +x. The edge passes through the weighted centroid of the
/// rays from the film point (field, 0), so position 0 is the edge image.
/// ESF(x) = fraction of the light reaching film point x that comes from the
/// bright side; LSF = dESF/dx by central differences, normalised to peak 1.
/// Returns (esf, lsf) per position (µm).
pub fn edge_spread(
    cam: &dyn Camera,
    object_z_mm: f64,
    field_mm: f64,
    positions_um: &[f64],
    wavelength_nm: f64,
    n: usize,
) -> Result<Vec<(f64, f64)>> {
    let z_obj = object_z_mm * 1e-3;
    let hits = |x_mm: f64| -> Vec<(f64, f64)> {
        let mut v = Vec::with_capacity(n * n);
        for i in 0..n {
            for j in 0..n {
                let u = DVec2::new((i as f64 + 0.5) / n as f64, (j as f64 + 0.5) / n as f64);
                if let Some(r) = cam.sample_ray(DVec2::new(x_mm * 1e-3, 0.0), u, wavelength_nm)
                    && r.direction.z > 0.0
                {
                    let t = (z_obj - r.origin.z) / r.direction.z;
                    if t > 0.0 {
                        v.push((r.origin.x + r.direction.x * t, r.weight));
                    }
                }
            }
        }
        v
    };
    let h0 = hits(field_mm);
    let wsum: f64 = h0.iter().map(|h| h.1).sum();
    if !(wsum > 0.0) {
        return Err(Error::Invalid(format!(
            "no light reaches film height {field_mm} mm"
        )));
    }
    let x_edge = h0.iter().map(|h| h.0 * h.1).sum::<f64>() / wsum;
    let esf: Vec<f64> = positions_um
        .par_iter()
        .map(|&p| {
            let h = hits(field_mm + p * 1e-3);
            let all: f64 = h.iter().map(|h| h.1).sum();
            let bright: f64 = h.iter().filter(|h| h.0 > x_edge).map(|h| h.1).sum();
            if all > 0.0 { bright / all } else { f64::NAN }
        })
        .collect();
    let m = esf.len();
    let mut lsf: Vec<f64> = (0..m)
        .map(|k| {
            let (a, b) = (k.saturating_sub(1), (k + 1).min(m - 1));
            if b > a {
                (esf[b] - esf[a]) / (positions_um[b] - positions_um[a])
            } else {
                0.0
            }
        })
        .collect();
    let peak = lsf.iter().cloned().fold(0.0, f64::max);
    if peak > 0.0 {
        lsf.iter_mut().for_each(|v| *v /= peak);
    }
    Ok(esf.into_iter().zip(lsf).collect())
}

/// Half-width (µm) of the film region an object point at `object_z_mm`
/// spreads over around film height `field_mm` (for choosing ESF positions).
pub fn blur_half_width_um(
    cam: &dyn Camera,
    object_z_mm: f64,
    field_mm: f64,
    wavelength_nm: f64,
) -> f64 {
    let z_obj = object_z_mm * 1e-3;
    let spot = |x_mm: f64| -> Option<(f64, f64)> {
        let n = 32;
        let (mut lo, mut hi, mut c, mut w) = (f64::INFINITY, f64::NEG_INFINITY, 0.0, 0.0);
        for i in 0..n {
            for j in 0..n {
                let u = DVec2::new((i as f64 + 0.5) / n as f64, (j as f64 + 0.5) / n as f64);
                if let Some(r) = cam.sample_ray(DVec2::new(x_mm * 1e-3, 0.0), u, wavelength_nm) {
                    let t = (z_obj - r.origin.z) / r.direction.z;
                    let x = r.origin.x + r.direction.x * t;
                    lo = lo.min(x);
                    hi = hi.max(x);
                    c += x * r.weight;
                    w += r.weight;
                }
            }
        }
        (w > 0.0).then(|| (c / w, 0.5 * (hi - lo)))
    };
    let dx = 0.01;
    match (spot(field_mm), spot(field_mm + dx)) {
        (Some((c0, half)), Some((c1, _))) => {
            let mag = ((c1 - c0) / (dx * 1e-3)).abs(); // object metres per film metre
            if mag > 0.0 { half / mag * 1e6 } else { 10.0 }
        }
        _ => 10.0,
    }
}

/// Best-fit vergence (1/m) of the beam a camera sends out from the on-axis
/// film point: each ray, extended back, meets the film plane at lateral
/// offset a (metres) with lateral slope b = d_xy/d_z; the beam that best
/// matches b = −v·a (weighted least squares over an n×n pupil grid)
/// converges at distance 1/v in front of the film. v > 0: focused at a
/// real object distance 1/v; v = 0: infinity; v < 0: "beyond infinity"
/// (the rays diverge; no real object is in focus). None if no ray passes.
pub fn on_axis_vergence_per_m(cam: &dyn Camera, wavelength_nm: f64, n: usize) -> Option<f64> {
    let (mut sab, mut saa) = (0.0, 0.0);
    for i in 0..n {
        for j in 0..n {
            let u = DVec2::new((i as f64 + 0.5) / n as f64, (j as f64 + 0.5) / n as f64);
            if let Some(r) = cam.sample_ray(DVec2::ZERO, u, wavelength_nm)
                && r.direction.z > 0.0
            {
                let b = DVec2::new(r.direction.x, r.direction.y) / r.direction.z;
                let a = DVec2::new(r.origin.x, r.origin.y) - b * r.origin.z;
                sab += r.weight * a.dot(b);
                saa += r.weight * a.dot(a);
            }
        }
    }
    (saa > 0.0).then(|| -sab / saa)
}

/// First-order summary of a lens for `camsim lens info` (mm).
#[derive(Clone, Copy, Debug, PartialEq)]
pub struct LensInfo {
    pub focal_length_mm: f64,
    pub f_number: f64,
    /// Exit pupil position measured from the film at the infinity-focus film distance.
    pub exit_pupil_from_film_mm: f64,
    pub exit_pupil_radius_mm: f64,
    pub film_distance_infinity_mm: f64,
    /// Working f-number from the measured on-axis irradiance, E = πL/(4N²).
    pub working_f_number: f64,
}

/// Lens summary. Prescriptions: paraxial. RTFs: focal length from the output
/// angle of a small off-axis film point at infinity focus (f = h/tan θ),
/// exit pupil = on-axis pass ellipse, f-number = working f-number.
pub fn lens_info(lens: &LensFile, wavelength_nm: f64) -> Result<LensInfo> {
    let cam = lens_camera(lens.clone(), None, None, wavelength_nm)?;
    let e0 = irradiance_factor(cam.camera(), DVec2::ZERO, wavelength_nm, 200);
    let working = (std::f64::consts::PI / (4.0 * e0)).sqrt();
    let d = cam.film_distance_mm();
    match (lens, &cam) {
        (LensFile::Prescription(p), _) => {
            let px = p.paraxial(wavelength_nm)?;
            Ok(LensInfo {
                focal_length_mm: px.effective_focal_length_mm,
                f_number: px.f_number,
                exit_pupil_from_film_mm: d - px.exit_pupil_from_rear_mm,
                exit_pupil_radius_mm: px.exit_pupil_radius_mm,
                film_distance_infinity_mm: d,
                working_f_number: working,
            })
        }
        (LensFile::Rtf(r), LensCamera::Rtf(c)) => {
            let w = &r.waves[0];
            let [x0, x1, y0, y1] = w.pass.bbox(0.0).unwrap_or([0.0; 4]);
            let (rx, ry) = (0.5 * (x1 - x0), 0.5 * (y1 - y0));
            // Focal length: chief-ray-like average output angle from a film point h.
            let h = 0.05 * w.pass.max_radius_mm().unwrap_or(d);
            let n = 32;
            let (mut sx, mut k) = (0.0, 0);
            for i in 0..n {
                for j in 0..n {
                    let u = DVec2::new((i as f64 + 0.5) / n as f64, (j as f64 + 0.5) / n as f64);
                    if let Some(ray) = c.sample_ray(DVec2::new(0.0, h * 1e-3), u, wavelength_nm) {
                        sx += ray.direction.y / ray.direction.z;
                        k += 1;
                    }
                }
            }
            let f = if k > 0 { h / (sx / k as f64) } else { f64::NAN };
            Ok(LensInfo {
                focal_length_mm: f,
                f_number: working,
                exit_pupil_from_film_mm: c.input_plane_z_mm() + w.pass.plane_distance_mm(),
                exit_pupil_radius_mm: (rx * ry).sqrt(),
                film_distance_infinity_mm: d,
                working_f_number: working,
            })
        }
        _ => unreachable!("lens_camera keeps the lens kind"),
    }
}

/// Film-plane residuals of a lens model against a prescription (µm).
#[derive(Clone, Copy, Debug, PartialEq)]
pub struct FilmResiduals {
    /// RMS and largest film-plane distance over the rays both pass.
    pub rms_um: f64,
    pub max_um: f64,
    /// Rays the model emits that the prescription carries back to the film.
    pub n_rays: usize,
    /// Rays the model emits that the prescription blocks on the way back
    /// (a pass/no-pass disagreement, counted but not in the distances).
    pub n_blocked: usize,
}

/// Where a camera model's rays land on the film when traced back through
/// the real lens. Definition: the film lies `film_distance_mm` behind the
/// prescription's rear vertex (camera space as in `PrescriptionCamera`); for
/// each film point (0, h) of `heights_mm` (physical film point −film_m, as
/// every camera maps it) and an n×n grid of pupil samples, the ray `cam`
/// emits into the scene is traced backwards through `lens` (the reversed
/// prescription) to the film plane; its distance from the film point that
/// emitted it is the residual. The prescription's own rays land back on
/// their film point (to rounding), so the residual is the model's ray error
/// re-imaged on the film by the real lens — position and direction errors
/// in the one unit an image sees, whatever the object distance.
pub fn film_residuals(
    cam: &dyn Camera,
    lens: &Prescription,
    film_distance_mm: f64,
    heights_mm: &[f64],
    wavelength_nm: f64,
    n: usize,
) -> Result<FilmResiduals> {
    let rev = lens.reversed()?;
    let track = lens.total_track_mm();
    let clear = track + lens.surfaces[0].semi_aperture_mm + 1.0;
    let per_height: Vec<(f64, f64, usize, usize)> = heights_mm
        .par_iter()
        .map(|&h| {
            let film_m = DVec2::new(0.0, h * 1e-3);
            let p = -film_m * 1e3;
            let (mut ss, mut mx, mut k, mut blocked) = (0.0, 0.0f64, 0, 0);
            for i in 0..n {
                for j in 0..n {
                    let u = DVec2::new((i as f64 + 0.5) / n as f64, (j as f64 + 0.5) / n as f64);
                    let Some(ray) = cam.sample_ray(film_m, u, wavelength_nm) else {
                        continue;
                    };
                    // Camera space (mm) → lens frame → reversed lens frame,
                    // starting on a plane clear of the front surface (a
                    // prescription's rays start *on* it).
                    let o = ray.origin * 1e3;
                    let z_lens = o.z - film_distance_mm;
                    let dz = ray.direction.z;
                    if !(dz > 0.0) {
                        blocked += 1;
                        continue;
                    }
                    let o = o + ray.direction * ((clear - z_lens) / dz);
                    let z_lens = clear;
                    let o_rev = glam::DVec3::new(o.x, o.y, track - z_lens);
                    // Travelling back: the direction reverses, then mirrors in z.
                    let d_rev = glam::DVec3::new(-ray.direction.x, -ray.direction.y, dz);
                    match rev.trace_to_scene(o_rev, d_rev, wavelength_nm) {
                        Ok((q, d)) => {
                            // Back in the lens frame; the film is at z = −D.
                            let (qz, dz) = (track - q.z, -d.z);
                            let t = (-film_distance_mm - qz) / dz;
                            let x = q.x + d.x * t;
                            let y = q.y + d.y * t;
                            let e = ((x - p.x).powi(2) + (y - p.y).powi(2)).sqrt() * 1e3;
                            if e.is_finite() {
                                ss += e * e;
                                mx = mx.max(e);
                                k += 1;
                            } else {
                                blocked += 1;
                            }
                        }
                        Err(_) => blocked += 1,
                    }
                }
            }
            (ss, mx, k, blocked)
        })
        .collect();
    let ss: f64 = per_height.iter().map(|v| v.0).sum();
    let max_um = per_height.iter().map(|v| v.1).fold(0.0, f64::max);
    let n_rays: usize = per_height.iter().map(|v| v.2).sum();
    let n_blocked: usize = per_height.iter().map(|v| v.3).sum();
    if n_rays == 0 {
        return Err(Error::Invalid(format!(
            "lens '{}': no ray of the model reaches the film through the prescription",
            lens.name
        )));
    }
    Ok(FilmResiduals {
        rms_um: (ss / n_rays as f64).sqrt(),
        max_um,
        n_rays,
        n_blocked,
    })
}

/// RMS difference of two ESFs sampled at the same positions, normalised by
/// the mean of the 10 largest `reference` values (the RTF metric).
pub fn esf_rmse(esf: &[f64], reference: &[f64]) -> f64 {
    let mut top: Vec<f64> = reference.to_vec();
    top.sort_by(|x, y| y.total_cmp(x));
    let norm = top.iter().take(10).sum::<f64>() / 10.0;
    let ss = esf
        .iter()
        .zip(reference)
        .map(|(x, y)| (x - y).powi(2))
        .sum::<f64>();
    (ss / esf.len() as f64).sqrt() / norm
}

/// How closely a fitted RTF reproduces the prescription it was fitted to,
/// in image terms (`fit-rtf` prints it).
#[derive(Clone, Debug, PartialEq)]
pub struct RtfValidation {
    pub wavelength_nm: f64,
    /// Largest |RI(RTF) − RI(prescription)| over 0–95 % of the film radius
    /// that receives light, infinity focus (13 heights).
    pub ri_max_abs_err: f64,
    /// Object distance of the ESF checks, from the front vertex (mm).
    pub object_mm: f64,
    /// ESF RMSE of RTF vs prescription (normalised by the mean of the 10
    /// largest prescription values; film at the object's paraxial focus;
    /// 201 positions over ±1.5 blur half-widths) at 0, 25, 50 and 75 % of
    /// the film radius. NaN where the RTF sends no light.
    pub esf_rmse: [f64; 4],
}

/// Compare `rtf` with `lens` at `wavelength_nm`: relative illumination
/// (infinity focus) and geometric ESFs of an object 20 focal lengths from
/// the front vertex. The RTF uses the prescription's film distances.
pub fn validate_rtf(lens: &Prescription, rtf: &Rtf, wavelength_nm: f64) -> Result<RtfValidation> {
    let px = lens.paraxial(wavelength_nm)?;
    let bfd = px.back_focal_distance_mm;
    let object_mm = 20.0 * px.effective_focal_length_mm.abs();
    let film = lens.image_distance_mm(object_mm, wavelength_nm)?;
    let presc_inf = PrescriptionCamera::new(lens.clone(), bfd, wavelength_nm)?;
    let r_hi = 0.95 * presc_inf.max_film_radius_mm;
    let heights: Vec<f64> = (0..=12).map(|k| r_hi * k as f64 / 12.0).collect();
    let ri_p = relative_illumination(&presc_inf, &heights, wavelength_nm, 64)?;
    let ri_r = relative_illumination(
        &RtfCamera::new(rtf.clone(), bfd)?,
        &heights,
        wavelength_nm,
        64,
    )?;
    let ri_max_abs_err = ri_p
        .iter()
        .zip(&ri_r)
        .map(|(a, b)| (a - b).abs())
        .fold(0.0, f64::max);
    let presc = PrescriptionCamera::new(lens.clone(), film, wavelength_nm)?;
    let cam = RtfCamera::new(rtf.clone(), film)?;
    let z_obj = film + lens.total_track_mm() + object_mm;
    let mut esf_err = [f64::NAN; 4];
    for (k, e) in esf_err.iter_mut().enumerate() {
        let field = r_hi / 0.95 * 0.25 * k as f64;
        let w = (1.5 * blur_half_width_um(&presc, z_obj, field, wavelength_nm)).max(2.0);
        let pos: Vec<f64> = (0..=200).map(|i| -w + 2.0 * w * i as f64 / 200.0).collect();
        let esf = |c: &dyn Camera| -> Option<Vec<f64>> {
            edge_spread(c, z_obj, field, &pos, wavelength_nm, 40)
                .ok()
                .map(|v| v.into_iter().map(|x| x.0).collect())
        };
        if let (Some(a), Some(b)) = (esf(&presc), esf(&cam)) {
            *e = esf_rmse(&b, &a);
        }
    }
    Ok(RtfValidation {
        wavelength_nm,
        ri_max_abs_err,
        object_mm,
        esf_rmse: esf_err,
    })
}
