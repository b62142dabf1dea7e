//! POV-Ray export for a geometry sanity image: an independent renderer draws
//! the same meshes, spheres, disks and camera, so misplaced objects, flipped
//! axes or wrong scales are visible at a glance. Colours are each material's
//! reflectance under D65 in linear sRGB; emissive shapes become point lights at
//! their centroids plus a faint ambient term. Not radiometric.
//!
//! POV-Ray's frame is left-handed with y up, the same as camsim's world and
//! pbrt's, so coordinates are written unchanged.

use crate::scene::{CameraModel, FilmSpec, Material, Scene};
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
    format!("<{:.9},{:.9},{:.9}>", p.x, p.y, p.z)
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
    let rgb_of = |id: u32| -> [f64; 3] {
        scene
            .materials
            .get(id as usize)
            .map(|m| material_rgb(&m.material))
            .unwrap_or([0.5; 3])
    };
    let finish = "finish { ambient 0.15 diffuse 0.85 }";
    for mesh in &scene.meshes {
        if mesh.indices.is_empty() {
            continue;
        }
        let c = rgb_of(mesh.material);
        let _ = writeln!(s, "mesh2 {{\n  vertex_vectors {{ {}", mesh.positions.len());
        for p in &mesh.positions {
            let _ = writeln!(s, "    {}", v(p.as_dvec3()));
        }
        let _ = writeln!(s, "  }}\n  face_indices {{ {}", mesh.indices.len());
        for t in &mesh.indices {
            let _ = writeln!(s, "    <{},{},{}>", t[0], t[1], t[2]);
        }
        let _ = writeln!(
            s,
            "  }}\n  texture {{ pigment {{ rgb <{:.6},{:.6},{:.6}> }} {finish} }}\n}}",
            c[0], c[1], c[2]
        );
        if mesh.emission.is_some() {
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
        let c = rgb_of(sp.material);
        let _ = writeln!(
            s,
            "sphere {{ {}, {:.9} texture {{ pigment {{ rgb <{:.6},{:.6},{:.6}> }} {finish} }} }}",
            v(sp.center),
            sp.radius,
            c[0],
            c[1],
            c[2]
        );
        if sp.emission.is_some() {
            emit(sp.center, &mut s);
        }
    }
    for d in &scene.disks {
        let c = rgb_of(d.material);
        let _ = writeln!(
            s,
            "disc {{ {}, {}, {:.9} texture {{ pigment {{ rgb <{:.6},{:.6},{:.6}> }} {finish} }} }}",
            v(d.center),
            v(d.normal),
            d.radius,
            c[0],
            c[1],
            c[2]
        );
        if d.emission.is_some() {
            emit(d.center + d.normal.normalize_or_zero() * 1e-3, &mut s);
        }
    }
    for inst in &scene.instances {
        let t = inst.to_world;
        for &pi in &inst.prototype {
            let Some(mesh) = scene.meshes.get(pi) else {
                continue;
            };
            let c = rgb_of(mesh.material);
            let _ = writeln!(
                s,
                "object {{ mesh2 {{ vertex_vectors {{ {}",
                mesh.positions.len()
            );
            for p in &mesh.positions {
                let _ = write!(s, " {}", v(p.as_dvec3()));
            }
            let _ = write!(s, " }} face_indices {{ {}", mesh.indices.len());
            for tr in &mesh.indices {
                let _ = write!(s, " <{},{},{}>", tr[0], tr[1], tr[2]);
            }
            let col = |c: DVec4| format!("{:.9},{:.9},{:.9}", c.x, c.y, c.z);
            let _ = writeln!(
                s,
                " }} texture {{ pigment {{ rgb <{:.6},{:.6},{:.6}> }} {finish} }} }} matrix <{},{},{},{}> }}",
                c[0],
                c[1],
                c[2],
                col(t.x_axis),
                col(t.y_axis),
                col(t.z_axis),
                col(t.w_axis)
            );
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

/// Write the `.pov` file and, when `png` is given, render it with the `povray`
/// binary (Debian package `povray`). Errors name the missing tool.
pub fn export_and_render(
    scene: &Scene,
    film: &FilmSpec,
    pov_path: &Path,
    png: Option<&Path>,
) -> Result<()> {
    let text = scene_to_pov(scene, film)?;
    crate::diag::write_atomic(pov_path, text.as_bytes())?;
    if let Some(png) = png {
        let out = std::process::Command::new("povray")
            .arg(format!("+I{}", pov_path.display()))
            .arg(format!("+O{}", png.display()))
            .arg(format!("+W{}", film.width_px))
            .arg(format!("+H{}", film.height_px))
            .args(["+FN", "-D", "-V", "+A0.1", "-GA"])
            .output()
            .map_err(|e| {
                Error::invalid(format!(
                    "cannot run povray ({e}); install it with `apt-get install povray`"
                ))
            })?;
        if !out.status.success() {
            return Err(Error::invalid(format!(
                "povray failed on {}: {}",
                pov_path.display(),
                String::from_utf8_lossy(&out.stderr)
                    .lines()
                    .rev()
                    .take(5)
                    .collect::<Vec<_>>()
                    .join(" | ")
            )));
        }
    }
    Ok(())
}
