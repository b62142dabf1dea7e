//! Results on disk, per experiment in `<out>/<experiment>/`:
//!
//! - `variants/<hash16>.csv`: the rows of one finished variant (written
//!   atomically the moment it finishes; `hash16` = first 16 hex digits of the
//!   variant's input hash). A rerun skips every variant whose file exists, so
//!   an interrupted run (Ctrl-C, `kill -9`, power loss) loses at most the
//!   variants in flight and the rerun completes without duplicates.
//! - `results.csv`: long form, one figure a row, assembled from the variant
//!   files in plan order (`experiment,variant,<swept paths…>,measurement,
//!   quantity,unit,value,stderr,render_s,total_s`).
//! - `manifest.json`: git commit and dirty flag, camsim version, thread count,
//!   per-variant id, hash, resolved parameters, seed, status and timings.
//!   A shard run writes `manifest.shard-<i>-of-<n>.json` instead, and the
//!   full `results.csv` + `manifest.json` once every variant of the plan is
//!   present (so shards sharing one output directory finish the job
//!   themselves); `camsim merge` does the same from separate directories.
//!
//! Numbers are written in Rust's shortest round-trip form. Rows are copied
//! between files as text, never re-parsed, so merging is lossless.

use super::plan::Plan;
use crate::diag::write_atomic;
use crate::figure::Figure;
use crate::params::Value;
use crate::{Error, Result};
use serde::{Deserialize, Serialize};
use std::collections::BTreeMap;
use std::path::{Path, PathBuf};

pub const LEADING: &[&str] = &["experiment", "variant"];
pub const TRAILING: &[&str] = &[
    "measurement",
    "quantity",
    "unit",
    "value",
    "stderr",
    "render_s",
    "total_s",
];

/// The header of `results.csv` for the given swept paths.
pub fn header(axes: &[String]) -> Vec<String> {
    LEADING
        .iter()
        .map(|s| s.to_string())
        .chain(axes.iter().cloned())
        .chain(TRAILING.iter().map(|s| s.to_string()))
        .collect()
}

fn csv_line(fields: &[String]) -> String {
    let mut w = csv::WriterBuilder::new()
        .terminator(csv::Terminator::Any(b'\n'))
        .from_writer(vec![]);
    let _ = w.write_record(fields);
    let _ = w.flush();
    String::from_utf8(w.into_inner().unwrap_or_default()).unwrap_or_default()
}

/// Format a number for the CSV (shortest round-trip; "0" for ±0).
pub fn num(x: f64) -> String {
    if x == 0.0 { "0".into() } else { format!("{x}") }
}

/// The CSV text of one variant's figures (header line included).
pub fn variant_csv(
    experiment: &str,
    variant: &str,
    axes: &[String],
    params: &BTreeMap<String, Value>,
    figures: &[Figure],
    render_s: f64,
    total_s: f64,
) -> String {
    let mut s = csv_line(&header(axes));
    for f in figures {
        let mut row = vec![experiment.to_string(), variant.to_string()];
        for a in axes {
            row.push(
                params
                    .get(a)
                    .map(super::apply::fmt_value)
                    .unwrap_or_default(),
            );
        }
        row.extend([
            f.measurement.clone(),
            f.quantity.clone(),
            f.unit.clone(),
            num(f.value),
            num(f.stderr),
            num(render_s),
            num(total_s),
        ]);
        s.push_str(&csv_line(&row));
    }
    s
}

/// Status of one variant in a manifest.
#[derive(Clone, Debug, Serialize, Deserialize, PartialEq)]
pub struct VariantRecord {
    pub index: usize,
    pub id: String,
    pub hash: String,
    pub params: BTreeMap<String, Value>,
    pub seed: u64,
    /// `done`, `cached`, `failed`, `not-run` (interrupted or another shard's).
    pub status: String,
    pub error: Option<String>,
    pub render_s: Option<f64>,
    pub total_s: Option<f64>,
    /// Where its optical image came from: `hit`, `miss` or `off` (`--no-cache`);
    /// absent when the variant renders none.
    #[serde(default, skip_serializing_if = "Option::is_none")]
    pub oi_cache: Option<String>,
    /// The optical image's cache key (hex SHA-256 of everything the render reads).
    #[serde(default, skip_serializing_if = "Option::is_none")]
    pub oi_hash: Option<String>,
    /// Error-driven sampling's record: spp reached, time, why it stopped and
    /// each targeted figure's final standard error against its target.
    #[serde(default, skip_serializing_if = "Option::is_none")]
    pub sampling: Option<super::sampling::SamplingRecord>,
    /// The resolved spec of the variant.
    pub spec: serde_json::Value,
}

#[derive(Clone, Debug, Serialize, Deserialize, PartialEq)]
pub struct Manifest {
    pub experiment: String,
    pub file: PathBuf,
    pub camsim_version: String,
    pub git_commit: String,
    pub git_dirty: Option<bool>,
    pub threads: usize,
    /// The machine's CPU model and vector width (wall times depend on both);
    /// empty in manifests written before it was recorded.
    #[serde(default)]
    pub cpu: String,
    /// The instruction set level the path tracer's kernel ran with
    /// (`render::simd::RenderIsa`: sse, avx2+fma or avx512f; `CAMSIM_RENDER_ISA`
    /// lowers it); empty in manifests written before it was recorded.
    #[serde(default)]
    pub render_isa: String,
    /// True when the path tracer traced 16 paths at a time (`render::film::
    /// packets_enabled`; the same image bits as one at a time); false in
    /// manifests written before it was recorded.
    #[serde(default)]
    pub render_packets: bool,
    /// Packets of 16 paths each image row kept in flight, their rays regrouped
    /// before each cast (`render::film::packets_in_flight`; the same image
    /// bits for any number); 0 in manifests written before it was recorded.
    #[serde(default)]
    pub render_packets_in_flight: usize,
    /// `[i, n]` for a shard run.
    pub shard: Option<[usize; 2]>,
    pub axes: Vec<String>,
    /// `--quality NAME` of the run (absent: the render nodes' own settings).
    #[serde(default, skip_serializing_if = "Option::is_none")]
    pub quality: Option<String>,
    pub wall_s: f64,
    /// True when every variant of the plan has results.
    pub complete: bool,
    pub variants: Vec<VariantRecord>,
    /// The experiment's `summary` nodes (`camsim merge` recomputes them).
    #[serde(default, skip_serializing_if = "Vec::is_empty")]
    pub summaries: Vec<super::summary::SummaryRecord>,
    /// Summaries that failed in the last assembly (reason each).
    #[serde(default, skip_serializing_if = "Vec::is_empty")]
    pub summary_errors: Vec<String>,
}

impl Manifest {
    pub fn new(plan: &Plan, threads: usize, shard: Option<(usize, usize)>) -> Self {
        let (git_commit, git_dirty) = git_info(plan.file.parent().unwrap_or(Path::new(".")));
        let kernel = crate::render::film::Kernel::detect();
        Self {
            experiment: plan.experiment.clone(),
            file: plan.file.clone(),
            camsim_version: plan.camsim_version.clone(),
            git_commit,
            git_dirty,
            threads,
            cpu: crate::machine::cpu().to_string(),
            render_isa: kernel.isa.name().to_string(),
            render_packets: kernel.packets,
            render_packets_in_flight: kernel.reported_in_flight(),
            shard: shard.map(|(i, n)| [i, n]),
            axes: plan.axes.clone(),
            quality: plan.quality.clone(),
            wall_s: 0.0,
            complete: false,
            variants: plan
                .variants
                .iter()
                .map(|v| VariantRecord {
                    index: v.variant.index,
                    id: v.variant.id.clone(),
                    hash: v.hash.clone(),
                    params: v.variant.params.clone(),
                    seed: v.variant.spec.render.seed,
                    status: "not-run".into(),
                    error: None,
                    render_s: None,
                    total_s: None,
                    oi_cache: None,
                    oi_hash: None,
                    sampling: None,
                    spec: serde_json::to_value(&v.variant.spec).unwrap_or_default(),
                })
                .collect(),
            summaries: plan.summaries.clone(),
            summary_errors: vec![],
        }
    }
    pub fn write(&self, path: &Path) -> Result<()> {
        let mut s = serde_json::to_string_pretty(self).map_err(|e| Error::io(path, e))?;
        s.push('\n');
        write_atomic(path, s.as_bytes())
    }
    pub fn read(path: &Path) -> Result<Self> {
        let t = std::fs::read_to_string(path).map_err(|e| Error::io(path, e))?;
        serde_json::from_str(&t).map_err(|e| Error::io(path, format!("not a camsim manifest: {e}")))
    }
}

/// `git rev-parse HEAD` and whether the work tree has changes, run in `dir`;
/// ("unknown", None) when git or the repository is unavailable.
pub fn git_info(dir: &Path) -> (String, Option<bool>) {
    let dir = if dir.as_os_str().is_empty() {
        Path::new(".")
    } else {
        dir
    };
    let out = |args: &[&str]| {
        std::process::Command::new("git")
            .arg("-C")
            .arg(dir)
            .args(args)
            .stderr(std::process::Stdio::null())
            .output()
            .ok()
            .filter(|o| o.status.success())
            .map(|o| String::from_utf8_lossy(&o.stdout).trim().to_string())
    };
    match out(&["rev-parse", "HEAD"]) {
        Some(c) if !c.is_empty() => {
            let dirty =
                out(&["status", "--porcelain", "--untracked-files=no"]).map(|s| !s.is_empty());
            (c, dirty)
        }
        _ => ("unknown".into(), None),
    }
}

/// Paths of one experiment's results.
pub struct ExperimentDir {
    pub root: PathBuf,
}

impl ExperimentDir {
    pub fn new(out: &Path, experiment: &str) -> Self {
        Self {
            root: out.join(experiment),
        }
    }
    pub fn variant_file(&self, short_hash: &str) -> PathBuf {
        self.root.join("variants").join(format!("{short_hash}.csv"))
    }
    pub fn results(&self) -> PathBuf {
        self.root.join("results.csv")
    }
    pub fn manifest(&self) -> PathBuf {
        self.root.join("manifest.json")
    }
    pub fn shard_manifest(&self, i: usize, n: usize) -> PathBuf {
        self.root.join(format!("manifest.shard-{i}-of-{n}.json"))
    }
    /// True when this variant's results exist (and have the expected header).
    pub fn has_variant(&self, short_hash: &str, axes: &[String]) -> bool {
        match std::fs::read_to_string(self.variant_file(short_hash)) {
            Ok(t) => t.starts_with(&csv_line(&header(axes))),
            Err(_) => false,
        }
    }
    /// Assemble `results.csv` from the variant files of `hashes` (plan order).
    /// Returns the text and the number of variants without results.
    pub fn assemble(&self, axes: &[String], hashes: &[&str]) -> Result<(String, usize)> {
        let head = csv_line(&header(axes));
        let mut s = head.clone();
        let mut missing = 0;
        for h in hashes {
            let p = self.variant_file(h);
            match std::fs::read_to_string(&p) {
                Ok(t) if t.starts_with(&head) => s.push_str(&t[head.len()..]),
                Ok(_) => {
                    return Err(Error::io(
                        &p,
                        "variant results have an unexpected header (written by another plan?)",
                    ));
                }
                Err(_) => missing += 1,
            }
        }
        Ok((s, missing))
    }
}

/// Merge shard output directories into `out` (see module docs). Returns the
/// number of experiments that are still incomplete after merging.
pub fn merge(inputs: &[PathBuf], out: &Path) -> Result<usize> {
    // experiment → manifests (with the directory holding their variants/)
    let mut by_exp: BTreeMap<String, Vec<(PathBuf, Manifest)>> = BTreeMap::new();
    for input in inputs {
        let rd = std::fs::read_dir(input).map_err(|e| Error::io(input, e))?;
        let mut dirs: Vec<PathBuf> = rd
            .filter_map(|e| e.ok())
            .map(|e| e.path())
            .filter(|p| p.is_dir())
            .collect();
        dirs.sort();
        let mut found = false;
        for d in dirs {
            let mut files: Vec<PathBuf> = std::fs::read_dir(&d)
                .map_err(|e| Error::io(&d, e))?
                .filter_map(|e| e.ok())
                .map(|e| e.path())
                .filter(|p| {
                    p.file_name()
                        .and_then(|n| n.to_str())
                        .is_some_and(|n| n.starts_with("manifest") && n.ends_with(".json"))
                })
                .collect();
            files.sort();
            for f in files {
                let m = Manifest::read(&f)?;
                found = true;
                by_exp
                    .entry(m.experiment.clone())
                    .or_default()
                    .push((d.clone(), m));
            }
        }
        if !found {
            return Err(Error::io(
                input,
                "no camsim results (no <experiment>/manifest*.json) here",
            ));
        }
    }
    let mut incomplete = 0;
    for (exp, ms) in by_exp {
        let first = &ms[0].1;
        let hashes: Vec<&str> = first.variants.iter().map(|v| v.hash.as_str()).collect();
        for (d, m) in &ms {
            let h: Vec<&str> = m.variants.iter().map(|v| v.hash.as_str()).collect();
            if h != hashes || m.axes != first.axes {
                return Err(Error::invalid(format!(
                    "{}: experiment '{exp}' was planned differently there (other inputs or camsim version); cannot merge",
                    d.display()
                )));
            }
        }
        let dst = ExperimentDir::new(out, &exp);
        let mut merged = first.clone();
        merged.shard = None;
        merged.wall_s = ms.iter().map(|(_, m)| m.wall_s).sum();
        for (d, m) in &ms {
            for (i, v) in m.variants.iter().enumerate() {
                let short = &v.hash[..16.min(v.hash.len())];
                let src = d.join("variants").join(format!("{short}.csv"));
                if let Ok(text) = std::fs::read_to_string(&src) {
                    let target = dst.variant_file(short);
                    match std::fs::read_to_string(&target) {
                        Ok(existing) if existing == text => {}
                        Ok(existing)
                            if target != src && !existing.is_empty() && existing != text =>
                        {
                            // Same inputs, different timings: keep the first, both are valid.
                        }
                        _ => write_atomic(&target, text.as_bytes())?,
                    }
                }
                if matches!(v.status.as_str(), "done" | "cached" | "failed")
                    && merged.variants[i].status == "not-run"
                {
                    merged.variants[i] = v.clone();
                }
            }
        }
        let short: Vec<&str> = hashes.iter().map(|h| &h[..16.min(h.len())]).collect();
        let (mut csv, missing) = dst.assemble(&merged.axes, &short)?;
        merged.complete = missing == 0;
        merged.summary_errors.clear();
        if missing == 0 {
            let (text, errors) = super::summary::append(
                &dst.root,
                &exp,
                &merged.file,
                &merged.axes,
                &csv,
                &merged.summaries,
            )?;
            csv = text;
            for e in &errors {
                eprintln!("camsim merge: experiment '{exp}': {e}");
            }
            if !errors.is_empty() {
                incomplete += 1;
            }
            merged.summary_errors = errors;
        }
        if missing > 0 {
            incomplete += 1;
            eprintln!(
                "camsim merge: experiment '{exp}': {missing} of {} variants have no results",
                hashes.len()
            );
        }
        write_atomic(&dst.results(), csv.as_bytes())?;
        merged.write(&dst.manifest())?;
    }
    Ok(incomplete)
}
