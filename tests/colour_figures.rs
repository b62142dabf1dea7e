//! The paper's colour figures as experiments (issue 15 items 1 and 3), run end
//! to end with `camsim run` and checked against numbers computed here,
//! independently of camsim's pipeline, from the shipped data files:
//!
//! - Fig. 3 (`experiments/fig03-qe-correction.kdl`): the `qe-correction`
//!   summary recovers the paper's M (`data/cornellbox/cornellbox_setup.json`)
//!   from simulated patch means.
//! - Fig. 10 (`experiments/fig10-chromatic.kdl`): the `steps` summary's RMS
//!   error falls at each step, and the final step's channel ratios per patch
//!   equal reflectance × illuminant × QE × λ summed on the render grid.
//!
//! Both reports open in headless Chromium without console errors and with
//! every plot drawn.

mod common;

use camsim::report::results::{ResultRow, read_results};
use std::collections::BTreeMap;
use std::path::{Path, PathBuf};
use std::process::Command;
use std::sync::OnceLock;

const ROOT: &str = env!("CARGO_MANIFEST_DIR");

/// Run a shipped experiment once per test binary; its results directory.
fn run(name: &str) -> PathBuf {
    static OUT: OnceLock<tempfile::TempDir> = OnceLock::new();
    static LOCK: std::sync::Mutex<()> = std::sync::Mutex::new(());
    let out = OUT.get_or_init(|| tempfile::tempdir().unwrap()).path();
    let _g = LOCK.lock().unwrap();
    let dir = out.join(name);
    if !dir.join("results.csv").exists() {
        let o = Command::new(env!("CARGO_BIN_EXE_camsim"))
            .args(["run", "--threads", "2", "--out"])
            .arg(out)
            .arg(Path::new(ROOT).join(format!("experiments/{name}.kdl")))
            .output()
            .unwrap();
        assert!(
            o.status.success(),
            "{name}: camsim run failed:\n{}",
            String::from_utf8_lossy(&o.stderr)
        );
    }
    dir
}

fn summary_rows(dir: &Path) -> BTreeMap<String, (f64, f64)> {
    read_results(&dir.join("results.csv"))
        .unwrap()
        .into_iter()
        .filter(|r| r.variant == "summary")
        .map(|r| {
            assert!(
                r.params.iter().all(|p| p.1.is_empty()),
                "summary rows leave the swept columns empty"
            );
            (r.quantity, (r.value, r.stderr))
        })
        .collect()
}

fn report_opens(dir: &Path, plots_at_least: usize) {
    let html = std::fs::read_to_string(dir.join("report.html")).unwrap();
    assert!(html.contains("<h2>Summary</h2>"), "no Summary section");
    let plots = html.matches("<figure class=\"plot\"").count();
    assert!(plots >= plots_at_least, "{plots} plots");
    if let Some(dom) = common::chromium_dom(&dir.join("report.html")) {
        assert!(
            dom.contains("data-plots-ok=\"true\""),
            "a plot is empty or missing"
        );
    }
}

#[test]
fn fig03_recovers_the_papers_qe_correction_matrix() {
    let dir = run("fig03-qe-correction");
    let s = summary_rows(&dir);
    let setup: serde_json::Value = serde_json::from_str(
        &std::fs::read_to_string(Path::new(ROOT).join("data/cornellbox/cornellbox_setup.json"))
            .unwrap(),
    )
    .unwrap();
    let m = &setup["sensor"]["qe_correction_matrix_M"]["M"];
    let ch = ["r", "g", "b"];
    let mut worst: f64 = 0.0;
    for (r, rn) in ch.iter().enumerate() {
        for (c, cn) in ch.iter().enumerate() {
            let want = m[r][c].as_f64().unwrap();
            let (got, se) = s[&format!("M_{rn}_{cn}")];
            // The corrected filters are nominal·M with M as printed (4 decimals), so an
            // exact chain recovers each entry to the printing's ±5e-5, plus f32 sums in
            // the sensor (≈1e-6 relative): 1e-4. The issue's acceptance is 0.01.
            assert!(
                (got - want).abs() <= 1e-4,
                "M[{rn},{cn}] = {got} ± {se}, the paper's {want}"
            );
            worst = worst.max((got - want).abs());
        }
    }
    println!("fig03: largest |M − M_paper| = {worst:.2e}");
    // The fit is exact (the chain is linear), the nominal QE is far off.
    assert!(
        s["fit_error_percent"].0 < 0.01,
        "{:?}",
        s["fit_error_percent"]
    );
    assert!(
        s["nominal_error_percent"].0 > 10.0,
        "{:?}",
        s["nominal_error_percent"]
    );
    // 3 lights × 18 patches (the 6 fluorescent ones left out).
    assert_eq!(s["pairs"].0, 54.0);
    let curves = std::fs::read_to_string(dir.join("curves/summary/qe.csv")).unwrap();
    for c in [
        "scatter-before/r",
        "scatter-after/b",
        "qe-nominal/g",
        "qe-corrected/r",
    ] {
        assert!(curves.contains(&format!("{c},")), "no curve {c}");
    }
    report_opens(&dir, 4);
}

/// Linear interpolation in a (x, y) table sorted by x.
fn interp(t: &[(f64, f64)], x: f64) -> f64 {
    let i = t.partition_point(|p| p.0 < x);
    if i == 0 {
        return t[0].1;
    }
    if i == t.len() {
        return t[t.len() - 1].1;
    }
    let (a, b) = (t[i - 1], t[i]);
    a.1 + (x - a.0) / (b.0 - a.0) * (b.1 - a.1)
}

fn column(rows: &[Vec<f64>], k: usize) -> Vec<(f64, f64)> {
    rows.iter().map(|r| (r[0], r[k])).collect()
}

#[test]
fn fig10_error_falls_at_each_step_and_the_full_model_reproduces_patch_ratios() {
    let dir = run("fig10-chromatic");
    let s = summary_rows(&dir);
    let rms = |k: &str| s[&format!("{k}/rms_error")];
    let (a, b, c) = (rms("nominal"), rms("ri"), rms("corrected"));
    println!("fig10 RMS error (DV): nominal {a:?}, + RI {b:?}, + corrected QE {c:?}");
    // Each step lowers the error by more than three combined standard errors.
    let falls = |x: (f64, f64), y: (f64, f64)| x.0 - y.0 > 3.0 * (x.1 * x.1 + y.1 * y.1).sqrt();
    assert!(falls(a, b) && falls(b, c), "{a:?} → {b:?} → {c:?}");
    assert_eq!(
        s["corrected/pairs"].0, 1728.0,
        "3 lights × 8 positions × 24 × 3"
    );

    // Independent ratios: per light and patch, Σ ρ·E·QE_c·λ over the render grid
    // (400–700 nm, 10 nm; λ turns energy into photons), for c = r, g, b. Relative
    // illumination, exposure and geometry scale every channel of a patch alike.
    let data = |p: &str| common::numeric_rows(&format!("{ROOT}/{p}"));
    let refl = data("data/surfaces/MiniatureMacbethChart_reflectance.csv");
    let qe = data("data/sensor/p4a_corrected_color_filters.csv");
    let lights = [
        ("gretag-a", data("data/lights/gretag_illA_20201023.csv")),
        ("gretag-cwf", data("data/lights/gretag_illCWF_20201023.csv")),
        ("gretag-day", data("data/lights/gretag_illDay_20201023.csv")),
    ];
    let signal = |light: &[Vec<f64>], patch: usize, ch: usize| -> f64 {
        let (e, r, q) = (column(light, 1), column(&refl, patch), column(&qe, 1 + ch));
        (0..=30)
            .map(|i| 400.0 + 10.0 * i as f64)
            .map(|l| interp(&r, l) * interp(&e, l) * interp(&q, l) * l)
            .sum()
    };
    let rows: Vec<ResultRow> = read_results(&dir.join("results.csv")).unwrap();
    let param = |r: &ResultRow, k: &str| {
        r.params
            .iter()
            .find(|p| p.0 == k)
            .map(|p| p.1.clone())
            .unwrap()
    };
    // (light, position, patch) → channel → (mean, stderr)
    type ByChannel = BTreeMap<String, (f64, f64)>;
    let mut sim: BTreeMap<(String, String, usize), ByChannel> = BTreeMap::new();
    for r in rows
        .iter()
        .filter(|r| r.variant != "summary" && param(r, "tag.step") == "corrected")
    {
        let Some((p, ch)) = r
            .quantity
            .strip_suffix("_mean")
            .and_then(|q| q.split_once('/'))
        else {
            continue;
        };
        let patch: usize = p.trim_start_matches("patch").parse().unwrap();
        sim.entry((
            param(r, "override.booth-lamp.radiance"),
            param(r, "tag.position"),
            patch,
        ))
        .or_default()
        .insert(ch.to_string(), (r.value, r.stderr));
    }
    assert_eq!(sim.len(), 3 * 8 * 24);
    let mut worst_z: f64 = 0.0;
    let mut worst_rel: f64 = 0.0;
    for ((light, pos, patch), v) in &sim {
        let l = &lights.iter().find(|x| x.0 == light).unwrap().1;
        let g_ind = signal(l, *patch, 1);
        for (ch, k) in [("r", 0), ("b", 2)] {
            let want = signal(l, *patch, k) / g_ind;
            let ((x, sx), (g, sg)) = (v[ch], v["g"]);
            let got = x / g;
            let se = got * ((sx / x).powi(2) + (sg / g).powi(2)).sqrt();
            // Tolerance: 3 rendering standard errors, plus what differs between a
            // patch's r, g and b pixels besides colour: their centroids sit ½ px
            // apart on the Bayer grid, and across a 5.6 µm pixel the lens' relative
            // illumination (≤ 0.22 /mm at 2.2 mm field) and the lamp's fall-off over
            // the chart (≈ 10 % over 140 px) change by ≤ 1.3e-3 and 7e-4: ≤ 1e-3
            // of the ratio for the ½ px offset.
            let tol = 3.0 * se + 1e-3 * want;
            let d = (got - want).abs();
            worst_z = worst_z.max(d / se.max(1e-300));
            worst_rel = worst_rel.max(d / want);
            assert!(
                d <= tol,
                "{light} {pos} patch {patch}: {ch}/g = {got} ± {se}, from the data {want}"
            );
        }
    }
    println!("fig10 ratios: largest |Δ|/ratio = {worst_rel:.2e}, largest |Δ|/se = {worst_z:.1}");
    report_opens(&dir, 6);
}
