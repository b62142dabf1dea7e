//! The stages a variant runs through: scene → camera → render → sensor →
//! measure. Each is one function here; the runner knows nothing else. Stages
//! that other modules are still building return `Error::NotSupported`, so a
//! variant that needs them fails with "not supported yet: …" and no number is
//! ever invented. The lead replaces the bodies as the modules land.

use super::spec::{Addition, Measure, ResolvedExperiment};
use crate::figure::Figure;
use crate::image::SensorImage;
use crate::measure::Measured;
use crate::optical_image::{OpticalImage, Rect};
use crate::optics::Camera;
use crate::params::ParamError;
use crate::render::RenderSettings;
use crate::scene::edits::{self, Placement, TargetSpec};
use crate::scene::{CameraModel, CameraPose, CameraSpec, FilmSpec, Scene, look_at_to_world};
use crate::sensor::SensorConfig;
use crate::spectrum::WavelengthGrid;
use crate::{Error, Result};
use glam::DVec3;
use std::collections::BTreeMap;
use std::path::Path;

pub use crate::measure::request::{Needs, needs};

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
    let dir = spec.file.parent().unwrap_or(Path::new("."));
    for name in &spec.removals {
        edits::remove_object(&mut scene, name)?;
    }
    for o in &spec.overrides {
        let os = edits::override_spec(&o.params, dir)
            .map_err(|e| Error::invalid(format!("override '{}': {e}", o.object)))?;
        edits::apply_override(&mut scene, &o.object, &os)?;
    }
    for a in &spec.additions {
        let t = target_spec(a, dir).map_err(|e| Error::invalid(format!("add '{}': {e}", a.id)))?;
        edits::add_target(&mut scene, &t)?;
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
                    cos4: true,
                });
        scene.camera = Some(CameraSpec { to_world, model });
    }
    Ok(scene)
}

/// The placement of an added object, as the scene edits take it.
fn placement(a: &Addition) -> Placement<'_> {
    Placement {
        id: &a.id,
        position_m: a.position_m,
        rotate_deg: a.rotate_deg,
        scale: a.scale,
        file: a.file.as_ref().map(|f| f.path.as_path()),
    }
}

/// The target an `add` node describes (read by check and by run).
pub fn target_spec(a: &Addition, dir: &Path) -> std::result::Result<TargetSpec, ParamError> {
    crate::scene::edits::target_spec(a.target, &placement(a), &a.params, dir)
}

/// The sensor of a variant: its file (or the generic sensor) with its `sensor`
/// node's properties, through the one function that reads them.
pub fn sensor_config(spec: &ResolvedExperiment) -> Result<Option<SensorConfig>> {
    let Some(s) = &spec.sensor else {
        return Ok(None);
    };
    crate::sensor::sensor_config(s.file.as_ref().map(|f| f.path.as_path()), &s.overrides)
        .map(Some)
        .map_err(|e| Error::invalid(format!("sensor: {e}")))
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

/// The camera model of a variant: its `lens` node (through the one function
/// that reads lens properties) or, without one, the scene's own camera.
pub fn camera_model(spec: &ResolvedExperiment, scene: &Scene) -> Result<CameraModel> {
    if let Some(l) = &spec.lens {
        let file = l.file.as_ref().map(|f| f.path.as_path());
        return crate::scene::camera_params::camera_model(file, &l.overrides).map_err(|e| {
            Error::invalid(match &l.file {
                Some(f) => format!("lens '{}': {e}", f.written),
                None => format!("lens: {e}"),
            })
        });
    }
    scene
        .camera
        .as_ref()
        .map(|c| c.model.clone())
        .ok_or_else(|| {
            Error::invalid(format!(
                "experiment '{}' has no camera and no lens",
                spec.name
            ))
        })
}

/// Build the camera (lens model) of a variant on its film, through the one
/// camera factory (`optics::camera::build`).
pub fn build_camera(spec: &ResolvedExperiment, scene: &Scene) -> Result<Box<dyn Camera>> {
    let film = film_spec(spec, scene)?;
    crate::optics::camera::build(&camera_model(spec, scene)?, &film)
}

/// Object names whose pixels the measurements read, and whether only the
/// central edge strip is read (slanted edges); None = the whole film.
fn wanted_objects(spec: &ResolvedExperiment) -> Option<Vec<(String, bool)>> {
    if !spec.save.is_empty() {
        return None; // saved images are whole frames
    }
    let mut v = vec![];
    for m in &spec.measures {
        if m.params.get("input").is_some() {
            continue; // reads a captured image
        }
        match m.kind.as_str() {
            "colorimetry" | "compare" | "compare-curve" | "convergence" => {}
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
        let b = crate::measure::inputs::label_box(
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
            r = crate::measure::sfr::edge_strip(inner);
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

/// The renderer's settings of a variant (its `render` node), whole frame.
pub fn render_settings(spec: &ResolvedExperiment) -> Result<RenderSettings> {
    Ok(RenderSettings {
        spp: u32::try_from(spec.render.spp)
            .map_err(|_| Error::invalid("render spp is too large"))?,
        max_bounces: spec.render.max_bounces,
        grid: spec.render.wavelength.clone(),
        seed: spec.render.seed,
        sampler: spec.render.sampler,
        ..Default::default()
    })
}

/// What a variant's render is asked to do: the film, the settings (with the
/// render window and the sensor's standard-error weights) and, per measured
/// object, the film rectangle chosen for it by the label pass.
pub struct RenderJob {
    pub film: FilmSpec,
    pub settings: RenderSettings,
    pub object_rects: BTreeMap<String, Rect>,
}

/// Render the optical image (only the regions the measurements read).
pub fn render(spec: &ResolvedExperiment, scene: &Scene, camera: &dyn Camera) -> Result<Rendered> {
    let job = render_job(spec, scene, camera)?;
    let oi = crate::render::render(scene, camera, &job.film, &job.settings)?;
    Ok(Rendered {
        oi,
        object_rects: job.object_rects,
    })
}

/// The film, settings and render window of a variant's render (the label
/// pass that finds the window is cheap: ≤ 512 px, 1 spp, primary hits only).
pub fn render_job(
    spec: &ResolvedExperiment,
    scene: &Scene,
    camera: &dyn Camera,
) -> Result<RenderJob> {
    let film = film_spec(spec, scene)?;
    let (roi, object_rects) = match wanted_objects(spec) {
        Some(objs) if !objs.is_empty() => {
            let (r, m) = roi_of_objects(scene, camera, &film, &objs)?;
            (Some(r), m)
        }
        _ => (None, BTreeMap::new()),
    };
    // With a sensor, each pixel also gets the standard error of every CFA
    // channel's electron rate (the noise model adds it to the sensor's noise).
    let stderr_weights = match sensor_config(spec)? {
        Some(cfg) => crate::sensor::pipeline::channel_weights(&cfg, &spec.render.wavelength)
            .iter()
            .map(|w| w.iter().map(|&x| x as f32).collect())
            .collect(),
        None => vec![],
    };
    let settings = RenderSettings {
        roi,
        stderr_weights,
        ..render_settings(spec)?
    };
    Ok(RenderJob {
        film,
        settings,
        object_rects,
    })
}

/// Turn the optical image into sensor digital values.
pub fn simulate_sensor(spec: &ResolvedExperiment, oi: &OpticalImage) -> Result<SensorImage> {
    let cfg = sensor_config(spec)?
        .ok_or_else(|| Error::invalid(format!("experiment '{}' has no sensor", spec.name)))?;
    crate::sensor::simulate(&cfg, oi, spec.render.seed)
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
    let sensor = if crate::measure::request::needs(&m.kind).sensor_config {
        sensor_config(spec)?
    } else {
        None
    };
    let inputs = crate::measure::request::Inputs {
        oi,
        si,
        sensor: sensor.as_ref(),
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

/// `sanity "pov"`: the variant's scene and camera rendered by POV-Ray, one
/// flat colour per object, against camsim's labels (`pov::sanity`). Figures:
/// per object `<object>/iou` and `min_iou`; the side-by-side PNG (camsim |
/// POV-Ray | disagreement) for the report. An object larger than 100 pixels
/// below `min-iou` fails the variant, naming it.
pub fn pov_sanity(spec: &ResolvedExperiment, node: &Measure) -> Result<(Vec<Figure>, Vec<u8>)> {
    let opts = crate::pov::check_params::pov_check(&node.params)
        .map_err(|e| Error::invalid(format!("sanity \"pov\": {e}")))?;
    let scene = build_scene(spec)?;
    let camera = build_camera(spec, &scene)?;
    let film = film_spec(spec, &scene)?;
    let (w, h) = crate::pov::check_params::check_size(&film, opts.width_px, opts.height_px);
    let s = if opts.through_lens {
        crate::pov::check(&scene, camera.as_ref(), &film, w, h)?
    } else {
        crate::pov::check_as_pinhole(&scene, camera.as_ref(), &film, w, h)?
    };
    let failures = s.failures(opts.min_iou);
    if !failures.is_empty() {
        return Err(Error::invalid(format!(
            "sanity \"pov\": {} object(s) disagree with POV-Ray (IoU < {}): {}",
            failures.len(),
            opts.min_iou,
            failures
                .iter()
                .map(|r| format!("{} {:.4}", r.object, r.iou))
                .collect::<Vec<_>>()
                .join(", ")
        )));
    }
    let mut figures: Vec<Figure> = s
        .rows
        .iter()
        .filter(|r| r.counts())
        .map(|r| Figure::new(&node.name, format!("{}/iou", r.object), "1", r.iou, 0.0))
        .collect();
    if let Some(m) = s.min_iou() {
        figures.push(Figure::new(&node.name, "min_iou", "1", m.iou, 0.0));
    }
    Ok((figures, s.side_by_side_png()?))
}
