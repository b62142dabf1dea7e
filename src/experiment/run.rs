//! The runner: for each planned variant of this shard, skip it when its
//! results exist (same input hash), else run scene → camera → render → sensor
//! → measure through [`super::stages`], write its rows atomically, and go on;
//! a failing variant is reported and the run continues (exit 1 at the end).
//!
//! Sharding: `--shard i/n` (1-based) runs the variants whose plan index `k`
//! satisfies `k mod n = i − 1` (round-robin, so each shard gets a similar mix
//! of cheap and expensive variants of a sweep).
//!
//! Interruption: Ctrl-C (SIGINT) lets the variant in flight finish, then stops
//! and writes the manifest and partial results. `CAMSIM_TEST_ABORT_AFTER=N`
//! (testing only) aborts the process like `kill -9` right after the N-th
//! variant of this process has been written; `CAMSIM_TEST_INTERRUPT_AFTER=N`
//! behaves as if Ctrl-C were pressed at that moment.

use super::oi_cache::{self, CacheUse, OiCache};
use super::parse::Parsed;
use super::plan::{Plan, PlannedVariant};
use super::results::{ExperimentDir, Manifest, variant_csv};
use super::stages;
use crate::figure::Figure;
use crate::{Error, Result};
use std::path::PathBuf;
use std::sync::Arc;
use std::sync::atomic::{AtomicBool, AtomicUsize, Ordering};
use std::time::Instant;

/// Options of a run.
#[derive(Clone, Debug)]
pub struct RunOptions {
    pub out: PathBuf,
    pub threads: usize,
    pub seed: Option<u64>,
    /// Caps every variant's `render.spp` (`--max-spp`).
    pub max_spp: Option<u64>,
    /// `--quality NAME`: the experiments' `quality "NAME"` presets.
    pub quality: Option<String>,
    /// (i, n), 1-based i.
    pub shard: Option<(usize, usize)>,
    /// Set by a Ctrl-C handler: stop after the variant in flight.
    pub interrupted: Arc<AtomicBool>,
    /// The optical-image cache (`<out>/.cache/optical-images`), None with `--no-cache`.
    pub oi_cache: Option<OiCache>,
}

/// What happened to one variant.
#[derive(Clone, Debug, PartialEq)]
pub enum Outcome {
    Done {
        figures: usize,
        total_s: f64,
        /// `hit`, `miss` or `off` when the variant has an optical image.
        oi_cache: Option<&'static str>,
        /// Error-driven sampling: spp reached and why it stopped, e.g.
        /// `spp 512, target met` or `spp 4096, spp-budget: budget reached`.
        sampling: Option<String>,
    },
    Cached,
    Failed(String),
}

/// Receives progress events.
pub trait Progress {
    fn start(&mut self, experiment: &str, variants: usize);
    fn variant(&mut self, experiment: &str, id: &str, outcome: &Outcome);
    fn finish(&mut self, experiment: &str);
}

/// Counts of one experiment's run.
#[derive(Clone, Debug, Default, PartialEq)]
pub struct Summary {
    pub done: usize,
    pub cached: usize,
    pub failed: usize,
    /// Variants of other shards or not reached after an interrupt.
    pub not_run: usize,
    pub interrupted: bool,
}

/// Parse `i/n` (1 ≤ i ≤ n).
pub fn parse_shard(s: &str) -> Result<(usize, usize)> {
    let bad = || {
        Error::invalid(format!(
            "--shard '{s}': expected i/n with 1 ≤ i ≤ n, e.g. --shard 2/8"
        ))
    };
    let (a, b) = s.split_once('/').ok_or_else(bad)?;
    let i: usize = a.trim().parse().map_err(|_| bad())?;
    let n: usize = b.trim().parse().map_err(|_| bad())?;
    if i == 0 || n == 0 || i > n {
        return Err(bad());
    }
    Ok((i, n))
}

/// Is plan index `k` in shard (i, n)?
pub fn in_shard(k: usize, shard: Option<(usize, usize)>) -> bool {
    shard.is_none_or(|(i, n)| k % n == i - 1)
}

static FINISHED_IN_PROCESS: AtomicUsize = AtomicUsize::new(0);

/// End the process as `kill -9` would (tests of interrupted runs): SIGKILL
/// through the `kill` command where there is one (no core dump), else abort.
fn kill_self() -> ! {
    let _ = std::process::Command::new("kill")
        .args(["-9", &std::process::id().to_string()])
        .status();
    std::thread::sleep(std::time::Duration::from_secs(5));
    std::process::abort()
}

/// What one variant produced.
#[derive(Default)]
pub struct VariantOutput {
    pub figures: Vec<Figure>,
    pub render_s: f64,
    /// (measurement name, curves) for `curves/<variant>/<measurement>.csv`.
    pub curves: Vec<(String, Vec<crate::measure::Curve>)>,
    /// Preview images: (file name, PNG bytes, ROI overlay JSON).
    pub previews: Vec<(String, Vec<u8>, String)>,
    /// Where the optical image came from (None: the variant renders none).
    pub oi_cache: Option<CacheUse>,
    /// What error-driven sampling did (None: a fixed sample count).
    pub sampling: Option<super::sampling::SamplingRecord>,
}

/// Run the figures of one variant (no optical-image cache).
pub fn run_variant(v: &PlannedVariant) -> Result<VariantOutput> {
    run_variant_with(v, None, &mut None)
}

/// Run the figures of one variant, its optical image through `cache`;
/// `used` tells where the optical image came from (set also when a later
/// stage fails).
pub fn run_variant_with(
    v: &PlannedVariant,
    cache: Option<&OiCache>,
    used: &mut Option<CacheUse>,
) -> Result<VariantOutput> {
    let spec = &v.variant.spec;
    // `save "dng"` needs the sensor image; a measurement that needs only the
    // sensor's configuration renders nothing.
    let save_dng = spec.save.iter().any(|s| s == "dng");
    let init = stages::Needs {
        optical_image: save_dng,
        sensor_image: save_dng,
        ..stages::Needs::default()
    };
    let need = spec
        .measures
        .iter()
        .fold(init, |a, m| a.union(super::measured::needs_of(m)));
    let need = stages::Needs {
        optical_image: need.optical_image || need.sensor_image,
        ..need
    };
    let mut out = VariantOutput::default();
    let mut oi = None;
    let mut si = None;
    let mut object_rects = std::collections::BTreeMap::new();
    let results;
    if need.optical_image {
        let scene = stages::build_scene(spec)?;
        let camera = stages::build_camera(spec, &scene)?;
        let t = Instant::now();
        let job = stages::render_job(spec, &scene, camera.as_ref())?;
        let model = stages::camera_model(spec, &scene)?;
        // One round's optical image, through the cache (each round is keyed
        // by its own settings: spp and seed).
        let render_round = |settings: &crate::render::RenderSettings| -> Result<(
            crate::optical_image::OpticalImage,
            &'static str,
            String,
        )> {
            let hash = oi_cache::key(&scene, &model, &job.film, settings)?;
            Ok(match cache.map(|c| (c, c.load(&hash))) {
                Some((_, Some(o))) => (o, "hit", hash),
                Some((c, None)) => {
                    let o = crate::render::render(&scene, camera.as_ref(), &job.film, settings)?;
                    match c.store(&hash, &o) {
                        Ok(true) => {}
                        Ok(false) => eprintln!(
                            "note: optical image of '{}' not cached: larger than --cache-max-gb {}",
                            v.variant.id,
                            c.max_bytes as f64 / 1e9
                        ),
                        Err(e) => eprintln!("warning: optical image not cached: {e}"),
                    }
                    (o, "miss", hash)
                }
                None => (
                    crate::render::render(&scene, camera.as_ref(), &job.film, settings)?,
                    "off",
                    hash,
                ),
            })
        };
        let (mut image, mut status, hash) = render_round(&job.settings)?;
        object_rects = job.object_rects.clone();
        out.oi_cache = Some(CacheUse {
            status,
            hash: hash.clone(),
        });
        used.clone_from(&out.oi_cache);
        let mut render_s = t.elapsed().as_secs_f64();
        // Error-driven sampling: more rounds until every figure meets its target.
        let r = &spec.render;
        let targeted = |name: &str| super::sampling::depends_on_render(spec, name);
        let mut round = 0u32;
        let mut history: Vec<(u64, f64)> = vec![];
        loop {
            let s = if need.sensor_image {
                Some(stages::simulate_sensor(spec, &image)?)
            } else {
                None
            };
            let res = super::measured::measure_all(spec, Some(&image), s.as_ref(), &object_rects)?;
            si = s;
            if !r.error_driven() {
                results = res;
                break;
            }
            let figs: Vec<Figure> = res.iter().flat_map(|m| m.figures.iter().cloned()).collect();
            let recs = super::sampling::assess(r, &figs, targeted);
            let n = image.spp as u64;
            let worst = super::sampling::worst_ratio(&recs);
            history.push((n, worst));
            let wall = t.elapsed().as_secs_f64();
            let k = history.len();
            let stop = if recs.iter().all(|f| f.met) {
                Some(super::sampling::Stop::Target)
            } else if r.max_spp.is_some_and(|m| n >= m) {
                Some(super::sampling::Stop::SppBudget)
            } else if k >= 3
                && super::sampling::stalled_round(history[k - 3], history[k - 2])
                && super::sampling::stalled_round(history[k - 2], history[k - 1])
            {
                Some(super::sampling::Stop::Stalled)
            } else {
                let next = super::sampling::next_total(n, worst, r.max_spp);
                // Time of the next round: its samples at this run's render
                // rate, plus one more sensor and measurement pass.
                let per_sample = render_s / n as f64;
                let measure_s = (wall - render_s) / k as f64;
                let projected = wall + per_sample * (next - n) as f64 + measure_s;
                if r.max_s.is_some_and(|m| projected > m) {
                    Some(super::sampling::Stop::TimeBudget)
                } else {
                    round += 1;
                    let settings = crate::render::RenderSettings {
                        spp: u32::try_from(next - n)
                            .map_err(|_| Error::invalid("render spp is too large"))?,
                        seed: super::sampling::round_seed(r.seed, round),
                        ..job.settings.clone()
                    };
                    let t1 = Instant::now();
                    let (more, st, _) = render_round(&settings)?;
                    render_s += t1.elapsed().as_secs_f64();
                    image.combine(&more).map_err(Error::invalid)?;
                    // any round rendered afresh makes the image a miss
                    if st != "hit" {
                        status = st;
                    }
                    None
                }
            };
            if let Some(stop) = stop {
                out.sampling = Some(super::sampling::SamplingRecord {
                    spp: n,
                    rounds: round + 1,
                    render_s,
                    wall_s: t.elapsed().as_secs_f64(),
                    stopped: stop,
                    budget_reached: stop.budget_reached(),
                    figures: recs,
                });
                results = res;
                break;
            }
        }
        out.oi_cache = Some(CacheUse { status, hash });
        used.clone_from(&out.oi_cache);
        out.render_s = render_s;
        oi = Some(image);
    } else {
        results = super::measured::measure_all(spec, None, None, &object_rects)?;
    }
    if let Some(o) = &oi {
        let tmp = tempfile::tempdir().map_err(|e| Error::invalid(format!("temp dir: {e}")))?;
        let p = tmp.path().join("oi.png");
        crate::render::output::write_png_preview(&p, o)?;
        let bytes = std::fs::read(&p).map_err(|e| Error::io(&p, e))?;
        out.previews
            .push(("optical-image.png".into(), bytes, String::new()));
    }
    if let Some(s) = &si {
        // Grey-world white balance for the preview only (raw DVs are untouched).
        let nch = s.cfa.channels.len();
        let mut sum = vec![0.0f64; nch];
        let mut cnt = vec![0usize; nch];
        for y in 0..s.height() {
            for x in 0..s.width() {
                let c = s.channel_at(x, y);
                sum[c] += (s.dv_at(x, y) as f64 - s.black_level_dv).max(0.0);
                cnt[c] += 1;
            }
        }
        let means: Vec<f64> = (0..nch).map(|c| sum[c] / cnt[c].max(1) as f64).collect();
        let top = means.iter().cloned().fold(1e-9, f64::max);
        let neutral: Vec<f64> = means.iter().map(|m| (m / top).max(1e-3)).collect();
        out.previews.push((
            "sensor.png".into(),
            crate::sensor::output::preview_png_bytes(s, &neutral)?,
            String::new(),
        ));
        if save_dng {
            let cfg = stages::sensor_config(spec)?
                .ok_or_else(|| Error::invalid("save \"dng\" needs a sensor (add a sensor node)"))?;
            out.previews.push((
                "sensor-raw-mosaic.png".into(),
                crate::sensor::output::mosaic_png_bytes(s)?,
                String::new(),
            ));
            out.previews.push((
                "sensor.dng".into(),
                crate::sensor::output::dng_bytes(s, &cfg)?,
                String::new(),
            ));
        }
    }
    let mut rois = vec![];
    for (m, r) in spec.measures.iter().zip(results) {
        for f in &r.figures {
            if !f.value.is_finite() || !f.stderr.is_finite() {
                return Err(Error::invalid(format!(
                    "measurement '{}' produced a non-finite {} ({} ± {}); not written",
                    m.name, f.quantity, f.value, f.stderr
                )));
            }
        }
        // Regions read on a captured image are not pixels of the sensor preview.
        let on_sensor = m.params.get("input").is_none();
        for p in r.pixels_read.iter().filter(|_| on_sensor) {
            rois.push(serde_json::json!({"x": p.x, "y": p.y, "w": p.w, "h": p.h, "label": m.name}));
        }
        out.figures.extend(r.figures);
        if !r.curves.is_empty() {
            out.curves.push((m.name.clone(), r.curves));
        }
    }
    if let Some(s) = &spec.sanity {
        let (figures, png) = stages::pov_sanity(spec, s)?;
        out.figures.extend(figures);
        out.previews
            .push(("pov-side-by-side.png".into(), png, String::new()));
    }
    let rois = serde_json::to_string(&rois).unwrap_or_else(|_| "[]".into());
    for p in &mut out.previews {
        if p.0 == "sensor.png" {
            p.2 = rois.clone();
        }
    }
    Ok(out)
}

/// Run one planned experiment.
pub fn run_plan(plan: &Plan, opts: &RunOptions, progress: &mut dyn Progress) -> Result<Summary> {
    let t0 = Instant::now();
    let dir = ExperimentDir::new(&opts.out, &plan.experiment);
    std::fs::create_dir_all(dir.root.join("variants")).map_err(|e| Error::io(&dir.root, e))?;
    let mut manifest = Manifest::new(plan, opts.threads, opts.shard);
    let mut sum = Summary::default();
    let mine: Vec<&PlannedVariant> = plan
        .variants
        .iter()
        .filter(|v| in_shard(v.variant.index, opts.shard))
        .collect();
    progress.start(&plan.experiment, mine.len());
    let abort_after: Option<usize> = std::env::var("CAMSIM_TEST_ABORT_AFTER")
        .ok()
        .and_then(|s| s.parse().ok());
    let interrupt_after: Option<usize> = std::env::var("CAMSIM_TEST_INTERRUPT_AFTER")
        .ok()
        .and_then(|s| s.parse().ok());
    for v in &mine {
        if opts.interrupted.load(Ordering::SeqCst) {
            sum.interrupted = true;
            break;
        }
        let rec = &mut manifest.variants[v.variant.index];
        let outcome = if dir.has_variant(v.short_hash(), &plan.axes) {
            rec.status = "cached".into();
            sum.cached += 1;
            Outcome::Cached
        } else {
            let t = Instant::now();
            let mut used = None;
            let result = run_variant_with(v, opts.oi_cache.as_ref(), &mut used);
            rec.oi_cache = used.as_ref().map(|c| c.status.to_string());
            rec.oi_hash = used.as_ref().map(|c| c.hash.clone());
            match result {
                Ok(vo) => {
                    let (figs, render_s) = (&vo.figures, vo.render_s);
                    // Curves and previews first: a variant CSV on disk means its
                    // side files are complete.
                    for (name, curves) in &vo.curves {
                        crate::report::results::write_curves(
                            &dir.root,
                            &v.variant.id,
                            name,
                            curves,
                        )?;
                    }
                    for (name, png, rois) in &vo.previews {
                        let p = dir.root.join("previews").join(&v.variant.id).join(name);
                        crate::diag::write_atomic(&p, png)?;
                        if !rois.is_empty() {
                            crate::diag::write_atomic(
                                &p.with_extension("rois.json"),
                                rois.as_bytes(),
                            )?;
                        }
                    }
                    let total_s = t.elapsed().as_secs_f64();
                    let csv = variant_csv(
                        &plan.experiment,
                        &v.variant.id,
                        &plan.axes,
                        &v.variant.params,
                        figs,
                        render_s,
                        total_s,
                    );
                    crate::diag::write_atomic(&dir.variant_file(v.short_hash()), csv.as_bytes())?;
                    rec.status = "done".into();
                    rec.render_s = Some(render_s);
                    rec.total_s = Some(total_s);
                    rec.sampling = vo.sampling.clone();
                    sum.done += 1;
                    let n = FINISHED_IN_PROCESS.fetch_add(1, Ordering::SeqCst) + 1;
                    if abort_after.is_some_and(|k| n >= k) {
                        kill_self();
                    }
                    if interrupt_after.is_some_and(|k| n >= k) {
                        opts.interrupted.store(true, Ordering::SeqCst);
                    }
                    Outcome::Done {
                        figures: figs.len(),
                        total_s,
                        oi_cache: vo.oi_cache.as_ref().map(|c| c.status),
                        sampling: vo.sampling.as_ref().map(|r| {
                            if r.budget_reached {
                                format!("spp {}, {}: budget reached", r.spp, r.stopped.as_str())
                            } else {
                                format!("spp {}, target met", r.spp)
                            }
                        }),
                    }
                }
                Err(e) => {
                    rec.status = "failed".into();
                    rec.error = Some(e.to_string());
                    sum.failed += 1;
                    Outcome::Failed(e.to_string())
                }
            }
        };
        progress.variant(&plan.experiment, &v.variant.id, &outcome);
    }
    sum.not_run = plan.variants.len() - sum.done - sum.cached - sum.failed;
    manifest.wall_s = t0.elapsed().as_secs_f64();
    let all: Vec<&str> = plan.variants.iter().map(|v| v.short_hash()).collect();
    let (mut csv, missing) = dir.assemble(&plan.axes, &all)?;
    manifest.complete = missing == 0;
    if missing == 0 {
        // The cross-variant stage: every variant has results.
        let (text, errors) = super::summary::append(
            &dir.root,
            &plan.experiment,
            &plan.file,
            &plan.axes,
            &csv,
            &plan.summaries,
        )?;
        csv = text;
        for e in &errors {
            eprintln!("camsim: experiment '{}': {e}", plan.experiment);
        }
        sum.failed += errors.len();
        manifest.summary_errors = errors;
    }
    // Variants of other shards that already have results (shared output directory).
    for (rec, v) in manifest.variants.iter_mut().zip(&plan.variants) {
        if rec.status == "not-run"
            && !in_shard(v.variant.index, opts.shard)
            && dir.has_variant(v.short_hash(), &plan.axes)
        {
            rec.status = "cached".into();
        }
    }
    match opts.shard {
        Some((i, n)) => {
            manifest.write(&dir.shard_manifest(i, n))?;
            if missing == 0 {
                crate::diag::write_atomic(&dir.results(), csv.as_bytes())?;
                let mut full = manifest.clone();
                full.shard = None;
                full.write(&dir.manifest())?;
            }
        }
        None => {
            crate::diag::write_atomic(&dir.results(), csv.as_bytes())?;
            manifest.write(&dir.manifest())?;
        }
    }
    if dir.results().exists() {
        if let Err(e) = crate::report::html::write_report(&dir.root) {
            eprintln!("warning: report for '{}' not written: {e}", plan.experiment);
        }
        if let Err(e) = crate::report::html::write_index(&opts.out) {
            eprintln!("warning: results index not written: {e}");
        }
    }
    progress.finish(&plan.experiment);
    Ok(sum)
}

/// Plan and run a parsed experiment.
pub fn run_parsed(
    parsed: &Parsed,
    opts: &RunOptions,
    progress: &mut dyn Progress,
) -> Result<Summary> {
    let plan = super::plan::plan_with(
        parsed,
        super::plan::PlanOverrides {
            seed: opts.seed,
            max_spp: opts.max_spp,
            quality: opts.quality.clone(),
        },
    )?;
    run_plan(&plan, opts, progress)
}
