//! A measurement as an experiment asks for it: `measure "<kind>" …` read into
//! typed options ([`options`], one [`ParamDict`] pass per node, the same for
//! `camsim check` and `camsim run`) and run on a variant's images ([`run`]).
//!
//! Each kind's properties are listed once, in the `SCHEMA` beside the
//! measurement (`sfr::SCHEMA`, `noise::SCHEMA`, …; see [`schema`]); the
//! properties every kind shares (`name`, `of`, `input`) come from the
//! constructors here so their docs agree.

use super::Measured;
use super::colorimetry::ColorimetryOptions;
use super::compare::CompareOptions;
use super::compare_curve::CompareCurveOptions;
use super::convergence::ConvergenceOptions;
use super::conversion_gain::ConversionGainOptions;
use super::mcc::MccRequest;
use super::noise::NoiseRequest;
use super::plane::Plane;
use super::profile::ProfileRequest;
use super::ri::RiRequest;
use super::sensor_calibration::CalibrationOptions;
use super::sfr::SfrRequest;
use super::stability::StabilityOptions;
use crate::params::{ParamDict, ParamError, Params, Schema, Value};
use crate::{Error, Result};
use std::path::Path;

pub use super::shared_params::{input_param, name_param, nonempty, of_param, roi_px};

/// The kinds of `measure "<kind>"`, in the order of the language reference.
pub const KINDS: &[&str] = &[
    "colorimetry",
    "sfr",
    "ri",
    "noise",
    "profile",
    "mcc",
    "compare",
    "compare-curve",
    "convergence",
    "conversion-gain",
    "sensor-calibration",
    "stability",
];

/// The schema of `measure "<kind>"`.
pub fn schema(kind: &str) -> Option<&'static Schema> {
    Some(match kind {
        "colorimetry" => &super::colorimetry::SCHEMA,
        "sfr" => &super::sfr::SCHEMA,
        "ri" => &super::ri::SCHEMA,
        "noise" => &super::noise::SCHEMA,
        "profile" => &super::profile::SCHEMA,
        "mcc" => &super::mcc::SCHEMA,
        "compare" => &super::compare::SCHEMA,
        "compare-curve" => &super::compare_curve::SCHEMA,
        "convergence" => &super::convergence::SCHEMA,
        "conversion-gain" => &super::conversion_gain::SCHEMA,
        "sensor-calibration" => &super::sensor_calibration::SCHEMA,
        "stability" => &super::stability::SCHEMA,
        _ => return None,
    })
}

/// Every measurement kind's schema, in [`KINDS`] order.
pub fn schemas() -> Vec<&'static Schema> {
    KINDS.iter().filter_map(|k| schema(k)).collect()
}

/// The typed options of one measurement.
#[derive(Clone, Debug)]
pub enum MeasureOptions {
    Colorimetry(ColorimetryOptions),
    Sfr(SfrRequest),
    Ri(RiRequest),
    Noise(NoiseRequest),
    Profile(ProfileRequest),
    Mcc(MccRequest),
    Compare(CompareOptions),
    CompareCurve(CompareCurveOptions),
    Convergence(ConvergenceOptions),
    ConversionGain(ConversionGainOptions),
    SensorCalibration(CalibrationOptions),
    Stability(StabilityOptions),
}

/// Read the properties of `measure "<kind>"` (without `name`/`of`, which the
/// experiment layer reads). Every written property must be one of the kind's
/// schema and valid; unread ones are "unknown property" errors. Properties a
/// run cannot do without are checked by [`MeasureOptions::require_complete`]
/// (so each property can be tried standing alone).
pub fn options(kind: &str, params: &Params, base_dir: &Path) -> Result<MeasureOptions, ParamError> {
    let schema = schema(kind).ok_or_else(|| {
        ParamError::section(format!(
            "unknown measurement '{kind}'; expected one of: {}",
            KINDS.join(", ")
        ))
    })?;
    let d = ParamDict::new(params, schema);
    let o = match kind {
        "colorimetry" => {
            MeasureOptions::Colorimetry(super::colorimetry::from_params(&d, base_dir)?)
        }
        "sfr" => MeasureOptions::Sfr(super::sfr::from_params(&d)?),
        "ri" => MeasureOptions::Ri(super::ri::from_params(&d)?),
        "noise" => MeasureOptions::Noise(super::noise::from_params(&d)?),
        "profile" => MeasureOptions::Profile(super::profile::from_params(&d)?),
        "mcc" => MeasureOptions::Mcc(super::mcc::from_params(&d)?),
        "compare" => MeasureOptions::Compare(super::compare::from_params(&d)?),
        "compare-curve" => {
            MeasureOptions::CompareCurve(super::compare_curve::from_params(&d, base_dir)?)
        }
        "convergence" => MeasureOptions::Convergence(super::convergence::from_params(&d)?),
        "conversion-gain" => {
            MeasureOptions::ConversionGain(super::conversion_gain::from_params(&d)?)
        }
        "sensor-calibration" => {
            MeasureOptions::SensorCalibration(super::sensor_calibration::from_params(&d)?)
        }
        "stability" => MeasureOptions::Stability(super::stability::from_params(&d)?),
        _ => unreachable!("schema() knows the kind"),
    };
    d.finish()?;
    Ok(o)
}

/// [`options`] and [`MeasureOptions::require_complete`]: what `check` and
/// `run` call on every `measure` node.
pub fn checked(kind: &str, params: &Params, base_dir: &Path) -> Result<MeasureOptions, ParamError> {
    let o = options(kind, params, base_dir)?;
    o.require_complete()?;
    Ok(o)
}

impl MeasureOptions {
    /// The kind as written in KDL.
    pub fn kind(&self) -> &'static str {
        match self {
            MeasureOptions::Colorimetry(_) => "colorimetry",
            MeasureOptions::Sfr(_) => "sfr",
            MeasureOptions::Ri(_) => "ri",
            MeasureOptions::Noise(_) => "noise",
            MeasureOptions::Profile(_) => "profile",
            MeasureOptions::Mcc(_) => "mcc",
            MeasureOptions::Compare(_) => "compare",
            MeasureOptions::CompareCurve(_) => "compare-curve",
            MeasureOptions::Convergence(_) => "convergence",
            MeasureOptions::ConversionGain(_) => "conversion-gain",
            MeasureOptions::SensorCalibration(_) => "sensor-calibration",
            MeasureOptions::Stability(_) => "stability",
        }
    }

    /// The captured image this measurement reads (`input=`), if any.
    pub fn input(&self) -> Option<&str> {
        match self {
            MeasureOptions::Sfr(r) => r.input.as_deref(),
            MeasureOptions::Ri(r) => r.input.as_deref(),
            MeasureOptions::Noise(r) => r.input.as_deref(),
            MeasureOptions::Profile(r) => r.input.as_deref(),
            MeasureOptions::Mcc(r) => r.input.as_deref(),
            _ => None,
        }
    }

    /// Properties without which the measurement cannot run.
    pub fn require_complete(&self) -> Result<(), ParamError> {
        match self {
            MeasureOptions::Colorimetry(c) if c.spectrum.is_none() => Err(ParamError::section(
                "colorimetry needs spectrum=\"<name>\" (e.g. spectrum=\"cie-d65\")",
            )),
            MeasureOptions::Compare(c) if c.reference.is_none() => Err(ParamError::section(
                "compare needs reference=\"<measurement>\"",
            )
            .with_help("e.g. reference=\"mcc-measured\", a measurement of a captured image")),
            MeasureOptions::CompareCurve(c) if c.curve.is_none() => Err(ParamError::section(
                "compare-curve needs curve=\"<curve name>\"",
            )
            .with_help(
                "e.g. curve=\"ri\" or curve=\"edge-near/mtf\": a curve of the of= measurement",
            )),
            MeasureOptions::CompareCurve(c) if c.reference.is_none() => Err(ParamError::section(
                "compare-curve needs reference-file=\"….csv\"",
            )
            .with_help("a CSV with '#' comment lines, a header row and numeric columns")),
            MeasureOptions::Convergence(c) if c.spp.is_empty() => {
                Err(ParamError::section("convergence needs spp=(…)")
                    .with_help("e.g. spp=(16 64 256): at least two increasing sample counts"))
            }
            MeasureOptions::ConversionGain(c)
                if c.reference.is_some_and(|(m, v)| m.is_nan() || v.is_nan()) =>
            {
                Err(ParamError::section(
                    "conversion-gain: reference-mean-dv and reference-variance-dv2 go together",
                )
                .with_help(
                    "e.g. reference-mean-dv=320.7 reference-variance-dv2=57.8 (Fig. 11's caption)",
                ))
            }
            MeasureOptions::Stability(s) if s.case.is_none() => {
                Err(ParamError::section("stability needs case=\"<case>\"")
                    .with_help(format!("one of: {}", super::stability::CASES.join(", "))))
            }
            _ => Ok(()),
        }
    }
}

/// Which stages a measurement needs.
#[derive(Clone, Copy, Debug, Default, PartialEq, Eq)]
pub struct Needs {
    /// Scene, camera and render (the optical image).
    pub optical_image: bool,
    /// The sensor image (implies the optical image).
    pub sensor_image: bool,
    /// The variant's sensor configuration only (no scene, no render): the
    /// measurement synthesises its own frames through the sensor pipeline.
    pub sensor_config: bool,
}

impl Needs {
    /// What either of two measurements needs.
    pub fn union(self, o: Needs) -> Needs {
        Needs {
            optical_image: self.optical_image || o.optical_image,
            sensor_image: self.sensor_image || o.sensor_image,
            sensor_config: self.sensor_config || o.sensor_config,
        }
    }
}

/// Stage requirements per measurement kind. `colorimetry` reads a spectrum
/// only; `conversion-gain` and `sensor-calibration` the sensor's
/// configuration only (`stability` for its sensor cases); `ri` and `convergence` can work on the optical image;
/// every other kind measures sensor digital values.
pub fn needs(kind: &str) -> Needs {
    match kind {
        "colorimetry" | "compare" | "compare-curve" => Needs::default(),
        "conversion-gain" | "sensor-calibration" | "stability" => Needs {
            sensor_config: true,
            ..Needs::default()
        },
        "ri" | "convergence" => Needs {
            optical_image: true,
            ..Needs::default()
        },
        _ => Needs {
            optical_image: true,
            sensor_image: true,
            sensor_config: true,
        },
    }
}

pub use super::inputs::{Inputs, label_box, to_window};

/// Run measurement `name` (of the objects `of`) on a variant's rendered
/// images. `compare` and `convergence` combine other measurements, and
/// `stability` renders on its own: the experiment layer runs them.
pub fn run(name: &str, of: &[String], opts: &MeasureOptions, inp: &Inputs) -> Result<Measured> {
    let need_si = || {
        inp.si
            .ok_or_else(|| Error::invalid(format!("measurement '{name}' needs a sensor image")))
    };
    let need_sensor = || {
        inp.sensor.ok_or_else(|| {
            Error::invalid(format!(
                "measurement '{name}' needs a sensor (add sensor \"sensors/….kdl\")"
            ))
        })
    };
    let no_of = || -> Result<()> {
        if of.is_empty() {
            Ok(())
        } else {
            Err(Error::invalid(format!(
                "measurement '{name}': {} takes no of=",
                opts.kind()
            )))
        }
    };
    match opts {
        MeasureOptions::Colorimetry(c) => {
            no_of()?;
            Ok(Measured {
                figures: super::colorimetry::colorimetry(name, c, inp.grid)?,
                ..Default::default()
            })
        }
        MeasureOptions::Sfr(r) => super::sfr::run_on_sensor(name, of, r, need_si()?, inp),
        MeasureOptions::Mcc(r) => {
            let si = need_si()?;
            let chart = of.first().map(String::as_str).unwrap_or("mcc");
            let patches = super::mcc::patch_means_of_sensor(si, chart, r.inset_fraction)?;
            Ok(super::mcc::measured(&patches, name))
        }
        MeasureOptions::Profile(r) => {
            super::profile::profile_of_sensor(need_si()?, of, &r.options, name)
        }
        MeasureOptions::Noise(r) => {
            no_of()?;
            let si = need_si()?;
            let mut plane = Plane::from_sensor(si)?;
            let crop = r
                .roi_px
                .map(|roi| to_window(roi, si.window, "roi-px"))
                .transpose()?;
            if let Some(c) = crop {
                plane = plane.crop(c)?;
            }
            let opts = super::noise::NoiseOptions {
                conversion_gain_dv_per_e: r
                    .conversion_gain_dv_per_e
                    .unwrap_or(si.conversion_gain_dv_per_e),
                seed: r.seed.unwrap_or(inp.seed),
                ..r.options.clone()
            };
            // On a rendered image: the render's Monte Carlo variance per
            // pixel (in the outlier test's σ) and the noise model's prediction.
            let mc = match (inp.sensor, inp.oi) {
                (Some(cfg), Some(oi)) => {
                    let mut mc = super::noise_model::mc_variance_plane(cfg, si, oi, name)?;
                    if let Some(c) = crop {
                        mc = mc.crop(c)?;
                    }
                    Some((cfg, mc))
                }
                _ => None,
            };
            let (mut out, regions) =
                super::noise::measure_with(&plane, &opts, mc.as_ref().map(|m| &m.1), name)?;
            if let Some((cfg, mc)) = &mc {
                super::noise_model::add_model(
                    &mut out,
                    &regions,
                    &plane,
                    mc,
                    cfg,
                    &opts.channel,
                    r.band,
                    name,
                )?;
            }
            Ok(out)
        }
        MeasureOptions::Ri(r) => {
            no_of()?;
            if let Some(channel) = &r.channel {
                // One CFA channel of the sensor image, black level subtracted
                // (the paper's Fig. 5 reads the G plane).
                let si = need_si()?;
                let plane = Plane::from_sensor(si)?;
                let (cx, cy) = r
                    .center_px
                    .unwrap_or((si.full_width as f64 / 2.0, si.full_height as f64 / 2.0));
                let opts = super::ri::RiOptions {
                    pixel_pitch_m: Some(si.pixel_pitch_m),
                    center_px: Some((cx - si.window.x as f64, cy - si.window.y as f64)),
                    bins: r.bins,
                    channel: channel.clone(),
                };
                return super::ri::relative_illumination(&plane, &opts, name);
            }
            let oi = inp.oi.ok_or_else(|| {
                Error::invalid(format!("measurement '{name}' needs an optical image"))
            })?;
            // band-integrated irradiance (W/m²) per pixel
            let n = oi.bands();
            let data: Vec<f64> = (0..oi.window.area() as usize)
                .map(|i| {
                    (0..n)
                        .map(|b| oi.irradiance[i * n + b] as f64 * oi.grid.trapezoid_weight(b))
                        .sum()
                })
                .collect();
            let plane = Plane::new(oi.width() as usize, oi.height() as usize, data)?;
            let (cx, cy) = r
                .center_px
                .unwrap_or((oi.full_width as f64 / 2.0, oi.full_height as f64 / 2.0));
            let opts = super::ri::RiOptions {
                pixel_pitch_m: Some(oi.pixel_pitch_m),
                center_px: Some((cx - oi.window.x as f64, cy - oi.window.y as f64)),
                bins: r.bins,
                ..Default::default()
            };
            super::ri::relative_illumination(&plane, &opts, name)
        }
        MeasureOptions::ConversionGain(o) => {
            no_of()?;
            super::conversion_gain::measure(need_sensor()?, o, inp.seed, name)
        }
        MeasureOptions::SensorCalibration(o) => {
            no_of()?;
            super::sensor_calibration::measure(need_sensor()?, o, inp.seed, name)
        }
        MeasureOptions::Compare(_)
        | MeasureOptions::CompareCurve(_)
        | MeasureOptions::Convergence(_)
        | MeasureOptions::Stability(_) => Err(Error::invalid(format!(
            "measurement '{name}': {} is run by the experiment layer",
            opts.kind()
        ))),
    }
}

/// The KDL text of a value (for messages and self-checks).
pub fn kdl_text(v: &Value) -> String {
    match v {
        Value::Bool(b) => format!("#{b}"),
        Value::String(s) => format!("\"{s}\""),
        Value::Number(x) => x.to_string(),
        Value::List(l) => format!("({})", l.iter().map(kdl_text).collect::<Vec<_>>().join(" ")),
    }
}
