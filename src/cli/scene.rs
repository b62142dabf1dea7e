use camsim::Result;
use camsim::scene::pbrt::{LoadOptions, info_json, load_full};
use clap::{Args, Subcommand};
use std::path::PathBuf;

#[derive(Subcommand)]
pub enum SceneCmd {
    /// Print JSON: counts of shapes, triangles, instances, lights, materials; camera, film, bounds,
    /// the pbrt version the file is read as, where camsim differs from pbrt, warnings.
    Info(InfoArgs),
}

#[derive(Args)]
pub struct InfoArgs {
    pub scene: PathBuf,
    /// Treat warnings (unsupported features, unused parameters) as errors.
    #[arg(long)]
    pub strict: bool,
    /// Read the file as this pbrt version (default: decided by its syntax).
    #[arg(long, value_enum)]
    pub pbrt_version: Option<camsim::scene::pbrt::dialect::PbrtVersion>,
}

pub fn run(c: SceneCmd) -> Result<i32> {
    match c {
        SceneCmd::Info(a) => {
            let l = load_full(
                &a.scene,
                &LoadOptions {
                    strict: a.strict,
                    pbrt_version: a.pbrt_version,
                },
            )?;
            let text = serde_json::to_string_pretty(&info_json(&l))
                .map_err(|e| camsim::Error::invalid(e.to_string()))?;
            use std::io::Write;
            // A closed pipe (e.g. `| head`) is not an error worth a panic.
            let _ = writeln!(std::io::stdout(), "{text}");
            Ok(0)
        }
    }
}

/// `camsim bench parse`: parse a generated ~100 MB `trianglemesh` file on one core and
/// print MB/s and peak memory as JSON (to be dispatched from `cli::render::bench`).
pub fn bench_parse() -> Result<i32> {
    let r = camsim::scene::pbrt::bench::run_parse_benchmark(100.0)?;
    let text =
        serde_json::to_string_pretty(&r).map_err(|e| camsim::Error::invalid(e.to_string()))?;
    use std::io::Write;
    let _ = writeln!(std::io::stdout(), "{text}");
    Ok(0)
}
