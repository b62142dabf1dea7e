//! The stages a variant runs through: scene → camera → render → sensor →
//! measure. Each is one function here; the runner knows nothing else. Stages
//! that other modules are still building return `Error::NotSupported`, so a
//! variant that needs them fails with "not supported yet: …" and no number is
//! ever invented. The lead replaces the bodies as the modules land.

use super::spec::{Addition, Measure, Override, ResolvedExperiment, Target};
use crate::figure::Figure;
use crate::image::SensorImage;
use crate::measure::Measured;
use crate::optical_image::{OpticalImage, Rect};
use crate::optics::Camera;
use crate::params::Value;
use crate::render::RenderSettings;
use crate::scene::{
    CameraModel, CameraPose, CameraSpec, FilmSpec, Material, Scene, look_at_to_world, targets,
};
use crate::sensor::SensorConfig;
use crate::spectrum::{Spectrum, WavelengthGrid, library};
use crate::{Error, Result};
use glam::DVec3;
use std::collections::BTreeMap;
use std::path::Path;

/// Which stages a measurement needs.
#[derive(Clone, Copy, Debug, Default, PartialEq, Eq)]
pub struct Needs {
    /// Scene, camera and render (the optical image).
    pub optical_image: bool,
    /// The sensor image (implies the optical image).
    pub sensor_image: bool,
}

/// Stage requirements per measurement kind. `colorimetry` reads a spectrum
/// only; `ri` and `convergence` can work on the optical image; every other
/// kind measures sensor digital values.
pub fn needs(kind: &str) -> Needs {
    let n = crate::measure::request::needs(kind);
    Needs {
        optical_image: n.optical_image,
        sensor_image: n.sensor_image,
    }
}

/// Load the scene file (pbrt or KDL) and apply removals, overrides and
/// additions, then the camera pose. pbrt scenes get the paper's spectra when
/// the experiment says `scene "…" materials="paper"`.
pub fn build_scene(spec: &ResolvedExperiment) -> Result<Scene> {
    let Some(f) = &spec.scene else {
        return Err(Error::invalid(format!(
            "experiment '{}' has no scene; add scene \"….pbrt\"",
            spec.name
        )));
    };
    let ext = f.path.extension().and_then(|e| e.to_str()).unwrap_or("");
    let mut scene = if ext == "kdl" {
        crate::scene::kdl_scene::load_kdl_scene(&f.path)?.scene
    } else {
        crate::scene::pbrt::load(&f.path, &crate::scene::pbrt::LoadOptions::default())?
    };
    if spec.scene_materials.as_deref() == Some("paper") {
        crate::scene::pbrt::paper::apply_paper_spectra(&mut scene)?;
    }
    for name in &spec.removals {
        remove_object(&mut scene, name)?;
    }
    for o in &spec.overrides {
        apply_override(&mut scene, o, spec)?;
    }
    let dir = spec.file.parent().unwrap_or(Path::new("."));
    for a in &spec.additions {
        add_object(&mut scene, a, dir)?;
    }
    if let Some(c) = &spec.camera {
        let pose = CameraPose {
            position: DVec3::from_array(c.position_m),
            look_at: DVec3::from_array(c.look_at_m),
            up: DVec3::from_array(c.up),
        };
        let to_world = look_at_to_world(&pose).ok_or_else(|| {
            Error::invalid(format!(
                "experiment '{}': degenerate camera pose (look-at at the eye, or up parallel to the view)",
                spec.name
            ))
        })?;
        let model =
            scene
                .camera
                .as_ref()
                .map(|c| c.model.clone())
                .unwrap_or(CameraModel::Pinhole {
                    fov_deg: 40.0,
                    f_number: 2.0,
                });
        scene.camera = Some(CameraSpec { to_world, model });
    }
    Ok(scene)
}

fn object_matches(name: &str, wanted: &str) -> bool {
    name == wanted
        || name
            .strip_prefix(wanted)
            .is_some_and(|r| r.starts_with('/'))
}

fn ids_matching(scene: &Scene, wanted: &str) -> Result<Vec<u32>> {
    let ids: Vec<u32> = scene
        .objects
        .iter()
        .enumerate()
        .filter(|(_, o)| object_matches(&o.name, wanted))
        .map(|(i, _)| i as u32)
        .collect();
    if ids.is_empty() {
        let names: Vec<&str> = scene.objects.iter().map(|o| o.name.as_str()).collect();
        let hint = crate::diag::did_you_mean(wanted, names.iter().copied())
            .map(|s| format!(" (did you mean '{s}'?)"))
            .unwrap_or_default();
        return Err(Error::invalid(format!(
            "no object '{wanted}' in the scene{hint}; objects are: {}",
            names.join(", ")
        )));
    }
    Ok(ids)
}

/// Remove every shape whose object is `name` or below it (`name/…`).
fn remove_object(scene: &mut Scene, name: &str) -> Result<()> {
    let ids = ids_matching(scene, name)?;
    scene.meshes.retain(|m| !ids.contains(&m.object));
    scene.spheres.retain(|m| !ids.contains(&m.object));
    scene.disks.retain(|m| !ids.contains(&m.object));
    Ok(())
}

/// `override "<object>" reflectance="<spectrum>" radiance="<spectrum>" radiance-scale=k`.
fn apply_override(scene: &mut Scene, o: &Override, spec: &ResolvedExperiment) -> Result<()> {
    let ids = ids_matching(scene, &o.object)?;
    let dir = spec.file.parent().unwrap_or(Path::new("."));
    let unknown = o
        .params
        .unknown(&["reflectance", "radiance", "radiance-scale"]);
    if let Some(u) = unknown.first() {
        return Err(Error::invalid(format!(
            "override '{}': unknown property '{u}'; expected reflectance, radiance or radiance-scale",
            o.object
        )));
    }
    let spectrum = |k: &str| -> Result<Option<Spectrum>> {
        match o.params.str(k).map_err(Error::invalid)? {
            Some(r) => Ok(Some(library::resolve(r, dir).map_err(Error::invalid)?)),
            None => Ok(None),
        }
    };
    let refl = spectrum("reflectance")?;
    let rad = spectrum("radiance")?;
    let scale = o.params.f64("radiance-scale").map_err(Error::invalid)?;
    let mut touched_materials = vec![];
    for m in &mut scene.meshes {
        if !ids.contains(&m.object) {
            continue;
        }
        touched_materials.push(m.material);
        if let Some(e) = &mut m.emission {
            if let Some(r) = &rad {
                e.radiance = r.clone();
            }
            if let Some(k) = scale {
                e.radiance = e.radiance.clone().scaled(k);
            }
        }
    }
    if let Some(r) = refl {
        for id in touched_materials {
            if let Some(nm) = scene.materials.get_mut(id as usize) {
                nm.material = match &nm.material {
                    Material::DiffuseSpecular {
                        diffuse,
                        specular,
                        roughness,
                    } => {
                        // keep the specular-to-diffuse ratio of the original
                        let k = specular.values.iter().cloned().fold(0.0, f64::max)
                            / diffuse.values.iter().cloned().fold(1e-12, f64::max);
                        let _ = diffuse;
                        Material::DiffuseSpecular {
                            diffuse: r.clone(),
                            specular: r.clone().scaled(k.min(1.0)),
                            roughness: *roughness,
                        }
                    }
                    _ => Material::Diffuse {
                        reflectance: r.clone(),
                    },
                };
            }
        }
    }
    Ok(())
}

fn add_object(scene: &mut Scene, a: &Addition, dir: &Path) -> Result<()> {
    let pos = DVec3::from_array(a.position_m);
    let rot = DVec3::from_array(a.rotate_deg);
    match a.target {
        Target::Mcc => {
            let known = ["patch-size-m", "patch-pitch-m"];
            if let Some(u) = a.params.unknown(&known).first() {
                return Err(Error::invalid(format!(
                    "add '{}': unknown property '{u}' for target=\"mcc\"",
                    a.id
                )));
            }
            let mut c = targets::MccChart {
                name: a.id.clone(),
                position_m: pos,
                rotation_deg: rot,
                ..Default::default()
            };
            let k = a.scale[0];
            c.width_m *= k;
            c.height_m *= k;
            c.patch_size_m *= k;
            c.patch_pitch_m *= k;
            if let Some(v) = a.params.f64("patch-size-m").map_err(Error::invalid)? {
                c.patch_size_m = v;
            }
            if let Some(v) = a.params.f64("patch-pitch-m").map_err(Error::invalid)? {
                c.patch_pitch_m = v;
            }
            targets::add_mcc(scene, &c)
        }
        Target::SlantedEdge => {
            if let Some(u) = a.params.unknown(&["tilt-deg", "reflectance"]).first() {
                return Err(Error::invalid(format!(
                    "add '{}': unknown property '{u}' for target=\"slanted-edge\"",
                    a.id
                )));
            }
            let mut e = targets::SlantedEdge::new(&a.id, pos)?;
            e.rotation_deg = rot;
            e.width_m *= a.scale[0];
            e.height_m *= a.scale[1];
            if let Some(t) = a.params.f64("tilt-deg").map_err(Error::invalid)? {
                e.tilt_deg = t;
            }
            if let Some(r) = a.params.str("reflectance").map_err(Error::invalid)? {
                e.white = library::resolve(r, dir).map_err(Error::invalid)?;
            }
            targets::add_slanted_edge(scene, &e)
        }
        Target::Mesh => {
            let f = a.file.as_ref().ok_or_else(|| {
                Error::invalid(format!("add '{}': target=\"mesh\" needs file=\"…\"", a.id))
            })?;
            let mut m = targets::PlacedMesh::bunny(&f.path)?;
            m.name = a.id.clone();
            m.position_m = pos;
            m.scale = a.scale[0];
            m.rot_y_deg = a.rotate_deg[1];
            if let Some(r) = a.params.str("reflectance").map_err(Error::invalid)? {
                m.reflectance = library::resolve(r, dir).map_err(Error::invalid)?;
            }
            targets::add_mesh(scene, &m)
        }
    }
}

/// The sensor of a variant: its file (or the generic sensor) with inline overrides.
pub fn sensor_config(spec: &ResolvedExperiment) -> Result<Option<SensorConfig>> {
    let Some(s) = &spec.sensor else {
        return Ok(None);
    };
    let mut cfg = match &s.file {
        Some(f) => SensorConfig::load(&f.path)?,
        None => SensorConfig::generic(),
    };
    cfg.apply_overrides(&s.overrides)
        .map_err(|e| Error::invalid(format!("sensor '{}': {e}", cfg.name)))?;
    Ok(Some(cfg))
}

/// The film the optical image is rendered on: the sensor's pixel grid when the
/// experiment has a sensor with a size (the paper renders at the sensor's
/// resolution), else the scene's film.
pub fn film_spec(spec: &ResolvedExperiment, scene: &Scene) -> Result<FilmSpec> {
    if let Some(cfg) = sensor_config(spec)?
        && let (Some(c), Some(r)) = (cfg.cols, cfg.rows)
    {
        return Ok(FilmSpec {
            width_px: c,
            height_px: r,
            pixel_pitch_m: cfg.pixel_size_m,
            crop_window: None,
        });
    }
    Ok(scene.film.clone().unwrap_or_default())
}

/// Properties of a `lens` node with a file.
const LENS_FILE_KEYS: &[&str] = &[
    "film-distance-mm",
    "focus-distance-m",
    "rtf-degree",
    "rtf-axis-weight",
];
/// Properties of an inline `lens model=…` node.
const LENS_MODEL_KEYS: &[&str] = &[
    "model",
    "fov-deg",
    "f-number",
    "focal-length-mm",
    "focus-distance-m",
];

/// `rtf-degree`: N fits an RTF of degree N to the prescription and renders
/// through it; absent or "none" traces the file as it is (so a sweep can
/// compare both).
fn rtf_degree(p: &crate::params::Params) -> std::result::Result<Option<usize>, String> {
    match p.get("rtf-degree") {
        None => Ok(None),
        Some(Value::String(s)) if s == "none" => Ok(None),
        Some(Value::Number(d)) if d.fract() == 0.0 && (1.0..=16.0).contains(d) => {
            Ok(Some(*d as usize))
        }
        Some(v) => Err(format!(
            "rtf-degree = {v}; expected a whole number 1…16 or \"none\""
        )),
    }
}

/// Check-time validator of an experiment's `lens` section (built into
/// `hooks::validator`): the same names and values `build_camera` accepts,
/// reported at the property's `file:line:col`.
pub fn validate_lens(
    file: Option<&Path>,
    p: &crate::params::Params,
) -> std::result::Result<(), super::hooks::ParamError> {
    use super::hooks::ParamError;
    let positive = |k: &str| -> std::result::Result<(), ParamError> {
        match p.f64(k) {
            Ok(Some(x)) if !(x > 0.0 && x.is_finite()) => Err(ParamError::new(
                Some(k),
                format!("'{k}' must be a positive number, found {x}"),
            )
            .at_value()),
            Err(e) => Err(ParamError::new(Some(k), e).at_value()),
            _ => Ok(()),
        }
    };
    let Some(file) = file else {
        if let Some(u) = p.unknown(LENS_MODEL_KEYS).first() {
            return Err(ParamError::unknown(u, LENS_MODEL_KEYS));
        }
        for k in ["fov-deg", "f-number", "focal-length-mm", "focus-distance-m"] {
            positive(k)?;
        }
        return match p.str("model") {
            Ok(None | Some("pinhole")) if p.get("fov-deg").is_none() => Err(ParamError::new(
                None,
                "lens model=\"pinhole\" needs fov-deg",
            )),
            Ok(Some("thin-lens")) if p.get("focal-length-mm").is_none() => Err(ParamError::new(
                None,
                "lens model=\"thin-lens\" needs focal-length-mm",
            )),
            Ok(None | Some("pinhole" | "thin-lens")) => Ok(()),
            Ok(Some(other)) => Err(ParamError::new(
                Some("model"),
                format!(
                    "lens model '{other}': expected \"pinhole\" or \"thin-lens\", or a lens file"
                ),
            )
            .at_value()),
            Err(e) => Err(ParamError::new(Some("model"), e).at_value()),
        };
    };
    if let Some(u) = p.unknown(LENS_FILE_KEYS).first() {
        return Err(ParamError::unknown(u, LENS_FILE_KEYS));
    }
    for k in ["film-distance-mm", "focus-distance-m", "rtf-axis-weight"] {
        positive(k)?;
    }
    let degree = rtf_degree(p).map_err(|e| ParamError::new(Some("rtf-degree"), e).at_value())?;
    match degree {
        None if p.get("rtf-axis-weight").is_some() => Err(ParamError::new(
            Some("rtf-axis-weight"),
            "rtf-axis-weight needs rtf-degree",
        )),
        Some(_) => match crate::optics::analysis::load_lens(file) {
            Ok(crate::optics::analysis::LensFile::Rtf(_)) => Err(ParamError::new(
                Some("rtf-degree"),
                "rtf-degree needs a lens prescription to fit, and this file is an RTF",
            )),
            Ok(_) => Ok(()),
            Err(e) => Err(ParamError::new(None, e.to_string())),
        },
        None => Ok(()),
    }
}

/// Build the camera (lens model + pose) of a variant: a lens file (prescription
/// or RTF) with `film-distance-mm` / `focus-distance-m`, an inline
/// `lens model="pinhole" fov-deg=… f-number=…` or
/// `lens model="thin-lens" focal-length-mm=… f-number=… focus-distance-m=…`,
/// or the scene's own camera.
pub fn build_camera(spec: &ResolvedExperiment, scene: &Scene) -> Result<Box<dyn Camera>> {
    let film = film_spec(spec, scene)?;
    if let Some(l) = &spec.lens {
        let p = &l.overrides;
        let fd_mm = p.f64("film-distance-mm").map_err(Error::invalid)?;
        let focus_m = p.f64("focus-distance-m").map_err(Error::invalid)?;
        if let Some(f) = &l.file {
            // The check-time validator is the one list of names and values
            // (variants built without `parse`/`plan` get the same checks).
            validate_lens(Some(&f.path), p)
                .map_err(|e| Error::invalid(format!("lens '{}': {}", f.written, e.message)))?;
            if let Some(d) = rtf_degree(p).map_err(Error::invalid)? {
                let axis_weight = p.f64("rtf-axis-weight").map_err(Error::invalid)?;
                return crate::optics::analysis::fitted_rtf_camera(
                    &f.path,
                    fd_mm.map(|d| d * 1e-3),
                    focus_m,
                    d,
                    axis_weight.unwrap_or(1.0),
                );
            }
            return crate::optics::analysis::load_lens_camera(
                &f.path,
                fd_mm.map(|d| d * 1e-3),
                focus_m,
                None,
            );
        }
        let model = p.str("model").map_err(Error::invalid)?.unwrap_or("pinhole");
        let fnum = p.f64("f-number").map_err(Error::invalid)?.unwrap_or(2.0);
        return match model {
            "pinhole" => {
                let fov = p
                    .f64("fov-deg")
                    .map_err(Error::invalid)?
                    .ok_or_else(|| Error::invalid("lens model=\"pinhole\" needs fov-deg"))?;
                Ok(Box::new(crate::optics::pinhole::Pinhole::new(
                    fov, fnum, &film,
                )?))
            }
            "thin-lens" => {
                let f_mm = p
                    .f64("focal-length-mm")
                    .map_err(Error::invalid)?
                    .ok_or_else(|| {
                        Error::invalid("lens model=\"thin-lens\" needs focal-length-mm")
                    })?;
                let focus = focus_m.unwrap_or(f64::INFINITY);
                Ok(Box::new(crate::optics::thin_lens::ThinLens::new(
                    f_mm * 1e-3,
                    fnum,
                    focus,
                )?))
            }
            other => Err(Error::invalid(format!(
                "lens model '{other}': expected \"pinhole\" or \"thin-lens\", or a lens file"
            ))),
        };
    }
    let cam = scene.camera.as_ref().ok_or_else(|| {
        Error::invalid(format!(
            "experiment '{}' has no camera and no lens",
            spec.name
        ))
    })?;
    match &cam.model {
        CameraModel::Pinhole { .. } => crate::optics::pinhole::camera_from_spec(cam, &film),
        CameraModel::ThinLens {
            focal_length_m,
            f_number,
            focus_distance_m,
        } => Ok(Box::new(crate::optics::thin_lens::ThinLens::new(
            *focal_length_m,
            *f_number,
            *focus_distance_m,
        )?)),
        CameraModel::LensFile {
            path,
            film_distance_m,
            focus_distance_m,
            aperture_diameter_m,
        } => crate::optics::analysis::load_lens_camera(
            path,
            *film_distance_m,
            *focus_distance_m,
            *aperture_diameter_m,
        ),
    }
}

/// Object names whose pixels the measurements read, and whether only the
/// central edge strip is read (slanted edges); None = the whole film.
fn wanted_objects(spec: &ResolvedExperiment) -> Option<Vec<(String, bool)>> {
    let mut v = vec![];
    for m in &spec.measures {
        if m.params.get("input").is_some() {
            continue; // reads a captured image
        }
        match m.kind.as_str() {
            "colorimetry" | "compare" | "convergence" => {}
            "sfr" => v.extend(m.of.iter().map(|o| (o.clone(), true))),
            "profile" | "mcc" if !m.of.is_empty() => {
                v.extend(m.of.iter().map(|o| (o.clone(), false)))
            }
            "mcc" => v.push(("mcc".into(), false)),
            _ => return None,
        }
    }
    Some(v)
}

/// The part of a slanted-edge plate's box that the SFR reads: the central half
/// of its width (both plateaus and the edge) and at most 128 rows about its
/// centre (≥ 11 rows make one phase cycle at 5°).
fn edge_strip(b: Rect) -> Rect {
    let h = (b.h / 2).clamp(8.min(b.h), 128);
    Rect::new(
        b.x + b.w / 4,
        b.y + (b.h - h) / 2,
        (b.w / 2).max(8.min(b.w)),
        h,
    )
}

/// Find the film rectangle holding `objects` with a cheap label pass: a coarse
/// film (≤ 512 px on its long side), 1 spp, primary hits only, through the
/// same camera; boxes are scaled back and padded by two coarse pixels.
fn roi_of_objects(
    scene: &Scene,
    camera: &dyn Camera,
    film: &FilmSpec,
    objects: &[(String, bool)],
) -> Result<(Rect, BTreeMap<String, Rect>)> {
    let k = (film.width_px.max(film.height_px) as f64 / 512.0)
        .ceil()
        .max(1.0) as u32;
    let coarse = FilmSpec {
        width_px: film.width_px.div_ceil(k),
        height_px: film.height_px.div_ceil(k),
        pixel_pitch_m: film.pixel_pitch_m * k as f64,
        crop_window: None,
    };
    let settings = RenderSettings {
        spp: 1,
        max_bounces: 0,
        batches: 1,
        grid: WavelengthGrid::new(550.0, 550.0, 10.0).map_err(Error::invalid)?,
        ..Default::default()
    };
    let img = crate::render::render(scene, camera, &coarse, &settings)?;
    let mut roi: Option<Rect> = None;
    let mut rects = BTreeMap::new();
    for (name, strip) in objects {
        let b = label_box(
            &img.labels,
            &img.label_names,
            img.width(),
            img.height(),
            name,
        )
        .ok_or_else(|| Error::invalid(format!("object '{name}' is not visible from the camera")))?;
        let (x0, y0, x1, y1) = (b.x, b.y, b.x + b.w, b.y + b.h);
        let fx0 = (x0.saturating_sub(2) * k).min(film.width_px - 1);
        let fy0 = (y0.saturating_sub(2) * k).min(film.height_px - 1);
        let fx1 = ((x1 + 2) * k).min(film.width_px);
        let fy1 = ((y1 + 2) * k).min(film.height_px);
        let mut r = Rect::new(fx0, fy0, fx1 - fx0, fy1 - fy0);
        if *strip {
            // the plate's box, less the label-pass padding, then its edge strip
            let inner = Rect::new(
                (x0 * k).min(film.width_px - 1),
                (y0 * k).min(film.height_px - 1),
                ((x1 - x0) * k).min(film.width_px - (x0 * k).min(film.width_px - 1)),
                ((y1 - y0) * k).min(film.height_px - (y0 * k).min(film.height_px - 1)),
            );
            r = edge_strip(inner);
        }
        rects.insert(name.clone(), r);
        roi = Some(roi.map_or(r, |a| a.union(&r)));
    }
    let roi = roi.ok_or_else(|| Error::invalid("no objects to measure"))?;
    Ok((roi, rects))
}

/// The optical image and, per measured object, the film rectangle (full-frame
/// pixels) chosen for it by the label pass.
pub struct Rendered {
    pub oi: OpticalImage,
    pub object_rects: BTreeMap<String, Rect>,
}

/// Render the optical image (only the regions the measurements read).
pub fn render(spec: &ResolvedExperiment, scene: &Scene, camera: &dyn Camera) -> Result<Rendered> {
    let film = film_spec(spec, scene)?;
    let (roi, object_rects) = match wanted_objects(spec) {
        Some(objs) if !objs.is_empty() => {
            let (r, m) = roi_of_objects(scene, camera, &film, &objs)?;
            (Some(r), m)
        }
        _ => (None, BTreeMap::new()),
    };
    let settings = RenderSettings {
        spp: u32::try_from(spec.render.spp)
            .map_err(|_| Error::invalid("render spp is too large"))?,
        max_bounces: spec.render.max_bounces,
        grid: spec.render.wavelength.clone(),
        seed: spec.render.seed,
        roi,
        ..Default::default()
    };
    let oi = crate::render::render(scene, camera, &film, &settings)?;
    Ok(Rendered { oi, object_rects })
}

/// Turn the optical image into sensor digital values.
pub fn simulate_sensor(spec: &ResolvedExperiment, oi: &OpticalImage) -> Result<SensorImage> {
    let cfg = sensor_config(spec)?
        .ok_or_else(|| Error::invalid(format!("experiment '{}' has no sensor", spec.name)))?;
    crate::sensor::simulate(&cfg, oi, spec.render.seed)
}

/// Bounding box (window coordinates) of the pixels labelled `name` (or below
/// it); None when no pixel carries it.
fn label_box(labels: &[u32], names: &[String], w: u32, h: u32, name: &str) -> Option<Rect> {
    let ids: Vec<u32> = names
        .iter()
        .enumerate()
        .filter(|(_, n)| object_matches(n, name))
        .map(|(i, _)| i as u32)
        .collect();
    let (mut x0, mut y0, mut x1, mut y1) = (u32::MAX, u32::MAX, 0u32, 0u32);
    for y in 0..h {
        for x in 0..w {
            if ids.contains(&labels[(y * w + x) as usize]) {
                x0 = x0.min(x);
                y0 = y0.min(y);
                x1 = x1.max(x + 1);
                y1 = y1.max(y + 1);
            }
        }
    }
    (x0 != u32::MAX).then(|| Rect::new(x0, y0, x1 - x0, y1 - y0))
}

/// Run one measurement: figures for results.csv and curves for the report.
/// Its options are read by [`crate::measure::request::checked`] (as at
/// `check`) and it runs in [`crate::measure::request::run`].
pub fn measure(
    m: &Measure,
    spec: &ResolvedExperiment,
    oi: Option<&OpticalImage>,
    si: Option<&SensorImage>,
    object_rects: &BTreeMap<String, Rect>,
) -> Result<Measured> {
    let dir = spec.file.parent().unwrap_or(Path::new("."));
    let opts = crate::measure::request::checked(&m.kind, &m.params, dir)
        .map_err(|e| Error::invalid(format!("measurement '{}': {e}", m.name)))?;
    let inputs = crate::measure::request::Inputs {
        oi,
        si,
        object_rects,
        seed: spec.render.seed,
        grid: &spec.render.wavelength,
    };
    crate::measure::request::run(&m.name, &m.of, &opts, &inputs)
}

/// CIE 1931 chromaticity and luminance of a named spectrum
/// ([`crate::measure::colorimetry`]).
pub fn colorimetry(m: &Measure, spec: &ResolvedExperiment) -> Result<Vec<Figure>> {
    let dir = spec.file.parent().unwrap_or(Path::new("."));
    let o = match crate::measure::request::checked(&m.kind, &m.params, dir)
        .map_err(|e| Error::invalid(format!("measurement '{}': {e}", m.name)))?
    {
        crate::measure::MeasureOptions::Colorimetry(o) => o,
        other => {
            return Err(Error::invalid(format!(
                "measurement '{}' is a '{}', not a colorimetry",
                m.name,
                other.kind()
            )));
        }
    };
    crate::measure::colorimetry::colorimetry(&m.name, &o, &spec.render.wavelength)
}
