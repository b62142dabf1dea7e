//! Self-check of the `sensor` parameter-reach probe (tests/params_reach/sensor.rs)
//! against `camsim::sensor::SCHEMA`, the way the harness uses it: each property
//! set alone to its schema example on `sensor "sensors/imx363.kdl"` must be
//! held by the built config; the examples differ from the imx363 file's values
//! and from the defaults, so a dropped property cannot pass by coincidence.

#[path = "params_reach/sensor.rs"]
mod sensor_probe;

use camsim::params::{Params, Value};
use camsim::sensor::{SCHEMA, SensorConfig, sensor_config};
use sensor_probe::probe;
use std::path::{Path, PathBuf};

fn imx363() -> PathBuf {
    Path::new(env!("CARGO_MANIFEST_DIR")).join("sensors/imx363.kdl")
}

/// A schema example as written in KDL: #true/#false, "string", or a number.
fn kdl(text: &str) -> Value {
    match text {
        "#true" => Value::Bool(true),
        "#false" => Value::Bool(false),
        t if t.starts_with('"') => Value::String(t.trim_matches('"').to_string()),
        t => Value::Number(t.parse().unwrap_or_else(|_| panic!("not a KDL value: {t}"))),
    }
}

/// A schema default (text, written without quotes).
fn default(text: &str) -> Value {
    match text.parse() {
        Ok(x) => Value::Number(x),
        Err(_) if text.starts_with('#') => kdl(text),
        Err(_) => Value::String(text.to_string()),
    }
}

/// Equal, numbers to 1e-12 relative: the setter and the probe each convert
/// units with one multiplication or division (≤ 1 ulp ≈ 2.2e-16 relative each).
fn same(a: &Value, b: &Value) -> bool {
    match (a, b) {
        (Value::Number(x), Value::Number(y)) => (x - y).abs() <= 1e-12 * x.abs().max(y.abs()),
        _ => a == b,
    }
}

fn one(name: &str, v: Value) -> Params {
    let mut p = Params::new();
    p.set(name, v);
    p
}

#[test]
fn every_sensor_property_reaches_the_config_in_its_unit() {
    let plain = SensorConfig::load(&imx363()).unwrap();
    for spec in SCHEMA.params {
        let example = kdl(spec.example);
        let before = probe(spec.name, &plain)
            .unwrap_or_else(|| panic!("the probe does not know '{}'", spec.name));
        assert!(
            !same(&before, &example),
            "'{}': example {} equals the imx363 file's value",
            spec.name,
            spec.example
        );
        if !spec.default.is_empty() {
            assert!(
                !same(&default(spec.default), &example),
                "'{}': example equals the default",
                spec.name
            );
        }
        let cfg = sensor_config(Some(&imx363()), &one(spec.name, example.clone()))
            .unwrap_or_else(|e| panic!("'{}' = {}: {e}", spec.name, spec.example));
        let held = probe(spec.name, &cfg).unwrap();
        assert!(
            same(&held, &example),
            "'{}' = {}: the built sensor holds {held}",
            spec.name,
            spec.example
        );
    }
    assert_eq!(probe("no-such-property", &plain), None);
}

#[test]
fn a_wrong_typed_or_misspelt_property_is_an_error_naming_it() {
    for spec in SCHEMA.params {
        // A number where a text/bool is expected and a bool where a number is.
        let wrong = match kdl(spec.example) {
            Value::Number(_) => Value::Bool(true),
            _ => Value::Number(3.5),
        };
        let e = sensor_config(Some(&imx363()), &one(spec.name, wrong)).unwrap_err();
        assert_eq!(e.name.as_deref(), Some(spec.name), "{e}");
        let misspelt = format!("{}x", spec.name);
        let e = sensor_config(Some(&imx363()), &one(&misspelt, kdl(spec.example))).unwrap_err();
        assert_eq!(e.name.as_deref(), Some(misspelt.as_str()), "{e}");
        assert!(e.message.contains("unknown property"), "{e}");
    }
}

#[test]
fn the_ir_filter_example_is_resolved_not_only_named() {
    let cfg = sensor_config(Some(&imx363()), &one("ir-filter", kdl("\"ircf-largan\""))).unwrap();
    // An IR-cut filter passes visible light and blocks the near infrared.
    assert!(
        cfg.ir_filter.eval(550.0) > 0.5,
        "{}",
        cfg.ir_filter.eval(550.0)
    );
    assert!(
        cfg.ir_filter.eval(900.0) < 0.1,
        "{}",
        cfg.ir_filter.eval(900.0)
    );
}
