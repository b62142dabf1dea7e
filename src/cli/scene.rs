use camsim::{Error, Result};
use clap::{Args, Subcommand};
use std::path::PathBuf;

#[derive(Subcommand)]
pub enum SceneCmd {
    /// Print JSON: counts of shapes, triangles, instances, lights, materials; camera, film, bounds, warnings.
    Info(InfoArgs),
}

#[derive(Args)]
pub struct InfoArgs {
    pub scene: PathBuf,
    /// Treat warnings (unsupported features, unused parameters) as errors.
    #[arg(long)]
    pub strict: bool,
}

pub fn run(_c: SceneCmd) -> Result<i32> {
    Err(Error::NotSupported("scene info".into()))
}
