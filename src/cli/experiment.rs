use camsim::{Error, Result};
use clap::Args;
use std::path::PathBuf;

#[derive(Args)]
pub struct CheckArgs {
    /// Experiment files to validate.
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
    /// Run shard i of n (1-based), e.g. --shard 2/8.
    #[arg(long)]
    pub shard: Option<String>,
}

#[derive(Args)]
pub struct MergeArgs {
    /// Shard results directories.
    #[arg(required = true)]
    pub inputs: Vec<PathBuf>,
    #[arg(long)]
    pub out: PathBuf,
}

pub fn check(_a: CheckArgs) -> Result<i32> {
    Err(Error::NotSupported("check".into()))
}
pub fn plan(_a: PlanArgs) -> Result<i32> {
    Err(Error::NotSupported("plan".into()))
}
pub fn run(_a: RunArgs) -> Result<i32> {
    Err(Error::NotSupported("run".into()))
}
pub fn merge(_a: MergeArgs) -> Result<i32> {
    Err(Error::NotSupported("merge".into()))
}
