//! Results files, HTML reports (minijinja templates, plotters SVG plots) and
//! the diff of two results sets.
//!
//! Layout of a results directory `results/<experiment>/`:
//! - `results.csv`: long form, one figure a row, columns
//!   `experiment,variant,<swept parameters…>,measurement,quantity,unit,value,stderr,render_s,total_s`;
//! - `manifest.json`: free-form JSON from the runner; the report shows its
//!   scalar fields and reads, when present, `status` (string), `total_s`,
//!   `git_commit`, `version`, `threads`;
//! - `curves/<variant>/<measurement>.csv`: curves of one measurement of one
//!   variant, long form with header `curve,x_name,x_unit,y_name,y_unit,x,y,stderr`
//!   (one row per point; `stderr` empty when unknown; the names and units
//!   repeat on every row so each file stands alone) — see [`results::write_curves`];
//! - `previews/<variant>/<name>.png`: images shown in the report, each with an
//!   optional `previews/<variant>/<name>.rois.json` = `[{"label":"edge-near","x":…,"y":…,"w":…,"h":…}, …]`
//!   (pixels of that PNG) drawn as overlays.

pub mod diff;
pub mod html;
pub mod plot;
pub mod results;

pub use html::{write_index, write_report};
