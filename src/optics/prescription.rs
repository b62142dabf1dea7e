//! Spherical-surface lens prescriptions (ISET JSON, pbrt `.dat`), paraxial
//! analysis, and the sequential film → scene ray trace used as a camera.
//!
//! File conventions (both formats, all lengths in mm): surfaces are listed
//! from the object side to the image side; `thickness` of surface i is the
//! axial distance to surface i+1 (the last one is ignored for the trace; Zemax
//! sample files store their image distance there); `ior` is the index of the
//! medium *after* surface i (towards the film; 0 means air); `radius` uses the
//! optics sign convention (positive: centre of curvature on the image side),
//! 0 is flat. A surface with ior 0 or radius 0 is the aperture stop (a flat
//! clipping disk; it refracts only if the media on its two sides differ).
//! pbrt `.dat` rows are `radius thickness ior aperture_diameter` (the
//! diameter is halved here); the first lone number is the nominal focal length.
//! Per-wavelength indices: in JSON, `ior` may be an array matched to a
//! top-level `wave` (or `wavelength_nm`) array in nm; interpolated linearly.
//!
//! The trace is sequential, as in lens-design programs: each surface is
//! intersected in file order on the hemisphere that holds its vertex, even
//! when that point lies behind the previous one (zero spacing between a
//! stop and a lens vertex); rays are blocked by semi-apertures, misses and TIR.
//!
//! Trace frame ("lens frame", mm): z along the axis towards the scene, the
//! rear vertex (last surface) at z = 0, the film at z = −D (D = film distance,
//! film to rear vertex). Camera space (metres) puts the film centre at the
//! origin: z_cam = (z_lens + D)·1e-3. The physical film point is −film_m.
//!
//! Pupil sampling: for 64 film-radius buckets the axis-aligned box, on the
//! plane of the rear vertex, that holds every ray reaching the scene is found
//! by tracing a 64×33 grid of rays (half plane, by symmetry) from 4 film
//! points spread across the bucket, then grown by two grid cells (conservative: no ray that could pass is outside
//! it). A film point at angle φ samples its bucket's box (computed on +x)
//! rotated by φ, uniformly, pdf = 1/area. Blocked rays are zero-valued
//! samples, so the estimator is unbiased for every film point and a flat field
//! has no rings at bucket edges. Weight = area·D²/dist⁴ (projected solid
//! angle, both planes perpendicular to the axis), so E = E[weight·L].

// `!(x > 0.0)` is used on purpose: it also rejects NaN.
#![allow(clippy::neg_cmp_op_on_partial_ord)]

use super::{Camera, CameraRay};
use crate::{Error, Result};
use glam::{DVec2, DVec3};
use rayon::prelude::*;
use serde_json::Value;
use std::path::Path;

/// Refractive index of one medium, constant or tabulated against wavelength.
#[derive(Clone, Debug, PartialEq)]
pub enum Ior {
    Constant(f64),
    Table {
        wavelengths_nm: Vec<f64>,
        ior: Vec<f64>,
    },
}

impl Ior {
    /// Index at `lambda_nm` (linear interpolation, clamped at the table ends).
    pub fn at(&self, lambda_nm: f64) -> f64 {
        match self {
            Ior::Constant(n) => *n,
            Ior::Table {
                wavelengths_nm: w,
                ior,
            } => {
                if lambda_nm <= w[0] {
                    return ior[0];
                }
                for k in 1..w.len() {
                    if lambda_nm <= w[k] {
                        let t = (lambda_nm - w[k - 1]) / (w[k] - w[k - 1]);
                        return ior[k - 1] + t * (ior[k] - ior[k - 1]);
                    }
                }
                *ior.last().unwrap()
            }
        }
    }
    fn varies(&self) -> bool {
        match self {
            Ior::Constant(_) => false,
            Ior::Table { ior, .. } => ior.iter().any(|&n| (n - ior[0]).abs() > 1e-12),
        }
    }
}

/// One refracting surface or the aperture stop.
#[derive(Clone, Debug, PartialEq)]
pub struct Surface {
    /// Optics sign convention; 0 = flat.
    pub radius_mm: f64,
    /// Axial distance to the next surface.
    pub thickness_mm: f64,
    /// Medium after this surface (towards the film); 0 in the file becomes 1.
    pub ior: Ior,
    pub semi_aperture_mm: f64,
    pub is_stop: bool,
}

/// A lens prescription.
#[derive(Clone, Debug, PartialEq)]
pub struct Prescription {
    pub name: String,
    pub surfaces: Vec<Surface>,
}

/// Why a traced ray did not reach the scene.
#[derive(Clone, Copy, Debug, PartialEq, Eq)]
pub enum Blocked {
    /// Missed a surface or hit it outside its semi-aperture (incl. the stop).
    Aperture(usize),
    /// Total internal reflection at surface i.
    Tir(usize),
    /// Ray does not travel towards the scene.
    Backwards,
}

/// Paraxial first-order properties at one wavelength (mm).
#[derive(Clone, Copy, Debug, PartialEq)]
pub struct Paraxial {
    pub effective_focal_length_mm: f64,
    /// Rear vertex to paraxial focus of an object at infinity.
    pub back_focal_distance_mm: f64,
    pub entrance_pupil_radius_mm: f64,
    pub f_number: f64,
    /// Index of the surface that limits the axial beam.
    pub stop_index: usize,
    /// Exit pupil position from the rear vertex, positive towards the film.
    pub exit_pupil_from_rear_mm: f64,
    pub exit_pupil_radius_mm: f64,
}

fn num(v: &Value, key: &str, file: &Path, ctx: &str) -> Result<f64> {
    match v.get(key) {
        Some(Value::Number(n)) => n
            .as_f64()
            .filter(|x| x.is_finite())
            .ok_or_else(|| bad(file, &format!("{ctx}: '{key}' is not finite"))),
        Some(_) => Err(bad(file, &format!("{ctx}: '{key}' must be a number"))),
        None => Err(bad(file, &format!("{ctx}: missing '{key}'"))),
    }
}

fn bad(file: &Path, msg: &str) -> Error {
    Error::Invalid(format!("{}: {msg}", file.display()))
}

impl Prescription {
    /// Load an ISET JSON or pbrt `.dat` prescription (by extension).
    pub fn load(path: &Path) -> Result<Self> {
        let text = std::fs::read_to_string(path).map_err(|e| Error::Io {
            path: path.to_path_buf(),
            message: e.to_string(),
        })?;
        if path
            .extension()
            .and_then(|e| e.to_str())
            .is_some_and(|e| e.eq_ignore_ascii_case("dat"))
        {
            Self::from_dat(&text, path)
        } else {
            Self::from_json(&text, path)
        }
    }

    /// Parse ISET lens JSON.
    pub fn from_json(text: &str, file: &Path) -> Result<Self> {
        let v: Value = crate::diag::parse_json(file, text)?;
        Self::from_value(&v, file)
    }

    /// Build from an already-parsed ISET JSON value.
    pub fn from_value(v: &Value, file: &Path) -> Result<Self> {
        let surfaces_v = v
            .get("surfaces")
            .and_then(|s| s.as_array())
            .ok_or_else(|| bad(file, "expected a 'surfaces' array (ISET lens JSON)"))?;
        let waves: Option<Vec<f64>> = v
            .get("wave")
            .or_else(|| v.get("wavelength_nm"))
            .and_then(|w| w.as_array())
            .map(|a| a.iter().filter_map(|x| x.as_f64()).collect());
        let mut surfaces = Vec::new();
        for (i, s) in surfaces_v.iter().enumerate() {
            let ctx = format!("surface {i}");
            for key in ["aspheric_coefficients", "conic_constant"] {
                if let Some(a) = s.get(key) {
                    let nonzero = match a {
                        Value::Array(a) => a.iter().any(|x| x.as_f64().is_some_and(|x| x != 0.0)),
                        Value::Number(n) => n.as_f64().is_some_and(|x| x != 0.0),
                        _ => false,
                    };
                    if nonzero {
                        return Err(Error::NotSupported(format!(
                            "{}: {ctx}: aspheric surfaces ('{key}')",
                            file.display()
                        )));
                    }
                }
            }
            let radius_mm = num(s, "radius", file, &ctx)?;
            let thickness_mm = num(s, "thickness", file, &ctx)?;
            let semi_aperture_mm = num(s, "semi_aperture", file, &ctx)?;
            let (ior, raw0) = match s.get("ior") {
                Some(Value::Number(n)) => {
                    let n = n.as_f64().unwrap_or(f64::NAN);
                    (Ior::Constant(if n == 0.0 { 1.0 } else { n }), n == 0.0)
                }
                Some(Value::Array(a)) => {
                    let vals: Vec<f64> = a.iter().filter_map(|x| x.as_f64()).collect();
                    let w = waves.as_ref().ok_or_else(|| {
                        bad(
                            file,
                            &format!("{ctx}: 'ior' is an array but the file has no 'wave' array"),
                        )
                    })?;
                    if vals.len() != w.len() || vals.len() != a.len() {
                        return Err(bad(
                            file,
                            &format!(
                                "{ctx}: 'ior' has {} values, 'wave' has {}",
                                a.len(),
                                w.len()
                            ),
                        ));
                    }
                    if w.windows(2).any(|p| p[1] <= p[0]) {
                        return Err(bad(file, "'wave' must increase"));
                    }
                    let zero = vals.iter().all(|&x| x == 0.0);
                    let vals = vals
                        .into_iter()
                        .map(|x| if x == 0.0 { 1.0 } else { x })
                        .collect();
                    (
                        Ior::Table {
                            wavelengths_nm: w.clone(),
                            ior: vals,
                        },
                        zero,
                    )
                }
                _ => return Err(bad(file, &format!("{ctx}: missing numeric 'ior'"))),
            };
            surfaces.push(Surface {
                radius_mm,
                thickness_mm,
                ior,
                semi_aperture_mm,
                is_stop: raw0 || radius_mm == 0.0,
            });
        }
        let name = v
            .get("name")
            .and_then(|n| n.as_str())
            .unwrap_or("")
            .trim()
            .to_string();
        let p = Self { name, surfaces };
        p.validate(file)?;
        Ok(p)
    }

    /// Parse a pbrt-v3 realistic-camera `.dat` file.
    pub fn from_dat(text: &str, file: &Path) -> Result<Self> {
        let mut surfaces = Vec::new();
        let mut seen_focal = false;
        for (ln, line) in text.lines().enumerate() {
            let t = line.split('#').next().unwrap_or("").trim();
            if t.is_empty() {
                continue;
            }
            let vals: std::result::Result<Vec<f64>, _> =
                t.split_whitespace().map(|x| x.parse::<f64>()).collect();
            let vals = vals.map_err(|_| {
                Error::from(crate::diag::Located::at_offset(
                    file,
                    text,
                    text.lines().take(ln).map(|l| l.len() + 1).sum(),
                    line.len().max(1),
                    "expected numbers: radius thickness ior aperture-diameter (mm)",
                ))
            })?;
            match vals.len() {
                1 if !seen_focal && surfaces.is_empty() => seen_focal = true,
                4 => {
                    let [radius_mm, thickness_mm, n, diameter] =
                        [vals[0], vals[1], vals[2], vals[3]];
                    surfaces.push(Surface {
                        radius_mm,
                        thickness_mm,
                        ior: Ior::Constant(if n == 0.0 { 1.0 } else { n }),
                        semi_aperture_mm: diameter / 2.0,
                        is_stop: n == 0.0 || radius_mm == 0.0,
                    });
                }
                k => {
                    return Err(crate::diag::Located::at_offset(
                        file,
                        text,
                        text.lines().take(ln).map(|l| l.len() + 1).sum(),
                        line.len().max(1),
                        format!(
                            "expected 4 numbers (radius thickness ior aperture-diameter), found {k}"
                        ),
                    )
                    .into());
                }
            }
        }
        let name = file
            .file_stem()
            .and_then(|s| s.to_str())
            .unwrap_or("")
            .to_string();
        let p = Self { name, surfaces };
        p.validate(file)?;
        Ok(p)
    }

    fn validate(&self, file: &Path) -> Result<()> {
        if self.surfaces.is_empty() {
            return Err(bad(file, "prescription has no surfaces"));
        }
        for (i, s) in self.surfaces.iter().enumerate() {
            if !(s.semi_aperture_mm > 0.0) {
                return Err(bad(
                    file,
                    &format!("surface {i}: semi-aperture must be > 0 mm"),
                ));
            }
            if s.thickness_mm < 0.0 && i + 1 < self.surfaces.len() {
                return Err(bad(
                    file,
                    &format!("surface {i}: negative thickness {} mm", s.thickness_mm),
                ));
            }
            if s.radius_mm != 0.0 && s.radius_mm.abs() < s.semi_aperture_mm * (1.0 - 1e-9) {
                return Err(bad(
                    file,
                    &format!(
                        "surface {i}: |radius| {} mm is smaller than the semi-aperture {} mm",
                        s.radius_mm, s.semi_aperture_mm
                    ),
                ));
            }
            let n0 = s.ior.at(550.0);
            if !(1.0 - 1e-9..5.0).contains(&n0) {
                return Err(bad(file, &format!("surface {i}: implausible ior {n0}")));
            }
        }
        Ok(())
    }

    /// True when some index depends on wavelength.
    pub fn is_dispersive(&self) -> bool {
        self.surfaces.iter().any(|s| s.ior.varies())
    }

    /// Medium on the object side of surface i.
    fn n_before(&self, i: usize, lambda_nm: f64) -> f64 {
        if i == 0 {
            1.0
        } else {
            self.surfaces[i - 1].ior.at(lambda_nm)
        }
    }

    /// Axial position of each vertex in the lens frame (rear vertex at 0).
    pub fn vertex_z_mm(&self) -> Vec<f64> {
        let n = self.surfaces.len();
        let mut z = vec![0.0; n];
        for i in (0..n.saturating_sub(1)).rev() {
            z[i] = z[i + 1] + self.surfaces[i].thickness_mm;
        }
        z
    }

    /// Front-to-rear vertex distance.
    pub fn total_track_mm(&self) -> f64 {
        self.vertex_z_mm()[0]
    }

    /// Paraxial trace (optics frame: light left→right, object side first).
    /// Starts at the vertex plane of surface `from` *before* refraction with
    /// height y and slope u in the medium before it; returns per-surface heights
    /// and the final (y, u) at the last vertex plane after refraction.
    fn paraxial_trace(
        &self,
        from: usize,
        mut y: f64,
        mut u: f64,
        lambda_nm: f64,
    ) -> (Vec<f64>, f64, f64) {
        let mut heights = vec![0.0; self.surfaces.len()];
        for (i, s) in self.surfaces.iter().enumerate().skip(from) {
            if i > from {
                y += self.surfaces[i - 1].thickness_mm * u;
            }
            heights[i] = y;
            let (n, n2) = (self.n_before(i, lambda_nm), s.ior.at(lambda_nm));
            let c = if s.radius_mm == 0.0 {
                0.0
            } else {
                1.0 / s.radius_mm
            };
            u = (n * u - y * (n2 - n) * c) / n2;
        }
        (heights, y, u)
    }

    /// First-order properties.
    pub fn paraxial(&self, lambda_nm: f64) -> Result<Paraxial> {
        let (h, y, u) = self.paraxial_trace(0, 1.0, 0.0, lambda_nm);
        if u >= 0.0 || !u.is_finite() {
            return Err(Error::Invalid(format!(
                "lens '{}' is not converging (paraxial slope {u})",
                self.name
            )));
        }
        let efl = -1.0 / u;
        let bfd = -y / u;
        let (mut stop, mut ep) = (0, f64::INFINITY);
        for (i, s) in self.surfaces.iter().enumerate() {
            let r = s.semi_aperture_mm / h[i].abs().max(1e-300);
            if r < ep {
                ep = r;
                stop = i;
            }
        }
        // Exit pupil: image of the stop edge through the surfaces behind it.
        let n = self.surfaces.len();
        let a = self.surfaces[stop].semi_aperture_mm;
        let (xp_z, xp_r) = if stop + 1 == n {
            (0.0, a)
        } else {
            // Rays leave the stop edge (height a) with slope u0 in the medium
            // behind the stop; the image of that point is where they meet again.
            let run = |u0: f64| {
                let (_, y, u) = self.paraxial_trace(
                    stop + 1,
                    a + self.surfaces[stop].thickness_mm * u0,
                    u0,
                    lambda_nm,
                );
                (y, u)
            };
            let (ya, ua) = run(0.0);
            let (yb, ub) = run(0.01);
            let z = (yb - ya) / (ua - ub);
            (z, (ya + ua * z).abs())
        };
        Ok(Paraxial {
            effective_focal_length_mm: efl,
            back_focal_distance_mm: bfd,
            entrance_pupil_radius_mm: ep,
            f_number: efl / (2.0 * ep),
            stop_index: stop,
            exit_pupil_from_rear_mm: xp_z,
            exit_pupil_radius_mm: xp_r,
        })
    }

    /// Paraxial film distance (film to rear vertex) that focuses an axial
    /// object `object_from_front_mm` in front of the front vertex (∞ allowed).
    pub fn image_distance_mm(&self, object_from_front_mm: f64, lambda_nm: f64) -> Result<f64> {
        if object_from_front_mm.is_infinite() {
            return Ok(self.paraxial(lambda_nm)?.back_focal_distance_mm);
        }
        let u0 = 1e-3;
        let (_, y, u) = self.paraxial_trace(0, object_from_front_mm * u0, u0, lambda_nm);
        let d = -y / u;
        if !(u < 0.0 && d > 0.0 && d.is_finite()) {
            return Err(Error::Invalid(format!(
                "lens '{}': an object {object_from_front_mm} mm away has no real image",
                self.name
            )));
        }
        Ok(d)
    }

    /// Film distance focusing an object at `focus_from_film_mm` from the film.
    pub fn film_distance_for_focus_mm(
        &self,
        focus_from_film_mm: f64,
        lambda_nm: f64,
    ) -> Result<f64> {
        let t = self.total_track_mm();
        let mut d = self.image_distance_mm(f64::INFINITY, lambda_nm)?;
        if focus_from_film_mm.is_infinite() {
            return Ok(d);
        }
        for _ in 0..50 {
            let obj = focus_from_film_mm - t - d;
            if obj <= 0.0 {
                return Err(Error::Invalid(format!(
                    "lens '{}': focus distance {focus_from_film_mm} mm is inside the lens",
                    self.name
                )));
            }
            d = self.image_distance_mm(obj, lambda_nm)?;
        }
        Ok(d)
    }

    /// The same lens seen from the scene side: surfaces in reverse order,
    /// radii negated, each medium moved to the other side of its surface.
    /// Its lens frame is this one mirrored: z_rev = total track − z, with
    /// direction z negated, so `reversed().trace_to_scene` traces a
    /// scene-side ray back to the film. Needs air on the film side (the
    /// forward trace starts there); otherwise `Error::NotSupported`.
    pub fn reversed(&self) -> Result<Prescription> {
        let n = self.surfaces.len();
        let Some(last) = self.surfaces.last() else {
            return Err(Error::Invalid(format!(
                "lens '{}' has no surfaces",
                self.name
            )));
        };
        if last.ior.varies() || last.ior.at(550.0) != 1.0 {
            return Err(Error::NotSupported(format!(
                "lens '{}': reversing a lens whose film-side medium is not air",
                self.name
            )));
        }
        let surfaces = (0..n)
            .rev()
            .map(|k| {
                let s = &self.surfaces[k];
                let (thickness_mm, ior) = if k >= 1 {
                    let before = &self.surfaces[k - 1];
                    (before.thickness_mm, before.ior.clone())
                } else {
                    (0.0, Ior::Constant(1.0))
                };
                Surface {
                    radius_mm: -s.radius_mm,
                    thickness_mm,
                    ior,
                    semi_aperture_mm: s.semi_aperture_mm,
                    is_stop: s.is_stop,
                }
            })
            .collect();
        Ok(Prescription {
            name: format!("{} (reversed)", self.name),
            surfaces,
        })
    }

    /// Sequential trace film → scene in the lens frame (mm). `d` need not be unit.
    pub fn trace_to_scene(
        &self,
        mut o: DVec3,
        d: DVec3,
        lambda_nm: f64,
    ) -> std::result::Result<(DVec3, DVec3), Blocked> {
        let mut d = d.normalize();
        if !(d.z > 0.0) {
            return Err(Blocked::Backwards);
        }
        // Vertex of surface i, accumulated from the rear vertex (z = 0).
        let mut z_i = 0.0;
        for i in (0..self.surfaces.len()).rev() {
            let s = &self.surfaces[i];
            if i + 1 < self.surfaces.len() {
                z_i += s.thickness_mm;
            }
            let (hit, normal) = if s.radius_mm == 0.0 {
                if d.z <= 0.0 {
                    return Err(Blocked::Aperture(i));
                }
                // Sequential trace: surfaces are met in file order even when
                // one lies behind the previous (zero or negative spacing, as
                // in Zemax files with the stop at a lens vertex), so t may be < 0.
                let t = (z_i - o.z) / d.z;
                (o + d * t, DVec3::new(0.0, 0.0, -1.0))
            } else {
                let r = s.radius_mm;
                let c = DVec3::new(0.0, 0.0, z_i - r);
                let oc = o - c;
                let b = oc.dot(d);
                let cc = oc.length_squared() - r * r;
                let disc = b * b - cc;
                if disc < 0.0 {
                    return Err(Blocked::Aperture(i));
                }
                let sq = disc.sqrt();
                // Film → scene: R > 0 (centre towards the film) is met on the far
                // side of the sphere, R < 0 on the near side.
                // t < 0 is allowed (sequential trace, see the stop above).
                let t = if r > 0.0 { -b + sq } else { -b - sq };
                let p = o + d * t;
                let mut nrm = (p - c) / r.abs();
                if nrm.dot(d) > 0.0 {
                    nrm = -nrm;
                }
                (p, nrm)
            };
            if hit.x * hit.x + hit.y * hit.y > s.semi_aperture_mm * s.semi_aperture_mm {
                return Err(Blocked::Aperture(i));
            }
            let (n1, n2) = (s.ior.at(lambda_nm), self.n_before(i, lambda_nm));
            if n1 != n2 {
                let eta = n1 / n2;
                let cosi = -normal.dot(d);
                let sin2t = eta * eta * (1.0 - cosi * cosi).max(0.0);
                if sin2t >= 1.0 {
                    return Err(Blocked::Tir(i));
                }
                let cost = (1.0 - sin2t).sqrt();
                d = (d * eta + normal * (eta * cosi - cost)).normalize();
            }
            o = hit;
        }
        if !(d.z > 0.0) || !d.is_finite() {
            return Err(Blocked::Backwards);
        }
        Ok((o, d))
    }
}

const N_BUCKETS: usize = 64;

/// A prescription used as a camera at a fixed film distance.
#[derive(Clone, Debug)]
pub struct PrescriptionCamera {
    pub lens: Prescription,
    pub film_distance_mm: f64,
    /// Film radius beyond which no ray passes (end of the last bucket).
    pub max_film_radius_mm: f64,
    /// Per bucket: pupil box on the rear-vertex plane for film points on +x,
    /// as [x0, x1, y0, y1] (mm); None when nothing passes.
    bounds: Vec<Option<[f64; 4]>>,
    wavelength_nm: f64,
}

impl PrescriptionCamera {
    /// Build with the film `film_distance_mm` behind the rear vertex; pupil
    /// bounds are computed at `design_wavelength_nm` (dispersive lenses: the
    /// union over 380, 550 and 780 nm).
    pub fn new(
        lens: Prescription,
        film_distance_mm: f64,
        design_wavelength_nm: f64,
    ) -> Result<Self> {
        if !(film_distance_mm.is_finite() && film_distance_mm > 0.0) {
            return Err(Error::Invalid(format!(
                "lens '{}': film distance must be > 0 mm, got {film_distance_mm}",
                lens.name
            )));
        }
        let mut cam = Self {
            lens,
            film_distance_mm,
            max_film_radius_mm: 0.0,
            bounds: Vec::new(),
            wavelength_nm: design_wavelength_nm,
        };
        cam.compute_bounds();
        if cam.bounds.iter().all(|b| b.is_none()) {
            return Err(Error::Invalid(format!(
                "lens '{}': no ray from the film reaches the scene",
                cam.lens.name
            )));
        }
        Ok(cam)
    }

    /// Film distance from a focus distance measured from the film (camera origin).
    pub fn focused(
        lens: Prescription,
        focus_from_film_m: f64,
        design_wavelength_nm: f64,
    ) -> Result<Self> {
        let d = lens.film_distance_for_focus_mm(focus_from_film_m * 1e3, design_wavelength_nm)?;
        Self::new(lens, d, design_wavelength_nm)
    }

    fn search_extent_mm(&self) -> f64 {
        let last = self.lens.surfaces.last().unwrap();
        2.0 * last.semi_aperture_mm
    }

    /// Does any ray from film radius r (on +x) pass, on a coarse grid?
    fn box_for(&self, r0: f64, r1: f64, n_film: usize, grid: usize) -> Option<[f64; 4]> {
        let ext = self.search_extent_mm();
        let cell = 2.0 * ext / grid as f64;
        let mut b = [
            f64::INFINITY,
            f64::NEG_INFINITY,
            f64::INFINITY,
            f64::NEG_INFINITY,
        ];
        let mut any = false;
        // Dispersive lenses: the union of the pupils at the ends and the middle
        // of the visible range.
        let waves: &[f64] = if self.lens.is_dispersive() {
            &[380.0, 550.0, 780.0]
        } else {
            &[self.wavelength_nm]
        };
        for k in 0..n_film {
            let r = if n_film == 1 {
                r0
            } else {
                r0 + (r1 - r0) * k as f64 / (n_film - 1) as f64
            };
            let o = DVec3::new(r, 0.0, -self.film_distance_mm);
            for i in 0..grid {
                let x = -ext + (i as f64 + 0.5) * cell;
                for j in 0..grid / 2 + 1 {
                    let y = (j as f64) * cell;
                    let target = DVec3::new(x, y, 0.0);
                    if waves
                        .iter()
                        .any(|&wl| self.lens.trace_to_scene(o, target - o, wl).is_ok())
                    {
                        any = true;
                        b[0] = b[0].min(x);
                        b[1] = b[1].max(x);
                        b[3] = b[3].max(y);
                    }
                }
            }
        }
        if !any {
            return None;
        }
        // Symmetric in y about the meridional plane.
        b[2] = -b[3];
        let m = 2.0 * cell;
        Some([
            (b[0] - m).max(-ext),
            (b[1] + m).min(ext),
            (b[2] - m).max(-ext),
            (b[3] + m).min(ext),
        ])
    }

    fn compute_bounds(&mut self) {
        // Find the film radius where vignetting becomes complete.
        let f = self
            .lens
            .paraxial(self.wavelength_nm)
            .map(|p| p.effective_focal_length_mm.abs())
            .unwrap_or(self.film_distance_mm);
        let step = 0.02 * f;
        let mut r_max = step;
        let mut misses = 0;
        let mut r = 0.0;
        while r < 6.0 * f {
            if self.box_for(r, r, 1, 48).is_some() {
                r_max = r + step;
                misses = 0;
            } else {
                misses += 1;
                if misses > 5 {
                    break;
                }
            }
            r += step;
        }
        self.max_film_radius_mm = r_max;
        self.bounds = (0..N_BUCKETS)
            .into_par_iter()
            .map(|k| {
                let r0 = r_max * k as f64 / N_BUCKETS as f64;
                let r1 = r_max * (k + 1) as f64 / N_BUCKETS as f64;
                self.box_for(r0, r1, 4, 64)
            })
            .collect();
    }

    /// Pupil box of the bucket holding film radius `r_mm` (for +x film points).
    pub fn pupil_bounds_mm(&self, r_mm: f64) -> Option<[f64; 4]> {
        let k = (r_mm / self.max_film_radius_mm * N_BUCKETS as f64).floor();
        if !(k >= 0.0) || k as usize >= N_BUCKETS {
            return None;
        }
        self.bounds[k as usize]
    }
}

impl Camera for PrescriptionCamera {
    fn sample_ray(&self, film_m: DVec2, u: DVec2, lambda_nm: f64) -> Option<CameraRay> {
        let p = -film_m * 1e3; // physical film point, mm
        let r = p.length();
        let b = self.pupil_bounds_mm(r)?;
        let (cphi, sphi) = if r > 0.0 {
            (p.x / r, p.y / r)
        } else {
            (1.0, 0.0)
        };
        let q = DVec2::new(b[0] + u.x * (b[1] - b[0]), b[2] + u.y * (b[3] - b[2]));
        let q = DVec2::new(cphi * q.x - sphi * q.y, sphi * q.x + cphi * q.y);
        let area = (b[1] - b[0]) * (b[3] - b[2]);
        let o = DVec3::new(p.x, p.y, -self.film_distance_mm);
        let dir = DVec3::new(q.x, q.y, 0.0) - o;
        let dist2 = dir.length_squared();
        let weight = area * self.film_distance_mm * self.film_distance_mm / (dist2 * dist2);
        let (po, pd) = self.lens.trace_to_scene(o, dir, lambda_nm).ok()?;
        let origin = DVec3::new(po.x, po.y, po.z + self.film_distance_mm) * 1e-3;
        (weight.is_finite() && origin.is_finite()).then_some(CameraRay {
            origin,
            direction: pd,
            weight,
        })
    }
    fn is_dispersive(&self) -> bool {
        self.lens.is_dispersive()
    }
    fn film_distance_m(&self) -> Option<f64> {
        Some(self.film_distance_mm * 1e-3)
    }
    fn describe(&self) -> String {
        format!(
            "lens prescription '{}', film distance {} mm",
            self.lens.name, self.film_distance_mm
        )
    }
}
