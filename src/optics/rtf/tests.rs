//! Unit tests of the RTF's evaluation: polynomials, pass/no-pass regions,
//! the rotation into and out of the input point's frame, the output plane,
//! the camera's sampling box and the JSON file's checks. Expected values are
//! worked out by hand from the definitions in the module docs (or, for the
//! sampling box, the closed-form projected solid angle of a disk).

use super::*;
use crate::optics::analysis::irradiance_factor;

fn poly(terms: &[([u32; 3], f64)]) -> Poly {
    Poly {
        terms: terms.iter().map(|t| t.0).collect(),
        coeff: terms.iter().map(|t| t.1).collect(),
    }
}

fn close(a: f64, b: f64, tol: f64) -> bool {
    (a - b).abs() <= tol
}

/// Ellipses at input radii 0, 1 and 3 mm (unevenly spaced, so the
/// interpolation weight differs from the radius).
fn ellipses() -> Ellipses {
    Ellipses {
        positions_mm: vec![0.0, 1.0, 3.0],
        radii_x_mm: vec![1.0, 1.5, 2.5],
        radii_y_mm: vec![0.5, 0.7, 1.1],
        centers_x_mm: vec![0.0, 0.2, 0.6],
        centers_y_mm: vec![1.0, 2.0, 4.0],
        plane_distance_mm: 2.0,
    }
}

/// Two circles: radius 1 centred on the axis, radius 0.8 at 0.5·r; inputs
/// beyond r = 2 mm blocked.
fn circles() -> Circles {
    Circles {
        radii_mm: vec![1.0, 0.8],
        sensitivities: vec![0.0, 0.5],
        plane_distance_mm: 2.0,
        max_input_radius_mm: Some(2.0),
    }
}

const M: f64 = 0.5; // magnification (outy ∝ r)
const Q: f64 = 0.01; // distortion (outy ∝ r²)
const B: f64 = 2.0; // lateral shift per unit lateral direction

/// A rotationally symmetric black box: the output point is
/// (M + Q·r)·r·p̂ + B·d⊥ and the direction is unchanged (outx = B·dx,
/// outy = M·r + Q·r² + B·dy, outdx = dx, outdy = dy), with everything
/// passing (one circle of 100 mm). Its output plane is 0.5 + 4 + 1.5 = 6 mm
/// beyond the input plane.
fn lens() -> Rtf {
    Rtf {
        name: "test lens".into(),
        description: String::new(),
        thickness_mm: 4.0,
        plane_offset_input_mm: 0.5,
        plane_offset_output_mm: 1.5,
        waves: vec![RtfWave {
            wavelength_nm: 550.0,
            outputs: [
                Some(poly(&[([0, 1, 0], B)])),
                Some(poly(&[([1, 0, 0], M), ([2, 0, 0], Q), ([0, 0, 1], B)])),
                None,
                Some(poly(&[([0, 1, 0], 1.0)])),
                Some(poly(&[([0, 0, 1], 1.0)])),
                None,
            ],
            pass: PassNoPass::Circles(Circles {
                radii_mm: vec![100.0],
                sensitivities: vec![0.0],
                plane_distance_mm: 2.0,
                max_input_radius_mm: None,
            }),
        }],
    }
}

#[test]
fn polynomial_is_the_sum_of_its_monomials() {
    let p = poly(&[([2, 0, 0], 1.5), ([0, 3, 0], -2.0), ([1, 1, 1], 0.25)]);
    assert_eq!(p.max_degree(), 3);
    let (r, dx, dy) = (1.3, -0.7, 0.4);
    let exact = 1.5 * r * r - 2.0 * dx * dx * dx + 0.25 * r * dx * dy;
    assert!(close(p.eval(r, dx, dy), exact, 1e-14));
    assert_eq!(poly(&[]).max_degree(), 0);
}

#[test]
fn ellipses_interpolate_linearly_between_positions() {
    let e = ellipses();
    // r = 1.5 lies a quarter of the way from 1 to 3.
    let got = e.at(1.5).unwrap();
    for (g, w) in got.iter().zip([0.3, 2.5, 1.75, 0.8]) {
        assert!(close(*g, w, 1e-14), "{got:?}");
    }
    // At a listed position: that ellipse, the last one included.
    assert_eq!(e.at(0.0).unwrap(), [0.0, 1.0, 1.0, 0.5]);
    assert_eq!(e.at(1.0).unwrap(), [0.2, 2.0, 1.5, 0.7]);
    assert_eq!(e.at(3.0).unwrap(), [0.6, 4.0, 2.5, 1.1]);
    // Beyond the last, below zero or NaN: no region (never extrapolated).
    assert!(e.at(3.0 + 1e-12).is_none());
    assert!(e.at(-1e-12).is_none());
    assert!(e.at(f64::NAN).is_none());
    let one = Ellipses {
        positions_mm: vec![2.0],
        radii_x_mm: vec![1.0],
        radii_y_mm: vec![0.5],
        centers_x_mm: vec![0.1],
        centers_y_mm: vec![2.0],
        plane_distance_mm: 1.0,
    };
    assert_eq!(one.at(0.5).unwrap(), [0.1, 2.0, 1.0, 0.5]);
    assert_eq!(one.at(2.0).unwrap(), [0.1, 2.0, 1.0, 0.5]);
    assert!(one.at(2.5).is_none());
}

#[test]
fn ellipse_pass_region_and_its_box() {
    let p = PassNoPass::Ellipses(ellipses());
    assert_eq!(p.plane_distance_mm(), 2.0);
    assert_eq!(p.max_radius_mm(), Some(3.0));
    // At r = 1.5 the ellipse is centred at (0.3, 2.5), semi-axes 1.75 × 0.8.
    assert!(p.passes(1.5, 0.3 + 1.74, 2.5));
    assert!(!p.passes(1.5, 0.3 + 1.76, 2.5));
    assert!(!p.passes(1.5, 0.3 - 1.76, 2.5));
    assert!(p.passes(1.5, 0.3, 2.5 + 0.79));
    assert!(!p.passes(1.5, 0.3, 2.5 - 0.81));
    assert!(!p.passes(3.5, 0.6, 4.0));
    let b = p.bbox(1.5).unwrap();
    for (g, w) in b.iter().zip([0.3 - 1.75, 0.3 + 1.75, 2.5 - 0.8, 2.5 + 0.8]) {
        assert!(close(*g, w, 1e-14), "{b:?}");
    }
    assert!(p.bbox(3.5).is_none());
    // Farthest any listed ellipse reaches: centre 4 + semi-axis 1.1 (radial);
    // with a wider last ellipse, 0.6 + 6 (tangential).
    assert!(close(p.reach(0.0), 5.1, 1e-14));
    let mut wide = ellipses();
    wide.radii_x_mm[2] = 6.0;
    wide.centers_x_mm[2] = -0.6;
    assert!(close(PassNoPass::Ellipses(wide).reach(0.0), 6.6, 1e-14));
}

#[test]
fn circle_pass_region_and_its_box() {
    let p = PassNoPass::Circles(circles());
    assert_eq!(p.plane_distance_mm(), 2.0);
    assert_eq!(p.max_radius_mm(), Some(2.0));
    // r = 1: circles centred at (0, 0) radius 1 and (0, 0.5) radius 0.8.
    assert!(p.passes(1.0, 0.0, -0.25));
    assert!(!p.passes(1.0, 0.0, -0.35));
    assert!(p.passes(1.0, 0.79, 0.5));
    assert!(!p.passes(1.0, 0.81, 0.5));
    assert!(p.passes(1.0, 0.0, 0.99));
    assert!(!p.passes(1.0, 0.0, 1.01));
    let b = p.bbox(1.0).unwrap();
    for (g, w) in b.iter().zip([-0.8, 0.8, -0.3, 1.0]) {
        assert!(close(*g, w, 1e-14), "{b:?}");
    }
    // The largest input radius passes; beyond it nothing does.
    assert!(p.passes(2.0, 0.0, 0.5));
    assert!(!p.passes(2.0 + 1e-9, 0.0, 0.5));
    let b = p.bbox(2.0).unwrap();
    for (g, w) in b.iter().zip([-0.8, 0.8, 0.2, 1.0]) {
        assert!(close(*g, w, 1e-14), "{b:?}");
    }
    assert!(p.bbox(2.0 + 1e-9).is_none());
    // Nearest edge: the first circle's radius 1 (the second reaches 1.3).
    assert!(close(p.reach(1.0), 1.0, 1e-14));
    let mut c = circles();
    c.sensitivities = vec![0.0, 1.0];
    c.radii_mm = vec![1.0, 0.5];
    assert!(close(
        PassNoPass::Circles(c.clone()).reach(-4.0),
        1.0,
        1e-14
    ));
    // The second circle nearer: |0.1 · 2| + 0.5 = 0.7.
    c.sensitivities = vec![0.0, 0.1];
    assert!(close(PassNoPass::Circles(c.clone()).reach(2.0), 0.7, 1e-14));
    // Disjoint circles (centres 0 and 1 at r = 1, radii 0.1): no region.
    c.sensitivities = vec![0.0, 1.0];
    c.radii_mm = vec![0.1, 0.1];
    assert!(PassNoPass::Circles(c.clone()).bbox(1.0).is_none());
    c.max_input_radius_mm = None;
    assert_eq!(PassNoPass::Circles(c).max_radius_mm(), None);
}

/// The black box of [`lens`] at input points all around the axis: the
/// rotation into the point's frame and back must give the symmetric answer.
#[test]
fn transfer_rotates_into_the_input_points_frame_and_back() {
    let rtf = lens();
    let w = &rtf.waves[0];
    for (x, y) in [
        (0.0, 2.0),
        (2.0, 0.0),
        (-1.2, 1.6),
        (-1.0, -1.5),
        (0.0, 0.0),
    ] {
        for d in [DVec3::new(0.1, -0.2, 1.0), DVec3::new(-0.3, 0.05, 1.0)] {
            let d = d.normalize();
            let (p, o) = rtf.transfer(w, x, y, d).unwrap();
            let r = f64::hypot(x, y);
            let want = DVec2::new(x, y) * (M + Q * r) + DVec2::new(d.x, d.y) * B;
            assert!(
                close(p.x, want.x, 1e-12) && close(p.y, want.y, 1e-12),
                "{p} vs {want}"
            );
            assert_eq!(p.z, 6.0);
            assert!((o - d).length() < 1e-12, "{o} vs {d}");
        }
    }
    assert_eq!(rtf.output_plane_from_input_mm(w), 6.0);
}

#[test]
fn transfer_uses_outz_and_outdz_when_given() {
    let mut rtf = lens();
    rtf.waves[0].outputs[2] = Some(poly(&[([0, 0, 0], 7.0)]));
    rtf.waves[0].outputs[5] = Some(poly(&[([0, 0, 0], 1.0)]));
    let w = &rtf.waves[0];
    assert_eq!(rtf.output_plane_from_input_mm(w), 7.0);
    let d = DVec3::new(0.3, -0.4, 1.0).normalize();
    let (p, o) = rtf.transfer(w, -1.0, 1.0, d).unwrap();
    assert_eq!(p.z, 7.0);
    // outdz = 1 with the unchanged lateral components, then normalised.
    let want = DVec3::new(d.x, d.y, 1.0).normalize();
    assert!((o - want).length() < 1e-12, "{o} vs {want}");
}

#[test]
fn transfer_refuses_backward_and_evanescent_rays() {
    let rtf = lens();
    let w = &rtf.waves[0];
    assert!(
        rtf.transfer(w, 0.5, 0.5, DVec3::new(0.0, 0.6, -0.8))
            .is_none()
    );
    assert!(
        rtf.transfer(w, 0.5, 0.5, DVec3::new(0.0, 1.0, 0.0))
            .is_none()
    );
    // outdx = 2·dx with dx = 0.8 leaves no room for a real outdz.
    let mut steep = lens();
    steep.waves[0].outputs[3] = Some(poly(&[([0, 1, 0], 2.0)]));
    let w = &steep.waves[0];
    assert!(
        steep
            .transfer(w, 0.0, 1.0, DVec3::new(0.8, 0.0, 0.6))
            .is_none()
    );
    assert!(
        steep
            .transfer(w, 0.0, 1.0, DVec3::new(0.3, 0.0, 0.6).normalize())
            .is_some()
    );
}

/// The pass test sees the ray in the input point's frame: a circle of radius
/// 0.5 mm centred at (0, 0.2·r) on a plane 2 mm beyond the input plane,
/// probed just inside and just outside its edge from r = 1 mm, and the same
/// rays rotated about the axis give the same verdicts.
#[test]
fn transfer_blocks_rays_outside_the_pass_region_in_any_direction() {
    let mut rtf = lens();
    rtf.waves[0].pass = PassNoPass::Circles(Circles {
        radii_mm: vec![0.5],
        sensitivities: vec![0.2],
        plane_distance_mm: 2.0,
        max_input_radius_mm: None,
    });
    let w = &rtf.waves[0];
    // (hit on the pass plane in the frame where the input point is (0, 1), passes)
    let cases = [
        ((0.0, 0.69), true),
        ((0.0, 0.71), false),
        ((0.0, -0.29), true),
        ((0.0, -0.31), false),
        ((0.49, 0.2), true),
        ((-0.51, 0.2), false),
    ];
    for angle in [0.0f64, 0.5, 1.7, 3.0, 4.4] {
        let (s, c) = angle.sin_cos();
        // Rotating (a, b) in the point's frame to the lab frame.
        let rot = |a: f64, b: f64| (a * c + b * s, -a * s + b * c);
        for ((hx, hy), pass) in cases {
            let d_rot = DVec3::new(hx / 2.0, (hy - 1.0) / 2.0, 1.0).normalize();
            let (px, py) = rot(0.0, 1.0);
            let (dx, dy) = rot(d_rot.x, d_rot.y);
            let got = rtf.transfer(w, px, py, DVec3::new(dx, dy, d_rot.z));
            assert_eq!(got.is_some(), pass, "angle {angle}, hit ({hx}, {hy})");
        }
    }
}

#[test]
fn the_nearest_wavelengths_table_is_used() {
    let mut rtf = lens();
    let base = rtf.waves[0].clone();
    rtf.waves = [450.0, 550.0, 650.0]
        .into_iter()
        .map(|nm| RtfWave {
            wavelength_nm: nm,
            ..base.clone()
        })
        .collect();
    for (ask, got) in [
        (540.0, 550.0),
        (599.9, 550.0),
        (600.1, 650.0),
        (100.0, 450.0),
    ] {
        assert_eq!(rtf.waves[rtf.wave_index(ask)].wavelength_nm, got);
    }
}

#[test]
fn dispersive_only_when_the_tables_differ() {
    let mut rtf = lens();
    assert!(!RtfCamera::new(rtf.clone(), 0.6).unwrap().is_dispersive());
    let mut other = rtf.waves[0].clone();
    other.wavelength_nm = 650.0;
    rtf.waves.push(other);
    assert!(!RtfCamera::new(rtf.clone(), 0.6).unwrap().is_dispersive());
    let mut outputs = rtf.clone();
    outputs.waves[1].outputs[0] = Some(poly(&[([0, 1, 0], 2.1)]));
    assert!(RtfCamera::new(outputs, 0.6).unwrap().is_dispersive());
    rtf.waves[1].pass = PassNoPass::Ellipses(ellipses());
    assert!(RtfCamera::new(rtf, 0.6).unwrap().is_dispersive());
}

#[test]
fn camera_geometry_and_film_distance_checks() {
    for bad in [0.0, -1.0, f64::NAN, f64::INFINITY] {
        assert!(RtfCamera::new(lens(), bad).is_err(), "{bad}");
    }
    let cam = RtfCamera::new(lens(), 0.6).unwrap();
    assert!(close(cam.input_plane_z_mm(), 0.6 - 0.5, 1e-15));
    assert!(close(cam.front_vertex_z_mm(), 0.6 + 4.0, 1e-15));
    assert_eq!(cam.film_distance_m(), Some(0.6e-3));
    let d = cam.describe();
    assert!(d.contains("test lens") && d.contains("0.6 mm"), "{d}");
}

/// Projected solid angle of a disk of radius `a` seen from a point at height
/// `h` below its plane and `rho` off its axis (configuration factor of a
/// differential area parallel to a disk, times π).
fn disk_projected_solid_angle(a: f64, h: f64, rho: f64) -> f64 {
    if rho == 0.0 {
        return std::f64::consts::PI * a * a / (h * h + a * a);
    }
    let (hh, rr) = (h / rho, a / rho);
    let z = 1.0 + hh * hh + rr * rr;
    std::f64::consts::PI / 2.0 * (1.0 - (z - 2.0 * rr * rr) / (z * z - 4.0 * rr * rr).sqrt())
}

/// The sampling box holds the whole pass region, and the weights make the
/// mean weight the projected solid angle of the rays that pass: with one
/// circle of radius 0.4 mm on the axis (sensitivity 0), the pass region is
/// a disk, whatever the input point, and E/L is its closed form. A 300×300
/// midpoint grid over a box of a circle has < 0.3 % error.
#[test]
fn sampling_box_weights_give_the_disks_projected_solid_angle() {
    let mut rtf = lens();
    rtf.waves[0].pass = PassNoPass::Circles(Circles {
        radii_mm: vec![0.4],
        sensitivities: vec![0.0],
        plane_distance_mm: 2.5,
        max_input_radius_mm: None,
    });
    let cam = RtfCamera::new(rtf, 0.6).unwrap();
    let h = cam.input_plane_z_mm() + 2.5;
    for rho_mm in [0.0, 0.3, 1.0, 2.5] {
        let e = irradiance_factor(&cam, DVec2::new(0.0, rho_mm * 1e-3), 550.0, 300);
        let exact = disk_projected_solid_angle(0.4, h, rho_mm);
        assert!(
            (e / exact - 1.0).abs() < 3e-3,
            "ρ {rho_mm} mm: {e} vs {exact}"
        );
        let e = irradiance_factor(
            &cam,
            DVec2::new(rho_mm * 0.6e-3, -rho_mm * 0.8e-3),
            550.0,
            300,
        );
        assert!(
            (e / exact - 1.0).abs() < 3e-3,
            "ρ {rho_mm} mm rotated: {e} vs {exact}"
        );
    }
}

/// Rays leave the output plane: origin at z_in + 6 mm (in metres), pointing
/// to the scene; film coordinates are the upright image's (the physical
/// film point is their negative), so a film point on +y looks at the scene
/// above the axis.
#[test]
fn camera_rays_start_on_the_output_plane() {
    let cam = RtfCamera::new(lens(), 0.6).unwrap();
    let z_out = (cam.input_plane_z_mm() + 6.0) * 1e-3;
    let mut n = 0;
    let mut sum_dy = 0.0;
    for i in 0..10 {
        for j in 0..10 {
            let u = DVec2::new((i as f64 + 0.5) / 10.0, (j as f64 + 0.5) / 10.0);
            if let Some(r) = cam.sample_ray(DVec2::new(0.0, 0.2e-3), u, 550.0) {
                assert!(close(r.origin.z, z_out, 1e-15), "{}", r.origin.z);
                assert!(r.direction.z > 0.0 && close(r.direction.length(), 1.0, 1e-12));
                assert!(r.weight > 0.0);
                sum_dy += r.direction.y;
                n += 1;
            }
        }
    }
    assert!(n > 50, "{n}");
    assert!(sum_dy > 0.0);
}

fn json() -> Value {
    let mut rtf = lens();
    rtf.waves[0].pass = PassNoPass::Ellipses(ellipses());
    let mut c = lens().waves[0].clone();
    c.wavelength_nm = 650.0;
    c.pass = PassNoPass::Circles(circles());
    rtf.waves.push(c);
    rtf.to_json()
}

#[test]
fn json_round_trip_is_exact() {
    let v = json();
    let rtf = Rtf::from_value(&v, Path::new("t.json")).unwrap();
    assert_eq!(rtf.to_json(), v);
    assert_eq!(rtf.name, "test lens");
    assert_eq!(rtf.thickness_mm, 4.0);
    assert_eq!(rtf.plane_offset_input_mm, 0.5);
    assert_eq!(rtf.plane_offset_output_mm, 1.5);
    assert_eq!(rtf.waves[1].pass, PassNoPass::Circles(circles()));
    // Without a method the ellipses are meant (ISET's default).
    let mut v = json();
    v["polynomials"][0]["passnopass"]
        .as_object_mut()
        .unwrap()
        .remove("method");
    let rtf = Rtf::from_value(&v, Path::new("t.json")).unwrap();
    assert_eq!(rtf.waves[0].pass, PassNoPass::Ellipses(ellipses()));
}

/// Each malformed field is refused with the file and what was expected.
#[test]
fn malformed_files_are_refused_with_the_reason() {
    let refuse = |edit: &dyn Fn(&mut Value), expect: &str| {
        let mut v = json();
        edit(&mut v);
        let e = Rtf::from_value(&v, Path::new("t.json"))
            .map(|_| ())
            .unwrap_err()
            .to_string();
        assert!(e.contains("t.json") && e.contains(expect), "{expect}: {e}");
    };
    fn pnp(v: &mut Value) -> &mut Value {
        &mut v["polynomials"][0]["passnopass"]
    }
    refuse(&|v| v["polynomials"] = json!([]), "empty");
    refuse(&|v| v["polynomials"] = json!(3), "polynomials");
    refuse(&|v| v["thickness"] = json!("4"), "thickness");
    refuse(&|v| v["planeoffsetinput"] = Value::Null, "planeoffsetinput");
    refuse(
        &|v| v["planeoffsetoutput"] = json!(f64::NAN),
        "planeoffsetoutput",
    );
    refuse(
        &|v| v["polynomials"][0]["wavelength_nm"] = json!(null),
        "wavelength_nm",
    );
    refuse(
        &|v| {
            v["polynomials"][0]
                .as_object_mut()
                .unwrap()
                .remove("passnopass");
        },
        "passnopass",
    );
    refuse(&|v| pnp(v)["method"] = json!("magic"), "magic");
    refuse(&|v| pnp(v)["radiiY"] = json!([1.0, 1.0]), "equal");
    refuse(
        &|v| pnp(v)["centersX"] = json!([0.0, 0.0, 0.0, 0.0]),
        "equal",
    );
    refuse(&|v| pnp(v)["positions"] = json!([]), "equal");
    refuse(
        &|v| pnp(v)["positions"] = json!([0.0, 1.0, 1.0]),
        "increase",
    );
    refuse(
        &|v| pnp(v)["positions"] = json!([0.0, 2.0, 1.0]),
        "increase",
    );
    refuse(&|v| pnp(v)["radiiX"] = json!([1.0, 0.0, 1.0]), "radii");
    refuse(&|v| pnp(v)["radiiY"] = json!([1.0, 1.0, -1.0]), "radii");
    refuse(&|v| pnp(v)["radiiX"] = json!([1.0, "a", 1.0]), "non-number");
    refuse(
        &|v| pnp(v)["intersectPlaneDistance"] = Value::Null,
        "intersectPlaneDistance",
    );
    fn circ(v: &mut Value) -> &mut Value {
        &mut v["polynomials"][1]["passnopass"]
    }
    refuse(&|v| circ(v)["circleRadii"] = json!([1.0]), "equal");
    refuse(&|v| circ(v)["circleRadii"] = json!([]), "equal");
    refuse(&|v| circ(v)["circlePlaneZ"] = json!("2"), "circlePlaneZ");
    let out = |v: &mut Value, k: usize| -> Value { v["polynomials"][0]["poly"][k].clone() };
    refuse(
        &|v| v["polynomials"][0]["poly"][0]["outputname"] = json!("outq"),
        "outq",
    );
    refuse(
        &|v| v["polynomials"][0]["poly"][0]["termr"] = json!([-1]),
        "bad exponent",
    );
    refuse(
        &|v| v["polynomials"][0]["poly"][0]["termdx"] = json!([0.5]),
        "bad exponent",
    );
    refuse(
        &|v| v["polynomials"][0]["poly"][0]["termdy"] = json!([64]),
        "bad exponent",
    );
    refuse(
        &|v| v["polynomials"][0]["poly"][0]["termr"] = json!([0, 0]),
        "lengths differ",
    );
    refuse(
        &|v| v["polynomials"][0]["poly"][0]["termdx"] = json!([]),
        "lengths differ",
    );
    refuse(
        &|v| v["polynomials"][0]["poly"][0]["termdy"] = json!([1, 1]),
        "lengths differ",
    );
    refuse(&|v| v["polynomials"][0]["poly"] = json!({}), "poly");
    for (k, name) in [(0, "outx"), (1, "outy"), (2, "outdx"), (3, "outdy")] {
        refuse(
            &|v| {
                let keep: Vec<Value> = (0..4).filter(|&i| i != k).map(|i| out(v, i)).collect();
                v["polynomials"][0]["poly"] = Value::Array(keep);
            },
            &format!("missing '{name}'"),
        );
    }
    // Exponent 63 is the largest accepted.
    let mut v = json();
    v["polynomials"][0]["poly"][0]["termdy"] = json!([63]);
    assert!(Rtf::from_value(&v, Path::new("t.json")).is_ok());
}

/// An output point that overflows (outx = 1e308·r² at r = 10 mm) makes no
/// ray, though its direction is fine.
#[test]
fn overflowing_outputs_make_no_ray() {
    let mut rtf = lens();
    rtf.waves[0].outputs[0] = Some(poly(&[([2, 0, 0], 1e308)]));
    let w = &rtf.waves[0];
    assert!(rtf.transfer(w, 0.0, 10.0, DVec3::Z).is_none());
    assert!(rtf.transfer(w, 0.0, 1e-200, DVec3::Z).is_some());
}

/// The sampling box is the pass region's box (the union over 9 input radii
/// within ±δ of the film point's) grown by 2 % of its size and by δ, with
/// δ = 1.05·g·(ρ + reach)/h: g the film-to-input-plane distance, h the
/// film-to-pass-plane distance, reach the farthest any pass region goes.
/// For a centred disk of radius R every radius has the box [−R, R]², so the
/// sampling box is [−R − m, R + m]², m = 0.04·R + δ. Beyond the largest
/// input radius by more than δ there is no box.
#[test]
fn sampling_box_is_the_pass_box_with_its_margins() {
    let mut rtf = lens();
    rtf.waves[0].pass = PassNoPass::Circles(Circles {
        radii_mm: vec![0.4],
        sensitivities: vec![0.0],
        plane_distance_mm: 2.5,
        max_input_radius_mm: Some(2.0),
    });
    let cam = RtfCamera::new(rtf, 0.6).unwrap();
    let w = &cam.rtf.waves[0];
    let (g, h) = (0.1, 0.1 + 2.5);
    for rho in [0.0, 1.0] {
        let delta = 1.05 * g * (rho + 0.4) / h;
        let m = 0.04 * 0.4 + delta;
        let b = cam.sampling_box(w, rho).unwrap();
        for (got, want) in b.iter().zip([-0.4 - m, 0.4 + m, -0.4 - m, 0.4 + m]) {
            assert!(close(*got, want, 1e-12), "ρ {rho}: {b:?}");
        }
    }
    assert!(cam.sampling_box(w, 3.0).is_none());
    // A table that is not the camera's own (a copy) gets the same box.
    let copy = w.clone();
    assert_eq!(cam.sampling_box(&copy, 1.0), cam.sampling_box(w, 1.0));
}

/// The reach bounding the sampling slope: over input radii up to the
/// largest one, or, when unlimited, up to 10 × max(film distance, thickness)
/// (here 10 × 4 mm): an off-axis circle (centre 0.1·r, radius 0.5) reaches
/// 0.1·40 + 0.5 = 4.5 mm, so δ = 1.05·g·(ρ + 4.5)/h.
#[test]
fn unlimited_pass_regions_reach_to_ten_lens_lengths() {
    let mut rtf = lens();
    rtf.waves[0].pass = PassNoPass::Circles(Circles {
        radii_mm: vec![0.5],
        sensitivities: vec![0.1],
        plane_distance_mm: 2.5,
        max_input_radius_mm: None,
    });
    let cam = RtfCamera::new(rtf, 0.6).unwrap();
    let w = cam.rtf.waves[0].clone();
    assert!(close(RtfCamera::reach_of(&w, 0.6, 4.0), 4.5, 1e-12));
    assert!(close(RtfCamera::reach_of(&w, 7.0, 4.0), 7.5, 1e-12));
    let (g, h, rho) = (0.1, 2.6, 0.0);
    let delta = 1.05 * g * (rho + 4.5) / h;
    // The film point on the axis: input radii 0 … δ; the box is the union of
    // the circles' boxes, [−0.5, 0.5] × [−0.5, 0.1·δ + 0.5].
    let b = cam.sampling_box(&w, rho).unwrap();
    let (x1, y0, y1) = (0.5, -0.5, 0.1 * delta + 0.5);
    let (mx, my) = (0.02 * 2.0 * x1 + delta, 0.02 * (y1 - y0) + delta);
    for (got, want) in b.iter().zip([-x1 - mx, x1 + mx, y0 - my, y1 + my]) {
        assert!(close(*got, want, 1e-12), "{b:?}");
    }
}

/// The camera's planned transfer (the six outputs evaluated together,
/// `FusedPolys`) gives `transfer`'s bits (each output on its own) on the
/// shipped Pixel 4a tables, for rays over the whole input plane and
/// aperture, passing and blocked; and a wave whose outputs use different
/// exponents is not fused.
#[test]
fn planned_transfer_is_bit_identical() {
    let rtf = Rtf::load(Path::new(
        "lenses/rtf/pixel4a-rearcamera-ellipse-raytransfer.json",
    ))
    .unwrap();
    let w = &rtf.waves[0];
    let plan = WavePlan::new(w);
    assert!(
        plan.fused.is_some(),
        "the fitted tables share their exponents"
    );
    let mut rng = crate::render::sampling::Rng::for_sample(7, 0, 0);
    let (mut passed, mut n) = (0, 0);
    for _ in 0..20_000 {
        let x = (rng.uniform() as f64 - 0.5) * 6.0;
        let y = (rng.uniform() as f64 - 0.5) * 6.0;
        let d = DVec3::new(
            (rng.uniform() as f64 - 0.5) * 0.8,
            (rng.uniform() as f64 - 0.5) * 0.8,
            1.0,
        )
        .normalize();
        let a = rtf.transfer(w, x, y, d);
        let b = rtf.transfer_planned(w, &plan, x, y, d);
        let bits = |r: Option<(DVec3, DVec3)>| {
            r.map(|(p, q)| [p.x, p.y, p.z, q.x, q.y, q.z].map(f64::to_bits))
        };
        assert_eq!(bits(a), bits(b), "ray ({x}, {y}) {d}");
        passed += a.is_some() as u32;
        n += 1;
    }
    assert!(passed > 100 && passed < n, "{passed} of {n} passed");
    let mut mixed = w.clone();
    mixed.outputs[0] = Some(poly(&[([0, 0, 0], 1.0), ([1, 0, 0], 2.0)]));
    assert!(WavePlan::new(&mixed).fused.is_none());
    // The first output with a coefficient missing is not fused either (a
    // fused table would index past its coefficients).
    let mut short = w.clone();
    if let Some(p) = short.outputs[0].as_mut() {
        p.coeff.pop();
    }
    assert!(WavePlan::new(&short).fused.is_none());
}

/// `first_above` is `partition_point(x <= r)` on even, uneven, repeated and
/// one-entry tables, for radii before, on, between and after the entries.
#[test]
fn first_above_is_the_partition_point() {
    let tables: [&[f64]; 5] = [
        &[0.0, 0.1, 0.2, 0.30000000000000004, 0.4],
        &[0.0, 1.0, 3.0, 3.0, 3.5, 10.0],
        &[2.0],
        &[1.0, 1.0, 1.0],
        &[0.0, 0.001, 0.5, 0.9, 0.95, 1.0],
    ];
    for p in tables {
        let mut rs: Vec<f64> = p.to_vec();
        rs.extend(p.iter().map(|x| x.next_up()));
        rs.extend(p.iter().map(|x| x.next_down()));
        rs.extend([-1.0, 0.05, 0.5, 2.5, 3.2, 7.0, 11.0, 1e300, f64::INFINITY]);
        for r in rs {
            assert_eq!(
                first_above(p, r),
                p.partition_point(|&x| x <= r),
                "{p:?} at {r}"
            );
        }
    }
}
