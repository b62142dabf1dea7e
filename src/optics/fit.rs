//! Fitting a ray-transfer function (RTF) to a lens prescription used as a
//! black box (paper III-B; Goossens et al. 2022).
//!
//! Planes (mm): the input plane lies `planeoffsetinput` = max(0.98 × back
//! focal distance, rear-surface sag towards the film + 1 % of f) behind the
//! rear vertex, the
//! output plane `planeoffsetoutput` = (sag of the front surface towards the
//! scene, if any) + 1 % of f beyond the front vertex. `outz` is written as the
//! constant input-to-output-plane distance (see `rtf.rs` for the convention).
//!
//! Data (`DataSampling`, decision): by default the rays an RTF camera
//! traces. For each object distance in `focus_distances_f` (default ∞, 20,
//! 10 and 5 focal lengths: a photographic focus range) the film sits at that
//! object's paraxial image; on it, film points (0, r_f) at `n_field` radii
//! from 0 to the last input radius that passes light each send an
//! `n_pupil` × `n_pupil` grid of rays over the RTF camera's own pupil
//! sampling box (`RtfCamera::sampling_box`, with the fit's area-matched
//! ellipses); every ray is put in the fit's frame (its input-plane point
//! rotated onto +y), traced through the prescription and, when it reaches
//! the scene, propagated to the output plane. Rays the lens blocks drop
//! out, so a vignetted film point contributes in proportion to the light it
//! receives. Each film point's rays form one bundle for the weights below.
//! `DataSampling::InputPlane` (sessions 1–3) instead puts the points on the
//! input plane itself, each with a polar grid (area-uniform in ρ, uniform in
//! angle) filling its radius's area-matched pass ellipse on the pass plane.
//!
//! Why film bundles (tests/optics_rtf_fit.rs, ESF RMSE against the
//! prescription, degrees 3/4/5/6/7, on axis and [at 25/50/75 % of the
//! field] — input-plane → film bundles):
//! - double Gauss on axis 1.67/1.28/0.39/0.33/0.33 → 1.79/0.43/0.36/0.31/
//!   0.31 %; off axis unchanged within ±0.3 % at degrees 4–7, better at 3
//!   (4.5/4.3/1.6 → 3.1/2.9/1.0 %); film residual RMS 17.6/4.2/1.2/0.4/0.1
//!   → 14.1/3.5/1.0/0.3/0.1 µm;
//! - Tessar on axis 0.90/1.21/1.68/0.47/0.21 → 2.46/0.40/0.15/0.04/0.03 %;
//!   off axis degree 4 2.4/7.7/12.4 → 2.2/3.9/6.2 %, degree 6 2.2/1.8/2.9 →
//!   1.1/1.1/1.3 %, degree 7 1.5/1.8/2.8 → 0.7/1.4/2.1 %; film residual RMS
//!   at infinity focus (dominated by the 42° strongly vignetted rim)
//!   226/250/135/69/47 → 206/310/196/102/62 µm.
//!
//! The input-plane data sample the on-axis image only at the r = 0 input
//! point and the next radius (1.8 / 3.75 mm away), while the rays of one
//! film point 10 mm behind the input plane (the 1–1.3 m focus of the ESF)
//! cross it at radii up to 1.9 / 1.3 mm, i.e. between the samples; its
//! low-degree on-axis lines swung by up to 10× with sampling details
//! (list below). With film bundles they are stable: double Gauss degree 3
//! 1.72–2.02 % and degree 4 0.39–0.53 %, Tessar degree 4 0.15–0.74 % over
//! 12/24/36/48 film radii, 16 or 24 pupil samples, weights 1/σ, 1/σ², 1/σ³
//! and focus planes {∞}, {∞, 10 f}, {∞, 20, 10, 5 f} or {∞, 40, 20, 10, 5 f}
//! (a throw-away harness on the test's metric).
//!
//! Degree 3 stays above 1 % on axis (double Gauss 1.8 %, Tessar 2.5 %):
//! a cubic cannot follow these lenses over a 28°/42° field, and its off-axis
//! ESFs are 1–9 % whatever the weighting. Moving the input plane
//! (`input_plane_fraction` 0.90/0.93/0.95/0.96/0.97/0.98/0.99) leaves double
//! Gauss degree 3 at 1.58/1.86/2.02/1.79/1.80/1.78/1.85 % and degrees 4–7 at
//! ≤ 0.48 %; the Tessar's degree 3 swings (1.24/1.91/1.47/1.76/1.74/2.46/
//! 0.07 %) and its film residual at degree 6 too (121/118/68/72/77/102/
//! 102 µm) without a trend, so 0.98 (the Pixel 4a file's choice: input
//! plane just in front of the film) stays. `axis_weight` (CLI
//! `--axis-weight`) multiplies the weight of the r_f = 0 bundles, so a user
//! who measures at the image centre can buy accuracy there: ×4/16/23/64
//! give double Gauss 1.59/1.11/0.98/0.75 %, Tessar 1.23/0.69/0.58/0.41 %
//! on axis, with the field-wide film residual nearly unchanged (double
//! Gauss 14.1 → 16.0 µm at ×64) but the ESF at 25 % of the field rising
//! (double Gauss 3.1 → 6.4 %, Tessar 2.3 → 2.8 %). The default stays 1: the
//! default fit serves the whole field. Also tried on the film-bundle data
//! and not kept: Lawson minimax reweighting (Tessar degree 3–7 on axis
//! 7.6/4.6/2.5/1.9/1.3 %), and fixing the constant and linear terms to the
//! lens's exact first-order map at the axis so that focus and focal length
//! cannot drift (double Gauss degree 3 0.89 % on axis but 8.8 % at 25 %
//! field; Tessar degree 3 and 4 2.6 %).
//!
//! Least squares: all monomials r^i·dx^j·dy^k with i+j+k ≤ N, in scaled
//! variables (r/r_max, dx/s, dy/s with s the largest |dx|,|dy|), columns
//! normalised to unit length, solved by Householder QR with column pivoting
//! (columns whose pivot falls below 1e-13 of the first are dropped, i.e. get
//! coefficient 0, and counted). The 2-norm condition number of the kept
//! block is estimated by power iteration on R and on R⁻¹; residuals are
//! re-evaluated from the written (unscaled) coefficients.
//!
//! Weights (`Weighting`, decision): by default every ray of a bundle (one
//! film point, or one input radius) gets weight 1/σ², σ the RMS residual of
//! that bundle's output directions after the best *affine* function of the
//! input direction — a perfect lens maps the directions from one point
//! affinely, so σ is the bundle's geometric aberration, i.e. its blur. An image (or ESF) sees ray
//! errors relative to the local blur; unweighted least squares spends the
//! low-degree polynomial on the strongly aberrated, heavily vignetted outer
//! field and leaves errors several times the blur near the axis, where the
//! lens is sharpest. Measured with the input-plane data (tests/
//! optics_rtf_fit.rs, ESF RMSE against the prescription on axis): Tessar degree 3/4/5 10.2/4.3/3.4 % → 0.9/1.2/
//! 1.7 %, double Gauss degree 3/4 2.5/1.3 % → 1.7/1.3 %; degrees 6–7
//! unchanged within ±0.4 %. The degree-3 Tessar figure is fragile (2.1 %
//! with 48 field radii instead of 24). Variants tried and not kept (no
//! better at degrees 3–6): a floor of 2 % of the largest σ, σ clamped below
//! at the on-axis σ or at half the median σ, weights 1/σ instead of 1/σ²,
//! other input-plane positions (0.9 and 0.999 × the back focal distance:
//! 2–3× worse); 16 instead of 8 radial pupil samples changes nothing
//! (±0.1 %), so the pupil is sampled densely enough. Off axis the weights
//! help as much (Tessar degree 3, ESF at 10 and 25 mm field: 8.3/10 %
//! unweighted → 1.2/1.6 %). `Weighting::Uniform` gives the unweighted fit.
//!
//! Input-plane data, sessions 2–3 (why they were replaced): what limited
//! the on-axis ESF at degrees 3–5 (measured with the acceptance test's
//! metric: on-axis ESF RMSE against the prescription, normalised by the
//! mean of the 10 largest values, every Zemax position):
//! - Not the reach of the form. The same monomials fitted to ONLY the rays
//!   the on-axis ESF traces (every ESF position × a 20×20 pupil grid, same
//!   planes and ellipses) give, degrees 3/4/5/6/7, double Gauss 0.39/0.30/
//!   0.31/0.31/0.31 % (the floor is the 40×40 ESF quadrature's) and Tessar
//!   0.20/0.18/0.03/0.01/0.06 % (report rows `rtf-degreeN-onaxis-only`).
//!   The rays of one film point spread over a range of input radii (up to
//!   1.9 / 1.3 mm here), so the r-terms act as extra pupil terms. Those
//!   fits are useless elsewhere (film residuals of mm, RI errors up to
//!   0.99).
//! - It is how one global polynomial shares its error between the axis and
//!   the rest of the field. No variant below brought all of double Gauss
//!   3–4 and Tessar 4–5 to 1 %; each that lowered some of those lines
//!   raised others (or Tessar degree 3 above 1 %), and most raised the
//!   field-wide film residual (`film_residuals`, RMS over 0–95 % of the
//!   film radius at infinity focus) or the off-axis ESFs (at 25/50/75 % of
//!   the film radius). Measured with a throw-away harness on the same
//!   traced data and the test's ESF; the acceptance test reproduces the
//!   default and on-axis-only lines. On-axis ESF %, degrees 3/4/5, [film
//!   RMS µm at the same degrees], double Gauss | Tessar:
//!   - default (1/σ², 24 uniform radii): 1.67/1.28/0.39 [17.6/4.2/1.2] |
//!     0.90/1.21/1.68 [226/250/135];
//!   - Lawson iteratively reweighted least squares equalising every
//!     field's RMS direction error relative to its σ (minimax over fields,
//!     10 iterations): 3.24/0.69/0.41 [19.1/5.2/1.1] | 2.03/0.71/0.37
//!     [295/215/114]; Tessar's off-axis ESFs rise from 4–17 % to 8–33 %;
//!   - field radii denser near the axis, r_k ∝ (k/23)²: 1.45/0.69/0.37
//!     [21.7/5.0/1.3] | 1.90/0.52/1.07 [224/260/143]; ∝ (k/23)³: 1.47/0.51/
//!     0.36 [23.8/5.6/1.4] | 1.08/0.31/0.31 [227/264/142]; Chebyshev–
//!     Lobatto radii (24 or 32): 2.0/0.8/0.37 | 1.7/1.2/1.3;
//!   - the same denser radii with quadrature weights (Δr per radius, so the
//!     objective is the same integral over r, only better resolved): 1.33/
//!     1.59/0.38 | 4.4/2.2/3.3 — the low-degree on-axis lines follow the
//!     weight the r = 0 radius happens to get (halving it, the trapezoid
//!     end weight, turns Tessar degree 3 from 0.9 % into 4.8 %);
//!   - the number of uniform radii, 12/16/24/32/48/96: double Gauss
//!     degree 3 2.4/2.0/1.7/1.6/1.5/1.4 %, degree 4 1.1/1.2/1.3/1.3/1.4/
//!     1.5 %; Tessar degree 3 0.8/1.6/0.9/0.6/2.1/3.7 %, degree 4 0.7/1.0/
//!     1.2/1.2/1.2/1.1 %, degree 5 0.2/0.9/1.7/2.0/2.3/2.6 %, while the
//!     field-wide film RMS moves by < 10 % (Tessar degree 5: 125/129/135/
//!     139/144/149 µm). The low-degree on-axis lines are not a stable
//!     property of the fit: they swing by 10× with a sampling detail that
//!     changes the whole-field quality little;
//!   - the continuum limit of the same objective (every pupil sample its
//!     own radius, jittered within n strata of [0, r_last], σ interpolated
//!     in r): stable in n (12/24/48 agree to 0.1 %), and double Gauss
//!     1.33/1.56/0.39/0.37/0.31 %, Tessar 5.5/0.9/3.2/0.5/0.9 % at degrees
//!     3–7 (film RMS: double Gauss 16.0/4.1/1.1/0.4/0.1 µm, Tessar 224/271/
//!     156/84/54 µm). So the default's 0.9 % at Tessar degree 3 owes
//!     itself to the discrete r = 0 radius carrying 1/24 of the weight;
//!   - the r = 0 radius weighted ×16: 2.23/0.46/0.36 [20.3/5.0/1.3] |
//!     0.27/0.52/0.07 [219/258/146]; ×256 still leaves double Gauss
//!     degree 3 at 1.61 %;
//!   - only the monomials the lens's symmetries allow (odd in dx for outx
//!     and outdx, odd total degree for the lateral outputs; the true map
//!     has that Taylor series): far worse (double Gauss 11 % at degree 3),
//!     because on the one-sided range r ≥ 0 the even terms add reach;
//!   - fitting the ray's landing point on a far reference plane (tangent
//!     form: outdx, outdy the slopes and outdz = 1) instead of the
//!     direction cosines: the same ESF to 0.01 % (measured on the on-axis
//!     rays; each output is fitted separately with the same weights, so
//!     any fixed linear combination of outputs has the same least-squares
//!     optimum, and the slopes differ from the cosines only through outdz).
//!   - per field, extra least-squares rows asking the residual to have
//!     zero mean and zero first moments over the pupil (the coherent
//!     shift/focus part an image sees most), weight λ = 1/3/10: worse
//!     (double Gauss degree 3 2.1/10/8 %, Tessar degree 4 2.3/6.2/11 %).
//!
//! The Tessar's degree 5 (1.68 %) being worse than its degree 3 (0.90 %)
//! is the same effect seen from the other side: its r = 0 RMS direction
//! error relative to σ is *lower* at degree 5 (0.72× that of degree 3;
//! degree 4 1.20×), yet the on-axis ESF error is higher. The on-axis line
//! is not a monotone function of the axis's share of the objective: it
//! depends on how the error is shaped over the near-axis rays: with the
//! film at the ESF's 1.3 m focus, 10.1 mm behind the input plane, the
//! on-axis ESF's rays cross the input plane at radii up to 1.3 mm (double
//! Gauss: 11.4 mm, 1.9 mm), between the sampled radii 0 and 3.75 mm
//! (1.82 mm), and the low-degree global fit leaves their error shape to
//! chance.
//!
//! The film-bundle data (above) resolved degrees 4–5: the instability was
//! the input-plane sampling's, not the polynomial's.
//!
//! Pass/no-pass: the pass plane is the paraxial exit pupil (its distance
//! from the input plane; the input-plane offset if that is not > 5 % of f).
//! The last input radius that passes light is found by a scan in steps of
//! 2 % of f (a 24×24 grid on the pass plane) refined by bisection. At each of
//! `n_ellipses` field radii the boundary of the passing region is located by
//! bisection along 64 directions from the centroid of a 48×48 passing grid
//! (points mirrored in x, so every ellipse is axis-aligned), and the aperture
//! that blocks just outside each boundary point is recorded. Three
//! representations (`PassMethod`; RI error against the prescription, double
//! Gauss / Tessar, degree 5, tests/optics_rtf_fit.rs):
//! - `AreaEllipses` (default, decision): the ellipse with the region's
//!   radial extent and area; it transmits the right flux: 0.005 / 0.004.
//! - `Ellipses` (the paper's files): the minimum-area enclosing ellipse,
//!   Khachiyan's algorithm, scaled to contain every point. Where the region
//!   is a vignetted "cat's eye" the enclosing ellipse lets through rays the
//!   lens blocks: 0.075 / 0.031, high at vignetted fields.
//! - `Circles` (Goossens et al.): one circle per blocking aperture, radius R
//!   and centre (0, s·r) fitted (Gauss–Newton on the geometric distance) to
//!   the boundary points that aperture blocks. Exact in first-order optics;
//!   real pupil aberration makes the images of the apertures change size and
//!   move non-linearly with r, and the constant-R, linear-centre model misses
//!   that: 0.013 / 0.027 — above the 0.01 acceptance, so not the default.
//!
//! Radii beyond the last one that passes light get no ellipse (circles: the
//! file's `maxInputRadius`), so the RTF camera blocks them (no extrapolation).

// `!(x > 0.0)` is used on purpose: it also rejects NaN.
#![allow(clippy::neg_cmp_op_on_partial_ord)]

use super::prescription::{Blocked, Prescription};
use super::rtf::{Circles, Ellipses, PassNoPass, Poly, Rtf, RtfCamera, RtfWave};
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

/// How the fit samples the lens (decision and measurements: module docs).
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

/// Least-squares solution of A x ≈ b_k for several right-hand sides.
pub struct LstsqSolution {
    pub x: Vec<Vec<f64>>,
    pub rank: usize,
    pub condition_number: f64,
}

/// Householder QR with column pivoting. `cols` is column-major (`cols[j][i]`),
/// m rows; each `rhs[k]` has m entries.
pub fn lstsq_qr(mut cols: Vec<Vec<f64>>, mut rhs: Vec<Vec<f64>>) -> Result<LstsqSolution> {
    let n = cols.len();
    let m = cols.first().map_or(0, |c| c.len());
    if m < n || n == 0 {
        return Err(Error::Invalid(format!(
            "least squares: {m} samples for {n} unknowns"
        )));
    }
    if cols
        .iter()
        .flatten()
        .chain(rhs.iter().flatten())
        .any(|v| !v.is_finite())
    {
        return Err(Error::Invalid("least squares: non-finite input".into()));
    }
    let mut perm: Vec<usize> = (0..n).collect();
    let mut rank = n;
    let mut r00 = 0.0;
    for k in 0..n {
        // Pivot on the largest remaining column norm.
        let norms: Vec<f64> = (k..n)
            .map(|j| cols[j][k..].iter().map(|v| v * v).sum::<f64>())
            .collect();
        let (pj, &pn) = norms
            .iter()
            .enumerate()
            .max_by(|a, b| a.1.total_cmp(b.1))
            .unwrap();
        let p = k + pj;
        cols.swap(k, p);
        perm.swap(k, p);
        let norm = pn.sqrt();
        if k == 0 {
            r00 = norm;
        }
        if !(norm > 1e-13 * r00) {
            rank = k;
            break;
        }
        let alpha = if cols[k][k] > 0.0 { -norm } else { norm };
        let mut v: Vec<f64> = cols[k][k..].to_vec();
        v[0] -= alpha;
        let vn2: f64 = v.iter().map(|x| x * x).sum();
        cols[k][k] = alpha;
        for x in cols[k][k + 1..].iter_mut() {
            *x = 0.0;
        }
        if vn2 == 0.0 {
            continue;
        }
        let apply = |c: &mut [f64]| {
            let s: f64 = c.iter().zip(&v).map(|(a, b)| a * b).sum::<f64>() * 2.0 / vn2;
            for (a, b) in c.iter_mut().zip(&v) {
                *a -= s * b;
            }
        };
        let (_, rest) = cols.split_at_mut(k + 1);
        rest.par_iter_mut().for_each(|c| apply(&mut c[k..]));
        for b in rhs.iter_mut() {
            apply(&mut b[k..]);
        }
    }
    let rr = |i: usize, j: usize| cols[j][i];
    let solve_r = |b: &[f64]| -> Vec<f64> {
        let mut x = vec![0.0; rank];
        for i in (0..rank).rev() {
            let s: f64 = (i + 1..rank).map(|j| rr(i, j) * x[j]).sum();
            x[i] = (b[i] - s) / rr(i, i);
        }
        x
    };
    let solve_rt = |b: &[f64]| -> Vec<f64> {
        let mut x = vec![0.0; rank];
        for i in 0..rank {
            let s: f64 = (0..i).map(|j| rr(j, i) * x[j]).sum();
            x[i] = (b[i] - s) / rr(i, i);
        }
        x
    };
    let x = rhs
        .iter()
        .map(|b| {
            let xs = solve_r(&b[..rank]);
            let mut out = vec![0.0; n];
            for (i, v) in xs.into_iter().enumerate() {
                out[perm[i]] = v;
            }
            out
        })
        .collect();
    // Condition number of the kept block: σ_max by power iteration on RᵀR,
    // σ_min by inverse iteration (two triangular solves per step).
    let mul_r = |v: &[f64]| {
        (0..rank)
            .map(|i| (i..rank).map(|j| rr(i, j) * v[j]).sum::<f64>())
            .collect::<Vec<_>>()
    };
    let mul_rt = |v: &[f64]| {
        (0..rank)
            .map(|i| (0..=i).map(|j| rr(j, i) * v[j]).sum::<f64>())
            .collect::<Vec<_>>()
    };
    let unit = |v: Vec<f64>| {
        let n = v.iter().map(|x| x * x).sum::<f64>().sqrt();
        (v.iter().map(|x| x / n).collect::<Vec<_>>(), n)
    };
    let start: Vec<f64> = (0..rank).map(|i| 1.0 + 0.1 * (i as f64).sin()).collect();
    let (mut v, _) = unit(start.clone());
    let mut smax2 = 0.0;
    for _ in 0..60 {
        let (w, n) = unit(mul_rt(&mul_r(&v)));
        v = w;
        smax2 = n;
    }
    let (mut v, _) = unit(start);
    let mut inv2 = 0.0;
    for _ in 0..60 {
        let (w, n) = unit(solve_r(&solve_rt(&v)));
        v = w;
        inv2 = n;
    }
    let cond = (smax2 * inv2).sqrt();
    Ok(LstsqSolution {
        x,
        rank,
        condition_number: if cond.is_finite() { cond } else { f64::MAX },
    })
}

/// Minimum-area enclosing ellipse (Khachiyan). Returns (centre, A) with
/// (p−c)ᵀA(p−c) ≤ 1 for every point (scaled to guarantee containment).
pub fn min_area_ellipse(points: &[DVec2], tol: f64) -> Option<(DVec2, [[f64; 2]; 2])> {
    let n = points.len();
    if n < 3 {
        return None;
    }
    let mut u = vec![1.0 / n as f64; n];
    for _ in 0..100_000 {
        // X = Σ u q qᵀ with q = (x, y, 1).
        let mut x = [[0.0; 3]; 3];
        for (p, &w) in points.iter().zip(&u) {
            let q = [p.x, p.y, 1.0];
            for a in 0..3 {
                for b in 0..3 {
                    x[a][b] += w * q[a] * q[b];
                }
            }
        }
        let xi = inv3(&x)?;
        let (mut jmax, mut mmax) = (0, f64::NEG_INFINITY);
        for (j, p) in points.iter().enumerate() {
            let q = [p.x, p.y, 1.0];
            let mut m = 0.0;
            for a in 0..3 {
                for b in 0..3 {
                    m += q[a] * xi[a][b] * q[b];
                }
            }
            if m > mmax {
                mmax = m;
                jmax = j;
            }
        }
        let step = (mmax - 3.0) / (3.0 * (mmax - 1.0));
        for w in u.iter_mut() {
            *w *= 1.0 - step;
        }
        u[jmax] += step;
        if step < tol {
            break;
        }
    }
    let c = points
        .iter()
        .zip(&u)
        .fold(DVec2::ZERO, |a, (p, &w)| a + *p * w);
    let mut s = [[0.0; 2]; 2];
    for (p, &w) in points.iter().zip(&u) {
        let d = *p - c;
        s[0][0] += w * d.x * d.x;
        s[0][1] += w * d.x * d.y;
        s[1][1] += w * d.y * d.y;
    }
    s[1][0] = s[0][1];
    let det = s[0][0] * s[1][1] - s[0][1] * s[1][0];
    if !(det > 0.0) {
        return None;
    }
    // A = (1/d)·S⁻¹ with d = 2.
    let mut a = [
        [s[1][1] / det / 2.0, -s[0][1] / det / 2.0],
        [-s[1][0] / det / 2.0, s[0][0] / det / 2.0],
    ];
    let q = |p: &DVec2| {
        let d = *p - c;
        a[0][0] * d.x * d.x + 2.0 * a[0][1] * d.x * d.y + a[1][1] * d.y * d.y
    };
    let worst = points.iter().map(q).fold(0.0, f64::max);
    if worst > 1.0 {
        for row in a.iter_mut() {
            for v in row.iter_mut() {
                *v /= worst;
            }
        }
    }
    Some((c, a))
}

fn inv3(m: &[[f64; 3]; 3]) -> Option<[[f64; 3]; 3]> {
    let c =
        |r0: usize, r1: usize, c0: usize, c1: usize| m[r0][c0] * m[r1][c1] - m[r0][c1] * m[r1][c0];
    let cof = [
        [c(1, 2, 1, 2), -c(1, 2, 0, 2), c(1, 2, 0, 1)],
        [-c(0, 2, 1, 2), c(0, 2, 0, 2), -c(0, 2, 0, 1)],
        [c(0, 1, 1, 2), -c(0, 1, 0, 2), c(0, 1, 0, 1)],
    ];
    let det = m[0][0] * cof[0][0] + m[0][1] * cof[0][1] + m[0][2] * cof[0][2];
    if !(det.abs() > 1e-300) {
        return None;
    }
    let mut inv = [[0.0; 3]; 3];
    for i in 0..3 {
        for j in 0..3 {
            inv[i][j] = cof[j][i] / det;
        }
    }
    Some(inv)
}

/// Axis-aligned ellipse with the region's radial (y) extent and its area:
/// cy, ry from the extreme y of the boundary, rx = area/(π·ry), cx = 0. The
/// boundary points come in angular order around an interior point as pairs
/// (p, mirrored p); the even ones form a star-shaped polygon (shoelace area).
pub fn area_matched_ellipse(pts: &[DVec2]) -> Option<(DVec2, [f64; 2])> {
    let poly: Vec<DVec2> = pts.iter().step_by(2).copied().collect();
    let n = poly.len();
    if n < 3 {
        return None;
    }
    let area = 0.5
        * (0..n)
            .map(|i| poly[i].perp_dot(poly[(i + 1) % n]))
            .sum::<f64>()
            .abs();
    let ymin = pts.iter().map(|p| p.y).fold(f64::INFINITY, f64::min);
    let ymax = pts.iter().map(|p| p.y).fold(f64::NEG_INFINITY, f64::max);
    let ry = 0.5 * (ymax - ymin);
    if !(ry > 0.0 && area > 0.0) {
        return None;
    }
    Some((
        DVec2::new(0.0, 0.5 * (ymin + ymax)),
        [area / (std::f64::consts::PI * ry), ry],
    ))
}

/// Fit one circle per blocking surface to boundary points (r, p, surface):
/// x² + (y − s·r)² = R², linear least squares for a start, then Gauss–Newton
/// on the geometric distance. Surfaces with fewer than 8 points are skipped.
pub fn vignetting_circles(
    pts: &[(f64, DVec2, usize)],
    plane_distance_mm: f64,
    max_input_radius_mm: f64,
) -> Option<PassNoPass> {
    let mut surfaces: Vec<usize> = pts.iter().map(|p| p.2).collect();
    surfaces.sort_unstable();
    surfaces.dedup();
    let (mut radii, mut sens) = (Vec::new(), Vec::new());
    for s in surfaces {
        let g: Vec<(f64, DVec2)> = pts
            .iter()
            .filter(|p| p.2 == s)
            .map(|p| (p.0, p.1))
            .collect();
        if g.len() < 8 {
            continue;
        }
        // x² + y² = A + B·(r·y) + C·r²  with A = R², B = 2s, C = −s².
        let cols = vec![
            g.iter().map(|_| 1.0).collect::<Vec<_>>(),
            g.iter().map(|(r, p)| r * p.y).collect(),
            g.iter().map(|(r, _)| r * r).collect(),
        ];
        let rhs = vec![
            g.iter()
                .map(|(_, p)| p.length_squared())
                .collect::<Vec<_>>(),
        ];
        let sol = lstsq_qr(cols, rhs).ok()?;
        let (mut rr, mut ss) = (sol.x[0][0].max(1e-12).sqrt(), 0.5 * sol.x[0][1]);
        for _ in 0..30 {
            let (mut a, mut b, mut c, mut g0, mut g1) = (0.0, 0.0, 0.0, 0.0, 0.0);
            for (r, p) in &g {
                let dy = p.y - ss * r;
                let rho = (p.x * p.x + dy * dy).sqrt().max(1e-12);
                let e = rho - rr;
                let (j0, j1) = (-1.0, -dy * r / rho);
                a += j0 * j0;
                b += j0 * j1;
                c += j1 * j1;
                g0 += j0 * e;
                g1 += j1 * e;
            }
            let det = a * c - b * b;
            if !(det.abs() > 1e-300) {
                // s undetermined (all points at r = 0): fit R only.
                rr -= g0 / a;
                continue;
            }
            rr -= (c * g0 - b * g1) / det;
            ss -= (a * g1 - b * g0) / det;
        }
        if !(rr > 0.0 && rr.is_finite() && ss.is_finite()) {
            return None;
        }
        radii.push(rr);
        sens.push(ss);
    }
    (!radii.is_empty()).then_some(PassNoPass::Circles(Circles {
        radii_mm: radii,
        sensitivities: sens,
        plane_distance_mm,
        max_input_radius_mm: Some(max_input_radius_mm),
    }))
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

#[cfg(test)]
mod tests {
    use super::*;

    /// QR least squares recovers an exact polynomial and a known condition number.
    #[test]
    fn qr_recovers_known_solution_and_condition() {
        // Columns: diag-like scaled basis with known singular values 1 and 1e-3.
        let m = 50;
        let c0: Vec<f64> = (0..m).map(|i| if i == 0 { 1.0 } else { 0.0 }).collect();
        let c1: Vec<f64> = (0..m).map(|i| if i == 1 { 1e-3 } else { 0.0 }).collect();
        let b: Vec<f64> = (0..m)
            .map(|i| {
                if i == 0 {
                    2.0
                } else if i == 1 {
                    3e-3
                } else {
                    0.0
                }
            })
            .collect();
        let s = lstsq_qr(vec![c0, c1], vec![b]).unwrap();
        assert!((s.x[0][0] - 2.0).abs() < 1e-12 && (s.x[0][1] - 3.0).abs() < 1e-9);
        assert!(
            (s.condition_number / 1e3 - 1.0).abs() < 1e-6,
            "{}",
            s.condition_number
        );
        // A cubic fitted through noiseless samples.
        let xs: Vec<f64> = (0..40).map(|i| -1.0 + 2.0 * i as f64 / 39.0).collect();
        let cols: Vec<Vec<f64>> = (0..4)
            .map(|p| xs.iter().map(|x| x.powi(p)).collect())
            .collect();
        let y: Vec<f64> = xs.iter().map(|x| 1.0 - 2.0 * x + 0.5 * x * x * x).collect();
        let s = lstsq_qr(cols, vec![y]).unwrap();
        for (got, want) in s.x[0].iter().zip([1.0, -2.0, 0.0, 0.5]) {
            assert!((got - want).abs() < 1e-12);
        }
    }

    /// Khachiyan: points on a known ellipse give that ellipse back.
    #[test]
    fn min_area_ellipse_recovers_ellipse() {
        let pts: Vec<DVec2> = (0..64)
            .map(|k| {
                let t = std::f64::consts::TAU * k as f64 / 64.0;
                DVec2::new(0.3 + 2.0 * t.cos(), -1.0 + 0.5 * t.sin())
            })
            .collect();
        let (c, a) = min_area_ellipse(&pts, 1e-9).unwrap();
        assert!((c - DVec2::new(0.3, -1.0)).length() < 1e-4);
        assert!(
            (1.0 / a[0][0].sqrt() - 2.0).abs() < 1e-3 && (1.0 / a[1][1].sqrt() - 0.5).abs() < 1e-3
        );
        assert!(a[0][1].abs() < 1e-4);
    }

    /// Vignetting circles: boundary points of an intersection of two known
    /// circles (radius R, centre (0, s·r)) over several input radii give
    /// those circles back.
    #[test]
    fn vignetting_circles_recover_known_circles() {
        let truth = [(0usize, 2.0, 0.0), (3usize, 2.5, 0.3)];
        let mut pts = Vec::new();
        for k in 0..6 {
            let r = 1.5 * k as f64;
            for a in 0..64 {
                let th = std::f64::consts::TAU * (a as f64 + 0.5) / 64.0;
                for &(surf, rad, s) in &truth {
                    let p = DVec2::new(rad * th.cos(), s * r + rad * th.sin());
                    // Keep the part of each circle inside the other one.
                    let inside = truth.iter().all(|&(_, r2, s2)| {
                        p.x * p.x + (p.y - s2 * r).powi(2) <= r2 * r2 * (1.0 + 1e-12)
                    });
                    if inside {
                        pts.push((r, p, surf));
                    }
                }
            }
        }
        let Some(PassNoPass::Circles(c)) = vignetting_circles(&pts, 10.0, 7.5) else {
            panic!("no circles");
        };
        assert_eq!(c.radii_mm.len(), 2);
        for (k, &(_, rad, s)) in truth.iter().enumerate() {
            assert!((c.radii_mm[k] - rad).abs() < 1e-9, "{:?}", c);
            assert!((c.sensitivities[k] - s).abs() < 1e-9, "{:?}", c);
        }
        assert_eq!(c.max_input_radius_mm, Some(7.5));
    }
}
