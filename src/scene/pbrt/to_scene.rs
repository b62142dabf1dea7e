//! Mapping pbrt shapes, materials, lights, camera and film onto camsim's scene model.
//!
//! - Shapes become world-space geometry: `trianglemesh`, `plymesh`, `bilinearmesh`
//!   (each patch split into two triangles), `loopsubdiv` (one level of Loop
//!   subdivision, without the limit-surface projection), `sphere` and `disk` (kept
//!   analytic; tessellated inside object definitions since instances reference
//!   meshes, and a `ReverseOrientation` sphere, which faces inwards, is a 96×48
//!   mesh), `cylinder` (a mesh of 96 segments per turn, zmin/zmax/phimax honoured).
//!   Triangles are wound so that their geometric normal is pbrt's: facing
//!   the shading normals when `N` is given (negated by `ReverseOrientation`, as
//!   pbrt-v4's TriangleMesh does), else flipped by `ReverseOrientation` xor a
//!   handedness-swapping transform.
//! - Materials: `diffuse`/`matte` → Diffuse; `coateddiffuse` → DiffuseSpecular with
//!   the coating's normal-incidence Fresnel reflectance ((η−1)/(η+1))² as the specular
//!   term; `uber`/`plastic` (pbrt-v3) → DiffuseSpecular(Kd, Ks); `conductor`/`metal` →
//!   Conductor (or, with `reflectance`, η = 1 and k = 2√(R/(1−R)), which reproduces R at
//!   normal incidence); `dielectric`/`glass` → Dielectric; `mirror` → Mirror;
//!   `interface` → an index-matched Dielectric (η = 1, light passes unchanged).
//!   Roughness is converted to the microfacet α: pbrt-v4 `sqrt(r)`, pbrt-v3 its
//!   polynomial in ln r, when `remaproughness` is true.
//! - Lights in pbrt-v4 files follow pbrt-v4's photometric normalisation: an emission
//!   spectrum is divided by ∫ȳ(λ)S(λ)dλ (for `rgb`, of the colour space's white only)
//!   so that a light of `scale` 1 has ∫ȳL dλ = 1, pbrt's "1 nit"; camsim keeps that
//!   number in W/(sr·m²·nm). `power` (point, spot, area) and `illuminance` (distant,
//!   infinite) rescale as pbrt-v4 does. In pbrt-v3 files (decided by the syntax,
//!   [`super::dialect`]) the spectrum × `scale` is taken literally, as pbrt-v3 does.
//!   Absolute radiometry of the paper's box comes from `apply_paper_spectra`.
//! - Camera: `perspective` → Pinhole (lens radius 0) or ThinLens (focal length from the
//!   film's physical size: `diagonal` mm, default 35, and `fov` across the shorter
//!   side; N = f/(2·lensradius)); `realistic` → LensFile (lens file path resolved
//!   against the scene directory, aperture diameter mm → m, focus distance m).
//!   The pinhole f-number is √π/2 ≈ 0.886, for which E = πL/(4N²) equals L on axis,
//!   i.e. the pixel value equals the radiance as in pbrt's film.

use super::lexer::Span;
use super::params::{Ctx, PResult, ParamList, ParamType, SpanError, SpectrumKind, luminance_y};
use crate::scene::{
    CameraModel, CameraSpec, Disk, Emission, FilmSpec, Light, Material, MaterialId, Mesh, ObjectId,
    Sphere,
};
use crate::spectrum::{Extrapolation, Spectrum};
use glam::{DMat3, DMat4, DVec3, Vec2, Vec3};
use std::collections::HashMap;
use std::f64::consts::PI;

/// Textures by name: a constant value when the texture is `constant`, else None
/// (a warning was given and materials fall back to their default).
#[derive(Debug, Default)]
pub struct Textures {
    pub map: HashMap<String, (Option<Spectrum>, Span)>,
}

#[derive(Clone, Debug)]
pub struct AreaLightSpec {
    /// Photometrically normalised radiance × scale (before `power`).
    pub radiance: Spectrum,
    pub two_sided: bool,
    pub power: Option<f64>,
    pub span: Span,
}

#[derive(Clone, Debug)]
pub enum CameraParams {
    Perspective {
        fov_deg: f64,
        lens_radius: f64,
        focal_distance: f64,
    },
    Realistic {
        lens_file: std::path::PathBuf,
        aperture_diameter_mm: f64,
        focus_distance_m: f64,
    },
}

#[derive(Clone, Debug)]
pub struct FilmParams {
    pub spec: FilmSpec,
    pub diagonal_mm: f64,
    /// A `spectral` film's buckets when the file sets `nbuckets`, `lambdamin`
    /// or `lambdamax` (pbrt-v4 defaults 16, 360, 830 fill the others): one
    /// band per bucket, named by its centre as pbrt-v4 names its channels
    /// (`camsim render` averages sub-bands over each bucket).
    pub spectral_grid: Option<crate::spectrum::WavelengthGrid>,
}

impl Default for FilmParams {
    fn default() -> Self {
        // pbrt-v4 defaults: 1280×720, 35 mm diagonal.
        let (w, h, diag) = (1280u32, 720u32, 35.0);
        Self {
            spec: FilmSpec {
                width_px: w,
                height_px: h,
                pixel_pitch_m: diag * 1e-3 / (w as f64).hypot(h as f64),
                crop_window: None,
            },
            diagonal_mm: diag,
            spectral_grid: None,
        }
    }
}

pub fn camera_params(ty: &str, tspan: Span, p: &ParamList, ctx: &mut Ctx) -> PResult<CameraParams> {
    match ty {
        "perspective" | "orthographic" | "spherical" => {
            if ty != "perspective" {
                ctx.warn(
                    tspan,
                    format!("camera '{ty}' not supported; a perspective camera is used"),
                )?;
            }
            let fov = p.float("fov", 90.0)?;
            if !(fov > 0.0 && fov < 180.0) {
                return Err(SpanError::new(
                    p.span_of("fov").unwrap_or(tspan),
                    format!("fov must be in (0, 180) degrees, got {fov}"),
                ));
            }
            let lr = p.float("lensradius", 0.0)?;
            let fd = p.float("focaldistance", 1e6)?;
            if lr < 0.0 || fd <= 0.0 {
                return Err(SpanError::new(
                    tspan,
                    "lensradius must be ≥ 0 and focaldistance > 0",
                ));
            }
            for n in [
                "frameaspectratio",
                "screenwindow",
                "shutteropen",
                "shutterclose",
            ] {
                if let Some(s) = p.span_of(n) {
                    p.find(n);
                    ctx.warn(s, format!("camera parameter '{n}' is ignored"))?;
                }
            }
            Ok(CameraParams::Perspective {
                fov_deg: fov,
                lens_radius: lr,
                focal_distance: fd,
            })
        }
        "realistic" => {
            let Some(f) = p.string("lensfile")? else {
                return Err(SpanError::new(
                    tspan,
                    "realistic camera needs \"string lensfile\"",
                ));
            };
            let ad = p.float("aperturediameter", 1.0)?;
            let fd = p.float("focusdistance", 10.0)?;
            if ad <= 0.0 || fd <= 0.0 {
                return Err(SpanError::new(
                    tspan,
                    "aperturediameter and focusdistance must be > 0",
                ));
            }
            for n in ["aperture", "shutteropen", "shutterclose"] {
                if let Some(s) = p.span_of(n) {
                    p.find(n);
                    ctx.warn(s, format!("camera parameter '{n}' is ignored"))?;
                }
            }
            Ok(CameraParams::Realistic {
                lens_file: ctx.resolve_path(&f),
                aperture_diameter_mm: ad,
                focus_distance_m: fd,
            })
        }
        _ => Err(SpanError::new(
            tspan,
            format!("unknown camera '{ty}' (perspective, orthographic, realistic, spherical)"),
        )),
    }
}

pub fn camera(
    c: &CameraParams,
    to_world: DMat4,
    film: &FilmParams,
    _span: Span,
    _ctx: &mut Ctx,
) -> PResult<CameraSpec> {
    let model = match c {
        CameraParams::Perspective {
            fov_deg,
            lens_radius,
            focal_distance,
        } => {
            if *lens_radius > 0.0 {
                let short_m =
                    film.spec.width_px.min(film.spec.height_px) as f64 * film.spec.pixel_pitch_m;
                let f = 0.5 * short_m / (0.5 * fov_deg.to_radians()).tan();
                CameraModel::ThinLens {
                    focal_length_m: f,
                    f_number: f / (2.0 * lens_radius),
                    focus_distance_m: *focal_distance,
                }
            } else {
                CameraModel::Pinhole {
                    fov_deg: *fov_deg,
                    f_number: PI.sqrt() / 2.0,
                    cos4: true,
                }
            }
        }
        CameraParams::Realistic {
            lens_file,
            aperture_diameter_mm,
            focus_distance_m,
        } => CameraModel::LensFile {
            path: lens_file.clone(),
            film_distance_m: None,
            focus_distance_m: Some(*focus_distance_m),
            aperture_diameter_m: Some(aperture_diameter_mm * 1e-3),
            rtf_fit: None,
        },
    };
    Ok(CameraSpec { to_world, model })
}

pub fn film_params(ty: &str, tspan: Span, p: &ParamList, ctx: &mut Ctx) -> PResult<FilmParams> {
    match ty {
        "rgb" | "gbuffer" | "spectral" => {}
        "image" => ctx.warn(tspan, "pbrt-v3 film 'image' read as pbrt-v4 'rgb'")?,
        _ => {
            return Err(SpanError::new(
                tspan,
                format!("unknown film '{ty}' (rgb, gbuffer, spectral)"),
            ));
        }
    }
    let w = p.int("xresolution", 1280)?;
    let h = p.int("yresolution", 720)?;
    if !(1..=1_000_000).contains(&w) || !(1..=1_000_000).contains(&h) {
        return Err(SpanError::new(
            tspan,
            format!("film resolution must be 1..1000000 pixels, got {w}×{h}"),
        ));
    }
    let diag = p.float("diagonal", 35.0)?;
    if !(diag > 0.0) {
        return Err(SpanError::new(
            p.span_of("diagonal").unwrap_or(tspan),
            "film diagonal must be > 0 mm",
        ));
    }
    let crop = match p.floats("cropwindow")? {
        None => None,
        Some(c) if c.len() == 4 => {
            let ok = c.iter().all(|v| (0.0..=1.0).contains(v)) && c[0] < c[1] && c[2] < c[3];
            if !ok {
                return Err(SpanError::new(
                    p.span_of("cropwindow").unwrap(),
                    "cropwindow must be [x0 x1 y0 y1] with 0 ≤ x0 < x1 ≤ 1, 0 ≤ y0 < y1 ≤ 1",
                ));
            }
            Some([c[0], c[1], c[2], c[3]])
        }
        Some(_) => {
            return Err(SpanError::new(
                p.span_of("cropwindow").unwrap(),
                "cropwindow needs 4 values",
            ));
        }
    };
    // Output-only settings (file name, sensor response, white balance) do not affect the scene.
    for n in [
        "filename",
        "iso",
        "whitebalance",
        "sensor",
        "savefp16",
        "maxcomponentvalue",
        "exposuretime",
        "writefp16",
    ] {
        p.find(n);
    }
    if let Some(s) = p.span_of("pixelbounds") {
        p.find("pixelbounds");
        ctx.warn(s, "film 'pixelbounds' ignored (use cropwindow)")?;
    }
    let spec = FilmSpec {
        width_px: w as u32,
        height_px: h as u32,
        pixel_pitch_m: diag * 1e-3 / (w as f64).hypot(h as f64),
        crop_window: crop,
    };
    let spectral_grid = if ty == "spectral"
        && ["nbuckets", "lambdamin", "lambdamax"]
            .iter()
            .any(|n| p.has(n))
    {
        Some(spectral_grid(p, tspan)?)
    } else {
        None
    };
    Ok(FilmParams {
        spec,
        diagonal_mm: diag,
        spectral_grid,
    })
}

/// pbrt-v4's spectral film buckets: `nbuckets` equal buckets over
/// [`lambdamin`, `lambdamax`], as a grid of their centres.
fn spectral_grid(p: &ParamList, tspan: Span) -> PResult<crate::spectrum::WavelengthGrid> {
    let n = p.int("nbuckets", 16)?;
    let lo = p.float("lambdamin", 360.0)?;
    let hi = p.float("lambdamax", 830.0)?;
    if !(1..=10_000).contains(&n) {
        return Err(SpanError::new(
            p.span_of("nbuckets").unwrap_or(tspan),
            format!("spectral film nbuckets must be 1..10000, got {n}"),
        ));
    }
    if !(lo > 0.0 && hi.is_finite() && lo < hi) {
        let at = p
            .span_of("lambdamin")
            .or(p.span_of("lambdamax"))
            .unwrap_or(tspan);
        return Err(SpanError::new(
            at,
            format!(
                "spectral film needs 0 < lambdamin < lambdamax (nm), got lambdamin {lo}, lambdamax {hi}"
            ),
        ));
    }
    let step = (hi - lo) / n as f64;
    Ok(crate::spectrum::WavelengthGrid {
        start_nm: lo + 0.5 * step,
        step_nm: step,
        count: n as usize,
    })
}

#[allow(clippy::too_many_arguments)]
pub fn texture(
    tex: &mut Textures,
    name: String,
    kind: &str,
    kspan: Span,
    class: &str,
    cspan: Span,
    p: &ParamList,
    ctx: &mut Ctx,
) -> PResult<()> {
    if kind != "spectrum" && kind != "float" && kind != "color" {
        return Err(SpanError::new(
            kspan,
            format!("texture type must be \"spectrum\" or \"float\", found \"{kind}\""),
        ));
    }
    let value = if class == "constant" {
        if kind == "float" {
            Some(Spectrum::constant(name.clone(), p.float("value", 1.0)?))
        } else {
            p.spectrum("value", SpectrumKind::Albedo, ctx)?
                .or_else(|| Some(Spectrum::constant(name.clone(), 1.0)))
        }
    } else {
        for q in &p.params {
            q.used.set(true);
        }
        ctx.warn(cspan, format!("texture class '{class}' not supported; materials using '{name}' fall back to their default value"))?;
        None
    };
    tex.map.insert(name, (value, cspan));
    Ok(())
}

fn spectrum_or_texture(
    p: &ParamList,
    names: &[&str],
    kind: SpectrumKind,
    default: f64,
    ctx: &mut Ctx,
    tex: &Textures,
) -> PResult<Spectrum> {
    for n in names {
        if let Some((t, tspan)) = p.texture_name(n) {
            return match tex.map.get(&t) {
                Some((Some(s), _)) => Ok(s.clone()),
                Some((None, _)) => {
                    Ok(Spectrum::constant(*n, default).with_extrapolation(Extrapolation::Clamp))
                }
                None => Err(SpanError::new(tspan, format!("unknown texture '{t}'"))),
            };
        }
        if p.has(n) {
            if let Some(s) = p.spectrum(n, kind, ctx)? {
                return Ok(s);
            }
            return Ok(Spectrum::constant(*n, default));
        }
    }
    Ok(Spectrum::constant(names[0], default))
}

fn roughness_alpha(
    p: &ParamList,
    default: f64,
    v3: bool,
    ctx: &mut Ctx,
    tex: &Textures,
) -> PResult<f64> {
    // A float texture for the roughness: its constant value, else the default with a warning.
    let mut default = default;
    if let Some((t, span)) = p.texture_name("roughness") {
        match tex.map.get(&t) {
            Some((Some(c), _)) => default = c.eval(550.0),
            Some((None, _)) => ctx.warn(
                span,
                format!("roughness texture '{t}' not supported; roughness {default} used"),
            )?,
            None => return Err(SpanError::new(span, format!("unknown texture '{t}'"))),
        }
    }
    let r = if p.texture_name("roughness").is_some() {
        default
    } else {
        p.float("roughness", default)?
    };
    let u = p.float("uroughness", r)?;
    let v = p.float("vroughness", r)?;
    let r = 0.5 * (u + v);
    let remap = p.bool("remaproughness", true)?;
    if !(r >= 0.0) {
        return Err(SpanError::new(
            p.span_of("roughness").unwrap_or_default(),
            "roughness must be ≥ 0",
        ));
    }
    Ok(if !remap {
        r
    } else if v3 {
        // pbrt-v3 TrowbridgeReitz RoughnessToAlpha (polynomial in ln r).
        let x = r.max(1e-3).ln();
        1.62142 + 0.819955 * x + 0.1734 * x * x + 0.0171201 * x.powi(3) + 0.000640711 * x.powi(4)
    } else {
        r.sqrt()
    })
}

fn eta_spectrum(p: &ParamList, names: &[&str], default: f64, ctx: &mut Ctx) -> PResult<Spectrum> {
    for n in names {
        if p.has(n) {
            return Ok(p
                .spectrum(n, SpectrumKind::Unbounded, ctx)?
                .unwrap_or_else(|| Spectrum::constant("eta", default)));
        }
    }
    Ok(Spectrum::constant("eta", default))
}

fn mark_used(p: &ParamList, names: &[&str]) {
    for n in names {
        p.find(n);
    }
}

pub fn material(
    ty: &str,
    tspan: Span,
    p: &ParamList,
    ctx: &mut Ctx,
    tex: &Textures,
) -> PResult<Material> {
    mark_used(p, &["type", "displacement", "normalmap"]);
    Ok(match ty {
        "diffuse" | "matte" => {
            if ty == "matte" {
                ctx.warn(tspan, "pbrt-v3 material 'matte' read as 'diffuse'")?;
                mark_used(p, &["sigma"]);
            }
            let names: &[&str] = if ty == "matte" {
                &["Kd"]
            } else {
                &["reflectance"]
            };
            Material::Diffuse {
                reflectance: spectrum_or_texture(p, names, SpectrumKind::Albedo, 0.5, ctx, tex)?,
            }
        }
        "coateddiffuse" => {
            let refl =
                spectrum_or_texture(p, &["reflectance"], SpectrumKind::Albedo, 0.5, ctx, tex)?;
            let alpha = roughness_alpha(p, 0.0, false, ctx, tex)?;
            let eta = p.float("interface.eta", p.float("eta", 1.5)?)?;
            mark_used(p, &["thickness", "albedo", "g", "maxdepth", "nsamples"]);
            let f0 = ((eta - 1.0) / (eta + 1.0)).powi(2);
            Material::DiffuseSpecular {
                diffuse: refl,
                specular: Spectrum::constant("coating-f0", f0),
                roughness: alpha,
            }
        }
        "uber" | "plastic" | "substrate" => {
            ctx.warn(tspan, format!("pbrt-v3 material '{ty}' read as diffuse + specular (Kd, Ks; other lobes ignored)"))?;
            let kd = spectrum_or_texture(
                p,
                &["Kd"],
                SpectrumKind::Albedo,
                if ty == "substrate" { 0.5 } else { 0.25 },
                ctx,
                tex,
            )?;
            let ks = spectrum_or_texture(p, &["Ks"], SpectrumKind::Albedo, 0.25, ctx, tex)?;
            let alpha = roughness_alpha(p, 0.1, true, ctx, tex)?;
            mark_used(p, &["index", "eta", "opacity", "bumpmap"]);
            for n in ["Kr", "Kt"] {
                if p.has(n) {
                    let s = spectrum_or_texture(p, &[n], SpectrumKind::Albedo, 0.0, ctx, tex)?;
                    if s.values.iter().any(|&v| v > 0.0) {
                        ctx.warn(
                            p.span_of(n).unwrap_or(tspan),
                            format!("uber '{n}' (perfect specular lobe) ignored"),
                        )?;
                    }
                }
            }
            Material::DiffuseSpecular {
                diffuse: kd,
                specular: ks,
                roughness: alpha,
            }
        }
        "conductor" | "metal" => {
            let v3 = ty == "metal";
            if v3 {
                ctx.warn(tspan, "pbrt-v3 material 'metal' read as 'conductor'")?;
            }
            let alpha = roughness_alpha(p, if v3 { 0.01 } else { 0.0 }, v3, ctx, tex)?;
            if p.has("reflectance") {
                let r =
                    spectrum_or_texture(p, &["reflectance"], SpectrumKind::Albedo, 1.0, ctx, tex)?;
                let k_vals = r
                    .values
                    .iter()
                    .map(|&v| 2.0 * (v.clamp(0.0, 0.9999) / (1.0 - v.clamp(0.0, 0.9999))).sqrt())
                    .collect();
                let k = Spectrum::new("k", r.wavelengths_nm.clone(), k_vals)
                    .map_err(|m| SpanError::new(tspan, m))?
                    .with_extrapolation(Extrapolation::Clamp);
                Material::Conductor {
                    eta: Spectrum::constant("eta", 1.0),
                    k,
                    roughness: alpha,
                }
            } else {
                let eta = p.spectrum("eta", SpectrumKind::Unbounded, ctx)?;
                let k = p.spectrum("k", SpectrumKind::Unbounded, ctx)?;
                let (eta, k) = match (eta, k) {
                    (Some(e), Some(k)) => (e, k),
                    (e, k) => {
                        ctx.warn(tspan, "conductor without built-in eta/k (pbrt's default is metal-Cu, not built in); using eta 0.2, k 3.0 (normal-incidence reflectance 0.92)")?;
                        (
                            e.unwrap_or(Spectrum::constant("eta", 0.2)),
                            k.unwrap_or(Spectrum::constant("k", 3.0)),
                        )
                    }
                };
                Material::Conductor {
                    eta,
                    k,
                    roughness: alpha,
                }
            }
        }
        "dielectric" | "glass" | "thindielectric" => {
            if ty == "glass" {
                ctx.warn(tspan, "pbrt-v3 material 'glass' read as 'dielectric'")?;
                mark_used(p, &["Kr", "Kt"]);
            }
            if ty == "thindielectric" {
                ctx.warn(tspan, "'thindielectric' read as a solid 'dielectric'")?;
            }
            let ior = eta_spectrum(p, &["eta", "index"], 1.5, ctx)?;
            let alpha = roughness_alpha(p, 0.0, ty == "glass", ctx, tex)?;
            if alpha > 0.0 {
                ctx.warn(tspan, "rough dielectric read as smooth")?;
            }
            Material::Dielectric { ior }
        }
        "mirror" => {
            ctx.warn(tspan, "pbrt-v3 material 'mirror' read as a perfect mirror")?;
            Material::Mirror {
                reflectance: spectrum_or_texture(p, &["Kr"], SpectrumKind::Albedo, 0.9, ctx, tex)?,
            }
        }
        "interface" | "none" | "" => Material::Dielectric {
            ior: Spectrum::constant("index-matched", 1.0),
        },
        _ => {
            for q in &p.params {
                q.used.set(true);
            }
            ctx.warn(
                tspan,
                format!("material '{ty}' not supported; using diffuse reflectance 0.5"),
            )?;
            Material::Diffuse {
                reflectance: Spectrum::constant("fallback", 0.5),
            }
        }
    })
}

/// ∫ȳ(λ)S(λ)dλ over 360–830 nm with ȳ peaking at 1 (pbrt's SpectrumToPhotometric).
fn photometric(s: &Spectrum) -> f64 {
    luminance_y(s) * luminance_y_of_one()
}

/// ∫ȳ(λ)dλ, 360–830 nm at 1 nm (106.857): pbrt-v4's normaliser of a constant spectrum.
pub(crate) fn luminance_y_of_one() -> f64 {
    static Y: std::sync::OnceLock<f64> = std::sync::OnceLock::new();
    *Y.get_or_init(|| {
        let grid = crate::spectrum::WavelengthGrid {
            start_nm: 360.0,
            step_nm: 1.0,
            count: 471,
        };
        Spectrum::constant("one", 1.0)
            .integrate_product(&crate::spectrum::library::cie1931_cmfs()[1], &grid)
    })
}

/// An emission spectrum normalised as pbrt-v4 does (see module docs), times `scale`.
fn emission(
    p: &ParamList,
    name: &str,
    scale: f64,
    ctx: &mut Ctx,
    tspan: Span,
) -> PResult<Spectrum> {
    let is_rgb = p
        .params
        .iter()
        .any(|q| q.name == name && q.ty == ParamType::Rgb);
    let s = match p.spectrum(name, SpectrumKind::Illuminant, ctx)? {
        Some(s) => s,
        None => super::params::rgb_to_spectrum([1.0, 1.0, 1.0], SpectrumKind::Illuminant, name)
            .expect("finite white"),
    };
    let norm = if ctx.dialect.version == super::dialect::PbrtVersion::V3 {
        // pbrt-v3: the numbers are the radiance (or intensity) itself.
        1.0
    } else if is_rgb || !p.has(name) {
        luminance_y_of_one()
    } else {
        photometric(&s)
    };
    if !(norm > 0.0) {
        if s.values.iter().all(|&v| v == 0.0) {
            return Ok(s);
        }
        return Err(SpanError::new(
            p.span_of(name).unwrap_or(tspan),
            format!("emission '{name}' has no luminance (zero in the visible range)"),
        ));
    }
    Ok(s.scaled(scale / norm).with_unit("W/(sr·m²·nm)"))
}

pub fn light(
    ty: &str,
    tspan: Span,
    p: &ParamList,
    ctx: &mut Ctx,
    xf: &DMat4,
) -> PResult<Option<Light>> {
    let scale = p.float("scale", 1.0)?;
    Ok(Some(match ty {
        "point" | "goniometric" | "projection" => {
            if ty != "point" {
                for q in &p.params {
                    if q.name != "I" && q.name != "scale" && q.name != "power" {
                        q.used.set(true);
                    }
                }
                ctx.warn(
                    tspan,
                    format!("light '{ty}' not supported; an isotropic point light is used"),
                )?;
            }
            let mut i = emission(p, "I", scale, ctx, tspan)?;
            if let Some(phi) = p.float_opt("power")?.filter(|&v| v > 0.0) {
                i = i.scaled(phi / (4.0 * PI));
            }
            let from = p.point3("from", [0.0; 3])?;
            Light::Point {
                position: xf.transform_point3(DVec3::from(from)),
                intensity: i,
            }
        }
        "spot" => {
            let mut i = emission(p, "I", scale, ctx, tspan)?;
            let from = DVec3::from(p.point3("from", [0.0; 3])?);
            let to = DVec3::from(p.point3("to", [0.0, 0.0, 1.0])?);
            let cone = p.float("coneangle", 30.0)?;
            let delta = p.float("conedelta", 5.0)?;
            if let Some(phi) = p.float_opt("power")?.filter(|&v| v > 0.0) {
                let cos_end = cone.to_radians().cos();
                let cos_start = (cone - delta).to_radians().cos();
                let k_e = 2.0 * PI * ((1.0 - cos_start) + (cos_start - cos_end) / 2.0);
                i = i.scaled(phi / k_e);
            }
            let dir = xf.transform_vector3(to - from);
            if !(dir.length() > 0.0) {
                return Err(SpanError::new(tspan, "spot light 'from' equals 'to'"));
            }
            Light::Spot {
                position: xf.transform_point3(from),
                direction: dir.normalize(),
                cone_angle_deg: cone,
                falloff_start_deg: (cone - delta).max(0.0),
                intensity: i,
            }
        }
        "distant" => {
            let mut l = emission(p, "L", scale, ctx, tspan)?;
            if let Some(e) = p.float_opt("illuminance")?.filter(|&v| v > 0.0) {
                l = l.scaled(e);
            }
            let from = DVec3::from(p.point3("from", [0.0; 3])?);
            let to = DVec3::from(p.point3("to", [0.0, 0.0, 1.0])?);
            let dir = xf.transform_vector3(to - from);
            if !(dir.length() > 0.0) {
                return Err(SpanError::new(tspan, "distant light 'from' equals 'to'"));
            }
            Light::Distant {
                direction: dir.normalize(),
                irradiance: l,
            }
        }
        "infinite" => {
            if let Some(f) = p.string("filename")? {
                ctx.warn(
                    p.span_of("filename").unwrap_or(tspan),
                    format!("environment map '{f}' not supported; a uniform environment is used"),
                )?;
            }
            mark_used(p, &["portal"]);
            let mut l = emission(p, "L", scale, ctx, tspan)?;
            if let Some(e) = p.float_opt("illuminance")?.filter(|&v| v > 0.0) {
                l = l.scaled(e / PI);
            }
            Light::Infinite { radiance: l }
        }
        _ => {
            for q in &p.params {
                q.used.set(true);
            }
            ctx.warn(tspan, format!("light '{ty}' not supported; skipped"))?;
            return Ok(None);
        }
    }))
}

pub fn area_light(
    ty: &str,
    tspan: Span,
    p: &ParamList,
    ctx: &mut Ctx,
) -> PResult<Option<AreaLightSpec>> {
    if ty != "diffuse" && ty != "area" {
        for q in &p.params {
            q.used.set(true);
        }
        ctx.warn(
            tspan,
            format!("area light '{ty}' not supported; shapes will not emit"),
        )?;
        return Ok(None);
    }
    if let Some(f) = p.string("filename")? {
        ctx.warn(
            tspan,
            format!("image area light '{f}' not supported; uniform L is used"),
        )?;
    }
    let scale = p.float("scale", 1.0)?;
    let radiance = emission(p, "L", scale, ctx, tspan)?;
    let two_sided = p.bool("twosided", false)?;
    let power = p.float_opt("power")?.filter(|&v| v > 0.0);
    Ok(Some(AreaLightSpec {
        radiance,
        two_sided,
        power,
        span: tspan,
    }))
}

pub enum Geometry {
    Mesh(Mesh),
    Sphere(Sphere),
    Disk(Disk),
}

pub struct ShapeInput<'a> {
    pub kind: &'a str,
    pub span: Span,
    pub params: &'a ParamList,
    pub to_world: DMat4,
    pub reverse_orientation: bool,
    pub material: MaterialId,
    pub object: ObjectId,
    pub area_light: Option<&'a AreaLightSpec>,
    /// Tessellate analytic shapes (inside object definitions).
    pub force_mesh: bool,
}

/// Object-space mesh data before transformation.
pub struct RawMesh {
    pub p: Vec<DVec3>,
    pub n: Option<Vec<DVec3>>,
    pub uv: Option<Vec<Vec2>>,
    pub tri: Vec<[u32; 3]>,
}

fn vec3s(v: &[f64]) -> Vec<DVec3> {
    v.chunks_exact(3)
        .map(|c| DVec3::new(c[0], c[1], c[2]))
        .collect()
}

fn indices<const N: usize>(
    p: &ParamList,
    span: Span,
    nverts: usize,
    what: &str,
) -> PResult<Vec<[u32; N]>> {
    match p.ints("indices")? {
        Some(v) => {
            let at = p.span_of("indices").unwrap_or(span);
            if !v.len().is_multiple_of(N) {
                return Err(SpanError::new(
                    at,
                    format!(
                        "{what} 'indices' count {} is not a multiple of {N}",
                        v.len()
                    ),
                ));
            }
            let mut out = Vec::with_capacity(v.len() / N);
            for c in v.chunks_exact(N) {
                let mut e = [0u32; N];
                for (k, &x) in c.iter().enumerate() {
                    if x < 0 || x as usize >= nverts {
                        return Err(SpanError::new(
                            at,
                            format!("{what} index {x} out of range (0..{nverts})"),
                        ));
                    }
                    e[k] = x as u32;
                }
                out.push(e);
            }
            Ok(out)
        }
        None if nverts == N => Ok(vec![std::array::from_fn(|k| k as u32)]),
        None => Err(SpanError::new(
            span,
            format!("{what} needs \"integer indices\" (it has {nverts} vertices)"),
        )),
    }
}

/// Optional per-vertex normals and uvs.
type MeshAttrs = (Option<Vec<DVec3>>, Option<Vec<Vec2>>);

fn mesh_attrs(p: &ParamList, span: Span, nverts: usize) -> PResult<MeshAttrs> {
    let n = match p.vec3s("N", &[ParamType::Normal])? {
        Some(v) if v.len() == 3 * nverts => Some(vec3s(v)),
        Some(v) => {
            return Err(SpanError::new(
                p.span_of("N").unwrap_or(span),
                format!("'N' has {} normals for {nverts} vertices", v.len() / 3),
            ));
        }
        None => None,
    };
    let uvname = if p.has("uv") { "uv" } else { "st" };
    let uv = match p.vec3s(uvname, &[ParamType::Point2, ParamType::Float])? {
        Some(v) if v.len() == 2 * nverts => Some(
            v.chunks_exact(2)
                .map(|c| Vec2::new(c[0] as f32, c[1] as f32))
                .collect(),
        ),
        Some(v) => {
            return Err(SpanError::new(
                p.span_of(uvname).unwrap_or(span),
                format!("'{uvname}' has {} values for {nverts} vertices", v.len()),
            ));
        }
        None => None,
    };
    mark_used(p, &["S", "faceIndices", "emissionfilename"]);
    Ok((n, uv))
}

fn positions(p: &ParamList, span: Span, what: &str) -> PResult<Vec<DVec3>> {
    match p.vec3s("P", &[ParamType::Point3])? {
        Some(v) if !v.is_empty() => Ok(vec3s(v)),
        _ => Err(SpanError::new(span, format!("{what} needs \"point3 P\""))),
    }
}

pub fn shape(s: &ShapeInput, ctx: &mut Ctx) -> PResult<Option<Geometry>> {
    let p = s.params;
    if let Some(a) = p.float_opt("alpha")?
        && a < 1.0
    {
        ctx.warn(
            p.span_of("alpha").unwrap_or(s.span),
            "shape 'alpha' cut-outs not supported; the shape is opaque",
        )?;
    }
    let raw = match s.kind {
        "trianglemesh" => {
            let pos = positions(p, s.span, "trianglemesh")?;
            let tri = indices::<3>(p, s.span, pos.len(), "trianglemesh")?;
            let (n, uv) = mesh_attrs(p, s.span, pos.len())?;
            RawMesh { p: pos, n, uv, tri }
        }
        "bilinearmesh" => {
            let pos = positions(p, s.span, "bilinearmesh")?;
            let idx = indices::<4>(p, s.span, pos.len(), "bilinearmesh")?;
            let (n, uv) = mesh_attrs(p, s.span, pos.len())?;
            let tri = idx
                .iter()
                .flat_map(|c| [[c[0], c[1], c[3]], [c[0], c[3], c[2]]])
                .collect();
            RawMesh { p: pos, n, uv, tri }
        }
        "loopsubdiv" => {
            let pos = positions(p, s.span, "loopsubdiv")?;
            let tri = indices::<3>(p, s.span, pos.len(), "loopsubdiv")?;
            let levels = p.int("levels", 3)?;
            if levels > 1 {
                ctx.warn(
                    p.span_of("levels").unwrap_or(s.span),
                    format!("loopsubdiv: {levels} levels requested; one level is applied"),
                )?;
            }
            let (p2, t2) = if levels >= 1 {
                super::subdiv::loop_once(&pos, &tri)
            } else {
                (pos, tri)
            };
            RawMesh {
                p: p2,
                n: None,
                uv: None,
                tri: t2,
            }
        }
        "plymesh" => {
            let Some(f) = p.string("filename")? else {
                return Err(SpanError::new(s.span, "plymesh needs \"string filename\""));
            };
            mark_used(p, &["displacement", "edgelength"]);
            let path = ctx.resolve_path(&f);
            let at = p.span_of("filename").unwrap_or(s.span);
            let m = crate::scene::mesh_io::read_ply(&path)
                .map_err(|e| SpanError::new(at, e.to_string()))?;
            if m.positions.iter().any(|v| !v.is_finite()) {
                return Err(SpanError::new(
                    at,
                    format!(
                        "{}: PLY data: vertex without finite x, y, z",
                        path.display()
                    ),
                ));
            }
            RawMesh {
                p: m.positions,
                n: m.normals,
                uv: m.uvs,
                tri: m.triangles,
            }
        }
        "sphere" => {
            let r = p.float("radius", 1.0)?;
            if !(r > 0.0) {
                return Err(SpanError::new(
                    s.span,
                    format!("sphere radius must be > 0, got {r}"),
                ));
            }
            for n in ["zmin", "zmax", "phimax"] {
                if p.has(n) {
                    p.find(n);
                    ctx.warn(
                        p.span_of(n).unwrap_or(s.span),
                        format!("partial spheres ('{n}') not supported; a full sphere is used"),
                    )?;
                }
            }
            // camsim's analytic spheres face outwards; a reversed one (facing
            // inwards, e.g. an enclosing emitter) becomes a fine mesh.
            if s.reverse_orientation {
                return Ok(Some(Geometry::Mesh(to_world_mesh(
                    tessellate_sphere(r, REVERSED_SPHERE_SEGMENTS),
                    s,
                ))));
            }
            if !s.force_mesh {
                let (scale, uniform) = uniform_scale(&s.to_world);
                if !uniform {
                    ctx.warn(
                        s.span,
                        "sphere under a non-uniform scale; the mean scale is used",
                    )?;
                }
                let radius = r * scale;
                let emission = s
                    .area_light
                    .map(|a| emission_for(a, 4.0 * PI * radius * radius));
                return Ok(Some(Geometry::Sphere(Sphere {
                    center: s.to_world.transform_point3(DVec3::ZERO),
                    radius,
                    material: s.material,
                    object: s.object,
                    emission,
                })));
            }
            tessellate_sphere(r, 48)
        }
        "cylinder" => {
            let r = p.float("radius", 1.0)?;
            let zmin = p.float("zmin", -1.0)?;
            let zmax = p.float("zmax", 1.0)?;
            let phimax = p.float("phimax", 360.0)?;
            if !(r > 0.0) {
                return Err(SpanError::new(
                    s.span,
                    format!("cylinder radius must be > 0, got {r}"),
                ));
            }
            if !(zmin.is_finite() && zmax.is_finite() && zmin != zmax) {
                return Err(SpanError::new(
                    s.span,
                    format!("cylinder needs finite zmin != zmax, got {zmin} and {zmax}"),
                ));
            }
            if !(phimax > 0.0) {
                return Err(SpanError::new(
                    p.span_of("phimax").unwrap_or(s.span),
                    format!("cylinder phimax must be > 0 degrees, got {phimax}"),
                ));
            }
            tessellate_cylinder(r, zmin, zmax, phimax.min(360.0).to_radians())
        }
        "disk" => {
            let r = p.float("radius", 1.0)?;
            let h = p.float("height", 0.0)?;
            if !(r > 0.0) {
                return Err(SpanError::new(
                    s.span,
                    format!("disk radius must be > 0, got {r}"),
                ));
            }
            for n in ["innerradius", "phimax"] {
                if p.has(n) {
                    p.find(n);
                    ctx.warn(
                        p.span_of(n).unwrap_or(s.span),
                        format!("partial disks ('{n}') not supported; a full disk is used"),
                    )?;
                }
            }
            if !s.force_mesh {
                let (scale, uniform) = uniform_scale(&s.to_world);
                if !uniform {
                    ctx.warn(
                        s.span,
                        "disk under a non-uniform scale; the mean scale is used",
                    )?;
                }
                let nm = normal_matrix(&s.to_world);
                let mut n = (nm * DVec3::Z).normalize();
                if s.reverse_orientation {
                    n = -n;
                }
                let radius = r * scale;
                let emission = s.area_light.map(|a| emission_for(a, PI * radius * radius));
                return Ok(Some(Geometry::Disk(Disk {
                    center: s.to_world.transform_point3(DVec3::new(0.0, 0.0, h)),
                    normal: n,
                    radius,
                    material: s.material,
                    object: s.object,
                    emission,
                })));
            }
            tessellate_disk(r, h)
        }
        _ => {
            for q in &p.params {
                q.used.set(true);
            }
            ctx.warn(s.span, format!("shape '{}' not supported; skipped", s.kind))?;
            return Ok(None);
        }
    };
    let mesh = to_world_mesh(raw, s);
    if mesh.indices.is_empty() {
        ctx.warn(s.span, "shape has no triangles; skipped")?;
        return Ok(None);
    }
    Ok(Some(Geometry::Mesh(mesh)))
}

fn emission_for(a: &AreaLightSpec, area_m2: f64) -> Emission {
    let mut radiance = a.radiance.clone();
    if let Some(phi) = a.power
        && area_m2 > 0.0
    {
        let k_e = if a.two_sided { 2.0 } else { 1.0 } * area_m2 * PI;
        radiance = radiance.scaled(phi / k_e);
    }
    Emission {
        radiance,
        two_sided: a.two_sided,
    }
}

fn normal_matrix(m: &DMat4) -> DMat3 {
    DMat3::from_mat4(*m).inverse().transpose()
}

/// Mean linear scale of a transform and whether it is uniform (conformal) to 1e-6.
fn uniform_scale(m: &DMat4) -> (f64, bool) {
    let a = DMat3::from_mat4(*m);
    let l = [a.x_axis.length(), a.y_axis.length(), a.z_axis.length()];
    let mean = (l[0] + l[1] + l[2]) / 3.0;
    let orth =
        a.x_axis.dot(a.y_axis).abs() + a.y_axis.dot(a.z_axis).abs() + a.x_axis.dot(a.z_axis).abs();
    let uniform = l.iter().all(|v| (v - mean).abs() <= 1e-6 * mean) && orth <= 1e-6 * mean * mean;
    (mean, uniform)
}

/// Segments around a `ReverseOrientation` sphere's tessellation (half as
/// many from pole to pole): the facets lie within r·(1 − cos(π/96)) ≈ 0.05 %
/// of the sphere.
pub const REVERSED_SPHERE_SEGMENTS: u32 = 96;

/// A sphere as `nu`×`nu/2` quads (triangles at the poles), outward winding,
/// smooth normals.
fn tessellate_sphere(r: f64, nu: u32) -> RawMesh {
    let nv = nu / 2;
    let mut p = vec![];
    for j in 0..=nv {
        let th = PI * j as f64 / nv as f64;
        for i in 0..nu {
            let ph = 2.0 * PI * i as f64 / nu as f64;
            p.push(DVec3::new(
                r * th.sin() * ph.cos(),
                r * th.sin() * ph.sin(),
                r * th.cos(),
            ));
        }
    }
    let mut tri = vec![];
    for j in 0..nv {
        for i in 0..nu {
            let a = j * nu + i;
            let b = j * nu + (i + 1) % nu;
            let c = (j + 1) * nu + i;
            let d = (j + 1) * nu + (i + 1) % nu;
            // outward winding (normal = (b-a)x(c-a) points away from the centre)
            if j > 0 {
                tri.push([a, c, b]);
            }
            if j + 1 < nv {
                tri.push([b, c, d]);
            }
        }
    }
    let n = p.iter().map(|q| q.normalize()).collect();
    RawMesh {
        p,
        n: Some(n),
        uv: None,
        tri,
    }
}

/// pbrt's cylinder (side only, no caps): x = r·cos φ, y = r·sin φ, z from
/// `zmin` to `zmax`, φ up to `phimax` (radians). Facing as pbrt's
/// ∂p/∂u × ∂p/∂v: outwards when zmax > zmin; smooth normals alike.
fn tessellate_cylinder(r: f64, zmin: f64, zmax: f64, phimax: f64) -> RawMesh {
    let nu = ((96.0 * phimax / (2.0 * PI)).ceil() as u32).max(1);
    let closed = phimax >= 2.0 * PI;
    let ncol = if closed { nu } else { nu + 1 };
    let sign = if zmax > zmin { 1.0 } else { -1.0 };
    let (mut p, mut n) = (vec![], vec![]);
    for z in [zmin, zmax] {
        for i in 0..ncol {
            let ph = phimax * i as f64 / nu as f64;
            p.push(DVec3::new(r * ph.cos(), r * ph.sin(), z));
            n.push(DVec3::new(ph.cos(), ph.sin(), 0.0) * sign);
        }
    }
    let mut tri = vec![];
    for i in 0..nu {
        let a = i;
        let b = (i + 1) % ncol;
        let (c, d) = (a + ncol, b + ncol);
        // (b−a)×(c−a) has the sign of (zmax − zmin) outwards
        tri.push([a, b, c]);
        tri.push([b, d, c]);
    }
    RawMesh {
        p,
        n: Some(n),
        uv: None,
        tri,
    }
}

fn tessellate_disk(r: f64, h: f64) -> RawMesh {
    let nu = 64u32;
    let mut p = vec![DVec3::new(0.0, 0.0, h)];
    for i in 0..nu {
        let ph = 2.0 * PI * i as f64 / nu as f64;
        p.push(DVec3::new(r * ph.cos(), r * ph.sin(), h));
    }
    let tri = (0..nu).map(|i| [0, 1 + i, 1 + (i + 1) % nu]).collect();
    RawMesh {
        p,
        n: None,
        uv: None,
        tri,
    }
}

/// Transform to world space and orient the triangles as pbrt does (see module docs).
fn to_world_mesh(raw: RawMesh, s: &ShapeInput) -> Mesh {
    let m = s.to_world;
    let nm = normal_matrix(&m);
    let swaps = DMat3::from_mat4(m).determinant() < 0.0;
    let RawMesh {
        p,
        n,
        uv,
        tri: mut indices,
    } = raw;
    let pw: Vec<DVec3> = p.iter().map(|&q| m.transform_point3(q)).collect();
    drop(p);
    // pbrt-v4 (TriangleMesh): ReverseOrientation negates the shading normals
    // too, and the geometric normal then faces them.
    let ns = if s.reverse_orientation { -1.0 } else { 1.0 };
    let nw: Option<Vec<DVec3>> = n.map(|n| {
        n.iter()
            .map(|&v| (nm * v).normalize_or_zero() * ns)
            .collect()
    });
    let flip_all = s.reverse_orientation ^ swaps;
    let mut area = 0.0;
    // In place: drop degenerate triangles (no area, never hit) and orient the rest.
    indices.retain_mut(|t| {
        let [a, b, c] = *t;
        let (pa, pb, pc) = (pw[a as usize], pw[b as usize], pw[c as usize]);
        let ng = (pb - pa).cross(pc - pa);
        if !(ng.length_squared() > 0.0) || !ng.is_finite() {
            return false;
        }
        let flip = match &nw {
            Some(n) => {
                let ns = n[a as usize] + n[b as usize] + n[c as usize];
                if ns.length_squared() > 0.0 {
                    ng.dot(ns) < 0.0
                } else {
                    flip_all
                }
            }
            None => flip_all,
        };
        if flip {
            t.swap(1, 2);
        }
        area += 0.5 * ng.length();
        true
    });
    let emission = s.area_light.map(|a| emission_for(a, area));
    let f32v = |q: &DVec3| Vec3::new(q.x as f32, q.y as f32, q.z as f32);
    Mesh {
        positions: pw.iter().map(f32v).collect(),
        normals: nw.map(|n| n.iter().map(f32v).collect()),
        uvs: uv,
        indices,
        material: s.material,
        object: s.object,
        emission,
    }
}
