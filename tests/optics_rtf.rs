//! RTF camera: the paper's Pixel 4a RTF against the Zemax relative
//! illumination (acceptance), pass/no-pass edge cases, file errors.

mod common;

use camsim::optics::Camera;
use camsim::optics::rtf::{Rtf, RtfCamera};
use glam::{DVec2, DVec3};
use std::path::Path;

const P4A: &str = "lenses/rtf/pixel4a-rearcamera-ellipse-raytransfer.json";

fn zemax_p4a() -> Vec<(f64, f64)> {
    common::numeric_rows("lenses/zemax-reference/zemax_p4a_relative_illumination.csv")
        .into_iter()
        .map(|v| (v[0], v[1]))
        .collect()
}

fn interp(t: &[(f64, f64)], x: f64) -> f64 {
    let k = t.partition_point(|p| p.0 <= x).clamp(1, t.len() - 1);
    let (a, b) = (t[k - 1], t[k]);
    a.1 + (b.1 - a.1) * (x - a.0) / (b.0 - a.0)
}

/// Acceptance: `camsim lens ri` on the Pixel 4a RTF at 0.465136 mm is within
/// 0.02 of Zemax at every field height 0–3.2 mm. (The known model error of
/// this file is ≈0.012; the 200×200 midpoint quadrature adds < 0.002.)
#[test]
fn optics_pixel4a_rtf_relative_illumination_matches_zemax() {
    let out = std::process::Command::new(env!("CARGO_BIN_EXE_camsim"))
        .args(["lens", "ri", P4A, "--film-distance-mm", "0.465136"])
        .output()
        .unwrap();
    assert!(
        out.status.success(),
        "{}",
        String::from_utf8_lossy(&out.stderr)
    );
    let text = String::from_utf8(out.stdout).unwrap();
    let mut lines = text.lines();
    assert_eq!(lines.next(), Some("field_height_mm,relative_illumination"));
    let zemax = zemax_p4a();
    let mut worst: f64 = 0.0;
    let mut n = 0;
    for l in lines {
        let v: Vec<f64> = l.split(',').map(|x| x.parse().unwrap()).collect();
        if v[0] <= 3.2 + 1e-9 {
            worst = worst.max((v[1] - interp(&zemax, v[0])).abs());
            n += 1;
        }
    }
    println!("pixel4a RTF vs Zemax RI: max |error| = {worst:.4} over {n} field heights (0–3.2 mm)");
    assert!(n >= 30 && worst < 0.02, "max |RI error| {worst}");
}

/// Beyond the last ellipse (3.5 mm) every ray is blocked: vignetted, not
/// extrapolated; just inside, light passes.
#[test]
fn optics_rtf_fields_beyond_last_ellipse_are_vignetted() {
    let rtf = Rtf::load(Path::new(P4A)).unwrap();
    let cam = RtfCamera::new(rtf.clone(), 0.465136).unwrap();
    let count = |h_mm: f64| {
        let n = 40;
        (0..n * n)
            .filter(|k| {
                let u = DVec2::new(
                    (k % n) as f64 / n as f64 + 0.5 / n as f64,
                    (k / n) as f64 / n as f64 + 0.5 / n as f64,
                );
                cam.sample_ray(DVec2::new(h_mm * 1e-3 * 0.6, h_mm * 1e-3 * 0.8), u, 550.0)
                    .is_some()
            })
            .count()
    };
    assert!(count(3.4) > 0);
    assert_eq!(count(3.6), 0);
    assert_eq!(count(10.0), 0);
    // Direct transfer: a ray at input radius just beyond 3.5 mm is blocked even
    // though the polynomial could be evaluated there.
    let w = &rtf.waves[0];
    let d = DVec3::new(0.0, -0.65, 1.0).normalize(); // aims at the ellipse centre (y ≈ 1.8 mm)
    assert!(rtf.transfer(w, 0.0, 3.49, d).is_some());
    assert!(rtf.transfer(w, 0.0, 3.51, d).is_none());
}

/// Output rays: finite, unit, pointing into the scene, origin on the output
/// plane z = z_in + outz (module docs), upright image (a film point on +x
/// sends its chief rays towards +x in the scene).
#[test]
fn optics_rtf_rays_are_well_formed() {
    let rtf = Rtf::load(Path::new(P4A)).unwrap();
    let outz = rtf.output_plane_from_input_mm(&rtf.waves[0]);
    assert!((outz - 6.300158).abs() < 1e-5);
    let cam = RtfCamera::new(rtf, 0.465136).unwrap();
    let z_out_m = (cam.input_plane_z_mm() + outz) * 1e-3;
    let mut sum_dx = 0.0;
    for i in 0..20 {
        for j in 0..20 {
            let u = DVec2::new((i as f64 + 0.5) / 20.0, (j as f64 + 0.5) / 20.0);
            if let Some(r) = cam.sample_ray(DVec2::new(2.0e-3, 0.0), u, 550.0) {
                assert!(
                    r.origin.is_finite()
                        && r.direction.is_finite()
                        && r.weight.is_finite()
                        && r.weight > 0.0
                );
                assert!((r.direction.length() - 1.0).abs() < 1e-12 && r.direction.z > 0.0);
                assert!((r.origin.z - z_out_m).abs() < 1e-12);
                sum_dx += r.direction.x;
            }
        }
    }
    assert!(sum_dx > 0.0, "image must be upright");
    assert!(!cam.is_dispersive());
}

#[test]
fn optics_rtf_bad_files_are_reported() {
    let dir = tempfile::tempdir().unwrap();
    let p = dir.path().join("broken.json");
    let mut v: serde_json::Value =
        serde_json::from_str(&std::fs::read_to_string(P4A).unwrap()).unwrap();
    v["polynomials"][0]["passnopass"]
        .as_object_mut()
        .unwrap()
        .remove("radiiX");
    std::fs::write(&p, v.to_string()).unwrap();
    let e = Rtf::load(&p).unwrap_err().to_string();
    assert!(e.contains("broken.json") && e.contains("radiiX"), "{e}");
    v["polynomials"][0]["passnopass"]["method"] = "magic".into();
    std::fs::write(&p, v.to_string()).unwrap();
    assert!(Rtf::load(&p).unwrap_err().to_string().contains("magic"));
    std::fs::write(&p, "{ \"polynomials\": [ }").unwrap();
    assert!(
        Rtf::load(&p)
            .unwrap_err()
            .to_string()
            .contains("broken.json:1:")
    );
    assert!(RtfCamera::new(Rtf::load(Path::new(P4A)).unwrap(), f64::NAN).is_err());
}

/// Circles variant: a single circle of radius R at distance L is a circular
/// pupil; the on-axis irradiance is then exactly that of a disk of radius R
/// at distance h = z_in + L: E/L = π R²/(h² + R²).
#[test]
fn optics_rtf_circles_variant_on_axis_irradiance() {
    let mut v: serde_json::Value =
        serde_json::from_str(&std::fs::read_to_string(P4A).unwrap()).unwrap();
    v["polynomials"][0]["passnopass"] = serde_json::json!({
        "method": "circles", "circleRadii": [0.4], "circleSensitivities": [0.0], "circlePlaneZ": 2.5
    });
    let rtf = Rtf::from_value(&v, Path::new("circles.json")).unwrap();
    let cam = RtfCamera::new(rtf, 0.465136).unwrap();
    let e = camsim::optics::analysis::irradiance_factor(&cam, DVec2::ZERO, 550.0, 300);
    let h = cam.input_plane_z_mm() + 2.5;
    let exact = std::f64::consts::PI * 0.16 / (h * h + 0.16);
    // 300×300 midpoint grid on a box with a circular edge: < 0.3 % error.
    assert!((e / exact - 1.0).abs() < 3e-3, "{e} vs {exact}");
}
