use camsim::{Error, Result};
use clap::{Args, Subcommand};
use std::path::PathBuf;

#[derive(Subcommand)]
pub enum LensCmd {
    /// Focal length, f-number, exit pupil, film distance for focus at infinity.
    Info(LensInfoArgs),
    /// Relative illumination vs field height: CSV field_height_mm,relative_illumination.
    Ri(LensRiArgs),
    /// Geometric edge-spread function: CSV position_um,esf,lsf.
    Esf(LensEsfArgs),
    /// Fit a ray-transfer function to a prescription.
    FitRtf(FitRtfArgs),
}

#[derive(Args)]
pub struct LensInfoArgs {
    pub lens: PathBuf,
}
#[derive(Args)]
pub struct LensRiArgs {
    pub lens: PathBuf,
    #[arg(long)]
    pub film_distance_mm: Option<f64>,
    #[arg(long)]
    pub wavelength_nm: Option<f64>,
}
#[derive(Args)]
pub struct LensEsfArgs {
    pub lens: PathBuf,
    #[arg(long)]
    pub object_distance_m: f64,
    #[arg(long)]
    pub film_distance_mm: Option<f64>,
    #[arg(long)]
    pub field_mm: Option<f64>,
}
#[derive(Args)]
pub struct FitRtfArgs {
    pub prescription: PathBuf,
    #[arg(long)]
    pub degree: usize,
    /// Comma-separated wavelengths in nm.
    #[arg(long, value_delimiter = ',')]
    pub wavelengths: Vec<f64>,
    #[arg(long)]
    pub out: PathBuf,
}

pub fn run(_c: LensCmd) -> Result<i32> {
    Err(Error::NotSupported("lens".into()))
}
