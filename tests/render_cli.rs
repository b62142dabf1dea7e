//! `camsim render` end to end on the shipped Cornell box KDL scene.

use std::process::Command;

fn camsim() -> Command {
    Command::new(env!("CARGO_BIN_EXE_camsim"))
}

/// `camsim render ARGS --out OUT` must exit 0 (stderr shown otherwise).
fn render_ok(args: &[&str], out: &std::path::Path) {
    let st = camsim()
        .arg("render")
        .args(args)
        .arg("--out")
        .arg(out)
        .output()
        .unwrap();
    assert_eq!(
        st.status.code(),
        Some(0),
        "{}",
        String::from_utf8_lossy(&st.stderr)
    );
}

#[test]
fn cornell_box_kdl_renders_identically_on_one_and_two_threads() {
    let dir = tempfile::tempdir().unwrap();
    let mut outs = vec![];
    for threads in ["1", "2"] {
        let out = dir.path().join(format!("cb{threads}.exr"));
        render_ok(
            &[
                "scenes/cornell-box.kdl",
                "--spp",
                "2",
                "--roi",
                "100,80,40,30",
                "--seed",
                "7",
                "--threads",
                threads,
            ],
            &out,
        );
        assert!(out.with_extension("png").exists());
        let side: serde_json::Value =
            serde_json::from_slice(&std::fs::read(out.with_extension("json")).unwrap()).unwrap();
        assert_eq!(side["spp"], 2);
        assert_eq!(side["nan_count"], 0);
        assert!(side["paths_per_s"].as_f64().unwrap() > 0.0);
        outs.push(std::fs::read(&out).unwrap());
    }
    assert_eq!(outs[0], outs[1], "EXR differs between 1 and 2 threads");
    // The spectral channels are named as pbrt-v4 names them.
    let s = String::from_utf8_lossy(&outs[0]);
    assert!(s.contains("S0.400,000nm") && s.contains("S0.700,000nm"));
}

#[test]
fn pbrt_scenes_render_and_kdl_errors_are_located() {
    let dir = tempfile::tempdir().unwrap();
    let out = dir.path().join("bitterli.exr");
    render_ok(
        &[
            "scenes/pbrt-v4/bitterli-cornell-box.pbrt",
            "--spp",
            "1",
            "--roi",
            "0,0,16,16",
        ],
        &out,
    );
    assert!(out.exists() && out.with_extension("png").exists());
    let out2 = dir.path().join("cbox.exr");
    render_ok(
        &[
            "scenes/CornellBoxReference/CornellBoxReference.pbrt",
            "--paper-spectra",
            "--spp",
            "1",
            "--roi",
            "600,300,8,8",
        ],
        &out2,
    );
    let dir = tempfile::tempdir().unwrap();
    let p = dir.path().join("bad.kdl");
    std::fs::write(&p, "film width-px=10 height-px=10\nshape \"x\" type=\"sphere\" material=\"nope\" { radius-m 1; }\n").unwrap();
    let st = camsim().arg("render").arg(&p).output().unwrap();
    assert_eq!(st.status.code(), Some(3));
    let e = String::from_utf8_lossy(&st.stderr);
    assert!(e.contains("bad.kdl:2:"), "{e}");
}

#[test]
fn cornell_box_scene_matches_the_setup_json() {
    let sf =
        camsim::scene::kdl_scene::load_kdl_scene(std::path::Path::new("scenes/cornell-box.kdl"))
            .unwrap();
    let s = &sf.scene;
    let names: Vec<&str> = s.objects.iter().map(|o| o.name.as_str()).collect();
    for n in [
        "wall-left",
        "wall-right",
        "wall-back",
        "floor",
        "ceiling",
        "light",
        "cube-small",
        "cube-large",
    ] {
        assert!(names.contains(&n), "{n} missing");
    }
    let light = s.meshes.iter().find(|m| m.emission.is_some()).unwrap();
    // 4×4 cm, facing down, at the top of the 0.3 m box.
    let (lo, hi) = light.positions.iter().fold(
        (glam::Vec3::splat(9.0), glam::Vec3::splat(-9.0)),
        |(a, b), p| (a.min(*p), b.max(*p)),
    );
    assert!(
        ((hi - lo).x - 0.04).abs() < 1e-6
            && ((hi - lo).z - 0.04).abs() < 1e-6
            && (lo.y - 0.2999).abs() < 1e-6
    );
    let p = &light.positions;
    let n = (p[1] - p[0]).cross(p[2] - p[0]);
    assert!(n.y < 0.0, "light must face down");
    // The red wall is at x = −0.1497 and faces +x.
    let red = s
        .objects
        .iter()
        .position(|o| o.name == "wall-left")
        .unwrap() as u32;
    let m = s.meshes.iter().find(|m| m.object == red).unwrap();
    assert!(m.positions.iter().all(|p| (p.x + 0.1497).abs() < 1e-6));
    assert_eq!(sf.max_bounces, Some(6));
}
