//! What the paper's scene figures rely on beyond their baselines
//! (tests/experiment_baselines.rs): `camsim check` refuses objects that
//! intersect (Fig. 4's bunny must stand free), and `save "dng"` writes each
//! view's raw mosaic as a DNG that an independent raw reader (dcraw) opens with
//! the sensor's size, CFA pattern and black level.

mod common;
use common::camsim;

use std::path::Path;

const ROOT: &str = env!("CARGO_MANIFEST_DIR");

fn write(dir: &Path, name: &str, text: &str) -> String {
    let p = dir.join(name);
    std::fs::write(&p, text).unwrap();
    p.to_string_lossy().to_string()
}

#[test]
fn check_refuses_a_bunny_that_stands_inside_a_cube_and_a_wall() {
    let tmp = tempfile::tempdir().unwrap();
    // The mesh target's default size (116 mm tall) at the setup's bunny position:
    // inside the small cube and through the green wall (x = 0.1497 m).
    let kdl = format!(
        r#"experiment "bunny" {{
    scene "{ROOT}/scenes/CornellBoxReference/CornellBoxReference.pbrt" materials="paper"
    add "bunny" target="mesh" file="{ROOT}/scenes/bunny.obj" position-m=(0.098 0.058 0) rotate-deg=(0 3 0)
    measure "ri"
}}
"#
    );
    let f = write(tmp.path(), "bunny.kdl", &kdl);
    let o = camsim(&["check", &f]);
    let e = String::from_utf8_lossy(&o.stderr);
    assert!(!o.status.success(), "{e}");
    assert!(e.contains("bunny.kdl:3:9"), "located at the add node: {e}");
    assert!(
        e.contains("'bunny'") && e.contains("intersect"),
        "names the objects: {e}"
    );
    // The same bunny at 16 mm on the cube's top (fig04-qualitative) stands free.
    let ok = kdl.replace("rotate-deg=(0 3 0)", "rotate-deg=(0 3 0) scale=0.19932");
    let f = write(tmp.path(), "bunny.kdl", &ok);
    let o = camsim(&["check", &f]);
    assert!(o.status.success(), "{}", String::from_utf8_lossy(&o.stderr));
}

#[test]
fn save_dng_writes_a_mosaic_that_dcraw_reads() {
    let tmp = tempfile::tempdir().unwrap();
    let kdl = format!(
        r#"experiment "dng" {{
    scene "{ROOT}/scenes/cornell-box.kdl"
    sensor "{ROOT}/sensors/imx363.kdl" rows=48 cols=64 pixel-size-um=1.4 exposure-s="auto"
    render spp=2 max-bounces=1
    save "dng"
    measure "ri"
}}
"#
    );
    let f = write(tmp.path(), "dng.kdl", &kdl);
    let out = tmp.path().join("out");
    let o = camsim(&["run", "--out", out.to_str().unwrap(), &f]);
    assert!(o.status.success(), "{}", String::from_utf8_lossy(&o.stderr));
    let dng = out.join("dng/previews/default/sensor.dng");
    assert!(dng.exists(), "no {}", dng.display());
    assert!(
        out.join("dng/previews/default/sensor-raw-mosaic.png")
            .exists()
    );
    let report = std::fs::read_to_string(out.join("dng/report.html")).unwrap();
    assert!(
        report.contains("sensor.dng\" download>"),
        "report links the DNG"
    );
    // the IMX363 file's cfa "grbg"; black 64 DV, white 1023 DV
    common::dcraw_reads(&dng, (64, 48), "GR/BG", (64, 1023));
}
