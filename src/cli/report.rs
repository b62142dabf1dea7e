//! `camsim diff A B` and `camsim report DIR`.
use camsim::Result;
use camsim::report::diff::{DiffOptions, diff_rows, load_side, summary, write_html};
use clap::Args;
use std::path::PathBuf;

#[derive(Args)]
pub struct DiffArgs {
    /// Results directory or git revision.
    pub a: String,
    /// Results directory or git revision.
    pub b: String,
    /// Significance threshold in σ of |Δ| / √(se_a² + se_b²), as a false-alarm
    /// rate for the whole comparison (Šidák-corrected per figure) unless --per-figure.
    #[arg(long, default_value_t = 3.0)]
    pub threshold: f64,
    /// Test each figure at --threshold itself (no correction for the number of figures).
    #[arg(long)]
    pub per_figure: bool,
    /// Relative floor: changes smaller than this fraction of the value are never significant.
    #[arg(long, default_value_t = 1e-3)]
    pub rel_floor: f64,
    /// Where to write the HTML diff.
    #[arg(long, default_value = "diff.html")]
    pub html: PathBuf,
    /// Path of the results tree inside the repository (for git revisions).
    #[arg(long, default_value = "results")]
    pub git_path: String,
}

pub fn diff(a: DiffArgs) -> Result<i32> {
    if !(a.threshold >= 0.0 && a.rel_floor >= 0.0) {
        return Err(camsim::Error::invalid(
            "--threshold and --rel-floor must be ≥ 0",
        ));
    }
    let opts = DiffOptions {
        threshold_sigma: a.threshold,
        rel_floor: a.rel_floor,
        per_figure: a.per_figure,
    };
    let ra = load_side(&a.a, &a.git_path)?;
    let rb = load_side(&a.b, &a.git_path)?;
    let d = diff_rows(&ra, &rb, &opts);
    print!("{}", summary(&d, &opts));
    write_html(&a.html, &a.a, &a.b, &d, &opts)?;
    eprintln!("wrote {}", a.html.display());
    Ok(if d.significant() > 0 { 1 } else { 0 })
}

#[derive(Args)]
pub struct ReportArgs {
    /// A results directory (`results/<experiment>`) or a results root (then every
    /// experiment's report and `index.html` are written).
    pub dir: PathBuf,
}

pub fn report(a: ReportArgs) -> Result<i32> {
    if a.dir.join("results.csv").exists() {
        camsim::report::write_report(&a.dir)?;
        println!("{}", a.dir.join("report.html").display());
        return Ok(0);
    }
    let rd = std::fs::read_dir(&a.dir).map_err(|e| camsim::Error::io(&a.dir, e))?;
    let mut dirs: Vec<PathBuf> = rd
        .filter_map(|e| e.ok().map(|e| e.path()))
        .filter(|p| p.join("results.csv").exists())
        .collect();
    dirs.sort();
    let mut failed = 0;
    for d in &dirs {
        match camsim::report::write_report(d) {
            Ok(()) => println!("{}", d.join("report.html").display()),
            Err(e) => {
                eprintln!("{e}");
                failed += 1;
            }
        }
    }
    camsim::report::write_index(&a.dir)?;
    println!("{}", a.dir.join("index.html").display());
    Ok(if failed > 0 { 1 } else { 0 })
}
