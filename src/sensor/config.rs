//! The sensor description, [`SensorConfig`], and the quantities derived from it
//! (conversion gain, full well, quantisation step, effective QE).
//!
//! A config is built from a sensor file ([`super::config_file`]: `sensors/*.kdl`)
//! and the inline properties of an experiment's `sensor` node
//! ([`super::sensor_params`]: its schema and [`super::sensor_config`]).

use crate::image::CfaPattern;
use crate::params::{Params, Value};
use crate::spectrum::Spectrum;
use std::path::{Path, PathBuf};

pub use super::relative_illumination::RelativeIllumination;

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
    /// A declared calibration factor on the optical image's irradiance before
    /// the sensor (the paper's per-figure mean-illuminance scale factors,
    /// `cornellbox_setup.json` render.illuminance_scale_factors); 1 = none.
    pub illuminance_scale: f64,
}

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

impl SensorConfig {
    /// A built-in generic sensor: 1.4 µm, RGGB, 10 bits, noiseless electronics,
    /// flat QE 0.5, fixed exposure 0.01 s (used when building configs in code and
    /// for an experiment's `sensor` node without a file). Not the same part as
    /// `sensors/generic.kdl` (2 µm, 12 bits, small noise, auto-exposure).
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
            illuminance_scale: 1.0,
        }
    }

    /// Base directory for relative spectrum paths.
    pub(super) fn base_dir(&self) -> PathBuf {
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
        p.set("illuminance-scale-factor", n(self.illuminance_scale));
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
    pub(super) fn set_auto_exposure(&mut self, level: Option<f64>, percentile: Option<f64>) {
        let (l, p) = match self.exposure {
            Exposure::Auto { level, percentile } => (level, percentile),
            Exposure::Seconds(_) => (AUTO_EXPOSURE_LEVEL, AUTO_EXPOSURE_PERCENTILE),
        };
        self.exposure = Exposure::Auto {
            level: level.unwrap_or(l),
            percentile: percentile.unwrap_or(p),
        };
    }
}

#[cfg(test)]
mod tests {
    use super::*;

    #[test]
    fn ktc_noise_by_hand() {
        // C = 1.602e-19 / 76.5e-6 = 2.094 fF; √(1.381e-23·300 / 2.094e-15) = 1.406 mV
        let v = ktc_noise_v(76.5e-6, 300.0);
        assert!((v - 1.406e-3).abs() < 0.002e-3, "{v}");
    }
}
