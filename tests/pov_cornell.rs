//! The POV-Ray geometry sanity check (issue 19) on the paper's Cornell box:
//! the shipped box with the bunny and the mini MCC, from both fig. 4 cameras,
//! must agree with camsim's labels (IoU ≥ 0.98 for every object > 100 px);
//! a mirrored object, an object shifted by 1 cm and a camera with a 5 % wrong
//! field of view must each be caught; and the pbrt-v4 Bitterli box, a scene
//! nobody in the project wrote, must pass too.
//!
//! Why 0.98 holds for a correct scene: both renderers shoot one ray through
//! each pixel centre along the same line (the same pinhole), so a pixel can
//! only differ where its centre lies within float rounding of a silhouette
//! (camsim intersects in f32, ~1e-7 relative) — a handful of pixels per
//! object, not 2 % of any object above 100 px. Why the faults are caught:
//! a 1 cm shift at 0.4–0.6 m is ≥ 4 px at the 320 px check width (fov ≈ 64°:
//! 320 px span 2·0.5·tan 32° ≈ 0.62 m at 0.5 m), which takes well over 2 % of a
//! ~40 px wide bunny; a 5 % zoom scales every silhouette by 5 %, which moves
//! the large walls' edges by tens of pixels.
//!
//! Skips with a note when `povray` is missing, except in CI (where .ci/run
//! installs it).

use camsim::optics::Camera;
use camsim::pov::sanity::{self, Sanity};
use camsim::pov::{PinholeEquivalent, check, check_as_pinhole};
use camsim::scene::targets::{MccChart, PlacedMesh, add_mcc, add_mesh};
use camsim::scene::{CameraModel, CameraPose, CameraSpec, FilmSpec, Scene, look_at_to_world};
use glam::{DMat4, DVec3};
use std::path::Path;

fn povray_or_skip() -> bool {
    if camsim::pov::povray::available() {
        return true;
    }
    assert!(
        std::env::var("CI").is_err(),
        "povray must be installed in CI (.ci/run installs it)"
    );
    eprintln!("note: povray not installed (apt-get install povray); POV-Ray check skipped");
    false
}

// Numbers from /work/shared/data/cornellbox/cornellbox_setup.json
// (ISET/isetcornellbox@492f9eb3, transcribed there):
// scene.mcc: world_position [0.006, 0.035, 0.125] m, world_rotation_deg [4, 0, 1];
//   asset mccCB: 1 cm patches on a 1.4 cm pitch (chart 8.4 × 5.6 cm, 5 mm thick).
const MCC_POSITION: [f64; 3] = [0.006, 0.035, 0.125];
const MCC_ROTATION_DEG: [f64; 3] = [4.0, 0.0, 1.0];
// scene.bunny: world_position [0.098, 0.058, 0.0] m, scale 1.445, rot_y_deg 3.
const BUNNY_POSITION: [f64; 3] = [0.098, 0.058, 0.0];
const BUNNY_SCALE: f64 = 1.445;
const BUNNY_ROT_Y_DEG: f64 = 3.0;
// cameras.fig4_center: from [0, 0.1, -0.39] to [0, 0.125, 0.6];
// cameras.fig4_left: from [-0.115, 0.105, -0.405] to [0.135, 0.115, 0.6].
const FIG4_CENTER: ([f64; 3], [f64; 3]) = ([0.0, 0.1, -0.39], [0.0, 0.125, 0.6]);
const FIG4_LEFT: ([f64; 3], [f64; 3]) = ([-0.115, 0.105, -0.405], [0.135, 0.115, 0.6]);
// optics: Pixel 4a rear camera RTF (lenses/rtf/, the project's copy), film
// distance at infinity focus 0.465135918 mm; sensor 4032 × 3024 px of 1.4 µm.
const RTF: &str = "lenses/rtf/pixel4a-rearcamera-ellipse-raytransfer.json";
const FILM_DISTANCE_M: f64 = 0.465135918e-3;
const SENSOR: (u32, u32, f64) = (4032, 3024, 1.4e-6);
/// Check image size (the sensor's aspect, 4:3; large enough that the MCC
/// patches, ~12 px across, count as objects > 100 px).
const CHECK: (u32, u32) = (800, 600);

/// The shipped Cornell box with the bunny and the mini MCC, seen from `pose`.
fn cornell_bunny_mcc(pose: ([f64; 3], [f64; 3])) -> Scene {
    let mut s = camsim::scene::pbrt::load(
        Path::new("scenes/CornellBoxReference/CornellBoxReference.pbrt"),
        &Default::default(),
    )
    .unwrap();
    let mcc = MccChart {
        position_m: DVec3::from(MCC_POSITION),
        rotation_deg: DVec3::from(MCC_ROTATION_DEG),
        ..MccChart::default()
    };
    add_mcc(&mut s, &mcc).unwrap();
    let bunny = PlacedMesh {
        position_m: DVec3::from(BUNNY_POSITION),
        scale: BUNNY_SCALE,
        rot_y_deg: BUNNY_ROT_Y_DEG,
        ..PlacedMesh::bunny(Path::new("scenes/bunny.obj")).unwrap()
    };
    add_mesh(&mut s, &bunny).unwrap();
    let to_world = look_at_to_world(&CameraPose {
        position: DVec3::from(pose.0),
        look_at: DVec3::from(pose.1),
        up: DVec3::Y,
    })
    .unwrap();
    let model = s.camera.as_ref().unwrap().model.clone();
    s.camera = Some(CameraSpec { to_world, model });
    s
}

fn sensor_film() -> FilmSpec {
    FilmSpec {
        width_px: SENSOR.0,
        height_px: SENSOR.1,
        pixel_pitch_m: SENSOR.2,
        crop_window: None,
    }
}

/// The paper's camera: the Pixel 4a RTF lens at its infinity film distance.
fn paper_lens() -> Box<dyn Camera> {
    camsim::optics::camera::build(
        &camsim::scene::CameraModel::LensFile {
            path: Path::new(RTF).to_path_buf(),
            film_distance_m: Some(FILM_DISTANCE_M),
            focus_distance_m: None,
            aperture_diameter_m: None,
            rtf_fit: None,
        },
        &sensor_film(),
    )
    .unwrap()
}

/// camsim's own pinhole for the paper lens' field of view: a Pinhole whose
/// fov is that of the lens' pinhole equivalent.
fn paper_pinhole() -> camsim::optics::pinhole::Pinhole {
    let eq = PinholeEquivalent::of_camera(DMat4::IDENTITY, paper_lens().as_ref(), &sensor_film())
        .unwrap();
    camsim::optics::pinhole::Pinhole::new(eq.fov_short_deg(), 1.8, &sensor_film()).unwrap()
}

fn report(tag: &str, s: &Sanity) {
    let m = s.min_iou().unwrap();
    eprintln!(
        "{tag}: min IoU {:.4} ({}), {} objects, {} larger than 100 px, pinhole fov {:.3}°",
        m.iou,
        m.object,
        s.rows.len(),
        s.rows.iter().filter(|r| r.counts()).count(),
        s.camera.fov_short_deg()
    );
    if let Ok(d) = std::env::var("CAMSIM_KEEP_POV") {
        let d = Path::new(&d);
        std::fs::create_dir_all(d).unwrap();
        std::fs::write(d.join(format!("{tag}.png")), s.side_by_side_png().unwrap()).unwrap();
        std::fs::write(d.join(format!("{tag}.csv")), s.csv().unwrap()).unwrap();
    }
}

fn assert_passes(tag: &str, s: &Sanity, must_see: &[&str]) {
    report(tag, s);
    let fails = s.failures(sanity::DEFAULT_MIN_IOU);
    assert!(fails.is_empty(), "{tag}: {fails:?}");
    for name in must_see {
        let r = s.rows.iter().find(|r| r.object == *name);
        assert!(
            r.is_some_and(|r| r.counts()),
            "{tag}: '{name}' should be a checked object (> 100 px): {r:?}"
        );
    }
}

fn assert_caught(tag: &str, s: &Sanity, object: &str) {
    report(tag, s);
    let fails = s.failures(sanity::DEFAULT_MIN_IOU);
    assert!(
        fails.iter().any(|r| r.object == object),
        "{tag}: '{object}' should fail the check; rows {:?}",
        s.rows
    );
}

#[test]
fn paper_cornell_box_agrees_from_both_fig4_cameras() {
    if !povray_or_skip() {
        return;
    }
    for (tag, pose) in [("fig4_center", FIG4_CENTER), ("fig4_left", FIG4_LEFT)] {
        let scene = cornell_bunny_mcc(pose);
        // Through camsim's pinhole with the paper lens' field of view.
        let s = check_as_pinhole(
            &scene,
            paper_lens().as_ref(),
            &sensor_film(),
            CHECK.0,
            CHECK.1,
        )
        .unwrap();
        assert!(
            (s.camera.fov_short_deg() - paper_pinhole().fov_deg).abs() < 1e-9,
            "{:?}",
            s.camera
        );
        assert_passes(
            &format!("{tag}-pinhole"),
            &s,
            &["bunny", "mcc/surround", "Box/BackWall", "CubeLarge"],
        );
        // Through the paper lens itself (labels from its chief rays): its
        // distortion is not a pinhole's; reported here, not asserted.
        let s = check(
            &scene,
            paper_lens().as_ref(),
            &sensor_film(),
            CHECK.0,
            CHECK.1,
        )
        .unwrap();
        report(&format!("{tag}-rtf"), &s);
    }
}

/// Scene `s` with object `name`'s meshes changed by `f` (world positions).
fn edit_object(s: &Scene, name: &str, f: impl Fn(DVec3) -> DVec3) -> Scene {
    let id = s.objects.iter().position(|o| o.name == name).unwrap() as u32;
    let mut t = s.clone();
    let mut n = 0;
    for m in t.meshes.iter_mut().filter(|m| m.object == id) {
        for p in &mut m.positions {
            *p = f(p.as_dvec3()).as_vec3();
        }
        n += 1;
    }
    assert!(n > 0, "no mesh carries '{name}'");
    t
}

/// The POV-Ray camera for `scene` and the paper pinhole on the check film.
fn pov_camera(scene: &Scene, cam: &dyn Camera) -> (PinholeEquivalent, FilmSpec) {
    let film = sanity::check_film(&sensor_film(), CHECK.0, CHECK.1).unwrap();
    let eq =
        PinholeEquivalent::of_camera(scene.camera.as_ref().unwrap().to_world, cam, &film).unwrap();
    (eq, film)
}

#[test]
fn a_mirrored_or_shifted_object_and_a_wrong_fov_are_caught() {
    if !povray_or_skip() {
        return;
    }
    let scene = cornell_bunny_mcc(FIG4_CENTER);
    let cam = paper_pinhole();
    let (eq, film) = pov_camera(&scene, &cam);
    // The bunny's bounding-box centre x (it is placed by that centre).
    let bunny_cx = BUNNY_POSITION[0];

    // Mirrored: the bunny reflected in the plane x = its centre (a transform
    // with determinant −1 that keeps it in place).
    let mirrored = edit_object(&scene, "bunny", |p| {
        DVec3::new(2.0 * bunny_cx - p.x, p.y, p.z)
    });
    let s = sanity::check_with(&scene, &mirrored, &cam, &eq, &film).unwrap();
    assert_caught("mirrored-bunny", &s, "bunny");

    // Shifted by 1 cm along x (sideways to the camera).
    let shifted = edit_object(&scene, "bunny", |p| p + DVec3::new(0.01, 0.0, 0.0));
    let s = sanity::check_with(&scene, &shifted, &cam, &eq, &film).unwrap();
    assert_caught("shifted-bunny", &s, "bunny");
    // …and the chart, a thin object, shifted 1 cm up.
    let shifted = edit_object(&scene, "mcc/surround", |p| p + DVec3::new(0.0, 0.01, 0.0));
    let s = sanity::check_with(&scene, &shifted, &cam, &eq, &film).unwrap();
    assert_caught("shifted-mcc", &s, "mcc/surround");

    // A camera with a 5 % wider field of view (both tangents × 1.05).
    let s = sanity::check_with(&scene, &scene, &cam, &eq.with_fov_scaled(1.05), &film).unwrap();
    assert_caught("fov+5%", &s, "Box/BackWall");
    // …and 5 % narrower.
    let s =
        sanity::check_with(&scene, &scene, &cam, &eq.with_fov_scaled(1.0 / 1.05), &film).unwrap();
    assert_caught("fov-5%", &s, "Box/BackWall");

    // A camera with the wrong handedness (image x flipped).
    let flipped = PinholeEquivalent {
        to_world: eq.to_world * DMat4::from_scale(DVec3::new(-1.0, 1.0, 1.0)),
        ..eq.clone()
    };
    let s = sanity::check_with(&scene, &scene, &cam, &flipped, &film).unwrap();
    assert_caught("mirrored-camera", &s, "Box/LeftWall");

    // The unaltered scene through the same pieces passes (the faults, not
    // the plumbing, fail the checks above).
    let s = sanity::check_with(&scene, &scene, &cam, &eq, &film).unwrap();
    assert_passes("unaltered", &s, &["bunny"]);
}

#[test]
fn bitterli_pbrt_v4_cornell_box_agrees() {
    if !povray_or_skip() {
        return;
    }
    let scene = camsim::scene::pbrt::load(
        Path::new("scenes/pbrt-v4/bitterli-cornell-box.pbrt"),
        &Default::default(),
    )
    .unwrap();
    let film = scene.film.clone().unwrap();
    let spec = scene.camera.as_ref().unwrap();
    assert!(matches!(spec.model, CameraModel::Pinhole { .. }));
    let cam = camsim::optics::camera::build(&spec.model, &film).unwrap();
    let s = check(&scene, cam.as_ref(), &film, 256, 256).unwrap();
    assert_passes(
        "bitterli",
        &s,
        &["LeftWall", "RightWall", "TallBox", "ShortBox", "Light"],
    );
}
