//! `camsim sensor simulate|calibrate`: flat-field sequences and their photon-transfer
//! analysis (library: `camsim::sensor::flatfield`, `camsim::sensor::calibrate`).

use camsim::sensor::calibrate::photon_transfer;
use camsim::sensor::flatfield::{
    FlatOptions, load_sensor, read_flat_sequences, write_flat_sequence,
};
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
    /// Sensor file (KDL) or shipped sensor name (imx363, imx363-nominal, generic).
    pub sensor: PathBuf,
    /// Mean spectral irradiance at the sensor over 400–700 nm, W/(m²·nm).
    #[arg(long = "flat-irradiance-w-m2-nm")]
    pub flat_irradiance_w_m2_nm: f64,
    /// Spectral shape (a shipped spectrum name, e.g. cie-d65); default flat.
    #[arg(long)]
    pub spectrum: Option<String>,
    #[arg(long)]
    pub exposure_s: f64,
    #[arg(long)]
    pub frames: usize,
    /// Output directory (frame_0000.png …, settings.csv).
    #[arg(long)]
    pub out: PathBuf,
    /// Dark frames (no light; same exposure).
    #[arg(long)]
    pub dark: bool,
    #[arg(long)]
    pub seed: Option<u64>,
    /// Frame size WxH, centred on the sensor (default 512x512).
    #[arg(long, default_value = "512x512")]
    pub size: String,
    /// Also write every frame as DNG (raw converters open it).
    #[arg(long)]
    pub dng: bool,
}

#[derive(Args)]
pub struct CalibrateArgs {
    /// Directory of sequences (itself and/or one subdirectory per level, each with settings.csv).
    pub dir: PathBuf,
    /// CFA channel to analyse.
    #[arg(long, default_value = "g")]
    pub channel: String,
}

pub fn run(c: SensorCmd) -> Result<i32> {
    match c {
        SensorCmd::Simulate(a) => simulate(a),
        SensorCmd::Calibrate(a) => calibrate(a),
    }
}

fn parse_size(s: &str) -> Result<(u32, u32)> {
    let (w, h) = s
        .split_once(['x', 'X'])
        .ok_or_else(|| Error::invalid(format!("--size '{s}': expected WxH, e.g. 512x512")))?;
    let p = |v: &str| v.trim().parse::<u32>().ok().filter(|&n| n > 0);
    match (p(w), p(h)) {
        (Some(w), Some(h)) => Ok((w, h)),
        _ => Err(Error::invalid(format!(
            "--size '{s}': expected positive integers WxH"
        ))),
    }
}

fn simulate(a: SimulateArgs) -> Result<i32> {
    let cfg = load_sensor(&a.sensor)?;
    let (width, height) = parse_size(&a.size)?;
    let o = FlatOptions {
        irradiance_w_m2_nm: a.flat_irradiance_w_m2_nm,
        spectrum: a.spectrum,
        exposure_s: a.exposure_s,
        frames: a.frames,
        dark: a.dark,
        seed: a.seed.unwrap_or(1),
        width,
        height,
        dng: a.dng,
    };
    write_flat_sequence(&cfg, &o, &a.out)?;
    eprintln!(
        "wrote {} frames{} and settings.csv to {}",
        o.frames,
        if o.dng { " (PNG and DNG)" } else { "" },
        a.out.display()
    );
    Ok(0)
}

fn calibrate(a: CalibrateArgs) -> Result<i32> {
    let seqs = read_flat_sequences(&a.dir, &a.channel)?;
    for (d, s) in &seqs {
        if s.frames.len() < 2 {
            return Err(Error::io(
                d,
                "a sequence needs at least 2 frames (temporal noise comes from frame pairs)",
            ));
        }
    }
    let only: Vec<_> = seqs.iter().map(|(_, s)| s.clone()).collect();
    let pt =
        photon_transfer(&only).map_err(|m| Error::invalid(format!("{}: {m}", a.dir.display())))?;
    eprintln!(
        "{} sequences ({} dark), {} light levels in the K fit, channel {}",
        seqs.len(),
        only.iter().filter(|s| s.dark).count(),
        pt.fit_levels.len(),
        a.channel
    );
    if pt.saturation_e.is_none() {
        eprintln!(
            "saturation not reached (no level beyond the variance maximum): saturation_capacity omitted"
        );
    }
    println!("quantity,unit,value,stderr");
    for f in pt.figures() {
        println!("{},{},{},{}", f.quantity, f.unit, f.value, f.stderr);
    }
    Ok(0)
}
