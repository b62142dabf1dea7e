//! The `camsim` command line. Data goes to stdout, diagnostics to stderr.
//!
//! Exit codes: 0 success; 1 the command ran and found a problem (invalid
//! experiment in `check`, significant change in `diff`, a failed variant in
//! `run`); 2 usage error (bad flags); 3 an error that stopped the command
//! (unreadable input, a stage not supported yet, I/O).

mod cli;

use clap::{Parser, Subcommand};

#[derive(Parser)]
#[command(
    name = "camsim",
    version,
    about = "Physics-based camera simulation: scene → optics → sensor → measurements"
)]
struct Cli {
    #[command(subcommand)]
    command: Command,
}

#[derive(Subcommand)]
enum Command {
    /// Validate experiment files (exit 0 when all are valid, 1 otherwise).
    Check(cli::experiment::CheckArgs),
    /// Print every property of the experiment language (Markdown tables).
    Params,
    /// List the expanded variants of an experiment with their resolved parameters.
    Plan(cli::experiment::PlanArgs),
    /// Run experiments (default: the embedded experiments/ directory).
    Run(cli::experiment::RunArgs),
    /// Merge shard results directories into one.
    Merge(cli::experiment::MergeArgs),
    /// Write (and with --submit, submit) a sweep as a Slurm job array plus a merge job.
    Slurm(cli::slurm::SlurmArgs),
    /// Render a scene file's own camera and film to a spectral EXR.
    Render(cli::render::RenderArgs),
    /// Benchmarks (renderer throughput and equal-time error, parser throughput, sensor).
    Bench(cli::render::BenchArgs),
    /// Scene tools.
    #[command(subcommand)]
    Scene(cli::scene::SceneCmd),
    /// Lens analysis and ray-transfer-function fitting.
    #[command(subcommand)]
    Lens(cli::lens::LensCmd),
    /// Sensor simulation and calibration.
    #[command(subcommand)]
    Sensor(cli::sensor::SensorCmd),
    /// Measure simulated or captured images.
    #[command(subcommand)]
    Measure(cli::measure::MeasureCmd),
    /// Compare two results directories or git revisions.
    Diff(cli::report::DiffArgs),
    /// Write report.html for a results directory (and index.html for a results root).
    Report(cli::report::ReportArgs),
    /// Export a scene to POV-Ray (geometry sanity image); render it with --png.
    Pov(cli::pov::PovArgs),
}

fn main() {
    let cli = match Cli::try_parse() {
        Ok(c) => c,
        Err(e) => {
            let code = if e.use_stderr() { 2 } else { 0 };
            let _ = e.print();
            std::process::exit(code);
        }
    };
    let result = match cli.command {
        Command::Check(a) => cli::experiment::check(a),
        Command::Params => {
            print!("{}", camsim::experiment::language::markdown());
            Ok(0)
        }
        Command::Plan(a) => cli::experiment::plan(a),
        Command::Run(a) => cli::experiment::run(a),
        Command::Merge(a) => cli::experiment::merge(a),
        Command::Slurm(a) => cli::slurm::slurm(a),
        Command::Render(a) => cli::render::render(a),
        Command::Bench(a) => cli::render::bench(a),
        Command::Scene(c) => cli::scene::run(c),
        Command::Lens(c) => cli::lens::run(c),
        Command::Sensor(c) => cli::sensor::run(c),
        Command::Measure(c) => cli::measure::run(c),
        Command::Diff(a) => cli::report::diff(a),
        Command::Report(a) => cli::report::report(a),
        Command::Pov(a) => cli::pov::pov(a),
    };
    match result {
        Ok(code) => std::process::exit(code),
        Err(e) => {
            eprintln!("{e}");
            std::process::exit(3);
        }
    }
}
