//! The properties of a sensor — the scalar nodes of a sensor file and the
//! inline properties of an experiment's `sensor` node — in one [`SCHEMA`], read
//! by one setter (`set_property`), and [`sensor_config`]: the one function
//! `camsim check` and `camsim run` call to build a sensor from its file and
//! its inline properties.
//!
//! Units are in the names (`pixel-size-um`, `read-noise-mv`); inside a
//! [`SensorConfig`] everything is SI (metres, volts, fractions).

use super::config::{ConversionGain, Exposure, SensorConfig, UNITY_GAIN_ISO};
use crate::image::CfaPattern;
use crate::params::{Kind, ParamDict, ParamError, ParamSpec, Params, Schema, Value};
use crate::spectrum::library;
use std::path::Path;

/// Block nodes of a sensor file (not settable inline).
pub const BLOCK_NAMES: &[&str] = &["qe", "qe-matrix", "relative-illumination"];

/// The CFA patterns a sensor can have.
pub const CFA_PATTERNS: &[&str] = &["rggb", "bggr", "grbg", "gbrg", "mono"];

/// The properties of a `sensor` node (and the scalar nodes of a sensor file).
/// Defaults are the built-in generic sensor's ([`SensorConfig::generic`], used
/// when the node names no file); with a file, an absent property keeps the
/// file's value. Each example differs from `sensors/imx363.kdl` and from the
/// default, and is valid alone on `sensor "sensors/imx363.kdl"`.
pub static SCHEMA: Schema = Schema {
    node: "sensor",
    params: &[
        ParamSpec::new(
            "name",
            Kind::Text,
            "generic",
            "Name of the sensor in manifests and reports",
            "\"my-sensor\"",
        ),
        ParamSpec::new(
            "rows",
            Kind::Integer,
            "",
            "Pixel rows (1…10⁶); absent: the optical image's field of view",
            "480",
        ),
        ParamSpec::new(
            "cols",
            Kind::Integer,
            "",
            "Pixel columns (1…10⁶); absent: the optical image's field of view",
            "640",
        ),
        ParamSpec::new(
            "pixel-size-um",
            Kind::Number,
            "1.4",
            "Pixel pitch, µm (> 0, ≤ 1000)",
            "1.12",
        ),
        ParamSpec::new(
            "fill-factor",
            Kind::Number,
            "1",
            "Photosensitive fraction of the pixel area, (0, 1]",
            "0.8",
        ),
        ParamSpec::new(
            "cfa",
            Kind::Choice(CFA_PATTERNS),
            "rggb",
            "Colour filter array, read row by row from the top-left 2×2 cell; \"mono\" needs a file with one `qe w=…`",
            "\"bggr\"",
        ),
        ParamSpec::new(
            "ir-filter",
            Kind::Spectrum,
            "one",
            "IR-cut filter transmittance (a shipped spectrum or file.csv#column, relative to the sensor file)",
            "\"ircf-largan\"",
        ),
        ParamSpec::new(
            "well-capacity-e",
            Kind::Number,
            "6000",
            "Well capacity, electrons (> 0)",
            "4500",
        ),
        ParamSpec::new(
            "voltage-swing-v",
            Kind::Number,
            "0.45",
            "Voltage swing of the pixel, V (> 0)",
            "0.6",
        ),
        ParamSpec::new(
            "conversion-gain-dv-per-e",
            Kind::Number,
            "",
            "Conversion gain at analog gain 1, DV/e⁻ (> 0); absent with conversion-gain-uv-per-e: voltage swing / well capacity; not with conversion-gain-uv-per-e",
            "0.25",
        ),
        ParamSpec::new(
            "conversion-gain-uv-per-e",
            Kind::Number,
            "",
            "Conversion gain at the sense node, µV/e⁻ (> 0); not with conversion-gain-dv-per-e",
            "50",
        ),
        ParamSpec::new(
            "analog-gain",
            Kind::Number,
            "1",
            "Gain applied to the pixel voltage before the ADC (> 0); not with iso",
            "2.5",
        ),
        ParamSpec::new(
            "iso",
            Kind::Number,
            "55",
            "Analog gain as ISO: gain = iso / 55 (> 0); not with analog-gain",
            "220",
        ),
        ParamSpec::new(
            "black-level-dv",
            Kind::Number,
            "64",
            "Black level, DV (≥ 0, below the white level 2^bits − 1)",
            "128",
        ),
        ParamSpec::new("bit-depth", Kind::Integer, "10", "ADC bits (1…16)", "12"),
        ParamSpec::new(
            "exposure-s",
            Kind::NumberOr(&["auto"]),
            "0.01",
            "Exposure time, s (≥ 0), or \"auto\" (auto-exposure-level, auto-exposure-percentile)",
            "0.125",
        ),
        ParamSpec::new(
            "auto-exposure-level",
            Kind::Number,
            "0.95",
            "Auto-exposure target, fraction of full well, (0, 1]; switches exposure-s to \"auto\" (not with a numeric exposure-s)",
            "0.8",
        ),
        ParamSpec::new(
            "auto-exposure-percentile",
            Kind::Number,
            "99.9",
            "Percentile of the pixels' mean signal that reaches the target, (0, 100]; switches exposure-s to \"auto\" (not with a numeric exposure-s)",
            "99.5",
        ),
        ParamSpec::new(
            "read-noise-mv",
            Kind::Number,
            "0",
            "Read noise, mV rms (≥ 0)",
            "0.5",
        ),
        ParamSpec::new(
            "reset-noise-mv",
            Kind::Number,
            "0",
            "Reset (kTC) noise, mV rms (≥ 0); 0 with correlated double sampling",
            "1.4",
        ),
        ParamSpec::new(
            "dsnu-mv",
            Kind::Number,
            "0",
            "Dark signal non-uniformity, mV rms (≥ 0)",
            "0.25",
        ),
        ParamSpec::new(
            "prnu-percent",
            Kind::Number,
            "0",
            "Photo-response non-uniformity, % rms (0 ≤ x < 100)",
            "1.5",
        ),
        ParamSpec::new(
            "dark-voltage-mv-per-s",
            Kind::Number,
            "0",
            "Dark current as a voltage rate, mV/s (≥ 0)",
            "0.75",
        ),
        ParamSpec::new(
            "column-fpn-offset-mv",
            Kind::Number,
            "0",
            "Column offset fixed-pattern noise, mV rms (≥ 0)",
            "0.1",
        ),
        ParamSpec::new(
            "column-fpn-gain-percent",
            Kind::Number,
            "0",
            "Column gain fixed-pattern noise, % rms (≥ 0)",
            "0.2",
        ),
        ParamSpec::new(
            "fpn-seed",
            Kind::Integer,
            "1",
            "Seed of the fixed-pattern fields (PRNU, DSNU, column FPN) of this sensor unit (0…2⁵³)",
            "4242",
        ),
        ParamSpec::new(
            "illuminance-scale-factor",
            Kind::Number,
            "1",
            "Calibration: factor on the optical image's irradiance before the sensor (the paper's per-figure mean-illuminance factors; > 0); recorded in the manifest and the report",
            "0.57",
        ),
        ParamSpec::new(
            "photon-noise",
            Kind::Bool,
            "#true",
            "Simulate photon (shot) noise",
            "#false",
        ),
        ParamSpec::new(
            "dark-current",
            Kind::Bool,
            "#true",
            "Simulate dark current",
            "#false",
        ),
        ParamSpec::new("dsnu", Kind::Bool, "#true", "Simulate DSNU", "#false"),
        ParamSpec::new("prnu", Kind::Bool, "#true", "Simulate PRNU", "#false"),
        ParamSpec::new(
            "read-noise",
            Kind::Bool,
            "#true",
            "Simulate read noise",
            "#false",
        ),
        ParamSpec::new(
            "reset-noise",
            Kind::Bool,
            "#true",
            "Simulate reset noise",
            "#false",
        ),
        ParamSpec::new(
            "column-fpn",
            Kind::Bool,
            "#true",
            "Simulate column fixed-pattern noise",
            "#false",
        ),
        ParamSpec::new(
            "pixel-vignetting",
            Kind::Bool,
            "#true",
            "Apply the sensor file's relative-illumination",
            "#false",
        ),
        ParamSpec::new(
            "clipping",
            Kind::Bool,
            "#true",
            "Clip at the full well and the ADC range",
            "#false",
        ),
        ParamSpec::new(
            "quantization",
            Kind::Bool,
            "#true",
            "Round to whole digital values",
            "#false",
        ),
    ],
};

/// Set property `name` of `cfg` from `d` (a typed look-up, so it is marked
/// used), checking its value. Shared by the sensor file's scalar nodes and an
/// experiment's inline properties. An absent property changes nothing.
pub(super) fn set_property(
    cfg: &mut SensorConfig,
    d: &ParamDict,
    name: &str,
) -> Result<(), ParamError> {
    let mv = 1e-3;
    let range = |x: f64, ok: bool, what: &str| {
        if ok {
            Ok(x)
        } else {
            Err(ParamError::value(
                name,
                format!("'{name}' {what}, found {x}"),
            ))
        }
    };
    match name {
        "name" => {
            if let Some(s) = d.str(name)? {
                cfg.name = s.to_string();
            }
        }
        "rows" => {
            if let Some(r) = d.int(name, 1, 1_000_000)? {
                cfg.rows = Some(r as u32);
            }
        }
        "cols" => {
            if let Some(c) = d.int(name, 1, 1_000_000)? {
                cfg.cols = Some(c as u32);
            }
        }
        "pixel-size-um" => {
            if let Some(x) = d.positive(name)? {
                let x = range(
                    x,
                    x <= 1000.0,
                    "is not a pixel size (the unit is micrometres)",
                )?;
                cfg.pixel_size_m = x * 1e-6;
            }
        }
        "fill-factor" => {
            if let Some(x) = d.positive(name)? {
                cfg.fill_factor = range(x, x <= 1.0, "is a fraction in (0, 1] (100 % is 1.0)")?;
            }
        }
        "cfa" => {
            if let Some(s) = d.choice(name)? {
                cfg.cfa = CfaPattern::bayer(s).map_err(|e| ParamError::value(name, e))?;
            }
        }
        "ir-filter" => {
            if let Some(s) = d.str(name)? {
                cfg.ir_filter =
                    library::resolve(s, &cfg.base_dir()).map_err(|e| ParamError::value(name, e))?;
                cfg.ir_filter_ref = s.to_string();
            }
        }
        "well-capacity-e" => {
            if let Some(x) = d.positive(name)? {
                cfg.well_capacity_e = x;
            }
        }
        "voltage-swing-v" => {
            if let Some(x) = d.positive(name)? {
                cfg.voltage_swing_v = x;
            }
        }
        "conversion-gain-dv-per-e" => {
            if let Some(x) = d.positive(name)? {
                cfg.conversion_gain = ConversionGain::DvPerElectron(x);
            }
        }
        "conversion-gain-uv-per-e" => {
            if let Some(x) = d.positive(name)? {
                cfg.conversion_gain = ConversionGain::VoltsPerElectron(x * 1e-6);
            }
        }
        "analog-gain" => {
            if let Some(x) = d.positive(name)? {
                cfg.analog_gain = x;
            }
        }
        "iso" => {
            if let Some(x) = d.positive(name)? {
                cfg.analog_gain = x / UNITY_GAIN_ISO;
            }
        }
        "black-level-dv" => {
            if let Some(x) = d.nonneg(name)? {
                cfg.black_level_dv = x;
            }
        }
        "bit-depth" => {
            if let Some(b) = d.int(name, 1, 16)? {
                cfg.bit_depth = b as u32;
            }
        }
        "exposure-s" => match d.raw(name)? {
            None => {}
            // "auto" keeps the file's auto-exposure settings.
            Some(Value::String(s)) if s == "auto" => {
                if let Exposure::Seconds(_) = cfg.exposure {
                    cfg.exposure = Exposure::auto_default();
                }
            }
            Some(Value::String(s)) => {
                return Err(ParamError::value(
                    name,
                    format!("'exposure-s' expects seconds or \"auto\", found \"{s}\""),
                ));
            }
            Some(_) => {
                if let Some(t) = d.nonneg(name)? {
                    cfg.exposure = Exposure::Seconds(t);
                }
            }
        },
        "auto-exposure-level" => {
            if let Some(x) = d.positive(name)? {
                let x = range(x, x <= 1.0, "is a fraction of full well in (0, 1]")?;
                cfg.set_auto_exposure(Some(x), None);
            }
        }
        "auto-exposure-percentile" => {
            if let Some(x) = d.positive(name)? {
                let x = range(x, x <= 100.0, "is a percentile in (0, 100]")?;
                cfg.set_auto_exposure(None, Some(x));
            }
        }
        "read-noise-mv" => {
            if let Some(x) = d.nonneg(name)? {
                cfg.read_noise_v = x * mv;
            }
        }
        "reset-noise-mv" => {
            if let Some(x) = d.nonneg(name)? {
                cfg.reset_noise_v = x * mv;
            }
        }
        "dsnu-mv" => {
            if let Some(x) = d.nonneg(name)? {
                cfg.dsnu_v = x * mv;
            }
        }
        "prnu-percent" => {
            if let Some(x) = d.nonneg(name)? {
                let x = range(x, x < 100.0, "must be below 100")?;
                cfg.prnu = x / 100.0;
            }
        }
        "dark-voltage-mv-per-s" => {
            if let Some(x) = d.nonneg(name)? {
                cfg.dark_voltage_v_per_s = x * mv;
            }
        }
        "column-fpn-offset-mv" => {
            if let Some(x) = d.nonneg(name)? {
                cfg.column_fpn_offset_v = x * mv;
            }
        }
        "column-fpn-gain-percent" => {
            if let Some(x) = d.nonneg(name)? {
                cfg.column_fpn_gain = x / 100.0;
            }
        }
        "illuminance-scale-factor" => {
            if let Some(x) = d.positive(name)? {
                cfg.illuminance_scale = x;
            }
        }
        "fpn-seed" => {
            if let Some(s) = d.int(name, 0, 1 << 53)? {
                cfg.fpn_seed = s;
            }
        }
        _ => {
            let s = &mut cfg.sources;
            let flag = match name {
                "photon-noise" => &mut s.photon_noise,
                "dark-current" => &mut s.dark_current,
                "dsnu" => &mut s.dsnu,
                "prnu" => &mut s.prnu,
                "read-noise" => &mut s.read_noise,
                "reset-noise" => &mut s.reset_noise,
                "column-fpn" => &mut s.column_fpn,
                "pixel-vignetting" => &mut s.pixel_vignetting,
                "clipping" => &mut s.clipping,
                "quantization" => &mut s.quantization,
                // Not a sensor property: `d.raw` names the schema's fault, and
                // `finish` reports a user's unknown name.
                other => {
                    d.raw(other)?;
                    return Ok(());
                }
            };
            if let Some(b) = d.bool(name)? {
                *flag = b;
            }
        }
    }
    Ok(())
}

/// Two properties that set the same thing cannot both be written.
fn exclusive(d: &ParamDict, a: &str, b: &str, why: &str) -> Result<(), ParamError> {
    if d.has(a) && d.has(b) {
        return Err(ParamError::new(
            Some(b),
            format!("'{a}' and '{b}' both set {why}; write one of them"),
        ));
    }
    Ok(())
}

/// Apply an experiment's inline `sensor` properties to `cfg`: every property
/// through `set_property` in [`SCHEMA`] order, then unknown names and the
/// cross-field checks. Errors name the property.
pub fn apply_params(cfg: &mut SensorConfig, params: &Params) -> Result<(), ParamError> {
    let d = ParamDict::new(params, &SCHEMA);
    if let Some(b) = BLOCK_NAMES.iter().find(|b| d.has(b)) {
        return Err(ParamError::new(
            Some(b),
            format!("'{b}' is a block and can only be set in the sensor file"),
        ));
    }
    exclusive(&d, "analog-gain", "iso", "the analog gain")?;
    exclusive(
        &d,
        "conversion-gain-dv-per-e",
        "conversion-gain-uv-per-e",
        "the conversion gain",
    )?;
    if let Some(Value::Number(t)) = params.get("exposure-s") {
        for k in ["auto-exposure-level", "auto-exposure-percentile"] {
            if d.has(k) {
                return Err(ParamError::new(
                    Some(k),
                    format!(
                        "'{k}' applies to exposure-s=\"auto\", not to the fixed exposure-s={t}"
                    ),
                ));
            }
        }
    }
    for p in SCHEMA.params {
        if d.has(p.name) {
            set_property(cfg, &d, p.name)?;
        }
    }
    d.finish()?;
    cfg.validate().map_err(ParamError::section)
}

/// The sensor of an experiment: `file` (or the built-in generic sensor when
/// `None`) with the inline properties `params` applied. The one function both
/// `camsim check` and `camsim run` use; an error names the property.
pub fn sensor_config(file: Option<&Path>, params: &Params) -> Result<SensorConfig, ParamError> {
    let mut cfg = match file {
        Some(f) => SensorConfig::load(f).map_err(|e| ParamError::section(e.to_string()))?,
        None => SensorConfig::generic(),
    };
    apply_params(&mut cfg, params)?;
    Ok(cfg)
}

impl SensorConfig {
    /// Apply inline properties (experiment `sensor "…" exposure-s=0.2`) to this
    /// config: [`apply_params`] with the error as text.
    pub fn apply_overrides(&mut self, p: &Params) -> Result<(), String> {
        apply_params(self, p).map_err(|e| e.to_string())
    }
}

#[cfg(test)]
mod tests {
    use super::*;
    use crate::sensor::config::ConversionGain;

    fn parse(s: &str) -> crate::Result<SensorConfig> {
        SensorConfig::parse(s, Path::new("t.kdl"))
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
}
