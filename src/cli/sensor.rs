use camsim::{Error, Result};
use clap::{Args, Subcommand};
use std::path::PathBuf;

#[derive(Subcommand)]
pub enum SensorCmd {
    /// Write a flat-field frame sequence for photon-transfer analysis.
    Simulate(SimulateArgs),
    /// Estimate K, read noise, DSNU, PRNU, saturation from a flat-field sequence.
    Calibrate(CalibrateArgs),
}

#[derive(Args)]
pub struct SimulateArgs {
    pub sensor: PathBuf,
    #[arg(long = "flat-irradiance-w-m2-nm")]
    pub flat_irradiance_w_m2_nm: f64,
    #[arg(long)]
    pub spectrum: Option<String>,
    #[arg(long)]
    pub exposure_s: f64,
    #[arg(long)]
    pub frames: usize,
    #[arg(long)]
    pub out: PathBuf,
    #[arg(long)]
    pub dark: bool,
    #[arg(long)]
    pub seed: Option<u64>,
}

#[derive(Args)]
pub struct CalibrateArgs {
    pub dir: PathBuf,
}

pub fn run(_c: SensorCmd) -> Result<i32> {
    Err(Error::NotSupported("sensor".into()))
}
