//! Flat-field sequences on disk, for photon-transfer analysis:
//! `DIR/frame_0000.png …` (raw mosaic DV, 16-bit greyscale PNG) and
//! `DIR/settings.csv` (`key,value` rows: sensor, exposure, irradiance, window, CFA,
//! black/white level, and the model's own numbers prefixed `model_` for comparison;
//! the analysis never reads `model_` rows).
//!
//! `camsim sensor calibrate DIR` reads every sequence in DIR and its immediate
//! subdirectories (one per level; `dark=true` marks dark frames).
//!
//! Irradiance: `E` W/(m²·nm) flat, or `E` × a named spectrum normalised to mean 1
//! over 400–700 nm (10 nm grid), so E is always the mean spectral irradiance.

use super::calibrate::FlatSequence;
pub use super::config::cfa_name;
use super::config::{Exposure, SensorConfig};
use super::output::{png16_bytes, read_png16};
use super::pipeline::{flat_rate_e_per_s, simulate_flat};
use crate::diag::{Error, Result, did_you_mean, write_atomic};
use crate::image::CfaPattern;
use crate::optical_image::Rect;
use crate::spectrum::{Spectrum, WavelengthGrid, library};
use std::collections::BTreeMap;
use std::path::{Path, PathBuf};

/// Shipped sensor files, embedded.
const SHIPPED: &[(&str, &str)] = &[
    (
        "imx363",
        include_str!(concat!(env!("CARGO_MANIFEST_DIR"), "/sensors/imx363.kdl")),
    ),
    (
        "imx363-nominal",
        include_str!(concat!(
            env!("CARGO_MANIFEST_DIR"),
            "/sensors/imx363-nominal.kdl"
        )),
    ),
    (
        "generic",
        include_str!(concat!(env!("CARGO_MANIFEST_DIR"), "/sensors/generic.kdl")),
    ),
];

/// A sensor file path, or the name of a shipped sensor (`imx363`, `imx363-nominal`, `generic`).
pub fn load_sensor(arg: &Path) -> Result<SensorConfig> {
    if arg.exists() {
        return SensorConfig::load(arg);
    }
    let name = arg.to_string_lossy();
    if let Some((n, text)) = SHIPPED.iter().find(|(n, _)| *n == name) {
        return SensorConfig::parse(text, &PathBuf::from(format!("sensors/{n}.kdl")));
    }
    let hint = did_you_mean(&name, SHIPPED.iter().map(|s| s.0))
        .map(|s| format!(" (did you mean '{s}'?)"))
        .unwrap_or_default();
    Err(Error::io(
        arg,
        format!("no such sensor file, and not a shipped sensor name{hint}"),
    ))
}

/// Options of a simulated flat-field sequence.
#[derive(Clone, Debug)]
pub struct FlatOptions {
    pub irradiance_w_m2_nm: f64,
    /// Named spectrum for the shape (None = flat).
    pub spectrum: Option<String>,
    pub exposure_s: f64,
    pub frames: usize,
    pub dark: bool,
    pub seed: u64,
    /// Window size (centred on the sensor).
    pub width: u32,
    pub height: u32,
    /// Also write each frame as DNG (`frame_0000.dng` …).
    pub dng: bool,
}

fn grid() -> WavelengthGrid {
    WavelengthGrid::default()
}

/// The spectral irradiance of a flat field (see module docs).
pub fn flat_spectrum(e: f64, spectrum: Option<&str>) -> Result<Spectrum> {
    if !(e.is_finite() && e >= 0.0) {
        return Err(Error::invalid(format!(
            "flat irradiance must be finite and ≥ 0 W/(m²·nm), found {e}"
        )));
    }
    match spectrum {
        None => Ok(Spectrum::constant("flat", e)),
        Some(n) => {
            let s = library::named(n).map_err(Error::invalid)?;
            let g = grid();
            let mean = (0..g.len()).map(|i| s.eval(g.wavelength(i))).sum::<f64>() / g.len() as f64;
            if !mean.is_finite() || mean <= 0.0 {
                return Err(Error::invalid(format!(
                    "spectrum '{n}' is zero over 400–700 nm"
                )));
            }
            Ok(s.scaled(e / mean))
        }
    }
}

/// Frame seed `i` of a sequence seeded `seed`.
pub fn frame_seed(seed: u64, i: usize) -> u64 {
    seed.wrapping_mul(0x9e37_79b9_7f4a_7c15)
        .wrapping_add(i as u64)
}

/// Simulate and write a flat-field sequence to `out`. Returns the files written
/// (`settings.csv` last).
pub fn write_flat_sequence(
    cfg: &SensorConfig,
    o: &FlatOptions,
    out: &Path,
) -> Result<Vec<PathBuf>> {
    if o.frames == 0 {
        return Err(Error::invalid("--frames must be ≥ 1"));
    }
    if !(o.exposure_s.is_finite() && o.exposure_s >= 0.0) {
        return Err(Error::invalid(format!(
            "exposure must be finite and ≥ 0 s, found {}",
            o.exposure_s
        )));
    }
    let (Some(cols), Some(rows)) = (cfg.cols, cfg.rows) else {
        return Err(Error::invalid(format!(
            "sensor '{}' needs rows and cols",
            cfg.name
        )));
    };
    let (w, h) = (o.width.min(cols).max(1), o.height.min(rows).max(1));
    // even origin keeps the CFA phase of the full frame at the window's (0,0)
    let window = Rect::new(((cols - w) / 2) & !1, ((rows - h) / 2) & !1, w, h);
    let mut c = cfg.clone();
    c.exposure = Exposure::Seconds(o.exposure_s);
    let spec = flat_spectrum(
        if o.dark { 0.0 } else { o.irradiance_w_m2_nm },
        o.spectrum.as_deref(),
    )?;
    std::fs::create_dir_all(out).map_err(|e| Error::io(out, e))?;
    let mut files = vec![];
    for i in 0..o.frames {
        let f = simulate_flat(&c, &spec, &grid(), window, frame_seed(o.seed, i))?;
        let p = out.join(format!("frame_{i:04}.png"));
        let dv: Vec<u16> = f
            .image
            .dv
            .iter()
            .map(|&v| v.round().clamp(0.0, 65535.0) as u16)
            .collect();
        write_atomic(&p, &png16_bytes(w, h, &dv)?)?;
        files.push(p);
        if o.dng {
            let d = out.join(format!("frame_{i:04}.dng"));
            super::output::write_dng(&d, &f.image, &c)?;
            files.push(d);
        }
        f.recycle();
    }
    let rates = flat_rate_e_per_s(&c, &spec, &grid());
    let mut rows_out: Vec<(String, String)> = vec![
        ("sensor".into(), c.name.clone()),
        ("sensor_file".into(), c.source.display().to_string()),
        ("exposure_s".into(), format!("{}", o.exposure_s)),
        (
            "flat_irradiance_w_m2_nm".into(),
            format!("{}", if o.dark { 0.0 } else { o.irradiance_w_m2_nm }),
        ),
        (
            "spectrum".into(),
            o.spectrum.clone().unwrap_or_else(|| "flat".into()),
        ),
        ("dark".into(), format!("{}", o.dark)),
        ("frames".into(), format!("{}", o.frames)),
        ("seed".into(), format!("{}", o.seed)),
        ("window_x".into(), format!("{}", window.x)),
        ("window_y".into(), format!("{}", window.y)),
        ("width".into(), format!("{w}")),
        ("height".into(), format!("{h}")),
        ("cfa".into(), cfa_name(&c.cfa)),
        ("black_level_dv".into(), format!("{}", c.black_level_dv)),
        ("white_level_dv".into(), format!("{}", c.white_level_dv())),
        (
            "model_conversion_gain_dv_per_e".into(),
            format!("{}", c.conversion_gain_dv_per_e()),
        ),
        ("model_read_noise_e".into(), format!("{}", c.read_noise_e())),
        ("model_prnu_percent".into(), format!("{}", c.prnu * 100.0)),
        ("model_full_well_e".into(), format!("{}", c.full_well_e())),
    ];
    for (ch, r) in c.cfa.channels.iter().zip(&rates) {
        rows_out.push((
            format!("model_mean_signal_e_{ch}"),
            format!("{}", if o.dark { 0.0 } else { r * o.exposure_s }),
        ));
    }
    let mut csv = String::from("key,value\n");
    for (k, v) in rows_out {
        csv.push_str(&format!("{k},{}\n", v.replace(',', ";")));
    }
    let sp = out.join("settings.csv");
    write_atomic(&sp, csv.as_bytes())?;
    files.push(sp);
    Ok(files)
}

/// Read `settings.csv` as a key → value map.
pub fn read_settings(path: &Path) -> Result<BTreeMap<String, String>> {
    let t = std::fs::read_to_string(path).map_err(|e| Error::io(path, e))?;
    let mut m = BTreeMap::new();
    for (i, l) in t.lines().enumerate().skip(1) {
        if l.trim().is_empty() {
            continue;
        }
        let (k, v) = l
            .split_once(',')
            .ok_or_else(|| Error::io(path, format!("line {}: expected key,value", i + 1)))?;
        m.insert(k.trim().to_string(), v.trim().to_string());
    }
    Ok(m)
}

/// Read one sequence directory, keeping the pixels of CFA channel `channel` ("r", "g", "b").
pub fn read_flat_sequence(dir: &Path, channel: &str) -> Result<FlatSequence> {
    let sp = dir.join("settings.csv");
    let s = read_settings(&sp)?;
    let get = |k: &str| -> Result<&String> {
        s.get(k)
            .ok_or_else(|| Error::io(&sp, format!("missing key '{k}'")))
    };
    let num = |k: &str| -> Result<f64> {
        get(k)?
            .parse::<f64>()
            .map_err(|_| Error::io(&sp, format!("'{k}' is not a number")))
    };
    let cfa = CfaPattern::bayer(get("cfa")?).map_err(|e| Error::io(&sp, e))?;
    let ch = if cfa.channels.len() == 1 {
        0
    } else {
        cfa.channel_index(channel)
            .ok_or_else(|| Error::io(&sp, format!("no CFA channel '{channel}' (r, g, b)")))?
    };
    let (wx, wy) = (num("window_x")? as u32, num("window_y")? as u32);
    let mut frames_p: Vec<PathBuf> = std::fs::read_dir(dir)
        .map_err(|e| Error::io(dir, e))?
        .filter_map(|e| e.ok().map(|e| e.path()))
        .filter(|p| {
            p.file_name()
                .and_then(|n| n.to_str())
                .is_some_and(|n| n.starts_with("frame_") && n.ends_with(".png"))
        })
        .collect();
    frames_p.sort();
    if frames_p.is_empty() {
        return Err(Error::io(dir, "no frame_*.png files"));
    }
    let mut frames = vec![];
    let mut size = None;
    for p in &frames_p {
        let (w, h, v) = read_png16(p)?;
        if *size.get_or_insert((w, h)) != (w, h) {
            return Err(Error::io(p, "frame size differs from the first frame"));
        }
        let mut px = vec![];
        for y in 0..h {
            for x in 0..w {
                if cfa.channel_at(wx + x, wy + y) == ch {
                    px.push(v[(y * w + x) as usize] as f64);
                }
            }
        }
        frames.push(px);
    }
    Ok(FlatSequence {
        exposure_s: num("exposure_s")?,
        dark: get("dark")? == "true",
        frames,
        white_level_dv: num("white_level_dv")?,
    })
}

/// All sequences in `dir` and its immediate subdirectories, sorted by path.
pub fn read_flat_sequences(dir: &Path, channel: &str) -> Result<Vec<(PathBuf, FlatSequence)>> {
    let mut dirs = vec![];
    if dir.join("settings.csv").exists() {
        dirs.push(dir.to_path_buf());
    }
    let rd = std::fs::read_dir(dir).map_err(|e| Error::io(dir, e))?;
    for e in rd.flatten() {
        let p = e.path();
        if p.is_dir() && p.join("settings.csv").exists() {
            dirs.push(p);
        }
    }
    dirs.sort();
    if dirs.is_empty() {
        return Err(Error::io(
            dir,
            "no flat-field sequences (directories with settings.csv) found",
        ));
    }
    dirs.into_iter()
        .map(|d| read_flat_sequence(&d, channel).map(|s| (d, s)))
        .collect()
}

/// The flat (wavelength-independent) irradiance, W/(m²·nm), that gives CFA
/// channel `channel` a mean signal of `signal_e` electrons in `exposure_s`
/// (on axis, dark current not included).
pub fn flat_for_signal(
    cfg: &SensorConfig,
    channel: usize,
    signal_e: f64,
    exposure_s: f64,
) -> Result<Spectrum> {
    let unit = Spectrum::constant("flat", 1.0);
    let rate = flat_rate_e_per_s(cfg, &unit, &grid())
        .get(channel)
        .copied()
        .unwrap_or(0.0);
    if !(rate > 0.0 && exposure_s > 0.0 && signal_e >= 0.0 && signal_e.is_finite()) {
        return Err(Error::invalid(format!(
            "sensor '{}': no flat irradiance gives {signal_e} e⁻ in {exposure_s} s (channel rate {rate} e⁻/s per W/(m²·nm))",
            cfg.name
        )));
    }
    flat_spectrum(signal_e / (rate * exposure_s), None)
}

/// A flat-field (or dark) sequence simulated in memory: `frames` frames of
/// `window` (full-frame pixels) at `exposure_s` under `irradiance` (None:
/// dark frames), keeping the pixels of CFA channel `channel` — what
/// [`write_flat_sequence`] followed by [`read_flat_sequence`] gives, without
/// the files. Frame `i` uses [`frame_seed`]`(seed, i)`.
pub fn flat_sequence(
    cfg: &SensorConfig,
    irradiance: Option<&Spectrum>,
    exposure_s: f64,
    window: Rect,
    frames: usize,
    seed: u64,
    channel: usize,
) -> Result<FlatSequence> {
    let mut c = cfg.clone();
    c.exposure = Exposure::Seconds(exposure_s);
    let zero = Spectrum::constant("dark", 0.0);
    let dark = irradiance.is_none();
    let spec = irradiance.unwrap_or(&zero);
    let mut out = Vec::with_capacity(frames);
    for i in 0..frames {
        let f = simulate_flat(&c, spec, &grid(), window, frame_seed(seed, i))?;
        let im = &f.image;
        let mut px = vec![];
        for y in 0..im.height() {
            for x in 0..im.width() {
                if c.cfa.channel_at(window.x + x, window.y + y) == channel {
                    px.push(im.dv_at(x, y) as f64);
                }
            }
        }
        out.push(px);
        f.recycle();
    }
    Ok(FlatSequence {
        exposure_s,
        dark,
        frames: out,
        white_level_dv: c.white_level_dv(),
    })
}
