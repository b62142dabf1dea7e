//! POV-Ray scene text for the same geometry camsim renders.
//!
//! Two flavours share one geometry writer:
//! - `labels_to_pov`: one flat, unlit colour per object label (`finish {
//!   ambient 1 diffuse 0 }`, no lights), the colour encoding the label (see
//!   `label_colour`), and the pinhole-equivalent camera (`camera.rs`). What
//!   the sanity check compares with camsim's label buffer.
//! - `scene_to_pov`: a shaded picture to look at (`camsim pov --out F.pov`).
//!   Colours are each material's reflectance under D65 in linear sRGB;
//!   emissive shapes become point lights at their centroids plus a faint
//!   ambient term. Not radiometric.
//!
//! Geometry is written as camsim's world builder sees it (`render::world`):
//! meshes as `mesh2` in world coordinates (prototypes of instances are not
//! drawn on their own), instances as the prototype `mesh2` under a POV-Ray
//! `matrix` (POV-Ray applies the transform, not camsim), spheres as `sphere`,
//! disks as `disc` — POV-Ray's own primitives, so camsim's intersection of
//! curved shapes is checked too. Coordinates are written unchanged: POV-Ray's
//! frame and camsim's are both left-handed with y up, and the camera is
//! written as explicit vectors, so no convention is translated.

use super::camera::pov_vec;
use crate::scene::{CameraModel, FilmSpec, Material, MaterialId, ObjectId, Scene};
use crate::spectrum::color::reflectance_to_linear_srgb;
use crate::{Error, Result};
use glam::{DVec3, DVec4};
use std::fmt::Write;
use std::path::Path;

fn material_rgb(m: &Material) -> [f64; 3] {
    let c = match m {
        Material::Diffuse { reflectance } => reflectance_to_linear_srgb(reflectance),
        Material::DiffuseSpecular { diffuse, .. } => reflectance_to_linear_srgb(diffuse),
        Material::Mirror { reflectance } => reflectance_to_linear_srgb(reflectance),
        Material::Dielectric { .. } => [0.9, 0.9, 0.9],
        Material::Conductor { .. } => [0.7, 0.7, 0.7],
        Material::Black => [0.0, 0.0, 0.0],
    };
    c.map(|v| v.clamp(0.0, 1.0))
}

fn v(p: DVec3) -> String {
    pov_vec(p)
}

/// The flat colour POV-Ray paints object `id` with: `id + 1` in base 256 over
/// (r, g, b), each an exact multiple of 1/255, so an 8-bit PNG written with
/// `File_Gamma=1.0` gives the bytes back. Black (0, 0, 0) is the background.
/// None when `id + 1` does not fit in 24 bits.
pub fn label_colour(id: ObjectId) -> Option<[u8; 3]> {
    let c = id.checked_add(1)?;
    (c < 1 << 24).then_some([(c >> 16) as u8, (c >> 8) as u8, c as u8])
}

/// The object id painted with `rgb` (None: background black or the
/// colour of no id below `n_objects`).
pub fn label_of_colour(rgb: [u8; 3], n_objects: usize) -> Option<ObjectId> {
    let c = (rgb[0] as u32) << 16 | (rgb[1] as u32) << 8 | rgb[2] as u32;
    (c >= 1 && ((c - 1) as usize) < n_objects).then(|| c - 1)
}

/// Write the scene's shapes, each with `texture(material, object)`.
fn write_geometry(scene: &Scene, s: &mut String, texture: impl Fn(MaterialId, ObjectId) -> String) {
    let mut prototype = vec![false; scene.meshes.len()];
    for inst in &scene.instances {
        for &p in &inst.prototype {
            if let Some(x) = prototype.get_mut(p) {
                *x = true;
            }
        }
    }
    let mesh2 = |mesh: &crate::scene::Mesh, s: &mut String| {
        let _ = writeln!(s, "mesh2 {{\n  vertex_vectors {{ {}", mesh.positions.len());
        for p in &mesh.positions {
            let _ = writeln!(s, "    {}", v(p.as_dvec3()));
        }
        let _ = writeln!(s, "  }}\n  face_indices {{ {}", mesh.indices.len());
        for t in &mesh.indices {
            let _ = writeln!(s, "    <{},{},{}>", t[0], t[1], t[2]);
        }
        let _ = writeln!(s, "  }}");
    };
    for (i, mesh) in scene.meshes.iter().enumerate() {
        if mesh.indices.is_empty() || prototype[i] {
            continue;
        }
        mesh2(mesh, s);
        let _ = writeln!(s, "  {}\n}}", texture(mesh.material, mesh.object));
    }
    for sp in &scene.spheres {
        let _ = writeln!(
            s,
            "sphere {{ {}, {:?} {} }}",
            v(sp.center),
            sp.radius,
            texture(sp.material, sp.object)
        );
    }
    for d in &scene.disks {
        let _ = writeln!(
            s,
            "disc {{ {}, {}, {:?} {} }}",
            v(d.center),
            v(d.normal),
            d.radius,
            texture(d.material, d.object)
        );
    }
    for inst in &scene.instances {
        let t = inst.to_world;
        for &pi in &inst.prototype {
            let Some(mesh) = scene.meshes.get(pi) else {
                continue;
            };
            if mesh.indices.is_empty() {
                continue;
            }
            // POV-Ray's matrix acts on row vectors: its rows are glam's columns.
            let col = |c: DVec4| format!("{:?},{:?},{:?}", c.x, c.y, c.z);
            let _ = write!(s, "object {{ ");
            mesh2(mesh, s);
            let _ = writeln!(
                s,
                "  }}\n  {}\n  matrix <{},{},{},{}>\n}}",
                texture(mesh.material, inst.object.unwrap_or(mesh.object)),
                col(t.x_axis),
                col(t.y_axis),
                col(t.z_axis),
                col(t.w_axis)
            );
        }
    }
}

/// POV-Ray scene text painting each object label in its `label_colour`,
/// unlit and unshaded, seen by `camera`.
pub fn labels_to_pov(scene: &Scene, camera: &super::camera::PinholeEquivalent) -> Result<String> {
    if label_colour(scene.objects.len() as u32).is_none() {
        return Err(Error::invalid(format!(
            "{} object labels do not fit in 24-bit label colours",
            scene.objects.len()
        )));
    }
    let mut s = String::new();
    let _ = writeln!(
        s,
        "// camsim geometry sanity export: one flat colour per object label\n\
         // (colour = label id + 1 in base 256 over r, g, b; black = no object)\n\
         #version 3.7;\n\
         global_settings {{ assumed_gamma 1.0 ambient_light rgb <1,1,1> max_trace_level 1 }}\n\
         background {{ rgb <0,0,0> }}\n{}",
        camera.to_pov()
    );
    let texture = |_m: MaterialId, o: ObjectId| {
        // Labels past the scene's object list get the next unused colour.
        let c = label_colour(o.min(scene.objects.len() as u32)).unwrap_or([0; 3]);
        format!(
            "texture {{ pigment {{ rgb <{}/255,{}/255,{}/255> }} finish {{ ambient 1 diffuse 0 specular 0 phong 0 reflection 0 }} }} no_shadow",
            c[0], c[1], c[2]
        )
    };
    write_geometry(scene, &mut s, texture);
    Ok(s)
}

/// POV-Ray scene text for `scene` seen by its camera on `film`.
pub fn scene_to_pov(scene: &Scene, film: &FilmSpec) -> Result<String> {
    let cam = scene
        .camera
        .as_ref()
        .ok_or_else(|| Error::invalid("scene has no camera; POV-Ray export needs one"))?;
    let m = cam.to_world;
    let eye = m.transform_point3(DVec3::ZERO);
    let fwd = m.transform_vector3(DVec3::Z).normalize();
    let up = m.transform_vector3(DVec3::Y).normalize();
    let aspect = film.width_px as f64 / film.height_px.max(1) as f64;
    // Horizontal field of view for POV-Ray's `angle`.
    let hfov_deg = match &cam.model {
        CameraModel::Pinhole { fov_deg, .. } => {
            let half_short = (fov_deg.to_radians() / 2.0).tan();
            let half_w = if aspect >= 1.0 {
                half_short * aspect
            } else {
                half_short
            };
            2.0 * half_w.atan().to_degrees()
        }
        CameraModel::ThinLens { focal_length_m, .. } => {
            let w = film.width_px as f64 * film.pixel_pitch_m;
            2.0 * (w / 2.0 / focal_length_m).atan().to_degrees()
        }
        CameraModel::LensFile { .. } => {
            return Err(Error::NotSupported(
                "POV-Ray export of lens-file cameras (use a pinhole pose)".into(),
            ));
        }
    };
    let mut s = String::new();
    let _ = writeln!(
        s,
        "// camsim geometry sanity export\n#version 3.7;\nglobal_settings {{ assumed_gamma 1.0 ambient_light rgb <1,1,1> }}"
    );
    let _ = writeln!(
        s,
        "camera {{ perspective location {} look_at {} sky {} right x*{:.9} up y angle {:.9} }}",
        v(eye),
        v(eye + fwd),
        v(up),
        aspect,
        hfov_deg
    );
    let mut lights = 0;
    let mut emit = |p: DVec3, s: &mut String| {
        let _ = writeln!(s, "light_source {{ {} rgb <1,1,1> shadowless }}", v(p));
        lights += 1;
    };
    let finish = "finish { ambient 0.15 diffuse 0.85 }";
    let texture = |m: MaterialId, _o: ObjectId| {
        let c = scene
            .materials
            .get(m as usize)
            .map(|m| material_rgb(&m.material))
            .unwrap_or([0.5; 3]);
        format!(
            "texture {{ pigment {{ rgb <{:.6},{:.6},{:.6}> }} {finish} }}",
            c[0], c[1], c[2]
        )
    };
    write_geometry(scene, &mut s, texture);
    for mesh in &scene.meshes {
        if mesh.emission.is_some() && !mesh.positions.is_empty() {
            let n = mesh.positions.len() as f64;
            let centroid = mesh
                .positions
                .iter()
                .fold(DVec3::ZERO, |a, p| a + p.as_dvec3())
                / n;
            emit(centroid, &mut s);
        }
    }
    for sp in &scene.spheres {
        if sp.emission.is_some() {
            emit(sp.center, &mut s);
        }
    }
    for d in &scene.disks {
        if d.emission.is_some() {
            emit(d.center + d.normal.normalize_or_zero() * 1e-3, &mut s);
        }
    }
    for l in &scene.lights {
        match l {
            crate::scene::Light::Point { position, .. }
            | crate::scene::Light::Spot { position, .. } => emit(*position, &mut s),
            crate::scene::Light::Distant { direction, .. } => {
                emit(eye - direction.normalize_or_zero() * 1e4, &mut s)
            }
            crate::scene::Light::Infinite { .. } => emit(eye, &mut s),
        }
    }
    if lights == 0 {
        let _ = writeln!(s, "light_source {{ {} rgb <1,1,1> shadowless }}", v(eye));
    }
    Ok(s)
}

/// Write the `.pov` file and, when `png` is given, render it (antialiased)
/// with the `povray` binary at the film's size.
pub fn export_and_render(
    scene: &Scene,
    film: &FilmSpec,
    pov_path: &Path,
    png: Option<&Path>,
) -> Result<()> {
    let text = scene_to_pov(scene, film)?;
    crate::diag::write_atomic(pov_path, text.as_bytes())?;
    if let Some(png) = png {
        let bytes = super::povray::render_png(
            &text,
            film.width_px,
            film.height_px,
            super::povray::Mode::Preview,
        )?;
        crate::diag::write_atomic(png, &bytes)?;
    }
    Ok(())
}
