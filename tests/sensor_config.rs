//! Sensor definition files: the shipped sensors parse, carry Table I, and the
//! nominal-QE option reproduces the paper's corrected filters.

use camsim::sensor::{Exposure, SensorConfig};
use std::path::Path;

fn root() -> &'static Path {
    Path::new(env!("CARGO_MANIFEST_DIR"))
}

#[test]
fn imx363_has_table_one_numbers() {
    let c = SensorConfig::load(&root().join("sensors/imx363.kdl")).unwrap();
    assert_eq!((c.cols, c.rows), (Some(4032), Some(3024)));
    assert!((c.pixel_size_m - 1.4e-6).abs() < 1e-15);
    assert_eq!(c.bit_depth, 10);
    assert_eq!(c.black_level_dv, 64.0);
    assert_eq!(c.white_level_dv(), 1023.0);
    assert!((c.conversion_gain_dv_per_e() - 0.1707).abs() < 1e-12);
    // 0.1707 DV/e⁻ × 0.4591 V / 1024 = 76.53 µV/e⁻ (ISETCam: 76.51 µV/e⁻)
    assert!((c.conversion_gain_v_per_e() * 1e6 - 76.53).abs() < 0.01);
    // Table I read noise 0.226 mV ≈ 2.95 e⁻ (data/README.md)
    assert!(
        (c.read_noise_e() - 2.95).abs() < 0.01,
        "{}",
        c.read_noise_e()
    );
    assert!((c.prnu - 0.0054).abs() < 1e-12);
    assert!((c.dsnu_v - 0.038e-3).abs() < 1e-15);
    assert!((c.dark_voltage_v_per_s - 0.02e-3).abs() < 1e-15);
    assert!(
        (c.full_well_e() - 5998.8).abs() < 0.5,
        "{}",
        c.full_well_e()
    );
    assert_eq!(c.cfa.channels, ["r", "g", "b"]);
}

#[test]
fn generic_sensor_parses() {
    let c = SensorConfig::load(&root().join("sensors/generic.kdl")).unwrap();
    assert_eq!(c.bit_depth, 12);
    assert!(
        matches!(c.exposure, Exposure::Auto { level, percentile } if (level - 0.95).abs() < 1e-12 && percentile == 99.9)
    );
    assert!((c.conversion_gain_v_per_e() - 100e-6).abs() < 1e-15);
}

/// data/README.md: p4a corrected filters = (nominal QE × IR cut) · M. Evaluated at
/// the 10 nm samples of the corrected file (where the 1 nm IR-cut table has exact
/// samples), the only differences are the 4-decimal rounding of M (≤ 5e-5 × the
/// nominal QE) and the rounding of the stored curves; we accept 1e-4 absolute.
#[test]
fn nominal_qe_times_ir_times_m_matches_corrected_filters() {
    let text = std::fs::read_to_string(root().join("sensors/imx363-nominal.kdl")).unwrap()
        + "qe-matrix {\n row 0.5636 0.0807 0.0069\n row 0 0.5917 0\n row 0 0.2470 0.7098\n}\n";
    let nominal = SensorConfig::parse(&text, &root().join("sensors/imx363-nominal.kdl")).unwrap();
    assert!(
        SensorConfig::load(&root().join("sensors/imx363-nominal.kdl"))
            .unwrap()
            .qe_matrix
            .is_none()
    );
    let corrected = SensorConfig::load(&root().join("sensors/imx363.kdl")).unwrap();
    let mut peak = [0.0f64; 3];
    let mut worst = [0.0f64; 3];
    for l in (400..=700).step_by(10) {
        let a = nominal.effective_qe(l as f64);
        let b = corrected.effective_qe(l as f64);
        for c in 0..3 {
            peak[c] = peak[c].max(b[c]);
            worst[c] = worst[c].max((a[c] - b[c]).abs());
        }
    }
    for c in 0..3 {
        eprintln!(
            "channel {c}: max |diff| {:.5} (peak {:.4})",
            worst[c], peak[c]
        );
        assert!(
            worst[c] < 1e-4,
            "channel {c}: max |diff| {} vs peak {}",
            worst[c],
            peak[c]
        );
    }
}

#[test]
fn errors_point_at_the_file() {
    let dir = tempfile::tempdir().unwrap();
    let p = dir.path().join("bad.kdl");
    std::fs::write(&p, "bit-depth 10\nwell-capacity 6000\n").unwrap();
    let e = SensorConfig::load(&p).unwrap_err().to_string();
    assert!(e.contains("bad.kdl:2:1"), "{e}");
    assert!(e.contains("well-capacity-e"), "{e}");
    let e = SensorConfig::load(&dir.path().join("missing.kdl"))
        .unwrap_err()
        .to_string();
    assert!(e.contains("missing.kdl"), "{e}");
}
