//! Issue 16 item 2: the optical-image cache. A sweep over sensor-only
//! settings renders once and gives results bit-identical to `--no-cache`;
//! each input of the render misses; a damaged cache file is re-rendered with
//! a warning; the size limit evicts.
//!
//! The experiments are small (480 × 270 film, 4 spp, 1 bounce: ~0.1 s each).

mod common;
use common::{camsim, stderr};

use std::path::{Path, PathBuf};
use std::process::Output;

const ROOT: &str = env!("CARGO_MANIFEST_DIR");

/// A one-triangle OBJ (an asset whose bytes the scene reads).
const TRIANGLE: &str = "v 0 0 0\nv 0.02 0 0\nv 0 0.02 0\nf 1 2 3\n";

/// The base experiment `name` with `scene`, `mesh` and extra `body` lines.
fn base_text(name: &str, scene: &Path, mesh: &Path, body: &str) -> String {
    format!(
        "experiment \"{name}\" {{
    scene \"{}\"
    sensor \"{ROOT}/sensors/generic.kdl\" rows=270 cols=480 exposure-s=2
    add \"mcc\" target=\"mcc\" position-m=(0 0.105 -0.1) scale=2
    add \"tri\" target=\"mesh\" file=\"{}\" position-m=(-0.05 0.2 0.1)
    render spp=4 max-bounces=1 seed=3
    measure \"mcc\" of=\"mcc\"
{body}}}
",
        scene.display(),
        mesh.display()
    )
}

struct Setup {
    dir: tempfile::TempDir,
    scene: PathBuf,
    mesh: PathBuf,
}

fn setup() -> Setup {
    let dir = tempfile::tempdir().unwrap();
    let scene = dir.path().join("box.kdl");
    std::fs::copy(Path::new(ROOT).join("scenes/cornell-box.kdl"), &scene).unwrap();
    let mesh = dir.path().join("tri.obj");
    std::fs::write(&mesh, TRIANGLE).unwrap();
    Setup { dir, scene, mesh }
}

fn manifest(out: &Path, exp: &str) -> serde_json::Value {
    let p = out.join(exp).join("manifest.json");
    serde_json::from_str(&std::fs::read_to_string(&p).unwrap()).unwrap()
}

/// (oi_cache, oi_hash) of every variant of a run, in plan order.
fn cache_use(out: &Path, exp: &str) -> Vec<(String, String)> {
    manifest(out, exp)["variants"]
        .as_array()
        .unwrap()
        .iter()
        .map(|v| {
            (
                v["oi_cache"].as_str().unwrap_or("<none>").to_string(),
                v["oi_hash"].as_str().unwrap_or("<none>").to_string(),
            )
        })
        .collect()
}

/// results.csv without the timing columns (render_s, total_s: the last two).
fn results_wo_times(out: &Path, exp: &str) -> Vec<Vec<String>> {
    let mut r = csv::Reader::from_path(out.join(exp).join("results.csv")).unwrap();
    let rows: Vec<Vec<String>> = r
        .records()
        .map(|x| {
            let x = x.unwrap();
            x.iter().take(x.len() - 2).map(str::to_string).collect()
        })
        .collect();
    assert!(!rows.is_empty());
    rows
}

fn run_ok(exp: &Path, out: &Path, extra: &[&str]) -> Output {
    let mut args = vec!["run", exp.to_str().unwrap(), "--out", out.to_str().unwrap()];
    args.extend_from_slice(extra);
    let o = camsim(&args);
    assert!(o.status.success(), "camsim run failed: {}", stderr(&o));
    o
}

fn cache_files(out: &Path) -> Vec<PathBuf> {
    let mut v: Vec<PathBuf> = std::fs::read_dir(out.join(".cache/optical-images"))
        .map(|rd| {
            rd.map(|e| e.unwrap().path())
                .filter(|p| p.extension().is_some_and(|x| x == "bin"))
                .collect()
        })
        .unwrap_or_default();
    v.sort();
    v
}

#[test]
fn exposure_sweep_renders_once_and_matches_no_cache_bit_for_bit() {
    let s = setup();
    let exp = s.dir.path().join("sweep.kdl");
    std::fs::write(
        &exp,
        base_text(
            "sweep",
            &s.scene,
            &s.mesh,
            "    sweep {\n        sensor.exposure-s 1 2 3 4 5\n    }\n",
        ),
    )
    .unwrap();
    let cached = s.dir.path().join("cached");
    let fresh = s.dir.path().join("fresh");
    let log = stderr(&run_ok(&exp, &cached, &["--threads", "1"]));
    let u = cache_use(&cached, "sweep");
    assert_eq!(u.len(), 5);
    let status: Vec<&str> = u.iter().map(|x| x.0.as_str()).collect();
    assert_eq!(status, ["miss", "hit", "hit", "hit", "hit"], "{log}");
    assert!(u.iter().all(|x| x.1 == u[0].1 && x.1.len() == 64));
    assert_eq!(log.matches("oi cache hit").count(), 4, "{log}");
    assert_eq!(log.matches("oi cache miss").count(), 1, "{log}");
    assert_eq!(cache_files(&cached).len(), 1, "one optical image on disk");
    // The report's variant table shows the column.
    let html = std::fs::read_to_string(cached.join("sweep/report.html")).unwrap();
    assert!(html.contains("oi cache</th>") && html.contains("<td>hit</td>"));

    // Without the cache, on another thread count: every variant renders.
    let log2 = stderr(&run_ok(&exp, &fresh, &["--no-cache", "--threads", "2"]));
    let u2 = cache_use(&fresh, "sweep");
    assert!(u2.iter().all(|x| x.0 == "off" && x.1 == u[0].1), "{log2}");
    assert!(cache_files(&fresh).is_empty(), "--no-cache writes no cache");
    // Bit-identical results (every column but the timings) and sensor images.
    let a = results_wo_times(&cached, "sweep");
    assert_eq!(a, results_wo_times(&fresh, "sweep"));
    // The sweep does reach the sensor: the patch means differ with exposure.
    assert_ne!(a[0][6], a[a.len() - 1][6]);
    for e in 1..=5 {
        let p = format!("sweep/previews/exposure-s={e}/sensor.png");
        assert_eq!(
            std::fs::read(cached.join(&p)).unwrap(),
            std::fs::read(fresh.join(&p)).unwrap(),
            "{p}"
        );
    }
}

#[test]
fn every_render_input_misses_and_sensor_only_settings_hit() {
    let s = setup();
    let out = s.dir.path().join("out");
    let base = base_text("NAME", &s.scene, &s.mesh, "");
    let mut n = 0;
    // Run the base text changed by `edit` as a new experiment; its (status, hash).
    let mut run = |edit: &dyn Fn(&str) -> String| {
        n += 1;
        let name = format!("e{n}");
        let exp = s.dir.path().join(format!("{name}.kdl"));
        let text = edit(&base.replace("NAME", &name));
        std::fs::write(&exp, text).unwrap();
        run_ok(&exp, &out, &[]);
        cache_use(&out, &name).remove(0)
    };
    let first = run(&|t| t.to_string());
    assert_eq!(first.0, "miss");
    assert_eq!(run(&|t| t.to_string()), ("hit".into(), first.1.clone()));
    let hits: [(&str, &str, &str); 3] = [
        ("exposure", "exposure-s=2", "exposure-s=3"),
        ("gain", "exposure-s=2", "exposure-s=2 analog-gain=4"),
        (
            "noise",
            "exposure-s=2",
            "exposure-s=2 read-noise-mv=0.5 photon-noise=#false prnu=#false",
        ),
    ];
    for (what, from, to) in hits {
        let r = run(&|t| t.replacen(from, to, 1));
        assert_eq!(r, ("hit".into(), first.1.clone()), "{what}");
    }
    let misses: [(&str, &str, &str); 11] = [
        ("spp", "spp=4", "spp=5"),
        ("seed", "seed=3", "seed=4"),
        ("bounces", "max-bounces=1", "max-bounces=2"),
        (
            "wavelength grid",
            "seed=3",
            "seed=3 wavelength-nm=(400 700 20)",
        ),
        ("film size", "rows=270", "rows=272"),
        ("pixel pitch", "rows=270", "rows=270 pixel-size-um=2.2"),
        (
            "scene edit (add)",
            "position-m=(0 0.105 -0.1)",
            "position-m=(0 0.106 -0.1)",
        ),
        (
            "scene edit (remove)",
            "    render ",
            "    remove \"wall-left\"\n    render ",
        ),
        (
            "camera pose",
            "    render ",
            "    camera position-m=(0 0.106 -0.4) look-at-m=(0 0.105 0.6) up=(0 1 0)\n    render ",
        ),
        (
            "lens",
            "    render ",
            "    lens model=\"pinhole\" fov-deg=45 f-number=1.73\n    render ",
        ),
        // A different measurement region (render window): the mcc alone vs the whole frame.
        (
            "render window",
            "    measure \"mcc\" of=\"mcc\"",
            "    measure \"mcc\" of=\"mcc\"\n    save \"dng\"",
        ),
    ];
    let mut seen = vec![first.1.clone()];
    for (what, from, to) in misses {
        let r = run(&|t| {
            assert!(t.contains(from), "{what}");
            t.replacen(from, to, 1)
        });
        assert_eq!(r.0, "miss", "{what}");
        assert!(!seen.contains(&r.1), "{what}: hash {} seen before", r.1);
        seen.push(r.1);
    }
    // The sensor's QE weights the render's per-channel standard error
    // (RenderSettings::stderr_weights), so a QE change re-renders.
    let sensor = s.dir.path().join("qe.kdl");
    let generic = std::fs::read_to_string(Path::new(ROOT).join("sensors/generic.kdl")).unwrap();
    let qe = "qe r=\"constant:0.5\" g=\"constant:0.5\" b=\"constant:0.5\"";
    assert!(generic.contains(qe));
    std::fs::write(
        &sensor,
        generic.replacen(
            qe,
            "qe r=\"constant:0.5\" g=\"constant:0.4\" b=\"constant:0.5\"",
            1,
        ),
    )
    .unwrap();
    let generic_path = format!("{ROOT}/sensors/generic.kdl");
    let r = run(&|t| t.replacen(&generic_path, sensor.to_str().unwrap(), 1));
    assert_eq!(r.0, "miss", "qe");
    assert!(!seen.contains(&r.1));
    seen.push(r.1);
    // The bytes of the scene file and of a mesh it uses.
    let scene_text = std::fs::read_to_string(&s.scene).unwrap();
    let changed = scene_text.replacen(
        "material \"red-wall\" diffuse=\"cbox-red-wall\"",
        "material \"red-wall\" diffuse=\"cbox-white-wall\"",
        1,
    );
    assert_ne!(changed, scene_text);
    std::fs::write(&s.scene, changed).unwrap();
    let r = run(&|t| t.to_string());
    assert_eq!(r.0, "miss", "scene file");
    assert!(!seen.contains(&r.1));
    seen.push(r.1);
    std::fs::write(&s.mesh, TRIANGLE.replace("v 0.02 0 0", "v 0.021 0 0")).unwrap();
    let r = run(&|t| t.to_string());
    assert_eq!(r.0, "miss", "mesh file");
    assert!(!seen.contains(&r.1));
}

#[test]
fn damaged_cache_file_is_rendered_again_with_a_warning() {
    let s = setup();
    let out = s.dir.path().join("out");
    let write = |name: &str| {
        let p = s.dir.path().join(format!("{name}.kdl"));
        std::fs::write(&p, base_text(name, &s.scene, &s.mesh, "")).unwrap();
        p
    };
    run_ok(&write("first"), &out, &[]);
    let files = cache_files(&out);
    assert_eq!(files.len(), 1);
    let full = std::fs::read(&files[0]).unwrap();
    std::fs::write(&files[0], &full[..full.len() / 2]).unwrap();
    let o = run_ok(&write("second"), &out, &[]);
    let log = stderr(&o);
    assert!(
        log.contains("warning: optical-image cache file") && log.contains("damaged"),
        "{log}"
    );
    assert_eq!(cache_use(&out, "second")[0].0, "miss");
    // Re-rendered: the same results and a sound file again.
    let strip = |rows: Vec<Vec<String>>| -> Vec<Vec<String>> {
        rows.into_iter().map(|r| r[2..].to_vec()).collect()
    };
    assert_eq!(
        strip(results_wo_times(&out, "first")),
        strip(results_wo_times(&out, "second"))
    );
    // (Not byte-equal: the image records its own render time.)
    assert_eq!(
        std::fs::metadata(&files[0]).unwrap().len(),
        full.len() as u64
    );
    run_ok(&write("third"), &out, &[]);
    assert_eq!(cache_use(&out, "third")[0].0, "hit");
}

#[test]
fn size_limit_evicts_least_recently_used() {
    let s = setup();
    // The size of one cached image.
    let probe_exp = s.dir.path().join("probe.kdl");
    std::fs::write(&probe_exp, base_text("probe", &s.scene, &s.mesh, "")).unwrap();
    let probe = s.dir.path().join("probe");
    run_ok(&probe_exp, &probe, &[]);
    let size = std::fs::metadata(&cache_files(&probe)[0]).unwrap().len();
    // Room for one and a half images: after each store only the newest stays.
    let gb = format!("{:e}", size as f64 * 1.5 / 1e9);
    let exp = s.dir.path().join("seeds.kdl");
    std::fs::write(
        &exp,
        base_text(
            "seeds",
            &s.scene,
            &s.mesh,
            "    sweep {\n        render.seed 1 2 3\n    }\n",
        ),
    )
    .unwrap();
    let out = s.dir.path().join("out");
    run_ok(&exp, &out, &["--cache-max-gb", &gb]);
    let u = cache_use(&out, "seeds");
    assert!(u.iter().all(|x| x.0 == "miss"));
    let files = cache_files(&out);
    assert_eq!(files.len(), 1, "{files:?}");
    assert!(files[0].ends_with(format!("{}.bin", u[2].1)));
    // A bad limit is refused with what was expected.
    let o = camsim(&[
        "run",
        exp.to_str().unwrap(),
        "--out",
        out.to_str().unwrap(),
        "--cache-max-gb",
        "0",
    ]);
    assert!(!o.status.success());
    assert!(stderr(&o).contains("expected a positive number of GB"));
}
