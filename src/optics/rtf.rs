//! Ray-transfer-function (RTF) camera: ISET RTF JSON (Goossens et al. 2022,
//! as used for the Pixel 4a lens in the paper, III-B).
//!
//! File: `thickness` (rear to front vertex), `planeoffsetinput` (input plane
//! this far from the rear vertex, towards the film), `planeoffsetoutput`
//! (output plane this far beyond the front vertex), all mm;
//! `polynomials[]` per wavelength with `poly[]` entries `outx, outy, outz,
//! outdx, outdy, outdz` (monomials r^termr·dx^termdx·dy^termdy) and a
//! `passnopass` block (`minimalellipse`: per input radius `positions`,
//! `radiiX`, `radiiY`, `centersX`, `centersY` on a plane
//! `intersectPlaneDistance` beyond the input plane).
//!
//! Geometry (mm, film at z = 0, +z to the scene; camera space is the same in
//! metres): rear vertex at z = D (the film distance, film to rear vertex),
//! input plane at z_in = D − planeoffsetinput, pass plane at
//! z_in + intersectPlaneDistance.
//!
//! Evaluation of one ray: the input point (x, y) on the input plane and the
//! unit direction are rotated about the axis by ψ = atan2(x, y), which puts
//! the point on +y at radius r; the polynomials are evaluated at (r, dx, dy)
//! of the rotated ray; the output point and direction are rotated back by −ψ.
//! Pass/no-pass: the rotated ray meets the pass plane at
//! (X, Y) = (0, r) + (dx, dy)/dz·intersectPlaneDistance and passes iff
//! ((X−cx)/rx)² + ((Y−cy)/ry)² ≤ 1 with cx, cy, rx (tangential, "radiiX"),
//! ry (radial, "radiiY") interpolated linearly in r between `positions`.
//! Inputs beyond the last position are blocked (vignetted), never extrapolated.
//!
//! Output-plane z convention (derivation). The polynomials map a ray on the
//! input plane to a ray on the output plane, so `outz` is the *axial distance
//! from the input plane to the output plane*: with the data generated from
//! a real lens, z_out − z_in = planeoffsetinput + thickness + planeoffsetoutput
//! (input plane to rear vertex, through the lens, front vertex to output
//! plane). The Pixel 4a file's `outz` is the constant 6.300158 mm, against
//! 0.464136 + 4.827 + 1.480022 = 6.771 mm for the sum, so the file's
//! offsets are not mutually consistent; the
//! polynomial output is what the fit actually saw, so when `outz` is
//! present the output ray starts at z_in + outz, otherwise at
//! z_in + planeoffsetinput + thickness + planeoffsetoutput. The alternative
//! ("outz measured from the rear vertex") moves every output ray by
//! planeoffsetinput along z. Our own fits (`fit.rs`) write `outz` as the
//! input-to-output-plane distance, and `tests/optics_rtf_fit.rs` checks the
//! convention: a fitted RTF and the prescription it came from give the same
//! ESF for an object at a *finite* distance, which would fail if the output
//! plane were displaced along z (a displaced plane shifts every ray's origin
//! and defocuses the image of a near object).
//!
//! Film distance of the paper's Pixel 4a file (measured, `camsim lens info
//! --film-distance-mm D`, column `beam_vergence_per_m`): the on-axis beam is
//! parallel (vergence −0.003 1/m) at D = 0.48060 mm, the infinity film
//! distance `lens info` reports. The paper's 0.465136 mm (Fig. 5 and its
//! Cornell box) is 1 µm behind this file's input plane (`planeoffsetinput`
//! 0.464136) — the black box's own image surface — and 15 µm *inside*
//! infinity focus: vergence −0.82 1/m, i.e. focus beyond infinity, as
//! Newton's relation Δ/f² = −0.81 1/m predicts (f = 4.368 mm). It is not
//! a finite focus distance, and the output-plane convention cannot make it
//! one: vergence near infinity does not depend on where the output plane
//! is, and moving it by planeoffsetinput shifts a focus by only 0.46 mm.
//! The paper's set-up pairs 0.49234 mm ↔ 0.5 m and 0.57624 mm ↔ 0.3 m
//! focus; this file gives 0.61 1/m (1.6 m) and 4.72 1/m (0.21 m) there.
//! Relative illumination barely depends on it (the Fig. 5 acceptance
//! holds at 0.465136), but depth of field does: use `lens info` to choose
//! film distances for a focus distance.
//!
//! Radiometry: the pass plane is parallel to the film, so sampling a point
//! uniformly in a box of area A on it gives weight A·h²/dist⁴ (projected
//! solid angle, h = film-to-pass-plane distance), with rays outside the
//! ellipse blocked. Several wavelengths: the table nearest to the requested
//! (hero) wavelength is used.

// `!(x > 0.0)` is used on purpose: it also rejects NaN.
#![allow(clippy::neg_cmp_op_on_partial_ord)]

use super::{Camera, CameraRay};
use crate::{Error, Result};
use glam::{DVec2, DVec3};
use pupil_boxes::PupilBoxes;
use serde_json::{Value, json};
use std::path::Path;

/// One output polynomial in (r, dx, dy).
#[derive(Clone, Debug, PartialEq)]
pub struct Poly {
    /// Exponents (r, dx, dy).
    pub terms: Vec<[u32; 3]>,
    pub coeff: Vec<f64>,
}

impl Poly {
    pub fn max_degree(&self) -> u32 {
        self.terms
            .iter()
            .map(|t| t[0].max(t[1]).max(t[2]))
            .max()
            .unwrap_or(0)
    }
    /// Value at (r, dx, dy) with precomputed power tables.
    fn eval_pow(&self, pr: &[f64], px: &[f64], py: &[f64]) -> f64 {
        self.terms
            .iter()
            .zip(&self.coeff)
            .map(|(t, c)| c * pr[t[0] as usize] * px[t[1] as usize] * py[t[2] as usize])
            .sum()
    }
    pub fn eval(&self, r: f64, dx: f64, dy: f64) -> f64 {
        let n = self.max_degree() as usize + 1;
        let pw = |v: f64| {
            (0..n)
                .scan(1.0, |a, _| {
                    let x = *a;
                    *a *= v;
                    Some(x)
                })
                .collect::<Vec<_>>()
        };
        self.eval_pow(&pw(r), &pw(dx), &pw(dy))
    }
}

/// Pass/no-pass ellipses against input radius.
#[derive(Clone, Debug, PartialEq)]
pub struct Ellipses {
    pub positions_mm: Vec<f64>,
    pub radii_x_mm: Vec<f64>,
    pub radii_y_mm: Vec<f64>,
    pub centers_x_mm: Vec<f64>,
    pub centers_y_mm: Vec<f64>,
    /// Pass plane distance beyond the input plane.
    pub plane_distance_mm: f64,
}

impl Ellipses {
    /// (cx, cy, rx, ry) at input radius r; None beyond the last position.
    #[inline]
    pub fn at(&self, r: f64) -> Option<[f64; 4]> {
        let p = &self.positions_mm;
        let last = *p.last()?;
        if !(r >= 0.0) || r > last {
            return None;
        }
        let k = first_above(p, r).clamp(1, p.len().max(2) - 1);
        if p.len() == 1 {
            return Some([
                self.centers_x_mm[0],
                self.centers_y_mm[0],
                self.radii_x_mm[0],
                self.radii_y_mm[0],
            ]);
        }
        let t = ((r - p[k - 1]) / (p[k] - p[k - 1])).clamp(0.0, 1.0);
        let l = |v: &Vec<f64>| v[k - 1] + t * (v[k] - v[k - 1]);
        Some([
            l(&self.centers_x_mm),
            l(&self.centers_y_mm),
            l(&self.radii_x_mm),
            l(&self.radii_y_mm),
        ])
    }
}

/// `p.partition_point(|&x| x <= r)` for sorted `p` and a number `r` (not
/// NaN): the first index whose entry is above `r`. Starts from where `r`
/// would fall if the entries were evenly spaced (the fitted tables' input
/// radii are) and steps to the exact index with the same comparisons, so
/// uneven spacing is only slower.
#[inline]
fn first_above(p: &[f64], r: f64) -> usize {
    let n = p.len();
    if n < 2 {
        return p.partition_point(|&x| x <= r);
    }
    let span = p[n - 1] - p[0];
    let guess = if span > 0.0 {
        (r - p[0]) / span * (n - 1) as f64
    } else {
        0.0
    };
    // `as usize` truncates, which is the floor for the non-negative guesses,
    // and saturates: below 0 (and NaN) to 0, above n to usize::MAX.
    let mut k = (guess as usize).saturating_add(1).min(n);
    while k > 0 && p[k - 1] > r {
        k -= 1;
    }
    while k < n && p[k] <= r {
        k += 1;
    }
    k
}

/// Pass/no-pass as an intersection of circles on a plane `plane_distance_mm`
/// beyond the input plane (Goossens et al.): circle i has radius R_i and its
/// centre at (0, s_i·r) in the rotated frame (input point on +y at radius r).
/// JSON (`passnopass.method = "circles"`): `circleRadii`, `circleSensitivities`,
/// `circlePlaneZ`, and optionally `maxInputRadius` (camsim: inputs beyond it
/// are blocked).
#[derive(Clone, Debug, PartialEq)]
pub struct Circles {
    pub radii_mm: Vec<f64>,
    pub sensitivities: Vec<f64>,
    pub plane_distance_mm: f64,
    pub max_input_radius_mm: Option<f64>,
}

/// The pass/no-pass test of one wavelength.
#[derive(Clone, Debug, PartialEq)]
pub enum PassNoPass {
    Ellipses(Ellipses),
    Circles(Circles),
}

impl PassNoPass {
    pub fn plane_distance_mm(&self) -> f64 {
        match self {
            PassNoPass::Ellipses(e) => e.plane_distance_mm,
            PassNoPass::Circles(c) => c.plane_distance_mm,
        }
    }
    /// Largest input radius with a defined region (None: unlimited).
    pub fn max_radius_mm(&self) -> Option<f64> {
        match self {
            PassNoPass::Ellipses(e) => e.positions_mm.last().copied(),
            PassNoPass::Circles(c) => c.max_input_radius_mm,
        }
    }
    /// Does the rotated ray meeting the pass plane at (x, y) from input radius r pass?
    pub fn passes(&self, r: f64, x: f64, y: f64) -> bool {
        match self {
            PassNoPass::Ellipses(e) => match e.at(r) {
                Some([cx, cy, rx, ry]) => ((x - cx) / rx).powi(2) + ((y - cy) / ry).powi(2) <= 1.0,
                None => false,
            },
            PassNoPass::Circles(c) => {
                if c.max_input_radius_mm.is_some_and(|m| r > m) {
                    return false;
                }
                c.radii_mm
                    .iter()
                    .zip(&c.sensitivities)
                    .all(|(rad, s)| x * x + (y - s * r).powi(2) <= rad * rad)
            }
        }
    }
    /// Bounding box [x0, x1, y0, y1] of the pass region at input radius r.
    #[inline]
    pub fn bbox(&self, r: f64) -> Option<[f64; 4]> {
        match self {
            PassNoPass::Ellipses(e) => e
                .at(r)
                .map(|[cx, cy, rx, ry]| [cx - rx, cx + rx, cy - ry, cy + ry]),
            PassNoPass::Circles(c) => {
                if c.max_input_radius_mm.is_some_and(|m| r > m) {
                    return None;
                }
                let mut b = [
                    f64::NEG_INFINITY,
                    f64::INFINITY,
                    f64::NEG_INFINITY,
                    f64::INFINITY,
                ];
                for (rad, s) in c.radii_mm.iter().zip(&c.sensitivities) {
                    b[0] = b[0].max(-rad);
                    b[1] = b[1].min(*rad);
                    b[2] = b[2].max(s * r - rad);
                    b[3] = b[3].min(s * r + rad);
                }
                (b[0] < b[1] && b[2] < b[3]).then_some(b)
            }
        }
    }
    /// Largest |coordinate| any region reaches (for sampling bounds).
    fn reach(&self, r: f64) -> f64 {
        match self {
            PassNoPass::Ellipses(e) => e
                .centers_y_mm
                .iter()
                .zip(&e.radii_y_mm)
                .map(|(c, r)| c.abs() + r)
                .chain(
                    e.centers_x_mm
                        .iter()
                        .zip(&e.radii_x_mm)
                        .map(|(c, r)| c.abs() + r),
                )
                .fold(0.0, f64::max),
            PassNoPass::Circles(c) => c
                .radii_mm
                .iter()
                .zip(&c.sensitivities)
                .map(|(rad, s)| (s * r).abs() + rad)
                .fold(f64::INFINITY, f64::min),
        }
    }
}

/// RTF at one wavelength.
#[derive(Clone, Debug, PartialEq)]
pub struct RtfWave {
    pub wavelength_nm: f64,
    /// outx, outy, outz, outdx, outdy, outdz (z and dz optional).
    pub outputs: [Option<Poly>; 6],
    pub pass: PassNoPass,
}

/// Highest exponent + 1 evaluated on the stack (exponents are validated < 64
/// when read; degrees above 63 are rejected there).
const MAX_POWERS: usize = 64;

/// What `Rtf::transfer` needs of one wavelength's tables, worked out once
/// (`RtfCamera` keeps one per wavelength): the powers to tabulate and, when
/// every output present uses the same exponents in the same order (as the
/// fitted tables do), the six polynomials as one (`FusedPolys`).
#[derive(Clone, Debug)]
pub struct WavePlan {
    /// Highest exponent + 1 over the outputs (at most `MAX_POWERS`).
    powers: usize,
    fused: Option<FusedPolys>,
}

impl WavePlan {
    pub fn new(w: &RtfWave) -> Self {
        WavePlan {
            fused: FusedPolys::new(w),
            ..Self::powers_only(w)
        }
    }
    /// The powers alone (no allocation): each output evaluated on its own.
    fn powers_only(w: &RtfWave) -> Self {
        let powers = (w
            .outputs
            .iter()
            .flatten()
            .map(|p| p.max_degree())
            .max()
            .unwrap_or(0) as usize
            + 1)
        .min(MAX_POWERS);
        WavePlan {
            powers,
            fused: None,
        }
    }
}

/// The outputs of one wavelength sharing one list of exponents, evaluated
/// together: per term, the monomial's three powers are looked up once and
/// each output's sum gets c·rᵃ·dxᵇ·dyᶜ in the same order and association as
/// `Poly::eval_pow` (((c·rᵃ)·dxᵇ)·dyᶜ, summed from −0.0 in term order, as
/// `Iterator::sum` does), so each value is `eval_pow`'s bit for bit; the six
/// sums are independent chains (and vector lanes) instead of six loops one
/// after another.
#[derive(Clone, Debug)]
struct FusedPolys {
    terms: Vec<[u32; 3]>,
    /// Per term, the coefficient of each output (0 for an absent output,
    /// whose value is not used).
    coeff: Vec<[f64; 8]>,
}

impl FusedPolys {
    fn new(w: &RtfWave) -> Option<Self> {
        let terms = w.outputs.iter().flatten().next()?.terms.clone();
        // Every output (the first too) with these exponents and one
        // coefficient each, so `coeff[i]` below exists for every term.
        if !w
            .outputs
            .iter()
            .flatten()
            .all(|p| p.terms == terms && p.coeff.len() == terms.len())
        {
            return None;
        }
        let coeff = (0..terms.len())
            .map(|i| {
                let mut c = [0.0; 8];
                for (k, p) in w.outputs.iter().enumerate() {
                    if let Some(p) = p {
                        c[k] = p.coeff[i];
                    }
                }
                c
            })
            .collect();
        Some(FusedPolys { terms, coeff })
    }

    #[inline]
    fn eval(&self, pr: &[f64], px: &[f64], py: &[f64]) -> [f64; 8] {
        let mut acc = [-0.0f64; 8];
        for (t, c) in self.terms.iter().zip(&self.coeff) {
            let (a, b, d) = (pr[t[0] as usize], px[t[1] as usize], py[t[2] as usize]);
            for k in 0..8 {
                acc[k] += c[k] * a * b * d;
            }
        }
        acc
    }
}

impl FusedPolys {
    /// `eval` for `L` rays side by side (lane l of every table is ray l's),
    /// the six outputs only: each lane's sums take `eval`'s operations in
    /// `eval`'s order, so each value is `eval`'s bit for bit; the lanes are
    /// independent chains, which is what lets a vector unit take several rays
    /// per instruction and keep its adders busy (`camera_lanes`).
    #[inline(always)]
    fn eval_lanes<const L: usize>(
        &self,
        pr: &[[f64; L]],
        px: &[[f64; L]],
        py: &[[f64; L]],
    ) -> [[f64; L]; 6] {
        let mut acc = [[-0.0f64; L]; 6];
        for (t, c) in self.terms.iter().zip(&self.coeff) {
            let (a, b, d) = (&pr[t[0] as usize], &px[t[1] as usize], &py[t[2] as usize]);
            for (acc_k, &ck) in acc.iter_mut().zip(c) {
                for l in 0..L {
                    acc_k[l] += ck * a[l] * b[l] * d[l];
                }
            }
        }
        acc
    }
}

const OUT_NAMES: [&str; 6] = ["outx", "outy", "outz", "outdx", "outdy", "outdz"];

/// A ray-transfer function.
#[derive(Clone, Debug, PartialEq)]
pub struct Rtf {
    pub name: String,
    pub description: String,
    pub thickness_mm: f64,
    pub plane_offset_input_mm: f64,
    pub plane_offset_output_mm: f64,
    pub waves: Vec<RtfWave>,
}

fn bad(file: &Path, msg: &str) -> Error {
    Error::Invalid(format!("{}: {msg}", file.display()))
}

fn f64_field(v: &Value, key: &str, file: &Path) -> Result<f64> {
    v.get(key)
        .and_then(|x| x.as_f64())
        .filter(|x| x.is_finite())
        .ok_or_else(|| bad(file, &format!("missing or non-numeric '{key}'")))
}

fn vec_field(v: &Value, key: &str, file: &Path) -> Result<Vec<f64>> {
    let a = v
        .get(key)
        .and_then(|x| x.as_array())
        .ok_or_else(|| bad(file, &format!("missing array '{key}'")))?;
    a.iter()
        .map(|x| {
            x.as_f64()
                .filter(|x| x.is_finite())
                .ok_or_else(|| bad(file, &format!("'{key}' holds a non-number")))
        })
        .collect()
}

impl Rtf {
    pub fn load(path: &Path) -> Result<Self> {
        let text = std::fs::read_to_string(path).map_err(|e| Error::Io {
            path: path.to_path_buf(),
            message: e.to_string(),
        })?;
        let v: Value = crate::diag::parse_json(path, &text)?;
        Self::from_value(&v, path)
    }

    pub fn from_value(v: &Value, file: &Path) -> Result<Self> {
        let polys = v
            .get("polynomials")
            .and_then(|p| p.as_array())
            .ok_or_else(|| bad(file, "expected a 'polynomials' array (ISET RTF JSON)"))?;
        let mut waves = Vec::new();
        for (wi, pw) in polys.iter().enumerate() {
            let wavelength_nm = f64_field(pw, "wavelength_nm", file)?;
            let pnp = pw
                .get("passnopass")
                .ok_or_else(|| bad(file, &format!("polynomials[{wi}]: missing 'passnopass'")))?;
            let method = pnp
                .get("method")
                .and_then(|m| m.as_str())
                .unwrap_or("minimalellipse");
            let pass = match method {
                "minimalellipse" => {
                    let e = Ellipses {
                        positions_mm: vec_field(pnp, "positions", file)?,
                        radii_x_mm: vec_field(pnp, "radiiX", file)?,
                        radii_y_mm: vec_field(pnp, "radiiY", file)?,
                        centers_x_mm: vec_field(pnp, "centersX", file)?,
                        centers_y_mm: vec_field(pnp, "centersY", file)?,
                        plane_distance_mm: f64_field(pnp, "intersectPlaneDistance", file)?,
                    };
                    let n = e.positions_mm.len();
                    if n == 0
                        || [
                            &e.radii_x_mm,
                            &e.radii_y_mm,
                            &e.centers_x_mm,
                            &e.centers_y_mm,
                        ]
                        .iter()
                        .any(|a| a.len() != n)
                    {
                        return Err(bad(
                            file,
                            &format!(
                                "polynomials[{wi}].passnopass: arrays must have equal, non-zero length"
                            ),
                        ));
                    }
                    if e.positions_mm.windows(2).any(|w| w[1] <= w[0]) {
                        return Err(bad(file, "passnopass 'positions' must increase"));
                    }
                    if e.radii_x_mm
                        .iter()
                        .chain(&e.radii_y_mm)
                        .any(|r| !(*r > 0.0))
                    {
                        return Err(bad(file, "passnopass radii must be > 0"));
                    }
                    PassNoPass::Ellipses(e)
                }
                "circles" => {
                    let c = Circles {
                        radii_mm: vec_field(pnp, "circleRadii", file)?,
                        sensitivities: vec_field(pnp, "circleSensitivities", file)?,
                        plane_distance_mm: f64_field(pnp, "circlePlaneZ", file)?,
                        max_input_radius_mm: pnp.get("maxInputRadius").and_then(|v| v.as_f64()),
                    };
                    if c.radii_mm.is_empty() || c.radii_mm.len() != c.sensitivities.len() {
                        return Err(bad(
                            file,
                            "passnopass: circleRadii and circleSensitivities must have equal, non-zero length",
                        ));
                    }
                    PassNoPass::Circles(c)
                }
                other => {
                    return Err(Error::NotSupported(format!(
                        "{}: pass/no-pass method '{other}' (known: minimalellipse, circles)",
                        file.display()
                    )));
                }
            };
            let mut outputs: [Option<Poly>; 6] = Default::default();
            for p in pw
                .get("poly")
                .and_then(|p| p.as_array())
                .ok_or_else(|| bad(file, "missing 'poly' array"))?
            {
                let name = p.get("outputname").and_then(|n| n.as_str()).unwrap_or("");
                let Some(k) = OUT_NAMES.iter().position(|&n| n == name) else {
                    return Err(bad(
                        file,
                        &format!("unknown outputname '{name}' (expected one of {OUT_NAMES:?})"),
                    ));
                };
                let coeff = vec_field(p, "coeff", file)?;
                let ex = |key: &str| -> Result<Vec<u32>> {
                    vec_field(p, key, file)?
                        .into_iter()
                        .map(|x| {
                            if x >= 0.0 && x.fract() == 0.0 && x < 64.0 {
                                Ok(x as u32)
                            } else {
                                Err(bad(file, &format!("{name}.{key}: bad exponent {x}")))
                            }
                        })
                        .collect()
                };
                let (tr, tx, ty) = (ex("termr")?, ex("termdx")?, ex("termdy")?);
                if tr.len() != coeff.len() || tx.len() != coeff.len() || ty.len() != coeff.len() {
                    return Err(bad(
                        file,
                        &format!("{name}: coeff/termr/termdx/termdy lengths differ"),
                    ));
                }
                let terms = (0..coeff.len()).map(|i| [tr[i], tx[i], ty[i]]).collect();
                outputs[k] = Some(Poly { terms, coeff });
            }
            for k in [0, 1, 3, 4] {
                if outputs[k].is_none() {
                    return Err(bad(
                        file,
                        &format!("polynomials[{wi}]: missing '{}'", OUT_NAMES[k]),
                    ));
                }
            }
            waves.push(RtfWave {
                wavelength_nm,
                outputs,
                pass,
            });
        }
        if waves.is_empty() {
            return Err(bad(file, "'polynomials' is empty"));
        }
        Ok(Self {
            name: v
                .get("name")
                .and_then(|n| n.as_str())
                .unwrap_or("")
                .to_string(),
            description: v
                .get("description")
                .and_then(|n| n.as_str())
                .unwrap_or("")
                .to_string(),
            thickness_mm: f64_field(v, "thickness", file)?,
            plane_offset_input_mm: f64_field(v, "planeoffsetinput", file)?,
            plane_offset_output_mm: f64_field(v, "planeoffsetoutput", file)?,
            waves,
        })
    }

    /// ISET-compatible JSON.
    pub fn to_json(&self) -> Value {
        let polys: Vec<Value> = self
            .waves
            .iter()
            .map(|w| {
                let poly: Vec<Value> = w
                    .outputs
                    .iter()
                    .zip(OUT_NAMES)
                    .filter_map(|(p, name)| {
                        p.as_ref().map(|p| {
                            json!({
                                "outputname": name,
                                "coeff": p.coeff,
                                "termr": p.terms.iter().map(|t| t[0]).collect::<Vec<_>>(),
                                "termdx": p.terms.iter().map(|t| t[1]).collect::<Vec<_>>(),
                                "termdy": p.terms.iter().map(|t| t[2]).collect::<Vec<_>>(),
                            })
                        })
                    })
                    .collect();
                json!({
                    "wavelength_nm": w.wavelength_nm,
                    "passnopass": match &w.pass {
                        PassNoPass::Ellipses(e) => json!({
                            "method": "minimalellipse",
                            "positions": e.positions_mm,
                            "radiiX": e.radii_x_mm,
                            "radiiY": e.radii_y_mm,
                            "centersX": e.centers_x_mm,
                            "centersY": e.centers_y_mm,
                            "intersectPlaneDistance": e.plane_distance_mm,
                        }),
                        PassNoPass::Circles(c) => json!({
                            "method": "circles",
                            "circleRadii": c.radii_mm,
                            "circleSensitivities": c.sensitivities,
                            "circlePlaneZ": c.plane_distance_mm,
                            "maxInputRadius": c.max_input_radius_mm,
                        }),
                    },
                    "poly": poly,
                })
            })
            .collect();
        json!({
            "description": self.description,
            "name": self.name,
            "thickness": self.thickness_mm,
            "planeoffsetoutput": self.plane_offset_output_mm,
            "planeoffsetinput": self.plane_offset_input_mm,
            "polynomials": polys,
        })
    }

    /// Index of the table nearest to `lambda_nm` (the first of equally near ones).
    fn wave_index(&self, lambda_nm: f64) -> usize {
        (0..self.waves.len())
            .min_by(|&a, &b| {
                (self.waves[a].wavelength_nm - lambda_nm)
                    .abs()
                    .total_cmp(&(self.waves[b].wavelength_nm - lambda_nm).abs())
            })
            .unwrap()
    }

    /// Distance from the input plane to the output plane (see module docs).
    pub fn output_plane_from_input_mm(&self, w: &RtfWave) -> f64 {
        match &w.outputs[2] {
            Some(p) => p.eval(0.0, 0.0, 0.0),
            None => self.plane_offset_input_mm + self.thickness_mm + self.plane_offset_output_mm,
        }
    }

    /// Transfer a ray given on the input plane (point (x, y), unit direction)
    /// to the output plane; returns (point relative to the input plane's axis
    /// point, i.e. with z measured from the input plane, direction), or None
    /// when blocked by the pass/no-pass test.
    pub fn transfer(&self, w: &RtfWave, x: f64, y: f64, d: DVec3) -> Option<(DVec3, DVec3)> {
        self.transfer_planned(w, &WavePlan::powers_only(w), x, y, d)
    }

    /// `transfer` with what it needs of `w` worked out once (`plan`, made
    /// from `w` by `WavePlan::new`): the same result, bit for bit.
    pub fn transfer_planned(
        &self,
        w: &RtfWave,
        plan: &WavePlan,
        x: f64,
        y: f64,
        d: DVec3,
    ) -> Option<(DVec3, DVec3)> {
        let ray = self.rotate_in(w, x, y, d)?;
        let v = if plan.powers <= SHORT_POWERS {
            outputs_at::<SHORT_POWERS>(w, plan, &ray)
        } else {
            outputs_at::<MAX_POWERS>(w, plan, &ray)
        };
        self.rotate_out(&ray, v)
    }

    /// The first step of `transfer` (restated lane-wise in
    /// `camera_lanes::front_lanes`; keep the two alike): the input point (x, y) and direction
    /// `d` rotated by ψ (sinψ = s, cosψ = c) so the point goes to (0, r);
    /// None when the ray does not go forward or the pass/no-pass test
    /// blocks it.
    #[inline(always)]
    fn rotate_in(&self, w: &RtfWave, x: f64, y: f64, d: DVec3) -> Option<InputRay> {
        let r = (x * x + y * y).sqrt();
        let (s, c) = if r > 0.0 { (x / r, y / r) } else { (0.0, 1.0) };
        let dx = d.x * c - d.y * s;
        let dy = d.x * s + d.y * c;
        if !(d.z > 0.0) {
            return None;
        }
        let l = w.pass.plane_distance_mm();
        if !w.pass.passes(r, dx / d.z * l, r + dy / d.z * l) {
            return None;
        }
        Some(InputRay { r, s, c, dx, dy })
    }

    /// The last step of `transfer`: the output ray from the six outputs'
    /// values at `ray` (None: the table has no such output), rotated back
    /// by −ψ.
    #[inline(always)]
    fn rotate_out(&self, ray: &InputRay, v: [Option<f64>; 6]) -> Option<(DVec3, DVec3)> {
        let (ox, oy) = (v[0]?, v[1]?);
        let oz = v[2].unwrap_or(
            self.plane_offset_input_mm + self.thickness_mm + self.plane_offset_output_mm,
        );
        let (odx, ody) = (v[3]?, v[4]?);
        let odz = match v[5] {
            Some(z) => z,
            None => (1.0 - odx * odx - ody * ody).max(0.0).sqrt(),
        };
        let dir = DVec3::new(odx, ody, odz);
        let len = dir.length();
        if !(odz > 0.0 && len.is_finite() && len > 0.0) {
            return None;
        }
        let dir = dir / len;
        let (s, c) = (ray.s, ray.c);
        let (bx, by) = (ox * c + oy * s, -ox * s + oy * c);
        let (bdx, bdy) = (dir.x * c + dir.y * s, -dir.x * s + dir.y * c);
        let p = DVec3::new(bx, by, oz);
        let d = DVec3::new(bdx, bdy, dir.z);
        (p.is_finite() && d.is_finite()).then_some((p, d))
    }
}

/// A ray on the RTF's input plane in its input point's frame: the point at
/// (0, r), the direction's rotated x and y components (dx, dy), and the
/// rotation ψ that took it there (s = sinψ, c = cosψ).
#[derive(Clone, Copy, Debug)]
struct InputRay {
    r: f64,
    s: f64,
    c: f64,
    dx: f64,
    dy: f64,
}

/// Power tables up to `SHORT_POWERS` (degree 7) fit a short array; the
/// fitted tables are of degree 4 or 5, and a 64-entry table costs more to
/// fill than the polynomials cost to evaluate.
const SHORT_POWERS: usize = 8;

/// The six outputs of `w` at `ray` (None where the table has none), with
/// power tables of `N` ≥ `plan.powers` entries.
#[inline(always)]
fn outputs_at<const N: usize>(w: &RtfWave, plan: &WavePlan, ray: &InputRay) -> [Option<f64>; 6] {
    let mut pr = [1.0; N];
    let mut px = [1.0; N];
    let mut py = [1.0; N];
    for i in 1..plan.powers {
        pr[i] = pr[i - 1] * ray.r;
        px[i] = px[i - 1] * ray.dx;
        py[i] = py[i - 1] * ray.dy;
    }
    let fused = plan.fused.as_ref().map(|f| f.eval(&pr, &px, &py));
    std::array::from_fn(|k| match &fused {
        Some(v) => w.outputs[k].as_ref().map(|_| v[k]),
        None => w.outputs[k].as_ref().map(|p| p.eval_pow(&pr, &px, &py)),
    })
}

/// An RTF used as a camera with the film `film_distance_mm` behind the rear vertex.
#[derive(Clone, Debug)]
pub struct RtfCamera {
    pub rtf: Rtf,
    pub film_distance_mm: f64,
    /// Per wavelength: largest |coordinate| of any pass region (sampling bound).
    reach_mm: Vec<f64>,
    /// Per wavelength: what `Rtf::transfer` needs, worked out once.
    plans: Vec<WavePlan>,
    /// Per wavelength: its sampling boxes tabulated over film radius
    /// (elliptical pass regions; `pupil_boxes`), or None (the exact box).
    boxes: Vec<Option<PupilBoxes>>,
}

impl RtfCamera {
    pub fn new(rtf: Rtf, film_distance_mm: f64) -> Result<Self> {
        if !(film_distance_mm.is_finite() && film_distance_mm > 0.0) {
            return Err(Error::Invalid(format!(
                "RTF '{}': film distance must be > 0 mm, got {film_distance_mm}",
                rtf.name
            )));
        }
        let reach_mm = rtf
            .waves
            .iter()
            .map(|w| Self::reach_of(w, film_distance_mm, rtf.thickness_mm))
            .collect();
        let plans = rtf.waves.iter().map(WavePlan::new).collect();
        let mut cam = Self {
            rtf,
            film_distance_mm,
            reach_mm,
            plans,
            boxes: Vec::new(),
        };
        cam.boxes = (0..cam.rtf.waves.len())
            .map(|i| match &cam.rtf.waves[i].pass {
                PassNoPass::Ellipses(e) => {
                    let w = &cam.rtf.waves[i];
                    PupilBoxes::new(e, |r| cam.probe_delta(w, cam.reach_mm[i], r))
                }
                PassNoPass::Circles(_) => None,
            })
            .collect();
        Ok(cam)
    }

    /// Half-width δ of the input radii `sampling_box` probes around film
    /// radius `r_film` (mm): the largest lateral slope reaching any pass
    /// region of `w` (farthest reach `reach`) from the film point, carried
    /// to the input plane, with 5 % to spare.
    fn probe_delta(&self, w: &RtfWave, reach: f64, r_film: f64) -> f64 {
        let g = self.input_plane_z_mm().abs();
        let h = self.input_plane_z_mm() + w.pass.plane_distance_mm();
        let slope = (r_film + reach) / h.abs().max(1e-9);
        g * slope * 1.05
    }
    /// Farthest any pass region of `w` reaches, over input radii up to its
    /// largest (or, when unlimited, ten times the film distance or the lens
    /// thickness, whichever is larger), mm.
    fn reach_of(w: &RtfWave, film_distance_mm: f64, thickness_mm: f64) -> f64 {
        let r_top = w
            .pass
            .max_radius_mm()
            .unwrap_or(10.0 * film_distance_mm.max(thickness_mm));
        w.pass.reach(r_top)
    }
    /// Input plane position (film at 0), mm.
    pub fn input_plane_z_mm(&self) -> f64 {
        self.film_distance_mm - self.rtf.plane_offset_input_mm
    }
    /// Front vertex position (film at 0), mm.
    pub fn front_vertex_z_mm(&self) -> f64 {
        self.film_distance_mm + self.rtf.thickness_mm
    }

    /// Sampling box on the pass plane (rotated frame: film point on +y), mm:
    /// [x0, x1, y0, y1]; None when no input radius near r_film passes.
    pub fn sampling_box(&self, w: &RtfWave, r_film: f64) -> Option<[f64; 4]> {
        // Reach precomputed for the camera's own tables; computed for any other.
        let reach = match self.rtf.waves.iter().position(|x| std::ptr::eq(x, w)) {
            Some(i) => self.reach_mm[i],
            None => Self::reach_of(w, self.film_distance_mm, self.rtf.thickness_mm),
        };
        let delta = self.probe_delta(w, reach, r_film);
        let mut b = [
            f64::INFINITY,
            f64::NEG_INFINITY,
            f64::INFINITY,
            f64::NEG_INFINITY,
        ];
        let n = 8;
        for i in 0..=n {
            let r = r_film - delta + 2.0 * delta * i as f64 / n as f64;
            if let Some(q) = w.pass.bbox(r.max(0.0)) {
                b[0] = b[0].min(q[0]);
                b[1] = b[1].max(q[1]);
                b[2] = b[2].min(q[2]);
                b[3] = b[3].max(q[3]);
            }
        }
        if !b[0].is_finite() {
            return None;
        }
        // Linear interpolation between listed ellipses stays inside the union of
        // the sampled ones up to the spacing of the 9 probes; grow by 2 %.
        // The input point's own frame is rotated from the film point's by at most
        // ≈ delta/r, which moves the ellipse by at most ≈ delta: grow by that too.
        let mx = 0.02 * (b[1] - b[0]) + delta;
        let my = 0.02 * (b[3] - b[2]) + delta;
        Some([b[0] - mx, b[1] + mx, b[2] - my, b[3] + my])
    }
}

/// A camera ray of an RTF camera up to the RTF's input plane: where it
/// crosses the plane (`pin`, mm, film at z = 0), its unit direction and the
/// weight of its pupil sample.
#[derive(Clone, Copy, Debug)]
struct FilmRay {
    pin: DVec3,
    d: DVec3,
    weight: f64,
}

impl RtfCamera {
    /// The first step of `sample_ray` for wavelength table `wi` (restated
    /// lane-wise in `camera_lanes::front_lanes`; keep the two alike): the film
    /// point, a point of its sampling box on the pass plane (drawn with `u`),
    /// and the ray between them carried to the input plane. None: no box
    /// (no input radius near the film point passes) or a pass plane behind
    /// the film.
    #[inline(always)]
    fn film_ray(&self, wi: usize, film_m: DVec2, u: DVec2) -> Option<FilmRay> {
        let w = &self.rtf.waves[wi];
        let p = -film_m * 1e3;
        let r = p.length();
        let b = match self.boxes[wi].as_ref().map(|t| t.at(r)) {
            Some(Ok(b)) => b?,
            // No table, or a film radius beyond it: the exact box.
            _ => self.sampling_box(w, r)?,
        };
        let (s, c) = if r > 0.0 {
            (p.x / r, p.y / r)
        } else {
            (0.0, 1.0)
        };
        // Sample in the frame where the film point is on +y, then rotate back.
        let (qx, qy) = (b[0] + u.x * (b[1] - b[0]), b[2] + u.y * (b[3] - b[2]));
        let q = DVec2::new(qx * c + qy * s, -qx * s + qy * c);
        let z_in = self.input_plane_z_mm();
        let h = z_in + w.pass.plane_distance_mm();
        if !(h > 0.0) {
            return None;
        }
        let o = DVec3::new(p.x, p.y, 0.0);
        let v = DVec3::new(q.x, q.y, h) - o;
        let dist2 = v.length_squared();
        let weight = (b[1] - b[0]) * (b[3] - b[2]) * h * h / (dist2 * dist2);
        let d = v / dist2.sqrt();
        let t = z_in / d.z;
        Some(FilmRay {
            pin: o + d * t,
            d,
            weight,
        })
    }

    /// The last step of `sample_ray`: the camera ray (metres) of `fr` whose
    /// transfer through the RTF is `t` (None: blocked).
    #[inline(always)]
    fn camera_ray(&self, fr: &FilmRay, t: Option<(DVec3, DVec3)>) -> Option<CameraRay> {
        let (po, pd) = t?;
        let origin = DVec3::new(po.x, po.y, self.input_plane_z_mm() + po.z) * 1e-3;
        (fr.weight.is_finite() && origin.is_finite()).then_some(CameraRay {
            origin,
            direction: pd,
            weight: fr.weight,
        })
    }
}

impl Camera for RtfCamera {
    fn sample_ray(&self, film_m: DVec2, u: DVec2, lambda_nm: f64) -> Option<CameraRay> {
        let wi = self.rtf.wave_index(lambda_nm);
        let fr = self.film_ray(wi, film_m, u)?;
        let t = self.rtf.transfer_planned(
            &self.rtf.waves[wi],
            &self.plans[wi],
            fr.pin.x,
            fr.pin.y,
            fr.d,
        );
        self.camera_ray(&fr, t)
    }
    fn sample_rays(
        &self,
        film_m: &[DVec2],
        u: &[DVec2],
        lambda_nm: &[f64],
        out: &mut [Option<CameraRay>],
    ) {
        camera_lanes::sample_rays(self, film_m, u, lambda_nm, out);
    }
    fn is_dispersive(&self) -> bool {
        self.rtf.waves.len() > 1
            && self
                .rtf
                .waves
                .iter()
                .any(|w| w.outputs != self.rtf.waves[0].outputs || w.pass != self.rtf.waves[0].pass)
    }
    fn film_distance_m(&self) -> Option<f64> {
        Some(self.film_distance_mm * 1e-3)
    }
    fn describe(&self) -> String {
        format!(
            "ray-transfer function '{}', film distance {} mm",
            self.rtf.name, self.film_distance_mm
        )
    }
}

mod camera_lanes;
mod pupil_boxes;
#[cfg(test)]
mod tests;
