//! Physics acceptance tests of the spectral path tracer (issue 3). Tolerances
//! are justified from the Monte Carlo standard error reported by the renderer
//! itself (independent batches) and checked to be well below the tolerance.

use camsim::optical_image::Rect;
use camsim::optics::Camera;
use camsim::optics::pinhole::Pinhole;
use camsim::render::{RenderSettings, render};
use camsim::scene::shapes::{cuboid, quad};
use camsim::scene::{
    CameraModel, CameraPose, CameraSpec, Emission, FilmSpec, Material, Scene, look_at_to_world,
};
use camsim::spectrum::{Spectrum, WavelengthGrid, library};
use glam::{DMat4, DVec2, DVec3};
use std::f64::consts::PI;

fn constant(v: f64) -> Spectrum {
    Spectrum::constant("c", v)
}

fn with_camera(scene: &mut Scene, from: DVec3, to: DVec3, fov_deg: f64, f_number: f64) {
    let to_world = look_at_to_world(&CameraPose {
        position: from,
        look_at: to,
        up: DVec3::Y,
    })
    .unwrap();
    scene.camera = Some(CameraSpec {
        to_world,
        model: CameraModel::Pinhole {
            fov_deg,
            f_number,
            cos4: true,
        },
    });
}

fn settings(spp: u32, max_bounces: u32) -> RenderSettings {
    RenderSettings {
        spp,
        max_bounces,
        grid: WavelengthGrid::default(),
        seed: 1,
        batches: 8,
        threads: 0,
        roi: None,
        stderr_weights: vec![],
        sampler: Default::default(),
    }
}

/// Mean over pixels of band `b` of E / w(pixel centre), and the matching stderr.
fn mean_over_weight(
    img: &camsim::optical_image::OpticalImage,
    cam: &Pinhole,
    film: &FilmSpec,
    b: usize,
) -> (f64, f64) {
    let nb = img.bands();
    let (mut s, mut v, mut n) = (0.0, 0.0, 0.0);
    for y in 0..img.height() {
        for x in 0..img.width() {
            let px = img.window.x + x;
            let py = img.window.y + y;
            let f = DVec2::new(
                (px as f64 + 0.5 - film.width_px as f64 / 2.0) * film.pixel_pitch_m,
                (film.height_px as f64 / 2.0 - (py as f64 + 0.5)) * film.pixel_pitch_m,
            );
            let w = cam.sample_ray(f, DVec2::splat(0.5), 550.0).unwrap().weight;
            let i = (y * img.width() + x) as usize * nb + b;
            s += img.irradiance[i] as f64 / w;
            v += (img.stderr[i] as f64 / w).powi(2);
            n += 1.0;
        }
    }
    (s / n, v.sqrt() / n)
}

fn assert_all_finite(img: &camsim::optical_image::OpticalImage) {
    assert_eq!(img.nan_count, 0, "non-finite samples were produced");
    assert!(
        img.irradiance
            .iter()
            .chain(&img.stderr)
            .all(|x| x.is_finite() && *x >= 0.0)
    );
}

#[test]
fn white_furnace_albedo_half() {
    // Closed cube, inward-facing walls: Lambertian albedo 0.5, emitting Le (D65 shape).
    // Radiance everywhere is Le/(1 − 0.5) = 2·Le.
    let mut scene = Scene::default();
    let le = library::named("cie-d65").unwrap().scaled(0.01);
    let m = scene.material(
        "wall",
        Material::Diffuse {
            reflectance: constant(0.5),
        },
    );
    let o = scene.object("enclosure");
    scene.meshes.push(cuboid(
        DVec3::splat(1.0),
        DMat4::IDENTITY,
        true,
        m,
        o,
        Some(Emission {
            radiance: le.clone(),
            two_sided: false,
        }),
    ));
    with_camera(
        &mut scene,
        DVec3::new(0.1, -0.2, 0.05),
        DVec3::new(0.5, 0.3, 1.0),
        20.0,
        1.0,
    );
    let film = FilmSpec {
        width_px: 16,
        height_px: 16,
        pixel_pitch_m: 1e-5,
        crop_window: None,
    };
    let cam = Pinhole::new(20.0, 1.0, &film).unwrap();
    // 200 bounces: truncation bias 0.5^201, negligible.
    let img = render(&scene, &cam, &film, &settings(1024, 200)).unwrap();
    assert_all_finite(&img);
    let grid = &img.grid;
    let mut ratios = vec![];
    for b in 0..img.bands() {
        let le_b = le.eval(grid.wavelength(b));
        let (mean, se) = mean_over_weight(&img, &cam, &film, b);
        let r = mean / le_b;
        // Stderr of the 262k-path mean is ~0.1–0.2 %; the 1 % tolerance is > 5σ.
        assert!(
            se / le_b < 0.002 * 2.0,
            "band {b}: stderr {} too large for the test",
            se / le_b
        );
        assert!(
            (r - 2.0).abs() < 0.02,
            "band {b}: L/Le = {r}, expected 2 within 1 %"
        );
        ratios.push(r);
    }
    // Neutral: every band rides the same paths, so L/Le is the same in every band
    // up to f32 rounding (no chroma drift, no colour noise).
    let (lo, hi) = ratios
        .iter()
        .fold((f64::MAX, f64::MIN), |(a, b), &r| (a.min(r), b.max(r)));
    eprintln!("white furnace: L/Le in [{lo:.5}, {hi:.5}] (expected 2)");
    assert!(hi / lo - 1.0 < 1e-4, "chroma drift: L/Le spans {lo}…{hi}");
}

/// Configuration factor from a differential area to a parallel rectangle
/// a×b whose corner is straight above it at height h.
fn corner_factor(a: f64, b: f64, h: f64) -> f64 {
    let (x, y) = (a / h, b / h);
    let (sx, sy) = ((1.0 + x * x).sqrt(), (1.0 + y * y).sqrt());
    (x / sx * (y / sx).atan() + y / sy * (x / sy).atan()) / (2.0 * PI)
}

#[test]
fn patch_under_rectangular_light_matches_form_factor() {
    let (a, b, h, le, rho) = (0.4, 0.2, 0.5, 2.0, 0.8);
    let mut scene = Scene::default();
    let floor_m = scene.material(
        "floor",
        Material::Diffuse {
            reflectance: constant(rho),
        },
    );
    let black = scene.material("black", Material::Black);
    let floor = scene.object("floor");
    let lamp = scene.object("lamp");
    // Floor y = 0 facing +y (u × v = Z × X = +Y).
    scene.meshes.push(quad(
        DVec3::ZERO,
        DVec3::Z * 2.0,
        DVec3::X * 2.0,
        floor_m,
        floor,
        None,
    ));
    // Light at y = h facing down (X × Z = −Y).
    scene.meshes.push(quad(
        DVec3::new(0.0, h, 0.0),
        DVec3::X * (a / 2.0),
        DVec3::Z * (b / 2.0),
        black,
        lamp,
        Some(Emission {
            radiance: constant(le),
            two_sided: false,
        }),
    ));
    with_camera(
        &mut scene,
        DVec3::new(0.0, 0.7, -0.7),
        DVec3::ZERO,
        0.5,
        2.0,
    );
    let film = FilmSpec {
        width_px: 8,
        height_px: 8,
        pixel_pitch_m: 1e-5,
        crop_window: None,
    };
    let cam = Pinhole::new(0.5, 2.0, &film).unwrap();
    let img = render(&scene, &cam, &film, &settings(1024, 1)).unwrap();
    assert_all_finite(&img);
    assert!(
        img.labels.iter().all(|&l| l == floor),
        "camera must see only the floor"
    );
    let e_expected = le * PI * 4.0 * corner_factor(a / 2.0, b / 2.0, h);
    let l_expected = rho / PI * e_expected;
    for band in [0, 15, 30] {
        let (l, se) = mean_over_weight(&img, &cam, &film, band);
        // Footprint ±6 mm around the point below the light centre: E varies by
        // ~(6 mm/0.5 m)² ≈ 1e-4 there. Stderr must be < 0.1 % so 0.5 % is > 5σ.
        assert!(se / l_expected < 0.001, "stderr {}", se / l_expected);
        eprintln!(
            "form factor: band {band}: L/L_closed = {:.5} ± {:.5}",
            l / l_expected,
            se / l_expected
        );
        assert!(
            (l / l_expected - 1.0).abs() < 0.005,
            "band {band}: L = {l}, closed form {l_expected}"
        );
    }
}

#[test]
fn pinhole_cos4_falloff_and_on_axis_irradiance() {
    // Uniform Lambertian emitting wall at z = 1 facing the camera (−z).
    let (le, n) = (0.3, 2.8);
    let mut scene = Scene::default();
    let black = scene.material("black", Material::Black);
    let wall = scene.object("wall");
    scene.meshes.push(quad(
        DVec3::new(0.0, 0.0, 1.0),
        DVec3::Y * 10.0,
        DVec3::X * 10.0,
        black,
        wall,
        Some(Emission {
            radiance: constant(le),
            two_sided: false,
        }),
    ));
    with_camera(&mut scene, DVec3::ZERO, DVec3::Z, 2.0, n);
    // Tall thin pixels budget: 101 px span 2° vertically; 30° lies at x ≈ 1670 px off centre.
    let film = FilmSpec {
        width_px: 3401,
        height_px: 101,
        pixel_pitch_m: 1e-6,
        crop_window: None,
    };
    let cam = Pinhole::new(2.0, n, &film).unwrap();
    let x30 = (1700.5 + (30f64.to_radians().tan() * cam.film_distance_m) / 1e-6).floor() as u32;
    let e0 = PI * le / (4.0 * n * n);
    for (px, theta_expected) in [(1700u32, None), (x30, Some(30.0f64))] {
        let mut s = settings(64, 0);
        s.roi = Some(Rect::new(px, 50, 1, 1));
        let img = render(&scene, &cam, &film, &s).unwrap();
        assert_all_finite(&img);
        let f = DVec2::new((px as f64 + 0.5 - 1700.5) * 1e-6, 0.0);
        let theta = (f.x / cam.film_distance_m).atan();
        if let Some(t) = theta_expected {
            assert!(
                (theta.to_degrees() - t).abs() < 0.02,
                "pixel is at {}°",
                theta.to_degrees()
            );
        }
        let expected = e0 * theta.cos().powi(4);
        let e = img.pixel(0, 0)[10] as f64;
        eprintln!(
            "pinhole: θ = {:.3}°: E/E_expected = {:.6}",
            theta.to_degrees(),
            e / expected
        );
        assert!(
            (e / expected - 1.0).abs() < 0.005,
            "θ = {}°: E = {e}, expected {expected}",
            theta.to_degrees()
        );
    }
}

fn small_box_scene(scale: f64) -> (Scene, FilmSpec) {
    let mut scene = Scene::default();
    let white = scene.material(
        "white",
        Material::DiffuseSpecular {
            diffuse: library::named("cbox-white-wall").unwrap(),
            specular: constant(0.05),
            roughness: 0.1,
        },
    );
    let red = scene.material(
        "red",
        Material::Diffuse {
            reflectance: library::named("cbox-red-wall").unwrap(),
        },
    );
    let glass = scene.material("glass", Material::Dielectric { ior: constant(1.5) });
    let black = scene.material("black", Material::Black);
    let walls = scene.object("walls");
    let cube = scene.object("cube");
    let ball = scene.object("ball");
    let lamp = scene.object("lamp");
    let s = scale;
    scene.meshes.push(cuboid(
        DVec3::splat(0.5 * s),
        DMat4::IDENTITY,
        true,
        white,
        walls,
        None,
    ));
    let rot =
        DMat4::from_translation(DVec3::new(-0.2, -0.35, 0.1) * s) * DMat4::from_rotation_y(0.5);
    scene
        .meshes
        .push(cuboid(DVec3::splat(0.15 * s), rot, false, red, cube, None));
    scene.spheres.push(camsim::scene::Sphere {
        center: DVec3::new(0.2, -0.3, 0.0) * s,
        radius: 0.2 * s,
        material: glass,
        object: ball,
        emission: None,
    });
    scene.meshes.push(quad(
        DVec3::new(0.0, 0.499, 0.0) * s,
        DVec3::X * 0.1 * s,
        DVec3::Z * 0.1 * s,
        black,
        lamp,
        Some(Emission {
            radiance: library::named("cbox-lamp").unwrap().scaled(1000.0),
            two_sided: false,
        }),
    ));
    with_camera(
        &mut scene,
        DVec3::new(0.0, 0.0, -0.45) * s,
        DVec3::new(0.0, 0.0, 1.0) * s,
        70.0,
        2.0,
    );
    (
        scene,
        FilmSpec {
            width_px: 24,
            height_px: 20,
            pixel_pitch_m: 2e-6,
            crop_window: None,
        },
    )
}

fn render_box(
    scale: f64,
    threads: usize,
    roi: Option<Rect>,
) -> camsim::optical_image::OpticalImage {
    let (scene, film) = small_box_scene(scale);
    let cam = Pinhole::new(70.0, 2.0, &film).unwrap();
    let mut s = settings(16, 6);
    s.threads = threads;
    s.roi = roi;
    render(&scene, &cam, &film, &s).unwrap()
}

fn bits(v: &[f32]) -> Vec<u32> {
    v.iter().map(|x| x.to_bits()).collect()
}

#[test]
fn roi_pixels_equal_full_render_bit_for_bit() {
    let full = render_box(1.0, 0, None);
    let roi = Rect::new(5, 7, 10, 6);
    let part = render_box(1.0, 0, Some(roi));
    // The multi-region entry point gives the same pixels.
    let (scene, film) = small_box_scene(1.0);
    let cam = Pinhole::new(70.0, 2.0, &film).unwrap();
    let regions = camsim::render::render_regions(
        &scene,
        &cam,
        &film,
        &settings(16, 6),
        &[roi, Rect::new(0, 0, 2, 2)],
    )
    .unwrap();
    assert_eq!(bits(&regions[0].irradiance), bits(&part.irradiance));
    let nb = full.bands();
    for y in 0..roi.h {
        for x in 0..roi.w {
            let a = part.pixel(x, y);
            let b = full.pixel(roi.x + x, roi.y + y);
            assert_eq!(bits(a), bits(b), "pixel ({}, {})", roi.x + x, roi.y + y);
            let ia = (y * roi.w + x) as usize;
            let ib = ((roi.y + y) * full.width() + roi.x + x) as usize;
            assert_eq!(
                bits(&part.stderr[ia * nb..(ia + 1) * nb]),
                bits(&full.stderr[ib * nb..(ib + 1) * nb])
            );
            assert_eq!(part.labels[ia], full.labels[ib]);
            assert_eq!(part.depth_m[ia].to_bits(), full.depth_m[ib].to_bits());
        }
    }
}

#[test]
fn one_and_two_threads_are_bit_identical() {
    let a = render_box(1.0, 1, None);
    let b = render_box(1.0, 2, None);
    assert_eq!(bits(&a.irradiance), bits(&b.irradiance));
    assert_eq!(bits(&a.stderr), bits(&b.stderr));
    assert_eq!(a.labels, b.labels);
    assert_eq!(a.nan_count, b.nan_count);
    assert!(a.irradiance.iter().any(|&x| x > 0.0), "image is black");
}

#[test]
fn millimetre_and_kilometre_scenes_stay_finite_and_agree() {
    // Radiance does not depend on scene scale: the same box at 1 mm, 1 m and
    // 1 km must give the same image (same random numbers), and no NaN/Inf.
    let m = render_box(1.0, 0, None);
    for scale in [1e-3, 1e3] {
        let img = render_box(scale, 0, None);
        assert_all_finite(&img);
        let sa: f64 = img.irradiance.iter().map(|&x| x as f64).sum();
        let sb: f64 = m.irradiance.iter().map(|&x| x as f64).sum();
        eprintln!("scale {scale}: image sum ratio to 1 m = {:.6}", sa / sb);
        // The same random numbers drive the same paths at every scale; they
        // diverge only where f32 rounding of the scaled geometry flips a
        // decision (measured: |ratio − 1| ≈ 1.6e-5 – 3e-5). A real scale bug (an
        // offset or a unit error) moves whole paths: ≥ 1 % of the 16-spp image
        // sum (its stderr). 1e-4 sits well between the two.
        assert!(
            (sa / sb - 1.0).abs() < 1e-4,
            "scale {scale}: image sum {sa} vs {sb} at 1 m"
        );
        let depth_ok =
            img.depth_m.iter().zip(&m.depth_m).all(|(a, b)| {
                !b.is_finite() || ((*a as f64) / scale / *b as f64 - 1.0).abs() < 1e-3
            });
        assert!(depth_ok, "depth does not scale with the scene");
    }
}

#[test]
fn spawned_rays_never_reintersect_their_surface_at_any_scale() {
    use camsim::render::accel::{Accel, BvhKind};
    use camsim::render::geometry::{Shape, offset_ray_origin};
    use camsim::render::sampling::Rng;
    use glam::Vec3;
    for scale in [1e-3f32, 1.0, 1e3] {
        // A tilted triangle far from the origin (large coordinates) and a sphere.
        let off = Vec3::new(3.0, -2.0, 5.0) * scale;
        let tri = Shape::Triangle {
            p: [
                off + Vec3::new(-1.0, 0.0, -1.0) * scale,
                off + Vec3::new(1.0, 0.1, -1.0) * scale,
                off + Vec3::new(0.0, -0.1, 1.0) * scale,
            ],
        };
        let sph = Shape::Sphere {
            center: off + Vec3::new(0.0, 3.0, 0.0) * scale,
            radius: 0.7 * scale,
        };
        let accel = Accel::build(vec![tri, sph], BvhKind::Bvh2);
        let mut rng = Rng::for_sample(3, 0, scale.to_bits() as u64);
        let (mut hits, mut bad) = (0, 0);
        for i in 0..20_000 {
            let target_prim = i % 2;
            let target = if target_prim == 0 {
                off
            } else {
                off + Vec3::new(0.0, 3.0, 0.0) * scale
            };
            // Origins on a shell around the target, aimed at it with jitter: many grazing hits.
            let dir0 = camsim::render::sampling::uniform_sphere(rng.uniform(), rng.uniform());
            let o = target + dir0 * 4.0 * scale;
            let aim = target
                + (Vec3::new(rng.uniform(), rng.uniform(), rng.uniform()) - 0.5) * 1.6 * scale;
            let d = (aim - o).normalize();
            let Some(h) = accel.intersect(o, d, f32::INFINITY) else {
                continue;
            };
            hits += 1;
            let (p, err, n) = accel.shapes[h.prim as usize].surface(o, d, &h.h);
            assert!(p.is_finite() && err.is_finite() && n.is_finite());
            // Leave on the side we came from (reflection), at a grazing angle.
            let n_side = if n.dot(d) < 0.0 { n } else { -n };
            let t = (d - n_side * d.dot(n_side)).normalize_or_zero();
            let w = (t + n_side * 1e-3).normalize();
            let o2 = offset_ray_origin(p, err, n_side, w);
            if let Some(h2) = accel.intersect(o2, w, f32::INFINITY)
                && h2.prim == h.prim
                && h2.h.t < 1e-3 * scale
            {
                bad += 1;
            }
        }
        assert!(hits > 5000, "scale {scale}: too few hits ({hits})");
        assert_eq!(
            bad, 0,
            "scale {scale}: {bad} of {hits} spawned rays re-hit their own surface"
        );
    }
}

#[test]
fn lambertian_floor_under_uniform_sky_and_point_light() {
    // Open floor under a uniform infinite light L: E = πL, radiance ρL.
    // Then the same floor (sky removed) under a point light of intensity I at
    // height h: E = I/h² straight below, radiance ρI/(πh²).
    let (rho, l_sky, i_pt, h) = (0.6, 0.8, 0.05, 0.4);
    for case in ["sky", "point", "spot", "distant"] {
        let mut scene = Scene::default();
        let m = scene.material(
            "floor",
            Material::Diffuse {
                reflectance: constant(rho),
            },
        );
        let o = scene.object("floor");
        scene.meshes.push(quad(
            DVec3::ZERO,
            DVec3::Z * 50.0,
            DVec3::X * 50.0,
            m,
            o,
            None,
        ));
        let expected = if case == "sky" {
            scene.lights.push(camsim::scene::Light::Infinite {
                radiance: constant(l_sky),
            });
            rho * l_sky
        } else if case == "spot" {
            // Straight below the spot, well inside its 30° cone: like the point light.
            scene.lights.push(camsim::scene::Light::Spot {
                position: DVec3::new(0.0, h, 0.0),
                direction: -DVec3::Y,
                cone_angle_deg: 30.0,
                falloff_start_deg: 25.0,
                intensity: constant(i_pt),
            });
            rho * i_pt / (PI * h * h)
        } else if case == "distant" {
            // Irradiance E⊥ arriving at 60° from the normal: E = E⊥·cos 60°.
            let dir = DVec3::new(0.0, -0.5, 3f64.sqrt() / 2.0);
            scene.lights.push(camsim::scene::Light::Distant {
                direction: dir,
                irradiance: constant(l_sky),
            });
            rho * l_sky * 0.5 / PI
        } else {
            scene.lights.push(camsim::scene::Light::Point {
                position: DVec3::new(0.0, h, 0.0),
                intensity: constant(i_pt),
            });
            rho * i_pt / (PI * h * h)
        };
        with_camera(
            &mut scene,
            DVec3::new(0.0, 0.3, -0.3),
            DVec3::ZERO,
            0.5,
            2.0,
        );
        let film = FilmSpec {
            width_px: 8,
            height_px: 8,
            pixel_pitch_m: 1e-5,
            crop_window: None,
        };
        let cam = Pinhole::new(0.5, 2.0, &film).unwrap();
        let img = render(&scene, &cam, &film, &settings(512, 1)).unwrap();
        assert_all_finite(&img);
        let (l, se) = mean_over_weight(&img, &cam, &film, 12);
        eprintln!(
            "{case}: L/L_expected = {:.7} ± {:.7}",
            l / expected,
            se / expected
        );
        if case == "sky" {
            // NEE (uniform sphere) + cosine BSDF sampling with MIS; 32k paths give a
            // stderr ≲ 0.5 %, checked below; the tolerance is 4σ of this render.
            assert!(se / expected < 0.005, "{case}: stderr {}", se / expected);
            assert!(
                (l / expected - 1.0).abs() < 4.0 * se / expected,
                "{case}: L = {l}, expected {expected} (σ = {se})"
            );
        } else {
            // Point, spot and distant lights are sampled deterministically: the only
            // variation is the position within the ±6 mm pixel footprints (E ∝
            // cos³/r², relative change ~(6 mm/0.4 m)²/2 ≈ 1e-4 at the footprint
            // edge, averaging to a few 1e-5) and f32 rounding (~1e-6). Measured
            // |error| ≤ 3.3e-5; 1e-4 tolerance.
            assert!(
                (l / expected - 1.0).abs() < 1e-4,
                "{case}: L = {l}, expected {expected}"
            );
        }
    }
}

#[test]
fn dispersive_glass_in_a_white_furnace_conserves_energy() {
    // A non-absorbing dielectric inside a uniform environment of radiance L
    // leaves the radiance L everywhere, for every wavelength. The ior varies
    // with λ (1.6 at 400 nm to 1.5 at 700 nm), which switches the paths that
    // touch the glass to hero-wavelength sampling.
    let mut scene = Scene::default();
    let ior = Spectrum::new("ior", vec![400.0, 700.0], vec![1.6, 1.5])
        .unwrap()
        .with_extrapolation(camsim::spectrum::Extrapolation::Clamp);
    let g = scene.material("glass", Material::Dielectric { ior });
    let o = scene.object("ball");
    scene.spheres.push(camsim::scene::Sphere {
        center: DVec3::new(0.0, 0.0, 1.0),
        radius: 0.3,
        material: g,
        object: o,
        emission: None,
    });
    scene.lights.push(camsim::scene::Light::Infinite {
        radiance: constant(1.0),
    });
    with_camera(&mut scene, DVec3::ZERO, DVec3::Z, 10.0, 1.0);
    let film = FilmSpec {
        width_px: 8,
        height_px: 8,
        pixel_pitch_m: 1e-5,
        crop_window: None,
    };
    let cam = Pinhole::new(10.0, 1.0, &film).unwrap();
    let img = render(&scene, &cam, &film, &settings(2048, 64)).unwrap();
    assert_all_finite(&img);
    assert!(
        img.labels.iter().all(|&l| l == o),
        "the sphere must fill the view"
    );
    let mut all = 0.0;
    for b in 0..img.bands() {
        let (l, _) = mean_over_weight(&img, &cam, &film, b);
        all += l / img.bands() as f64;
        // Per band a path survives with probability 1/31 (×31 weight): ~131k
        // paths per image give ≈ 2–3 % stderr per band; 12 % is > 4σ.
        assert!((l - 1.0).abs() < 0.12, "band {b}: L = {l}");
    }
    eprintln!("dispersive furnace: band-mean L = {all:.5} (expected 1)");
    // Band average: stderr ≈ 0.5 %; 2 % tolerance.
    assert!((all - 1.0).abs() < 0.02, "band-mean L = {all}");
}

/// A pinhole that claims to be dispersive: forces hero-wavelength camera sampling.
struct DispersivePinhole(Pinhole);
impl Camera for DispersivePinhole {
    fn sample_ray(&self, f: DVec2, u: DVec2, l: f64) -> Option<camsim::optics::CameraRay> {
        self.0.sample_ray(f, u, l)
    }
    fn is_dispersive(&self) -> bool {
        true
    }
    fn describe(&self) -> String {
        "dispersive test pinhole".into()
    }
}

#[test]
fn hero_wavelength_camera_is_unbiased_in_the_furnace() {
    let mut scene = Scene::default();
    let m = scene.material(
        "wall",
        Material::Diffuse {
            reflectance: constant(0.5),
        },
    );
    let o = scene.object("enclosure");
    scene.meshes.push(cuboid(
        DVec3::splat(1.0),
        DMat4::IDENTITY,
        true,
        m,
        o,
        Some(Emission {
            radiance: constant(1.0),
            two_sided: false,
        }),
    ));
    with_camera(&mut scene, DVec3::ZERO, DVec3::Z, 20.0, 1.0);
    let film = FilmSpec {
        width_px: 8,
        height_px: 8,
        pixel_pitch_m: 1e-5,
        crop_window: None,
    };
    let cam = DispersivePinhole(Pinhole::new(20.0, 1.0, &film).unwrap());
    let img = render(&scene, &cam, &film, &settings(1024, 200)).unwrap();
    assert_all_finite(&img);
    let mut mean = 0.0;
    for b in 0..img.bands() {
        let (l, _) = mean_over_weight(&img, &cam.0, &film, b);
        mean += l / img.bands() as f64;
        // One band per path: ~2.1k effective paths per band, ≈ 2 % stderr; 10 % > 4σ.
        assert!((l / 2.0 - 1.0).abs() < 0.1, "band {b}: L = {l}");
    }
    eprintln!("hero camera furnace: band-mean L/Le = {mean:.5} (expected 2)");
    assert!((mean / 2.0 - 1.0).abs() < 0.02, "band-mean L/Le = {mean}");
}

#[test]
fn bad_render_inputs_are_errors_not_panics() {
    let (mut scene, film) = small_box_scene(1.0);
    let cam = Pinhole::new(70.0, 2.0, &film).unwrap();
    let mut s = settings(0, 6);
    assert!(render(&scene, &cam, &film, &s).is_err(), "spp 0");
    s.spp = 1;
    s.roi = Some(Rect::new(20, 0, 10, 5));
    assert!(
        render(&scene, &cam, &film, &s).is_err(),
        "ROI outside the film"
    );
    s.roi = None;
    let bad_film = FilmSpec {
        width_px: 0,
        ..film.clone()
    };
    assert!(render(&scene, &cam, &bad_film, &s).is_err(), "empty film");
    scene.meshes[0].material = 99;
    let e = render(&scene, &cam, &film, &s).unwrap_err().to_string();
    assert!(e.contains("walls") && e.contains("material 99"), "{e}");
    let (mut scene, _) = small_box_scene(1.0);
    scene.meshes[0].positions[0].x = f32::NAN;
    let e = render(&scene, &cam, &film, &s).unwrap_err().to_string();
    assert!(e.contains("walls") && e.contains("not finite"), "{e}");
}

#[test]
fn smooth_glass_sphere_vanishes_in_a_white_furnace() {
    // A non-absorbing, non-dispersive smooth dielectric (η = 1.5) inside a
    // uniform environment of radiance 1: every path reflects (weight 1) or
    // refracts (radiance × 1/η² going in, × η² coming out), so each path
    // returns exactly 1 and the sphere is invisible — in every pixel, band
    // and sample. Russian roulette never fires (throughput × η-scale = 1).
    // Bounce limit 1000: a path still inside after 1000 internal reflections
    // (probability < 0.99^1000 ≈ 4e-5 even at 86° incidence) would be lost.
    let mut scene = Scene::default();
    let g = scene.material("glass", Material::Dielectric { ior: constant(1.5) });
    let o = scene.object("ball");
    scene.spheres.push(camsim::scene::Sphere {
        center: DVec3::new(0.0, 0.0, 1.0),
        radius: 0.012,
        material: g,
        object: o,
        emission: None,
    });
    scene.lights.push(camsim::scene::Light::Infinite {
        radiance: constant(1.0),
    });
    // 2° field: the sphere (1.4° across) fills the centre, sky around it.
    with_camera(&mut scene, DVec3::ZERO, DVec3::Z, 2.0, 1.0);
    let film = FilmSpec {
        width_px: 16,
        height_px: 16,
        pixel_pitch_m: 1e-5,
        crop_window: None,
    };
    let cam = Pinhole::new(2.0, 1.0, &film).unwrap();
    let img = render(&scene, &cam, &film, &settings(64, 1000)).unwrap();
    assert_all_finite(&img);
    let on = img.labels.iter().filter(|&&l| l == o).count();
    assert!(on > 64 && on < 256, "sphere covers {on} of 256 pixels");
    let nb = img.bands();
    let mut worst = 0.0f64;
    for y in 0..img.height() {
        for x in 0..img.width() {
            let f = DVec2::new(
                (x as f64 + 0.5 - 8.0) * film.pixel_pitch_m,
                (8.0 - (y as f64 + 0.5)) * film.pixel_pitch_m,
            );
            let w = cam.sample_ray(f, DVec2::splat(0.5), 550.0).unwrap().weight;
            for b in 0..nb {
                let l = img.pixel(x, y)[b] as f64 / w;
                worst = worst.max((l - 1.0).abs());
            }
        }
    }
    eprintln!("glass furnace: max |L − 1| over pixels and bands = {worst:.2e}");
    // Residual: the cos⁴ weight varies across a pixel by < 2e-7 at this field
    // (θ ≤ 1°), f32 rounding of 1/η²·η² and of the pixel sums ~1e-6. Any
    // energy error of the dielectric (a wrong 1/η² or Fresnel split) is
    // ≥ 1e-2 on the sphere's pixels. Tolerance 1e-4.
    assert!(
        worst < 1e-4,
        "sphere visible in the furnace: max |L − 1| = {worst}"
    );
}

#[test]
fn uniform_wall_image_follows_cos4_over_the_whole_field() {
    // A 60° pinhole image of a uniform Lambertian emitter (radiance Le) facing
    // the camera: every pixel is the average over the pixel of
    // E(θ) = π Le/(4N²) cos⁴θ. The reference integrates that over each pixel
    // by an 8×8 midpoint rule (cos⁴ varies by up to 7 % across a corner pixel
    // here, nearly linearly: the rule's error is < 1e-5 relative), and the same sub-samples give the spread σ_px of
    // E within the pixel; the render averages 16 samples placed in the pixel,
    // so its error is at most σ_px/√16 (less if stratified). Tolerance 5 of
    // those (1200 pixels: a 5σ excursion has probability < 1e-3 overall)
    // + 1e-6 relative for f32 rounding. (The render's own 8-batch stderr has
    // 7 degrees of freedom, too noisy to bound each of 1200 pixels.)
    let (le, n) = (0.7, 4.0);
    let mut scene = Scene::default();
    let black = scene.material("black", Material::Black);
    let wall = scene.object("wall");
    scene.meshes.push(quad(
        DVec3::new(0.0, 0.0, 1.0),
        DVec3::Y * 10.0,
        DVec3::X * 10.0,
        black,
        wall,
        Some(Emission {
            radiance: constant(le),
            two_sided: false,
        }),
    ));
    with_camera(&mut scene, DVec3::ZERO, DVec3::Z, 60.0, n);
    let film = FilmSpec {
        width_px: 40,
        height_px: 30,
        pixel_pitch_m: 1e-5,
        crop_window: None,
    };
    let cam = Pinhole::new(60.0, n, &film).unwrap();
    let img = render(&scene, &cam, &film, &settings(16, 0)).unwrap();
    assert_all_finite(&img);
    let d = cam.film_distance_m;
    let p = film.pixel_pitch_m;
    let nb = img.bands();
    let (mut corner, mut worst_z) = (0.0f64, 0.0f64);
    // Mean relative deviation over all pixels and its standard error.
    let (mut dev, mut dev_var) = (0.0f64, 0.0f64);
    for y in 0..30u32 {
        for x in 0..40u32 {
            let (mut e_ref, mut e2) = (0.0, 0.0);
            for a in 0..8 {
                for b in 0..8 {
                    let fx = (x as f64 + (b as f64 + 0.5) / 8.0 - 20.0) * p;
                    let fy = (15.0 - (y as f64 + (a as f64 + 0.5) / 8.0)) * p;
                    let c = d / (fx * fx + fy * fy + d * d).sqrt();
                    let e = PI * le / (4.0 * n * n) * c.powi(4);
                    e_ref += e / 64.0;
                    e2 += e * e / 64.0;
                }
            }
            let sigma = (e2 - e_ref * e_ref).max(0.0).sqrt() / 4.0;
            let i = (y * 40 + x) as usize * nb + 10;
            let e = img.irradiance[i] as f64;
            let z = (e - e_ref).abs() / (5.0 * sigma + 1e-6 * e_ref);
            worst_z = worst_z.max(z);
            dev += (e / e_ref - 1.0) / 1200.0;
            dev_var += (sigma / e_ref / 1200.0).powi(2);
            if x == 0 && y == 0 {
                corner = e / e_ref;
            }
            assert!(
                z < 1.0,
                "pixel ({x}, {y}): E = {e}, cos⁴ reference {e_ref} (σ = {sigma})"
            );
        }
    }
    eprintln!(
        "cos⁴ field: corner E/E_ref = {corner:.6}, worst |ΔE|/(5σ + 1e-6 E) = {worst_z:.3}, \
         mean E/E_ref − 1 = {dev:.2e} ± {:.2e}",
        dev_var.sqrt()
    );
    // The whole field on average: 4 standard errors of the mean deviation.
    assert!(
        dev.abs() < 4.0 * dev_var.sqrt() + 1e-6,
        "mean deviation {dev}"
    );
}
