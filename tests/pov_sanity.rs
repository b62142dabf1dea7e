//! POV-Ray geometry sanity render: an independent renderer must see the same
//! layout (red sphere in the centre, green sphere on the image's right, white
//! wall behind). Skips with a note when `povray` is not installed, except in CI.

use camsim::scene::*;
use camsim::spectrum::Spectrum;
use glam::{DVec3, Vec3};

fn scene() -> Scene {
    let mut s = Scene::default();
    let white = s.material(
        "white",
        Material::Diffuse {
            reflectance: Spectrum::constant("w", 0.8),
        },
    );
    let red = s.material(
        "red",
        Material::Diffuse {
            reflectance: Spectrum::new(
                "r",
                vec![400.0, 580.0, 600.0, 700.0],
                vec![0.02, 0.02, 0.8, 0.8],
            )
            .unwrap(),
        },
    );
    let green = s.material(
        "green",
        Material::Diffuse {
            reflectance: Spectrum::new(
                "g",
                vec![400.0, 480.0, 500.0, 560.0, 580.0, 700.0],
                vec![0.02, 0.02, 0.8, 0.8, 0.02, 0.02],
            )
            .unwrap(),
        },
    );
    let wall = s.object("wall");
    s.meshes.push(Mesh {
        positions: vec![
            Vec3::new(-5.0, -5.0, 3.0),
            Vec3::new(5.0, -5.0, 3.0),
            Vec3::new(5.0, 5.0, 3.0),
            Vec3::new(-5.0, 5.0, 3.0),
        ],
        indices: vec![[0, 1, 2], [0, 2, 3]],
        material: white,
        object: wall,
        ..Default::default()
    });
    let o1 = s.object("red-ball");
    s.spheres.push(Sphere {
        center: DVec3::new(0.0, 0.0, 1.5),
        radius: 0.25,
        material: red,
        object: o1,
        emission: None,
    });
    let o2 = s.object("green-ball");
    s.spheres.push(Sphere {
        center: DVec3::new(0.6, 0.0, 1.5),
        radius: 0.15,
        material: green,
        object: o2,
        emission: None,
    });
    s.lights.push(Light::Point {
        position: DVec3::new(0.0, 1.0, -1.0),
        intensity: Spectrum::constant("i", 1.0),
    });
    let pose = CameraPose {
        position: DVec3::ZERO,
        look_at: DVec3::Z,
        up: DVec3::Y,
    };
    s.camera = Some(CameraSpec {
        to_world: look_at_to_world(&pose).unwrap(),
        model: CameraModel::Pinhole {
            fov_deg: 60.0,
            f_number: 2.0,
            cos4: true,
        },
    });
    s
}

#[test]
fn povray_sees_the_same_layout() {
    let s = scene();
    let film = FilmSpec {
        width_px: 80,
        height_px: 60,
        pixel_pitch_m: 1e-5,
        crop_window: None,
    };
    let text = camsim::pov::scene_to_pov(&s, &film).unwrap();
    assert!(text.contains("sphere") && text.contains("mesh2") && text.contains("camera"));
    if std::process::Command::new("povray")
        .arg("--version")
        .output()
        .is_err()
    {
        assert!(
            std::env::var("CI").is_err(),
            "povray must be installed in CI (.ci/run installs it)"
        );
        eprintln!("note: povray not installed; render part skipped");
        return;
    }
    let dir = tempfile::tempdir().unwrap();
    let keep = std::env::var("CAMSIM_KEEP_POV").ok();
    let pov = dir.path().join("s.pov");
    let png = dir.path().join("s.png");
    camsim::pov::export_and_render(&s, &film, &pov, Some(&png)).unwrap();
    if let Some(k) = keep {
        std::fs::copy(&png, k).unwrap();
    }
    let dec = png::Decoder::new(std::io::BufReader::new(std::fs::File::open(&png).unwrap()));
    let mut r = dec.read_info().unwrap();
    let mut buf = vec![0; r.output_buffer_size().unwrap()];
    let info = r.next_frame(&mut buf).unwrap();
    assert_eq!((info.width, info.height), (80, 60));
    let ch = info.color_type.samples();
    let bpc = if info.bit_depth == png::BitDepth::Sixteen {
        2
    } else {
        1
    };
    let px = |x: usize, y: usize| -> [f64; 3] {
        let i = (y * 80 + x) * ch * bpc;
        let g = |k: usize| {
            if bpc == 2 {
                u16::from_be_bytes([buf[i + 2 * k], buf[i + 2 * k + 1]]) as f64 / 65535.0
            } else {
                buf[i + k] as f64 / 255.0
            }
        };
        [g(0), g(1), g(2)]
    };
    let c = px(40, 30);
    assert!(
        c[0] > 2.0 * c[1] && c[0] > 2.0 * c[2],
        "centre should be red: {c:?}"
    );
    // green ball at x=+0.6, z=1.5: tan = 0.4, image half-width tan(hfov/2) = tan(30°)·4/3 = 0.77
    // → column 40 + 40·0.4/0.77 ≈ 61 (to the RIGHT).
    let g = px(61, 30);
    assert!(
        g[1] > 1.5 * g[0] && g[1] > 1.5 * g[2],
        "right side should be green: {g:?}"
    );
    let w = px(3, 3);
    assert!(
        (w[0] - w[1]).abs() < 0.1 && (w[1] - w[2]).abs() < 0.1 && w[0] > 0.05,
        "corner should be neutral wall: {w:?}"
    );
}
