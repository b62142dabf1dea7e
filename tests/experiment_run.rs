//! `camsim run` end to end on colorimetry experiments (the stage that exists
//! today): real numbers, resume after a simulated `kill -9`, shards and merge,
//! failing stages.

use std::collections::BTreeSet;
use std::path::{Path, PathBuf};
use std::process::{Command, Output};

fn camsim(args: &[&str], env: &[(&str, &str)]) -> Output {
    let mut c = Command::new(env!("CARGO_BIN_EXE_camsim"));
    c.args(args);
    for (k, v) in env {
        c.env(k, v);
    }
    c.output().unwrap()
}

fn stderr(o: &Output) -> String {
    String::from_utf8_lossy(&o.stderr).into_owned()
}

/// An experiment with 48 colorimetry variants (24 chart patches × 2 grids).
fn many_variants(dir: &Path) -> PathBuf {
    let patches: Vec<String> = (1..=24).map(|i| format!("\"mcc-{i:02}\"")).collect();
    let text = format!(
        "experiment \"many\" {{\n    measure \"colorimetry\" name=\"patch\" spectrum=\"mcc-01\"\n    sweep {{\n        measure.patch.spectrum {}\n        render.wavelength-nm (400 700 10) (380 780 5)\n    }}\n}}\n",
        patches.join(" ")
    );
    let p = dir.join("many.kdl");
    std::fs::write(&p, text).unwrap();
    p
}

fn read_rows(p: &Path) -> Vec<Vec<String>> {
    let mut r = csv::Reader::from_path(p).unwrap();
    r.records()
        .map(|x| x.unwrap().iter().map(str::to_string).collect())
        .collect()
}

fn variant_files(dir: &Path) -> BTreeSet<(String, String)> {
    std::fs::read_dir(dir)
        .map(|rd| {
            rd.map(|e| {
                let e = e.unwrap();
                (
                    e.file_name().to_string_lossy().to_string(),
                    std::fs::read_to_string(e.path()).unwrap(),
                )
            })
            .collect()
        })
        .unwrap_or_default()
}

#[test]
fn killed_run_resumes_without_lost_or_duplicated_rows() {
    let tmp = tempfile::tempdir().unwrap();
    let exp = many_variants(tmp.path());
    let out = tmp.path().join("out");
    let (e, o) = (exp.to_str().unwrap(), out.to_str().unwrap());
    // Simulated kill -9 after the 17th variant is written.
    let first = camsim(
        &["run", e, "--out", o],
        &[("CAMSIM_TEST_ABORT_AFTER", "17")],
    );
    assert!(
        !first.status.success(),
        "the aborted run must not look successful"
    );
    assert_eq!(
        first.status.code(),
        None,
        "aborted by a signal: {}",
        stderr(&first)
    );
    let vdir = out.join("many/variants");
    let before = variant_files(&vdir);
    assert_eq!(before.len(), 17, "every finished variant survives the kill");
    assert!(!out.join("many/results.csv").exists());

    let second = camsim(&["run", e, "--out", o], &[]);
    assert_eq!(second.status.code(), Some(0), "{}", stderr(&second));
    assert!(
        stderr(&second).contains("many: 31 done, 17 cached, 0 failed, 0 not run"),
        "{}",
        stderr(&second)
    );
    let after = variant_files(&vdir);
    assert!(before.is_subset(&after), "earlier results are left intact");
    assert_eq!(after.len(), 48);

    let rows = read_rows(&out.join("many/results.csv"));
    assert_eq!(rows.len(), 48 * 3, "3 figures per variant, no row lost");
    let keys: BTreeSet<(String, String, String)> = rows
        .iter()
        .map(|r| (r[1].clone(), r[5].clone(), r[6].clone()))
        .collect();
    assert_eq!(keys.len(), rows.len(), "no duplicated rows");
    let plan = camsim(&["plan", "--json", e], &[]);
    let plan: serde_json::Value = serde_json::from_slice(&plan.stdout).unwrap();
    let ids: BTreeSet<String> = plan["variants"]
        .as_array()
        .unwrap()
        .iter()
        .map(|v| v["id"].as_str().unwrap().to_string())
        .collect();
    let got: BTreeSet<String> = rows.iter().map(|r| r[1].clone()).collect();
    assert_eq!(ids, got);

    // A third run changes nothing.
    let csv2 = std::fs::read(out.join("many/results.csv")).unwrap();
    let third = camsim(&["run", e, "--out", o], &[]);
    assert!(
        stderr(&third).contains("0 done, 48 cached"),
        "{}",
        stderr(&third)
    );
    assert_eq!(std::fs::read(out.join("many/results.csv")).unwrap(), csv2);
    let m: serde_json::Value =
        serde_json::from_slice(&std::fs::read(out.join("many/manifest.json")).unwrap()).unwrap();
    assert_eq!(m["complete"], true);
    assert_eq!(m["variants"].as_array().unwrap().len(), 48);
}

#[test]
fn d65_chromaticity_through_the_runner() {
    let tmp = tempfile::tempdir().unwrap();
    let p = tmp.path().join("d65.kdl");
    std::fs::write(&p, "experiment \"d65\" {\n    render wavelength-nm=(380 780 5)\n    measure \"colorimetry\" spectrum=\"cie-d65\"\n}\n").unwrap();
    let out = tmp.path().join("out");
    let r = camsim(
        &["run", p.to_str().unwrap(), "--out", out.to_str().unwrap()],
        &[],
    );
    assert_eq!(r.status.code(), Some(0), "{}", stderr(&r));
    let rows = read_rows(&out.join("d65/results.csv"));
    let get = |q: &str| {
        rows.iter()
            .find(|r| r[3] == q)
            .map(|r| (r[5].parse::<f64>().unwrap(), r[6].clone()))
            .unwrap()
    };
    // CIE 15: D65 white point (0.3127, 0.3290), 4 decimals.
    let (x, sx) = get("x");
    let (y, _) = get("y");
    assert!(
        (x - 0.3127).abs() < 1e-4 && (y - 0.3290).abs() < 1e-4,
        "x={x} y={y}"
    );
    assert_eq!(sx, "0", "exact computation: stderr 0");
    assert_eq!(rows[0][0], "d65");
    assert_eq!(rows[0][1], "default");
    let m: serde_json::Value =
        serde_json::from_slice(&std::fs::read(out.join("d65/manifest.json")).unwrap()).unwrap();
    assert!(m["git_commit"].as_str().is_some());
    assert_eq!(m["camsim_version"], env!("CARGO_PKG_VERSION"));
    // the render kernel's instruction set level (issue 17)
    assert_eq!(
        m["render_isa"],
        camsim::render::simd::RenderIsa::detect().name()
    );
}

/// Drop the timing columns (render_s, total_s), which differ between runs.
fn without_timings(p: &Path) -> Vec<Vec<String>> {
    read_rows(p)
        .into_iter()
        .map(|mut r| {
            r.truncate(r.len() - 2);
            r
        })
        .collect()
}

#[test]
fn shards_merge_losslessly() {
    let tmp = tempfile::tempdir().unwrap();
    let exp = many_variants(tmp.path());
    let e = exp.to_str().unwrap();
    let whole = tmp.path().join("whole");
    assert_eq!(
        camsim(&["run", e, "--out", whole.to_str().unwrap()], &[])
            .status
            .code(),
        Some(0)
    );
    let mut shard_dirs = Vec::new();
    for i in 1..=3 {
        let d = tmp.path().join(format!("shard{i}"));
        let r = camsim(
            &[
                "run",
                e,
                "--out",
                d.to_str().unwrap(),
                "--shard",
                &format!("{i}/3"),
            ],
            &[],
        );
        assert_eq!(r.status.code(), Some(0), "{}", stderr(&r));
        assert_eq!(
            variant_files(&d.join("many/variants")).len(),
            16,
            "round-robin: 48/3 per shard"
        );
        assert!(
            d.join(format!("many/manifest.shard-{i}-of-3.json"))
                .exists()
        );
        assert!(
            !d.join("many/results.csv").exists(),
            "a lone shard does not pretend to be complete"
        );
        shard_dirs.push(d);
    }
    let merged = tmp.path().join("merged");
    let mut args = vec!["merge".to_string()];
    args.extend(shard_dirs.iter().map(|d| d.to_string_lossy().to_string()));
    args.extend(["--out".into(), merged.to_string_lossy().to_string()]);
    let a: Vec<&str> = args.iter().map(String::as_str).collect();
    let r = camsim(&a, &[]);
    assert_eq!(r.status.code(), Some(0), "{}", stderr(&r));
    // Lossless: every shard row appears verbatim, and the figures equal the unsharded run.
    let merged_text = std::fs::read_to_string(merged.join("many/results.csv")).unwrap();
    for d in &shard_dirs {
        for (_, t) in variant_files(&d.join("many/variants")) {
            for line in t.lines().skip(1) {
                assert_eq!(
                    merged_text.lines().filter(|l| *l == line).count(),
                    1,
                    "{line}"
                );
            }
        }
    }
    assert_eq!(
        without_timings(&merged.join("many/results.csv")),
        without_timings(&whole.join("many/results.csv"))
    );
    let m: serde_json::Value =
        serde_json::from_slice(&std::fs::read(merged.join("many/manifest.json")).unwrap()).unwrap();
    assert_eq!(m["complete"], true);

    // Merging only two of three shards is reported as incomplete (exit 1).
    let partial = tmp.path().join("partial");
    let r = camsim(
        &[
            "merge",
            shard_dirs[0].to_str().unwrap(),
            shard_dirs[1].to_str().unwrap(),
            "--out",
            partial.to_str().unwrap(),
        ],
        &[],
    );
    assert_eq!(r.status.code(), Some(1));
    assert!(
        stderr(&r).contains("16 of 48 variants have no results"),
        "{}",
        stderr(&r)
    );

    // Shards sharing one output directory assemble the results themselves.
    let shared = tmp.path().join("shared");
    for i in 1..=2 {
        let r = camsim(
            &[
                "run",
                e,
                "--out",
                shared.to_str().unwrap(),
                "--shard",
                &format!("{i}/2"),
            ],
            &[],
        );
        assert_eq!(r.status.code(), Some(0));
    }
    assert_eq!(
        without_timings(&shared.join("many/results.csv")),
        without_timings(&whole.join("many/results.csv"))
    );
}

#[test]
fn missing_stage_fails_clearly_and_the_run_goes_on() {
    let tmp = tempfile::tempdir().unwrap();
    let scene = Path::new(env!("CARGO_MANIFEST_DIR"))
        .join("scenes/CornellBoxReference/CornellBoxReference.pbrt");
    let a = tmp.path().join("a-render.kdl");
    std::fs::write(
        &a,
        format!(
            "experiment \"needs-render\" {{\n    scene \"{}\"\n    camera position-m=(0 0.1 -0.4) look-at-m=(0 0.1 0.6)\n    measure \"colorimetry\" spectrum=\"cie-a\"\n    measure \"sfr\" of=\"edge\"\n}}\n",
            scene.display()
        ),
    )
    .unwrap();
    let b = tmp.path().join("b-color.kdl");
    std::fs::write(
        &b,
        "experiment \"color\" {\n    measure \"colorimetry\" spectrum=\"cie-a\"\n}\n",
    )
    .unwrap();
    let out = tmp.path().join("out");
    let r = camsim(
        &[
            "run",
            tmp.path().to_str().unwrap(),
            "--out",
            out.to_str().unwrap(),
        ],
        &[],
    );
    assert_eq!(r.status.code(), Some(1));
    let err = stderr(&r);
    // The scene renders, but the measured object does not exist: a clear
    // failure for this variant, and the other experiment still runs.
    assert!(
        err.contains("FAILED: object 'edge' is not visible from the camera"),
        "{err}"
    );
    assert!(err.contains("color: 1 done"), "{err}");
    // No invented numbers: the failed variant has no rows at all.
    assert_eq!(read_rows(&out.join("needs-render/results.csv")).len(), 0);
    let m: serde_json::Value =
        serde_json::from_slice(&std::fs::read(out.join("needs-render/manifest.json")).unwrap())
            .unwrap();
    assert_eq!(m["variants"][0]["status"], "failed");
    assert!(
        m["variants"][0]["error"]
            .as_str()
            .unwrap()
            .contains("not visible")
    );
    assert_eq!(read_rows(&out.join("color/results.csv")).len(), 3);
}

#[test]
fn bad_shard_flag_is_an_error() {
    let r = camsim(&["run", "experiments/smoke.kdl", "--shard", "4/3"], &[]);
    assert_eq!(r.status.code(), Some(3));
    assert!(
        stderr(&r).contains("expected i/n with 1 ≤ i ≤ n"),
        "{}",
        stderr(&r)
    );
}

#[test]
fn ctrl_c_stops_after_the_variant_in_flight_and_keeps_results() {
    let tmp = tempfile::tempdir().unwrap();
    let exp = many_variants(tmp.path());
    let out = tmp.path().join("out");
    let (e, o) = (exp.to_str().unwrap(), out.to_str().unwrap());
    let r = camsim(
        &["run", e, "--out", o],
        &[("CAMSIM_TEST_INTERRUPT_AFTER", "5")],
    );
    assert_eq!(r.status.code(), Some(130), "{}", stderr(&r));
    // The partial results and manifest are written.
    assert_eq!(read_rows(&out.join("many/results.csv")).len(), 5 * 3);
    let m: serde_json::Value =
        serde_json::from_slice(&std::fs::read(out.join("many/manifest.json")).unwrap()).unwrap();
    assert_eq!(m["complete"], false);
    let done = m["variants"]
        .as_array()
        .unwrap()
        .iter()
        .filter(|v| v["status"] == "done")
        .count();
    assert_eq!(done, 5);
    let r = camsim(&["run", e, "--out", o], &[]);
    assert!(stderr(&r).contains("43 done, 5 cached"), "{}", stderr(&r));
    assert_eq!(read_rows(&out.join("many/results.csv")).len(), 48 * 3);
}

/// Issue 13 item 7: relative paths resolve from the file's directory and its
/// parents whatever the working directory; an empty directory is an error,
/// not a silent success.
#[test]
fn check_from_inside_experiments_and_run_of_an_empty_dir() {
    let root = env!("CARGO_MANIFEST_DIR");
    let o = std::process::Command::new(env!("CARGO_BIN_EXE_camsim"))
        .args(["check", "fig07-lsf-mtf.kdl"])
        .current_dir(std::path::Path::new(root).join("experiments"))
        .output()
        .unwrap();
    assert!(o.status.success(), "{}", String::from_utf8_lossy(&o.stderr));
    let empty = tempfile::tempdir().unwrap();
    let o = std::process::Command::new(env!("CARGO_BIN_EXE_camsim"))
        .arg("run")
        .arg(empty.path())
        .args(["--out"])
        .arg(empty.path().join("out"))
        .output()
        .unwrap();
    let err = String::from_utf8_lossy(&o.stderr);
    assert!(!o.status.success(), "run of an empty directory exited 0");
    assert!(err.contains("no experiment files"), "{err}");
}
