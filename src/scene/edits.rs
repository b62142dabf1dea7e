//! Edits an experiment makes to a loaded scene: `remove` objects, `override`
//! an object's spectra, `add` a target (MCC chart, slanted edge, mesh). Each
//! edit's properties are read here, once, through a [`ParamDict`] and its
//! schema ([`override_schema`], [`addition_schema`]); `check` builds the same
//! target specs `run` adds, so they cannot disagree.

use super::model::{Material, Scene};
use super::targets::{self, MccChart, PlacedMesh, SlantedEdge};
use crate::params::{Kind, ParamDict, ParamError, ParamSpec, Params, Schema};
use crate::spectrum::{Spectrum, library};
use crate::{Error, Result};
use glam::DVec3;
use serde::Serialize;
use std::path::Path;

/// Kinds of object an experiment can add to a scene.
#[derive(Clone, Copy, Debug, PartialEq, Eq, Serialize)]
#[serde(rename_all = "kebab-case")]
pub enum Target {
    /// Macbeth ColorChecker chart (24 patches; labels per patch).
    Mcc,
    /// ISO 12233 slanted-edge target.
    SlantedEdge,
    /// A mesh file (`file="scenes/bunny.obj"`).
    Mesh,
    /// A spot light (the paper's Fig. 6 edges are lit by one).
    SpotLight,
}

impl Target {
    pub const NAMES: &'static [&'static str] = &["mcc", "slanted-edge", "mesh", "spot-light"];
    pub const ALL: &'static [Target] = &[
        Target::Mcc,
        Target::SlantedEdge,
        Target::Mesh,
        Target::SpotLight,
    ];
    pub fn parse(s: &str) -> Option<Self> {
        match s {
            "mcc" => Some(Self::Mcc),
            "slanted-edge" => Some(Self::SlantedEdge),
            "mesh" => Some(Self::Mesh),
            "spot-light" => Some(Self::SpotLight),
            _ => None,
        }
    }
}

/// Is object `name` the object `wanted` or below it (`wanted/…`)?
pub fn object_matches(name: &str, wanted: &str) -> bool {
    name == wanted
        || name
            .strip_prefix(wanted)
            .is_some_and(|r| r.starts_with('/'))
}

fn ids_matching(scene: &Scene, wanted: &str) -> Result<Vec<u32>> {
    let ids: Vec<u32> = scene
        .objects
        .iter()
        .enumerate()
        .filter(|(_, o)| object_matches(&o.name, wanted))
        .map(|(i, _)| i as u32)
        .collect();
    if ids.is_empty() {
        let names: Vec<&str> = scene.objects.iter().map(|o| o.name.as_str()).collect();
        let hint = crate::diag::did_you_mean(wanted, names.iter().copied())
            .map(|s| format!(" (did you mean '{s}'?)"))
            .unwrap_or_default();
        return Err(Error::invalid(format!(
            "no object '{wanted}' in the scene{hint}; objects are: {}",
            names.join(", ")
        )));
    }
    Ok(ids)
}

/// Remove every shape whose object is `name` or below it (`name/…`).
pub fn remove_object(scene: &mut Scene, name: &str) -> Result<()> {
    let ids = ids_matching(scene, name)?;
    scene.meshes.retain(|m| !ids.contains(&m.object));
    scene.spheres.retain(|m| !ids.contains(&m.object));
    scene.disks.retain(|m| !ids.contains(&m.object));
    Ok(())
}

/// `override "OBJECT" …`.
pub static OVERRIDE_SCHEMA: Schema = Schema {
    node: "override \"OBJECT\"",
    params: &[
        ParamSpec::new(
            "reflectance",
            Kind::Spectrum,
            "",
            "new diffuse reflectance of the object's materials (a diffuse+specular material keeps its specular-to-diffuse ratio)",
            "\"cbox-red-wall\"",
        ),
        ParamSpec::new(
            "radiance",
            Kind::Spectrum,
            "",
            "new emitted radiance of the object's emitting shapes, W/(sr·m²·nm)",
            "\"cie-a\"",
        ),
        ParamSpec::new(
            "radiance-scale",
            Kind::Number,
            "1",
            "factor on the emitted radiance (after `radiance`)",
            "2.5",
        ),
    ],
};

/// The schema of `override` (the node's properties).
pub fn override_schema() -> &'static Schema {
    &OVERRIDE_SCHEMA
}

/// What an `override` asks for.
#[derive(Clone, Debug, PartialEq)]
pub struct OverrideSpec {
    pub reflectance: Option<Spectrum>,
    pub radiance: Option<Spectrum>,
    pub radiance_scale: Option<f64>,
}

/// Read an `override`'s properties (spectra resolved relative to `dir`).
pub fn override_spec(params: &Params, dir: &Path) -> std::result::Result<OverrideSpec, ParamError> {
    let d = ParamDict::new(params, &OVERRIDE_SCHEMA);
    d.check_names()?;
    let spectrum = |k: &str| -> std::result::Result<Option<Spectrum>, ParamError> {
        match d.str(k)? {
            Some(r) => library::resolve(r, dir)
                .map(Some)
                .map_err(|e| ParamError::value(k, e)),
            None => Ok(None),
        }
    };
    let reflectance = spectrum("reflectance")?;
    let radiance = spectrum("radiance")?;
    let radiance_scale = d.nonneg("radiance-scale")?;
    d.finish()?;
    Ok(OverrideSpec {
        reflectance,
        radiance,
        radiance_scale,
    })
}

/// Check an `override`'s properties without a scene.
pub fn check_override(params: &Params, dir: &Path) -> std::result::Result<(), ParamError> {
    override_spec(params, dir).map(|_| ())
}

/// Apply an override to every shape of `object` (or below it).
pub fn apply_override(scene: &mut Scene, object: &str, o: &OverrideSpec) -> Result<()> {
    let ids = ids_matching(scene, object)?;
    let mut touched_materials = vec![];
    for m in &mut scene.meshes {
        if !ids.contains(&m.object) {
            continue;
        }
        touched_materials.push(m.material);
        if let Some(e) = &mut m.emission {
            if let Some(r) = &o.radiance {
                e.radiance = r.clone();
            }
            if let Some(k) = o.radiance_scale {
                e.radiance = e.radiance.clone().scaled(k);
            }
        }
    }
    if let Some(r) = &o.reflectance {
        for id in touched_materials {
            if let Some(nm) = scene.materials.get_mut(id as usize) {
                nm.material = match &nm.material {
                    Material::DiffuseSpecular {
                        diffuse,
                        specular,
                        roughness,
                    } => {
                        // keep the specular-to-diffuse ratio of the original
                        let k = specular.values.iter().cloned().fold(0.0, f64::max)
                            / diffuse.values.iter().cloned().fold(1e-12, f64::max);
                        Material::DiffuseSpecular {
                            diffuse: r.clone(),
                            specular: r.clone().scaled(k.min(1.0)),
                            roughness: *roughness,
                        }
                    }
                    _ => Material::Diffuse {
                        reflectance: r.clone(),
                    },
                };
            }
        }
    }
    Ok(())
}

/// Where an added object goes (the typed properties every `add` has).
#[derive(Clone, Debug, PartialEq)]
pub struct Placement<'a> {
    pub id: &'a str,
    pub position_m: [f64; 3],
    /// Rotation about x, then y, then z, degrees.
    pub rotate_deg: [f64; 3],
    pub scale: [f64; 3],
    /// The mesh file (`target="mesh"`).
    pub file: Option<&'a Path>,
}

const PLACEMENT: [ParamSpec; 5] = [
    ParamSpec::new(
        "target",
        Kind::Choice(Target::NAMES),
        "",
        "what to add (required)",
        "\"mcc\"",
    ),
    ParamSpec::new(
        "position-m",
        Kind::Vec3,
        "the target's",
        "position in scene coordinates (MCC: bottom centre of the front face; edge: plate centre; mesh: bounding-box centre)",
        "(0.011 0.052 0.093)",
    ),
    ParamSpec::new(
        "rotate-deg",
        Kind::Vec3,
        "(0 0 0)",
        "rotation about x, then y, then z (a mesh turns about y only)",
        "(3 0 2)",
    ),
    ParamSpec::new(
        "scale",
        Kind::Numbers,
        "1",
        "size factor: one number, or (x y z) (MCC and mesh: uniform only; edge: x = width, y = height)",
        "1.25",
    ),
    ParamSpec::new(
        "file",
        Kind::File,
        "",
        "mesh file (OBJ, glTF, PLY; `target=\"mesh\"` only)",
        "\"scenes/bunny.obj\"",
    ),
];

/// `add "ID" target="mcc" …`.
pub static MCC_SCHEMA: Schema = Schema {
    node: "add target=\"mcc\"",
    params: &[
        PLACEMENT[0],
        PLACEMENT[1],
        PLACEMENT[2],
        PLACEMENT[3],
        ParamSpec::new(
            "patch-size-m",
            Kind::Number,
            "0.01 (× scale)",
            "side of a colour patch",
            "0.0125",
        ),
        ParamSpec::new(
            "patch-pitch-m",
            Kind::Number,
            "0.014 (× scale)",
            "centre-to-centre patch spacing",
            "0.0135",
        ),
    ],
};

/// `add "ID" target="slanted-edge" …`.
pub static SLANTED_EDGE_SCHEMA: Schema = Schema {
    node: "add target=\"slanted-edge\"",
    params: &[
        PLACEMENT[0],
        PLACEMENT[1],
        PLACEMENT[2],
        PLACEMENT[3],
        ParamSpec::new(
            "tilt-deg",
            Kind::Number,
            "5",
            "in-plane tilt of the edge from vertical (ISO 12233: a few degrees)",
            "7.5",
        ),
        ParamSpec::new(
            "reflectance",
            Kind::Spectrum,
            "the white wall",
            "reflectance of the plate's light half",
            "\"cbox-green-wall\"",
        ),
    ],
};

/// `add "ID" target="mesh" file="…" …`.
pub static MESH_SCHEMA: Schema = Schema {
    node: "add target=\"mesh\"",
    params: &[
        PLACEMENT[0],
        PLACEMENT[1],
        ParamSpec::new(
            "rotate-deg",
            Kind::Vec3,
            "(0 0 0)",
            "rotation about y only: (0 a 0)",
            "(0 3 0)",
        ),
        PLACEMENT[3],
        PLACEMENT[4],
        ParamSpec::new(
            "reflectance",
            Kind::Spectrum,
            "the white wall",
            "diffuse reflectance of the mesh",
            "\"cbox-red-wall\"",
        ),
    ],
};

/// `add "ID" target="spot-light" …` (paper Fig. 6: the slanted edges are lit
/// by `cbox-lights-1 × 0.001` from (0.008 0.15 −0.3) towards (0.008 0.03 0),
/// cone 60°, fall-off from 50°).
pub static SPOT_LIGHT_SCHEMA: Schema = Schema {
    node: "add target=\"spot-light\"",
    params: &[
        PLACEMENT[0],
        ParamSpec::new(
            "position-m",
            Kind::Vec3,
            "",
            "position of the light (required)",
            "(0.008 0.15 -0.3)",
        ),
        ParamSpec::new(
            "look-at-m",
            Kind::Vec3,
            "",
            "point the spot's axis passes through (required)",
            "(0.008 0.03 0.01)",
        ),
        ParamSpec::new(
            "intensity",
            Kind::Spectrum,
            "",
            "on-axis intensity, W/(sr·nm) (required)",
            "\"cbox-lamp\"",
        ),
        ParamSpec::new(
            "intensity-scale",
            Kind::Number,
            "1",
            "factor on the intensity",
            "0.0015",
        ),
        ParamSpec::new(
            "cone-deg",
            Kind::Number,
            "30",
            "half-angle where the light ends",
            "55",
        ),
        ParamSpec::new(
            "falloff-start-deg",
            Kind::Number,
            "cone-deg",
            "half-angle where the smooth fall-off starts",
            "45",
        ),
    ],
};

/// The schema of an `add` of `target`.
pub fn addition_schema(target: Target) -> &'static Schema {
    match target {
        Target::Mcc => &MCC_SCHEMA,
        Target::SlantedEdge => &SLANTED_EDGE_SCHEMA,
        Target::Mesh => &MESH_SCHEMA,
        Target::SpotLight => &SPOT_LIGHT_SCHEMA,
    }
}

/// A target, ready to add.
#[derive(Clone, Debug, PartialEq)]
pub enum TargetSpec {
    Mcc(MccChart),
    SlantedEdge(SlantedEdge),
    Mesh(PlacedMesh),
    Light(super::model::Light),
}

fn uniform(scale: [f64; 3], what: &str) -> std::result::Result<f64, ParamError> {
    if scale[0] == scale[1] && scale[1] == scale[2] {
        Ok(scale[0])
    } else {
        Err(ParamError::value(
            "scale",
            format!("{what} scales uniformly: give one number, not (x y z)"),
        ))
    }
}

/// The target an `add` node describes: its placement and its own properties
/// (spectra resolved relative to `dir`). Reads the mesh file of a mesh.
pub fn target_spec(
    target: Target,
    at: &Placement,
    params: &Params,
    dir: &Path,
) -> std::result::Result<TargetSpec, ParamError> {
    let d = ParamDict::new(params, addition_schema(target));
    d.check_names()?;
    let pos = DVec3::from_array(at.position_m);
    let rot = DVec3::from_array(at.rotate_deg);
    let spectrum = |k: &str| -> std::result::Result<Option<Spectrum>, ParamError> {
        match d.str(k)? {
            Some(r) => library::resolve(r, dir)
                .map(Some)
                .map_err(|e| ParamError::value(k, e)),
            None => Ok(None),
        }
    };
    let t = match target {
        Target::Mcc => {
            let k = uniform(at.scale, "an MCC chart")?;
            let mut c = MccChart {
                name: at.id.to_string(),
                position_m: pos,
                rotation_deg: rot,
                ..Default::default()
            };
            c.width_m *= k;
            c.height_m *= k;
            c.patch_size_m *= k;
            c.patch_pitch_m *= k;
            if let Some(v) = d.positive("patch-size-m")? {
                c.patch_size_m = v;
            }
            if let Some(v) = d.positive("patch-pitch-m")? {
                c.patch_pitch_m = v;
            }
            TargetSpec::Mcc(c)
        }
        Target::SlantedEdge => {
            let mut e =
                SlantedEdge::new(at.id, pos).map_err(|e| ParamError::section(e.to_string()))?;
            e.rotation_deg = rot;
            if at.scale[2] != at.scale[0] && at.scale[2] != 1.0 {
                return Err(ParamError::value(
                    "scale",
                    "a slanted edge scales its width (x) and height (y); its thickness stays",
                ));
            }
            e.width_m *= at.scale[0];
            e.height_m *= at.scale[1];
            if let Some(t) = d.in_range("tilt-deg", -45.0, 45.0)? {
                e.tilt_deg = t;
            }
            if let Some(r) = spectrum("reflectance")? {
                e.white = r;
            }
            TargetSpec::SlantedEdge(e)
        }
        Target::Mesh => {
            let f = at
                .file
                .ok_or_else(|| ParamError::section("target=\"mesh\" needs file=\"…\""))?;
            if at.rotate_deg[0] != 0.0 || at.rotate_deg[2] != 0.0 {
                return Err(ParamError::value(
                    "rotate-deg",
                    "a mesh turns about y only: write rotate-deg=(0 a 0)",
                ));
            }
            let mut m = PlacedMesh::bunny(f).map_err(|e| ParamError::section(e.to_string()))?;
            m.name = at.id.to_string();
            m.position_m = pos;
            m.scale = uniform(at.scale, "a mesh")?;
            m.rot_y_deg = at.rotate_deg[1];
            if let Some(r) = spectrum("reflectance")? {
                m.reflectance = r;
            }
            TargetSpec::Mesh(m)
        }
        Target::SpotLight => {
            if at.rotate_deg != [0.0; 3] || at.scale != [1.0; 3] {
                return Err(ParamError::section(
                    "a spot light has no rotate-deg or scale: aim it with look-at-m",
                ));
            }
            let look_at = d
                .vec3("look-at-m")?
                .ok_or_else(|| ParamError::section("a spot light needs look-at-m=(x y z)"))?;
            let direction = (DVec3::from_array(look_at) - pos).normalize_or_zero();
            if direction == DVec3::ZERO {
                return Err(ParamError::value(
                    "look-at-m",
                    "look-at-m equals position-m",
                ));
            }
            let intensity = spectrum("intensity")?.ok_or_else(|| {
                ParamError::section("a spot light needs intensity=\"<spectrum>\"")
            })?;
            let k = d.nonneg("intensity-scale")?.unwrap_or(1.0);
            let cone = d.in_range("cone-deg", 1e-3, 90.0)?.unwrap_or(30.0);
            let start = d.in_range("falloff-start-deg", 0.0, cone)?.unwrap_or(cone);
            TargetSpec::Light(super::model::Light::Spot {
                position: pos,
                direction,
                cone_angle_deg: cone,
                falloff_start_deg: start,
                intensity: intensity.scaled(k),
            })
        }
    };
    d.finish()?;
    Ok(t)
}

/// Add a target to the scene.
pub fn add_target(scene: &mut Scene, t: &TargetSpec) -> Result<()> {
    match t {
        TargetSpec::Mcc(c) => targets::add_mcc(scene, c),
        TargetSpec::SlantedEdge(e) => targets::add_slanted_edge(scene, e),
        TargetSpec::Mesh(m) => targets::add_mesh(scene, m),
        TargetSpec::Light(l) => {
            scene.lights.push(l.clone());
            Ok(())
        }
    }
}
