//! A measured figure: one row of `results.csv` before the runner adds the
//! experiment, variant, swept parameters and timings.

use serde::{Deserialize, Serialize};

/// One measured number with its unit and Monte Carlo / statistical standard error.
#[derive(Clone, Debug, PartialEq, Serialize, Deserialize)]
pub struct Figure {
    /// Measurement name as written in the experiment (e.g. "sfr", "mcc").
    pub measurement: String,
    /// What was measured, e.g. "mtf50", "mtf@0.25cy/px", "patch04/g_mean".
    pub quantity: String,
    /// Unit, e.g. "cy/px", "DV", "1".
    pub unit: String,
    pub value: f64,
    /// Standard error (NaN is never written; use 0 when exact, and say so in docs).
    pub stderr: f64,
}

impl Figure {
    pub fn new(
        measurement: &str,
        quantity: impl Into<String>,
        unit: &str,
        value: f64,
        stderr: f64,
    ) -> Self {
        Self {
            measurement: measurement.into(),
            quantity: quantity.into(),
            unit: unit.into(),
            value,
            stderr,
        }
    }
}
