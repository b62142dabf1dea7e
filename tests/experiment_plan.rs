//! Sweep expansion and plans: counts, stable ids, values applied to the
//! resolved spec, byte-identical JSON on repeat.

use camsim::experiment::{self, Loader};
use camsim::params::Value;
use std::path::Path;

fn plan_of(path: &str) -> experiment::Plan {
    let p = experiment::parse_file(Path::new(path), Loader::Disk).unwrap_or_else(|e| panic!("{e}"));
    experiment::plan(&p, None).unwrap_or_else(|e| panic!("{e}"))
}

#[test]
fn cartesian_3x2_plus_zip_gives_12_stable_ids() {
    let plan = plan_of("tests/experiments/grid12.kdl");
    let ids: Vec<&str> = plan
        .variants
        .iter()
        .map(|v| v.variant.id.as_str())
        .collect();
    let mut want = Vec::new();
    for e in ["0.1", "0.2", "0.3"] {
        for s in ["64", "128"] {
            for (f, d) in [("0.3", "0.57624"), ("0.5", "0.49234")] {
                want.push(format!(
                    "exposure-s={e},spp={s},focus-m={f},film-distance-mm={d}"
                ));
            }
        }
    }
    assert_eq!(ids, want);
    assert_eq!(
        plan.axes,
        [
            "sensor.exposure-s",
            "render.spp",
            "tag.focus-m",
            "lens.film-distance-mm"
        ]
    );
    // Values are applied onto the resolved spec of each variant.
    let v = &plan.variants[11].variant;
    assert_eq!(v.spec.render.spp, 128);
    assert_eq!(v.spec.render.seed, 7);
    assert_eq!(
        v.spec.sensor.as_ref().unwrap().overrides.get("exposure-s"),
        Some(&Value::Number(0.3))
    );
    assert_eq!(
        v.spec
            .lens
            .as_ref()
            .unwrap()
            .overrides
            .get("film-distance-mm"),
        Some(&Value::Number(0.49234))
    );
    assert_eq!(v.spec.tags.get("focus-m"), Some(&Value::Number(0.5)));
    // The range value is exactly 0.3, not 0.1 + 2·0.1 = 0.30000000000000004.
    assert_eq!(v.params.get("sensor.exposure-s"), Some(&Value::Number(0.3)));
    // Distinct inputs → distinct hashes.
    let mut hashes: Vec<&str> = plan.variants.iter().map(|v| v.hash.as_str()).collect();
    hashes.sort();
    hashes.dedup();
    assert_eq!(hashes.len(), 12);
}

#[test]
fn planning_twice_gives_byte_identical_json() {
    let a = plan_of("tests/experiments/grid12.kdl").to_json();
    let b = plan_of("tests/experiments/grid12.kdl").to_json();
    assert_eq!(a, b);
    let exe = env!("CARGO_BIN_EXE_camsim");
    let run = || {
        std::process::Command::new(exe)
            .args(["plan", "--json", "tests/experiments/grid12.kdl"])
            .output()
            .unwrap()
    };
    let (x, y) = (run(), run());
    assert_eq!(
        x.status.code(),
        Some(0),
        "{}",
        String::from_utf8_lossy(&x.stderr)
    );
    assert_eq!(x.stdout, y.stdout);
    assert_eq!(String::from_utf8(x.stdout).unwrap(), a);
    let json: serde_json::Value = serde_json::from_str(&a).unwrap();
    assert_eq!(json["variants"].as_array().unwrap().len(), 12);
}

#[test]
fn comments_and_layout_do_not_change_ids_or_hashes() {
    let text = std::fs::read_to_string("tests/experiments/grid12.kdl").unwrap();
    let reformatted = text
        .replace("    ", "\t")
        .replace("// 3 × 2", "/* block */ // 3 × 2");
    let a = plan_of("tests/experiments/grid12.kdl");
    let p = experiment::parse_source(
        Path::new("tests/experiments/grid12.kdl"),
        reformatted,
        Loader::Disk,
    )
    .unwrap();
    let b = experiment::plan(&p, None).unwrap();
    assert_eq!(a.to_json(), b.to_json());
}

#[test]
fn bases_merge_and_overrides_win() {
    let plan = plan_of("experiments/fig07-lsf-mtf.kdl");
    assert_eq!(plan.variants.len(), 4);
    let s = &plan.variants[0].variant.spec;
    // From the base: scene, camera, lens file; from the experiment: spp, additions.
    assert!(
        s.scene
            .as_ref()
            .unwrap()
            .path
            .ends_with("scenes/CornellBoxReference/CornellBoxReference.pbrt")
    );
    assert_eq!(s.camera.as_ref().unwrap().position_m, [0.0, 0.115, -0.40]);
    assert_eq!(s.render.spp, 128);
    assert_eq!(s.render.max_bounces, 2);
    assert_eq!(s.render.seed, 1);
    assert_eq!(s.additions.len(), 3);
    assert_eq!(s.removals, ["CubeSmall", "CubeLarge"]);
    assert_eq!(s.measures[0].of, ["edge-near", "edge-far"]);
    assert_eq!(
        plan.variants[0].variant.id,
        "focus-m=0.3,film-distance=paper,film-distance-mm=0.57624"
    );
    assert_eq!(
        s.lens.as_ref().unwrap().overrides.get("film-distance-mm"),
        Some(&Value::Number(0.57624))
    );
    assert_eq!(s.bases.len(), 1);
}

#[test]
fn seed_flag_replaces_every_variant_seed() {
    let p =
        experiment::parse_file(Path::new("tests/experiments/grid12.kdl"), Loader::Disk).unwrap();
    let a = experiment::plan(&p, Some(99)).unwrap();
    assert!(a.variants.iter().all(|v| v.variant.spec.render.seed == 99));
    let b = experiment::plan(&p, None).unwrap();
    assert_ne!(a.variants[0].hash, b.variants[0].hash);
}

#[test]
fn embedded_list_matches_the_experiments_directory() {
    let mut on_disk: Vec<String> = std::fs::read_dir("experiments")
        .unwrap()
        .map(|e| e.unwrap().file_name().to_string_lossy().to_string())
        .filter(|n| n.ends_with(".kdl"))
        .collect();
    on_disk.sort();
    let embedded: Vec<&str> = experiment::embedded::EXPERIMENTS
        .iter()
        .map(|e| e.0)
        .collect();
    assert_eq!(
        embedded, on_disk,
        "add new experiments/*.kdl to src/experiment/embedded.rs"
    );
    for (name, text) in experiment::embedded::EXPERIMENTS {
        let disk = std::fs::read_to_string(Path::new("experiments").join(name)).unwrap();
        assert_eq!(&disk, text);
        let p = experiment::parse_file(&Path::new("experiments").join(name), Loader::Embedded)
            .unwrap_or_else(|e| panic!("{e}"));
        if p.kind == experiment::DocKind::Experiment {
            experiment::plan(&p, None).unwrap_or_else(|e| panic!("{e}"));
        }
    }
}

#[test]
fn hashes_do_not_depend_on_how_the_file_is_reached() {
    let a = plan_of("experiments/fig07-lsf-mtf.kdl");
    let b = plan_of("tests/../experiments/fig07-lsf-mtf.kdl");
    let abs =
        std::path::Path::new(env!("CARGO_MANIFEST_DIR")).join("experiments/fig07-lsf-mtf.kdl");
    let c = plan_of(abs.to_str().unwrap());
    for ((x, y), z) in a.variants.iter().zip(&b.variants).zip(&c.variants) {
        assert_eq!(x.hash, y.hash);
        assert_eq!(x.hash, z.hash);
    }
    // …but a changed input changes them.
    let text = std::fs::read_to_string("experiments/fig07-lsf-mtf.kdl")
        .unwrap()
        .replace("spp=128", "spp=512");
    let p = experiment::parse_source(
        Path::new("experiments/fig07-lsf-mtf.kdl"),
        text,
        Loader::Disk,
    )
    .unwrap();
    let d = experiment::plan(&p, None).unwrap();
    assert_ne!(a.variants[0].hash, d.variants[0].hash);
}

/// A base is merged as a whole value: every shipped experiment that uses a
/// base plans to the same resolved parameters and the same variant hashes as
/// the same experiment written out inline (`tests/experiments/inline/<name>.kdl`,
/// parsed as if it stood where the shipped file stands, so relative paths
/// resolve alike). Only the list of bases differs.
#[test]
fn based_experiments_plan_like_their_inline_versions() {
    let mut checked = 0;
    for e in std::fs::read_dir("experiments").unwrap() {
        let path = e.unwrap().path();
        let text = std::fs::read_to_string(&path).unwrap();
        let based = text.lines().any(|l| l.trim_start().starts_with("base "));
        if !based || !text.contains("experiment \"") {
            continue;
        }
        let name = path.file_name().unwrap().to_str().unwrap();
        let inline_path = Path::new("tests/experiments/inline").join(name);
        let inline = std::fs::read_to_string(&inline_path).unwrap_or_else(|_| {
            panic!(
                "{} uses a base: write it out inline as {}",
                path.display(),
                inline_path.display()
            )
        });
        let a = experiment::parse_file(&path, Loader::Disk).unwrap_or_else(|e| panic!("{e}"));
        let b =
            experiment::parse_source(&path, inline, Loader::Disk).unwrap_or_else(|e| panic!("{e}"));
        assert!(!a.spec.bases.is_empty() && b.spec.bases.is_empty());
        let pa = experiment::plan(&a, None).unwrap();
        let pb = experiment::plan(&b, None).unwrap();
        assert_eq!(pa.variants.len(), pb.variants.len(), "{name}");
        for (va, vb) in pa.variants.iter().zip(&pb.variants) {
            let mut sa = va.variant.spec.clone();
            sa.bases.clear();
            // (compared as serialised: source spans differ by construction)
            assert_eq!(
                serde_json::to_string_pretty(&sa).unwrap(),
                serde_json::to_string_pretty(&vb.variant.spec).unwrap(),
                "{name} {}: resolved specs differ",
                va.variant.id
            );
            assert_eq!(va.hash, vb.hash, "{name} {}: hashes differ", va.variant.id);
        }
        checked += 1;
    }
    assert!(checked >= 2, "only {checked} based experiments checked");
}
