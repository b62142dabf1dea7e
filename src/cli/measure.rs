//! `camsim measure …`: the measurements on captured or simulated image files
//! (PNG 8/16-bit, OpenEXR, DNG). Output is CSV on stdout; figures follow as
//! `# quantity=value ± stderr unit` comment lines.
use camsim::measure::io::{LoadedImage, read_image, read_label_map_for};
use camsim::measure::plane::{Plane, parse_rect};
use camsim::measure::{Measured, mcc, noise, profile, ri, sfr};
use camsim::{Error, Result};
use clap::{Args, Subcommand};
use std::path::PathBuf;

#[derive(Subcommand)]
pub enum MeasureCmd {
    /// Slanted-edge SFR: CSV freq_cy_per_px,freq_cy_per_mm,mtf.
    Sfr(SfrArgs),
    /// Uniform-region noise (paper Appendix IV): CSV of accepted regions x,y,mean_dv,std_dv.
    Noise(NoiseArgs),
    /// Relative illumination from a flat field: CSV field_height,ri,stderr.
    Ri(RiArgs),
    /// Line profile through labelled objects: CSV position_px,<channel>… and ratios.
    Profile(ProfileArgs),
    /// MCC patch means from a label map: CSV patch,channel,mean_dv,stderr_dv,pixels.
    Mcc(MccArgs),
}

#[derive(Args)]
pub struct SfrArgs {
    pub image: PathBuf,
    /// Region of interest x,y,w,h in pixels (default: whole image).
    #[arg(long)]
    pub roi: Option<String>,
    /// Pixel pitch in micrometres (for cy/mm).
    #[arg(long)]
    pub pixel_um: Option<f64>,
    #[arg(long, default_value = "lum")]
    pub channel: String,
    /// Degree of the edge polynomial fit (1 = straight edge).
    #[arg(long, default_value_t = 1)]
    pub fit_degree: usize,
}

#[derive(Args)]
pub struct NoiseArgs {
    pub image: PathBuf,
    /// Conversion gain, DV per electron.
    #[arg(long)]
    pub conversion_gain: f64,
    #[arg(long)]
    pub roi: Option<String>,
    #[arg(long, default_value_t = 500)]
    pub regions: usize,
    #[arg(long, default_value_t = 10)]
    pub region_px: usize,
    #[arg(long, default_value_t = 1)]
    pub seed: u64,
    #[arg(long, default_value = "g")]
    pub channel: String,
    /// Read noise in electrons (added in quadrature to the Poisson σ of the 3σ test).
    #[arg(long, default_value_t = 0.0)]
    pub read_noise_e: f64,
}

#[derive(Args)]
pub struct RiArgs {
    pub image: PathBuf,
    #[arg(long)]
    pub pixel_um: Option<f64>,
    #[arg(long, default_value_t = 20)]
    pub bins: usize,
    #[arg(long, default_value = "g")]
    pub channel: String,
}

#[derive(Args)]
pub struct LabelArgs {
    /// Label map: grey PNG, value k = object k (0 = none).
    #[arg(long)]
    pub labels: PathBuf,
    /// Object names, line k names label value k.
    #[arg(long)]
    pub names: PathBuf,
}

#[derive(Args)]
pub struct ProfileArgs {
    pub image: PathBuf,
    #[command(flatten)]
    pub label: LabelArgs,
    /// Objects the line passes through, comma-separated.
    #[arg(long, value_delimiter = ',', required = true)]
    pub objects: Vec<String>,
    #[arg(long, default_value_t = 4)]
    pub band_px: usize,
    #[arg(long)]
    pub vertical: bool,
}

#[derive(Args)]
pub struct MccArgs {
    pub image: PathBuf,
    #[command(flatten)]
    pub label: LabelArgs,
    /// Chart object name; patches are `<chart>/patch01` … `<chart>/patch24`.
    #[arg(long, default_value = "mcc")]
    pub chart: String,
    /// Erosion radius as a fraction of the patch's smaller side.
    #[arg(long, default_value_t = 0.15)]
    pub erode: f64,
}

pub fn run(c: MeasureCmd) -> Result<i32> {
    match c {
        MeasureCmd::Sfr(a) => run_sfr(a),
        MeasureCmd::Noise(a) => run_noise(a),
        MeasureCmd::Ri(a) => run_ri(a),
        MeasureCmd::Profile(a) => run_profile(a),
        MeasureCmd::Mcc(a) => run_mcc(a),
    }
}

fn roi_plane(img: &LoadedImage, channel: &str, roi: &Option<String>) -> Result<Plane> {
    let p = img.plane_for(channel)?;
    match roi {
        Some(r) => p.crop(parse_rect(r)?).map_err(|e| Error::io(&img.path, e)),
        None => Ok(p),
    }
}

fn print_figures(m: &Measured) {
    for f in &m.figures {
        println!("# {}={} ± {} {}", f.quantity, f.value, f.stderr, f.unit);
    }
}

fn run_sfr(a: SfrArgs) -> Result<i32> {
    let img = read_image(&a.image)?;
    let plane = roi_plane(&img, &a.channel, &a.roi)?;
    let pitch_m = a.pixel_um.map(|p| p * 1e-6);
    if let Some(p) = a.pixel_um.filter(|p| !p.is_finite() || *p <= 0.0) {
        return Err(Error::invalid(format!(
            "--pixel-um {p}: must be a positive number of micrometres"
        )));
    }
    let opts = sfr::SfrOptions {
        channel: sfr::SfrChannel::parse(&a.channel)?,
        fit_degree: a.fit_degree,
        pixel_pitch_m: pitch_m,
        ..Default::default()
    };
    let r = sfr::sfr(&plane, &opts).map_err(|e| Error::io(&a.image, e))?;
    let mm = r.freq_cy_per_mm();
    println!("freq_cy_per_px,freq_cy_per_mm,mtf");
    for (i, (f, m)) in r.freq_cy_per_px.iter().zip(&r.mtf).enumerate() {
        let fm = mm
            .as_ref()
            .map(|v| format!("{:.6}", v[i]))
            .unwrap_or_default();
        println!("{f:.6},{fm},{m:.6}");
    }
    match r.mtf50_cy_per_px {
        Some(m) => println!("# mtf50_cy_per_px={m:.6}"),
        None => println!("# mtf50_cy_per_px=none (MTF stays above 0.5)"),
    }
    if let (Some(m), Some(p)) = (r.mtf50_cy_per_px, pitch_m) {
        println!("# mtf50_cy_per_mm={:.4}", m / (p * 1e3));
    }
    println!("# mtf50_stderr_cy_per_px={:.6}", r.mtf50_stderr);
    println!(
        "# edge_angle_deg={:.4} ± {:.4}",
        r.edge_angle_deg, r.edge_angle_stderr_deg
    );
    println!("# rows_used={} transposed={}", r.rows_used, r.transposed);
    Ok(0)
}

fn run_noise(a: NoiseArgs) -> Result<i32> {
    let img = read_image(&a.image)?;
    let plane = roi_plane(&img, &a.channel, &a.roi)?;
    let opts = noise::NoiseOptions {
        region_px: a.region_px,
        regions: a.regions,
        seed: a.seed,
        conversion_gain_dv_per_e: a.conversion_gain,
        read_noise_e: a.read_noise_e,
        channel: a.channel.clone(),
        ..Default::default()
    };
    let (m, regions) =
        noise::measure(&plane, &opts, "noise").map_err(|e| Error::io(&a.image, e))?;
    println!("x,y,w,h,verdict,mean_dv,std_dv");
    for r in &regions {
        println!(
            "{},{},{},{},{:?},{:.4},{:.4}",
            r.rect.x, r.rect.y, r.rect.w, r.rect.h, r.verdict, r.mean_dv, r.std_dv
        );
    }
    print_figures(&m);
    Ok(0)
}

fn run_ri(a: RiArgs) -> Result<i32> {
    let img = read_image(&a.image)?;
    let plane = img.plane_for(&a.channel)?;
    let opts = ri::RiOptions {
        pixel_pitch_m: a.pixel_um.map(|p| p * 1e-6),
        bins: a.bins,
        channel: a.channel.clone(),
        ..Default::default()
    };
    let m = ri::relative_illumination(&plane, &opts, "ri").map_err(|e| Error::io(&a.image, e))?;
    let c = &m.curves[0];
    println!("field_height_{},ri,stderr", c.x_unit);
    for i in 0..c.x.len() {
        println!("{:.6},{:.6},{:.6}", c.x[i], c.y[i], c.stderr[i]);
    }
    print_figures(&m);
    Ok(0)
}

fn run_profile(a: ProfileArgs) -> Result<i32> {
    let img = read_image(&a.image)?;
    let (labels, names) = read_label_map_for(&img, &a.label.labels, &a.label.names)?;
    let views = img.views();
    let step = if img.mosaic.is_some() { 2 } else { 1 };
    let opts = profile::ProfileOptions {
        band_px: a.band_px,
        vertical: a.vertical,
        step_px: step,
        ..Default::default()
    };
    let m = profile::profile(&views, &labels, &names, &a.objects, &opts, "profile")
        .map_err(|e| Error::io(&a.image, e))?;
    let head: Vec<String> = m.curves.iter().map(|c| c.name.replace('/', "_")).collect();
    println!("position_px,{}", head.join(","));
    for i in 0..m.curves[0].x.len() {
        let row: Vec<String> = m.curves.iter().map(|c| format!("{:.6}", c.y[i])).collect();
        println!("{},{}", m.curves[0].x[i], row.join(","));
    }
    print_figures(&m);
    Ok(0)
}

fn run_mcc(a: MccArgs) -> Result<i32> {
    let img = read_image(&a.image)?;
    let (labels, names) = read_label_map_for(&img, &a.label.labels, &a.label.names)?;
    let views = img.views();
    let patches = mcc::patch_means(&views, &labels, &names, &a.chart, a.erode)
        .map_err(|e| Error::io(&a.image, e))?;
    println!("patch,channel,mean_dv,stderr_dv,pixels");
    for p in &patches {
        for (c, m, se) in &p.means {
            println!("{},{c},{m:.6},{se:.6},{}", p.number, p.pixels);
        }
    }
    Ok(0)
}
