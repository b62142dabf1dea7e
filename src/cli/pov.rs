//! `camsim pov SCENE --out DIR [--width W --height H] [--min-iou X]`: the
//! geometry sanity check against POV-Ray (see `camsim::pov::sanity`);
//! `camsim pov SCENE --out F.pov [--png F.png]`: the shaded export only.

use camsim::pov::sanity::{self, DEFAULT_MIN_IOU};
use camsim::scene::{CameraModel, CameraSpec, FilmSpec, Scene};
use camsim::{Error, Result};
use clap::Args;
use std::path::{Path, PathBuf};

#[derive(Args)]
pub struct PovArgs {
    /// Scene file (.kdl or .pbrt).
    pub scene: PathBuf,
    /// Output directory (scene.pov, iou.csv, side-by-side.png); a path ending
    /// in .pov writes only the shaded POV-Ray scene there.
    #[arg(long)]
    pub out: PathBuf,
    /// With --out F.pov: also render it with `povray` to this PNG.
    #[arg(long)]
    pub png: Option<PathBuf>,
    /// Check image width in pixels (default: the film's, at most 640 on the long side).
    #[arg(long)]
    pub width: Option<u32>,
    /// Check image height in pixels (default: from the width and the film's aspect).
    #[arg(long)]
    pub height: Option<u32>,
    /// Fail (exit 1) when an object larger than 100 pixels has a lower IoU.
    #[arg(long)]
    pub min_iou: Option<f64>,
    /// Render camsim's labels through its pinhole with the camera's field of
    /// view instead of the camera itself (a real lens' distortion is not a
    /// geometry error).
    #[arg(long)]
    pub pinhole: bool,
}

/// Load a KDL or pbrt scene with its own camera and film.
pub fn load_scene(path: &Path) -> Result<camsim::scene::Scene> {
    match path.extension().and_then(|e| e.to_str()).unwrap_or("") {
        "kdl" => Ok(camsim::scene::kdl_scene::load_kdl_scene(path)?.scene),
        "pbrt" | "gz" => {
            camsim::scene::pbrt::load(path, &camsim::scene::pbrt::LoadOptions::default())
        }
        _ => Err(Error::invalid(format!(
            "{}: unknown scene format (expected .kdl or .pbrt)",
            path.display()
        ))),
    }
}

/// The renderer's camera for the scene's own camera model (the one camera
/// factory). Labels come from chief rays (pupil centre), which a lens file's
/// aperture size does not move, so a stopped-down lens file is checked at its
/// full aperture.
fn scene_camera(spec: &CameraSpec, film: &FilmSpec) -> Result<Box<dyn camsim::optics::Camera>> {
    let mut model = spec.model.clone();
    if let CameraModel::LensFile {
        aperture_diameter_m,
        ..
    } = &mut model
        && aperture_diameter_m.take().is_some()
    {
        eprintln!("note: the lens' aperture diameter is not used (labels follow chief rays)");
    }
    camsim::optics::camera::build(&model, film)
}

pub fn pov(a: PovArgs) -> Result<i32> {
    let usage = |m: &str| -> Result<i32> {
        eprintln!("error: {m}");
        Ok(2)
    };
    let export_only = a.out.extension().is_some_and(|e| e == "pov");
    if export_only {
        if a.width.is_some() || a.height.is_some() || a.min_iou.is_some() || a.pinhole {
            return usage(
                "--width, --height, --min-iou and --pinhole need --out DIR (not a .pov file)",
            );
        }
        let scene = load_scene(&a.scene)?;
        let film = scene.film.clone().unwrap_or_default();
        camsim::pov::export_and_render(&scene, &film, &a.out, a.png.as_deref())?;
        println!("{}", a.out.display());
        if let Some(p) = &a.png {
            println!("{}", p.display());
        }
        return Ok(0);
    }
    if a.png.is_some() {
        return usage("--png goes with --out F.pov; with --out DIR the pictures are in DIR");
    }
    if a.width == Some(0) || a.height == Some(0) {
        return usage("--width and --height must be at least 1");
    }
    let min_iou = a.min_iou.unwrap_or(DEFAULT_MIN_IOU);
    if !(0.0..=1.0).contains(&min_iou) {
        return usage(&format!("--min-iou must be in [0, 1], found {min_iou}"));
    }
    if !camsim::pov::povray::available() {
        return Err(Error::invalid(camsim::pov::povray::NOT_INSTALLED));
    }
    let scene: Scene = load_scene(&a.scene)?;
    let film = scene.film.clone().unwrap_or_default();
    let spec = scene
        .camera
        .as_ref()
        .ok_or_else(|| Error::invalid(format!("{}: the scene has no camera", a.scene.display())))?;
    let camera = scene_camera(spec, &film)?;
    let (w, h) = camsim::pov::check_params::check_size(&film, a.width, a.height);
    let s = if a.pinhole {
        sanity::check_as_pinhole(&scene, camera.as_ref(), &film, w, h)?
    } else {
        sanity::check(&scene, camera.as_ref(), &film, w, h)?
    };
    // Everything is computed before the first file is written.
    let csv = s.csv()?;
    let png = s.side_by_side_png()?;
    std::fs::create_dir_all(&a.out).map_err(|e| Error::io(&a.out, e))?;
    camsim::diag::write_atomic(&a.out.join("scene.pov"), s.pov_text.as_bytes())?;
    camsim::diag::write_atomic(&a.out.join("iou.csv"), csv.as_bytes())?;
    camsim::diag::write_atomic(&a.out.join("side-by-side.png"), &png)?;
    let counted = s.rows.iter().filter(|r| r.counts()).count();
    match s.min_iou() {
        Some(r) => println!(
            "minimum IoU {:.4} ({}; {} of {} objects larger than {} px; {}×{} px, pinhole fov {:.3}°)",
            r.iou,
            r.object,
            counted,
            s.rows.len(),
            sanity::MIN_PIXELS,
            w,
            h,
            s.camera.fov_short_deg()
        ),
        None => println!(
            "minimum IoU: no object larger than {} px in the {w}×{h} image",
            sanity::MIN_PIXELS
        ),
    }
    let fails = s.failures(min_iou);
    for r in &fails {
        eprintln!(
            "object '{}': IoU {:.4} < {min_iou} (camsim {} px, POV-Ray {} px)",
            r.object, r.iou, r.pixels_camsim, r.pixels_povray
        );
    }
    println!("{}", a.out.display());
    Ok(if fails.is_empty() { 0 } else { 1 })
}
