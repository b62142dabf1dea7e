//! Every file in tests/malformed/ is a different mistake; each must fail to
//! check with a diagnostic at the exact file:line:col of the offending text,
//! and with the expected message. Locations were verified by hand against the
//! files (the caret sits on the offending token).

use camsim::experiment::{self, Loader};
use std::path::Path;

/// (file, where the error must point (file:line:col, file relative to tests/malformed), message fragment)
const CASES: &[(&str, &str, &str)] = &[
    (
        "bad-experiment-name.kdl",
        "bad-experiment-name.kdl:1:12",
        "invalid name '../x'",
    ),
    (
        "bounces-negative.kdl",
        "bounces-negative.kdl:2:24",
        "'max-bounces' = -1 is out of range",
    ),
    (
        "camera-look-at-itself.kdl",
        "camera-look-at-itself.kdl:2:5",
        "look-at-m equals position-m",
    ),
    (
        "camera-two-coordinates.kdl",
        "camera-two-coordinates.kdl:2:23",
        "expected 3 numbers (x y z), found 2",
    ),
    (
        "camera-up-parallel.kdl",
        "camera-up-parallel.kdl:2:5",
        "up is parallel to the view direction",
    ),
    (
        "camera-without-look-at.kdl",
        "camera-without-look-at.kdl:2:5",
        "camera needs position-m=(x y z) and look-at-m=(x y z)",
    ),
    (
        "colorimetry-without-spectrum.kdl",
        "colorimetry-without-spectrum.kdl:2:13",
        "colorimetry needs spectrum=",
    ),
    (
        "duplicate-axis.kdl",
        "duplicate-axis.kdl:5:9",
        "duplicate sweep axis 'render.spp'",
    ),
    (
        "duplicate-measure-name.kdl",
        "duplicate-measure-name.kdl:3:13",
        "duplicate measurement name 'colorimetry'",
    ),
    (
        "duplicate-object-id.kdl",
        "duplicate-object-id.kdl:3:9",
        "duplicate object id 'edge'",
    ),
    (
        "duplicate-property.kdl",
        "duplicate-property.kdl:2:25",
        "duplicate property 'spp'",
    ),
    (
        "duplicate-render.kdl",
        "duplicate-render.kdl:4:5",
        "duplicate 'render' node",
    ),
    (
        "empty-axis.kdl",
        "empty-axis.kdl:5:9",
        "empty sweep axis 'render.spp'",
    ),
    ("empty-file.kdl", "empty-file.kdl:1:1", "empty file"),
    ("empty-sweep.kdl", "empty-sweep.kdl:3:5", "empty sweep"),
    (
        "experiment-as-base.kdl",
        "../malformed-support/two-experiments-base.kdl:1:1",
        "a base file must be a `setup`",
    ),
    (
        "include-cycle-base.kdl",
        "include-cycle-base.kdl:4:10",
        "include cycle",
    ),
    (
        "include-cycle.kdl",
        "include-cycle-base.kdl:4:10",
        "include cycle",
    ),
    (
        "infinite-number.kdl",
        "infinite-number.kdl:2:47",
        "'tilt-deg' must be a finite number",
    ),
    (
        "lens-number-without-unit.kdl",
        "lens-number-without-unit.kdl:2:67",
        "expected a unit suffix, e.g. film-distance-mm",
    ),
    (
        "lens-model-unknown-property.kdl",
        "lens-model-unknown-property.kdl:2:37",
        "unknown property 'film-distance-mm' on lens model=…; expected one of: model, fov-deg",
    ),
    (
        "lens-rtf-degree-fraction.kdl",
        "lens-rtf-degree-fraction.kdl:2:68",
        "rtf-degree = 2.5; expected a whole number 1…16",
    ),
    (
        "measures-nothing.kdl",
        "measures-nothing.kdl:1:1",
        "measures nothing",
    ),
    (
        "mesh-without-file.kdl",
        "mesh-without-file.kdl:2:9",
        "needs file=",
    ),
    (
        "missing-base.kdl",
        "missing-base.kdl:2:10",
        "base file 'no-such-setup.kdl' not found",
    ),
    (
        "missing-brace.kdl",
        "missing-brace.kdl:1:16",
        "KDL syntax: No closing '}'",
    ),
    (
        "missing-scene-file.kdl",
        "missing-scene-file.kdl:2:11",
        "scene file 'scenes/no-such-scene.pbrt' not found",
    ),
    (
        "null-seed.kdl",
        "null-seed.kdl:2:17",
        "#null is not a value",
    ),
    (
        "override-without-properties.kdl",
        "override-without-properties.kdl:2:5",
        "changes nothing",
    ),
    (
        "range-without-step.kdl",
        "range-without-step.kdl:4:9",
        "needs start=, stop= and step=",
    ),
    (
        "range-wrong-sign.kdl",
        "range-wrong-sign.kdl:4:9",
        "wrong sign",
    ),
    (
        "removed-twice.kdl",
        "removed-twice.kdl:3:12",
        "'cube-small' is removed twice",
    ),
    (
        "render-with-block.kdl",
        "render-with-block.kdl:3:9",
        "unknown node 'spp' inside render",
    ),
    (
        "scale-negative.kdl",
        "scale-negative.kdl:2:61",
        "'scale' must be > 0",
    ),
    (
        "scene-wrong-extension.kdl",
        "scene-wrong-extension.kdl:2:11",
        "expected a .pbrt or .kdl scene file",
    ),
    (
        "sensor-unknown-property.kdl",
        "sensor-unknown-property.kdl:2:33",
        "unknown property 'exposur-s' on sensor",
    ),
    (
        "sensor-number-without-unit.kdl",
        "sensor-number-without-unit.kdl:2:12",
        "expected a unit suffix, e.g. exposure-s",
    ),
    (
        "setup-with-sweep.kdl",
        "setup-with-sweep.kdl:3:5",
        "'sweep' belongs in an experiment",
    ),
    (
        "spp-fraction.kdl",
        "spp-fraction.kdl:2:16",
        "'spp': expected an integer, found 1.5",
    ),
    (
        "spp-string.kdl",
        "spp-string.kdl:2:16",
        "'spp': expected an integer, found the string \"many\"",
    ),
    (
        "spp-zero.kdl",
        "spp-zero.kdl:2:17",
        "'spp' = 0 is out of range",
    ),
    (
        "sweep-bad-value.kdl",
        "sweep-bad-value.kdl:4:23",
        "expected an integer, found the string \"lots\"",
    ),
    (
        "sweep-number-without-unit.kdl",
        "sweep-number-without-unit.kdl:5:25",
        "expected a unit suffix, e.g. exposure-s",
    ),
    (
        "sweep-unknown-object.kdl",
        "sweep-unknown-object.kdl:5:9",
        "no object 'edge-ner'",
    ),
    (
        "sweep-unknown-render-key.kdl",
        "sweep-unknown-render-key.kdl:4:9",
        "unknown parameter 'sp' in 'render'",
    ),
    (
        "sweep-unknown-section.kdl",
        "sweep-unknown-section.kdl:5:9",
        "unknown parameter path 'sensr.exposure-s'",
    ),
    (
        "tuple-with-word.kdl",
        "tuple-with-word.kdl:2:24",
        "KDL syntax",
    ),
    (
        "two-experiments.kdl",
        "two-experiments.kdl:4:1",
        "unexpected second top-level node",
    ),
    (
        "type-annotation.kdl",
        "type-annotation.kdl:2:17",
        "type annotation '(u8)'",
    ),
    (
        "unknown-measurement.kdl",
        "unknown-measurement.kdl:2:13",
        "unknown measurement 'sfrr'",
    ),
    (
        "unknown-node.kdl",
        "unknown-node.kdl:2:5",
        "unknown node 'rendr'",
    ),
    (
        "unknown-render-property.kdl",
        "unknown-render-property.kdl:2:18",
        "unknown property 'max-bounce' on 'render'",
    ),
    (
        "unknown-spectrum.kdl",
        "unknown-spectrum.kdl:2:36",
        "unknown spectrum 'cie-d66'",
    ),
    (
        "unknown-target.kdl",
        "unknown-target.kdl:2:23",
        "unknown target 'slanted-egde'",
    ),
    (
        "unknown-top-level.kdl",
        "unknown-top-level.kdl:1:1",
        "unknown top-level node 'experimnt'",
    ),
    (
        "unterminated-string.kdl",
        "unterminated-string.kdl:2:36",
        "KDL syntax",
    ),
    (
        "wavelength-reversed.kdl",
        "wavelength-reversed.kdl:2:26",
        "stop 400 nm is below start 700 nm",
    ),
    (
        "wavelength-two-values.kdl",
        "wavelength-two-values.kdl:2:26",
        "expected (start stop step)",
    ),
    (
        "sweep-repeated-value.kdl",
        "sweep-repeated-value.kdl:4:27",
        "repeated value 64 in sweep axis 'render.spp'",
    ),
    (
        "zip-repeated-combination.kdl",
        "zip-repeated-combination.kdl:5:23",
        "repeated value combination (1, x) in this zip",
    ),
    (
        "zip-unequal.kdl",
        "zip-unequal.kdl:7:13",
        "zip axes must have equal lengths",
    ),
];

/// Suggestions that must be offered (file, help fragment).
const HELPS: &[(&str, &str)] = &[
    ("unknown-node.kdl", "did you mean 'render'?"),
    ("unknown-render-property.kdl", "did you mean 'max-bounces'?"),
    ("unknown-target.kdl", "did you mean 'slanted-edge'?"),
    ("unknown-measurement.kdl", "did you mean 'sfr'?"),
    ("unknown-spectrum.kdl", "did you mean 'cie-d65'?"),
    ("unknown-top-level.kdl", "did you mean 'experiment'?"),
    (
        "sweep-unknown-section.kdl",
        "did you mean 'sensor.exposure-s'?",
    ),
    ("sweep-unknown-render-key.kdl", "did you mean 'render.spp'?"),
    (
        "sweep-unknown-object.kdl",
        "did you mean 'object.edge-near.position-m'?",
    ),
    ("sensor-number-without-unit.kdl", "write exposure-s=…"),
    ("sensor-unknown-property.kdl", "did you mean 'exposure-s'?"),
];

fn dir() -> &'static Path {
    Path::new("tests/malformed")
}

fn check(file: &str) -> camsim::diag::Located {
    let path = dir().join(file);
    let r = experiment::parse_file(&path, Loader::Disk)
        .and_then(|p| experiment::plan(&p, None).map(|_| ()));
    match r {
        Ok(()) => panic!("{file}: expected an error, but it checked fine"),
        Err(e) => e,
    }
}

#[test]
fn every_malformed_file_fails_at_its_line_and_column() {
    let mut listed: Vec<&str> = CASES.iter().map(|c| c.0).collect();
    listed.sort();
    let mut on_disk: Vec<String> = std::fs::read_dir(dir())
        .unwrap()
        .map(|e| e.unwrap().file_name().to_string_lossy().to_string())
        .filter(|n| n.ends_with(".kdl"))
        .collect();
    on_disk.sort();
    assert_eq!(
        listed, on_disk,
        "every file in tests/malformed must have an expectation"
    );
    assert!(CASES.len() >= 30);
    for (file, at, msg) in CASES {
        let e = check(file);
        let (loc_file, rest) = at
            .rsplit_once(':')
            .map(|(a, c)| (a.rsplit_once(':').unwrap(), c))
            .unwrap();
        let want_file = dir().join(loc_file.0);
        let got = format!("{}:{}:{}", e.file.display(), e.line, e.col);
        let want = format!("{}:{}:{}", want_file.display(), loc_file.1, rest);
        assert_eq!(got, want, "{file}: wrong location\n{e}");
        assert!(
            e.message.contains(msg),
            "{file}: message {:?} lacks {:?}\n{e}",
            e.message,
            msg
        );
        // The rendered diagnostic has the location, the source line (if any) and a caret.
        let shown = e.to_string();
        assert!(shown.starts_with(&format!("{got}: error: ")), "{shown}");
        if !e.snippet.is_empty() {
            assert!(shown.contains('^'), "{shown}");
        }
    }
}

#[test]
fn misspellings_get_suggestions() {
    for (file, help) in HELPS {
        let e = check(file);
        let h = e.help.clone().unwrap_or_default();
        assert!(h.contains(help), "{file}: help {h:?} lacks {help:?}");
    }
}

#[test]
fn check_command_exits_1_with_diagnostics_on_stderr() {
    let exe = env!("CARGO_BIN_EXE_camsim");
    let out = std::process::Command::new(exe)
        .args([
            "check",
            "tests/malformed/unknown-node.kdl",
            "experiments/smoke.kdl",
        ])
        .output()
        .unwrap();
    assert_eq!(out.status.code(), Some(1));
    let err = String::from_utf8_lossy(&out.stderr);
    assert!(
        err.contains("tests/malformed/unknown-node.kdl:2:5: error: unknown node 'rendr'"),
        "{err}"
    );
    assert!(err.contains("experiments/smoke.kdl: ok"), "{err}");
    assert!(out.stdout.is_empty());
    let ok = std::process::Command::new(exe)
        .args(["check", "experiments/smoke.kdl"])
        .output()
        .unwrap();
    assert_eq!(ok.status.code(), Some(0));
}
