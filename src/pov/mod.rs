//! POV-Ray: an independent renderer for a geometry sanity check.
//!
//! A second renderer catches what a path tracer hides: a mirrored transform,
//! a wrong unit, an object in the wrong place, a camera with the wrong
//! handedness or field of view. `sanity::check` renders camsim's label
//! buffer and POV-Ray's flat label image of the same scene through the same
//! (pinhole-equivalent) camera and compares them object by object
//! (`camsim pov SCENE --out DIR`).
//!
//! - `export`: scene text (flat label colours, or a shaded preview).
//! - `camera`: the pinhole equivalent of a camsim camera.
//! - `povray`: running the `povray` binary headless.
//! - `sanity`: the comparison (IoU per object, `iou.csv`, side-by-side PNG).

pub mod camera;
pub mod check_params;
pub mod export;
pub mod povray;
pub mod sanity;

pub use camera::PinholeEquivalent;
pub use export::{export_and_render, labels_to_pov, scene_to_pov};
pub use sanity::{IouRow, Sanity, check, check_as_pinhole};
