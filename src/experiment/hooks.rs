//! Validator hooks: the sensor, lens and measurement modules own the names of
//! their parameters; the experiment language only enforces the unit rule and
//! the value types. Each module provides a [`SectionValidator`] (built in:
//! colorimetry, `sensor` → `sensor::sensor_params::validate_overrides`, `lens` →
//! `stages::validate_lens`; others through [`register`]), and `camsim check` /
//! `plan` / `run` call it on the resolved section of every variant, so a
//! misspelt sensor property is an error with `file:line:col` before anything
//! runs.
//!
//! Section keys: `"sensor"`, `"lens"`, `"measure:<kind>"` (e.g. `"measure:sfr"`),
//! `"add:<target>"` (e.g. `"add:slanted-edge"`), `"override"`.

use crate::params::Params;
use std::collections::BTreeMap;
use std::path::Path;
use std::sync::RwLock;

/// What a validator reports (the one error type of parameter handling).
pub use crate::params::ParamError;

/// Validates one section: `file` is the referenced definition file (if any),
/// `params` the inline overrides / properties. Must not panic.
pub type SectionValidator = fn(file: Option<&Path>, params: &Params) -> Result<(), ParamError>;

static REGISTRY: RwLock<BTreeMap<String, SectionValidator>> = RwLock::new(BTreeMap::new());

/// Register (or replace) the validator of a section key.
pub fn register(section: &str, f: SectionValidator) {
    if let Ok(mut r) = REGISTRY.write() {
        r.insert(section.to_string(), f);
    }
}

/// The validator of a section key, if one is registered.
pub fn validator(section: &str) -> Option<SectionValidator> {
    REGISTRY
        .read()
        .ok()
        .and_then(|r| r.get(section).copied())
        .or_else(|| builtin(section))
}

/// Validators that are always present (unless replaced through [`register`]).
fn builtin(section: &str) -> Option<SectionValidator> {
    match section {
        "measure:colorimetry" => Some(validate_colorimetry),
        "sensor" => Some(crate::sensor::sensor_params::validate_overrides),
        "lens" => Some(super::stages::validate_lens),
        _ => None,
    }
}

/// Validators camsim installs beyond the built-in ones (colorimetry, the
/// sensor section: `sensor::sensor_params::validate_overrides`, the lens section:
/// `stages::validate_lens`). Called by the CLI before parsing; a place for
/// validators of future modules.
pub fn install_defaults() {}

/// `measure "colorimetry" spectrum="cie-d65" [wavelength-nm=(380 780 5)]`.
pub fn validate_colorimetry(_file: Option<&Path>, p: &Params) -> Result<(), ParamError> {
    const KNOWN: &[&str] = &["spectrum", "wavelength-nm"];
    if let Some(u) = p.unknown(KNOWN).first() {
        return Err(ParamError::unknown(u, KNOWN));
    }
    match p.get("spectrum") {
        None => Err(ParamError::new(
            None,
            "colorimetry needs spectrum=\"<name>\" (e.g. spectrum=\"cie-d65\")",
        )),
        Some(crate::params::Value::String(s)) => {
            if s.contains('#') {
                return Ok(()); // a CSV column; read (and checked) when the variant runs
            }
            crate::spectrum::library::named(s).map(|_| ()).map_err(|e| {
                let mut err = ParamError::new(Some("spectrum"), e.clone()).at_value();
                if let Some(i) = e.find("(did you mean") {
                    err.help = Some(e[i + 1..e.len() - 1].to_string());
                    err.message = e[..i].trim().to_string();
                }
                err
            })
        }
        Some(v) => Err(ParamError::new(
            Some("spectrum"),
            format!("spectrum: expected a string, found {v}"),
        )),
    }
}
