//! A `lens` node (an experiment's, or a KDL scene's `camera`) → the camera
//! model it asks for. One function, [`camera_model`], reads every property
//! (through a [`ParamDict`], converting units once, here) and is called by
//! `check` and by `run` alike; `optics::camera::build` turns the model into
//! the camera the renderer traces.
//!
//! - `lens "FILE" [film-distance-mm=D] [focus-distance-m=Z] [rtf-degree=N|"none"] [rtf-axis-weight=W]`
//! - `lens model="pinhole" fov-deg=A [f-number=N] [falloff="cos4"|"none"]`
//! - `lens model="thin-lens" focal-length-mm=F [f-number=N] [focus-distance-m=Z]`

use super::model::{CameraModel, RtfFitRequest};
use crate::params::{Kind, ParamDict, ParamError, ParamSpec, Params, Schema, Value};
use std::path::Path;

/// `lens "FILE" …`: a prescription or RTF file.
pub static LENS_FILE_SCHEMA: Schema = Schema {
    node: "lens \"FILE\"",
    params: &[
        ParamSpec {
            name: "film-distance-mm",
            kind: Kind::Number,
            default: "focus-distance-m, else infinity focus",
            doc: "film to rear vertex (prescription) or to the RTF's input plane",
            example: "0.4711",
        },
        ParamSpec {
            name: "focus-distance-m",
            kind: Kind::Number,
            default: "infinity",
            doc: "object distance in focus, from the film (prescriptions; ignored when film-distance-mm is given)",
            example: "0.875",
        },
        ParamSpec {
            name: "rtf-degree",
            kind: Kind::NumberOr(&["none"]),
            default: "none",
            doc: "render a prescription through an RTF of this degree (1–16) fitted on the fly; \"none\" traces the prescription",
            example: "3",
        },
        ParamSpec {
            name: "rtf-axis-weight",
            kind: Kind::Number,
            default: "1",
            doc: "extra weight of the on-axis film bundles in that fit (needs rtf-degree)",
            example: "4.5",
        },
    ],
};

/// `lens model=…`: an ideal lens written inline.
pub static LENS_MODEL_SCHEMA: Schema = Schema {
    node: "lens model=…",
    params: &[
        ParamSpec {
            name: "model",
            kind: Kind::Choice(&["pinhole", "thin-lens"]),
            default: "pinhole",
            doc: "ideal lens model",
            example: "\"thin-lens\"",
        },
        ParamSpec {
            name: "fov-deg",
            kind: Kind::Number,
            default: "",
            doc: "pinhole: full field of view across the shorter film side (required)",
            example: "33.5",
        },
        ParamSpec {
            name: "f-number",
            kind: Kind::Number,
            default: "2",
            doc: "f-number (a pinhole's sets only its irradiance scale πL/(4N²))",
            example: "3.3",
        },
        ParamSpec {
            name: "focal-length-mm",
            kind: Kind::Number,
            default: "",
            doc: "thin lens: focal length (required)",
            example: "4.25",
        },
        ParamSpec {
            name: "focus-distance-m",
            kind: Kind::Number,
            default: "infinity",
            doc: "thin lens: object distance in focus",
            example: "1.75",
        },
        ParamSpec {
            name: "falloff",
            kind: Kind::Choice(&["cos4", "none"]),
            default: "cos4",
            doc: "pinhole: \"none\" leaves out the cos⁴ fall-off (irradiance πL/(4N²) everywhere), for a sensor whose relative-illumination table supplies the fall-off",
            example: "\"none\"",
        },
    ],
};

/// The camera model a `lens` node asks for: `file` is its lens file (None for
/// an inline model). Every property is read here, once; what is not read is an
/// error naming the accepted properties.
pub fn camera_model(file: Option<&Path>, params: &Params) -> Result<CameraModel, ParamError> {
    match file {
        Some(f) => file_model(f, params),
        None => inline_model(params),
    }
}

fn file_model(path: &Path, params: &Params) -> Result<CameraModel, ParamError> {
    let d = ParamDict::new(params, &LENS_FILE_SCHEMA);
    d.check_names()?;
    let film_distance_m = d.positive("film-distance-mm")?.map(|mm| mm * 1e-3);
    let focus_distance_m = d.positive("focus-distance-m")?;
    let degree = match d.raw("rtf-degree")? {
        None => None,
        Some(Value::String(s)) if s == "none" => None,
        Some(Value::Number(x)) if x.fract() == 0.0 && (1.0..=16.0).contains(x) => Some(*x as usize),
        Some(v) => {
            return Err(ParamError::value(
                "rtf-degree",
                format!("rtf-degree = {v}; expected a whole number 1…16 or \"none\""),
            ));
        }
    };
    let axis_weight = d.positive("rtf-axis-weight")?;
    d.finish()?;
    let rtf_fit = match (degree, axis_weight) {
        (None, Some(_)) => {
            return Err(ParamError::new(
                Some("rtf-axis-weight"),
                "rtf-axis-weight needs rtf-degree",
            ));
        }
        (None, None) => None,
        (Some(degree), w) => Some(RtfFitRequest {
            degree,
            axis_weight: w.unwrap_or(1.0),
        }),
    };
    Ok(CameraModel::LensFile {
        path: path.to_path_buf(),
        film_distance_m,
        focus_distance_m,
        aperture_diameter_m: None,
        rtf_fit,
    })
}

fn inline_model(params: &Params) -> Result<CameraModel, ParamError> {
    let d = ParamDict::new(params, &LENS_MODEL_SCHEMA);
    d.check_names()?;
    let model = d.choice("model")?.unwrap_or("pinhole");
    let f_number = d.positive("f-number")?.unwrap_or(2.0);
    let fov_deg = d.in_range("fov-deg", f64::MIN_POSITIVE, 179.9)?;
    let focal_length_m = d.positive("focal-length-mm")?.map(|mm| mm * 1e-3);
    let focus_distance_m = d.positive("focus-distance-m")?;
    let falloff = d.choice("falloff")?;
    d.finish()?;
    let unused = |name: &str, v: Option<f64>| match v {
        Some(_) => Err(ParamError::new(
            Some(name),
            format!("'{name}' does not apply to lens model=\"{model}\""),
        )),
        None => Ok(()),
    };
    match model {
        "thin-lens" => {
            unused("fov-deg", fov_deg)?;
            if falloff.is_some() {
                return Err(ParamError::new(
                    Some("falloff"),
                    "'falloff' applies to lens model=\"pinhole\"",
                ));
            }
            let Some(focal_length_m) = focal_length_m else {
                return Err(ParamError::section(
                    "lens model=\"thin-lens\" needs focal-length-mm",
                ));
            };
            Ok(CameraModel::ThinLens {
                focal_length_m,
                f_number,
                focus_distance_m: focus_distance_m.unwrap_or(f64::INFINITY),
            })
        }
        _ => {
            unused("focal-length-mm", focal_length_m)?;
            unused("focus-distance-m", focus_distance_m)?;
            let Some(fov_deg) = fov_deg else {
                return Err(ParamError::section("lens model=\"pinhole\" needs fov-deg"));
            };
            Ok(CameraModel::Pinhole {
                fov_deg,
                f_number,
                cos4: falloff != Some("none"),
            })
        }
    }
}
