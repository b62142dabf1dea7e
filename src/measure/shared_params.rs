//! Properties several measurement kinds share (`name`, `of`, `input`,
//! `roi-px`, non-empty text): one definition, so their docs and checks agree.

use crate::optical_image::Rect;
use crate::params::{Kind, ParamDict, ParamError, ParamSpec};

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
