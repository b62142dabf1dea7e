//! Sensor definition files (`sensors/*.kdl`, KDL v2) → typed [`SensorConfig`].
//!
//! A sensor file is a flat list of nodes. Scalar nodes take one argument and
//! carry their unit in the name (`pixel-size-um 1.4`, `exposure-s 0.01`);
//! block nodes are `qe` (one property per CFA channel naming a spectrum),
//! `qe-matrix` (three `row` children), and `relative-illumination`.
//! Validation is strict: an unknown name, a wrong type, a number without its
//! unit or an out-of-range value is an error at `file:line:col`, with the
//! nearest valid name suggested.
//!
//! The same scalar names are accepted as inline overrides from an experiment
//! ([`SensorConfig::apply_overrides`]), e.g. `sensor "sensors/imx363.kdl" exposure-s=0.2`.

use crate::diag::{Error, Located, did_you_mean};
use crate::image::CfaPattern;
use crate::params::{Params, Value};
use crate::spectrum::{Spectrum, library};
use kdl::{KdlDocument, KdlNode, KdlValue};
use std::path::{Path, PathBuf};

/// How the conversion gain was specified (resolved with [`SensorConfig::conversion_gain_v_per_e`]).
#[derive(Clone, Copy, Debug, PartialEq)]
pub enum ConversionGain {
    /// Volts per electron at the sense node.
    VoltsPerElectron(f64),
    /// Digital values per electron at analog gain 1 (converted with the ADC step).
    DvPerElectron(f64),
    /// Voltage swing / well capacity (ISETCam's derivation).
    FromWell,
}

/// Exposure time.
#[derive(Clone, Copy, Debug, PartialEq)]
pub enum Exposure {
    Seconds(f64),
    /// Auto-exposure: the `percentile`-th percentile (nearest rank) of the pixels'
    /// mean signal reaches `level` × full well. ISETCam's default auto-exposure
    /// targets 0.95 of the voltage swing at the brightest pixel (percentile 100).
    /// Decision: the default percentile is 99.9, so a few Monte Carlo outliers
    /// ("fireflies") of a path-traced optical image do not set the exposure; an
    /// image with fewer than 1000 pixels still exposes for its brightest pixel.
    /// `auto-exposure-percentile 100` restores ISETCam's rule exactly.
    Auto {
        level: f64,
        percentile: f64,
    },
}

/// Default auto-exposure level (fraction of full well) and percentile.
pub const AUTO_EXPOSURE_LEVEL: f64 = 0.95;
pub const AUTO_EXPOSURE_PERCENTILE: f64 = 99.9;

impl Exposure {
    /// `exposure-s "auto"` without further settings.
    pub fn auto_default() -> Self {
        Exposure::Auto {
            level: AUTO_EXPOSURE_LEVEL,
            percentile: AUTO_EXPOSURE_PERCENTILE,
        }
    }
}

/// Pixel/microlens relative illumination applied at the sensor (issue 5 item 4),
/// as a function of image-side field height from the sensor centre.
#[derive(Clone, Debug, PartialEq)]
pub enum RelativeIllumination {
    None,
    /// cos^n of the chief-ray angle atan(h / distance).
    CosN {
        n: f64,
        distance_mm: f64,
    },
    /// Measured table, linear in field height; beyond the last point the last value holds.
    Table {
        field_height_mm: Vec<f64>,
        value: Vec<f64>,
    },
}

impl RelativeIllumination {
    /// Relative illumination at field height `h_mm` (1 on axis for the models above).
    pub fn at(&self, h_mm: f64) -> f64 {
        match self {
            RelativeIllumination::None => 1.0,
            RelativeIllumination::CosN { n, distance_mm } => {
                let c = distance_mm / (distance_mm * distance_mm + h_mm * h_mm).sqrt();
                c.powf(*n)
            }
            RelativeIllumination::Table {
                field_height_mm: h,
                value: v,
            } => {
                if h_mm <= h[0] {
                    return v[0];
                }
                let i = h.partition_point(|&x| x < h_mm);
                if i >= h.len() {
                    return v[v.len() - 1];
                }
                let t = (h_mm - h[i - 1]) / (h[i] - h[i - 1]);
                v[i - 1] + t * (v[i] - v[i - 1])
            }
        }
    }
}

/// Which parts of the model run. All on by default; each can be switched off
/// (`photon-noise #false` in a file or as an override).
#[derive(Clone, Copy, Debug, PartialEq, Eq)]
pub struct Sources {
    pub photon_noise: bool,
    pub dark_current: bool,
    pub dsnu: bool,
    pub prnu: bool,
    pub read_noise: bool,
    pub reset_noise: bool,
    pub column_fpn: bool,
    pub pixel_vignetting: bool,
    pub clipping: bool,
    pub quantization: bool,
}

impl Default for Sources {
    fn default() -> Self {
        Self::all()
    }
}

impl Sources {
    pub fn all() -> Self {
        Self {
            photon_noise: true,
            dark_current: true,
            dsnu: true,
            prnu: true,
            read_noise: true,
            reset_noise: true,
            column_fpn: true,
            pixel_vignetting: true,
            clipping: true,
            quantization: true,
        }
    }
    /// The noiseless linear sensor: no noise, no dark current, no clipping, no quantisation.
    pub fn none() -> Self {
        Self {
            photon_noise: false,
            dark_current: false,
            dsnu: false,
            prnu: false,
            read_noise: false,
            reset_noise: false,
            column_fpn: false,
            pixel_vignetting: false,
            clipping: false,
            quantization: false,
        }
    }
}

/// A complete, validated sensor description. Every number is SI inside (metres,
/// seconds, volts, fractions); the file names carry the file's unit.
#[derive(Clone, Debug)]
pub struct SensorConfig {
    pub name: String,
    /// The file this came from ("" when built in code); spectra resolve relative to it.
    pub source: PathBuf,
    /// Full sensor size; `None` = take the optical image's field of view.
    pub rows: Option<u32>,
    pub cols: Option<u32>,
    pub pixel_size_m: f64,
    pub fill_factor: f64,
    pub cfa: CfaPattern,
    /// Spectrum references per CFA channel, in CFA channel order.
    pub qe_refs: Vec<String>,
    /// Resolved QE per CFA channel (without IR filter and matrix).
    pub qe: Vec<Spectrum>,
    pub ir_filter_ref: String,
    pub ir_filter: Spectrum,
    /// Optional correction matrix: effective_c = Σ_n (qe_n · ir) · `M[n][c]` (paper Eq. 2).
    pub qe_matrix: Option<Vec<Vec<f64>>>,
    pub well_capacity_e: f64,
    pub voltage_swing_v: f64,
    pub conversion_gain: ConversionGain,
    /// Multiplies the pixel voltage before the ADC (ISETCam's `analogGain` is its inverse).
    pub analog_gain: f64,
    pub black_level_dv: f64,
    pub bit_depth: u32,
    pub exposure: Exposure,
    pub read_noise_v: f64,
    pub reset_noise_v: f64,
    pub dsnu_v: f64,
    /// PRNU as a fraction (0.0054 for 0.54 %).
    pub prnu: f64,
    pub dark_voltage_v_per_s: f64,
    pub column_fpn_offset_v: f64,
    /// Column gain FPN as a fraction.
    pub column_fpn_gain: f64,
    pub relative_illumination: RelativeIllumination,
    pub sources: Sources,
    /// Seed of the fixed-pattern fields (PRNU, DSNU, column FPN): a property of the
    /// sensor unit, independent of the per-frame seed.
    pub fpn_seed: u64,
}

/// The scalar names accepted in files and as overrides (for did-you-mean).
pub const SCALAR_NAMES: &[&str] = &[
    "name",
    "rows",
    "cols",
    "pixel-size-um",
    "fill-factor",
    "cfa",
    "ir-filter",
    "well-capacity-e",
    "voltage-swing-v",
    "conversion-gain-dv-per-e",
    "conversion-gain-uv-per-e",
    "analog-gain",
    "iso",
    "black-level-dv",
    "bit-depth",
    "exposure-s",
    "auto-exposure-level",
    "auto-exposure-percentile",
    "read-noise-mv",
    "reset-noise-mv",
    "dsnu-mv",
    "prnu-percent",
    "dark-voltage-mv-per-s",
    "column-fpn-offset-mv",
    "column-fpn-gain-percent",
    "fpn-seed",
    "photon-noise",
    "dark-current",
    "dsnu",
    "prnu",
    "read-noise",
    "reset-noise",
    "column-fpn",
    "pixel-vignetting",
    "clipping",
    "quantization",
];

/// Block node names (files only).
pub const BLOCK_NAMES: &[&str] = &["qe", "qe-matrix", "relative-illumination"];

/// Reset (kTC) noise of a sense node, volts: √(k_B·T / C) with C = q / conversion gain.
/// Without correlated double sampling this is the `reset-noise-mv` to use (e.g. 1.41 mV
/// for 76.5 µV/e⁻ at 300 K, ≈ 18 e⁻); with CDS, as in the IMX363, it cancels (0).
pub fn ktc_noise_v(conversion_gain_v_per_e: f64, temperature_k: f64) -> f64 {
    const K_B: f64 = 1.380_649e-23;
    const Q: f64 = 1.602_176_634e-19;
    let c = Q / conversion_gain_v_per_e;
    (K_B * temperature_k / c).sqrt()
}

/// ISO at which the analog gain is 1 (ISETCam's IMX363: analog gain = 55/ISO in its
/// inverse convention, i.e. our multiplicative gain = ISO/55).
pub const UNITY_GAIN_ISO: f64 = 55.0;

fn num(name: &str, v: &Value) -> Result<f64, String> {
    match v {
        Value::Number(x) if x.is_finite() => Ok(*x),
        Value::Number(x) => Err(format!("'{name}' must be finite, found {x}")),
        o => Err(format!("'{name}' expects a number, found {}", describe(o))),
    }
}
fn positive(name: &str, v: &Value) -> Result<f64, String> {
    let x = num(name, v)?;
    if x > 0.0 {
        Ok(x)
    } else {
        Err(format!("'{name}' must be > 0, found {x}"))
    }
}
fn nonneg(name: &str, v: &Value) -> Result<f64, String> {
    let x = num(name, v)?;
    if x >= 0.0 {
        Ok(x)
    } else {
        Err(format!("'{name}' must be ≥ 0, found {x}"))
    }
}
fn integer(name: &str, v: &Value, lo: f64, hi: f64) -> Result<u64, String> {
    let x = num(name, v)?;
    if x.fract() != 0.0 || x < lo || x > hi {
        return Err(format!(
            "'{name}' expects an integer in {lo}..={hi}, found {x}"
        ));
    }
    Ok(x as u64)
}
fn string<'a>(name: &str, v: &'a Value) -> Result<&'a str, String> {
    match v {
        Value::String(s) => Ok(s),
        o => Err(format!("'{name}' expects a string, found {}", describe(o))),
    }
}
fn boolean(name: &str, v: &Value) -> Result<bool, String> {
    match v {
        Value::Bool(b) => Ok(*b),
        o => Err(format!(
            "'{name}' expects #true or #false, found {}",
            describe(o)
        )),
    }
}
fn describe(v: &Value) -> String {
    match v {
        Value::Bool(b) => format!("#{b}"),
        Value::Number(x) => format!("the number {x}"),
        Value::String(s) => format!("the string \"{s}\""),
        Value::List(_) => format!("the list {v}"),
    }
}

/// Suggestion text for an unknown name: a missing unit is called out explicitly.
fn suggestion(word: &str, names: &[&str]) -> Option<String> {
    if let Some(n) = names
        .iter()
        .find(|n| n.starts_with(word) && n.as_bytes().get(word.len()) == Some(&b'-'))
    {
        return Some(format!(
            "numbers carry their unit in the name: did you mean '{n}'?"
        ));
    }
    did_you_mean(word, names.iter().copied()).map(|s| format!("did you mean '{s}'?"))
}

/// Bayer name of a pattern ("rggb" …) or "mono".
pub fn cfa_name(c: &CfaPattern) -> String {
    if c.channels.len() == 1 {
        return "mono".into();
    }
    c.cells
        .iter()
        .map(|&i| c.channels[i as usize].chars().next().unwrap_or('?'))
        .collect()
}

fn resolve_spectrum(r: &str, base: &Path) -> Result<Spectrum, String> {
    library::resolve(r, base)
}

impl SensorConfig {
    /// A generic sensor: 1.4 µm, RGGB, ideal-ish electronics, flat QE 0.5 (used when
    /// building configs in code; `sensors/generic.kdl` documents the same values).
    pub fn generic() -> Self {
        let flat = Spectrum::constant("constant:0.5", 0.5);
        Self {
            name: "generic".into(),
            source: PathBuf::new(),
            rows: None,
            cols: None,
            pixel_size_m: 1.4e-6,
            fill_factor: 1.0,
            cfa: CfaPattern::bayer("rggb").expect("rggb is valid"),
            qe_refs: vec!["constant:0.5".into(); 3],
            qe: vec![flat.clone(), flat.clone(), flat],
            ir_filter_ref: "one".into(),
            ir_filter: Spectrum::constant("one", 1.0),
            qe_matrix: None,
            well_capacity_e: 6000.0,
            voltage_swing_v: 0.45,
            conversion_gain: ConversionGain::FromWell,
            analog_gain: 1.0,
            black_level_dv: 64.0,
            bit_depth: 10,
            exposure: Exposure::Seconds(0.01),
            read_noise_v: 0.0,
            reset_noise_v: 0.0,
            dsnu_v: 0.0,
            prnu: 0.0,
            dark_voltage_v_per_s: 0.0,
            column_fpn_offset_v: 0.0,
            column_fpn_gain: 0.0,
            relative_illumination: RelativeIllumination::None,
            sources: Sources::all(),
            fpn_seed: 1,
        }
    }

    /// Base directory for relative spectrum paths.
    fn base_dir(&self) -> PathBuf {
        self.source
            .parent()
            .map(Path::to_path_buf)
            .unwrap_or_default()
    }

    /// Digital step of the ADC in volts (voltage swing / 2^bits, ISETCam's convention).
    pub fn quantization_step_v(&self) -> f64 {
        self.voltage_swing_v / (1u64 << self.bit_depth) as f64
    }
    /// Sense-node conversion gain, V/e⁻.
    pub fn conversion_gain_v_per_e(&self) -> f64 {
        match self.conversion_gain {
            ConversionGain::VoltsPerElectron(g) => g,
            ConversionGain::DvPerElectron(k) => k * self.quantization_step_v(),
            ConversionGain::FromWell => self.voltage_swing_v / self.well_capacity_e,
        }
    }
    /// Overall system gain K, DV/e⁻, including the analog gain.
    pub fn conversion_gain_dv_per_e(&self) -> f64 {
        self.conversion_gain_v_per_e() * self.analog_gain / self.quantization_step_v()
    }
    /// Largest collectable charge: min(well capacity, voltage swing / conversion gain).
    pub fn full_well_e(&self) -> f64 {
        self.well_capacity_e
            .min(self.voltage_swing_v / self.conversion_gain_v_per_e())
    }
    /// Largest digital value, 2^bits − 1.
    pub fn white_level_dv(&self) -> f64 {
        ((1u64 << self.bit_depth) - 1) as f64
    }
    /// Read noise in electrons (at the sense node).
    pub fn read_noise_e(&self) -> f64 {
        self.read_noise_v / self.conversion_gain_v_per_e()
    }
    /// Pixel area × fill factor, m².
    pub fn effective_pixel_area_m2(&self) -> f64 {
        self.pixel_size_m * self.pixel_size_m * self.fill_factor
    }

    /// Effective spectral QE per CFA channel at wavelength `lambda_nm`: QE × IR filter,
    /// mixed by the correction matrix when given.
    pub fn effective_qe(&self, lambda_nm: f64) -> Vec<f64> {
        let ir = self.ir_filter.eval(lambda_nm);
        let nominal: Vec<f64> = self.qe.iter().map(|s| s.eval(lambda_nm) * ir).collect();
        match &self.qe_matrix {
            None => nominal,
            Some(m) => (0..nominal.len())
                .map(|c| (0..nominal.len()).map(|n| nominal[n] * m[n][c]).sum())
                .collect(),
        }
    }

    /// Set one scalar property by name (shared by the file parser and overrides).
    pub fn set(&mut self, name: &str, v: &Value) -> Result<(), String> {
        let mv = 1e-3;
        match name {
            "name" => self.name = string(name, v)?.to_string(),
            "rows" => self.rows = Some(integer(name, v, 1.0, 1e6)? as u32),
            "cols" => self.cols = Some(integer(name, v, 1.0, 1e6)? as u32),
            "pixel-size-um" => {
                let x = positive(name, v)?;
                if x > 1000.0 {
                    return Err(format!(
                        "'{name}' = {x} µm is not a pixel size (unit is micrometres)"
                    ));
                }
                self.pixel_size_m = x * 1e-6
            }
            "fill-factor" => {
                let x = positive(name, v)?;
                if x > 1.0 {
                    return Err(format!(
                        "'fill-factor' is a fraction in (0, 1], found {x} (100 % is 1.0)"
                    ));
                }
                self.fill_factor = x
            }
            "cfa" => {
                let s = string(name, v)?;
                self.cfa = CfaPattern::bayer(s)?;
            }
            "ir-filter" => {
                let s = string(name, v)?;
                self.ir_filter = resolve_spectrum(s, &self.base_dir())?;
                self.ir_filter_ref = s.to_string();
            }
            "well-capacity-e" => self.well_capacity_e = positive(name, v)?,
            "voltage-swing-v" => self.voltage_swing_v = positive(name, v)?,
            "conversion-gain-dv-per-e" => {
                self.conversion_gain = ConversionGain::DvPerElectron(positive(name, v)?)
            }
            "conversion-gain-uv-per-e" => {
                self.conversion_gain = ConversionGain::VoltsPerElectron(positive(name, v)? * 1e-6)
            }
            "analog-gain" => self.analog_gain = positive(name, v)?,
            "iso" => self.analog_gain = positive(name, v)? / UNITY_GAIN_ISO,
            "black-level-dv" => self.black_level_dv = nonneg(name, v)?,
            "bit-depth" => self.bit_depth = integer(name, v, 1.0, 16.0)? as u32,
            "exposure-s" => {
                self.exposure = match v {
                    Value::String(s) if s == "auto" => match self.exposure {
                        a @ Exposure::Auto { .. } => a,
                        _ => Exposure::auto_default(),
                    },
                    Value::String(s) => {
                        return Err(format!(
                            "'exposure-s' expects seconds or \"auto\", found \"{s}\""
                        ));
                    }
                    o => Exposure::Seconds(nonneg(name, o)?),
                }
            }
            "auto-exposure-level" => {
                let x = positive(name, v)?;
                if x > 1.0 {
                    return Err(format!(
                        "'auto-exposure-level' is a fraction of full well in (0, 1], found {x}"
                    ));
                }
                self.set_auto_exposure(Some(x), None);
            }
            "auto-exposure-percentile" => {
                let x = positive(name, v)?;
                if x > 100.0 {
                    return Err(format!(
                        "'auto-exposure-percentile' is a percentile in (0, 100], found {x}"
                    ));
                }
                self.set_auto_exposure(None, Some(x));
            }
            "read-noise-mv" => self.read_noise_v = nonneg(name, v)? * mv,
            "reset-noise-mv" => self.reset_noise_v = nonneg(name, v)? * mv,
            "dsnu-mv" => self.dsnu_v = nonneg(name, v)? * mv,
            "prnu-percent" => {
                let x = nonneg(name, v)?;
                if x >= 100.0 {
                    return Err(format!("'prnu-percent' must be below 100, found {x}"));
                }
                self.prnu = x / 100.0
            }
            "dark-voltage-mv-per-s" => self.dark_voltage_v_per_s = nonneg(name, v)? * mv,
            "column-fpn-offset-mv" => self.column_fpn_offset_v = nonneg(name, v)? * mv,
            "column-fpn-gain-percent" => self.column_fpn_gain = nonneg(name, v)? / 100.0,
            "fpn-seed" => self.fpn_seed = integer(name, v, 0.0, 9.007_199_254_740_992e15)?,
            "photon-noise" => self.sources.photon_noise = boolean(name, v)?,
            "dark-current" => self.sources.dark_current = boolean(name, v)?,
            "dsnu" => self.sources.dsnu = boolean(name, v)?,
            "prnu" => self.sources.prnu = boolean(name, v)?,
            "read-noise" => self.sources.read_noise = boolean(name, v)?,
            "reset-noise" => self.sources.reset_noise = boolean(name, v)?,
            "column-fpn" => self.sources.column_fpn = boolean(name, v)?,
            "pixel-vignetting" => self.sources.pixel_vignetting = boolean(name, v)?,
            "clipping" => self.sources.clipping = boolean(name, v)?,
            "quantization" => self.sources.quantization = boolean(name, v)?,
            other => {
                let mut all: Vec<&str> = SCALAR_NAMES.to_vec();
                all.extend_from_slice(BLOCK_NAMES);
                let hint = suggestion(other, &all)
                    .map(|h| format!(" ({h})"))
                    .unwrap_or_default();
                return Err(format!("unknown sensor property '{other}'{hint}"));
            }
        }
        Ok(())
    }

    /// Cross-field checks after all properties are set.
    pub fn validate(&self) -> Result<(), String> {
        if self.qe.len() != self.cfa.channels.len() {
            return Err(format!(
                "the CFA has channels {:?} but {} QE curve(s) are given",
                self.cfa.channels,
                self.qe.len()
            ));
        }
        if let Some(m) = &self.qe_matrix
            && (m.len() != self.qe.len() || m.iter().any(|r| r.len() != self.qe.len()))
        {
            return Err(format!(
                "qe-matrix must be {0}×{0} for {0} channels",
                self.qe.len()
            ));
        }
        if self.black_level_dv >= self.white_level_dv() {
            return Err(format!(
                "black-level-dv {} is not below the white level {} of a {}-bit ADC",
                self.black_level_dv,
                self.white_level_dv(),
                self.bit_depth
            ));
        }
        let g = self.conversion_gain_v_per_e();
        if !(g.is_finite() && g > 0.0) {
            return Err("conversion gain must be finite and > 0".into());
        }
        Ok(())
    }

    /// The resolved scalar settings under their file names (for manifests and
    /// reports); `apply_overrides` of this map onto any config reproduces the scalars.
    pub fn resolved_params(&self) -> Params {
        let mut p = Params::new();
        let n = |x: f64| Value::Number(x);
        p.set("name", Value::String(self.name.clone()));
        if let Some(r) = self.rows {
            p.set("rows", n(r as f64));
        }
        if let Some(c) = self.cols {
            p.set("cols", n(c as f64));
        }
        p.set("pixel-size-um", n(self.pixel_size_m * 1e6));
        p.set("fill-factor", n(self.fill_factor));
        p.set("cfa", Value::String(cfa_name(&self.cfa)));
        p.set("ir-filter", Value::String(self.ir_filter_ref.clone()));
        p.set("well-capacity-e", n(self.well_capacity_e));
        p.set("voltage-swing-v", n(self.voltage_swing_v));
        p.set(
            "conversion-gain-uv-per-e",
            n(self.conversion_gain_v_per_e() * 1e6),
        );
        p.set("analog-gain", n(self.analog_gain));
        p.set("black-level-dv", n(self.black_level_dv));
        p.set("bit-depth", n(self.bit_depth as f64));
        match self.exposure {
            Exposure::Seconds(t) => p.set("exposure-s", n(t)),
            Exposure::Auto { level, percentile } => {
                p.set("exposure-s", Value::String("auto".into()));
                p.set("auto-exposure-level", n(level));
                p.set("auto-exposure-percentile", n(percentile));
            }
        }
        p.set("read-noise-mv", n(self.read_noise_v * 1e3));
        p.set("reset-noise-mv", n(self.reset_noise_v * 1e3));
        p.set("dsnu-mv", n(self.dsnu_v * 1e3));
        p.set("prnu-percent", n(self.prnu * 100.0));
        p.set("dark-voltage-mv-per-s", n(self.dark_voltage_v_per_s * 1e3));
        p.set("column-fpn-offset-mv", n(self.column_fpn_offset_v * 1e3));
        p.set("column-fpn-gain-percent", n(self.column_fpn_gain * 100.0));
        p.set("fpn-seed", n(self.fpn_seed as f64));
        let s = &self.sources;
        for (k, v) in [
            ("photon-noise", s.photon_noise),
            ("dark-current", s.dark_current),
            ("dsnu", s.dsnu),
            ("prnu", s.prnu),
            ("read-noise", s.read_noise),
            ("reset-noise", s.reset_noise),
            ("column-fpn", s.column_fpn),
            ("pixel-vignetting", s.pixel_vignetting),
            ("clipping", s.clipping),
            ("quantization", s.quantization),
        ] {
            p.set(k, Value::Bool(v));
        }
        p
    }

    /// Switch to auto-exposure (if not already) and set the given parts; the
    /// others keep their current or default values.
    fn set_auto_exposure(&mut self, level: Option<f64>, percentile: Option<f64>) {
        let (l, p) = match self.exposure {
            Exposure::Auto { level, percentile } => (level, percentile),
            Exposure::Seconds(_) => (AUTO_EXPOSURE_LEVEL, AUTO_EXPOSURE_PERCENTILE),
        };
        self.exposure = Exposure::Auto {
            level: level.unwrap_or(l),
            percentile: percentile.unwrap_or(p),
        };
    }

    /// Apply inline overrides (experiment `sensor "…" exposure-s=0.2`). Names are the
    /// scalar names of the file format; unknown names get a suggestion.
    pub fn apply_overrides(&mut self, p: &Params) -> Result<(), String> {
        self.apply_overrides_at(p).map_err(|(_, e)| e)
    }

    /// As `apply_overrides`; an error names the property it is about (None:
    /// the cross-field checks).
    fn apply_overrides_at<'a>(&mut self, p: &'a Params) -> Result<(), (Option<&'a str>, String)> {
        for (k, v) in &p.0 {
            if BLOCK_NAMES.contains(&k.as_str()) {
                return Err((
                    Some(k),
                    format!("'{k}' is a block and can only be set in the sensor file"),
                ));
            }
            self.set(k, v).map_err(|e| (Some(k.as_str()), e))?;
        }
        self.validate().map_err(|e| (None, e))
    }

    /// Read and validate a sensor file.
    pub fn load(path: &Path) -> crate::Result<Self> {
        let text = std::fs::read_to_string(path).map_err(|e| Error::io(path, e))?;
        Self::parse(&text, path)
    }

    /// Parse a sensor file's text; `path` names it in diagnostics and anchors spectra.
    pub fn parse(text: &str, path: &Path) -> crate::Result<Self> {
        let doc = KdlDocument::parse(text).map_err(|e| {
            let d = e.diagnostics.first();
            let (off, len) = d.map(|d| (d.span.offset(), d.span.len())).unwrap_or((0, 1));
            let msg = d
                .and_then(|d| d.message.clone())
                .unwrap_or_else(|| "invalid KDL".into());
            let help = d.and_then(|d| d.help.clone());
            Located::at_offset(path, text, off, len, format!("KDL syntax: {msg}"))
                .with_help_opt(help)
        })?;
        let mut c = Self::generic();
        c.name = path
            .file_stem()
            .map(|s| s.to_string_lossy().into_owned())
            .unwrap_or_default();
        c.source = path.to_path_buf();
        let base = c.base_dir();
        let at = |span: miette::SourceSpan, msg: String| -> Error {
            Located::at_offset(path, text, span.offset(), span.len(), msg).into()
        };
        let mut seen: Vec<String> = vec![];
        let mut cfa_span = None;
        let mut qe_span = None;
        for node in doc.nodes() {
            let name = node.name().value().to_string();
            let span = node.name().span();
            if seen.contains(&name) {
                return Err(at(span, format!("'{name}' is given twice")));
            }
            seen.push(name.clone());
            match name.as_str() {
                "qe" => {
                    qe_span = Some(node.span());
                    parse_qe(node, &mut c, &base, path, text)?;
                }
                "qe-matrix" => c.qe_matrix = Some(parse_matrix(node, path, text)?),
                "relative-illumination" => {
                    c.relative_illumination = parse_ri(node, &base, path, text)?
                }
                _ => {
                    if !SCALAR_NAMES.contains(&name.as_str()) {
                        let mut all: Vec<&str> = SCALAR_NAMES.to_vec();
                        all.extend_from_slice(BLOCK_NAMES);
                        let hint = suggestion(&name, &all);
                        return Err(Error::from(
                            Located::at_offset(
                                path,
                                text,
                                span.offset(),
                                span.len(),
                                format!("unknown sensor property '{name}'"),
                            )
                            .with_help_opt(hint),
                        ));
                    }
                    if name == "cfa" {
                        cfa_span = Some(node.span());
                    }
                    if node.children().is_some() {
                        return Err(at(
                            node.span(),
                            format!("'{name}' takes one value, not a block"),
                        ));
                    }
                    let entries = node.entries();
                    if let Some(p) = entries.iter().find(|e| e.name().is_some()) {
                        return Err(at(
                            p.span(),
                            format!("'{name}' takes one value, not properties"),
                        ));
                    }
                    if entries.len() != 1 {
                        return Err(at(
                            node.span(),
                            format!("'{name}' takes exactly one value, found {}", entries.len()),
                        ));
                    }
                    let e = &entries[0];
                    let v =
                        kdl_value(e.value()).map_err(|m| at(e.span(), format!("'{name}': {m}")))?;
                    c.set(&name, &v).map_err(|m| at(e.span(), m))?;
                }
            }
        }
        if let Err(m) = c.validate() {
            let span = qe_span.or(cfa_span).unwrap_or_else(|| (0, 1).into());
            return Err(at(span, m));
        }
        Ok(c)
    }
}

/// KDL value → parameter value.
pub fn kdl_value(v: &KdlValue) -> Result<Value, String> {
    Ok(match v {
        KdlValue::String(s) => Value::String(s.clone()),
        KdlValue::Integer(i) => Value::Number(*i as f64),
        KdlValue::Float(x) => Value::Number(*x),
        KdlValue::Bool(b) => Value::Bool(*b),
        KdlValue::Null => return Err("#null is not a value here".into()),
    })
}

fn loc(path: &Path, text: &str, span: miette::SourceSpan, msg: String) -> Error {
    Located::at_offset(path, text, span.offset(), span.len(), msg).into()
}

fn parse_qe(
    node: &KdlNode,
    c: &mut SensorConfig,
    base: &Path,
    path: &Path,
    text: &str,
) -> crate::Result<()> {
    if node.children().is_some() {
        return Err(loc(
            path,
            text,
            node.span(),
            "'qe' takes properties, one per CFA channel (r=\"p4a-qe-r\" …)".into(),
        ));
    }
    let mut refs: Vec<(String, String, miette::SourceSpan)> = vec![];
    for e in node.entries() {
        let Some(ch) = e.name() else {
            return Err(loc(
                path,
                text,
                e.span(),
                "'qe' takes properties named by CFA channel, e.g. r=\"p4a-qe-r\"".into(),
            ));
        };
        let Some(s) = e.value().as_string() else {
            return Err(loc(
                path,
                text,
                e.span(),
                format!(
                    "qe channel '{}' expects a spectrum name or PATH.csv#column",
                    ch.value()
                ),
            ));
        };
        refs.push((ch.value().to_string(), s.to_string(), e.span()));
    }
    c.qe_refs.clear();
    c.qe.clear();
    // Order by the CFA's channels; the cfa node may come later, so keep file order and
    // reorder in `validate_qe_order` below.
    let channels = ["r", "g", "b", "w"];
    for (ch, r, span) in &refs {
        if !channels.contains(&ch.as_str()) {
            let hint = did_you_mean(ch, channels).map(|s| format!("did you mean '{s}'?"));
            return Err(Error::from(
                Located::at_offset(
                    path,
                    text,
                    span.offset(),
                    span.len(),
                    format!("unknown CFA channel '{ch}' (r, g, b, or w for mono)"),
                )
                .with_help_opt(hint),
            ));
        }
        let s = resolve_spectrum(r, base).map_err(|m| loc(path, text, *span, m))?;
        c.qe_refs.push(format!("{ch}={r}"));
        c.qe.push(s);
    }
    // Canonical order r, g, b (CfaPattern::bayer uses channel indices 0=r, 1=g, 2=b).
    let mut order: Vec<usize> = (0..refs.len()).collect();
    order.sort_by_key(|&i| channels.iter().position(|c| *c == refs[i].0).unwrap_or(9));
    c.qe = order.iter().map(|&i| c.qe[i].clone()).collect();
    c.qe_refs = order.iter().map(|&i| c.qe_refs[i].clone()).collect();
    let names: Vec<&str> = order.iter().map(|&i| refs[i].0.as_str()).collect();
    if !(names == ["r", "g", "b"] || names == ["w"]) {
        return Err(loc(
            path,
            text,
            node.span(),
            format!("'qe' needs r, g and b (or w for a mono sensor), found {names:?}"),
        ));
    }
    Ok(())
}

fn parse_matrix(node: &KdlNode, path: &Path, text: &str) -> crate::Result<Vec<Vec<f64>>> {
    let Some(ch) = node.children() else {
        return Err(loc(
            path,
            text,
            node.span(),
            "'qe-matrix' takes a block of rows: qe-matrix { row 1 0 0; … }".into(),
        ));
    };
    if !node.entries().is_empty() {
        return Err(loc(
            path,
            text,
            node.span(),
            "'qe-matrix' takes only a block of rows".into(),
        ));
    }
    let mut m = vec![];
    for r in ch.nodes() {
        if r.name().value() != "row" {
            return Err(loc(
                path,
                text,
                r.name().span(),
                format!("expected 'row', found '{}'", r.name().value()),
            ));
        }
        let mut row = vec![];
        for e in r.entries() {
            let x = match (e.name(), e.value()) {
                (None, KdlValue::Integer(i)) => *i as f64,
                (None, KdlValue::Float(x)) if x.is_finite() => *x,
                _ => {
                    return Err(loc(
                        path,
                        text,
                        e.span(),
                        "matrix entries are plain numbers".into(),
                    ));
                }
            };
            row.push(x);
        }
        m.push(row);
    }
    let n = m.len();
    if n == 0 || m.iter().any(|r| r.len() != n) {
        return Err(loc(
            path,
            text,
            node.span(),
            format!(
                "'qe-matrix' must be square; found {n} rows of lengths {:?}",
                m.iter().map(|r| r.len()).collect::<Vec<_>>()
            ),
        ));
    }
    Ok(m)
}

fn parse_ri(
    node: &KdlNode,
    base: &Path,
    path: &Path,
    text: &str,
) -> crate::Result<RelativeIllumination> {
    let args: Vec<_> = node
        .entries()
        .iter()
        .filter(|e| e.name().is_none())
        .collect();
    let model = match args.as_slice() {
        [a] => a.value().as_string().map(str::to_string).ok_or_else(|| {
            loc(
                path,
                text,
                a.span(),
                "relative-illumination model is a string: \"none\", \"cos-n\" or \"table\"".into(),
            )
        })?,
        _ => {
            return Err(loc(
                path,
                text,
                node.span(),
                "relative-illumination takes one model name: \"none\", \"cos-n\" or \"table\""
                    .into(),
            ));
        }
    };
    let prop = |n: &str| {
        node.entries()
            .iter()
            .find(|e| e.name().map(|i| i.value()) == Some(n))
    };
    let allowed: &[&str] = match model.as_str() {
        "none" => &[],
        "cos-n" => &["n", "distance-mm"],
        "table" => &["file"],
        m => {
            let hint =
                did_you_mean(m, ["none", "cos-n", "table"]).map(|s| format!("did you mean '{s}'?"));
            return Err(Error::from(
                Located::at_offset(
                    path,
                    text,
                    args[0].span().offset(),
                    args[0].span().len(),
                    format!("unknown relative-illumination model '{m}'"),
                )
                .with_help_opt(hint),
            ));
        }
    };
    for e in node.entries() {
        if let Some(n) = e.name()
            && !allowed.contains(&n.value())
        {
            let hint = did_you_mean(n.value(), allowed.iter().copied())
                .map(|s| format!("did you mean '{s}'?"));
            return Err(Error::from(
                Located::at_offset(
                    path,
                    text,
                    e.span().offset(),
                    e.span().len(),
                    format!(
                        "'{}' is not a property of model '{model}' (allowed: {allowed:?})",
                        n.value()
                    ),
                )
                .with_help_opt(hint),
            ));
        }
    }
    let number = |n: &str| -> crate::Result<f64> {
        let e = prop(n).ok_or_else(|| {
            loc(
                path,
                text,
                node.span(),
                format!("model '{model}' needs {n}=…"),
            )
        })?;
        match e.value() {
            KdlValue::Integer(i) => Ok(*i as f64),
            KdlValue::Float(x) if x.is_finite() => Ok(*x),
            _ => Err(loc(path, text, e.span(), format!("'{n}' expects a number"))),
        }
    };
    match model.as_str() {
        "none" => Ok(RelativeIllumination::None),
        "cos-n" => {
            let n = number("n")?;
            let d = number("distance-mm")?;
            if n < 0.0 || d <= 0.0 {
                return Err(loc(
                    path,
                    text,
                    node.span(),
                    format!("cos-n needs n ≥ 0 and distance-mm > 0, found n={n}, distance-mm={d}"),
                ));
            }
            Ok(RelativeIllumination::CosN { n, distance_mm: d })
        }
        _ => {
            if let Some(ch) = node.children() {
                if prop("file").is_some() {
                    return Err(loc(
                        path,
                        text,
                        node.span(),
                        "give the table as file=… or as point children, not both".into(),
                    ));
                }
                let mut h = vec![];
                let mut v = vec![];
                for p in ch.nodes() {
                    if p.name().value() != "point" {
                        return Err(loc(
                            path,
                            text,
                            p.name().span(),
                            format!(
                                "expected 'point field-height-mm=… value=…', found '{}'",
                                p.name().value()
                            ),
                        ));
                    }
                    let get = |n: &str| -> crate::Result<f64> {
                        let e = p
                            .entries()
                            .iter()
                            .find(|e| e.name().map(|i| i.value()) == Some(n))
                            .ok_or_else(|| {
                                loc(path, text, p.span(), format!("'point' needs {n}=…"))
                            })?;
                        match e.value() {
                            KdlValue::Integer(i) => Ok(*i as f64),
                            KdlValue::Float(x) if x.is_finite() => Ok(*x),
                            _ => Err(loc(path, text, e.span(), format!("'{n}' expects a number"))),
                        }
                    };
                    for e in p.entries() {
                        let ok = e.name().is_some_and(|n| {
                            n.value() == "field-height-mm" || n.value() == "value"
                        });
                        if !ok {
                            let hint = e
                                .name()
                                .and_then(|n| did_you_mean(n.value(), ["field-height-mm", "value"]))
                                .map(|s| format!("did you mean '{s}'?"));
                            return Err(Error::from(
                                Located::at_offset(
                                    path,
                                    text,
                                    e.span().offset(),
                                    e.span().len(),
                                    "'point' takes field-height-mm=… value=…",
                                )
                                .with_help_opt(hint),
                            ));
                        }
                    }
                    h.push(get("field-height-mm")?);
                    v.push(get("value")?);
                }
                table(h, v).map_err(|m| loc(path, text, node.span(), m))
            } else {
                let e = prop("file").ok_or_else(|| {
                    loc(
                        path,
                        text,
                        node.span(),
                        "table needs file=\"ri.csv\" or point children".into(),
                    )
                })?;
                let f = e.value().as_string().ok_or_else(|| {
                    loc(path, text, e.span(), "'file' expects a path string".into())
                })?;
                let p = base.join(f);
                let (h, v) = read_ri_csv(&p).map_err(|m| loc(path, text, e.span(), m))?;
                table(h, v).map_err(|m| loc(path, text, e.span(), format!("{}: {m}", p.display())))
            }
        }
    }
}

fn table(h: Vec<f64>, v: Vec<f64>) -> Result<RelativeIllumination, String> {
    if h.is_empty() {
        return Err("relative-illumination table is empty".into());
    }
    for i in 1..h.len() {
        if h[i] <= h[i - 1] {
            return Err(format!(
                "field heights must increase ({} then {} mm)",
                h[i - 1],
                h[i]
            ));
        }
    }
    if h.iter().chain(&v).any(|x| !x.is_finite()) || v.iter().any(|&x| x < 0.0) || h[0] < 0.0 {
        return Err("relative-illumination values must be finite and ≥ 0".into());
    }
    Ok(RelativeIllumination::Table {
        field_height_mm: h,
        value: v,
    })
}

/// Read `field_height_mm,relative_illumination` CSV (the output of `camsim lens ri`;
/// `#` comment lines allowed).
pub fn read_ri_csv(p: &Path) -> Result<(Vec<f64>, Vec<f64>), String> {
    let t = std::fs::read_to_string(p).map_err(|e| format!("{}: {e}", p.display()))?;
    let mut lines = t
        .lines()
        .filter(|l| !l.trim().is_empty() && !l.trim_start().starts_with('#'));
    let header = lines
        .next()
        .ok_or_else(|| format!("{}: empty file", p.display()))?;
    let cols: Vec<&str> = header.split(',').map(str::trim).collect();
    let hi = cols.iter().position(|c| *c == "field_height_mm");
    let vi = cols.iter().position(|c| *c == "relative_illumination");
    let (Some(hi), Some(vi)) = (hi, vi) else {
        return Err(format!(
            "{}: header must name field_height_mm and relative_illumination, found '{header}'",
            p.display()
        ));
    };
    let (mut h, mut v) = (vec![], vec![]);
    for (n, l) in lines.enumerate() {
        let f: Vec<&str> = l.split(',').map(str::trim).collect();
        let g = |i: usize| -> Result<f64, String> {
            f.get(i)
                .and_then(|s| s.parse::<f64>().ok())
                .ok_or_else(|| format!("{}: data row {}: bad number in '{l}'", p.display(), n + 1))
        };
        h.push(g(hi)?);
        v.push(g(vi)?);
    }
    Ok((h, v))
}

/// Check-time validator of an experiment's `sensor` section (built into
/// `experiment::check`): the file (or the generic sensor)
/// with each inline override applied in turn, so an unknown or out-of-range
/// property is reported at its own `file:line:col` before anything runs.
pub fn validate_overrides(
    file: Option<&Path>,
    p: &Params,
) -> std::result::Result<(), crate::params::ParamError> {
    use crate::params::ParamError;
    let mut cfg = match file {
        Some(f) => SensorConfig::load(f).map_err(|e| ParamError::new(None, e.to_string()))?,
        None => SensorConfig::generic(),
    };
    cfg.apply_overrides_at(p)
        .map_err(|(k, e)| ParamError::new(k, e))
}

#[cfg(test)]
mod tests {
    use super::*;

    fn parse(s: &str) -> crate::Result<SensorConfig> {
        SensorConfig::parse(s, Path::new("t.kdl"))
    }

    #[test]
    fn unknown_and_unitless_names_are_located_with_help() {
        let e = parse("bit-depth 10\npixel-size 1.4\n")
            .unwrap_err()
            .to_string();
        assert!(e.starts_with("t.kdl:2:1:"), "{e}");
        assert!(e.contains("pixel-size-um"), "{e}");
        let e = parse("exposure-ms 10\n").unwrap_err().to_string();
        assert!(e.contains("did you mean 'exposure-s'"), "{e}");
    }

    #[test]
    fn wrong_types_and_ranges() {
        let e = parse("bit-depth \"ten\"\n").unwrap_err().to_string();
        assert!(
            e.contains("t.kdl:1:11") && e.contains("expects a number"),
            "{e}"
        );
        assert!(
            parse("fill-factor 100\n")
                .unwrap_err()
                .to_string()
                .contains("fraction")
        );
        assert!(parse("bit-depth 10.5\n").is_err());
        assert!(
            parse("photon-noise 1\n")
                .unwrap_err()
                .to_string()
                .contains("#true")
        );
        assert!(parse("black-level-dv 2000\n").is_err());
        assert!(parse("read-noise-mv -1\n").is_err());
        assert!(
            parse("rows 10\nrows 12\n")
                .unwrap_err()
                .to_string()
                .contains("twice")
        );
        assert!(parse("qe r=\"p4a-qe-r\" g=\"p4a-qe-g\"\n").is_err());
        assert!(
            parse("qe r=\"p4a-qe-r\" g=\"p4a-qe-g\" b=\"p4a-qe-bb\"\n")
                .unwrap_err()
                .to_string()
                .contains("did you mean")
        );
        assert!(parse("exposure-s \"later\"\n").is_err());
        let e = parse("exposure-s \"auto\"\nauto-exposure-percentile 150\n")
            .unwrap_err()
            .to_string();
        assert!(e.contains("(0, 100]"), "{e}");
        let c = parse("exposure-s \"auto\"\nauto-exposure-percentile 100\n").unwrap();
        assert_eq!(
            c.exposure,
            Exposure::Auto {
                level: 0.95,
                percentile: 100.0
            }
        );
        assert!(
            parse("garbage {{{")
                .unwrap_err()
                .to_string()
                .starts_with("t.kdl:")
        );
    }

    #[test]
    fn overrides_apply_and_suggest() {
        let mut c = SensorConfig::generic();
        let mut p = Params::new();
        p.set("exposure-s", Value::Number(0.2));
        p.set("photon-noise", Value::Bool(false));
        c.apply_overrides(&p).unwrap();
        assert_eq!(c.exposure, Exposure::Seconds(0.2));
        assert!(!c.sources.photon_noise);
        let mut p = Params::new();
        p.set("exposure-sec", Value::Number(0.2));
        let e = c.apply_overrides(&p).unwrap_err();
        assert!(e.contains("did you mean 'exposure-s'"), "{e}");
    }

    #[test]
    fn ktc_noise_by_hand() {
        // C = 1.602e-19 / 76.5e-6 = 2.094 fF; √(1.381e-23·300 / 2.094e-15) = 1.406 mV
        let v = ktc_noise_v(76.5e-6, 300.0);
        assert!((v - 1.406e-3).abs() < 0.002e-3, "{v}");
    }

    #[test]
    fn resolved_params_round_trip() {
        let mut a = parse(
            "cfa \"gbrg\"\nexposure-s 0.3\nread-noise-mv 0.2\nprnu #false\nrows 10\ncols 12\n",
        )
        .unwrap();
        a.conversion_gain = ConversionGain::DvPerElectron(0.2);
        let p = a.resolved_params();
        let mut b = SensorConfig::generic();
        b.apply_overrides(&p).unwrap();
        assert_eq!(b.resolved_params(), p);
        assert!((b.conversion_gain_dv_per_e() - 0.2).abs() < 1e-12);
        assert_eq!(b.cfa, a.cfa);
        assert!(!b.sources.prnu);
    }

    #[test]
    fn relative_illumination_models() {
        let c = parse("relative-illumination \"cos-n\" n=4 distance-mm=4.0\n").unwrap();
        let ri = &c.relative_illumination;
        assert_eq!(ri.at(0.0), 1.0);
        let expect = (4.0f64 / (16.0f64 + 9.0).sqrt()).powi(4);
        assert!((ri.at(3.0) - expect).abs() < 1e-12);
        let c = parse("relative-illumination \"table\" {\n point field-height-mm=0 value=1\n point field-height-mm=2 value=0.5\n}\n").unwrap();
        assert!((c.relative_illumination.at(1.0) - 0.75).abs() < 1e-12);
        assert_eq!(c.relative_illumination.at(5.0), 0.5);
        let e = parse("relative-illumination \"cos-n\" n=4 distance=4.0\n")
            .unwrap_err()
            .to_string();
        assert!(e.contains("distance-mm"), "{e}");
    }
}
