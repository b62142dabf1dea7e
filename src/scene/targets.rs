//! Measurement targets built as labelled geometry: the miniature Macbeth
//! ColorChecker (MCC), a slanted-edge plate, and an OBJ mesh (the bunny) placed
//! by scale, rotation and position. Defaults come from
//! `data/cornellbox/cornellbox_setup.json`.
//!
//! Frames: each target is built in a local frame, rotated by `rotation_deg = [rx, ry,
//! rz]` (applied x first, then y, then z: R = Rz·Ry·Rx, right-handed, degrees) and then
//! translated by `position_m`. Targets face −z in their local frame (towards a camera
//! at −z looking along +z, the Cornell box convention).
//!
//! - MCC: the local origin is the bottom centre of the chart's front face (as in the
//!   exported `mccCB` asset, whose chart spans y ∈ [0, 0.056] m). A black box
//!   `width × height × thickness` (label `<name>/surround`, material Black) holds 24
//!   square patches 0.1 mm proud of its front face, 4 rows × 6 columns, numbered
//!   column-major from the top-left (patch 04 = bottom of the first column = white,
//!   as `data/README.md` says), reflectances `mcc-mini-01…24`, labels
//!   `<name>/patch01…24`. The patch grid is centred on the chart.
//! - Slanted edge: a plate `width × height × thickness` centred on its local origin,
//!   its front face split by a line through the centre, tilted by `tilt_deg` from the
//!   local +y axis (positive = clockwise as seen from the camera); the −x side is white
//!   (default `cbox-white-wall`, the box's own paint), the +x side Black. All faces
//!   carry the single label `<name>`.
//! - Mesh (bunny): the OBJ is centred on its bounding-box centre, scaled so its height
//!   is `height_m`, then by `scale`, rotated by `rot_y_deg` about y and its bounding-box
//!   centre placed at `position_m`. The shipped OBJ is in arbitrary units; the default
//!   `height_m = 2·0.058/1.445 ≈ 0.0803 m` is derived from the paper's placement
//!   (scale 1.445, centre y = 0.058 m) under the assumption that the bunny rests on
//!   the floor.

// `!(x > 0.0)` is deliberate: it rejects NaN along with non-positive values.
#![allow(clippy::neg_cmp_op_on_partial_ord)]

use crate::diag::{Error, Result};
use crate::scene::{Material, Mesh, Scene};
use crate::spectrum::{Spectrum, library};
use glam::{DMat3, DMat4, DVec2, DVec3, Vec3};
use std::path::Path;

/// The world-from-local transform of a target.
pub fn placement(position_m: DVec3, rotation_deg: DVec3) -> DMat4 {
    let r = DMat4::from_rotation_z(rotation_deg.z.to_radians())
        * DMat4::from_rotation_y(rotation_deg.y.to_radians())
        * DMat4::from_rotation_x(rotation_deg.x.to_radians());
    DMat4::from_translation(position_m) * r
}

fn check_finite(what: &str, v: &[f64]) -> Result<()> {
    if v.iter().all(|x| x.is_finite()) {
        Ok(())
    } else {
        Err(Error::invalid(format!(
            "{what}: all numbers must be finite"
        )))
    }
}

fn push_mesh(
    scene: &mut Scene,
    xf: &DMat4,
    pos: &[DVec3],
    tris: Vec<[u32; 3]>,
    material: u32,
    object: u32,
) {
    let positions = pos
        .iter()
        .map(|&p| {
            let q = xf.transform_point3(p);
            Vec3::new(q.x as f32, q.y as f32, q.z as f32)
        })
        .collect();
    scene.meshes.push(Mesh {
        positions,
        normals: None,
        uvs: None,
        indices: tris,
        material,
        object,
        emission: None,
    });
}

/// A quad facing −z at depth `z` with corners (x0,y0)–(x1,y1) (wound so the normal is −z).
fn quad_front(x0: f64, y0: f64, x1: f64, y1: f64, z: f64) -> (Vec<DVec3>, Vec<[u32; 3]>) {
    let p = vec![
        DVec3::new(x0, y0, z),
        DVec3::new(x1, y0, z),
        DVec3::new(x1, y1, z),
        DVec3::new(x0, y1, z),
    ];
    // (p1−p0)×(p2−p0) = (+x)×(+x+y) = +z, so reverse for −z
    (p, vec![[0, 2, 1], [0, 3, 2]])
}

/// An axis-aligned box [lo, hi] with outward-facing triangles.
fn box_mesh(lo: DVec3, hi: DVec3) -> (Vec<DVec3>, Vec<[u32; 3]>) {
    let c = |i: u32| {
        DVec3::new(
            if i & 1 == 0 { lo.x } else { hi.x },
            if i & 2 == 0 { lo.y } else { hi.y },
            if i & 4 == 0 { lo.z } else { hi.z },
        )
    };
    let p: Vec<DVec3> = (0..8).map(c).collect();
    let mut t = vec![];
    // faces as (a, b, c, d) counter-clockwise seen from outside
    for f in [
        [0u32, 2, 3, 1],
        [4, 5, 7, 6],
        [0, 1, 5, 4],
        [2, 6, 7, 3],
        [0, 4, 6, 2],
        [1, 3, 7, 5],
    ] {
        t.push([f[0], f[1], f[2]]);
        t.push([f[0], f[2], f[3]]);
    }
    (p, t)
}

/// The miniature Macbeth chart (see module docs).
#[derive(Clone, Debug, PartialEq)]
pub struct MccChart {
    pub name: String,
    /// Bottom centre of the chart's front face, world metres.
    pub position_m: DVec3,
    pub rotation_deg: DVec3,
    pub width_m: f64,
    pub height_m: f64,
    pub thickness_m: f64,
    pub patch_size_m: f64,
    pub patch_pitch_m: f64,
}

impl Default for MccChart {
    /// cornellbox_setup.json `scene.mcc`: 1 cm patches on a 1.4 cm pitch, chart 8.4 × 5.6 cm
    /// (the `mccCB` substrate, 5 mm thick), at [0.006, 0.035, 0.125] m rotated [4, 0, 1]°.
    fn default() -> Self {
        Self {
            name: "mcc".into(),
            position_m: DVec3::new(0.006, 0.035, 0.125),
            rotation_deg: DVec3::new(4.0, 0.0, 1.0),
            width_m: 0.084,
            height_m: 0.056,
            thickness_m: 0.005,
            patch_size_m: 0.01,
            patch_pitch_m: 0.014,
        }
    }
}

/// Row (0 = top) and column (0 = left, seen from the camera) of 1-based patch `n`,
/// column-major with 4 rows.
pub fn mcc_patch_row_col(n: usize) -> (usize, usize) {
    ((n - 1) % 4, (n - 1) / 4)
}

/// Centre of patch `n` in the chart's local frame (origin at the bottom centre).
pub fn mcc_patch_centre_local(spec: &MccChart, n: usize) -> DVec2 {
    let (row, col) = mcc_patch_row_col(n);
    // Seen from a camera at −z looking +z with +y up, image right is world +x.
    DVec2::new(
        (col as f64 - 2.5) * spec.patch_pitch_m,
        0.5 * spec.height_m + (1.5 - row as f64) * spec.patch_pitch_m,
    )
}

/// Add the chart to `scene`.
pub fn add_mcc(scene: &mut Scene, spec: &MccChart) -> Result<()> {
    check_finite(
        "mcc",
        &[
            spec.width_m,
            spec.height_m,
            spec.thickness_m,
            spec.patch_size_m,
            spec.patch_pitch_m,
        ],
    )?;
    check_finite("mcc position/rotation", &spec.position_m.to_array())?;
    check_finite("mcc position/rotation", &spec.rotation_deg.to_array())?;
    let ok = spec.patch_size_m > 0.0
        && spec.patch_size_m <= spec.patch_pitch_m
        && 6.0 * spec.patch_pitch_m <= spec.width_m + 1e-12
        && 4.0 * spec.patch_pitch_m <= spec.height_m + 1e-12
        && spec.thickness_m > 0.0;
    if !ok {
        return Err(Error::invalid(format!(
            "mcc '{}': need 0 < patch size ≤ pitch, 6·pitch ≤ width, 4·pitch ≤ height, thickness > 0",
            spec.name
        )));
    }
    let xf = placement(spec.position_m, spec.rotation_deg);
    let black = scene.material("mcc-surround", Material::Black);
    let surround = scene.object(&format!("{}/surround", spec.name));
    let (p, t) = box_mesh(
        DVec3::new(-0.5 * spec.width_m, 0.0, 0.0),
        DVec3::new(0.5 * spec.width_m, spec.height_m, spec.thickness_m),
    );
    push_mesh(scene, &xf, &p, t, black, surround);
    let half = 0.5 * spec.patch_size_m;
    for n in 1..=24 {
        let sname = format!("mcc-mini-{n:02}");
        let refl = library::named(&sname).map_err(Error::invalid)?;
        let m = scene.material(&sname, Material::Diffuse { reflectance: refl });
        let o = scene.object(&format!("{}/patch{n:02}", spec.name));
        let c = mcc_patch_centre_local(spec, n);
        let (p, t) = quad_front(c.x - half, c.y - half, c.x + half, c.y + half, -1e-4);
        push_mesh(scene, &xf, &p, t, m, o);
    }
    Ok(())
}

/// A slanted-edge plate (see module docs).
#[derive(Clone, Debug, PartialEq)]
pub struct SlantedEdge {
    pub name: String,
    /// Centre of the plate, world metres.
    pub position_m: DVec3,
    pub rotation_deg: DVec3,
    pub width_m: f64,
    pub height_m: f64,
    pub thickness_m: f64,
    pub tilt_deg: f64,
    pub white: Spectrum,
}

impl SlantedEdge {
    /// cornellbox_setup.json `slanted_edges_fig6`: plate 0.096 × 0.156 × 0.012 m, tilt 5°.
    pub fn new(name: &str, position_m: DVec3) -> Result<Self> {
        Ok(Self {
            name: name.into(),
            position_m,
            rotation_deg: DVec3::ZERO,
            width_m: 0.096,
            height_m: 0.156,
            thickness_m: 0.012,
            tilt_deg: 5.0,
            white: library::named("cbox-white-wall").map_err(Error::invalid)?,
        })
    }
}

/// Clip a convex polygon to the half-plane n·p ≤ 0 (Sutherland–Hodgman, one plane).
fn clip(poly: &[DVec2], n: DVec2) -> Vec<DVec2> {
    let mut out = vec![];
    for i in 0..poly.len() {
        let (a, b) = (poly[i], poly[(i + 1) % poly.len()]);
        let (da, db) = (n.dot(a), n.dot(b));
        if da <= 0.0 {
            out.push(a);
        }
        if (da < 0.0 && db > 0.0) || (da > 0.0 && db < 0.0) {
            out.push(a + (b - a) * (da / (da - db)));
        }
    }
    out
}

/// Unit normal of the edge line in the plate's local xy plane; the white side has n·p ≤ 0.
pub fn slanted_edge_normal(tilt_deg: f64) -> DVec2 {
    // Edge direction: +y rotated clockwise (seen from −z, image right = +x) by tilt.
    let t = tilt_deg.to_radians();
    let dir = DVec2::new(t.sin(), t.cos());
    DVec2::new(dir.y, -dir.x)
}

/// Add the slanted-edge plate to `scene`.
pub fn add_slanted_edge(scene: &mut Scene, spec: &SlantedEdge) -> Result<()> {
    check_finite(
        "slanted edge",
        &[spec.width_m, spec.height_m, spec.thickness_m, spec.tilt_deg],
    )?;
    check_finite(
        "slanted edge position/rotation",
        &spec.position_m.to_array(),
    )?;
    check_finite(
        "slanted edge position/rotation",
        &spec.rotation_deg.to_array(),
    )?;
    if !(spec.width_m > 0.0 && spec.height_m > 0.0 && spec.thickness_m > 0.0)
        || spec.tilt_deg.abs() >= 45.0
    {
        return Err(Error::invalid(format!(
            "slanted edge '{}': sizes must be > 0 and |tilt| < 45°",
            spec.name
        )));
    }
    let xf = placement(spec.position_m, spec.rotation_deg);
    let obj = scene.object(&spec.name);
    let white = scene.material(
        &format!("{}-white", spec.name),
        Material::Diffuse {
            reflectance: spec.white.clone(),
        },
    );
    let black = scene.material(&format!("{}-black", spec.name), Material::Black);
    let (w, h, t) = (0.5 * spec.width_m, 0.5 * spec.height_m, spec.thickness_m);
    let rect = [
        DVec2::new(-w, -h),
        DVec2::new(w, -h),
        DVec2::new(w, h),
        DVec2::new(-w, h),
    ];
    let n = slanted_edge_normal(spec.tilt_deg);
    for (side, m) in [(n, white), (-n, black)] {
        let poly = clip(&rect, side);
        let z = -0.5 * t;
        let p: Vec<DVec3> = poly.iter().map(|q| DVec3::new(q.x, q.y, z)).collect();
        // fan, counter-clockwise in xy → normal +z; reversed for −z
        let tris = (1..poly.len() as u32 - 1).map(|i| [0, i + 1, i]).collect();
        push_mesh(scene, &xf, &p, tris, m, obj);
    }
    // the rest of the plate (sides and back), black
    let (p, mut tris) = box_mesh(DVec3::new(-w, -h, -0.5 * t), DVec3::new(w, h, 0.5 * t));
    tris.retain(|tr| !tr.iter().all(|&i| p[i as usize].z < 0.0));
    push_mesh(scene, &xf, &p, tris, black, obj);
    Ok(())
}

/// An OBJ mesh placed in the scene (see module docs).
#[derive(Clone, Debug, PartialEq)]
pub struct PlacedMesh {
    pub name: String,
    pub path: std::path::PathBuf,
    /// World position of the bounding-box centre, metres.
    pub position_m: DVec3,
    pub scale: f64,
    pub rot_y_deg: f64,
    /// Height of the mesh before `scale`, metres.
    pub height_m: f64,
    pub reflectance: Spectrum,
}

impl PlacedMesh {
    /// The paper's bunny: cornellbox_setup.json `scene.bunny` (scale 1.445, at
    /// [0.098, 0.058, 0.0] m, rotated 3° about y, white).
    pub fn bunny(path: &Path) -> Result<Self> {
        Ok(Self {
            name: "bunny".into(),
            path: path.to_path_buf(),
            position_m: DVec3::new(0.098, 0.058, 0.0),
            scale: 1.445,
            rot_y_deg: 3.0,
            height_m: 2.0 * 0.058 / 1.445,
            reflectance: library::named("cbox-white-wall").map_err(Error::invalid)?,
        })
    }
}

/// Load an OBJ with `tobj` and add it to `scene` (see module docs).
pub fn add_mesh(scene: &mut Scene, spec: &PlacedMesh) -> Result<()> {
    check_finite(
        "mesh placement",
        &[spec.scale, spec.rot_y_deg, spec.height_m],
    )?;
    check_finite("mesh placement", &spec.position_m.to_array())?;
    if !(spec.scale > 0.0 && spec.height_m > 0.0) {
        return Err(Error::invalid(format!(
            "mesh '{}': scale and height must be > 0",
            spec.name
        )));
    }
    let (models, _) = tobj::load_obj(
        &spec.path,
        &tobj::LoadOptions {
            triangulate: true,
            single_index: true,
            ..Default::default()
        },
    )
    .map_err(|e| Error::io(&spec.path, e))?;
    let mut pos: Vec<DVec3> = vec![];
    let mut tris: Vec<[u32; 3]> = vec![];
    for m in &models {
        let base = pos.len() as u32;
        pos.extend(
            m.mesh
                .positions
                .chunks_exact(3)
                .map(|c| DVec3::new(c[0] as f64, c[1] as f64, c[2] as f64)),
        );
        tris.extend(
            m.mesh
                .indices
                .chunks_exact(3)
                .map(|c| [base + c[0], base + c[1], base + c[2]]),
        );
    }
    if tris.is_empty() {
        return Err(Error::invalid(format!(
            "{}: no triangles",
            spec.path.display()
        )));
    }
    let lo = pos
        .iter()
        .fold(DVec3::splat(f64::INFINITY), |a, &b| a.min(b));
    let hi = pos
        .iter()
        .fold(DVec3::splat(f64::NEG_INFINITY), |a, &b| a.max(b));
    let h = hi.y - lo.y;
    if !(h > 0.0) {
        return Err(Error::invalid(format!(
            "{}: the mesh has no height",
            spec.path.display()
        )));
    }
    let k = spec.height_m / h * spec.scale;
    let centre = 0.5 * (lo + hi);
    let xf = DMat4::from_translation(spec.position_m)
        * DMat4::from_mat3(DMat3::from_rotation_y(spec.rot_y_deg.to_radians()))
        * DMat4::from_scale(DVec3::splat(k))
        * DMat4::from_translation(-centre);
    let m = scene.material(
        &format!("{}-material", spec.name),
        Material::Diffuse {
            reflectance: spec.reflectance.clone(),
        },
    );
    let o = scene.object(&spec.name);
    push_mesh(scene, &xf, &pos, tris, m, o);
    Ok(())
}
