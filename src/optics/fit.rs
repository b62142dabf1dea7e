//! Fitting a ray-transfer function (RTF) to a lens prescription used as a
//! black box (paper III-B; Goossens et al. 2022).
//!
//! [`fit_rtf`] places an input plane just in front of the film and an output
//! plane just beyond the front vertex, traces rays through the prescription
//! between them (by default the rays an RTF camera traces from film points
//! on several focus planes, [`DataSampling`]), weights each bundle by its own
//! geometric blur ([`Weighting`]) and fits every output (x, y, dx, dy, dz)
//! with all monomials r^i·dx^j·dy^k up to the degree ([`fit_polys`], solved
//! by [`lstsq_qr`]). The pass/no-pass region ([`PassMethod`]) comes from
//! traced boundaries of the region that passes light
//! ([`super::pass_region`]).
//!
//! Design notes, with the measurements behind each decision and every
//! variant tried: docs/rtf-fit.md.

// `!(x > 0.0)` is used on purpose: it also rejects NaN.
#![allow(clippy::neg_cmp_op_on_partial_ord)]

pub use super::lstsq::{LstsqSolution, lstsq_qr};
pub use super::pass_region::{area_matched_ellipse, min_area_ellipse, vignetting_circles};
use super::prescription::{Blocked, Prescription};
use super::rtf::{Ellipses, PassNoPass, Poly, Rtf, RtfCamera, RtfWave};
use crate::{Error, Result};
use glam::{DVec2, DVec3};
use rayon::prelude::*;

/// Fitting options.
#[derive(Clone, Debug)]
pub struct FitOptions {
    pub degree: usize,
    /// Field radii for the polynomial data.
    pub n_field: usize,
    /// Radial × angular pupil grid per field radius.
    pub n_rho: usize,
    pub n_theta: usize,
    /// Field radii with an ellipse (or used to fit the circles).
    pub n_ellipses: usize,
    pub pass_method: PassMethod,
    pub weighting: Weighting,
    /// Input plane distance from the rear vertex as a fraction of the
    /// paraxial back focal distance.
    pub input_plane_fraction: f64,
    /// Where the polynomial data come from.
    pub sampling: DataSampling,
    /// `DataSampling::FilmBundles`: object distances (in focal lengths;
    /// `f64::INFINITY` for infinity) whose film planes are sampled.
    pub focus_distances_f: Vec<f64>,
    /// `DataSampling::FilmBundles`: n × n grid over each film point's pupil.
    pub n_pupil: usize,
    /// Extra weight on the on-axis data (the r = 0 film point of each film
    /// plane, or the r = 0 input radius): 1 = none.
    pub axis_weight: f64,
}

/// How the fit samples the lens (decision and measurements: docs/rtf-fit.md).
#[derive(Clone, Copy, Debug, PartialEq, Eq)]
pub enum DataSampling {
    /// `n_field` film points (radii 0 … last passing radius) on each film
    /// plane of `focus_distances_f`; from each, an `n_pupil` × `n_pupil`
    /// grid over the RTF camera's pupil sampling box, keeping the rays the
    /// prescription passes: the rays an RTF camera traces (default).
    FilmBundles,
    /// `n_field` input points on the input plane, each with an `n_rho` ×
    /// `n_theta` polar grid inside its area-matched pass ellipse
    /// (sessions 1–3).
    InputPlane,
}

/// Pass/no-pass representation written by the fit.
#[derive(Clone, Copy, Debug, PartialEq, Eq)]
pub enum PassMethod {
    /// Minimum-area enclosing ellipse per field radius (the paper's files).
    Ellipses,
    /// Per field radius, the axis-aligned ellipse with the pass region's
    /// radial extent and area (preserves the transmitted flux where the
    /// region is a vignetted "cat's eye", which the enclosing ellipse
    /// overestimates).
    AreaEllipses,
    /// Intersection of vignetting circles (Goossens et al.): each aperture
    /// that bounds the pass region is seen from input radius r as a circle
    /// of fixed radius whose centre moves linearly with r. Exact for
    /// circular apertures in first-order optics; fitted here to the traced
    /// boundary points each aperture blocks.
    Circles,
}

impl Default for FitOptions {
    fn default() -> Self {
        Self {
            degree: 5,
            n_field: 24,
            n_rho: 8,
            n_theta: 24,
            n_ellipses: 25,
            pass_method: PassMethod::AreaEllipses,
            weighting: Weighting::AberrationRelative { floor: 0.0 },
            input_plane_fraction: 0.98,
            sampling: DataSampling::FilmBundles,
            focus_distances_f: vec![f64::INFINITY, 20.0, 10.0, 5.0],
            n_pupil: 16,
            axis_weight: 1.0,
        }
    }
}

/// Fit quality of one output polynomial.
#[derive(Clone, Debug)]
pub struct FitReport {
    pub wavelength_nm: f64,
    pub output: String,
    pub degree: usize,
    pub n_terms: usize,
    pub n_samples: usize,
    /// Dropped (rank-deficient) columns.
    pub n_dropped: usize,
    pub condition_number: f64,
    pub rms_residual: f64,
    pub max_residual: f64,
}

/// Monomial exponents of total degree ≤ N, ordered by degree.
pub fn monomials(degree: usize) -> Vec<[u32; 3]> {
    let mut t = Vec::new();
    for d in 0..=degree as u32 {
        for i in (0..=d).rev() {
            for j in (0..=d - i).rev() {
                t.push([i, j, d - i - j]);
            }
        }
    }
    t
}

/// The black box: a prescription between an input and an output plane.
struct BlackBox<'a> {
    lens: &'a Prescription,
    wavelength_nm: f64,
    /// Input plane z in the lens frame (rear vertex at 0): −planeoffsetinput.
    z_in: f64,
    z_out: f64,
    pass_distance: f64,
}

impl BlackBox<'_> {
    /// Trace a ray from input point (0, r) (rotated frame) towards the
    /// pass-plane point (px, py). Returns input (r, dx, dy) and outputs.
    fn trace(&self, r: f64, px: f64, py: f64) -> Option<Sample> {
        let o = DVec3::new(0.0, r, self.z_in);
        self.trace_dir(
            r,
            (DVec3::new(px, py, self.z_in + self.pass_distance) - o).normalize(),
        )
    }
    /// Trace from input point (0, r) along unit direction `d` (rotated frame).
    fn trace_dir(&self, r: f64, d: DVec3) -> Option<Sample> {
        let o = DVec3::new(0.0, r, self.z_in);
        let (p, dir) = self.lens.trace_to_scene(o, d, self.wavelength_nm).ok()?;
        let t = (self.z_out - p.z) / dir.z;
        if !(t >= -1e-9) {
            return None;
        }
        let q = p + dir * t;
        Some(([r, d.x, d.y], [q.x, q.y, dir.x, dir.y, dir.z]))
    }
    /// The rays the RTF camera `cam` (its film plane, its pass regions)
    /// traces from film point (0, r_f): an n × n grid over its
    /// pupil sampling box on the pass plane, each ray put in the fit's frame
    /// (input point rotated onto +y) and traced; rays crossing the input
    /// plane beyond `r_max` or blocked by the lens are left out.
    fn film_bundle(&self, cam: &RtfCamera, r_f: f64, n: usize, r_max: f64) -> Vec<Sample> {
        let w = &cam.rtf.waves[0];
        let g = cam.input_plane_z_mm();
        let h = g + w.pass.plane_distance_mm();
        let Some(b) = cam.sampling_box(w, r_f) else {
            return Vec::new();
        };
        let mut v = Vec::with_capacity(n * n);
        for i in 0..n {
            for j in 0..n {
                let qx = b[0] + (i as f64 + 0.5) / n as f64 * (b[1] - b[0]);
                let qy = b[2] + (j as f64 + 0.5) / n as f64 * (b[3] - b[2]);
                let d = DVec3::new(qx, qy - r_f, h).normalize();
                let t = g / d.z;
                let (px, py) = (d.x * t, r_f + d.y * t);
                let r = px.hypot(py);
                if !(r <= r_max) {
                    continue;
                }
                let (sn, cs) = if r > 0.0 {
                    (px / r, py / r)
                } else {
                    (0.0, 1.0)
                };
                let dr = DVec3::new(d.x * cs - d.y * sn, d.x * sn + d.y * cs, d.z);
                v.extend(self.trace_dir(r, dr));
            }
        }
        v
    }
    fn passes(&self, r: f64, p: DVec2) -> bool {
        self.trace(r, p.x, p.y).is_some()
    }
    /// The surface whose semi-aperture blocks the ray aimed at `p`, if any.
    fn blocked_at(&self, r: f64, p: DVec2) -> Option<usize> {
        let o = DVec3::new(0.0, r, self.z_in);
        let d = (DVec3::new(p.x, p.y, self.z_in + self.pass_distance) - o).normalize();
        match self.lens.trace_to_scene(o, d, self.wavelength_nm) {
            Err(Blocked::Aperture(i)) => Some(i),
            _ => None,
        }
    }
}

/// The rays an RTF camera with `rtf`'s planes and pass regions (first
/// wavelength), its film `film_mm` behind the rear vertex, traces from film
/// point (0, r_f) over an n × n grid of its pupil sampling box, traced
/// through `lens` at `wavelength_nm` to the RTF's output plane: the fit's
/// samples (input point rotated onto +y) for that film point. Rays beyond
/// the RTF's last pass radius or blocked by the lens are left out.
pub fn film_bundle_samples(
    lens: &Prescription,
    rtf: &Rtf,
    film_mm: f64,
    r_f: f64,
    n: usize,
    wavelength_nm: f64,
) -> Result<Vec<Sample>> {
    let cam = RtfCamera::new(rtf.clone(), film_mm)?;
    let w = rtf
        .waves
        .first()
        .ok_or_else(|| Error::Invalid(format!("RTF '{}' has no wavelength", rtf.name)))?;
    let bb = BlackBox {
        lens,
        wavelength_nm,
        z_in: -rtf.plane_offset_input_mm,
        z_out: lens.total_track_mm() + rtf.plane_offset_output_mm,
        pass_distance: w.pass.plane_distance_mm(),
    };
    let r_max = w.pass.max_radius_mm().unwrap_or(f64::INFINITY);
    Ok(bb.film_bundle(&cam, r_f, n, r_max))
}

/// Boundary points of a pass region and the aperture blocking just outside
/// each (None: blocked otherwise, e.g. total internal reflection).
type Boundary = (Vec<DVec2>, Vec<Option<usize>>);

/// One traced black-box sample: input (r, dx, dy) on the input plane (point
/// rotated onto +y), output (x, y, dx, dy, dz) on the output plane.
pub type Sample = ([f64; 3], [f64; 5]);

/// How the least squares weights the traced samples.
#[derive(Clone, Copy, Debug, PartialEq)]
pub enum Weighting {
    /// Every traced ray counts the same.
    Uniform,
    /// Each ray's weight is 1/σ(r)², σ(r) the RMS *aberration* of its field
    /// radius: the residual of the output directions after the best affine
    /// map from input direction (a perfect lens maps directions affinely),
    /// plus `floor` × the largest σ. The fit then keeps every field's ray
    /// errors small against that field's own geometric blur.
    AberrationRelative { floor: f64 },
}

/// Per-sample least-squares weights; `group[i]` names the bundle sample `i`
/// belongs to (one film point, or one input radius), over which σ is taken.
pub fn sample_weights(data: &[Sample], group: &[usize], w: Weighting) -> Vec<f64> {
    match w {
        Weighting::Uniform => vec![1.0; data.len()],
        Weighting::AberrationRelative { floor } => aberration_weights(data, group, floor),
    }
}

fn aberration_weights(data: &[Sample], group: &[usize], floor: f64) -> Vec<f64> {
    let n_groups = group.iter().map(|g| g + 1).max().unwrap_or(0);
    let mut members: Vec<Vec<usize>> = vec![Vec::new(); n_groups];
    for (i, &g) in group.iter().enumerate() {
        members[g].push(i);
    }
    let sig: Vec<f64> = members
        .iter()
        .map(|idx| affine_residual(data, idx))
        .collect();
    let smax = sig.iter().cloned().fold(0.0, f64::max);
    let mut w = vec![1.0; data.len()];
    for (idx, s) in members.iter().zip(&sig) {
        let s = s + floor * smax;
        let v = if s > 0.0 { 1.0 / (s * s) } else { 1.0 };
        for &i in idx {
            w[i] = v;
        }
    }
    let m = w.iter().cloned().fold(0.0, f64::max);
    w.iter().map(|v| v / m).collect()
}

/// RMS residual of the output directions of samples `idx` after the best
/// affine function of the input direction.
fn affine_residual(data: &[Sample], idx: &[usize]) -> f64 {
    if idx.len() < 6 {
        return 0.0;
    }
    let cols: Vec<Vec<f64>> = vec![
        idx.iter().map(|_| 1.0).collect(),
        idx.iter().map(|&i| data[i].0[1]).collect(),
        idx.iter().map(|&i| data[i].0[2]).collect(),
    ];
    let rhs: Vec<Vec<f64>> = (2..4)
        .map(|k| idx.iter().map(|&i| data[i].1[k]).collect())
        .collect();
    let Ok(sol) = lstsq_qr(cols, rhs.clone()) else {
        return 0.0;
    };
    let mut ss = 0.0;
    for (k, x) in sol.x.iter().enumerate() {
        for (j, &i) in idx.iter().enumerate() {
            let p = x[0] + x[1] * data[i].0[1] + x[2] * data[i].0[2];
            ss += (p - rhs[k][j]).powi(2);
        }
    }
    (ss / idx.len() as f64).sqrt()
}

/// Weighted least-squares fit of outx, outy, outdx, outdy, outdz (slots 0,
/// 1, 3, 4, 5 of the returned array; slot 2 — outz — is left None) with all
/// monomials up to `degree`; reports carry the unweighted residuals.
pub fn fit_polys(
    data: &[Sample],
    weights: &[f64],
    degree: usize,
    wl: f64,
    lens_name: &str,
) -> Result<([Option<Poly>; 6], Vec<FitReport>)> {
    let mut reports = Vec::new();
    let terms = monomials(degree);
    if data.len() < 2 * terms.len() {
        return Err(Error::Invalid(format!(
            "lens '{}': {} traced samples for {} monomials; use more samples or a lower degree",
            lens_name,
            data.len(),
            terms.len()
        )));
    }
    if weights.len() != data.len() || weights.iter().any(|w| !(*w > 0.0 && w.is_finite())) {
        return Err(Error::Invalid("least squares: bad sample weights".into()));
    }
    let sw: Vec<f64> = weights.iter().map(|w| w.sqrt()).collect();
    let r_s = data.iter().map(|s| s.0[0].abs()).fold(1e-9, f64::max);
    let d_s = data
        .iter()
        .map(|s| s.0[1].abs().max(s.0[2].abs()))
        .fold(1e-12, f64::max);
    let deg = degree + 1;
    let pows = |v: f64| {
        let mut p = vec![1.0; deg];
        for i in 1..deg {
            p[i] = p[i - 1] * v;
        }
        p
    };
    let rows: Vec<(Vec<f64>, Vec<f64>, Vec<f64>)> = data
        .iter()
        .map(|s| (pows(s.0[0] / r_s), pows(s.0[1] / d_s), pows(s.0[2] / d_s)))
        .collect();
    let mut cols: Vec<Vec<f64>> = terms
        .iter()
        .map(|t| {
            rows.iter()
                .zip(&sw)
                .map(|((a, b, c), w)| w * a[t[0] as usize] * b[t[1] as usize] * c[t[2] as usize])
                .collect()
        })
        .collect();
    let col_norm: Vec<f64> = cols
        .iter()
        .map(|c| c.iter().map(|v| v * v).sum::<f64>().sqrt().max(1e-300))
        .collect();
    for (c, n) in cols.iter_mut().zip(&col_norm) {
        c.iter_mut().for_each(|v| *v /= n);
    }
    let rhs: Vec<Vec<f64>> = (0..5)
        .map(|k| data.iter().zip(&sw).map(|(s, w)| w * s.1[k]).collect())
        .collect();
    let sol = lstsq_qr(cols, rhs)?;
    let names = ["outx", "outy", "outdx", "outdy", "outdz"];
    let slots = [0usize, 1, 3, 4, 5];
    let mut outputs: [Option<Poly>; 6] = Default::default();
    for (k, x) in sol.x.iter().enumerate() {
        let coeff: Vec<f64> = terms
            .iter()
            .zip(x)
            .zip(&col_norm)
            .map(|((t, c), n)| c / n / (r_s.powi(t[0] as i32) * d_s.powi((t[1] + t[2]) as i32)))
            .collect();
        let poly = Poly {
            terms: terms.clone(),
            coeff,
        };
        let res: Vec<f64> = data
            .iter()
            .map(|s| poly.eval(s.0[0], s.0[1], s.0[2]) - s.1[k])
            .collect();
        if res.iter().any(|v| !v.is_finite()) {
            return Err(Error::Invalid(format!(
                "lens '{}': degree-{} fit of {} is not finite",
                lens_name, degree, names[k]
            )));
        }
        reports.push(FitReport {
            wavelength_nm: wl,
            output: names[k].to_string(),
            degree,
            n_terms: terms.len(),
            n_samples: data.len(),
            n_dropped: terms.len() - sol.rank,
            condition_number: sol.condition_number,
            rms_residual: (res.iter().map(|v| v * v).sum::<f64>() / res.len() as f64).sqrt(),
            max_residual: res.iter().map(|v| v.abs()).fold(0.0, f64::max),
        });
        outputs[slots[k]] = Some(poly);
    }
    Ok((outputs, reports))
}

/// Sag of surface `s` at its rim towards +z (scene) and −z (film), mm.
fn rim_sag(radius: f64, semi: f64) -> f64 {
    if radius == 0.0 {
        0.0
    } else {
        radius.abs() - (radius * radius - semi * semi).max(0.0).sqrt()
    }
}

/// Fit an RTF to `lens` at each wavelength; returns the RTF and per-output reports.
pub fn fit_rtf(
    lens: &Prescription,
    wavelengths_nm: &[f64],
    opts: &FitOptions,
) -> Result<(Rtf, Vec<FitReport>)> {
    fit_rtf_degrees(lens, wavelengths_nm, &[opts.degree], opts)?
        .pop()
        .ok_or_else(|| Error::Invalid("no fit".into()))
}

/// Fit RTFs of several degrees from one set of traced data (`opts.degree`
/// is ignored); one (RTF, reports) per degree, in order.
pub fn fit_rtf_degrees(
    lens: &Prescription,
    wavelengths_nm: &[f64],
    degrees: &[usize],
    opts: &FitOptions,
) -> Result<Vec<(Rtf, Vec<FitReport>)>> {
    if let Some(d) = degrees.iter().find(|&&d| d > 24) {
        return Err(Error::Invalid(format!(
            "RTF degree {d} is above the supported 24"
        )));
    }
    if wavelengths_nm.is_empty() || wavelengths_nm.iter().any(|w| !(w.is_finite() && *w > 0.0)) {
        return Err(Error::Invalid(
            "fit-rtf: wavelengths must be positive numbers (nm)".into(),
        ));
    }
    if !(opts.axis_weight > 0.0 && opts.axis_weight.is_finite()) {
        return Err(Error::Invalid(format!(
            "fit-rtf: axis weight must be a positive number, got {}",
            opts.axis_weight
        )));
    }
    if opts.sampling == DataSampling::FilmBundles
        && (opts.focus_distances_f.is_empty()
            || opts.focus_distances_f.iter().any(|o| !(*o > 1.0))
            || opts.n_pupil < 2)
    {
        return Err(Error::Invalid(format!(
            "fit-rtf: focus distances must be more than one focal length (got {:?}) and the \
             pupil grid at least 2 × 2 (got {})",
            opts.focus_distances_f, opts.n_pupil
        )));
    }
    let px = lens.paraxial(wavelengths_nm[0])?;
    let f = px.effective_focal_length_mm.abs();
    let first = &lens.surfaces[0];
    let last = lens.surfaces.last().unwrap();
    // Rear surface bulging towards the film: radius > 0 (centre on the film side).
    let rear_sag = if last.radius_mm > 0.0 {
        rim_sag(last.radius_mm, last.semi_aperture_mm)
    } else {
        0.0
    };
    let front_sag = if first.radius_mm < 0.0 {
        rim_sag(first.radius_mm, first.semi_aperture_mm)
    } else {
        0.0
    };
    // Input plane just in front of the infinity-focus film plane (as in the
    // Pixel 4a file): each input point then is (nearly) a film point, and the
    // pass region is that film point's vignetted pupil, which an ellipse fits
    // far better than the half-plane cuts the rear rim makes close to the lens.
    let offset_in =
        (opts.input_plane_fraction * px.back_focal_distance_mm).max(rear_sag + 0.01 * f);
    let offset_out = front_sag + 0.01 * f;
    let track = lens.total_track_mm();
    let mut per_degree: Vec<(Vec<RtfWave>, Vec<FitReport>)> =
        degrees.iter().map(|_| (Vec::new(), Vec::new())).collect();
    for &wl in wavelengths_nm {
        let pxw = lens.paraxial(wl)?;
        let xp = -pxw.exit_pupil_from_rear_mm; // lens-frame z of the exit pupil
        let mut pass_distance = xp + offset_in;
        if !(pass_distance > 0.05 * f) {
            pass_distance = offset_in;
        }
        let bb = BlackBox {
            lens,
            wavelength_nm: wl,
            z_in: -offset_in,
            z_out: track + offset_out,
            pass_distance,
        };
        // The pass region lies near the exit pupil on the pass plane: search a
        // square of half-width 3·(exit pupil radius) around the axis.
        let half = 3.0 * pxw.exit_pupil_radius_mm.max(1e-6);
        let grid_pass = |r: f64, ng: usize| -> Option<DVec2> {
            let (mut c, mut k) = (DVec2::ZERO, 0);
            for i in 0..ng {
                for j in 0..ng {
                    let q = DVec2::new(
                        -half + 2.0 * half * (i as f64 + 0.5) / ng as f64,
                        -half + 2.0 * half * (j as f64 + 0.5) / ng as f64,
                    );
                    if bb.passes(r, q) {
                        c += q;
                        k += 1;
                    }
                }
            }
            (k > 0).then(|| c / k as f64)
        };
        // Last input radius that passes light: scan, then bisect.
        let step = 0.02 * f;
        let mut r_pass = 0.0;
        let mut misses = 0;
        let mut r = 0.0;
        while r < 5.0 * f && misses < 10 {
            if grid_pass(r, 24).is_some() {
                r_pass = r;
                misses = 0;
            } else {
                misses += 1;
            }
            r += step;
        }
        let (mut lo, mut hi) = (r_pass, r_pass + step);
        for _ in 0..16 {
            let mid = 0.5 * (lo + hi);
            if grid_pass(mid, 48).is_some() {
                lo = mid
            } else {
                hi = mid
            }
        }
        let r_end = lo;
        let region = |r: f64| -> Option<(DVec2, f64)> { grid_pass(r, 48).map(|c| (c, half)) };
        // Boundary points of the pass region at radius r.
        let boundary = |r: f64| -> Option<Boundary> {
            let (centre, half) = region(r)?;
            let c = DVec2::new(0.0, centre.y);
            if !bb.passes(r, c) {
                return None;
            }
            let na = 64;
            let mut pts = Vec::with_capacity(2 * na);
            let mut surf = Vec::with_capacity(2 * na);
            for a in 0..na {
                let th = std::f64::consts::TAU * (a as f64 + 0.5) / na as f64;
                let dir = DVec2::new(th.cos(), th.sin());
                let (mut lo, mut hi) = (0.0, 4.0 * half);
                for _ in 0..30 {
                    let mid = 0.5 * (lo + hi);
                    if bb.passes(r, c + dir * mid) {
                        lo = mid
                    } else {
                        hi = mid
                    }
                }
                let p = c + dir * lo;
                pts.push(p);
                pts.push(DVec2::new(-p.x, p.y));
                let by = bb.blocked_at(r, c + dir * hi);
                surf.push(by);
                surf.push(by);
            }
            Some((pts, surf))
        };
        // Boundaries of the pass region per field radius.
        let radii: Vec<f64> = (0..opts.n_ellipses)
            .map(|k| r_end * k as f64 / (opts.n_ellipses - 1) as f64)
            .collect();
        let bounds: Vec<Option<Boundary>> = radii.par_iter().map(|&r| boundary(r)).collect();
        let n_ok = bounds.iter().take_while(|e| e.is_some()).count();
        if n_ok < 4 {
            return Err(Error::Invalid(format!(
                "lens '{}': fewer than four field radii pass light",
                lens.name
            )));
        }
        let (bounds, blockers): (Vec<Vec<DVec2>>, Vec<Vec<Option<usize>>>) =
            bounds.into_iter().take(n_ok).map(|b| b.unwrap()).unzip();
        let radii = &radii[..n_ok];
        let ellipses = |method: PassMethod| -> Result<PassNoPass> {
            let ell: Vec<(DVec2, [f64; 2])> = bounds
                .par_iter()
                .map(|pts| {
                    if method != PassMethod::Ellipses {
                        return area_matched_ellipse(pts);
                    }
                    let (c, a) = min_area_ellipse(pts, 1e-7)?;
                    let det = a[0][0] * a[1][1] - a[0][1] * a[1][0];
                    // Half-widths of the bounding box: sqrt of the diagonal of A⁻¹.
                    Some((c, [(a[1][1] / det).sqrt(), (a[0][0] / det).sqrt()]))
                })
                .collect::<Option<Vec<_>>>()
                .ok_or_else(|| {
                    Error::Invalid(format!("lens '{}': degenerate pass region", lens.name))
                })?;
            Ok(PassNoPass::Ellipses(Ellipses {
                positions_mm: radii.to_vec(),
                radii_x_mm: ell.iter().map(|e| e.1[0]).collect(),
                radii_y_mm: ell.iter().map(|e| e.1[1]).collect(),
                centers_x_mm: ell.iter().map(|e| e.0.x).collect(),
                centers_y_mm: ell.iter().map(|e| e.0.y).collect(),
                plane_distance_mm: pass_distance,
            }))
        };
        // The polynomial data are sampled inside the area-matched ellipses
        // whatever the pass/no-pass representation, so the polynomials do
        // not depend on that choice.
        let sampling = ellipses(PassMethod::AreaEllipses)?;
        let r_last = radii[n_ok - 1];
        let pass = match opts.pass_method {
            PassMethod::Circles => {
                let pts: Vec<(f64, DVec2, usize)> = radii
                    .iter()
                    .zip(bounds.iter().zip(&blockers))
                    .flat_map(|(&r, (p, b))| {
                        p.iter()
                            .zip(b)
                            .filter_map(move |(p, b)| b.map(|i| (r, *p, i)))
                    })
                    .collect();
                vignetting_circles(&pts, pass_distance, r_last).ok_or_else(|| {
                    Error::Invalid(format!(
                        "lens '{}': could not fit vignetting circles",
                        lens.name
                    ))
                })?
            }
            m => ellipses(m)?,
        };
        // Polynomial data, grouped in bundles (one film point or input
        // radius each), each with whether it lies on the axis.
        let fields: Vec<f64> = (0..opts.n_field)
            .map(|k| r_last * k as f64 / (opts.n_field - 1) as f64)
            .collect();
        let bundles: Vec<(bool, Vec<Sample>)> = match opts.sampling {
            DataSampling::InputPlane => fields
                .par_iter()
                .map(|&r| {
                    let [x0, x1, y0, y1] = sampling.bbox(r).unwrap_or([0.0; 4]);
                    let (cx, cy, rx, ry) = (
                        0.5 * (x0 + x1),
                        0.5 * (y0 + y1),
                        0.5 * (x1 - x0),
                        0.5 * (y1 - y0),
                    );
                    let mut v = Vec::new();
                    for i in 0..opts.n_rho {
                        let rho = ((i as f64 + 0.5) / opts.n_rho as f64).sqrt();
                        for j in 0..opts.n_theta {
                            let th = std::f64::consts::TAU * (j as f64 + 0.25 * (i % 4) as f64)
                                / opts.n_theta as f64;
                            v.extend(bb.trace(
                                r,
                                cx + rho * rx * th.cos(),
                                cy + rho * ry * th.sin(),
                            ));
                        }
                    }
                    (r == 0.0, v)
                })
                .collect(),
            DataSampling::FilmBundles => {
                // The RTF camera's own pupil sampling (same planes, the
                // area-matched ellipses), so the data are the rays it traces.
                let probe = Rtf {
                    name: lens.name.clone(),
                    description: String::new(),
                    thickness_mm: track,
                    plane_offset_input_mm: offset_in,
                    plane_offset_output_mm: offset_out,
                    waves: vec![RtfWave {
                        wavelength_nm: wl,
                        outputs: Default::default(),
                        pass: sampling.clone(),
                    }],
                };
                let mut cams = Vec::new();
                for &o in &opts.focus_distances_f {
                    let film = lens.image_distance_mm(o * f, wl)?;
                    if !(film > offset_in) {
                        return Err(Error::Invalid(format!(
                            "lens '{}': the film plane for an object at {o} focal lengths \
                             ({film:.3} mm behind the rear vertex) is not behind the RTF \
                             input plane ({offset_in:.3} mm); use farther focus distances",
                            lens.name
                        )));
                    }
                    cams.push(RtfCamera::new(probe.clone(), film)?);
                }
                let jobs: Vec<(usize, f64)> = (0..cams.len())
                    .flat_map(|c| fields.iter().map(move |&r| (c, r)))
                    .collect();
                jobs.par_iter()
                    .map(|&(c, r)| (r == 0.0, bb.film_bundle(&cams[c], r, opts.n_pupil, r_last)))
                    .collect()
            }
        };
        let (mut data, mut group, mut on_axis) = (Vec::new(), Vec::new(), Vec::new());
        for (g, (axis, v)) in bundles.into_iter().filter(|b| !b.1.is_empty()).enumerate() {
            group.extend(std::iter::repeat_n(g, v.len()));
            on_axis.extend(std::iter::repeat_n(axis, v.len()));
            data.extend(v);
        }
        let mut weights = sample_weights(&data, &group, opts.weighting);
        if opts.axis_weight != 1.0 {
            for (w, &a) in weights.iter_mut().zip(&on_axis) {
                if a {
                    *w *= opts.axis_weight;
                }
            }
        }
        for (di, &degree) in degrees.iter().enumerate() {
            let (waves, reports) = &mut per_degree[di];
            let (mut outputs, reps) = fit_polys(&data, &weights, degree, wl, &lens.name)?;
            reports.extend(reps);
            outputs[2] = Some(Poly {
                terms: vec![[0, 0, 0]],
                coeff: vec![offset_in + track + offset_out],
            });
            waves.push(RtfWave {
                wavelength_nm: wl,
                outputs,
                pass: pass.clone(),
            });
        }
    }
    Ok(degrees
        .iter()
        .zip(per_degree)
        .map(|(degree, (waves, reports))| {
            let rtf = Rtf {
                name: format!("{}-rtf-degree{degree}", lens.name),
                description: format!(
                    "RTF fitted by camsim to prescription '{}', degree {degree}",
                    lens.name
                ),
                thickness_mm: track,
                plane_offset_input_mm: offset_in,
                plane_offset_output_mm: offset_out,
                waves,
            };
            (rtf, reports)
        })
        .collect())
}
