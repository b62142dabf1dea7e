//! Measurements, one module each: slanted-edge SFR, relative illumination,
//! uniform-region noise, line profiles, MCC patch means, comparisons,
//! colorimetry. [`request`] reads a `measure` node's options (each kind's
//! `SCHEMA` lives beside it) and runs it on a variant's images.
//! Reports: HTML (minijinja + plotters SVG) and diff across results.
//!
//! Every measurement takes a [`plane::Plane`] (one value per pixel, optionally
//! with a colour-filter channel per pixel) or a [`crate::image::SensorImage`],
//! and returns [`crate::figure::Figure`]s (value, standard error, unit), the
//! curves it computed ([`Curve`]) and the pixel rectangles it read.

pub mod colorimetry;
pub mod compare;
pub mod compare_curve;
pub mod convergence;
pub mod conversion_gain;
pub mod inputs;
pub mod io;
pub mod mcc;
pub mod noise;
pub mod noise_model;
pub mod plane;
pub mod profile;
pub mod request;
pub mod ri;
pub mod sensor_calibration;
pub mod sfr;
pub mod shared_params;
pub mod stability;
pub mod stats;

pub use request::{MeasureOptions, options};

use serde::{Deserialize, Serialize};

/// A sampled curve produced by a measurement (ESF, LSF, MTF, RI, profile…),
/// with the name and unit of both axes. `stderr` is empty or as long as `y`.
#[derive(Clone, Debug, PartialEq, Serialize, Deserialize)]
pub struct Curve {
    /// Curve name, e.g. "mtf", "lsf", "profile/g".
    pub name: String,
    pub x_name: String,
    pub x_unit: String,
    pub y_name: String,
    pub y_unit: String,
    pub x: Vec<f64>,
    pub y: Vec<f64>,
    pub stderr: Vec<f64>,
}

impl Curve {
    pub fn new(
        name: &str,
        x: (&str, &str),
        y: (&str, &str),
        xs: Vec<f64>,
        ys: Vec<f64>,
        se: Vec<f64>,
    ) -> Self {
        Self {
            name: name.into(),
            x_name: x.0.into(),
            x_unit: x.1.into(),
            y_name: y.0.into(),
            y_unit: y.1.into(),
            x: xs,
            y: ys,
            stderr: se,
        }
    }
}

/// What a measurement returns: figures for `results.csv`, curves for
/// `curves/<variant>/<measurement>.csv`, and the window-pixel rectangles read.
#[derive(Clone, Debug, Default)]
pub struct Measured {
    pub figures: Vec<crate::figure::Figure>,
    pub curves: Vec<Curve>,
    pub pixels_read: Vec<crate::optical_image::Rect>,
}

impl Measured {
    /// Prefix every figure quantity and curve name with `p/` (an object or
    /// input name), so several runs of one measurement stay apart.
    pub fn prefixed(mut self, p: &str) -> Measured {
        for f in &mut self.figures {
            f.quantity = format!("{p}/{}", f.quantity);
        }
        for c in &mut self.curves {
            c.name = format!("{p}/{}", c.name);
        }
        self
    }
}
