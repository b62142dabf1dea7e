//! `camsim pov SCENE --out DIR`: files, columns and exit codes (issue 19).
//! The POV-Ray parts skip with a note when `povray` is missing, except in CI.

use std::path::Path;
use std::process::{Command, Output};

const BIN: &str = env!("CARGO_BIN_EXE_camsim");
const BITTERLI: &str = "scenes/pbrt-v4/bitterli-cornell-box.pbrt";

fn camsim(args: &[&str]) -> Output {
    Command::new(BIN).args(args).output().unwrap()
}

fn povray_or_skip() -> bool {
    if camsim::pov::povray::available() {
        return true;
    }
    assert!(
        std::env::var("CI").is_err(),
        "povray must be installed in CI (.ci/run installs it)"
    );
    eprintln!("note: povray not installed (apt-get install povray); POV-Ray part skipped");
    false
}

#[test]
fn without_povray_one_line_names_the_package_and_exit_3() {
    let dir = tempfile::tempdir().unwrap();
    let out = dir.path().join("out");
    // An empty PATH: no povray to be found.
    let o = Command::new(BIN)
        .args(["pov", BITTERLI, "--out", out.to_str().unwrap()])
        .env("PATH", dir.path())
        .output()
        .unwrap();
    let err = String::from_utf8_lossy(&o.stderr);
    assert_eq!(o.status.code(), Some(3), "stderr: {err}");
    assert_eq!(err.trim().lines().count(), 1, "stderr: {err}");
    assert!(err.contains("apt-get install povray"), "stderr: {err}");
    assert!(!out.exists(), "no output directory without a check");
}

#[test]
fn bad_flags_are_usage_errors() {
    for args in [
        vec!["pov", BITTERLI, "--out", "d", "--min-iou", "1.5"],
        vec!["pov", BITTERLI, "--out", "d", "--width", "0"],
        vec!["pov", BITTERLI, "--out", "d", "--png", "x.png"],
        vec!["pov", BITTERLI, "--out", "x.pov", "--min-iou", "0.9"],
    ] {
        let o = camsim(&args);
        assert_eq!(o.status.code(), Some(2), "{args:?}");
        assert!(!Path::new("d").exists());
    }
}

fn png_size(path: &Path) -> (u32, u32) {
    let dec = png::Decoder::new(std::io::BufReader::new(std::fs::File::open(path).unwrap()));
    let r = dec.read_info().unwrap();
    (r.info().width, r.info().height)
}

#[test]
fn check_writes_scene_csv_and_picture() {
    if !povray_or_skip() {
        return;
    }
    let dir = tempfile::tempdir().unwrap();
    let out = dir.path().join("check");
    let o = camsim(&[
        "pov",
        BITTERLI,
        "--out",
        out.to_str().unwrap(),
        "--width",
        "128",
    ]);
    let stdout = String::from_utf8_lossy(&o.stdout);
    assert_eq!(
        o.status.code(),
        Some(0),
        "{stdout} {}",
        String::from_utf8_lossy(&o.stderr)
    );
    assert!(stdout.starts_with("minimum IoU "), "{stdout}");
    let pov = std::fs::read_to_string(out.join("scene.pov")).unwrap();
    assert!(pov.contains("mesh2") && pov.contains("camera"));
    let csv = std::fs::read_to_string(out.join("iou.csv")).unwrap();
    let mut lines = csv.lines();
    assert_eq!(lines.next(), Some("object,pixels_camsim,pixels_povray,iou"));
    let rows: Vec<Vec<&str>> = lines.map(|l| l.split(',').collect()).collect();
    // 8 objects: floor, ceiling, 3 walls, 2 boxes, the light.
    assert_eq!(rows.len(), 8, "{csv}");
    for r in &rows {
        let iou: f64 = r[3].parse().unwrap();
        assert!(iou >= 0.98, "{csv}");
    }
    // 128×128 (the film is square): three panels with two 4 px gaps.
    assert_eq!(png_size(&out.join("side-by-side.png")), (3 * 128 + 8, 128));

    // `--out F.pov` keeps the export-only behaviour.
    let f = dir.path().join("shaded.pov");
    let o = camsim(&["pov", BITTERLI, "--out", f.to_str().unwrap()]);
    assert_eq!(o.status.code(), Some(0));
    assert!(
        std::fs::read_to_string(&f)
            .unwrap()
            .contains("light_source")
    );
}

/// A real wide-angle lens is not a pinhole: its distortion and vignetting
/// move silhouettes away from the pinhole equivalent's, the check says so
/// and exits 1 (and still writes its files).
#[test]
fn a_distorting_lens_fails_the_check_with_exit_1() {
    if !povray_or_skip() {
        return;
    }
    let dir = tempfile::tempdir().unwrap();
    let lens = Path::new(env!("CARGO_MANIFEST_DIR"))
        .join("lenses/prescriptions/dgauss.100deg.4.38mm.json");
    let scene = dir.path().join("wide.pbrt");
    std::fs::write(
        &scene,
        format!(
            r#"LookAt 0 0 -1  0 0 0  0 1 0
Camera "realistic" "string lensfile" ["{}"] "float aperturediameter" [1] "float focusdistance" [1]
Film "rgb" "integer xresolution" [160] "integer yresolution" [120] "float diagonal" [7.056]
WorldBegin
Shape "trianglemesh" "point3 P" [-2 -2 1  2 -2 1  2 2 1  -2 2 1] "integer indices" [0 1 2 0 2 3]
AttributeBegin
Translate 0.35 0.25 0
Shape "sphere" "float radius" [0.08]
AttributeEnd
"#,
            lens.display()
        ),
    )
    .unwrap();
    let out = dir.path().join("check");
    let o = camsim(&[
        "pov",
        scene.to_str().unwrap(),
        "--out",
        out.to_str().unwrap(),
    ]);
    let err = String::from_utf8_lossy(&o.stderr);
    assert_eq!(o.status.code(), Some(1), "{err}");
    assert!(err.contains("IoU"), "{err}");
    assert!(out.join("iou.csv").exists() && out.join("side-by-side.png").exists());
    // With --pinhole camsim's labels follow its pinhole with the lens' field
    // of view: the geometry itself agrees.
    let o = camsim(&[
        "pov",
        scene.to_str().unwrap(),
        "--out",
        out.to_str().unwrap(),
        "--pinhole",
    ]);
    assert_eq!(
        o.status.code(),
        Some(0),
        "{}",
        String::from_utf8_lossy(&o.stderr)
    );
}
