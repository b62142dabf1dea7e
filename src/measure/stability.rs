//! `measure "stability"`: the options of one stiff or extreme case. The
//! cases themselves render, run the sensor, fit RTFs and measure SFRs, so
//! they live a layer up, in [`crate::stability`] (measurements never
//! render); the experiment layer runs them.

use crate::params::{Kind, ParamDict, ParamError, ParamSpec, Schema};

/// The case names, in the order of the language reference (issue 16 item 5).
pub const CASES: &[&str] = &[
    "dynamic-range",
    "grazing",
    "scale",
    "sensor-saturated-dark",
    "rtf-beyond-field",
    "rtf-singular-fit",
    "sfr-noisy",
    "exposure-gain",
];

/// `measure "stability" case="…" [tolerance-scale=…]`.
#[derive(Clone, Debug, PartialEq)]
pub struct StabilityOptions {
    /// The case run (required).
    pub case: Option<String>,
    /// Every check's tolerance is multiplied by this (1 = the derived
    /// tolerances; 0 leaves only exact checks passable — a failure probe).
    pub tolerance_scale: f64,
}

impl Default for StabilityOptions {
    fn default() -> Self {
        Self {
            case: None,
            tolerance_scale: 1.0,
        }
    }
}

/// The properties of `measure "stability"`.
pub static SCHEMA: Schema = Schema {
    node: "measure \"stability\"",
    params: &[
        super::shared_params::name_param(),
        ParamSpec {
            name: "case",
            kind: Kind::Choice(CASES),
            default: "",
            doc: "the stiff or extreme case run against its analytic or converged reference (required); figures passed, checks, failed_checks and the worst check's value, reference, error, tolerance",
            example: "\"grazing\"",
        },
        ParamSpec {
            name: "tolerance-scale",
            kind: Kind::Number,
            default: "1",
            doc: "multiplies every check's derived tolerance (0 … 1e6); below 1 tightens the case (0 makes every inexact check fail: a failure probe)",
            example: "0.5",
        },
    ],
};

/// Read `measure "stability"` (see [`SCHEMA`]).
pub fn from_params(d: &ParamDict) -> Result<StabilityOptions, ParamError> {
    Ok(StabilityOptions {
        case: d.choice("case")?.map(str::to_string),
        tolerance_scale: d.in_range("tolerance-scale", 0.0, 1e6)?.unwrap_or(1.0),
    })
}
