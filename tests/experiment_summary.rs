//! The cross-variant stage (`summary` nodes) end to end on a colorimetry
//! experiment (exact, renders nothing): its rows in results.csv (variant
//! `summary`, empty swept columns) with values recomputed here from the
//! variants' rows, its curves, the same rows from a run, from shards sharing
//! one directory and from `camsim merge`, a failing summary, and the located
//! errors of `check`.

mod common;
use common::camsim;

use camsim::report::results::{ResultRow, read_results};
use std::path::{Path, PathBuf};

fn p(x: &Path) -> &str {
    x.to_str().unwrap()
}

/// Three "steps" (D65 as the reference, A and F2 as steps) × two grids; the
/// summary compares each step's chromaticity x with the reference's.
fn experiment(dir: &Path, summary: &str) -> PathBuf {
    let text = format!(
        r#"experiment "sum" {{
    measure "colorimetry" name="c" spectrum="cie-d65"
    sweep {{
        zip {{
            tag.step           "ref"     "a"     "f2"
            measure.c.spectrum "cie-d65" "cie-a" "cie-f2"
        }}
        render.wavelength-nm (400 700 10) (380 780 5)
    }}
    {summary}
}}
"#
    );
    let f = dir.join("sum.kdl");
    std::fs::write(&f, text).unwrap();
    f
}

const STEPS: &str = r#"summary "steps" name="s" of="c" axis="tag.step" reference="ref" quantity="x" histogram-bin-dv=0.05 note="D65 stands in""#;

fn summary_rows(rows: &[ResultRow]) -> Vec<&ResultRow> {
    rows.iter().filter(|r| r.variant == "summary").collect()
}

#[test]
fn summary_rows_hold_the_cross_variant_figures() {
    let tmp = tempfile::tempdir().unwrap();
    let f = experiment(tmp.path(), STEPS);
    let out = tmp.path().join("out");
    let o = camsim(&["run", "--out", p(&out), p(&f)]);
    assert!(o.status.success(), "{}", String::from_utf8_lossy(&o.stderr));
    let rows = read_results(&out.join("sum/results.csv")).unwrap();
    let s = summary_rows(&rows);
    assert_eq!(
        s.len(),
        6,
        "rms_error, rms_error_percent, pairs for steps a and f2"
    );
    for r in &s {
        assert_eq!(r.measurement, "s");
        assert!(r.params.iter().all(|p| p.1.is_empty()), "{r:?}");
        assert_eq!(r.render_s, 0.0);
    }
    // Recompute step a's RMS error from the variant rows (x at both grids).
    let x = |step: &str, grid: &str| {
        rows.iter()
            .find(|r| {
                r.quantity == "x"
                    && r.params.contains(&("tag.step".into(), step.into()))
                    && r.params
                        .contains(&("render.wavelength-nm".into(), grid.into()))
            })
            .unwrap()
            .value
    };
    for step in ["a", "f2"] {
        let d: Vec<f64> = ["(400 700 10)", "(380 780 5)"]
            .iter()
            .map(|g| x(step, g) - x("ref", g))
            .collect();
        let rms = ((d[0] * d[0] + d[1] * d[1]) / 2.0).sqrt();
        let got = s
            .iter()
            .find(|r| r.quantity == format!("{step}/rms_error"))
            .unwrap();
        assert!(
            (got.value - rms).abs() <= 1e-12 * rms,
            "{step}: {got:?} vs {rms}"
        );
        let pairs = s
            .iter()
            .find(|r| r.quantity == format!("{step}/pairs"))
            .unwrap();
        assert_eq!(pairs.value, 2.0);
    }
    let curves = std::fs::read_to_string(out.join("sum/curves/summary/s.csv")).unwrap();
    for c in [
        "scatter-a/all,",
        "scatter-f2/all,",
        "histogram/ref,",
        "histogram/a,",
    ] {
        assert!(curves.contains(c), "no curve {c}:\n{curves}");
    }
    let html = std::fs::read_to_string(out.join("sum/report.html")).unwrap();
    assert!(html.contains("<h2>Summary</h2>") && html.contains("D65 stands in"));
    // A rerun (every variant cached) writes the same summary rows.
    let before = std::fs::read_to_string(out.join("sum/results.csv")).unwrap();
    let o = camsim(&["run", "--out", p(&out), p(&f)]);
    assert!(o.status.success());
    let after = std::fs::read_to_string(out.join("sum/results.csv")).unwrap();
    let strip = |t: &str| -> Vec<String> {
        // total_s of summary rows is their own wall time
        t.lines()
            .map(|l| l.rsplit_once(',').unwrap().0.to_string())
            .collect()
    };
    assert_eq!(strip(&before), strip(&after));
}

#[test]
fn shards_and_merge_write_the_summary_once_the_plan_is_complete() {
    let tmp = tempfile::tempdir().unwrap();
    let f = experiment(tmp.path(), STEPS);
    let full = tmp.path().join("full");
    assert!(camsim(&["run", "--out", p(&full), p(&f)]).status.success());
    let values = |d: &Path| -> Vec<(String, f64)> {
        summary_rows(&read_results(&d.join("sum/results.csv")).unwrap())
            .iter()
            .map(|r| (r.quantity.clone(), r.value))
            .collect()
    };
    let want = values(&full);
    // Separate shard directories: neither is complete alone; merge completes it.
    let (a, b) = (tmp.path().join("a"), tmp.path().join("b"));
    for (d, sh) in [(&a, "1/2"), (&b, "2/2")] {
        let o = camsim(&["run", "--shard", sh, "--out", p(d), p(&f)]);
        assert!(o.status.success(), "{}", String::from_utf8_lossy(&o.stderr));
        assert!(
            !d.join("sum/results.csv").exists(),
            "a lone shard writes no results.csv"
        );
    }
    let merged = tmp.path().join("merged");
    let o = camsim(&["merge", p(&a), p(&b), "--out", p(&merged)]);
    assert!(o.status.success(), "{}", String::from_utf8_lossy(&o.stderr));
    assert_eq!(values(&merged), want);
    assert!(merged.join("sum/curves/summary/s.csv").exists());
    // Shards sharing one directory: the one that completes the plan runs it.
    let shared = tmp.path().join("shared");
    for sh in ["2/2", "1/2"] {
        assert!(
            camsim(&["run", "--shard", sh, "--out", p(&shared), p(&f)])
                .status
                .success()
        );
    }
    assert_eq!(values(&shared), want);
}

#[test]
fn a_failing_summary_writes_no_rows_and_fails_the_run() {
    let tmp = tempfile::tempdir().unwrap();
    // Every variant is fine, but `quantity` keeps no row.
    let f = experiment(
        tmp.path(),
        r#"summary "steps" name="s" of="c" axis="tag.step" reference="ref" quantity="nothing-like-this""#,
    );
    let out = tmp.path().join("out");
    let o = camsim(&["run", "--out", p(&out), p(&f)]);
    assert_eq!(o.status.code(), Some(1));
    assert!(
        String::from_utf8_lossy(&o.stderr).contains("summary 's'"),
        "{}",
        String::from_utf8_lossy(&o.stderr)
    );
    let rows = read_results(&out.join("sum/results.csv")).unwrap();
    assert!(summary_rows(&rows).is_empty());
    assert_eq!(rows.len(), 6 * 3, "the variants' rows are written");
    let m = std::fs::read_to_string(out.join("sum/manifest.json")).unwrap();
    assert!(m.contains("summary_errors"), "{m}");
}

fn check_error(text: &str) -> String {
    let tmp = tempfile::tempdir().unwrap();
    let f = tmp.path().join("x.kdl");
    std::fs::write(&f, text).unwrap();
    let o = camsim(&["check", p(&f)]);
    assert!(!o.status.success(), "check passed:\n{text}");
    String::from_utf8_lossy(&o.stderr).into_owned()
}

#[test]
fn check_locates_summary_errors() {
    let m = r#"measure "colorimetry" name="c" spectrum="cie-d65""#;
    // of= names no measurement: at the value, with the names there are
    let e = check_error(&format!(
        "experiment \"x\" {{\n    {m}\n    summary \"steps\" of=\"cc\" axis=\"tag.a\" reference=\"r\"\n}}\n"
    ));
    assert!(e.contains("x.kdl:3:24:") && e.contains("'c'"), "{e}");
    // a name shared with a measurement
    let e = check_error(&format!(
        "experiment \"x\" {{\n    {m}\n    summary \"steps\" name=\"c\" of=\"c\" axis=\"tag.a\" reference=\"r\"\n}}\n"
    ));
    assert!(
        e.contains("x.kdl:3:") && e.contains("also a measurement"),
        "{e}"
    );
    // not in a setup
    let e = check_error("setup \"x\" {\n    summary \"steps\" of=\"c\"\n}\n");
    assert!(
        e.contains("x.kdl:2:") && e.contains("belongs in an experiment"),
        "{e}"
    );
    // an unknown kind, with the nearest
    let e = check_error(&format!(
        "experiment \"x\" {{\n    {m}\n    summary \"step\" of=\"c\"\n}}\n"
    ));
    assert!(e.contains("x.kdl:3:13:") && e.contains("'steps'"), "{e}");
    // a required property missing
    let e = check_error(&format!(
        "experiment \"x\" {{\n    {m}\n    summary \"qe-correction\" of=\"c\" axis=\"tag.a\"\n}}\n"
    ));
    assert!(e.contains("x.kdl:3:") && e.contains("measured="), "{e}");
    // of= missing
    let e = check_error(&format!(
        "experiment \"x\" {{\n    {m}\n    summary \"steps\" axis=\"tag.a\" reference=\"r\"\n}}\n"
    ));
    assert!(e.contains("x.kdl:3:") && e.contains("needs of="), "{e}");
}
