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
use super::convergence::ConvergenceOptions;
use super::mcc::MccRequest;
use super::noise::NoiseRequest;
use super::plane::Plane;
use super::profile::ProfileRequest;
use super::ri::RiRequest;
use super::sfr::SfrRequest;
use crate::image::SensorImage;
use crate::optical_image::{OpticalImage, Rect};
use crate::params::{Kind, ParamDict, ParamError, ParamSpec, Params, Schema, Value};
use crate::spectrum::WavelengthGrid;
use crate::{Error, Result};
use std::collections::BTreeMap;
use std::path::Path;

/// `name=`: the measurement's name in results (read by the experiment layer).
pub const fn name_param() -> ParamSpec {
    ParamSpec {
        name: "name",
        kind: Kind::Text,
        default: "the kind",
        doc: "the measurement's name in results.csv and in other measurements' of=/reference= (unique per experiment; no '.' or ',')",
        example: "\"m-probe\"",
    }
}

/// `of=`: what the measurement reads (read by the experiment layer).
pub const fn of_param(doc: &'static str, example: &'static str) -> ParamSpec {
    ParamSpec {
        name: "of",
        kind: Kind::Text,
        default: "",
        doc,
        example,
    }
}

/// `input=`: a captured image instead of the simulated sensor image.
pub const fn input_param() -> ParamSpec {
    ParamSpec {
        name: "input",
        kind: Kind::Text,
        default: "",
        doc: "read the captured image of the `measured \"<input>\"` node instead of the simulated sensor image (no render)",
        example: "\"capture-near\"",
    }
}

/// The kinds of `measure "<kind>"`, in the order of the language reference.
pub const KINDS: &[&str] = &[
    "colorimetry",
    "sfr",
    "ri",
    "noise",
    "profile",
    "mcc",
    "compare",
    "convergence",
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
        "convergence" => &super::convergence::SCHEMA,
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
    Convergence(ConvergenceOptions),
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
        "convergence" => MeasureOptions::Convergence(super::convergence::from_params(&d)?),
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
            MeasureOptions::Convergence(_) => "convergence",
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
            MeasureOptions::Convergence(c) if c.spp.is_empty() => {
                Err(ParamError::section("convergence needs spp=(…)")
                    .with_help("e.g. spp=(16 64 256): at least two increasing sample counts"))
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
}

/// Stage requirements per measurement kind. `colorimetry` reads a spectrum
/// only; `ri` and `convergence` can work on the optical image; every other
/// kind measures sensor digital values.
pub fn needs(kind: &str) -> Needs {
    match kind {
        "colorimetry" => Needs::default(),
        "ri" | "convergence" => Needs {
            optical_image: true,
            sensor_image: false,
        },
        _ => Needs {
            optical_image: true,
            sensor_image: true,
        },
    }
}

/// `roi-px=(x y w h)`: non-negative whole numbers, w and h ≥ 1.
pub fn roi_px(d: &ParamDict, name: &str) -> Result<Option<Rect>, ParamError> {
    let Some(v) = d.f64s(name)? else {
        return Ok(None);
    };
    let bad = || {
        ParamError::value(
            name,
            format!(
                "'{name}': expected (x y w h), four whole pixel numbers ≥ 0 with w, h ≥ 1, found ({})",
                v.iter().map(|x| x.to_string()).collect::<Vec<_>>().join(" ")
            ),
        )
        .with_help("e.g. roi-px=(100 80 64 128): left, top, width, height")
    };
    if v.len() != 4
        || v.iter()
            .any(|x| *x < 0.0 || x.fract() != 0.0 || *x > u32::MAX as f64)
        || v[2] < 1.0
        || v[3] < 1.0
    {
        return Err(bad());
    }
    Ok(Some(Rect::new(
        v[0] as u32,
        v[1] as u32,
        v[2] as u32,
        v[3] as u32,
    )))
}

/// A `Text` property that may not be empty.
pub fn nonempty(d: &ParamDict, name: &str) -> Result<Option<String>, ParamError> {
    match d.str(name)? {
        Some("") => Err(ParamError::value(
            name,
            format!("'{name}' must not be empty"),
        )),
        o => Ok(o.map(str::to_string)),
    }
}

/// The images and choices of the render stage a measurement reads.
pub struct Inputs<'a> {
    pub oi: Option<&'a OpticalImage>,
    pub si: Option<&'a SensorImage>,
    /// Per measured object, the film rectangle (full-frame pixels) the render
    /// stage chose for it.
    pub object_rects: &'a BTreeMap<String, Rect>,
    /// The variant's render seed (noise regions are drawn with it unless
    /// `seed=` is given).
    pub seed: u64,
    /// The variant's wavelength grid (colorimetry's default).
    pub grid: &'a WavelengthGrid,
}

/// A full-frame rectangle in window pixels of an image whose window is `w`.
pub fn to_window(r: Rect, w: Rect, what: &str) -> Result<Rect> {
    let x0 = r.x.max(w.x);
    let y0 = r.y.max(w.y);
    let x1 = (r.x + r.w).min(w.x + w.w);
    let y1 = (r.y + r.h).min(w.y + w.h);
    if x1 <= x0 || y1 <= y0 {
        return Err(Error::invalid(format!(
            "{what} (x {} y {} w {} h {}) is outside the rendered window (x {} y {} w {} h {})",
            r.x, r.y, r.w, r.h, w.x, w.y, w.w, w.h
        )));
    }
    Ok(Rect::new(x0 - w.x, y0 - w.y, x1 - x0, y1 - y0))
}

/// Bounding box (window pixels) of the pixels labelled `name` or below it
/// (`name/…`); None when no pixel carries it.
pub fn label_box(labels: &[u32], names: &[String], w: u32, h: u32, name: &str) -> Option<Rect> {
    let ids: Vec<u32> = names
        .iter()
        .enumerate()
        .filter(|(_, n)| *n == name || n.strip_prefix(name).is_some_and(|r| r.starts_with('/')))
        .map(|(i, _)| i as u32)
        .collect();
    let (mut x0, mut y0, mut x1, mut y1) = (u32::MAX, u32::MAX, 0u32, 0u32);
    for y in 0..h {
        for x in 0..w {
            if ids.contains(&labels[(y * w + x) as usize]) {
                x0 = x0.min(x);
                y0 = y0.min(y);
                x1 = x1.max(x + 1);
                y1 = y1.max(y + 1);
            }
        }
    }
    (x0 != u32::MAX).then(|| Rect::new(x0, y0, x1 - x0, y1 - y0))
}

/// Run measurement `name` (of the objects `of`) on a variant's rendered
/// images. `compare` and `convergence` combine other measurements and are run
/// by the experiment layer.
pub fn run(name: &str, of: &[String], opts: &MeasureOptions, inp: &Inputs) -> Result<Measured> {
    let need_si = || {
        inp.si
            .ok_or_else(|| Error::invalid(format!("measurement '{name}' needs a sensor image")))
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
            if let Some(roi) = r.roi_px {
                plane = plane.crop(to_window(roi, si.window, "roi-px")?)?;
            }
            let opts = super::noise::NoiseOptions {
                conversion_gain_dv_per_e: r
                    .conversion_gain_dv_per_e
                    .unwrap_or(si.conversion_gain_dv_per_e),
                seed: r.seed.unwrap_or(inp.seed),
                ..r.options.clone()
            };
            Ok(super::noise::measure(&plane, &opts, name)?.0)
        }
        MeasureOptions::Ri(r) => {
            no_of()?;
            let oi = inp.oi.ok_or_else(|| {
                Error::invalid(format!("measurement '{name}' needs an optical image"))
            })?;
            if r.channel.is_some() {
                return Err(Error::invalid(format!(
                    "measurement '{name}': ri of the optical image reads band-integrated irradiance; channel= applies to captured images (input=…)"
                )));
            }
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
        MeasureOptions::Compare(_) | MeasureOptions::Convergence(_) => {
            Err(Error::invalid(format!(
                "measurement '{name}': {} combines other measurements of the experiment",
                opts.kind()
            )))
        }
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
