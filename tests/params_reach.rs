//! Parameter reach: every property of the experiment language (the schemas
//! `camsim params` prints, which are the language reference's tables) is set,
//! alone, to its schema's distinctive example in a KDL experiment; the file is
//! parsed and checked as `camsim check` does, the stage that reads the
//! property is built by the same function `run` uses, and the value the BUILT
//! stage holds — read back into the KDL unit by this test's own arithmetic
//! (tests/params_reach/*.rs for the sensor and the measurements) — must equal
//! the example. A unit slip (film distance in mm where metres are meant), a
//! dropped property or one read by nobody fails here. Then a misspelt and a
//! wrong-typed version of the property must each fail `check` at the
//! property's line.
//!
//! The list is the code's: a property added to a schema without a probe here
//! fails `every_property_reaches_its_stage` ("no probe").

#[path = "params_reach/measure.rs"]
mod measure_probe;
#[path = "params_reach/sensor.rs"]
mod sensor_probe;

use camsim::experiment::{self, Loader, language, stages};
use camsim::params::{Kind, ParamSpec, Params, Schema, Value};
use camsim::scene::edits::{self, TargetSpec};
use camsim::scene::{CameraModel, Light, Material};
use std::collections::BTreeMap;
use std::path::{Path, PathBuf};

const ROOT: &str = env!("CARGO_MANIFEST_DIR");

/// Parse a KDL value as written in a schema example.
fn parse_example(s: &str) -> Value {
    let s = s.trim();
    if let Some(inner) = s.strip_prefix('(').and_then(|x| x.strip_suffix(')')) {
        return Value::List(
            inner
                .split_whitespace()
                .map(|t| Value::Number(t.parse().unwrap()))
                .collect(),
        );
    }
    if let Some(t) = s.strip_prefix('"').and_then(|x| x.strip_suffix('"')) {
        return Value::String(t.to_string());
    }
    match s {
        "#true" => Value::Bool(true),
        "#false" => Value::Bool(false),
        _ => Value::Number(s.parse().unwrap_or_else(|_| panic!("example '{s}'"))),
    }
}

fn same(a: &Value, b: &Value) -> bool {
    match (a, b) {
        (Value::Number(x), Value::Number(y)) => (x - y).abs() <= 1e-12 * x.abs().max(y.abs()),
        (Value::List(x), Value::List(y)) => {
            x.len() == y.len() && x.iter().zip(y).all(|(p, q)| same(p, q))
        }
        // a single number where a list is accepted
        (Value::Number(_), Value::List(y)) if y.len() == 3 => y.iter().all(|q| same(a, q)),
        _ => a == b,
    }
}

/// An experiment whose nodes hold `props`, keyed by node, each node's other
/// properties being the minimum it needs. Returns the text and the line of
/// `target_prop` (1-based).
struct Case {
    nodes: BTreeMap<&'static str, Vec<(String, String)>>,
    extra: Vec<String>,
}

impl Case {
    fn new() -> Self {
        let mut nodes: BTreeMap<&'static str, Vec<(String, String)>> = BTreeMap::new();
        nodes.insert(
            "camera",
            vec![
                ("position-m".into(), "(0 0.115 -0.40)".into()),
                ("look-at-m".into(), "(0 0.115 0.60)".into()),
            ],
        );
        nodes.insert("render", vec![("spp".into(), "4".into())]);
        nodes.insert("sensor", vec![]);
        nodes.insert(
            "lens",
            vec![
                (
                    String::new(),
                    format!("\"{ROOT}/lenses/rtf/pixel4a-rearcamera-ellipse-raytransfer.json\""),
                ),
                ("film-distance-mm".into(), "0.465136".into()),
            ],
        );
        nodes.insert(
            "measure",
            vec![
                (String::new(), "\"colorimetry\"".into()),
                ("spectrum".into(), "\"cie-d65\"".into()),
            ],
        );
        Self {
            nodes,
            extra: vec![],
        }
    }
    fn set(&mut self, node: &'static str, k: &str, v: &str) {
        let props = self.nodes.entry(node).or_default();
        props.retain(|(n, _)| n != k);
        props.push((k.to_string(), v.to_string()));
    }
    fn replace(&mut self, node: &'static str, props: Vec<(&str, &str)>) {
        self.nodes.insert(
            node,
            props
                .into_iter()
                .map(|(a, b)| (a.to_string(), b.to_string()))
                .collect(),
        );
    }
    fn text(&self, dir: &Path) -> String {
        // The scene schema's own cases read the Cornell box (materials="paper");
        // every other case a scene with nothing near the origin, so added
        // objects stand free (check refuses intersecting objects) and
        // `override "LeftWall"` finds an emitting object.
        let scene = if self.nodes.contains_key("scene") {
            format!("{ROOT}/scenes/CornellBoxReference/CornellBoxReference.pbrt")
        } else {
            dir.join("reach-scene.kdl").to_string_lossy().to_string()
        };
        let mut s = format!(
            "experiment \"reach\" {{\n    scene \"{scene}\"{}\n",
            self.props("scene")
        );
        for node in [
            "camera", "lens", "render", "override", "add", "measured", "measure", "sanity",
            "summary",
        ] {
            if let Some(p) = self.nodes.get(node) {
                s.push_str(&format!("    {node}{}", fmt_props(p)));
                // `target` is a child of `render`
                if let (Some(t), "render") = (self.nodes.get("target"), node) {
                    s.push_str(&format!(" {{\n        target{}\n    }}", fmt_props(t)));
                }
                s.push('\n');
            }
        }
        s.push_str(&format!(
            "    sensor \"{ROOT}/sensors/imx363.kdl\"{}\n",
            self.props("sensor")
        ));
        for e in &self.extra {
            s.push_str(&format!("    {e}\n"));
        }
        s.push_str("}\n");
        let _ = dir;
        s
    }
    fn props(&self, node: &str) -> String {
        self.nodes
            .get(node)
            .map(|p| fmt_props(p))
            .unwrap_or_default()
    }
}

fn fmt_props(p: &[(String, String)]) -> String {
    p.iter()
        .map(|(k, v)| {
            if k.is_empty() {
                format!(" {v}")
            } else {
                format!(" {k}={v}")
            }
        })
        .collect()
}

/// The KDL node a schema's properties are written on, and what it needs
/// besides the property under test.
fn setup(schema: &Schema, p: &ParamSpec, c: &mut Case) -> &'static str {
    let ex = p.example;
    let node = schema.node;
    if node.starts_with("scene") {
        c.set("scene", p.name, ex);
        return "scene";
    }
    if node == "camera" {
        c.set("camera", p.name, ex);
        return "camera";
    }
    if node == "render" {
        // error-driven sampling: a target needs a budget and a budget a
        // target, both a measurement whose figures the render changes
        match p.name {
            "target-stderr" => c.set("render", "max-spp", "64"),
            "max-s" | "max-spp" => c.set("render", "target-stderr", "\"1%\""),
            _ => {}
        }
        if matches!(p.name, "target-stderr" | "max-s" | "max-spp") {
            c.replace("measure", vec![("", "\"ri\"")]);
        }
        c.set("render", p.name, ex);
        return "render";
    }
    if node.starts_with("target ") {
        c.replace("measure", vec![("", "\"ri\"")]);
        c.set("render", "max-spp", "64");
        c.replace("target", vec![("", "\"ri\""), ("stderr", "0.5")]);
        c.set("target", p.name, ex);
        return "target";
    }
    if node == "sensor" {
        c.set("sensor", p.name, ex);
        return "sensor";
    }
    if node.starts_with("lens \"FILE\"") {
        let file = format!("\"{ROOT}/lenses/prescriptions/dgauss.28deg-zemax.json\"");
        c.replace("lens", vec![("", &file)]);
        if p.name == "rtf-axis-weight" {
            c.set("lens", "rtf-degree", "3");
        }
        c.set("lens", p.name, ex);
        return "lens";
    }
    if node.starts_with("lens model") {
        c.replace("lens", vec![]);
        match p.name {
            "f-number" | "falloff" => c.set("lens", "fov-deg", "40"),
            "model" => c.set("lens", "focal-length-mm", "4.38"),
            "focal-length-mm" => c.set("lens", "model", "\"thin-lens\""),
            "focus-distance-m" => {
                c.set("lens", "model", "\"thin-lens\"");
                c.set("lens", "focal-length-mm", "4.38");
            }
            _ => {}
        }
        c.set("lens", p.name, ex);
        return "lens";
    }
    if let Some(t) = node.strip_prefix("add target=") {
        let target = t.trim_matches('"');
        c.replace(
            "add",
            vec![("", "\"t\""), ("target", &format!("\"{target}\""))],
        );
        match target {
            "mesh" if p.name != "file" => c.set("add", "file", "\"scenes/bunny.obj\""),
            "spot-light" => {
                c.set("add", "position-m", "(0 0.2 0)");
                c.set("add", "look-at-m", "(0 0 0)");
                c.set("add", "intensity", "\"cie-a\"");
                c.set("add", "cone-deg", "60");
            }
            _ => {}
        }
        // `target` names the schema: its value is the schema's own target
        let target_value = format!("\"{target}\"");
        let ex = if p.name == "target" {
            target_value.as_str()
        } else {
            ex
        };
        c.set("add", p.name, ex);
        return "add";
    }
    if node.starts_with("override") {
        c.replace("override", vec![("", "\"LeftWall\"")]);
        c.set("override", p.name, ex);
        return "override";
    }
    if node.starts_with("measured") {
        c.replace(
            "measured",
            vec![("", "\"cap\""), ("file", "\"capture.png\"")],
        );
        match p.name {
            "labels" => c.set("measured", "names", "\"names.txt\""),
            "names" => c.set("measured", "labels", "\"labels.png\""),
            _ => {}
        }
        c.set("measured", p.name, ex);
        return "measured";
    }
    if node.starts_with("sanity") {
        c.replace("sanity", vec![("", "\"pov\"")]);
        c.set("sanity", p.name, ex);
        return "sanity";
    }
    if let Some(k) = node.strip_prefix("summary ") {
        let kind = k.trim_matches('"');
        c.replace(
            "summary",
            vec![("", &format!("\"{kind}\"")), ("of", "\"colorimetry\"")],
        );
        c.set("summary", "axis", "\"tag.a\"");
        match kind {
            "qe-correction" => {
                c.set("summary", "measured", "\"m\"");
                c.set("summary", "nominal", "\"n\"");
            }
            _ => c.set("summary", "reference", "\"r\""),
        }
        if p.name == "of" {
            // of= names a measurement of the experiment: give it the example's name
            c.set("measure", "name", p.example);
        }
        c.set("summary", p.name, ex);
        return "summary";
    }
    if let Some(k) = node.strip_prefix("measure ") {
        let kind = k.trim_matches('"');
        c.replace("measure", vec![("", &format!("\"{kind}\""))]);
        match kind {
            "colorimetry" if p.name != "spectrum" => c.set("measure", "spectrum", "\"cie-d65\""),
            "sfr" | "profile" if p.name != "of" => c.set("measure", "of", "\"LeftWall\""),
            "mcc" if p.name != "of" => c.set("measure", "of", "\"mcc\""),
            "compare-curve" => {
                for (k, v) in [
                    ("curve", "\"ri\""),
                    (
                        "reference-file",
                        "\"lenses/zemax-reference/zemax_p4a_geometric_mtf.csv\"",
                    ),
                ] {
                    if p.name != k {
                        c.set("measure", k, v);
                    }
                }
            }
            // these two go together
            "conversion-gain" if p.name == "reference-mean-dv" => {
                c.set("measure", "reference-variance-dv2", "57.8")
            }
            "conversion-gain" if p.name == "reference-variance-dv2" => {
                c.set("measure", "reference-mean-dv", "320.7")
            }
            "stability" if p.name != "case" => c.set("measure", "case", "\"scale\""),
            _ => {}
        }
        if p.name == "input" || (kind == "ri" && p.name == "channel") {
            c.extra.push(
                "measured \"capture-near\" file=\"capture.png\" labels=\"labels.png\" names=\"names.txt\""
                    .into(),
            );
            match kind {
                "sfr" => c.set("measure", "roi-px", "(0 0 2 2)"),
                "noise" => c.set("measure", "conversion-gain-dv-e", "0.17"),
                "ri" if p.name == "channel" => c.set("measure", "input", "\"capture-near\""),
                _ => {}
            }
        }
        c.set("measure", p.name, ex);
        return "measure";
    }
    panic!("no KDL node for schema '{node}'");
}

/// Schemas probed at the parameter level only: their required cross-references
/// (a measurement to compare against, or to re-render) are checked by
/// tests/experiment_measured.rs.
fn params_level_only(schema: &Schema) -> bool {
    schema.node == "measure \"compare\""
        || schema.node == "measure \"compare-curve\""
        || schema.node == "measure \"convergence\""
}

fn write_side_files(dir: &Path) {
    // a 2×2 grey PNG for `measured` inputs (file existence and type are checked)
    let f = std::fs::File::create(dir.join("capture.png")).unwrap();
    let mut e = png::Encoder::new(f, 2, 2);
    e.set_color(png::ColorType::Grayscale);
    e.set_depth(png::BitDepth::Eight);
    e.write_header()
        .unwrap()
        .write_image_data(&[0, 1, 1, 0])
        .unwrap();
    std::fs::copy(dir.join("capture.png"), dir.join("labels.png")).unwrap();
    std::fs::write(dir.join("names.txt"), "background\nthing\n").unwrap();
    // the scene of the non-scene cases: one emitting panel 5 m away
    std::fs::write(
        dir.join("reach-scene.kdl"),
        "film width-px=64 height-px=48 pixel-pitch-um=1.4\n\
         material \"white\" diffuse=\"constant:0.5\"\n\
         shape \"LeftWall\" type=\"rectangle\" material=\"white\" emission=\"constant:1\" {\n\
         position-m 0 0 5\n    size-m 1 1\n    normal 0 0 -1\n}\n",
    )
    .unwrap();
    // relative mesh files (`scenes/bunny.obj`) resolve from the experiment's directory
    std::os::unix::fs::symlink(Path::new(ROOT).join("scenes"), dir.join("scenes")).unwrap();
    std::os::unix::fs::symlink(Path::new(ROOT).join("lenses"), dir.join("lenses")).unwrap();
    // the nominal sensor file of `summary "qe-correction" sensor=…`
    std::os::unix::fs::symlink(Path::new(ROOT).join("sensors"), dir.join("sensors")).unwrap();
}

fn parse(dir: &Path, text: &str) -> Result<experiment::plan::Plan, String> {
    let path = dir.join("reach.kdl");
    let p = experiment::parse_source(&path, text.to_string(), Loader::Disk)
        .map_err(|e| e.to_string())?;
    experiment::plan(&p, None).map_err(|e| e.to_string())
}

fn spectrum_is(s: &camsim::spectrum::Spectrum, name: &str) -> bool {
    let r = camsim::spectrum::library::named(name).unwrap();
    s.wavelengths_nm == r.wavelengths_nm
        && s.values.len() == r.values.len()
        && s.values
            .iter()
            .zip(&r.values)
            .all(|(a, b)| (a - b).abs() <= 1e-12 * b.abs().max(1e-300))
}

fn num(x: f64) -> Option<Value> {
    Some(Value::Number(x))
}
fn text(s: &str) -> Option<Value> {
    Some(Value::String(s.to_string()))
}
fn v3(v: glam::DVec3) -> Option<Value> {
    Some(Value::List(vec![
        Value::Number(v.x),
        Value::Number(v.y),
        Value::Number(v.z),
    ]))
}

/// The value the built stage holds for (node, property), in the KDL unit.
fn probe(
    schema: &Schema,
    p: &ParamSpec,
    spec: &experiment::ResolvedExperiment,
    dir: &Path,
) -> Result<Option<Value>, String> {
    let e = |x: camsim::Error| x.to_string();
    let node = schema.node;
    let ex = parse_example(p.example);
    Ok(match node {
        "scene \"FILE\"" => {
            // the paper's spectra replace the pbrt file's placeholder materials
            let scene = stages::build_scene(spec).map_err(e)?;
            let left = scene
                .materials
                .iter()
                .find(|m| m.name == "LeftWall")
                .unwrap();
            match &left.material {
                Material::DiffuseSpecular { diffuse, .. }
                    if spectrum_is(diffuse, "cbox-red-wall") =>
                {
                    text("paper")
                }
                _ => text("file"),
            }
        }
        "camera" => {
            let scene = stages::build_scene(spec).map_err(e)?;
            let m = scene.camera.unwrap().to_world;
            let eye = m.transform_point3(glam::DVec3::ZERO);
            let fwd = m.transform_vector3(glam::DVec3::Z).normalize();
            let up = m.transform_vector3(glam::DVec3::Y).normalize();
            match p.name {
                "position-m" => v3(eye),
                // the camera looks along the example's direction: report the
                // point on that ray at the example's distance
                "look-at-m" => {
                    let Value::List(l) = &ex else { unreachable!() };
                    let target = glam::DVec3::new(num_of(&l[0]), num_of(&l[1]), num_of(&l[2]));
                    v3(eye + fwd * (target - eye).length())
                }
                // `up` is orthogonalised against the view: compare directions
                "up" => {
                    let Value::List(l) = &ex else { unreachable!() };
                    let w = glam::DVec3::new(num_of(&l[0]), num_of(&l[1]), num_of(&l[2]));
                    let w_perp = (w - fwd * w.dot(fwd)).normalize();
                    if (up - w_perp).length() < 1e-12 {
                        Some(ex.clone())
                    } else {
                        v3(up)
                    }
                }
                _ => None,
            }
        }
        "render" => {
            let r = stages::render_settings(spec).map_err(e)?;
            match p.name {
                "spp" => num(r.spp as f64),
                "max-bounces" => num(r.max_bounces as f64),
                "seed" => num(r.seed as f64),
                "sampler" => text(r.sampler.name()),
                "wavelength-nm" => Some(Value::List(vec![
                    Value::Number(r.grid.start_nm),
                    Value::Number(r.grid.start_nm + r.grid.step_nm * (r.grid.count as f64 - 1.0)),
                    Value::Number(r.grid.step_nm),
                ])),
                // error-driven sampling reads the spec's render settings (run.rs)
                "target-stderr" => spec.render.target_stderr.and_then(|t| text(&t.to_string())),
                "max-s" => spec.render.max_s.and_then(num),
                "max-spp" => spec.render.max_spp.and_then(|n| num(n as f64)),
                _ => None,
            }
        }
        n if n.starts_with("target ") => {
            let t = spec.render.targets.first().ok_or("no target")?;
            match p.name {
                "stderr" => match t.stderr {
                    camsim::experiment::spec::StderrTarget::Absolute(a) => num(a),
                    r => text(&r.to_string()),
                },
                "quantity" => t.quantity.as_deref().and_then(text),
                _ => None,
            }
        }
        "sensor" => {
            let cfg = stages::sensor_config(spec).map_err(e)?.unwrap();
            sensor_probe::probe(p.name, &cfg)
        }
        n if n.starts_with("lens") => {
            let scene = camsim::scene::Scene::default();
            let model = stages::camera_model(spec, &scene).map_err(e)?;
            match (&model, p.name) {
                (CameraModel::LensFile { .. }, "film-distance-mm") => {
                    // the film distance inside the built camera
                    let cam = stages::build_camera(spec, &scene).map_err(e)?;
                    num(cam.film_distance_m().unwrap() * 1e3)
                }
                (
                    CameraModel::LensFile {
                        focus_distance_m, ..
                    },
                    "focus-distance-m",
                ) => focus_distance_m.and_then(num),
                (CameraModel::LensFile { rtf_fit, .. }, "rtf-degree") => {
                    rtf_fit.map(|f| f.degree as f64).and_then(num)
                }
                (CameraModel::LensFile { rtf_fit, .. }, "rtf-axis-weight") => {
                    rtf_fit.map(|f| f.axis_weight).and_then(num)
                }
                (CameraModel::ThinLens { .. }, "model") => text("thin-lens"),
                (CameraModel::Pinhole { .. }, "model") => text("pinhole"),
                (CameraModel::Pinhole { fov_deg, .. }, "fov-deg") => num(*fov_deg),
                (CameraModel::Pinhole { cos4, .. }, "falloff") => {
                    text(if *cos4 { "cos4" } else { "none" })
                }
                (CameraModel::Pinhole { f_number, .. }, "f-number")
                | (CameraModel::ThinLens { f_number, .. }, "f-number") => num(*f_number),
                (CameraModel::ThinLens { focal_length_m, .. }, "focal-length-mm") => {
                    num(focal_length_m * 1e3)
                }
                (
                    CameraModel::ThinLens {
                        focus_distance_m, ..
                    },
                    "focus-distance-m",
                ) => num(*focus_distance_m),
                _ => None,
            }
        }
        n if n.starts_with("add") => {
            let a = &spec.additions[0];
            let t = stages::target_spec(a, dir).map_err(|x| x.to_string())?;
            match (&t, p.name) {
                (TargetSpec::Mcc(_), "target") => text("mcc"),
                (TargetSpec::SlantedEdge(_), "target") => text("slanted-edge"),
                (TargetSpec::Mesh(_), "target") => text("mesh"),
                (TargetSpec::Light(_), "target") => text("spot-light"),
                (TargetSpec::Mcc(c), "position-m") => v3(c.position_m),
                (TargetSpec::SlantedEdge(c), "position-m") => v3(c.position_m),
                (TargetSpec::Mesh(c), "position-m") => v3(c.position_m),
                (TargetSpec::Light(Light::Spot { position, .. }), "position-m") => v3(*position),
                (TargetSpec::Mcc(c), "rotate-deg") => v3(c.rotation_deg),
                (TargetSpec::SlantedEdge(c), "rotate-deg") => v3(c.rotation_deg),
                (TargetSpec::Mesh(c), "rotate-deg") => v3(glam::DVec3::new(0.0, c.rot_y_deg, 0.0)),
                // defaults from cornellbox_setup.json (targets.rs): 8.4 × 5.6 cm chart,
                // 0.096 × 0.156 m plate
                (TargetSpec::Mcc(c), "scale") => num(c.width_m / 0.084),
                (TargetSpec::SlantedEdge(c), "scale") => num(c.width_m / 0.096),
                (TargetSpec::Mesh(c), "scale") => num(c.scale),
                (TargetSpec::Mesh(c), "file") => {
                    let want = Path::new(ROOT).join("scenes/bunny.obj");
                    if c.path.canonicalize().ok() == want.canonicalize().ok() {
                        text("scenes/bunny.obj")
                    } else {
                        text(&c.path.display().to_string())
                    }
                }
                (TargetSpec::Mcc(c), "patch-size-m") => num(c.patch_size_m),
                (TargetSpec::Mcc(c), "patch-pitch-m") => num(c.patch_pitch_m),
                (TargetSpec::SlantedEdge(c), "tilt-deg") => num(c.tilt_deg),
                (TargetSpec::SlantedEdge(c), "reflectance") => spectrum_text(&c.white, &ex),
                (TargetSpec::Mesh(c), "reflectance") => spectrum_text(&c.reflectance, &ex),
                (
                    TargetSpec::Light(Light::Spot {
                        position,
                        direction,
                        ..
                    }),
                    "look-at-m",
                ) => {
                    let Value::List(l) = &ex else { unreachable!() };
                    let t = glam::DVec3::new(num_of(&l[0]), num_of(&l[1]), num_of(&l[2]));
                    v3(*position + *direction * (t - *position).length())
                }
                (TargetSpec::Light(Light::Spot { intensity, .. }), "intensity") => {
                    // with intensity-scale 1
                    spectrum_text(intensity, &ex)
                }
                (TargetSpec::Light(Light::Spot { intensity, .. }), "intensity-scale") => {
                    let a = camsim::spectrum::library::named("cie-a").unwrap();
                    num(intensity.values[10] / a.values[10])
                }
                (TargetSpec::Light(Light::Spot { cone_angle_deg, .. }), "cone-deg") => {
                    num(*cone_angle_deg)
                }
                (
                    TargetSpec::Light(Light::Spot {
                        falloff_start_deg, ..
                    }),
                    "falloff-start-deg",
                ) => num(*falloff_start_deg),
                _ => None,
            }
        }
        n if n.starts_with("override") => {
            let o =
                edits::override_spec(&spec.overrides[0].params, dir).map_err(|x| x.to_string())?;
            match p.name {
                "reflectance" => o.reflectance.as_ref().and_then(|s| spectrum_text(s, &ex)),
                "radiance" => o.radiance.as_ref().and_then(|s| spectrum_text(s, &ex)),
                "radiance-scale" => o.radiance_scale.and_then(num),
                _ => None,
            }
        }
        n if n.starts_with("measured") => {
            let m = &spec.measured[0];
            let file =
                |f: &Option<experiment::spec::FileRef>| f.as_ref().map(|f| f.written.clone());
            match p.name {
                "file" => text(&m.file.written),
                "pixel-um" => m.pixel_um.and_then(num),
                "labels" => file(&m.labels).as_deref().and_then(text),
                "names" => file(&m.names).as_deref().and_then(text),
                _ => None,
            }
        }
        n if n.starts_with("sanity") => {
            let o = camsim::pov::check_params::pov_check(&spec.sanity.as_ref().unwrap().params)
                .map_err(|x| x.to_string())?;
            match p.name {
                "min-iou" => num(o.min_iou),
                "width-px" => o.width_px.map(|x| x as f64).and_then(num),
                "height-px" => o.height_px.map(|x| x as f64).and_then(num),
                "through" => text(if o.through_lens { "lens" } else { "pinhole" }),
                _ => None,
            }
        }
        n if n.starts_with("summary ") => {
            let m = &spec.summaries[0];
            match p.name {
                "name" => text(&m.name),
                "of" => m.of.first().and_then(|s| text(s)),
                _ => {
                    use camsim::summary::SummaryOptions as S;
                    let o = camsim::summary::options(&m.kind, &m.params, dir)
                        .map_err(|x| x.to_string())?;
                    let t = |s: &Option<String>| s.as_deref().and_then(text);
                    match (&o, p.name) {
                        (S::QeCorrection(q), "note") => t(&q.note),
                        (S::Steps(q), "note") => t(&q.note),
                        (S::QeCorrection(q), "axis") => t(&q.axis),
                        (S::Steps(q), "axis") => t(&q.axis),
                        (S::QeCorrection(q), "measured") => t(&q.measured),
                        (S::QeCorrection(q), "nominal") => t(&q.nominal),
                        (S::QeCorrection(q), "exclude-patch-number") => Some(Value::List(
                            q.exclude.iter().map(|&x| Value::Number(x as f64)).collect(),
                        )),
                        // the file as found from the experiment's directory
                        (S::QeCorrection(q), "sensor") => q
                            .sensor
                            .as_ref()
                            .and_then(|f| f.strip_prefix(dir).ok())
                            .and_then(|f| text(&f.to_string_lossy())),
                        (S::Steps(q), "reference") => t(&q.reference),
                        (S::Steps(q), "quantity") => text(&q.quantity),
                        (S::Steps(q), "histogram-bin-dv") => num(q.bin),
                        _ => None,
                    }
                }
            }
        }
        n if n.starts_with("measure ") => {
            let m = &spec.measures[0];
            match p.name {
                "name" => text(&m.name),
                "of" => match m.of.as_slice() {
                    [one] => text(one),
                    _ => None,
                },
                "input" => m.params.get("input").cloned(),
                _ => {
                    let o = camsim::measure::request::options(&m.kind, &m.params, dir)
                        .map_err(|x| x.to_string())?;
                    measure_probe::probe(&m.kind, p.name, &o)
                }
            }
        }
        _ => None,
    })
}

fn num_of(v: &Value) -> f64 {
    match v {
        Value::Number(x) => *x,
        _ => panic!("{v:?}"),
    }
}

/// A spectrum reported as the example's name when it is that library spectrum.
fn spectrum_text(s: &camsim::spectrum::Spectrum, ex: &Value) -> Option<Value> {
    match ex {
        Value::String(n) if spectrum_is(s, n) => Some(ex.clone()),
        _ => text(&s.name),
    }
}

/// The line (1-based) and column (1-based, characters) of `needle` in `text`.
fn line_col(text: &str, needle: &str) -> (usize, usize) {
    let off = text
        .find(needle)
        .unwrap_or_else(|| panic!("'{needle}' not in\n{text}"));
    let line = text[..off].matches('\n').count() + 1;
    let col = text[..off].rfind('\n').map_or(off, |n| off - n - 1) + 1;
    (line, col)
}

/// A misspelling of `name` that is no property of the schema.
fn misspell(name: &str, schema: &Schema) -> String {
    let mut cands = vec![];
    for i in 1..name.len() {
        if name.is_char_boundary(i) && name.is_char_boundary(i + 1) && &name[i..i + 1] != "-" {
            cands.push(format!("{}{}", &name[..i], &name[i + 1..]));
        }
    }
    cands.push(format!("{name}x"));
    cands
        .into_iter()
        .find(|c| schema.get(c).is_none() && c.len() > 1)
        .unwrap()
}

/// A value of the wrong type for `kind`.
fn wrong_value(kind: Kind) -> &'static str {
    match kind {
        Kind::Number | Kind::Integer | Kind::Numbers | Kind::Vec3 | Kind::NumberOr(_) => "#true",
        Kind::Text | Kind::Choice(_) | Kind::Spectrum | Kind::File => "7",
        Kind::Bool => "\"yes\"",
    }
}

#[test]
fn every_property_reaches_its_stage() {
    let tmp = tempfile::tempdir().unwrap();
    let dir = tmp.path();
    write_side_files(dir);
    let mut failures = vec![];
    let mut checked = 0;
    for schema in language::schemas() {
        for p in schema.params {
            let mut c = Case::new();
            if params_level_only(schema) {
                // parameter level: the measurement's options from {name: example}
                if matches!(p.name, "name" | "of" | "input") {
                    continue; // experiment-level, probed on the other kinds
                }
                let mut params = Params::new();
                params.set(p.name, parse_example(p.example));
                let kind = schema.node.trim_start_matches("measure ").trim_matches('"');
                match camsim::measure::request::options(kind, &params, dir) {
                    Ok(o) => match measure_probe::probe(kind, p.name, &o) {
                        Some(v) if same(&parse_example(p.example), &v) => checked += 1,
                        other => failures.push(format!(
                            "{} {}: example {} → built {:?}",
                            schema.node, p.name, p.example, other
                        )),
                    },
                    Err(e) => failures.push(format!("{} {}: {e}", schema.node, p.name)),
                }
                continue;
            }
            setup(schema, p, &mut c);
            let text = c.text(dir);
            let plan = match parse(dir, &text) {
                Ok(pl) => pl,
                Err(e) => {
                    failures.push(format!(
                        "{} {}: check failed: {e}\n{text}",
                        schema.node, p.name
                    ));
                    continue;
                }
            };
            let spec = &plan.variants[0].variant.spec;
            let expected = match (schema.node.strip_prefix("add target="), p.name) {
                (Some(t), "target") => Value::String(t.trim_matches('"').to_string()),
                _ => parse_example(p.example),
            };
            match probe(schema, p, spec, dir) {
                Ok(Some(v)) if same(&expected, &v) => checked += 1,
                Ok(Some(v)) => failures.push(format!(
                    "{} {}: example {} → the built stage holds {v:?}",
                    schema.node, p.name, p.example
                )),
                Ok(None) => failures.push(format!(
                    "{} {}: no probe (or the value did not arrive)",
                    schema.node, p.name
                )),
                Err(e) => failures.push(format!(
                    "{} {}: building the stage: {e}",
                    schema.node, p.name
                )),
            }
        }
    }
    assert!(
        failures.is_empty(),
        "{} reached; failures:\n{}",
        checked,
        failures.join("\n")
    );
    assert!(checked >= 100, "only {checked} properties checked");
}

#[test]
fn misspelt_and_wrong_typed_properties_fail_check_at_their_line() {
    let tmp = tempfile::tempdir().unwrap();
    let dir = tmp.path();
    write_side_files(dir);
    let mut failures = vec![];
    for schema in language::schemas() {
        if params_level_only(schema) {
            continue; // tests/measure_options.rs covers these at file:line:col
        }
        for p in schema.params {
            if matches!(p.name, "target") {
                continue; // names the schema itself (tests/malformed covers it)
            }
            // misspelt
            let mut c = Case::new();
            let node = setup(schema, p, &mut c);
            let bad = misspell(p.name, schema);
            let props = c.nodes.get_mut(node).unwrap();
            let i = props.iter().position(|(k, _)| k == p.name).unwrap();
            props[i].0 = bad.clone();
            let text = c.text(dir);
            let (line, col) = line_col(&text, &format!(" {bad}="));
            match parse(dir, &text) {
                Ok(_) => failures.push(format!("{} '{bad}': passed check", schema.node)),
                Err(e) => {
                    let at = format!("reach.kdl:{line}:{}:", col + 1);
                    if !e.contains(&at) || !e.contains(&bad) {
                        failures.push(format!(
                            "{} '{bad}': not located at {at}:\n{e}",
                            schema.node
                        ));
                    }
                }
            }
            // wrong type
            let mut c = Case::new();
            let node = setup(schema, p, &mut c);
            let wrong = wrong_value(p.kind);
            let props = c.nodes.get_mut(node).unwrap();
            let i = props.iter().position(|(k, _)| k == p.name).unwrap();
            props[i].1 = wrong.to_string();
            let text = c.text(dir);
            let (line, _) = line_col(&text, &format!(" {}={wrong}", p.name));
            match parse(dir, &text) {
                Ok(_) => failures.push(format!("{} {}={wrong}: passed check", schema.node, p.name)),
                Err(e) => {
                    if !e.contains(&format!("reach.kdl:{line}:")) {
                        failures.push(format!(
                            "{} {}={wrong}: not at line {line}:\n{e}",
                            schema.node, p.name
                        ));
                    }
                }
            }
        }
    }
    assert!(failures.is_empty(), "{}", failures.join("\n"));
}

/// The language reference's tables are `camsim params`'s output.
#[test]
fn language_reference_holds_the_generated_tables() {
    let doc =
        std::fs::read_to_string(PathBuf::from(ROOT).join("docs/experiment-language.md")).unwrap();
    for schema in language::schemas() {
        assert!(
            doc.contains(&schema.markdown()),
            "docs/experiment-language.md lacks the current table of `{}`: regenerate the tables with `camsim params`",
            schema.node
        );
    }
}
