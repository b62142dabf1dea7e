//! camsim's own pbrt-v4 scene parser, reading pbrt-v3 files with their v4 meaning
//! except for lights, which keep pbrt-v3's literal meaning in files whose syntax is
//! pbrt-v3 ([`dialect`]; `scene info` reports the version and [`differences`]).
//!
//! `load(path, &LoadOptions)` returns a [`Scene`]; every error is a
//! `diag::Located` (file:line:col with the source line); non-fatal notes
//! (unsupported features with the fallback used, pbrt-v3 forms, unused
//! parameters) go to `Scene::warnings` as `file:line:col: warning: …`, or are
//! errors with `strict`.
//!
//! Modules: [`lexer`] (tokens with byte spans), [`params`] (typed parameter lists,
//! spectra), [`parser`] (directives, graphics state, includes), [`to_scene`]
//! (mapping onto the scene model), PLY via [`crate::scene::mesh_io::read_ply`], [`subdiv`], [`paper`] (the paper's
//! spectra for the ISET Cornell box), [`bench`](mod@bench).
//!
//! ## Object labels
//! Every shape gets an object label (`Scene::objects`), chosen in this order:
//! 1. inside `ObjectBegin "name"` … `ObjectEnd`: `name`;
//! 2. the `#ObjectName NAME:…` comments of the enclosing `AttributeBegin` blocks
//!    (written by the Cinema 4D exporter of the ISET scenes), joined by `/`
//!    (consecutive repeats collapsed), followed by `/MATERIAL` when the shape's
//!    `NamedMaterial` differs from the last name — e.g. `Box/LeftWall`, `MCC/Patch04`,
//!    `CubeSmall`;
//! 3. the current `NamedMaterial` name (e.g. `LeftWall` in the Bitterli box);
//! 4. `shape<N>`, N the 0-based index of the `Shape` directive in the file.
//!
//! Shapes with the same label share one object id.
//!
//! ## Instances
//! Shapes between `ObjectBegin`/`ObjectEnd` become meshes (spheres and disks are
//! tessellated) in the coordinates they were defined in; `ObjectInstance` adds an
//! `Instance` whose `to_world` is the CTM at the instance; its label override is the
//! `#ObjectName` path around the `ObjectInstance`, if any (else the prototype's label). Meshes listed in
//! [`LoadedScene::prototypes`] (also named by any instance) are not drawn on their own.

// `!(x > 0.0)` is deliberate throughout: it rejects NaN along with non-positive values.
#![allow(clippy::neg_cmp_op_on_partial_ord)]

pub mod bench;
pub mod dialect;
pub mod differences;
pub mod lexer;
pub mod paper;
pub mod params;
pub mod parser;
pub mod subdiv;
pub mod to_scene;

use crate::diag::{Error, Located, Result};
use crate::scene::Scene;
use glam::{DVec3, Vec3};
use params::SpanError;
use std::path::{Path, PathBuf};

/// Loading options.
#[derive(Clone, Debug, Default)]
pub struct LoadOptions {
    /// Warnings (unsupported features, unused parameters, pbrt-v3 forms) become errors.
    pub strict: bool,
    /// Read the file as this pbrt version instead of the one its syntax shows
    /// (see [`dialect`]).
    pub pbrt_version: Option<dialect::PbrtVersion>,
}

/// A parsed scene plus what the model does not hold.
#[derive(Clone, Debug)]
pub struct LoadedScene {
    pub scene: Scene,
    /// Indices into `scene.meshes` of instance prototypes (not drawn on their own).
    pub prototypes: Vec<usize>,
    /// Number of `Shape` directives read.
    pub shape_directives: usize,
    /// The pbrt version the file was read as, and why.
    pub dialect: dialect::Dialect,
    /// The wavelength grid a `spectral` film asks for (None: camsim's default).
    pub spectral_grid: Option<crate::spectrum::WavelengthGrid>,
}

/// Load a pbrt scene file (v4, or v3; see the module docs).
pub fn load(path: &Path, opts: &LoadOptions) -> Result<Scene> {
    Ok(load_full(path, opts)?.scene)
}

/// Load, returning the prototype list too.
pub fn load_full(path: &Path, opts: &LoadOptions) -> Result<LoadedScene> {
    let text = parser::read_source(path).map_err(|m| Error::io(path, m))?;
    parse_text(&text, path, opts)
}

/// Parse scene text as if it were the file `path` (used for diagnostics and as the
/// base directory of relative paths).
pub fn parse_text(text: &str, path: &Path, opts: &LoadOptions) -> Result<LoadedScene> {
    let base: PathBuf = path.parent().map(|p| p.to_path_buf()).unwrap_or_default();
    let mut p = parser::Parser::new(opts.strict, base);
    p.ctx.dialect = dialect::decide(text, opts.pbrt_version);
    p.push_source(path.to_path_buf(), text.to_string());
    let r = p.run();
    if let Err(e) = r {
        return Err(located(&p, &e).into());
    }
    // Identical messages are reported once, with the location of the first and a count.
    let mut order: Vec<&str> = vec![];
    let mut seen: std::collections::HashMap<&str, (usize, &SpanError)> =
        std::collections::HashMap::new();
    for w in &p.ctx.warnings {
        let e = seen.entry(w.message.as_str()).or_insert_with(|| {
            order.push(w.message.as_str());
            (0, w)
        });
        e.0 += 1;
    }
    let warnings: Vec<String> = order
        .iter()
        .map(|m| {
            let (n, w) = seen[m];
            let t = warning_text(&p, w);
            if n > 1 {
                format!("{t} (and {} more like this)", n - 1)
            } else {
                t
            }
        })
        .collect();
    let mut scene = std::mem::take(&mut p.scene);
    scene.warnings.extend(warnings);
    Ok(LoadedScene {
        scene,
        prototypes: p.prototypes.clone(),
        shape_directives: p.shape_count,
        dialect: p.ctx.dialect.clone(),
        spectral_grid: p.film.as_ref().and_then(|f| f.spectral_grid.clone()),
    })
}

fn located(p: &parser::Parser, e: &SpanError) -> Located {
    let f = &p.files[(e.span.file as usize).min(p.files.len().saturating_sub(1))];
    let len = e.span.end.saturating_sub(e.span.start).max(1);
    Located::at_offset(&f.path, &f.text, e.span.start, len, e.message.clone())
        .with_help_opt(e.help.clone())
}

fn warning_text(p: &parser::Parser, w: &SpanError) -> String {
    let l = located(p, w);
    format!(
        "{}:{}:{}: warning: {}",
        l.file.display(),
        l.line,
        l.col,
        l.message
    )
}

/// Which meshes are instance prototypes: those named by any `Instance::prototype`.
/// The pbrt loader never lists a prototype as a plain mesh too, so a renderer draws
/// mesh `i` directly exactly when `!prototype_mask(scene)[i]`.
pub fn prototype_mask(scene: &Scene) -> Vec<bool> {
    let mut m = vec![false; scene.meshes.len()];
    for inst in &scene.instances {
        for &i in &inst.prototype {
            if let Some(x) = m.get_mut(i) {
                *x = true;
            }
        }
    }
    m
}

/// Axis-aligned world bounds of everything drawn (plain meshes, instances, spheres,
/// disks), or None for an empty scene.
pub fn world_bounds(scene: &Scene, prototypes: &[usize]) -> Option<(DVec3, DVec3)> {
    let mut lo = DVec3::splat(f64::INFINITY);
    let mut hi = DVec3::splat(f64::NEG_INFINITY);
    let mut add = |q: DVec3| {
        lo = lo.min(q);
        hi = hi.max(q);
    };
    let d = |v: &Vec3| DVec3::new(v.x as f64, v.y as f64, v.z as f64);
    for (i, m) in scene.meshes.iter().enumerate() {
        if prototypes.contains(&i) {
            continue;
        }
        for t in &m.indices {
            for &k in t {
                add(d(&m.positions[k as usize]));
            }
        }
    }
    for inst in &scene.instances {
        for &mi in &inst.prototype {
            if let Some(m) = scene.meshes.get(mi) {
                for q in &m.positions {
                    add(inst.to_world.transform_point3(d(q)));
                }
            }
        }
    }
    for s in &scene.spheres {
        add(s.center - DVec3::splat(s.radius));
        add(s.center + DVec3::splat(s.radius));
    }
    for k in &scene.disks {
        // exact box of a disk: centre ± r·sqrt(1 − n_i²) per axis
        let e = DVec3::new(
            (1.0 - k.normal.x * k.normal.x).max(0.0).sqrt(),
            (1.0 - k.normal.y * k.normal.y).max(0.0).sqrt(),
            (1.0 - k.normal.z * k.normal.z).max(0.0).sqrt(),
        ) * k.radius;
        add(k.center - e);
        add(k.center + e);
    }
    lo.is_finite().then_some((lo, hi))
}

/// The JSON of `camsim scene info`.
pub fn info_json(l: &LoadedScene) -> serde_json::Value {
    let s = &l.scene;
    let plain: Vec<usize> = (0..s.meshes.len())
        .filter(|i| !l.prototypes.contains(i))
        .collect();
    let triangles: usize = plain.iter().map(|&i| s.meshes[i].indices.len()).sum();
    let instanced: usize = s
        .instances
        .iter()
        .map(|inst| {
            inst.prototype
                .iter()
                .filter_map(|&i| s.meshes.get(i))
                .map(|m| m.indices.len())
                .sum::<usize>()
        })
        .sum();
    let area_lights = plain
        .iter()
        .filter(|&&i| s.meshes[i].emission.is_some())
        .count()
        + s.spheres.iter().filter(|x| x.emission.is_some()).count()
        + s.disks.iter().filter(|x| x.emission.is_some()).count();
    let bounds = world_bounds(s, &l.prototypes)
        .map(|(a, b)| serde_json::json!({"min_m": [a.x, a.y, a.z], "max_m": [b.x, b.y, b.z]}));
    let camera = s.camera.as_ref().map(|c| {
        let pos = c.to_world.transform_point3(DVec3::ZERO);
        let dir = c.to_world.transform_vector3(DVec3::Z).normalize();
        serde_json::json!({"position_m": [pos.x, pos.y, pos.z], "direction": [dir.x, dir.y, dir.z], "model": c.model})
    });
    serde_json::json!({
        "shapes": plain.len() + s.spheres.len() + s.disks.len(),
        "meshes": plain.len(),
        "spheres": s.spheres.len(),
        "disks": s.disks.len(),
        "prototype_meshes": l.prototypes.len(),
        "triangles": triangles,
        "instanced_triangles": instanced,
        "instances": s.instances.len(),
        "lights": s.lights.len() + area_lights,
        "area_lights": area_lights,
        "materials": s.materials.len(),
        "objects": s.objects.iter().map(|o| o.name.clone()).collect::<Vec<_>>(),
        "camera": camera,
        "film": s.film,
        "spectral_grid": l.spectral_grid,
        "world_bounds": bounds,
        "pbrt_version": l.dialect.reason,
        "differences_from_pbrt": differences::differences_from_pbrt(l),
        "warnings": s.warnings,
    })
}
