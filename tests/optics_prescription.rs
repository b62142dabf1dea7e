//! Lens prescriptions: parsing, paraxial optics against closed forms, the
//! sequential trace in stiff cases (TIR, rays grazing the stop), and the
//! pupil sampling (flat field without rings at the pupil-bound buckets).

use camsim::optics::Camera;
use camsim::optics::prescription::{Blocked, Prescription, PrescriptionCamera};
use glam::{DVec2, DVec3};
use std::path::Path;

fn write_tmp(name: &str, text: &str) -> (tempfile::TempDir, std::path::PathBuf) {
    let dir = tempfile::tempdir().unwrap();
    let p = dir.path().join(name);
    std::fs::write(&p, text).unwrap();
    (dir, p)
}

/// Deterministic uniform numbers (splitmix64).
struct Rng(u64);
impl Rng {
    fn next(&mut self) -> f64 {
        self.0 = self.0.wrapping_add(0x9E37_79B9_7F4A_7C15);
        let mut z = self.0;
        z = (z ^ (z >> 30)).wrapping_mul(0xBF58_476D_1CE4_E5B9);
        z = (z ^ (z >> 27)).wrapping_mul(0x94D0_49BB_1331_11EB);
        ((z ^ (z >> 31)) >> 11) as f64 / (1u64 << 53) as f64
    }
}

#[test]
fn optics_thick_singlet_matches_lensmaker_equation() {
    let (n, r1, r2, d) = (1.5168, 50.0, -80.0, 6.0);
    let json = format!(
        r#"{{"name":"singlet","surfaces":[
        {{"radius":{r1},"thickness":{d},"ior":{n},"semi_aperture":10}},
        {{"radius":{r2},"thickness":0,"ior":1,"semi_aperture":10}}]}}"#
    );
    let (_d, p) = write_tmp("singlet.json", &json);
    let lens = Prescription::load(&p).unwrap();
    let px = lens.paraxial(550.0).unwrap();
    let inv_f = (n - 1.0) * (1.0 / r1 - 1.0 / r2 + (n - 1.0) * d / (n * r1 * r2));
    let f = 1.0 / inv_f;
    // Paraxial trace is exact first-order optics: agreement to rounding.
    assert!(
        (px.effective_focal_length_mm / f - 1.0).abs() < 1e-12,
        "{} vs {f}",
        px.effective_focal_length_mm
    );
    // Back focal distance: f·(1 − (n−1)·d/(n·R1)).
    let bfd = f * (1.0 - (n - 1.0) * d / (n * r1));
    assert!((px.back_focal_distance_mm / bfd - 1.0).abs() < 1e-12);
}

#[test]
fn optics_film_distance_focuses_near_object() {
    let lens =
        Prescription::load(Path::new("lenses/prescriptions/dgauss.28deg-zemax.json")).unwrap();
    let z_obj_m = 1.5; // from the film
    let cam = PrescriptionCamera::focused(lens, z_obj_m, 550.0).unwrap();
    // Near-axis rays from the film centre must cross the axis at the object.
    let mut zs = Vec::new();
    for &(ux, uy) in &[(0.5, 0.51), (0.51, 0.5), (0.49, 0.5), (0.5, 0.49)] {
        let r = cam
            .sample_ray(DVec2::ZERO, DVec2::new(ux, uy), 550.0)
            .unwrap();
        // Signed: the ray must reach the axis *ahead* (t > 0), not diverge.
        let (o, d) = (
            DVec2::new(r.origin.x, r.origin.y),
            DVec2::new(r.direction.x, r.direction.y),
        );
        let t = -o.dot(d) / d.length_squared();
        assert!(t > 0.0, "rays diverge");
        zs.push(r.origin.z + t * r.direction.z);
    }
    for z in zs {
        // Rays 1 % of the pupil off axis: spherical aberration shifts the
        // crossing by far less than 0.5 % of the distance.
        assert!(
            (z / z_obj_m - 1.0).abs() < 5e-3,
            "axis crossing at {z} m, want {z_obj_m} m"
        );
    }
}

#[test]
fn optics_dat_and_json_prescriptions_agree() {
    let a = Prescription::load(Path::new("lenses/prescriptions/dgauss.22deg.50.0mm.dat")).unwrap();
    let b = Prescription::load(Path::new("lenses/prescriptions/dgauss.22deg.50.0mm.json")).unwrap();
    assert_eq!(a.surfaces.len(), b.surfaces.len());
    for (s, t) in a.surfaces.iter().zip(&b.surfaces) {
        // The JSON holds single-precision values.
        assert!(
            (s.radius_mm - t.radius_mm).abs() < 1e-5
                && (s.thickness_mm - t.thickness_mm).abs() < 1e-5
        );
        assert!(
            (s.ior.at(550.0) - t.ior.at(550.0)).abs() < 1e-6
                && (s.semi_aperture_mm - t.semi_aperture_mm).abs() < 1e-5
        );
        assert_eq!(s.is_stop, t.is_stop);
    }
}

#[test]
fn optics_prescription_bad_input_errors_name_the_file() {
    let e = Prescription::load(Path::new("lenses/prescriptions/missing.json"))
        .unwrap_err()
        .to_string();
    assert!(e.contains("missing.json"), "{e}");
    let (_d, p) = write_tmp("bad.json", "{\"surfaces\": [ {\"radius\": 1, }");
    let e = Prescription::load(&p).unwrap_err().to_string();
    assert!(e.contains("bad.json:1:"), "{e}");
    let (_d, p) = write_tmp("bad.dat", "# c\n50\n1 2 3\n");
    let e = Prescription::load(&p).unwrap_err().to_string();
    assert!(e.contains("bad.dat:3:") && e.contains("found 3"), "{e}");
    let (_d, p) = write_tmp(
        "nan.json",
        r#"{"surfaces":[{"radius":1,"thickness":1,"ior":1.5,"semi_aperture":0}]}"#,
    );
    assert!(
        Prescription::load(&p)
            .unwrap_err()
            .to_string()
            .contains("semi-aperture")
    );
    let (_d, p) = write_tmp(
        "asph.json",
        r#"{"surfaces":[{"radius":10,"thickness":1,"ior":1.5,"semi_aperture":2,"aspheric_coefficients":[0.1]}]}"#,
    );
    assert!(
        Prescription::load(&p)
            .unwrap_err()
            .to_string()
            .contains("not supported")
    );
}

/// Per-wavelength indices make the lens dispersive and move the focus.
#[test]
fn optics_per_wavelength_ior_is_dispersive() {
    let json = r#"{"name":"d","wave":[400,700],"surfaces":[
        {"radius":50,"thickness":5,"ior":[1.53,1.51],"semi_aperture":10},
        {"radius":-50,"thickness":0,"ior":1,"semi_aperture":10}]}"#;
    let (_d, p) = write_tmp("disp.json", json);
    let lens = Prescription::load(&p).unwrap();
    assert!(lens.is_dispersive());
    let fb = lens.paraxial(400.0).unwrap().effective_focal_length_mm;
    let fr = lens.paraxial(700.0).unwrap().effective_focal_length_mm;
    assert!(fb < fr, "blue focuses shorter: {fb} vs {fr}");
    let fixed = Prescription::load(Path::new("lenses/prescriptions/tessar-zemax.json")).unwrap();
    assert!(!fixed.is_dispersive());
}

/// Total internal reflection: film immersed in glass, flat exit face.
#[test]
fn optics_total_internal_reflection_blocks() {
    let json = r#"{"surfaces":[
        {"radius":1e9,"thickness":5,"ior":1.5,"semi_aperture":100},
        {"radius":1e9,"thickness":0,"ior":1.5,"semi_aperture":100}]}"#;
    let (_d, p) = write_tmp("tir.json", json);
    let lens = Prescription::load(&p).unwrap();
    let o = DVec3::new(0.0, 0.0, -1.0);
    // 45° in glass: sin θt = 1.5·sin 45° = 1.06 > 1.
    let steep = DVec3::new(1.0, 0.0, 1.0);
    assert_eq!(lens.trace_to_scene(o, steep, 550.0), Err(Blocked::Tir(0)));
    // 30°: refracts to asin(0.75) (Snell).
    let (_, d) = lens
        .trace_to_scene(o, DVec3::new(0.5, 0.0, 0.75f64.sqrt()), 550.0)
        .unwrap();
    // The 1e9 mm "flat" face tilts the normal by ≤ 1e-8 rad at these heights.
    assert!((d.x - 0.75).abs() < 1e-7, "{d}");
    // Just below the critical angle still passes; just above is TIR.
    let crit = (1.0f64 / 1.5).asin();
    let dir = |a: f64| DVec3::new(a.sin(), 0.0, a.cos());
    assert!(lens.trace_to_scene(o, dir(crit - 1e-6), 550.0).is_ok());
    assert_eq!(
        lens.trace_to_scene(o, dir(crit + 1e-6), 550.0),
        Err(Blocked::Tir(0))
    );
}

/// Rays grazing the aperture stop: bisection on the pupil height finds the
/// rim; inside passes with finite output, outside is blocked *by the stop*.
#[test]
fn optics_rays_grazing_the_stop() {
    let lens = Prescription::load(Path::new("lenses/prescriptions/tessar-zemax.json")).unwrap();
    let px = lens.paraxial(550.0).unwrap();
    let stop = lens.surfaces.iter().position(|s| s.is_stop).unwrap();
    assert_eq!(px.stop_index, stop);
    let d = px.back_focal_distance_mm;
    let o = DVec3::new(0.0, 0.0, -d);
    let through = |h: f64| lens.trace_to_scene(o, DVec3::new(h, 0.0, d), 550.0);
    let (mut lo, mut hi) = (0.0, 30.0);
    assert!(through(lo).is_ok() && through(hi).is_err());
    for _ in 0..200 {
        let mid = 0.5 * (lo + hi);
        if through(mid).is_ok() {
            lo = mid
        } else {
            hi = mid
        }
    }
    let (p, dir) = through(lo).unwrap();
    assert!(p.is_finite() && dir.is_finite() && (dir.length() - 1.0).abs() < 1e-12);
    assert_eq!(
        through(hi),
        Err(Blocked::Aperture(stop)),
        "on-axis beam is limited by the stop"
    );
}

/// On-axis irradiance of the traced lens equals π/(4N²) with the paraxial
/// f-number: the double Gauss nearly satisfies the sine condition, so the
/// real-ray cone matches the paraxial one to ≈1 %; 2 % tolerance.
#[test]
fn optics_prescription_on_axis_irradiance_matches_f_number() {
    let lens =
        Prescription::load(Path::new("lenses/prescriptions/dgauss.28deg-zemax.json")).unwrap();
    let n = lens.paraxial(550.0).unwrap().f_number;
    let cam = PrescriptionCamera::focused(lens, f64::INFINITY, 550.0).unwrap();
    let e = camsim::optics::analysis::irradiance_factor(&cam, DVec2::ZERO, 550.0, 128);
    let ideal = std::f64::consts::PI / (4.0 * n * n);
    assert!(
        (e / ideal - 1.0).abs() < 0.02,
        "E/L = {e}, π/(4N²) = {ideal}"
    );
}

/// Flat field: pupil boxes change at 64 film-radius buckets. The estimator
/// is unbiased in every bucket, so irradiance just below and just above each
/// bucket edge must agree within Monte Carlo noise (|z| < 4.5 for 63 edges:
/// false-alarm probability < 1e-3 overall). A non-conservative box would
/// drop light on one side and show up as a ring.
#[test]
fn optics_flat_field_has_no_rings() {
    let lens =
        Prescription::load(Path::new("lenses/prescriptions/dgauss.28deg-zemax.json")).unwrap();
    let cam = PrescriptionCamera::focused(lens, f64::INFINITY, 550.0).unwrap();
    let rmax = cam.max_film_radius_mm;
    let mut rng = Rng(7);
    let mut est = |r_mm: f64| {
        let n = 6000;
        let (mut s, mut s2) = (0.0, 0.0);
        for _ in 0..n {
            let u = DVec2::new(rng.next(), rng.next());
            let w = cam
                .sample_ray(DVec2::new(0.0, r_mm * 1e-3), u, 550.0)
                .map_or(0.0, |r| r.weight);
            s += w;
            s2 += w * w;
        }
        let m = s / n as f64;
        (m, ((s2 / n as f64 - m * m) / n as f64).sqrt())
    };
    let mut worst: f64 = 0.0;
    for k in 1..60 {
        let edge = rmax * k as f64 / 64.0;
        let (a, sa) = est(edge - 1e-6);
        let (b, sb) = est(edge + 1e-6);
        if sa + sb == 0.0 {
            continue;
        }
        let z = (a - b) / (sa * sa + sb * sb).sqrt();
        worst = worst.max(z.abs());
    }
    assert!(worst < 4.5, "largest jump at a bucket edge: {worst} σ");
}

/// Zemax samples with the stop at a lens vertex (zero spacing) trace
/// sequentially; their relative illumination follows Zemax in the
/// unvignetted inner field (≤ 9 mm: measured deviation ≤ 0.012; the 0.02
/// bound leaves room for the 64×64 quadrature, < 0.003).
#[test]
fn optics_zemax_samples_with_stop_at_vertex_trace() {
    for (lens, reference) in [
        ("cooke40deg-zemax", "cooke40deg"),
        ("petzval-zemax", "petzval"),
    ] {
        let p =
            Prescription::load(Path::new(&format!("lenses/prescriptions/{lens}.json"))).unwrap();
        let cam = PrescriptionCamera::focused(p, f64::INFINITY, 550.0).unwrap();
        let zemax: Vec<(f64, f64)> = std::fs::read_to_string(format!(
            "lenses/zemax-reference/{reference}-relativeillum-zemax.csv"
        ))
        .unwrap()
        .lines()
        .filter(|l| !l.trim().is_empty())
        .map(|l| {
            let v: Vec<f64> = l.split(',').map(|x| x.trim().parse().unwrap()).collect();
            (v[0], v[1])
        })
        .filter(|p| p.0 > 0.0 && p.0 <= 9.0)
        .collect();
        let heights: Vec<f64> = zemax.iter().map(|p| p.0).collect();
        let ri =
            camsim::optics::analysis::relative_illumination(&cam, &heights, 550.0, 64).unwrap();
        // Zemax's own table is normalised to its maximum (Petzval: 0.9977 on axis).
        let z0 = if reference == "petzval" { 0.99769 } else { 1.0 };
        for ((h, z), v) in zemax.iter().zip(ri) {
            assert!(
                (v - z / z0).abs() < 0.02,
                "{lens} at {h} mm: {v} vs Zemax {}",
                z / z0
            );
        }
    }
}

/// The reversed prescription traces a scene-side ray back along the path it
/// came: random film rays through both Zemax samples return to their film
/// point (the path is reversible; only rounding remains), and the reverse
/// of the reverse is the lens itself.
#[test]
fn optics_reversed_prescription_retraces_rays() {
    for file in [
        "lenses/prescriptions/dgauss.28deg-zemax.json",
        "lenses/prescriptions/tessar-zemax.json",
    ] {
        let lens = Prescription::load(Path::new(file)).unwrap();
        let rev = lens.reversed().unwrap();
        // (up to the rear surface's distance to the film, which the trace
        // does not use and the reversal cannot know)
        let mut same = lens.surfaces.clone();
        same.last_mut().unwrap().thickness_mm = 0.0;
        assert_eq!(rev.reversed().unwrap().surfaces, same);
        let track = lens.total_track_mm();
        let bfd = lens.paraxial(550.0).unwrap().back_focal_distance_mm;
        let mut rng = Rng(7);
        let mut n = 0;
        for _ in 0..2000 {
            let o = DVec3::new(0.0, 20.0 * rng.next(), -bfd);
            let d = DVec3::new(0.4 * rng.next() - 0.2, 0.4 * rng.next() - 0.2, 1.0);
            let Ok((p, dir)) = lens.trace_to_scene(o, d, 550.0) else {
                continue;
            };
            // Start well in front of the lens, travelling back.
            let p = p + dir * 20.0;
            let (q, dq) = rev
                .trace_to_scene(
                    DVec3::new(p.x, p.y, track - p.z),
                    DVec3::new(-dir.x, -dir.y, dir.z),
                    550.0,
                )
                .unwrap();
            let t = (-bfd - (track - q.z)) / -dq.z;
            let back = DVec2::new(q.x + dq.x * t, q.y + dq.y * t);
            assert!(
                (back - DVec2::new(o.x, o.y)).length() < 1e-9,
                "{file}: {back}"
            );
            n += 1;
        }
        assert!(n > 200, "{file}: only {n} rays passed");
    }
}
