//! `lens "PRESCRIPTION" rtf-degree=N` in an experiment: the prescription is
//! rendered through an RTF fitted to it on the fly, focused like the
//! prescription, so a sweep compares both in images. Bad values are errors
//! at the property's file:line:col before anything runs.

use std::path::Path;
use std::process::Command;

/// The shipped rtf-vs-prescription set-up (absolute paths), with `sweep`
/// and `lens` lines given.
fn experiment(dir: &Path, lens: &str, sweep: &str) -> std::path::PathBuf {
    let root = env!("CARGO_MANIFEST_DIR");
    let text = format!(
        r#"experiment "lens-rtf" {{
    scene "{root}/scenes/CornellBoxReference/CornellBoxReference.pbrt" materials="paper"
    camera position-m=(-0.08 0.08 -1.0) look-at-m=(-0.08 0.08 0.0) up=(0 1 0)
    {lens}
    sensor "{root}/sensors/imx363.kdl" exposure-s="auto" pixel-size-um=5.6 rows=512 cols=512
    render spp=256 max-bounces=2 seed=1 wavelength-nm=(400 700 10)
    remove "CubeSmall" "CubeLarge"
    add "edge" target="slanted-edge" position-m=(-0.08 0.08 0.0) tilt-deg=5 rotate-deg=(30 0 0)
    sweep {{
        {sweep}
    }}
    measure "sfr" of="edge" channel="lum"
}}
"#
    );
    let p = dir.join("lens-rtf.kdl");
    std::fs::write(&p, text).unwrap();
    p
}

fn run(exp: &Path, out: &Path) -> String {
    let o = Command::new(env!("CARGO_BIN_EXE_camsim"))
        .args(["run", exp.to_str().unwrap(), "--out", out.to_str().unwrap()])
        .output()
        .unwrap();
    format!(
        "{}{}",
        String::from_utf8_lossy(&o.stdout),
        String::from_utf8_lossy(&o.stderr)
    )
}

/// MTF50 (cy/px) per variant from results.csv.
fn mtf50(out: &Path) -> Vec<(String, f64)> {
    let mut r = csv::Reader::from_path(out.join("lens-rtf/results.csv")).unwrap();
    let h = r.headers().unwrap().clone();
    let col = |n: &str| h.iter().position(|x| x == n).unwrap();
    let (v, q, val) = (col("variant"), col("quantity"), col("value"));
    r.records()
        .map(|x| x.unwrap())
        .filter(|x| &x[q] == "edge/mtf50")
        .map(|x| (x[v].to_string(), x[val].parse().unwrap()))
        .collect()
}

/// A degree-7 RTF fitted to the double Gauss gives the prescription's
/// slanted-edge MTF50 (measured 1.5 % apart; the fit's geometric ESF error
/// is 0.3 %, the rest Monte Carlo): within 5 %.
#[test]
fn fitted_rtf_renders_like_its_prescription() {
    let dir = tempfile::tempdir().unwrap();
    let root = env!("CARGO_MANIFEST_DIR");
    let exp = experiment(
        dir.path(),
        &format!(
            r#"lens "{root}/lenses/prescriptions/dgauss.28deg-zemax.json" focus-distance-m=1.0"#
        ),
        r#"lens.rtf-degree "none" 7"#,
    );
    let out = dir.path().join("out");
    let log = run(&exp, &out);
    let m = mtf50(&out);
    assert_eq!(m.len(), 2, "{log}");
    let (p, r) = (m[0].1, m[1].1);
    println!("MTF50 prescription {p:.4} cy/px, RTF degree 7 {r:.4} cy/px");
    assert!(p > 0.0 && (r / p - 1.0).abs() < 0.05, "{m:?}");
}

/// Bad rtf-degree / rtf-axis-weight values are located errors; nothing runs.
#[test]
fn bad_rtf_degree_values_are_reported() {
    let dir = tempfile::tempdir().unwrap();
    let root = env!("CARGO_MANIFEST_DIR");
    let dgauss = format!("{root}/lenses/prescriptions/dgauss.28deg-zemax.json");
    let p4a = format!("{root}/lenses/rtf/pixel4a-rearcamera-ellipse-raytransfer.json");
    for (lens, expect) in [
        (
            format!(r#"lens "{dgauss}" rtf-degree=2.5"#),
            "rtf-degree = 2.5",
        ),
        (
            format!(r#"lens "{dgauss}" rtf-degree=40"#),
            "rtf-degree = 40",
        ),
        (
            format!(r#"lens "{dgauss}" rtf-degree="all""#),
            "rtf-degree = all",
        ),
        (
            format!(r#"lens "{dgauss}" rtf-axis-weight=4"#),
            "rtf-axis-weight needs rtf-degree",
        ),
        (
            format!(r#"lens "{p4a}" rtf-degree=5"#),
            "needs a lens prescription",
        ),
        (
            format!(r#"lens "{dgauss}" rtf-degree=5 rtf-axis-weight=-1"#),
            "'rtf-axis-weight' must be > 0",
        ),
        (
            format!(r#"lens "{dgauss}" rtf-degre="none""#),
            "did you mean 'rtf-degree'?",
        ),
    ] {
        let exp = experiment(dir.path(), &lens, "render.seed 1");
        let out = dir.path().join("bad");
        let log = run(&exp, &out);
        // Reported before anything runs, at the property (line 4 holds the lens).
        assert!(
            log.contains("lens-rtf.kdl:4:") && log.contains(expect),
            "{lens}: {log}"
        );
        assert!(!log.contains("panicked") && !out.exists(), "{log}");
    }
}
