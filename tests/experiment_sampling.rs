//! Issue 16 items 1 and 3: error-driven sampling (`render target-stderr=…
//! max-s=… max-spp=…`, `target "MEASUREMENT" stderr=…`) and quality presets
//! (`quality "NAME" …`, `camsim run --quality NAME`).
//!
//! The experiments are small: the shipped KDL Cornell box, the MCC on a
//! 480 × 270 generic sensor (auto-exposed) with every sensor noise switched off (so the
//! patch means carry Monte Carlo error only, which more samples lower), one
//! bounce, the MCC's pixels only (~0.1 s per 4 spp).

mod common;
use common::{camsim, stderr};

use std::path::{Path, PathBuf};
use std::process::Output;

const ROOT: &str = env!("CARGO_MANIFEST_DIR");

/// The experiment `name` with `render` line and extra `body` lines.
fn text(name: &str, scene: &Path, render: &str, body: &str) -> String {
    format!(
        "experiment \"{name}\" {{
    scene \"{}\"
    sensor \"{ROOT}/sensors/generic.kdl\" rows=270 cols=480 exposure-s=\"auto\" photon-noise=#false read-noise=#false reset-noise=#false dsnu=#false prnu=#false dark-current=#false column-fpn=#false quantization=#false
    add \"mcc\" target=\"mcc\" position-m=(0.03 0.12 0.12) scale=1.5
    {render}
    measure \"mcc\" of=\"mcc\"
{body}}}
",
        scene.display()
    )
}

struct Setup {
    dir: tempfile::TempDir,
    scene: PathBuf,
}

fn setup() -> Setup {
    let dir = tempfile::tempdir().unwrap();
    let scene = dir.path().join("box.kdl");
    std::fs::copy(Path::new(ROOT).join("scenes/cornell-box.kdl"), &scene).unwrap();
    Setup { dir, scene }
}

fn write(s: &Setup, file: &str, body: String) -> PathBuf {
    let p = s.dir.path().join(file);
    std::fs::write(&p, body).unwrap();
    p
}

fn manifest(out: &Path, exp: &str) -> serde_json::Value {
    let p = out.join(exp).join("manifest.json");
    serde_json::from_str(&std::fs::read_to_string(&p).unwrap()).unwrap()
}

/// (quantity, value, stderr) of every mcc row of results.csv.
fn mcc_rows(out: &Path, exp: &str) -> Vec<(String, f64, f64)> {
    let mut r = csv::Reader::from_path(out.join(exp).join("results.csv")).unwrap();
    let h = r.headers().unwrap().clone();
    let col = |n: &str| h.iter().position(|x| x == n).unwrap();
    let (q, v, e, m) = (
        col("quantity"),
        col("value"),
        col("stderr"),
        col("measurement"),
    );
    r.records()
        .map(|x| x.unwrap())
        .filter(|x| &x[m] == "mcc")
        .map(|x| {
            (
                x[q].to_string(),
                x[v].parse().unwrap(),
                x[e].parse().unwrap(),
            )
        })
        .collect()
}

fn run(exp: &Path, out: &Path, extra: &[&str]) -> Output {
    let mut args = vec!["run", exp.to_str().unwrap(), "--out", out.to_str().unwrap()];
    args.extend_from_slice(extra);
    camsim(&args)
}

fn run_ok(exp: &Path, out: &Path, extra: &[&str]) -> Output {
    let o = run(exp, out, extra);
    assert!(o.status.success(), "camsim run failed: {}", stderr(&o));
    o
}

/// Experiment "t" with `render` run once (no cache) into `s`'s directory `o`:
/// that directory, the run log, and the variant's sampling record.
fn run_sampled(s: &Setup, render: &str) -> (PathBuf, String, serde_json::Value) {
    let exp = write(s, "t.kdl", text("t", &s.scene, render, ""));
    let out = s.dir.path().join("o");
    let log = stderr(&run_ok(&exp, &out, &["--no-cache"]));
    let rec = manifest(&out, "t")["variants"][0]["sampling"].clone();
    (out, log, rec)
}

#[test]
fn a_target_is_met_deterministically_for_any_thread_count() {
    let s = setup();
    let exp = write(
        &s,
        "t.kdl",
        text(
            "t",
            &s.scene,
            "render spp=4 max-bounces=1 seed=3 target-stderr=\"2%\" max-spp=4096 max-s=600",
            "",
        ),
    );
    let (a, b) = (s.dir.path().join("a"), s.dir.path().join("b"));
    let log = stderr(&run_ok(&exp, &a, &["--threads", "1", "--no-cache"]));
    run_ok(&exp, &b, &["--threads", "2", "--no-cache"]);
    // Same seed: the same rounds and bit-identical figures at 1 and 2 threads.
    let (ra, rb) = (mcc_rows(&a, "t"), mcc_rows(&b, "t"));
    assert_eq!(ra, rb);
    let m = manifest(&a, "t");
    let rec = &m["variants"][0]["sampling"];
    assert_eq!(rec["stopped"], "target", "{rec}");
    assert_eq!(rec["budget_reached"], false);
    let spp = rec["spp"].as_u64().unwrap();
    assert!(spp > 4 && spp <= 4096, "spp {spp}");
    assert!(rec["rounds"].as_u64().unwrap() >= 2);
    assert!(rec["render_s"].as_f64().unwrap() > 0.0);
    assert_eq!(
        manifest(&b, "t")["variants"][0]["sampling"]["spp"],
        rec["spp"]
    );
    assert!(log.contains(&format!("spp {spp}, target met")), "{log}");
    // Every figure the manifest lists meets 2 % of its magnitude, and every
    // mcc figure of results.csv is listed.
    let figs = rec["figures"].as_array().unwrap();
    assert_eq!(figs.len(), ra.len());
    for (f, (q, v, e)) in figs.iter().zip(&ra) {
        assert_eq!(f["quantity"].as_str().unwrap(), q);
        assert_eq!(f["met"], true, "{f}");
        assert!(*e <= 0.02 * v.abs(), "{q}: {v} ± {e}");
    }
    // The report's Sampling section.
    let html = std::fs::read_to_string(a.join("t/report.html")).unwrap();
    assert!(html.contains("<h2>Sampling</h2>") && html.contains("target met"));
}

#[test]
fn the_sampled_standard_errors_are_honest_against_a_converged_reference() {
    // The rounds' combined standard error must describe the error of the
    // combined mean: against a 16× longer render (its own error ¼ of the
    // target, so negligible to first order), |value − reference| ≤ 3·se for
    // ≥ 90 % of the patch means (a Gaussian puts 99.7 % within 3 se; the
    // 90 % allows for the 8-batch standard errors' own ≈ 25 % uncertainty).
    // A combination rule that ignored the earlier rounds' weights, or
    // under-counted their errors, fails this.
    let s = setup();
    let (out, _, rec) = run_sampled(
        &s,
        "render spp=4 max-bounces=1 seed=11 target-stderr=\"2%\" max-spp=4096 max-s=600",
    );
    let rec = &rec;
    assert_eq!(rec["stopped"], "target", "{rec}");
    let spp = rec["spp"].as_u64().unwrap();
    let refx = write(
        &s,
        "r.kdl",
        text(
            "r",
            &s.scene,
            &format!("render spp={} max-bounces=1 seed=99", spp * 16),
            "",
        ),
    );
    run_ok(&refx, &out, &["--no-cache"]);
    let (t, r) = (mcc_rows(&out, "t"), mcc_rows(&out, "r"));
    let means: Vec<_> = t
        .iter()
        .zip(&r)
        .filter(|(a, _)| a.0.ends_with("_mean"))
        .collect();
    assert!(means.len() >= 72);
    let within = means
        .iter()
        .filter(|(a, b)| (a.1 - b.1).abs() <= 3.0 * a.2)
        .count();
    assert!(
        within as f64 >= 0.9 * means.len() as f64,
        "{within} of {} within 3 se",
        means.len()
    );
}

#[test]
fn an_unreachable_target_stops_at_the_budget_and_is_flagged() {
    let s = setup();
    let (out, log, rec) = run_sampled(
        &s,
        "render spp=4 max-bounces=1 seed=3 max-spp=32 {\n        target \"mcc\" quantity=\"patch19/g_mean\" stderr=\"0.001%\"\n    }",
    );
    let rec = &rec;
    assert_eq!(rec["stopped"], "spp-budget", "{rec}");
    assert_eq!(rec["budget_reached"], true);
    assert_eq!(rec["spp"], 32);
    // Only the named figure is targeted.
    let figs = rec["figures"].as_array().unwrap();
    assert_eq!(figs.len(), 1);
    assert_eq!(figs[0]["quantity"], "patch19/g_mean");
    assert_eq!(figs[0]["met"], false);
    assert!(log.contains("spp 32, spp-budget: budget reached"), "{log}");
    let html = std::fs::read_to_string(out.join("t/report.html")).unwrap();
    assert!(html.contains("spp-budget: budget reached"));
    // The figure is flagged in its measurement's table too.
    assert!(html.contains("<span class=\"warn\">budget reached</span>"));
}

#[test]
fn sampling_settings_are_checked_where_they_are_written() {
    let s = setup();
    let cases: &[(&str, &str, &str)] = &[
        (
            "render spp=4 target-stderr=\"1%\"",
            "needs a budget",
            "t.kdl:5:5",
        ),
        (
            "render spp=4 max-s=10",
            "budgets of error-driven sampling",
            "t.kdl:5:5",
        ),
        (
            "render spp=4 target-stderr=\"abc\" max-s=10",
            "percentage like",
            "t.kdl:5:",
        ),
        (
            "render spp=4 target-stderr=-1 max-s=10",
            "must be > 0",
            "t.kdl:5:",
        ),
        (
            "render spp=64 target-stderr=\"1%\" max-spp=16",
            "below the first round",
            "t.kdl:5:5",
        ),
        (
            "render spp=4 max-s=10 {\n        target \"mc\" stderr=1\n    }",
            "did you mean 'mcc'",
            "t.kdl:6:9",
        ),
        (
            "render spp=4 max-s=10 {\n        target \"mcc\" stderror=1\n    }",
            "unknown property 'stderror'",
            "t.kdl:6:",
        ),
        (
            "render spp=4 max-s=10 {\n        target \"mcc\"\n    }",
            "needs stderr",
            "t.kdl:6:9",
        ),
        (
            "render spp=4\n    quality \"paper\" max-s=10 {\n        target \"mc\" stderr=1\n    }",
            "quality \"paper\": target \"mc\"",
            "t.kdl:7:9",
        ),
        (
            "render spp=4 target-stder=\"1%\"",
            "did you mean 'target-stderr'",
            "t.kdl:5:",
        ),
    ];
    for (render, msg, at) in cases {
        let exp = write(&s, "t.kdl", text("t", &s.scene, render, ""));
        let o = camsim(&["check", exp.to_str().unwrap()]);
        let e = stderr(&o);
        assert!(!o.status.success(), "{render}: accepted");
        assert!(e.contains(msg), "{render}: {e}");
        assert!(e.contains(at), "{render}: not at {at}: {e}");
    }
}

#[test]
fn a_quality_preset_replaces_the_render_settings_and_sweeps_still_win() {
    let s = setup();
    let exp = write(
        &s,
        "q.kdl",
        text(
            "q",
            &s.scene,
            "render spp=4 max-bounces=1 seed=3\n    quality \"paper\" spp=8 target-stderr=\"50%\" max-spp=64 {\n        target \"mcc\" quantity=\"g_mean\" stderr=\"50%\"\n    }",
            "    sweep {\n        tag.k 1 2\n    }\n",
        ),
    );
    let (quick, paper) = (s.dir.path().join("quick"), s.dir.path().join("paper"));
    run_ok(&exp, &quick, &["--no-cache"]);
    run_ok(&exp, &paper, &["--no-cache", "--quality", "paper"]);
    let (mq, mp) = (manifest(&quick, "q"), manifest(&paper, "q"));
    assert!(mq.get("quality").is_none());
    assert_eq!(mp["quality"], "paper");
    for v in mq["variants"].as_array().unwrap() {
        assert_eq!(v["spec"]["render"]["spp"], 4);
        assert!(v.get("sampling").is_none());
    }
    for v in mp["variants"].as_array().unwrap() {
        assert_eq!(v["spec"]["render"]["spp"], 8);
        assert_eq!(v["spec"]["render"]["max_spp"], 64);
        assert_eq!(v["sampling"]["stopped"], "target", "{v}");
        // The preset's target child: the 24 green patch means only.
        let figs = v["sampling"]["figures"].as_array().unwrap();
        assert_eq!(figs.len(), 24);
        assert!(
            figs.iter()
                .all(|f| f["quantity"].as_str().unwrap().ends_with("/g_mean"))
        );
    }
    // `--quality quick` is the render node itself: the same plan as no flag.
    let q2 = s.dir.path().join("quick2");
    run_ok(&exp, &q2, &["--no-cache", "--quality", "quick"]);
    assert_eq!(mcc_rows(&quick, "q"), mcc_rows(&q2, "q"));
    // An experiment without the preset runs at its own settings, and says so.
    let plain = write(
        &s,
        "p.kdl",
        text("p", &s.scene, "render spp=4 max-bounces=1", ""),
    );
    let o = s.dir.path().join("plain");
    run_ok(&plain, &o, &["--no-cache", "--quality", "paper"]);
    assert_eq!(
        manifest(&o, "p")["quality"],
        "paper (not defined: the render node's settings)"
    );
    // A bad preset is refused at check, where it is written.
    let bad = write(
        &s,
        "b.kdl",
        text(
            "b",
            &s.scene,
            "render spp=4\n    quality \"paper\" spp=0",
            "",
        ),
    );
    let e = stderr(&camsim(&["check", bad.to_str().unwrap()]));
    assert!(e.contains("b.kdl:6:") && e.contains("out of range"), "{e}");
    let quick_def = write(
        &s,
        "b.kdl",
        text(
            "b",
            &s.scene,
            "render spp=4\n    quality \"quick\" spp=8",
            "",
        ),
    );
    let e = stderr(&camsim(&["check", quick_def.to_str().unwrap()]));
    assert!(
        e.contains("'quick' is the render node's own settings"),
        "{e}"
    );
}

#[test]
fn a_floor_that_samples_cannot_lower_stops_as_stalled() {
    // The patch means' standard error is std/√n over the patch's pixels: on a
    // noise-free sensor it also holds the light's real gradient across each
    // patch, which no number of samples removes. A 0.3 % target sits below
    // that floor for the darker patches: the rounds must notice (two rounds in
    // a row falling < ⅓ of the 1/√n law) and stop, flagged, well before the
    // sample budget.
    let s = setup();
    let (_, log, rec) = run_sampled(
        &s,
        "render spp=4 max-bounces=1 seed=3 target-stderr=\"0.3%\" max-spp=100000",
    );
    let rec = &rec;
    assert_eq!(rec["stopped"], "stalled", "{rec}");
    assert_eq!(rec["budget_reached"], true);
    assert!(rec["spp"].as_u64().unwrap() < 100_000);
    assert!(log.contains("stalled: budget reached"), "{log}");
}
