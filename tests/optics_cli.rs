//! `camsim lens …` commands: CSV with one header row, numbers that agree
//! with first-order optics, and the fit-rtf → RTF round trip.

use std::process::Command;

fn camsim(args: &[&str]) -> (bool, String, String) {
    let out = Command::new(env!("CARGO_BIN_EXE_camsim"))
        .args(args)
        .output()
        .unwrap();
    (
        out.status.success(),
        String::from_utf8_lossy(&out.stdout).into_owned(),
        String::from_utf8_lossy(&out.stderr).into_owned(),
    )
}

fn rows(csv: &str) -> (Vec<String>, Vec<Vec<f64>>) {
    let mut l = csv.lines();
    let header = l.next().unwrap().split(',').map(String::from).collect();
    let rows = l
        .map(|r| r.split(',').map(|x| x.parse().unwrap()).collect())
        .collect();
    (header, rows)
}

/// Tessar (Zemax sample): f = 100 mm, f/5.45 by its metadata; paraxial
/// values agree within 0.2 %, the traced working f-number within 2 %.
#[test]
fn optics_cli_lens_info_and_esf() {
    let (ok, out, err) = camsim(&["lens", "info", "lenses/prescriptions/tessar-zemax.json"]);
    assert!(ok, "{err}");
    let (h, r) = rows(&out);
    assert_eq!(h[0], "focal_length_mm");
    assert_eq!(r.len(), 1);
    assert!((r[0][0] / 100.0 - 1.0).abs() < 2e-3, "f = {}", r[0][0]);
    assert!((r[0][1] / 5.45 - 1.0).abs() < 2e-3, "N = {}", r[0][1]);
    assert!(
        (r[0][2] / r[0][1] - 1.0).abs() < 0.02,
        "working N = {}",
        r[0][2]
    );

    let (ok, out, err) = camsim(&[
        "lens",
        "esf",
        "lenses/prescriptions/tessar-zemax.json",
        "--object-distance-m",
        "1.3",
    ]);
    assert!(ok, "{err}");
    let (h, r) = rows(&out);
    assert_eq!(h, ["position_um", "esf", "lsf"]);
    // Monotone up to the quadrature granularity of the 128×128 pupil grid.
    assert!(
        r.windows(2).all(|w| w[1][1] >= w[0][1] - 2e-3),
        "ESF must not decrease"
    );
    assert!(r[0][1] < 0.01 && r.last().unwrap()[1] > 0.99);

    let (ok, _, err) = camsim(&["lens", "info", "lenses/prescriptions/nope.json"]);
    assert!(!ok && err.contains("nope.json"), "{err}");
}

/// fit-rtf writes an RTF that `lens info` reads back with the same focal length.
#[test]
fn optics_cli_fit_rtf_round_trip() {
    let dir = tempfile::tempdir().unwrap();
    let out_path = dir.path().join("tessar-rtf.json");
    let p = out_path.to_str().unwrap();
    let (ok, out, err) = camsim(&[
        "lens",
        "fit-rtf",
        "lenses/prescriptions/tessar-zemax.json",
        "--degree",
        "3",
        "--out",
        p,
    ]);
    assert!(ok, "{err}");
    let (h, r) = rows(
        &out.lines()
            .map(|l| {
                l.split(',')
                    .enumerate()
                    .map(|(i, x)| if i == 1 { "0" } else { x })
                    .collect::<Vec<_>>()
                    .join(",")
            })
            .collect::<Vec<_>>()
            .join("\n"),
    );
    assert_eq!(h[5], "condition_number");
    assert_eq!(r.len(), 5, "outx outy outdx outdy outdz");
    // The validation summary on stderr: RI within 0.01 of the prescription
    // (tests/optics_rtf_fit.rs: 0.004 for this lens at every degree).
    let ri_err: f64 = err
        .split("max |error| ")
        .nth(1)
        .and_then(|t| t.split_whitespace().next())
        .and_then(|t| t.parse().ok())
        .unwrap_or_else(|| panic!("no validation summary: {err}"));
    assert!(ri_err < 0.01, "{err}");
    assert!(err.contains("geometric ESF RMSE"), "{err}");
    assert!(r.iter().all(|row| row[5].is_finite() && row[6].is_finite()));
    let (ok, out, err) = camsim(&["lens", "info", p]);
    assert!(ok, "{err}");
    let (_, r) = rows(&out);
    // Focal length from output angles of a 5 %-field film point: within 1 %.
    assert!(
        (r[0][0] / 100.086 - 1.0).abs() < 0.01,
        "RTF focal length {}",
        r[0][0]
    );
}

/// `lens info --film-distance-mm` reports where a film distance focuses. For
/// the paper's Pixel 4a RTF the beam vergence follows Newton's relation
/// v ≈ Δ/f² (Δ = film distance − infinity film distance, f from the same
/// output) within 10 % (first order; the RTF's spherical aberration moves
/// the best-fit focus by ≈6 % at 5 1/m). The paper's 0.465136 mm lies
/// 15 µm *inside* the infinity film distance: focus beyond infinity
/// (negative vergence), not a finite focus distance.
#[test]
fn optics_cli_lens_info_focus_of_film_distance() {
    let p4a = "lenses/rtf/pixel4a-rearcamera-ellipse-raytransfer.json";
    let info = |d: Option<&str>| {
        let mut args = vec!["lens", "info", p4a];
        if let Some(d) = d {
            args.extend(["--film-distance-mm", d]);
        }
        let (ok, out, err) = camsim(&args);
        assert!(ok, "{err}");
        let (h, r) = rows(&out);
        assert_eq!(h[6], "film_distance_mm");
        assert_eq!(h[7], "beam_vergence_per_m");
        r[0].clone()
    };
    let inf = info(None);
    let (f_mm, d_inf) = (inf[0], inf[5]);
    assert!(inf[7].abs() < 0.05, "vergence at infinity focus {}", inf[7]);
    for d in ["0.465136", "0.57624"] {
        let r = info(Some(d));
        let newton = (r[6] - d_inf) / (f_mm * f_mm) * 1e3; // 1/m
        println!(
            "Pixel 4a RTF, film {d} mm: vergence {:.3} 1/m (Newton {newton:.3}); infinity film {d_inf:.5} mm",
            r[7]
        );
        assert!(
            (r[7] / newton - 1.0).abs() < 0.1,
            "vergence {} vs {newton}",
            r[7]
        );
    }
    assert!(info(Some("0.465136"))[7] < -0.5);
}

/// The fit's sampling flags: bad values are one-line errors naming the flag
/// and leave no RTF file; `--axis-weight` and `--sampling input-plane` reach
/// the fit (each changes the written polynomials).
#[test]
fn optics_cli_fit_rtf_sampling_flags() {
    let dir = tempfile::tempdir().unwrap();
    let lens = "lenses/prescriptions/tessar-zemax.json";
    let fit = |name: &str, extra: &[&str]| {
        let p = dir.path().join(name);
        let mut args = vec![
            "lens",
            "fit-rtf",
            lens,
            "--degree",
            "3",
            "--out",
            p.to_str().unwrap(),
        ];
        args.extend(extra);
        let (ok, _, err) = camsim(&args);
        (ok, err, p)
    };
    for (extra, expect) in [
        (&["--axis-weight", "0"][..], "axis weight"),
        (&["--axis-weight", "NaN"][..], "axis weight"),
        (
            &["--focus-distances-f", "inf,abc"][..],
            "--focus-distances-f",
        ),
        (&["--focus-distances-f", "0.5"][..], "focal length"),
        (&["--sampling", "grid"][..], "--sampling"),
    ] {
        let (ok, err, p) = fit("bad.json", extra);
        assert!(!ok, "{extra:?} accepted");
        assert!(err.contains(expect), "{extra:?}: {err}");
        assert!(!err.contains("panicked"), "{err}");
        assert!(!p.exists(), "{extra:?} wrote {}", p.display());
    }
    let read = |p: &std::path::Path| std::fs::read_to_string(p).unwrap();
    let (ok, err, base) = fit("base.json", &[]);
    assert!(ok, "{err}");
    for (name, extra) in [
        ("axis.json", &["--axis-weight", "64"][..]),
        ("plane.json", &["--sampling", "input-plane"][..]),
        ("inf.json", &["--focus-distances-f", "inf"][..]),
    ] {
        let (ok, err, p) = fit(name, extra);
        assert!(ok, "{extra:?}: {err}");
        assert_ne!(read(&p), read(&base), "{extra:?} did not change the fit");
    }
}

/// Same prescription and options → byte-identical RTF for any thread count
/// (the traced bundles are collected in order; the least squares is serial).
#[test]
fn optics_cli_fit_rtf_is_thread_count_independent() {
    let dir = tempfile::tempdir().unwrap();
    let fit = |threads: &str| {
        let p = dir.path().join(format!("t{threads}.json"));
        let o = Command::new(env!("CARGO_BIN_EXE_camsim"))
            .args([
                "lens",
                "fit-rtf",
                "lenses/prescriptions/dgauss.28deg-zemax.json",
                "--degree",
                "4",
                "--out",
                p.to_str().unwrap(),
            ])
            .env("RAYON_NUM_THREADS", threads)
            .output()
            .unwrap();
        assert!(o.status.success(), "{}", String::from_utf8_lossy(&o.stderr));
        std::fs::read(p).unwrap()
    };
    assert!(fit("1") == fit("3"), "RTF differs between 1 and 3 threads");
}
