//! camsim's own scene file format (KDL v2), for `camsim render SCENE.kdl`.
//!
//! ```kdl
//! film width-px=320 height-px=240 pixel-pitch-um=1.4
//! camera model="pinhole" fov-deg=48.21 f-number=2 {
//!     position-m 0 0.105 -0.4
//!     look-at-m 0 0.105 0.6
//!     up 0 1 0
//! }
//! // or a lens, with the properties of an experiment's `lens` node (`camsim params`):
//! //   camera model="thin-lens" focal-length-mm=4.38 f-number=1.73 focus-distance-m=0.5 { … }
//! //   camera lens="../lenses/rtf/pixel4a-rearcamera-ellipse-raytransfer.json" film-distance-mm=0.4651 { … }
//! render spp=64 max-bounces=6
//! material "white" diffuse="cbox-white-wall"
//! material "red" diffuse="cbox-red-wall" specular="cbox-red-wall" specular-scale=0.1 roughness=0.46
//! material "glass" dielectric-ior="constant:1.5"
//! material "steel" mirror="constant:0.6"      // or conductor-eta=… conductor-k=… roughness=…
//! material "none" black=#true
//! shape "wall-left" type="rectangle" material="red" {
//!     position-m -0.15 0.15 0
//!     size-m 0.3 0.3          // width, height
//!     normal 1 0 0            // front side (emitting side of an area light)
//! }
//! shape "lamp" type="rectangle" material="none" emission="cbox-lamp" emission-scale=1 { … }
//! shape "cube" type="box" material="white" { position-m …; size-m 0.05 0.05 0.05; rotate-deg 0 44.4 0 }
//! shape "ball" type="sphere" material="glass" { position-m …; radius-m 0.03 }
//! shape "spot" type="disk" material="white" { position-m …; radius-m 0.01; normal 0 1 0 }
//! shape "bunny" type="mesh" file="bunny.obj" material="white" { position-m …; rotate-deg …; scale 1.445 }
//! light "sun" type="distant" irradiance="cie-d65" scale=0.01 { direction 0 -1 0 }
//! light "bulb" type="point" intensity="cie-a" { position-m 0 0.2 0 }
//! light "spot" type="spot" intensity="cbox-lamp" cone-deg=60 falloff-start-deg=50 { position-m …; look-at-m … }
//! light "sky" type="infinite" radiance="constant:1"
//! ```
//!
//! Spectra are names from `spectrum::library` (`cbox-white-wall`,
//! `constant:0.5`, …) or `FILE.csv#column` relative to the scene file; every
//! spectrum attribute `x` may have a multiplier `x-scale`. Transforms apply
//! scale, then rotations about x, y, z (degrees, world axes, in that order),
//! then the translation `position-m`. `scale` takes one or three numbers.
//! Rectangles lie in their local xy plane with the front along +z unless
//! `normal` is given (then width runs along up×normal with up = +y, or +z for
//! a vertical normal). Radiance is W/(sr·m²·nm); point/spot intensity
//! W/(sr·nm); distant irradiance W/(m²·nm).
//!
//! Every error carries `file:line:col` (`diag::Located`).

use super::mesh_io::load_mesh;
use super::model::*;
use super::shapes::{cuboid, quad};
use crate::diag::{Located, did_you_mean};
use crate::spectrum::{Spectrum, library};
use crate::{Error, Result};
use glam::{DMat4, DQuat, DVec3};
use kdl::{KdlDocument, KdlNode, KdlValue};
use std::path::{Path, PathBuf};

/// A parsed scene file: the scene (with camera and film) and optional render defaults.
#[derive(Clone, Debug)]
pub struct SceneFile {
    pub scene: Scene,
    pub spp: Option<u32>,
    pub max_bounces: Option<u32>,
    pub path: PathBuf,
}

/// Read and parse a KDL scene file.
pub fn load_kdl_scene(path: &Path) -> Result<SceneFile> {
    let src = std::fs::read_to_string(path).map_err(|e| Error::io(path, e))?;
    parse_kdl_scene(&src, path)
}

struct Ctx<'a> {
    src: &'a str,
    file: &'a Path,
    base: PathBuf,
}

impl Ctx<'_> {
    fn err_at(&self, span: miette::SourceSpan, msg: impl Into<String>) -> Error {
        Located::at_offset(self.file, self.src, span.offset(), span.len(), msg).into()
    }
    fn err(&self, node: &KdlNode, msg: impl Into<String>) -> Error {
        self.err_at(node.span(), msg)
    }
    /// Named property value.
    fn prop<'n>(&self, node: &'n KdlNode, key: &str) -> Option<(&'n KdlValue, miette::SourceSpan)> {
        node.entries()
            .iter()
            .rev()
            .find(|e| e.name().map(|n| n.value()) == Some(key))
            .map(|e| (e.value(), e.span()))
    }
    /// `camera [lens="FILE"] <lens properties>`: the same properties as an
    /// experiment's `lens` node, read by the same function
    /// (`camera_params::camera_model`); errors point at the property.
    fn camera_model(&self, node: &KdlNode) -> Result<CameraModel> {
        use crate::params::{Params, Value};
        let mut params = Params::new();
        let mut file = None;
        for e in node.entries() {
            let Some(n) = e.name() else {
                return Err(self.err_at(
                    e.span(),
                    "unexpected argument on 'camera'; expected name=value properties",
                ));
            };
            let v = match e.value() {
                KdlValue::Integer(i) => Value::Number(*i as f64),
                KdlValue::Float(x) if x.is_finite() => Value::Number(*x),
                KdlValue::String(t) => Value::String(t.clone()),
                KdlValue::Bool(b) => Value::Bool(*b),
                _ => {
                    return Err(self.err_at(
                        e.span(),
                        format!(
                            "'{}': expected a finite number, string or boolean",
                            n.value()
                        ),
                    ));
                }
            };
            if n.value() == "lens" {
                let Value::String(f) = v else {
                    return Err(self.err_at(e.span(), "'lens': expected a file name"));
                };
                let path = self.base.join(&f);
                if !path.is_file() {
                    return Err(self.err_at(e.span(), format!("lens file '{f}' not found")));
                }
                file = Some(path);
                continue;
            }
            params.set(n.value(), v);
        }
        super::camera_params::camera_model(file.as_deref(), &params).map_err(|pe| {
            let span = pe
                .name
                .as_deref()
                .and_then(|k| self.prop(node, k))
                .map(|(_, sp)| sp)
                .unwrap_or(node.span());
            let l = Located::at_offset(
                self.file,
                self.src,
                span.offset(),
                span.len(),
                format!("camera: {}", pe.message),
            );
            l.with_help_opt(pe.help).into()
        })
    }

    fn check_props(&self, node: &KdlNode, allowed: &[&str]) -> Result<()> {
        for e in node.entries() {
            let Some(n) = e.name() else { continue };
            if allowed.contains(&n.value()) {
                continue;
            }
            let help = did_you_mean(n.value(), allowed.iter().copied())
                .map(|s| format!("did you mean '{s}'?"))
                .or_else(|| Some(format!("allowed: {}", allowed.join(", "))));
            let msg = format!(
                "unknown property '{}' on '{}'",
                n.value(),
                node.name().value()
            );
            let sp = e.span();
            return Err(
                Located::at_offset(self.file, self.src, sp.offset(), sp.len(), msg)
                    .with_help_opt(help)
                    .into(),
            );
        }
        Ok(())
    }
    fn num(&self, node: &KdlNode, key: &str) -> Result<Option<f64>> {
        match self.prop(node, key) {
            None => Ok(None),
            Some((v, sp)) => {
                let x = match v {
                    KdlValue::Integer(i) => *i as f64,
                    KdlValue::Float(f) => *f,
                    _ => return Err(self.err_at(sp, format!("'{key}' must be a number"))),
                };
                if !x.is_finite() {
                    return Err(self.err_at(sp, format!("'{key}' must be finite")));
                }
                Ok(Some(x))
            }
        }
    }
    fn positive(&self, node: &KdlNode, key: &str) -> Result<Option<f64>> {
        let v = self.num(node, key)?;
        if let Some(x) = v
            && x <= 0.0
        {
            let sp = self.prop(node, key).unwrap().1;
            return Err(self.err_at(sp, format!("'{key}' must be > 0, got {x}")));
        }
        Ok(v)
    }
    fn string<'n>(&self, node: &'n KdlNode, key: &str) -> Result<Option<&'n str>> {
        match self.prop(node, key) {
            None => Ok(None),
            Some((KdlValue::String(s), _)) => Ok(Some(s.as_str())),
            Some((_, sp)) => Err(self.err_at(sp, format!("'{key}' must be a string"))),
        }
    }
    fn boolean(&self, node: &KdlNode, key: &str) -> Result<Option<bool>> {
        match self.prop(node, key) {
            None => Ok(None),
            Some((KdlValue::Bool(b), _)) => Ok(Some(*b)),
            Some((_, sp)) => Err(self.err_at(sp, format!("'{key}' must be #true or #false"))),
        }
    }
    /// Spectrum attribute `key` times optional `key-scale`.
    fn spectrum(&self, node: &KdlNode, key: &str) -> Result<Option<Spectrum>> {
        let Some(name) = self.string(node, key)? else {
            return Ok(None);
        };
        let sp = self.prop(node, key).unwrap().1;
        let s = library::resolve(name, &self.base).map_err(|e| self.err_at(sp, e))?;
        let k = self.num(node, &format!("{key}-scale"))?.unwrap_or(1.0);
        Ok(Some(if k == 1.0 { s } else { s.scaled(k) }))
    }
    fn name_arg<'n>(&self, node: &'n KdlNode) -> Result<&'n str> {
        match node
            .entries()
            .iter()
            .find(|e| e.name().is_none())
            .map(|e| e.value())
        {
            Some(KdlValue::String(s)) => Ok(s),
            _ => Err(self.err(
                node,
                format!(
                    "'{}' needs a name, e.g. {} \"name\"",
                    node.name().value(),
                    node.name().value()
                ),
            )),
        }
    }
    /// Numeric arguments of child node `key` (e.g. `position-m 0 0.1 0`).
    fn child_vec(
        &self,
        node: &KdlNode,
        key: &str,
        n_allowed: &[usize],
    ) -> Result<Option<Vec<f64>>> {
        let Some(doc) = node.children() else {
            return Ok(None);
        };
        let Some(c) = doc.nodes().iter().rev().find(|c| c.name().value() == key) else {
            return Ok(None);
        };
        let mut v = vec![];
        for e in c.entries() {
            if e.name().is_some() {
                return Err(self.err_at(e.span(), format!("'{key}' takes plain numbers")));
            }
            let x = match e.value() {
                KdlValue::Integer(i) => *i as f64,
                KdlValue::Float(f) => *f,
                _ => return Err(self.err_at(e.span(), format!("'{key}' takes numbers"))),
            };
            if !x.is_finite() {
                return Err(self.err_at(e.span(), format!("'{key}' values must be finite")));
            }
            v.push(x);
        }
        if !n_allowed.contains(&v.len()) {
            return Err(self.err(
                c,
                format!(
                    "'{key}' takes {} number(s), got {}",
                    n_allowed
                        .iter()
                        .map(|n| n.to_string())
                        .collect::<Vec<_>>()
                        .join(" or "),
                    v.len()
                ),
            ));
        }
        Ok(Some(v))
    }
    fn child_v3(&self, node: &KdlNode, key: &str) -> Result<Option<DVec3>> {
        Ok(self
            .child_vec(node, key, &[3])?
            .map(|v| DVec3::new(v[0], v[1], v[2])))
    }
    fn check_children(&self, node: &KdlNode, allowed: &[&str]) -> Result<()> {
        if let Some(doc) = node.children() {
            for c in doc.nodes() {
                let n = c.name().value();
                if !allowed.contains(&n) {
                    let help = did_you_mean(n, allowed.iter().copied())
                        .map(|s| format!("did you mean '{s}'?"));
                    return Err(Located::at_offset(
                        self.file,
                        self.src,
                        c.span().offset(),
                        n.len(),
                        format!("unknown child '{n}' in '{}'", node.name().value()),
                    )
                    .with_help_opt(
                        help.or_else(|| Some(format!("allowed: {}", allowed.join(", ")))),
                    )
                    .into());
                }
            }
        }
        Ok(())
    }
    /// Transform from position-m, rotate-deg, scale children.
    fn transform(&self, node: &KdlNode) -> Result<DMat4> {
        let t = self.child_v3(node, "position-m")?.unwrap_or(DVec3::ZERO);
        let r = self.child_v3(node, "rotate-deg")?.unwrap_or(DVec3::ZERO);
        let s = match self.child_vec(node, "scale", &[1, 3])? {
            None => DVec3::ONE,
            Some(v) if v.len() == 1 => DVec3::splat(v[0]),
            Some(v) => DVec3::new(v[0], v[1], v[2]),
        };
        if s.min_element() <= 0.0 {
            return Err(self.err(node, "scale must be > 0"));
        }
        let q = DQuat::from_rotation_z(r.z.to_radians())
            * DQuat::from_rotation_y(r.y.to_radians())
            * DQuat::from_rotation_x(r.x.to_radians());
        Ok(DMat4::from_scale_rotation_translation(s, q, t))
    }
}

fn frame_from_normal(n: DVec3) -> (DVec3, DVec3) {
    let up = if n.y.abs() > 0.99 { DVec3::Z } else { DVec3::Y };
    let u = up.cross(n).normalize();
    let v = n.cross(u);
    (u, v)
}

const TOP: &[&str] = &["film", "camera", "render", "material", "shape", "light"];

/// Parse a KDL scene from source text (`path` for diagnostics and relative files).
pub fn parse_kdl_scene(src: &str, path: &Path) -> Result<SceneFile> {
    let doc: KdlDocument = KdlDocument::parse(src).map_err(|e| {
        let d = e.diagnostics.first();
        let (off, len) = d.map(|d| (d.span.offset(), d.span.len())).unwrap_or((0, 1));
        let msg = d
            .and_then(|d| d.message.clone().or_else(|| d.help.clone()))
            .unwrap_or_else(|| "invalid KDL".into());
        Error::from(Located::at_offset(
            path,
            src,
            off,
            len,
            format!("KDL syntax: {msg}"),
        ))
    })?;
    let base = path.parent().map(Path::to_path_buf).unwrap_or_default();
    let cx = Ctx {
        src,
        file: path,
        base,
    };
    let mut scene = Scene::default();
    let (mut spp, mut max_bounces) = (None, None);
    let mut camera_node = None;
    // Materials first, so shapes may refer to materials defined later in the file.
    for node in doc.nodes() {
        let kind = node.name().value();
        if !TOP.contains(&kind) {
            let help =
                did_you_mean(kind, TOP.iter().copied()).map(|s| format!("did you mean '{s}'?"));
            return Err(Located::at_offset(
                path,
                src,
                node.span().offset(),
                kind.len(),
                format!("unknown scene node '{kind}'"),
            )
            .with_help_opt(help)
            .into());
        }
        if kind == "material" {
            let name = cx.name_arg(node)?;
            cx.check_props(
                node,
                &[
                    "diffuse",
                    "diffuse-scale",
                    "specular",
                    "specular-scale",
                    "roughness",
                    "mirror",
                    "mirror-scale",
                    "dielectric-ior",
                    "dielectric-ior-scale",
                    "conductor-eta",
                    "conductor-eta-scale",
                    "conductor-k",
                    "conductor-k-scale",
                    "black",
                ],
            )?;
            let roughness = cx.num(node, "roughness")?.unwrap_or(0.0);
            if roughness < 0.0 {
                return Err(cx.err(node, "roughness must be ≥ 0"));
            }
            let m = if cx.boolean(node, "black")? == Some(true) {
                Material::Black
            } else if let Some(ior) = cx.spectrum(node, "dielectric-ior")? {
                Material::Dielectric { ior }
            } else if let Some(r) = cx.spectrum(node, "mirror")? {
                Material::Mirror { reflectance: r }
            } else if let Some(eta) = cx.spectrum(node, "conductor-eta")? {
                let k = cx
                    .spectrum(node, "conductor-k")?
                    .ok_or_else(|| cx.err(node, "conductor needs conductor-k"))?;
                Material::Conductor { eta, k, roughness }
            } else if let Some(d) = cx.spectrum(node, "diffuse")? {
                match cx.spectrum(node, "specular")? {
                    Some(s) => Material::DiffuseSpecular {
                        diffuse: d,
                        specular: s,
                        roughness,
                    },
                    None => Material::Diffuse { reflectance: d },
                }
            } else {
                return Err(cx.err(node, format!("material '{name}' needs one of diffuse=, mirror=, dielectric-ior=, conductor-eta=, black=#true")));
            };
            scene.material(name, m);
        }
    }
    let mat_names: Vec<String> = scene.materials.iter().map(|m| m.name.clone()).collect();
    for node in doc.nodes() {
        match node.name().value() {
            "film" => {
                cx.check_props(node, &["width-px", "height-px", "pixel-pitch-um"])?;
                let w = cx
                    .positive(node, "width-px")?
                    .ok_or_else(|| cx.err(node, "film needs width-px"))?;
                let h = cx
                    .positive(node, "height-px")?
                    .ok_or_else(|| cx.err(node, "film needs height-px"))?;
                let p = cx.positive(node, "pixel-pitch-um")?.unwrap_or(1.4);
                if w.fract() != 0.0 || h.fract() != 0.0 || w > 65536.0 || h > 65536.0 {
                    return Err(cx.err(
                        node,
                        "film width-px and height-px must be whole numbers ≤ 65536",
                    ));
                }
                scene.film = Some(FilmSpec {
                    width_px: w as u32,
                    height_px: h as u32,
                    pixel_pitch_m: p * 1e-6,
                    crop_window: None,
                });
            }
            "render" => {
                cx.check_props(node, &["spp", "max-bounces"])?;
                spp = cx.positive(node, "spp")?.map(|x| x as u32);
                max_bounces = cx.num(node, "max-bounces")?.map(|x| x.max(0.0) as u32);
            }
            "camera" => camera_node = Some(node),
            "shape" => {
                let name = cx.name_arg(node)?;
                cx.check_props(
                    node,
                    &[
                        "type",
                        "material",
                        "emission",
                        "emission-scale",
                        "two-sided",
                        "file",
                    ],
                )?;
                cx.check_children(
                    node,
                    &[
                        "position-m",
                        "rotate-deg",
                        "scale",
                        "size-m",
                        "normal",
                        "radius-m",
                    ],
                )?;
                let mname = cx
                    .string(node, "material")?
                    .ok_or_else(|| cx.err(node, format!("shape '{name}' needs material=\"…\"")))?;
                let Some(material) = mat_names.iter().position(|m| m == mname) else {
                    let sp = cx.prop(node, "material").unwrap().1;
                    return Err(Located::at_offset(
                        path,
                        src,
                        sp.offset(),
                        sp.len(),
                        format!("unknown material '{mname}'"),
                    )
                    .with_help_opt(
                        did_you_mean(mname, mat_names.iter().map(|s| s.as_str()))
                            .map(|s| format!("did you mean '{s}'?")),
                    )
                    .into());
                };
                let material = material as u32;
                let emission = cx.spectrum(node, "emission")?.map(|radiance| Emission {
                    radiance: radiance.with_unit("W/(sr·m²·nm)"),
                    two_sided: false,
                });
                let emission = match (emission, cx.boolean(node, "two-sided")?) {
                    (Some(e), Some(t)) => Some(Emission { two_sided: t, ..e }),
                    (e, _) => e,
                };
                let object = scene.object(name);
                let xf = cx.transform(node)?;
                let ty = cx.string(node, "type")?.ok_or_else(|| {
                    cx.err(node, "shape needs type=\"rectangle|box|sphere|disk|mesh\"")
                })?;
                match ty {
                    "rectangle" | "quad" => {
                        let size = cx
                            .child_vec(node, "size-m", &[2])?
                            .ok_or_else(|| cx.err(node, "rectangle needs size-m W H"))?;
                        if size[0] <= 0.0 || size[1] <= 0.0 {
                            return Err(cx.err(node, "size-m must be > 0"));
                        }
                        let c = xf.transform_point3(DVec3::ZERO);
                        let (mut u, mut v) = (
                            xf.transform_vector3(DVec3::X * size[0] / 2.0),
                            xf.transform_vector3(DVec3::Y * size[1] / 2.0),
                        );
                        if let Some(n) = cx.child_v3(node, "normal")? {
                            let n = n.normalize_or_zero();
                            if n == DVec3::ZERO {
                                return Err(cx.err(node, "normal must not be zero"));
                            }
                            let (a, b) = frame_from_normal(n);
                            let sc = cx
                                .child_vec(node, "scale", &[1, 3])?
                                .map(|s| s[0])
                                .unwrap_or(1.0);
                            u = a * size[0] / 2.0 * sc;
                            v = b * size[1] / 2.0 * sc;
                        }
                        scene.meshes.push(quad(c, u, v, material, object, emission));
                    }
                    "box" => {
                        let size = cx
                            .child_vec(node, "size-m", &[3])?
                            .ok_or_else(|| cx.err(node, "box needs size-m X Y Z"))?;
                        if size.iter().any(|&s| s <= 0.0) {
                            return Err(cx.err(node, "size-m must be > 0"));
                        }
                        scene.meshes.push(cuboid(
                            DVec3::new(size[0], size[1], size[2]) / 2.0,
                            xf,
                            false,
                            material,
                            object,
                            emission,
                        ));
                    }
                    "sphere" => {
                        let r = cx
                            .child_vec(node, "radius-m", &[1])?
                            .ok_or_else(|| cx.err(node, "sphere needs radius-m"))?[0];
                        let s = xf.transform_vector3(DVec3::X).length();
                        if r <= 0.0 {
                            return Err(cx.err(node, "radius-m must be > 0"));
                        }
                        scene.spheres.push(Sphere {
                            center: xf.transform_point3(DVec3::ZERO),
                            radius: r * s,
                            material,
                            object,
                            emission,
                        });
                    }
                    "disk" => {
                        let r = cx
                            .child_vec(node, "radius-m", &[1])?
                            .ok_or_else(|| cx.err(node, "disk needs radius-m"))?[0];
                        if r <= 0.0 {
                            return Err(cx.err(node, "radius-m must be > 0"));
                        }
                        let n = match cx.child_v3(node, "normal")? {
                            Some(n) => n,
                            None => xf.transform_vector3(DVec3::Z),
                        }
                        .normalize_or_zero();
                        if n == DVec3::ZERO {
                            return Err(cx.err(node, "normal must not be zero"));
                        }
                        let s = xf.transform_vector3(DVec3::X).length();
                        scene.disks.push(Disk {
                            center: xf.transform_point3(DVec3::ZERO),
                            normal: n,
                            radius: r * s,
                            material,
                            object,
                            emission,
                        });
                    }
                    "mesh" => {
                        let f = cx
                            .string(node, "file")?
                            .ok_or_else(|| cx.err(node, "mesh needs file=\"…\""))?;
                        let fp = cx.base.join(f);
                        let sp = cx.prop(node, "file").unwrap().1;
                        let lm = load_mesh(&fp).map_err(|e| cx.err_at(sp, e.to_string()))?;
                        scene.warnings.extend(lm.warnings);
                        let mut m = lm.mesh;
                        let nxf = xf.inverse().transpose();
                        for p in &mut m.positions {
                            *p = xf.transform_point3(p.as_dvec3()).as_vec3();
                        }
                        if let Some(ns) = &mut m.normals {
                            for n in ns.iter_mut() {
                                *n = nxf
                                    .transform_vector3(n.as_dvec3())
                                    .normalize_or_zero()
                                    .as_vec3();
                            }
                        }
                        m.material = material;
                        m.object = object;
                        m.emission = emission;
                        scene.meshes.push(m);
                    }
                    other => {
                        let sp = cx.prop(node, "type").unwrap().1;
                        let kinds = ["rectangle", "quad", "box", "sphere", "disk", "mesh"];
                        return Err(Located::at_offset(
                            path,
                            src,
                            sp.offset(),
                            sp.len(),
                            format!("unknown shape type '{other}'"),
                        )
                        .with_help_opt(
                            did_you_mean(other, kinds).map(|s| format!("did you mean '{s}'?")),
                        )
                        .into());
                    }
                }
            }
            "light" => {
                cx.name_arg(node)?;
                cx.check_props(
                    node,
                    &[
                        "type",
                        "intensity",
                        "intensity-scale",
                        "irradiance",
                        "irradiance-scale",
                        "radiance",
                        "radiance-scale",
                        "cone-deg",
                        "falloff-start-deg",
                    ],
                )?;
                cx.check_children(node, &["position-m", "look-at-m", "direction"])?;
                let need = |s: Option<Spectrum>, what: &str| {
                    s.ok_or_else(|| cx.err(node, format!("light needs {what}=\"…\"")))
                };
                let ty = cx.string(node, "type")?.ok_or_else(|| {
                    cx.err(node, "light needs type=\"point|spot|distant|infinite\"")
                })?;
                let pos = || {
                    cx.child_v3(node, "position-m")
                        .and_then(|p| p.ok_or_else(|| cx.err(node, "light needs position-m")))
                };
                let l = match ty {
                    "point" => Light::Point {
                        position: pos()?,
                        intensity: need(cx.spectrum(node, "intensity")?, "intensity")?,
                    },
                    "spot" => {
                        let p = pos()?;
                        let at = cx
                            .child_v3(node, "look-at-m")?
                            .ok_or_else(|| cx.err(node, "spot light needs look-at-m"))?;
                        let cone = cx.positive(node, "cone-deg")?.unwrap_or(30.0);
                        let start = cx.num(node, "falloff-start-deg")?.unwrap_or(cone);
                        Light::Spot {
                            position: p,
                            direction: at - p,
                            cone_angle_deg: cone,
                            falloff_start_deg: start,
                            intensity: need(cx.spectrum(node, "intensity")?, "intensity")?,
                        }
                    }
                    "distant" => {
                        let d = cx.child_v3(node, "direction")?.ok_or_else(|| {
                            cx.err(
                                node,
                                "distant light needs direction (where the light travels)",
                            )
                        })?;
                        Light::Distant {
                            direction: d,
                            irradiance: need(cx.spectrum(node, "irradiance")?, "irradiance")?,
                        }
                    }
                    "infinite" => Light::Infinite {
                        radiance: need(cx.spectrum(node, "radiance")?, "radiance")?,
                    },
                    other => {
                        return Err(cx.err(
                            node,
                            format!(
                                "unknown light type '{other}' (point, spot, distant, infinite)"
                            ),
                        ));
                    }
                };
                scene.lights.push(l);
            }
            _ => {}
        }
    }
    if let Some(node) = camera_node {
        cx.check_children(node, &["position-m", "look-at-m", "up"])?;
        let model = cx.camera_model(node)?;
        let pose = CameraPose {
            position: cx
                .child_v3(node, "position-m")?
                .unwrap_or(CameraPose::default().position),
            look_at: cx.child_v3(node, "look-at-m")?.unwrap_or(DVec3::ZERO),
            up: cx.child_v3(node, "up")?.unwrap_or(DVec3::Y),
        };
        let to_world = look_at_to_world(&pose).ok_or_else(|| {
            cx.err(
                node,
                "degenerate camera pose (look-at equals position, or up parallel to the view)",
            )
        })?;
        scene.camera = Some(CameraSpec { to_world, model });
    }
    Ok(SceneFile {
        scene,
        spp,
        max_bounces,
        path: path.to_path_buf(),
    })
}

#[cfg(test)]
mod tests {
    use super::*;

    #[test]
    fn errors_point_at_file_line_col() {
        let src = "film width-px=10 height-px=10\nmaterial \"w\" diffuse=\"cbox-white-wal\"\n";
        let e = parse_kdl_scene(src, Path::new("t.kdl"))
            .unwrap_err()
            .to_string();
        assert!(
            e.contains("t.kdl:2:") && e.contains("cbox-white-wall"),
            "{e}"
        );
        let src = "material \"w\" diffuse=\"one\"\nshape \"a\" type=\"sphere\" material=\"w\" {\n  radius-m 0.1\n  positon-m 0 0 0\n}\n";
        let e = parse_kdl_scene(src, Path::new("t.kdl"))
            .unwrap_err()
            .to_string();
        assert!(e.contains("t.kdl:4:3") && e.contains("position-m"), "{e}");
        let e = parse_kdl_scene("film width-px=10 {", Path::new("t.kdl"))
            .unwrap_err()
            .to_string();
        assert!(e.contains("t.kdl:1:"), "{e}");
        let src = "material \"w\" diffuse=\"one\"\nshape \"a\" type=\"sphere\" material=\"white\" { radius-m 1; }\n";
        let e = parse_kdl_scene(src, Path::new("t.kdl"))
            .unwrap_err()
            .to_string();
        assert!(
            e.contains("t.kdl:2:") && e.contains("unknown material"),
            "{e}"
        );
    }
}
