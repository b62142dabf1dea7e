use camsim::optical_image::Rect;
use camsim::render::{RenderSettings, output};
use camsim::scene::FilmSpec;
use camsim::scene::kdl_scene::load_kdl_scene;
use camsim::{Error, Result};
use clap::Args;
use std::path::PathBuf;

#[derive(Args)]
pub struct RenderArgs {
    /// Scene file (pbrt or KDL).
    pub scene: PathBuf,
    #[arg(long)]
    pub spp: Option<u32>,
    #[arg(long)]
    pub threads: Option<usize>,
    /// Render only this pixel rectangle: x,y,w,h.
    #[arg(long)]
    pub roi: Option<String>,
    #[arg(long, default_value = "render.exr")]
    pub out: PathBuf,
    #[arg(long)]
    pub seed: Option<u64>,
    /// Bounce limit (pbrt's maxdepth; default: the KDL scene's, else 6 —
    /// a pbrt file's Integrator maxdepth is not read).
    #[arg(long)]
    pub max_bounces: Option<u32>,
    /// pbrt scenes: replace the ISET Cornell box placeholder materials by the paper's spectra.
    #[arg(long)]
    pub paper_spectra: bool,
    /// What a pixel records: `irradiance` at the sensor, W/(m²·nm) (default),
    /// or `radiance` along the camera ray, W/(sr·m²·nm), as pbrt's film.
    #[arg(long, value_enum, default_value = "irradiance")]
    pub film: camsim::optics::radiance::FilmQuantity,
    /// pbrt scenes: read as this pbrt version (default: decided by the file's syntax).
    #[arg(long, value_enum)]
    pub pbrt_version: Option<camsim::scene::pbrt::dialect::PbrtVersion>,
}

#[derive(Args)]
pub struct BenchArgs {
    /// Which benchmark: render, parse, sensor.
    pub which: String,
    /// Samples per pixel of the timed render.
    #[arg(long, default_value_t = 16)]
    pub spp: u32,
    /// Samples per pixel of the reference render (for RMSE).
    #[arg(long, default_value_t = 256)]
    pub ref_spp: u32,
    #[arg(long, default_value_t = 2)]
    pub threads: usize,
    /// Wavelength bands carried per path (400–700 nm).
    #[arg(long, default_value_t = 31)]
    pub bands: usize,
    /// render: bounce limit of the timed render (pbrt's count: 0 = emitters
    /// seen directly; Mitsuba's max_depth is one more). The comparison with
    /// Mitsuba is at 6.
    #[arg(long, default_value_t = 6)]
    pub max_bounces: u32,
    /// render: seed of the timed render.
    #[arg(long, default_value_t = 1)]
    pub seed: u64,
    /// render: BVH(s) to time: bvh4 (the renderer's), bvh2, cwbvh, both or all (the first one's image is measured).
    #[arg(long, default_value = "all")]
    pub bvh: String,
    /// render: reference CIE Y image (grey PFM) instead of camsim's own --ref-spp render.
    #[arg(long)]
    pub reference: Option<PathBuf>,
    /// render: per-pixel variance of the reference's mean (grey PFM).
    #[arg(long)]
    pub reference_var: Option<PathBuf>,
    /// render: write the timed render's CIE Y image (grey PFM).
    #[arg(long)]
    pub y_out: Option<PathBuf>,
    /// render: independent sample batches of the timed render (the renderer's
    /// standard-error estimate; each batch is stratified and scrambled on its own).
    #[arg(long, default_value_t = camsim::render::RenderSettings::default().batches)]
    pub batches: u32,
    /// render: the timed render's sampler: sobol (the renderer's default) or independent.
    #[arg(long, default_value = camsim::render::SamplerKind::default().name())]
    pub sampler: String,
}

fn parse_roi(s: &str) -> Result<Rect> {
    let v: Vec<&str> = s.split(',').map(str::trim).collect();
    let bad = || Error::invalid(format!("--roi '{s}': expected x,y,w,h (whole pixels)"));
    if v.len() != 4 {
        return Err(bad());
    }
    let n: Vec<u32> = v
        .iter()
        .map(|x| x.parse::<u32>())
        .collect::<std::result::Result<_, _>>()
        .map_err(|_| bad())?;
    Ok(Rect::new(n[0], n[1], n[2], n[3]))
}

/// Widest sub-band (nm) a pbrt spectral film bucket is averaged over: the
/// midpoint rule over sub-bands this narrow, aligned with 5 nm data knots,
/// reproduces the bucket mean of the measured Cornell-box lamp × walls to
/// 1e-4 (docs/pbrt-radiometry.md); one sample at the bucket centre is off by
/// up to 8 % for 10 nm buckets.
const BUCKET_SUB_BAND_NM: f64 = 2.5;

/// Sub-bands per bucket: enough for ≤ `BUCKET_SUB_BAND_NM` each, as long as
/// the fine image (irradiance and standard error, f32) stays within 1 GiB.
fn bucket_sub_bands(buckets: &camsim::spectrum::WavelengthGrid, pixels: u64) -> usize {
    let want = (buckets.step_nm / BUCKET_SUB_BAND_NM - 1e-9)
        .ceil()
        .max(1.0) as u64;
    let budget = (1u64 << 30) / (8 * pixels.max(1) * buckets.len().max(1) as u64);
    want.min(budget).max(1) as usize
}

pub fn render(a: RenderArgs) -> Result<i32> {
    let ext = a
        .scene
        .extension()
        .and_then(|e| e.to_str())
        .unwrap_or("")
        .to_ascii_lowercase();
    // A pbrt spectral film's buckets (None: the default grid).
    let mut grid = None;
    let sf = if ext == "kdl" {
        load_kdl_scene(&a.scene)?
    } else if ext == "pbrt" || ext == "gz" {
        let loaded = camsim::scene::pbrt::load_full(
            &a.scene,
            &camsim::scene::pbrt::LoadOptions {
                pbrt_version: a.pbrt_version,
                ..Default::default()
            },
        )?;
        grid = loaded.spectral_grid;
        let mut scene = loaded.scene;
        if a.paper_spectra {
            camsim::scene::pbrt::paper::apply_paper_spectra(&mut scene)?;
        }
        camsim::scene::kdl_scene::SceneFile {
            scene,
            spp: None,
            max_bounces: None,
            path: a.scene.clone(),
        }
    } else {
        return Err(Error::invalid(format!(
            "{}: unknown scene format (expected .kdl or .pbrt)",
            a.scene.display()
        )));
    };
    for w in &sf.scene.warnings {
        eprintln!("warning: {w}");
    }
    let film: FilmSpec = sf.scene.film.clone().unwrap_or_default();
    let spec =
        sf.scene.camera.as_ref().ok_or_else(|| {
            Error::invalid(format!("{}: the scene has no camera", a.scene.display()))
        })?;
    let camera = camsim::optics::radiance::for_film(
        camsim::optics::camera::build(&spec.model, &film)?,
        a.film,
    );
    let roi = a.roi.as_deref().map(parse_roi).transpose()?;
    // A pbrt spectral film records each bucket's mean over its width; camsim
    // renders sub-bands and averages them (see `bucket_sub_bands`).
    let buckets = grid.map(|g| {
        let px = roi.map_or(film.width_px as u64 * film.height_px as u64, |r| {
            r.w as u64 * r.h as u64
        });
        let k = bucket_sub_bands(&g, px);
        if g.step_nm / k as f64 > BUCKET_SUB_BAND_NM + 1e-9 {
            eprintln!(
                "warning: spectral film: {} buckets of {:.3} nm are averaged over {k} sub-bands of {:.3} nm \
                 (not ≤ {BUCKET_SUB_BAND_NM} nm: the fine image would exceed 1 GiB)",
                g.len(),
                g.step_nm,
                g.step_nm / k as f64
            );
        }
        (g, k)
    });
    let settings = RenderSettings {
        spp: a.spp.or(sf.spp).unwrap_or(64),
        max_bounces: a.max_bounces.or(sf.max_bounces).unwrap_or(6),
        seed: a.seed.unwrap_or(0),
        threads: a.threads.unwrap_or(0),
        roi,
        grid: buckets
            .as_ref()
            .map(|(g, k)| g.subdivided(*k))
            .unwrap_or_default(),
        ..Default::default()
    };
    let mut img = camsim::render::render(&sf.scene, camera.as_ref(), &film, &settings)?;
    if let Some((g, k)) = buckets {
        img = img.average_band_groups(k, g).map_err(Error::invalid)?;
    }
    let paths = img.window.area() as f64 * settings.spp as f64;
    output::write_exr(&a.out, &img)?;
    let png = a.out.with_extension("png");
    output::write_png_preview(&png, &img)?;
    let json = a.out.with_extension("json");
    let side = serde_json::json!({
        "scene": a.scene.display().to_string(),
        "camera": camera.describe(),
        "film": { "width_px": film.width_px, "height_px": film.height_px, "pixel_pitch_m": film.pixel_pitch_m },
        "window": img.window,
        "spp": img.spp,
        "render_s": img.render_s,
        "paths": paths,
        "paths_per_s": paths / img.render_s.max(1e-9),
        "nan_count": img.nan_count,
        "settings": settings,
        "units": a.film.units(),
        "labels": img.label_names,
        "warnings": sf.scene.warnings,
    });
    output::write_sidecar(&json, &side)?;
    println!(
        "{}: {}×{} px, {} spp, {:.2} s, {:.3} M paths/s, {} non-finite samples dropped → {}, {}, {}",
        a.scene.display(),
        img.width(),
        img.height(),
        img.spp,
        img.render_s,
        paths / img.render_s.max(1e-9) / 1e6,
        img.nan_count,
        a.out.display(),
        png.display(),
        json.display()
    );
    Ok(0)
}

pub fn bench(a: BenchArgs) -> Result<i32> {
    match a.which.as_str() {
        "render" => {
            use camsim::render::BvhKind;
            let bvh = match a.bvh.as_str() {
                "bvh4" => vec![BvhKind::Bvh4],
                "bvh2" => vec![BvhKind::Bvh2],
                "all" => vec![BvhKind::Bvh4, BvhKind::Bvh2, BvhKind::Cwbvh],
                "cwbvh" => vec![BvhKind::Cwbvh],
                "both" => vec![BvhKind::Bvh2, BvhKind::Cwbvh],
                other => {
                    return Err(Error::invalid(format!(
                        "--bvh '{other}': expected bvh4 (the renderer's), bvh2, cwbvh, both (bvh2 and cwbvh) or all"
                    )));
                }
            };
            let sampler = camsim::render::SamplerKind::parse(&a.sampler).ok_or_else(|| {
                Error::invalid(format!(
                    "--sampler '{}': expected {}",
                    a.sampler,
                    camsim::render::SamplerKind::NAMES.join(" or ")
                ))
            })?;
            let r = camsim::render::bench::run(&camsim::render::bench::BenchOptions {
                spp: a.spp,
                ref_spp: a.ref_spp,
                threads: a.threads,
                bands: a.bands,
                max_bounces: a.max_bounces,
                seed: a.seed,
                bvh,
                reference: a.reference,
                reference_var: a.reference_var,
                y_out: a.y_out,
                batches: a.batches,
                sampler,
            })?;
            println!("cpu: {}", camsim::machine::cpu());
            println!("{r}");
            Ok(0)
        }
        "parse" => super::scene::bench_parse(),
        "sensor" => {
            // The simulation and the stream-read floor both run on a pool of
            // --threads threads (0: one per core), as the render bench does.
            let pool = rayon::ThreadPoolBuilder::new()
                .num_threads(a.threads)
                .build()
                .map_err(|e| Error::Invalid(format!("thread pool: {e}")))?;
            println!("{}", pool.install(camsim::sensor::bench_sensor)?);
            Ok(0)
        }
        other => Err(Error::NotSupported(format!(
            "bench '{other}' (available: render, parse, sensor)"
        ))),
    }
}
