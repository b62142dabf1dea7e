//! camsim: declarative, physics-based camera simulation.
//!
//! Data flow (see README.md): experiment (KDL) → variants → scene → camera/optics
//! → spectral path tracer → optical image → sensor → measurements → results/report.
//! Dependencies point one way: `experiment` uses everything; `render` uses
//! `scene`, `optics`, `spectrum`; `sensor`, `measure` and `report` never render.

pub mod diag;
pub mod experiment;
pub mod figure;
pub mod frame_buffer;
pub mod image;
pub mod machine;
pub mod measure;
pub mod optical_image;
pub mod optics;
pub mod params;
pub mod pov;
pub mod render;
pub mod report;
pub mod scene;
pub mod sensor;
pub mod spectrum;
pub mod stability;
pub mod summary;

pub use diag::{Error, Result};

/// camsim's version (Cargo package version).
pub fn version() -> &'static str {
    env!("CARGO_PKG_VERSION")
}
