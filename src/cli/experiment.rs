//! `camsim check | plan | run | merge` — see docs/experiment-language.md.
//!
//! Exit codes: 0 success; 1 invalid experiment (check/plan), a failed or
//! missing variant (run), an incomplete merge; 2 usage; 3 I/O or other errors.

use camsim::experiment::run::{Outcome, Progress, RunOptions, parse_shard};
use camsim::experiment::{self, DocKind, Loader};
use camsim::{Error, Result};
use clap::Args;
use std::io::IsTerminal;
use std::path::{Path, PathBuf};
use std::sync::Arc;
use std::sync::atomic::{AtomicBool, Ordering};

#[derive(Args)]
pub struct CheckArgs {
    /// Experiment files (or directories of *.kdl files) to validate.
    #[arg(required = true)]
    pub files: Vec<PathBuf>,
}

#[derive(Args)]
pub struct PlanArgs {
    pub file: PathBuf,
    /// Print JSON instead of a table.
    #[arg(long)]
    pub json: bool,
}

#[derive(Args)]
pub struct RunArgs {
    /// Experiment files or directories (default: the embedded experiments/).
    pub paths: Vec<PathBuf>,
    #[arg(long, default_value = "results")]
    pub out: PathBuf,
    #[arg(long)]
    pub threads: Option<usize>,
    #[arg(long)]
    pub seed: Option<u64>,
    /// Cap every variant's samples per pixel at N (a quicker, noisier run of the
    /// same experiments; the cap is part of each variant's input hash).
    #[arg(long, value_name = "N", value_parser = clap::value_parser!(u64).range(1..))]
    pub max_spp: Option<u64>,
    /// Quality preset: `quick` (the default: each experiment's `render` node)
    /// or a preset the experiments define with `quality "NAME" …`, e.g.
    /// `paper` (publication-quality error bars; each experiment states its
    /// targets). An experiment without the preset runs at its own settings.
    #[arg(long, value_name = "NAME")]
    pub quality: Option<String>,
    /// Run shard i of n (1-based), e.g. --shard 2/8.
    #[arg(long)]
    pub shard: Option<String>,
    /// Render every optical image afresh: neither read nor write the
    /// optical-image cache (<out>/.cache/optical-images).
    #[arg(long)]
    pub no_cache: bool,
    /// Size limit of the optical-image cache in GB (10⁹ bytes); the least
    /// recently used images are removed beyond it.
    #[arg(long, value_name = "X", default_value_t = experiment::oi_cache::DEFAULT_MAX_GB, value_parser = parse_gb)]
    pub cache_max_gb: f64,
}

/// A positive, finite size in GB.
fn parse_gb(s: &str) -> std::result::Result<f64, String> {
    match s.trim().parse::<f64>() {
        Ok(x) if x.is_finite() && x > 0.0 => Ok(x),
        _ => Err(format!(
            "expected a positive number of GB (e.g. 4 or 0.5), got '{s}'"
        )),
    }
}

#[derive(Args)]
pub struct MergeArgs {
    /// Shard results directories.
    #[arg(required = true)]
    pub inputs: Vec<PathBuf>,
    #[arg(long)]
    pub out: PathBuf,
}

pub fn check(a: CheckArgs) -> Result<i32> {
    let mut bad = 0;
    for f in &collect(&a.files)? {
        match experiment::parse_file(f, Loader::Disk).and_then(|p| {
            if p.kind == DocKind::Experiment {
                experiment::plan(&p, None).map(|pl| (p, pl.variants.len()))
            } else {
                Ok((p, 0))
            }
        }) {
            Ok((p, n)) => match p.kind {
                DocKind::Experiment => eprintln!(
                    "{}: ok (experiment '{}', {n} variants)",
                    f.display(),
                    p.spec.name
                ),
                DocKind::Setup => eprintln!("{}: ok (setup '{}')", f.display(), p.spec.name),
            },
            Err(e) => {
                bad += 1;
                eprint!("{e}");
            }
        }
    }
    Ok(if bad > 0 { 1 } else { 0 })
}

pub fn plan(a: PlanArgs) -> Result<i32> {
    let p = match experiment::parse_file(&a.file, Loader::Disk) {
        Ok(p) => p,
        Err(e) => {
            eprint!("{e}");
            return Ok(1);
        }
    };
    if p.kind != DocKind::Experiment {
        eprintln!(
            "{}: a setup has no variants; plan the experiments that use it",
            a.file.display()
        );
        return Ok(1);
    }
    match experiment::plan(&p, None) {
        Ok(pl) => {
            print!("{}", if a.json { pl.to_json() } else { pl.to_table() });
            Ok(0)
        }
        Err(e) => {
            eprint!("{e}");
            Ok(1)
        }
    }
}

/// Experiment files named by the arguments: files as given; directories →
/// their `*.kdl` files (sorted), setups skipped later.
pub fn collect(paths: &[PathBuf]) -> Result<Vec<PathBuf>> {
    let mut out = Vec::new();
    for p in paths {
        if p.is_dir() {
            let mut v: Vec<PathBuf> = std::fs::read_dir(p)
                .map_err(|e| Error::io(p, e))?
                .filter_map(|e| e.ok())
                .map(|e| e.path())
                .filter(|x| x.extension().is_some_and(|e| e == "kdl") && x.is_file())
                .collect();
            if v.is_empty() {
                return Err(Error::invalid(format!(
                    "{}: no experiment files (*.kdl) in this directory",
                    p.display()
                )));
            }
            v.sort();
            out.extend(v);
        } else {
            out.push(p.clone());
        }
    }
    Ok(out)
}

struct Bar {
    bar: Option<indicatif::ProgressBar>,
    done: usize,
    total: usize,
}

impl Progress for Bar {
    fn start(&mut self, experiment: &str, variants: usize) {
        self.done = 0;
        self.total = variants;
        if std::io::stderr().is_terminal() {
            let b = indicatif::ProgressBar::new(variants as u64);
            if let Ok(style) = indicatif::ProgressStyle::with_template(
                "{prefix} [{bar:30}] {pos}/{len} {elapsed_precise} {msg}",
            ) {
                b.set_style(style.progress_chars("=> "));
            }
            b.set_prefix(experiment.to_string());
            self.bar = Some(b);
        } else {
            eprintln!("{experiment}: {variants} variants");
        }
    }
    fn variant(&mut self, experiment: &str, id: &str, o: &Outcome) {
        self.done += 1;
        let status = match o {
            Outcome::Done {
                figures,
                total_s,
                oi_cache,
                sampling,
            } => {
                let mut s = format!("ok ({figures} figures, {total_s:.3} s");
                if let Some(c) = oi_cache {
                    s.push_str(&format!(", oi cache {c}"));
                }
                if let Some(x) = sampling {
                    s.push_str(&format!(", {x}"));
                }
                s.push(')');
                s
            }
            Outcome::Cached => "cached".into(),
            Outcome::Failed(e) => format!("FAILED: {e}"),
        };
        match &self.bar {
            Some(b) => {
                if let Outcome::Failed(_) = o {
                    b.println(format!("{experiment} {id}: {status}"));
                }
                b.set_message(id.to_string());
                b.inc(1);
            }
            None => eprintln!("[{}/{}] {experiment} {id}: {status}", self.done, self.total),
        }
    }
    fn finish(&mut self, _experiment: &str) {
        if let Some(b) = self.bar.take() {
            b.finish();
        }
    }
}

pub fn run(a: RunArgs) -> Result<i32> {
    let shard = a.shard.as_deref().map(parse_shard).transpose()?;
    let threads = a.threads.unwrap_or_else(|| {
        std::thread::available_parallelism()
            .map(|n| n.get())
            .unwrap_or(1)
    });
    if threads == 0 {
        return Err(Error::invalid("--threads must be ≥ 1"));
    }
    let _ = rayon::ThreadPoolBuilder::new()
        .num_threads(threads)
        .build_global();
    let (files, loader) = if a.paths.is_empty() {
        (experiment::embedded::paths(), Loader::Embedded)
    } else {
        (collect(&a.paths)?, Loader::Disk)
    };
    let interrupted = Arc::new(AtomicBool::new(false));
    {
        let flag = interrupted.clone();
        let _ = ctrlc::set_handler(move || {
            if flag.swap(true, Ordering::SeqCst) {
                std::process::exit(130);
            }
            eprintln!("\ninterrupted: finishing the variant in flight (Ctrl-C again to stop now)");
        });
    }
    let opts = RunOptions {
        out: a.out.clone(),
        threads,
        seed: a.seed,
        max_spp: a.max_spp,
        quality: a.quality.clone().filter(|q| q != "quick"),
        shard,
        interrupted: interrupted.clone(),
        oi_cache: (!a.no_cache)
            .then(|| experiment::oi_cache::OiCache::under(&a.out, a.cache_max_gb)),
    };
    let mut code = 0;
    let mut ran = 0;
    let mut names: std::collections::BTreeMap<String, PathBuf> = Default::default();
    let mut bar = Bar {
        bar: None,
        done: 0,
        total: 0,
    };
    for f in files {
        let parsed = match experiment::parse_file(&f, loader) {
            Ok(p) => p,
            Err(e) => {
                eprint!("{e}");
                code = 1;
                continue;
            }
        };
        if parsed.kind == DocKind::Setup {
            continue;
        }
        if let Some(prev) = names.insert(parsed.spec.name.clone(), f.clone()) {
            eprintln!(
                "{}: experiment '{}' is also defined in {}; both would write {}",
                f.display(),
                parsed.spec.name,
                prev.display(),
                display(&a.out.join(&parsed.spec.name))
            );
            code = 1;
            continue;
        }
        ran += 1;
        match experiment::run::run_parsed(&parsed, &opts, &mut bar) {
            Ok(s) => {
                eprintln!(
                    "{}: {} done, {} cached, {} failed, {} not run → {}",
                    parsed.spec.name,
                    s.done,
                    s.cached,
                    s.failed,
                    s.not_run,
                    display(&a.out.join(&parsed.spec.name))
                );
                if s.failed > 0 {
                    code = 1;
                }
                if s.interrupted {
                    return Ok(130);
                }
            }
            Err(Error::Located(l)) => {
                eprint!("{l}");
                code = 1;
            }
            Err(e) => {
                eprintln!("{}: {e}", parsed.spec.name);
                code = code.max(1);
            }
        }
    }
    if ran == 0 && code == 0 {
        eprintln!("no experiment to run: the files given hold only setups");
        code = 1;
    }
    Ok(code)
}

fn display(p: &Path) -> String {
    p.display().to_string()
}

pub fn merge(a: MergeArgs) -> Result<i32> {
    let incomplete = experiment::results::merge(&a.inputs, &a.out)?;
    Ok(if incomplete > 0 { 1 } else { 0 })
}
