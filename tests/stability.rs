//! The `stability` cases (issue 16 item 5): every case passes at its
//! derived tolerances (the tolerances are derived beside each case in
//! src/stability/), through the library and through `camsim run
//! experiments/stability.kdl`; a failing case — an impossible tolerance, a
//! NaN-producing sensor — is reported as failed with its check named, never
//! as a pass and never as a NaN figure; results are bit-identical for 1 and
//! 2 threads.

use camsim::measure::stability::{CASES, StabilityOptions};
use camsim::sensor::config::SensorConfig;
use camsim::stability::{Check, measure, run_case};
use std::path::{Path, PathBuf};
use std::process::Command;

const ROOT: &str = env!("CARGO_MANIFEST_DIR");

fn imx363() -> SensorConfig {
    SensorConfig::load(&Path::new(ROOT).join("sensors/imx363.kdl")).unwrap()
}

fn show(case: &str, checks: &[Check]) {
    for c in checks {
        eprintln!(
            "{case}: {:<38} value {:>13.6e} ref {:>11.4e} |err| {:>10.3e} tol {:>10.3e} {} ({})",
            c.name,
            c.value,
            c.reference,
            c.error().abs(),
            c.tolerance,
            if c.passed(1.0) { "ok" } else { "FAILED" },
            c.at
        );
    }
}

#[test]
fn every_case_passes_through_the_library() {
    let s = imx363();
    let mut failed = vec![];
    for case in CASES {
        let checks = run_case(case, Some(&s), 7).unwrap_or_else(|e| panic!("{case}: {e}"));
        show(case, &checks);
        assert!(checks.len() >= 2, "{case}: too few checks");
        // a tolerance is never negative or NaN, and only counts are exact
        for c in &checks {
            assert!(
                c.tolerance >= 0.0,
                "{case}/{}: tolerance {}",
                c.name,
                c.tolerance
            );
        }
        failed.extend(
            checks
                .iter()
                .filter(|c| !c.passed(1.0))
                .map(|c| format!("{case}: {}", c.name)),
        );
    }
    assert!(failed.is_empty(), "failed checks: {failed:?}");
}

fn get(m: &camsim::measure::Measured, q: &str) -> Option<f64> {
    m.figures.iter().find(|f| f.quantity == q).map(|f| f.value)
}

#[test]
fn an_impossible_tolerance_fails_the_case_and_names_the_check() {
    // tolerance-scale 0: only exact checks can pass; the scale case's image
    // sums differ from the 1 m one by f32 rounding (≈ 10⁻⁷), so its two
    // sum_ratio checks must fail (and its non-finite counts still pass).
    let o = StabilityOptions {
        case: Some("scale".into()),
        tolerance_scale: 0.0,
    };
    let m = measure("stab", &o, None, 3).unwrap();
    assert_eq!(get(&m, "passed"), Some(0.0));
    assert_eq!(get(&m, "failed_checks"), Some(2.0));
    assert!(get(&m, "failed/1mm/sum_ratio").is_some());
    assert!(get(&m, "failed/1km/sum_ratio").is_some());
    assert!(
        m.figures
            .iter()
            .all(|f| f.value.is_finite() && f.stderr.is_finite())
    );
    // the same case at its derived tolerance passes
    let o = StabilityOptions {
        case: Some("scale".into()),
        tolerance_scale: 1.0,
    };
    assert_eq!(
        get(&measure("stab", &o, None, 3).unwrap(), "passed"),
        Some(1.0)
    );
}

#[test]
fn a_nan_producing_sensor_is_a_failed_case_not_a_nan() {
    // An analog gain of NaN makes every DV NaN in the pipeline (it is not
    // validated there): the case must fail on its non-finite counts, and
    // write no NaN figure.
    let mut s = imx363();
    s.analog_gain = f64::NAN;
    let checks = run_case("sensor-saturated-dark", Some(&s), 1).unwrap();
    show("nan-sensor", &checks);
    let bad: Vec<&Check> = checks.iter().filter(|c| !c.passed(1.0)).collect();
    assert!(
        bad.iter()
            .any(|c| c.name == "dark/nonfinite" && c.value > 0.0),
        "the NaN DVs were not counted"
    );
    let o = StabilityOptions {
        case: Some("sensor-saturated-dark".into()),
        tolerance_scale: 1.0,
    };
    let m = measure("stab", &o, Some(&s), 1).unwrap();
    assert_eq!(get(&m, "passed"), Some(0.0));
    assert!(get(&m, "failed/dark/nonfinite").is_some_and(|v| v > 0.0));
    assert!(get(&m, "failed/saturated/nonfinite").is_some_and(|v| v > 0.0));
    assert!(
        m.figures
            .iter()
            .all(|f| f.value.is_finite() && f.stderr.is_finite())
    );
    // a sensor case without a sensor is the experiment's error, said plainly
    let e = measure("stab", &o, None, 1).unwrap_err().to_string();
    assert!(e.contains("sensor"), "{e}");
}

fn camsim(args: &[&str]) -> std::process::Output {
    Command::new(env!("CARGO_BIN_EXE_camsim"))
        .args(args)
        .current_dir(ROOT)
        .output()
        .unwrap()
}

/// (case, quantity) → value of a results.csv.
fn results(dir: &Path) -> Vec<(String, String, f64)> {
    let text = std::fs::read_to_string(dir.join("stability/results.csv")).unwrap();
    let mut r = csv::Reader::from_reader(text.as_bytes());
    let h = r.headers().unwrap().clone();
    let col = |n: &str| h.iter().position(|x| x == n);
    // the case column exists when the case is swept
    let c = col("measure.stability.case");
    let (q, v) = (col("quantity").unwrap(), col("value").unwrap());
    r.records()
        .map(|x| {
            let x = x.unwrap();
            let case = c.map(|c| x[c].to_string()).unwrap_or_default();
            (case, x[q].to_string(), x[v].parse().unwrap())
        })
        .collect()
}

#[test]
fn the_experiment_lists_every_case_passing_and_is_thread_independent() {
    let tmp = tempfile::tempdir().unwrap();
    let mut runs: Vec<Vec<(String, String, f64)>> = vec![];
    for threads in ["1", "2"] {
        let out: PathBuf = tmp.path().join(threads);
        let o = camsim(&[
            "run",
            "experiments/stability.kdl",
            "--threads",
            threads,
            "--out",
            out.to_str().unwrap(),
        ]);
        assert!(o.status.success(), "{}", String::from_utf8_lossy(&o.stderr));
        let rows = results(&out);
        for case in CASES {
            let passed = rows
                .iter()
                .find(|r| r.0 == *case && r.1 == "passed")
                .unwrap_or_else(|| panic!("no row for case {case}"));
            assert_eq!(passed.2, 1.0, "case {case} failed");
        }
        let html = std::fs::read_to_string(out.join("stability/report.html")).unwrap();
        for s in ["Measurement: stability", "passed (1)", "failed_checks (1)"] {
            assert!(html.contains(s), "report lacks '{s}'");
        }
        for case in CASES {
            assert!(
                html.contains(&format!("case={case}")),
                "report lacks {case}"
            );
        }
        runs.push(rows);
    }
    let bits = |r: &Vec<(String, String, f64)>| {
        r.iter()
            .map(|x| (x.0.clone(), x.1.clone(), x.2.to_bits()))
            .collect::<Vec<_>>()
    };
    assert_eq!(bits(&runs[0]), bits(&runs[1]), "1 and 2 threads differ");
}

#[test]
fn a_failing_case_in_a_run_is_listed_as_failed_and_logged() {
    let tmp = tempfile::tempdir().unwrap();
    let kdl = tmp.path().join("stab.kdl");
    std::fs::write(
        &kdl,
        format!(
            "experiment \"stability\" {{\n    sensor \"{ROOT}/sensors/imx363.kdl\"\n    render seed=4\n    measure \"stability\" name=\"stability\" case=\"grazing\" tolerance-scale=0\n}}\n"
        ),
    )
    .unwrap();
    let out = tmp.path().join("out");
    let o = camsim(&["run", kdl.to_str().unwrap(), "--out", out.to_str().unwrap()]);
    let err = String::from_utf8_lossy(&o.stderr);
    assert!(o.status.success(), "{err}");
    // what failed and where, on the run log
    assert!(
        err.contains("stability case 'grazing': check '89.9deg/irradiance_ratio'")
            && err.contains("failed: value"),
        "{err}"
    );
    let rows = results(&out);
    let v = |q: &str| rows.iter().find(|r| r.1 == q).map(|r| r.2);
    assert_eq!(v("passed"), Some(0.0));
    assert!(v("failed_checks").is_some_and(|n| n >= 1.0));
    assert!(v("failed/89.9deg/irradiance_ratio").is_some());
    let html = std::fs::read_to_string(out.join("stability/report.html")).unwrap();
    // (minijinja escapes the slashes of the column title)
    assert!(html.contains("89.9deg") && html.contains("irradiance_ratio"));
}
