//! Every `measure "<kind>"` property reaches the built options
//! (`camsim::measure::options`), bad ones are errors naming the property,
//! and `camsim check` locates them at file:line:col.

mod common;
use common::camsim;

#[path = "params_reach/measure.rs"]
mod reach;

use camsim::measure::request::{KINDS, kdl_text, options, schema, schemas};
use camsim::params::{Params, Value};
use std::path::Path;

/// A value as written in KDL: "text", #true/#false, a number or (a b …).
/// (This test's own reader, so the examples are not read by the code under test.)
fn parse_kdl(s: &str) -> Value {
    let s = s.trim();
    if let Some(t) = s.strip_prefix('"').and_then(|t| t.strip_suffix('"')) {
        return Value::String(t.to_string());
    }
    match s {
        "#true" => return Value::Bool(true),
        "#false" => return Value::Bool(false),
        _ => {}
    }
    if let Some(inner) = s.strip_prefix('(').and_then(|t| t.strip_suffix(')')) {
        return Value::List(inner.split_whitespace().map(parse_kdl).collect());
    }
    Value::Number(s.parse().unwrap_or_else(|_| panic!("not a KDL value: {s}")))
}

fn one(name: &str, v: Value) -> Params {
    let mut p = Params::new();
    p.set(name, v);
    p
}

fn root() -> &'static Path {
    Path::new(env!("CARGO_MANIFEST_DIR"))
}

/// Values equal up to the last bit of a decimal written in the example
/// (probes convert integers and grids by exact arithmetic; 1e-12 relative
/// covers the grid's stop = start + step·(count − 1)).
fn same(a: &Value, b: &Value) -> bool {
    match (a, b) {
        (Value::Number(x), Value::Number(y)) => (x - y).abs() <= 1e-12 * x.abs().max(1.0),
        (Value::List(x), Value::List(y)) => {
            x.len() == y.len() && x.iter().zip(y).all(|(p, q)| same(p, q))
        }
        _ => a == b,
    }
}

#[test]
fn every_schema_property_reaches_the_built_options() {
    assert_eq!(schemas().len(), KINDS.len());
    let mut probed = 0;
    for kind in KINDS {
        let s = schema(kind).unwrap();
        assert_eq!(s.node, format!("measure \"{kind}\""));
        assert!(s.get("name").is_some(), "{kind}: no 'name'");
        let capture = ["sfr", "mcc", "profile", "noise", "ri"].contains(kind);
        assert_eq!(s.get("input").is_some(), capture, "{kind}: 'input'");
        // the defaults build
        options(kind, &Params::new(), root()).unwrap();
        for p in s.params {
            assert!(!p.doc.is_empty(), "{kind}.{}: no doc", p.name);
            assert_ne!(
                p.example.trim_matches('"'),
                p.default,
                "{kind}.{}: the example must differ from the default",
                p.name
            );
            if ["name", "of", "input"].contains(&p.name) {
                continue; // read by the experiment layer (probed by its test)
            }
            let v = parse_kdl(p.example);
            let o = options(kind, &one(p.name, v.clone()), root())
                .unwrap_or_else(|e| panic!("{kind}.{}={}: {e}", p.name, p.example));
            let got = reach::probe(kind, p.name, &o)
                .unwrap_or_else(|| panic!("{kind}.{}: the probe does not know it", p.name));
            assert!(
                same(&got, &v),
                "{kind}.{}: wrote {}, the options hold {}",
                p.name,
                p.example,
                kdl_text(&got)
            );
            // and without it, the options hold something else (the default)
            let d = options(kind, &Params::new(), root()).unwrap();
            assert!(
                reach::probe(kind, p.name, &d).is_none_or(|x| !same(&x, &v)),
                "{kind}.{}: the default equals the example",
                p.name
            );
            probed += 1;
        }
    }
    assert!(probed >= 30, "{probed} properties probed");
}

#[test]
fn unknown_misspelt_wrong_typed_and_out_of_range_properties_are_named() {
    let str_ = |s: &str| Value::String(s.into());
    let n = Value::Number;
    let nums = |v: &[f64]| Value::List(v.iter().map(|x| Value::Number(*x)).collect());
    let cases: Vec<(&str, &str, Value, &str)> = vec![
        ("sfr", "chanel", str_("g"), "unknown property 'chanel'"),
        ("sfr", "channel", n(1.0), "expected a string"),
        ("sfr", "channel", str_("x"), "expected one of"),
        ("sfr", "fit-degree", n(6.0), "out of range"),
        ("sfr", "fit-degree", n(1.5), "whole number"),
        ("sfr", "max-freq-cy-px", n(2.5), "out of range"),
        ("sfr", "max-noise-fraction", n(0.0), "must be > 0"),
        ("sfr", "roi-px", nums(&[1.0, 2.0, 0.0, 4.0]), "(x y w h)"),
        ("sfr", "roi-px", nums(&[1.0, 2.0, 3.0]), "(x y w h)"),
        ("noise", "region-px", n(2.0), "out of range"),
        ("noise", "nonuniform-ratio", n(0.9), "out of range"),
        ("noise", "conversion-gain-dv-e", n(-1.0), "must be > 0"),
        ("noise", "chanel", str_("g"), "unknown property"),
        ("ri", "center-px", nums(&[1.0]), "2 numbers"),
        ("ri", "bin-count", n(0.0), "out of range"),
        ("profile", "ratios", str_("g:r"), "not a ratio"),
        ("profile", "vertical", str_("yes"), "#true or #false"),
        ("mcc", "inset-fraction", n(0.5), "out of range"),
        ("mcc", "inset", n(0.1), "unknown property"),
        ("compare", "normalize", str_("max"), "expected one of"),
        (
            "convergence",
            "spp",
            nums(&[64.0, 16.0]),
            "strictly increasing",
        ),
        (
            "convergence",
            "spp",
            nums(&[16.5, 64.0]),
            "whole sample counts",
        ),
        ("colorimetry", "spectrum", str_("cie-d56"), "cie-d56"),
        (
            "colorimetry",
            "wavelength-nm",
            nums(&[400.0, 700.0]),
            "(start stop step)",
        ),
        (
            "colorimetry",
            "input",
            str_("cap"),
            "unknown property 'input'",
        ),
        ("stability", "case", str_("grazeing"), "expected one of"),
        ("stability", "case", n(1.0), "expected a string"),
        ("stability", "tolerance-scale", n(-1.0), "out of range"),
        ("stability", "of", str_("sfr"), "unknown property 'of'"),
    ];
    for (kind, name, v, needle) in cases {
        let e = match options(kind, &one(name, v.clone()), root()) {
            Ok(_) => panic!("{kind}.{name}={} was accepted", kdl_text(&v)),
            Err(e) => e,
        };
        assert_eq!(e.name.as_deref(), Some(name), "{kind}.{name}: {e}");
        assert!(e.to_string().contains(needle), "{kind}.{name}: {e}");
    }
    let e = options("sfr", &one("chanel", Value::String("g".into())), root()).unwrap_err();
    assert_eq!(e.help.as_deref(), Some("did you mean 'channel'?"));
    assert!(
        e.message.contains("fit-degree"),
        "lists the accepted names: {e}"
    );
}

#[test]
fn check_locates_bad_measure_properties() {
    let tmp = tempfile::tempdir().unwrap();
    // (line, the text the error points at, what it says)
    let cases: &[(&str, &str, &[&str])] = &[
        (
            "    measure \"sfr\" of=\"edge\" chanel=\"g\" roi-px=(0 0 10 10)\n",
            "chanel",
            &["unknown property 'chanel'", "did you mean 'channel'?"],
        ),
        (
            "    measure \"noise\" region-px=3\n",
            "3\n",
            &["'region-px' = 3 is out of range"],
        ),
        (
            "    measure \"mcc\" inset-fraction=\"wide\"\n",
            "\"wide\"",
            &["expected a finite number"],
        ),
        ("    measure \"ri\" channel=\"x\"\n", "\"x\"", &["channel"]),
        (
            "    measure \"compare-curve\" of=\"ri\" curve=\"ri\" reference-file=\"no-such.csv\"\n",
            "\"no-such.csv\"",
            &["reference file 'no-such.csv' not found"],
        ),
        (
            "    measure \"noise\" of=\"mcc\"\n",
            "\"mcc\"",
            &["takes no of="],
        ),
        (
            "    measure \"colorimetry\"\n",
            "\"colorimetry\"",
            &["colorimetry needs spectrum="],
        ),
    ];
    for (i, (line, token, needles)) in cases.iter().enumerate() {
        let at = format!("3:{}", line.find(token).unwrap() + 1);
        let p = tmp.path().join(format!("case{i}.kdl"));
        std::fs::write(
            &p,
            format!("experiment \"x\" {{\n    render spp=4\n{line}}}\n"),
        )
        .unwrap();
        let o = camsim(&["check", p.to_str().unwrap()]);
        let e = String::from_utf8_lossy(&o.stderr);
        assert_eq!(o.status.code(), Some(1), "case {i}: {e}");
        assert!(
            e.contains(&format!("case{i}.kdl:{at}:")),
            "case {i}: expected at {at}: {e}"
        );
        for n in *needles {
            assert!(e.contains(n), "case {i}: expected '{n}' in: {e}");
        }
    }
}
