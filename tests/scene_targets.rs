//! Measurement targets: geometry, labels and materials, checked against hand-derived
//! positions and against the shipped `mccCB` export.

use camsim::scene::pbrt::{LoadOptions, load};
use camsim::scene::targets::{
    MccChart, PlacedMesh, SlantedEdge, add_mcc, add_mesh, add_slanted_edge,
};
use camsim::scene::{Material, Mesh, Scene};
use camsim::spectrum::library;
use glam::{DVec2, DVec3};
use std::path::PathBuf;

fn root() -> PathBuf {
    PathBuf::from(env!("CARGO_MANIFEST_DIR"))
}

fn centroid(m: &Mesh) -> DVec3 {
    let s: DVec3 = m
        .positions
        .iter()
        .map(|p| DVec3::new(p.x as f64, p.y as f64, p.z as f64))
        .sum();
    s / m.positions.len() as f64
}

fn bbox(m: &Mesh) -> (DVec3, DVec3) {
    let mut lo = DVec3::splat(f64::INFINITY);
    let mut hi = -lo;
    for p in &m.positions {
        let q = DVec3::new(p.x as f64, p.y as f64, p.z as f64);
        lo = lo.min(q);
        hi = hi.max(q);
    }
    (lo, hi)
}

fn normal(m: &Mesh, t: usize) -> DVec3 {
    let [a, b, c] = m.indices[t].map(|i| {
        let p = m.positions[i as usize];
        DVec3::new(p.x as f64, p.y as f64, p.z as f64)
    });
    (b - a).cross(c - a).normalize()
}

fn by_label<'a>(s: &'a Scene, label: &str) -> Vec<&'a Mesh> {
    let id = s
        .objects
        .iter()
        .position(|o| o.name == label)
        .unwrap_or_else(|| panic!("no object {label}")) as u32;
    s.meshes.iter().filter(|m| m.object == id).collect()
}

#[test]
fn mcc_layout_labels_and_spectra() {
    let mut s = Scene::default();
    let spec = MccChart {
        position_m: DVec3::ZERO,
        rotation_deg: DVec3::ZERO,
        ..MccChart::default()
    };
    add_mcc(&mut s, &spec).unwrap();
    assert_eq!(s.meshes.len(), 25);
    assert_eq!(s.objects.len(), 25);
    // chart centre at y = 0.028; pitch 0.014: patch 01 top-left, 04 bottom-left, 24 bottom-right
    let c = |n: usize| centroid(by_label(&s, &format!("mcc/patch{n:02}"))[0]);
    assert!(
        (c(1) - DVec3::new(-0.035, 0.049, -1e-4)).length() < 1e-7,
        "{}",
        c(1)
    );
    assert!(
        (c(4) - DVec3::new(-0.035, 0.007, -1e-4)).length() < 1e-7,
        "{}",
        c(4)
    );
    assert!(
        (c(5) - DVec3::new(-0.021, 0.049, -1e-4)).length() < 1e-7,
        "{}",
        c(5)
    );
    assert!(
        (c(24) - DVec3::new(0.035, 0.007, -1e-4)).length() < 1e-7,
        "{}",
        c(24)
    );
    let p4 = by_label(&s, "mcc/patch04")[0];
    let (lo, hi) = bbox(p4);
    assert!(((hi - lo).x - 0.01).abs() < 1e-7 && ((hi - lo).y - 0.01).abs() < 1e-7);
    assert!(
        (normal(p4, 0) + DVec3::Z).length() < 1e-6,
        "patches face -z"
    );
    match &s.materials[p4.material as usize].material {
        Material::Diffuse { reflectance } => {
            let w = library::named("mcc-mini-04").unwrap();
            assert_eq!(reflectance.eval(560.0), w.eval(560.0));
            assert!(w.eval(560.0) > 0.8, "patch 04 is the white patch");
        }
        m => panic!("{m:?}"),
    }
    let sur = by_label(&s, "mcc/surround")[0];
    assert_eq!(s.materials[sur.material as usize].material, Material::Black);
    let (lo, hi) = bbox(sur);
    assert!(
        (lo - DVec3::new(-0.042, 0.0, 0.0)).length() < 1e-7
            && (hi - DVec3::new(0.042, 0.056, 0.005)).length() < 1e-7
    );
}

#[test]
fn mcc_numbering_matches_the_shipped_export() {
    // The exported mccCB chart: patch PatchNN's centroid vs ours, both unrotated at the origin.
    let shipped = load(
        &root().join("scenes/mccCB/mccCB.pbrt"),
        &LoadOptions::default(),
    )
    .unwrap();
    let mut s = Scene::default();
    add_mcc(
        &mut s,
        &MccChart {
            position_m: DVec3::ZERO,
            rotation_deg: DVec3::ZERO,
            ..MccChart::default()
        },
    )
    .unwrap();
    for n in 1..=24 {
        let theirs = centroid(by_label(&shipped, &format!("MCC/Patch{n:02}"))[0]);
        let ours = centroid(by_label(&s, &format!("mcc/patch{n:02}"))[0]);
        // The export's grid is offset by 0.1 mm in x; 0.5 mm bounds that in x and y.
        let d = DVec2::new(theirs.x - ours.x, theirs.y - ours.y).length();
        assert!(d < 5e-4, "patch {n}: export {theirs} vs ours {ours}");
    }
}

#[test]
fn mcc_placement_rotates_then_translates() {
    let mut s = Scene::default();
    let spec = MccChart {
        position_m: DVec3::new(1.0, 2.0, 3.0),
        rotation_deg: DVec3::new(0.0, 90.0, 0.0),
        ..MccChart::default()
    };
    add_mcc(&mut s, &spec).unwrap();
    let p = by_label(&s, "mcc/patch01")[0];
    // local (-0.035, 0.049, -1e-4) rotated 90° about y: (x, y, z) → (z, y, −x)
    let want = DVec3::new(1.0 - 1e-4, 2.049, 3.035);
    assert!((centroid(p) - want).length() < 1e-6, "{}", centroid(p));
    assert!((normal(p, 0) + DVec3::X).length() < 1e-6);
    let bad = MccChart {
        patch_size_m: 0.02,
        ..MccChart::default()
    };
    assert!(add_mcc(&mut Scene::default(), &bad).is_err());
}

#[test]
fn slanted_edge_halves_and_tilt() {
    let mut s = Scene::default();
    let spec = SlantedEdge::new("edge-near", DVec3::new(0.05, 0.08, -0.10)).unwrap();
    add_slanted_edge(&mut s, &spec).unwrap();
    assert_eq!(s.objects.len(), 1);
    assert!(s.meshes.iter().all(|m| m.object == 0));
    let area = |m: &Mesh| -> f64 {
        (0..m.indices.len())
            .map(|t| {
                let [a, b, c] = m.indices[t].map(|i| {
                    let p = m.positions[i as usize];
                    DVec3::new(p.x as f64, p.y as f64, p.z as f64)
                });
                0.5 * (b - a).cross(c - a).length()
            })
            .sum()
    };
    let (white, black) = (&s.meshes[0], &s.meshes[1]);
    assert!(matches!(
        s.materials[white.material as usize].material,
        Material::Diffuse { .. }
    ));
    assert_eq!(
        s.materials[black.material as usize].material,
        Material::Black
    );
    // a line through the centre halves the rectangle
    let half = 0.5 * 0.096 * 0.156;
    assert!((area(white) - half).abs() < 1e-9 && (area(black) - half).abs() < 1e-9);
    for t in 0..white.indices.len() {
        assert!((normal(white, t) + DVec3::Z).length() < 1e-6);
    }
    // the two white vertices on the edge line: their direction is 5° from vertical,
    // leaning to +x at the top (clockwise seen from the camera)
    let on_edge: Vec<DVec3> = white
        .positions
        .iter()
        .map(|p| DVec3::new(p.x as f64, p.y as f64, p.z as f64))
        .filter(|p| {
            black
                .positions
                .iter()
                .any(|q| (DVec3::new(q.x as f64, q.y as f64, q.z as f64) - *p).length() < 1e-9)
        })
        .collect();
    assert_eq!(on_edge.len(), 2);
    let (a, b) = if on_edge[0].y < on_edge[1].y {
        (on_edge[0], on_edge[1])
    } else {
        (on_edge[1], on_edge[0])
    };
    let ang = ((b.x - a.x) / (b.y - a.y)).atan().to_degrees();
    assert!((ang - 5.0).abs() < 1e-4, "{ang}");
    // the edge passes through the plate centre (the position)
    let mid_t = (0.08 - a.y) / (b.y - a.y);
    assert!((a.x + mid_t * (b.x - a.x) - 0.05).abs() < 1e-7);
    // white on the −x side
    assert!(centroid(white).x < 0.05 && centroid(black).x > 0.05);
}

#[test]
fn bunny_placed_on_the_floor() {
    let mut s = Scene::default();
    let spec = PlacedMesh::bunny(&root().join("scenes/bunny.obj")).unwrap();
    add_mesh(&mut s, &spec).unwrap();
    assert_eq!(s.triangle_count(), 3674);
    assert_eq!(s.meshes[0].positions.len(), 1839);
    let (lo, hi) = bbox(&s.meshes[0]);
    // height 1.445 × (2·0.058/1.445) = 0.116 m, centred at y = 0.058: base on the floor
    assert!(
        lo.y.abs() < 1e-6 && (hi.y - 0.116).abs() < 1e-6,
        "{lo} {hi}"
    );
    assert_eq!(s.objects[0].name, "bunny");
    let missing = PlacedMesh {
        path: root().join("scenes/nope.obj"),
        ..spec
    };
    let e = add_mesh(&mut Scene::default(), &missing)
        .unwrap_err()
        .to_string();
    assert!(e.contains("nope.obj"), "{e}");
}
