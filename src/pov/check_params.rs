//! The experiment's `sanity "pov"` node: the geometry check of each variant's
//! scene and camera against POV-Ray ([`super::sanity`]), its properties read
//! once through a [`ParamDict`].

use crate::params::{Kind, ParamDict, ParamError, ParamSpec, Params, Schema};
use crate::scene::FilmSpec;

/// `sanity "pov" …`.
pub static SCHEMA: Schema = Schema {
    node: "sanity \"pov\"",
    params: &[
        ParamSpec {
            name: "min-iou",
            kind: Kind::Number,
            default: "0.98",
            doc: "an object larger than 100 pixels whose IoU with POV-Ray's silhouette is below this fails the variant",
            example: "0.95",
        },
        ParamSpec {
            name: "width-px",
            kind: Kind::Integer,
            default: "the film's, at most 640 on the long side",
            doc: "width of the check image (the film's field of view)",
            example: "320",
        },
        ParamSpec {
            name: "height-px",
            kind: Kind::Integer,
            default: "the film's aspect",
            doc: "height of the check image",
            example: "180",
        },
        ParamSpec {
            name: "through",
            kind: Kind::Choice(&["pinhole", "lens"]),
            default: "pinhole",
            doc: "camsim's labels through the lens' pinhole equivalent (a real lens' distortion is not a geometry error) or through the lens itself",
            example: "\"lens\"",
        },
    ],
};

/// What `sanity "pov"` asks for.
#[derive(Clone, Copy, Debug, PartialEq)]
pub struct PovCheck {
    pub min_iou: f64,
    pub width_px: Option<u32>,
    pub height_px: Option<u32>,
    pub through_lens: bool,
}

/// Read `sanity "pov"`'s properties.
pub fn pov_check(params: &Params) -> Result<PovCheck, ParamError> {
    let d = ParamDict::new(params, &SCHEMA);
    d.check_names()?;
    let c = PovCheck {
        min_iou: d
            .in_range("min-iou", 0.0, 1.0)?
            .unwrap_or(super::sanity::DEFAULT_MIN_IOU),
        width_px: d.int("width-px", 8, 8192)?.map(|x| x as u32),
        height_px: d.int("height-px", 8, 8192)?.map(|x| x as u32),
        through_lens: d.choice("through")? == Some("lens"),
    };
    d.finish()?;
    Ok(c)
}

/// The check image size for a film: as given, else the film's, scaled to at
/// most 640 px on its long side (one given side keeps the film's aspect).
/// `camsim pov --width/--height` and `sanity "pov" width-px/height-px`.
pub fn check_size(film: &FilmSpec, w: Option<u32>, h: Option<u32>) -> (u32, u32) {
    let aspect = film.width_px as f64 / film.height_px.max(1) as f64;
    let round = |x: f64| (x.round() as u32).max(1);
    match (w, h) {
        (Some(w), Some(h)) => (w, h),
        (Some(w), None) => (w, round(w as f64 / aspect)),
        (None, Some(h)) => (round(h as f64 * aspect), h),
        (None, None) => {
            let k = (film.width_px.max(film.height_px) as f64 / 640.0).max(1.0);
            (
                round(film.width_px as f64 / k),
                round(film.height_px as f64 / k),
            )
        }
    }
}
