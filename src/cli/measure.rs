use camsim::{Error, Result};
use clap::{Args, Subcommand};
use std::path::PathBuf;

#[derive(Subcommand)]
pub enum MeasureCmd {
    /// Slanted-edge SFR: CSV freq_cy_per_px,freq_cy_per_mm,mtf.
    Sfr(SfrArgs),
}

#[derive(Args)]
pub struct SfrArgs {
    pub image: PathBuf,
    #[arg(long)]
    pub roi: Option<String>,
    #[arg(long)]
    pub pixel_um: Option<f64>,
    #[arg(long, default_value = "lum")]
    pub channel: String,
}

pub fn run(_c: MeasureCmd) -> Result<i32> {
    Err(Error::NotSupported("measure".into()))
}
