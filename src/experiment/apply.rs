//! Typed values and parameter paths: converting a [`Value`] into the type a
//! field needs (shared by the parser and by sweeps, so a swept value is
//! checked exactly like a written one) and setting a value at a path such as
//! `sensor.exposure-s` or `object.edge-near.position-m`.
//!
//! Paths:
//! - `render.spp | render.max-bounces | render.seed | render.wavelength-nm |
//!   render.target-stderr | render.max-s | render.max-spp`
//! - `camera.position-m | camera.look-at-m | camera.up`
//! - `scene.file`, `lens.file`, `sensor.file` (a file reference)
//! - `lens.<name>`, `sensor.<name>` (an inline override)
//! - `object.<id>.position-m | rotate-deg | scale | file | <name>` (an added object)
//! - `override.<object>.<name>` (an override of a base-scene object)
//! - `measure.<name>.<property>` (a measurement property)
//! - `tag.<name>`: a label-only axis (appears in ids and results, changes nothing)

use super::spec::{ConfigSection, FileRef, ResolvedExperiment};
use super::units;
use crate::params::Value;
use crate::spectrum::WavelengthGrid;
use std::path::Path;

/// A problem with a value or a path: message (incl. what was expected) and help.
#[derive(Clone, Debug, PartialEq)]
pub struct ApplyError {
    pub message: String,
    pub help: Option<String>,
    /// The path itself is wrong (not the value).
    pub on_path: bool,
}

impl ApplyError {
    pub fn new(m: impl Into<String>) -> Self {
        Self {
            message: m.into(),
            help: None,
            on_path: false,
        }
    }
    /// Mark as an error of the path, not of the value.
    pub fn path(mut self) -> Self {
        self.on_path = true;
        self
    }
    pub fn help(mut self, h: impl Into<String>) -> Self {
        self.help = Some(h.into());
        self
    }
}

impl From<String> for ApplyError {
    fn from(s: String) -> Self {
        Self::new(s)
    }
}

pub type R<T> = Result<T, ApplyError>;

pub fn as_f64(v: &Value, what: &str) -> R<f64> {
    match v {
        Value::Number(x) if x.is_finite() => Ok(*x),
        Value::Number(x) => Err(ApplyError::new(format!(
            "'{what}' must be a finite number, found {x}"
        ))),
        o => Err(ApplyError::new(format!(
            "'{what}': expected a number, found {}",
            describe(o)
        ))),
    }
}

pub fn as_positive(v: &Value, what: &str) -> R<f64> {
    let x = as_f64(v, what)?;
    if x <= 0.0 {
        return Err(ApplyError::new(format!("'{what}' must be > 0, found {x}")));
    }
    Ok(x)
}

pub fn as_vec3(v: &Value, what: &str) -> R<[f64; 3]> {
    match v {
        Value::List(l) if l.len() == 3 => {
            let mut out = [0.0; 3];
            for (o, x) in out.iter_mut().zip(l) {
                *o = as_f64(x, what)?;
            }
            Ok(out)
        }
        Value::List(l) => Err(ApplyError::new(format!(
            "'{what}': expected 3 numbers (x y z), found {}",
            l.len()
        ))
        .help(format!("write {what}=(x y z), e.g. {what}=(0 0.1 -0.4)"))),
        o => Err(ApplyError::new(format!(
            "'{what}': expected 3 numbers (x y z), found {}",
            describe(o)
        ))
        .help(format!("write {what}=(x y z), e.g. {what}=(0 0.1 -0.4)"))),
    }
}

pub fn as_int(v: &Value, what: &str, min: u64, max: u64) -> R<u64> {
    let x = match v {
        Value::Number(x) => *x,
        o => {
            return Err(ApplyError::new(format!(
                "'{what}': expected an integer, found {}",
                describe(o)
            )));
        }
    };
    if !x.is_finite() || x.fract() != 0.0 {
        return Err(ApplyError::new(format!(
            "'{what}': expected an integer, found {x}"
        )));
    }
    if x < min as f64 || x > max as f64 {
        return Err(ApplyError::new(format!(
            "'{what}' = {x} is out of range; expected {min}…{max}"
        )));
    }
    Ok(x as u64)
}

/// A standard-error target: a positive number (absolute, in each figure's
/// own unit) or a percentage string `"1%"` (relative to |value|).
pub fn as_stderr_target(v: &Value, what: &str) -> R<super::spec::StderrTarget> {
    use super::spec::StderrTarget;
    let help = || {
        format!(
            "write {what}=\"1%\" (relative: stderr ≤ 1 % of |value|) or {what}=0.5 (absolute, in each figure's own unit)"
        )
    };
    match v {
        Value::Number(_) => Ok(StderrTarget::Absolute(as_positive(v, what)?)),
        Value::String(s) => {
            let pct = s
                .trim()
                .strip_suffix('%')
                .and_then(|p| p.trim().parse::<f64>().ok())
                .filter(|p| p.is_finite() && *p > 0.0 && *p < 1000.0);
            match pct {
                Some(p) => Ok(StderrTarget::Relative(p / 100.0)),
                None => Err(ApplyError::new(format!(
                    "'{what}': expected a positive number or a percentage like \"1%\", found \"{s}\""
                ))
                .help(help())),
            }
        }
        o => Err(ApplyError::new(format!(
            "'{what}': expected a positive number or a percentage like \"1%\", found {}",
            describe(o)
        ))
        .help(help())),
    }
}

pub fn as_str<'a>(v: &'a Value, what: &str) -> R<&'a str> {
    match v {
        Value::String(s) => Ok(s),
        o => Err(ApplyError::new(format!(
            "'{what}': expected a string, found {}",
            describe(o)
        ))),
    }
}

pub fn as_grid(v: &Value, what: &str) -> R<WavelengthGrid> {
    match v {
        Value::List(l) if l.len() == 3 => {
            let a = as_f64(&l[0], what)?;
            let b = as_f64(&l[1], what)?;
            let c = as_f64(&l[2], what)?;
            WavelengthGrid::new(a, b, c).map_err(|e| ApplyError::new(format!("'{what}': {e}")))
        }
        _ => Err(ApplyError::new(format!(
            "'{what}': expected (start stop step) in nm, found {}",
            describe(v)
        ))
        .help("e.g. wavelength-nm=(400 700 10)")),
    }
}

/// A short description of a value for messages.
pub fn describe(v: &Value) -> String {
    match v {
        Value::Bool(b) => format!("the boolean #{b}"),
        Value::Number(x) => format!("the number {}", fmt_value(&Value::Number(*x))),
        Value::String(s) => format!("the string \"{s}\""),
        Value::List(l) => format!("a list of {}", l.len()),
    }
}

/// Shortest round-trip text of a value (as used in variant ids and CSV).
pub fn fmt_value(v: &Value) -> String {
    match v {
        Value::Number(x) => {
            if *x == 0.0 {
                "0".into()
            } else {
                format!("{x}")
            }
        }
        Value::List(l) => format!(
            "({})",
            l.iter().map(fmt_value).collect::<Vec<_>>().join(" ")
        ),
        Value::Bool(b) => format!("{b}"),
        Value::String(s) => s.clone(),
    }
}

/// The unit rule for a generic (override / extra) property value.
pub fn check_generic(name: &str, v: &Value) -> R<()> {
    let numeric = match v {
        Value::Number(x) => {
            if !x.is_finite() {
                return Err(ApplyError::new(format!(
                    "'{name}' must be finite, found {x}"
                )));
            }
            true
        }
        Value::List(l) => {
            for x in l {
                if let Value::Number(n) = x
                    && !n.is_finite()
                {
                    return Err(ApplyError::new(format!(
                        "'{name}' must be finite, found {n}"
                    )));
                }
            }
            l.iter().any(|x| matches!(x, Value::Number(_)))
        }
        _ => false,
    };
    if numeric && !units::has_unit(name) {
        return Err(ApplyError::new(format!(
            "'{name}' holds a number but its name has no unit: expected a unit suffix, e.g. {}",
            units::suggest_unit(name)
        ))
        .help(units::unit_help(name)));
    }
    Ok(())
}

/// Find a relative file: in `base_dir`, then in each of its parents in turn
/// (so files under `experiments/` can name `scenes/…` relative to the project root).
pub fn resolve_ref(
    written: &str,
    base_dir: &Path,
    loader: super::source::Loader,
) -> Option<std::path::PathBuf> {
    crate::diag::find_up(written, base_dir, |p| loader.exists(p))
}

/// Resolve and check a file reference relative to `base_dir` (see [`resolve_ref`]).
pub fn file_ref(
    written: &str,
    base_dir: &Path,
    what: &str,
    loader: super::source::Loader,
) -> R<FileRef> {
    if written.trim().is_empty() {
        return Err(ApplyError::new(format!("{what}: empty file name")));
    }
    let Some(path) = resolve_ref(written, base_dir, loader) else {
        return Err(
            ApplyError::new(format!("{what} file '{written}' not found")).help(format!(
                "relative paths are looked up in {} and then in each parent directory",
                if base_dir.as_os_str().is_empty() {
                    ".".to_string()
                } else {
                    base_dir.display().to_string()
                }
            )),
        );
    };
    Ok(FileRef {
        written: written.to_string(),
        path,
        span: Default::default(),
    })
}

pub const PATH_ROOTS: &[&str] = &[
    "render", "camera", "scene", "lens", "sensor", "object", "override", "measure", "tag",
];

/// Set `value` at `path` in `spec`, with the same checks as when written in the file.
pub fn apply(
    spec: &mut ResolvedExperiment,
    path: &str,
    v: &Value,
    loader: super::source::Loader,
) -> R<()> {
    let parts: Vec<&str> = path.split('.').collect();
    let bad_root = || {
        ApplyError::new(format!(
            "unknown parameter path '{path}'; a path starts with one of: {}",
            PATH_ROOTS.join(", ")
        ))
        .help(
            crate::diag::did_you_mean(parts[0], PATH_ROOTS.iter().copied())
                .map(|s| format!("did you mean '{s}.{}'?", parts[1..].join(".")))
                .unwrap_or_else(|| {
                    "e.g. sensor.exposure-s, lens.film-distance-mm, render.spp, tag.label".into()
                }),
        )
        .path()
    };
    let unknown_key = |key: &str, known: &[&str], section: &str| {
        let mut e = ApplyError::new(format!(
            "unknown parameter '{key}' in '{section}'; expected one of: {}",
            known.join(", ")
        ));
        e.help = crate::diag::did_you_mean(key, known.iter().copied())
            .map(|s| format!("did you mean '{section}.{s}'?"));
        e.path()
    };
    let base_dir = spec
        .file
        .parent()
        .map(Path::to_path_buf)
        .unwrap_or_default();
    match parts.as_slice() {
        ["render", key] => match *key {
            "spp" => spec.render.spp = as_int(v, "spp", 1, 1_000_000_000)?,
            "max-bounces" => spec.render.max_bounces = as_int(v, "max-bounces", 0, 1000)? as u32,
            "seed" => spec.render.seed = as_int(v, "seed", 0, 1u64 << 53)?,
            "wavelength-nm" => spec.render.wavelength = as_grid(v, "wavelength-nm")?,
            "sampler" => {
                let name = as_str(v, "sampler")?;
                spec.render.sampler = crate::render::SamplerKind::parse(name).ok_or_else(|| {
                    let names = crate::render::SamplerKind::NAMES.map(|n| format!("\"{n}\""));
                    ApplyError::new(format!(
                        "'sampler': expected {}, found \"{name}\"",
                        names.join(" or ")
                    ))
                })?
            }
            "target-stderr" => {
                spec.render.target_stderr = Some(as_stderr_target(v, "target-stderr")?)
            }
            "max-s" => spec.render.max_s = Some(as_positive(v, "max-s")?),
            "max-spp" => spec.render.max_spp = Some(as_int(v, "max-spp", 1, 1_000_000_000)?),
            k => {
                return Err(unknown_key(
                    k,
                    &super::language::RENDER_SCHEMA.names(),
                    "render",
                ));
            }
        },
        ["camera", key] => {
            let Some(cam) = spec.camera.as_mut() else {
                return Err(
                    ApplyError::new(format!("'{path}': the experiment has no camera"))
                        .help("add a `camera position-m=(…) look-at-m=(…)` node")
                        .path(),
                );
            };
            match *key {
                "position-m" => cam.position_m = as_vec3(v, "position-m")?,
                "look-at-m" => cam.look_at_m = as_vec3(v, "look-at-m")?,
                "up" => cam.up = as_vec3(v, "up")?,
                k => {
                    return Err(unknown_key(
                        k,
                        &super::language::CAMERA_SCHEMA.names(),
                        "camera",
                    ));
                }
            }
            check_camera(cam)?;
        }
        ["scene", "file"] => {
            let mut f = file_ref(as_str(v, "scene.file")?, &base_dir, "scene", loader)?;
            if let Some(old) = &spec.scene {
                f.span = old.span;
            }
            spec.scene = Some(f);
        }
        ["scene", k] => return Err(unknown_key(k, &["file"], "scene")),
        [sec @ ("lens" | "sensor"), key] => {
            let section: &mut Option<ConfigSection> = if *sec == "lens" {
                &mut spec.lens
            } else {
                &mut spec.sensor
            };
            let Some(s) = section.as_mut() else {
                return Err(
                    ApplyError::new(format!("'{path}': the experiment has no {sec}"))
                        .help(format!("add a `{sec} …` node"))
                        .path(),
                );
            };
            if *key == "file" {
                s.file = Some(file_ref(as_str(v, "file")?, &base_dir, sec, loader)?);
            } else {
                check_generic(key, v)?;
                s.overrides.set(*key, v.clone());
            }
        }
        ["object", id, key] => {
            let Some(a) = spec.additions.iter_mut().find(|a| a.id == *id) else {
                let ids: Vec<&str> = spec.additions.iter().map(|a| a.id.as_str()).collect();
                let mut e = ApplyError::new(format!(
                    "'{path}': no object '{id}' is added by this experiment"
                ));
                e.help = crate::diag::did_you_mean(id, ids.iter().copied())
                    .map(|s| format!("did you mean 'object.{s}.{key}'?"));
                return Err(e.path());
            };
            match *key {
                "position-m" => a.position_m = as_vec3(v, "position-m")?,
                "rotate-deg" => a.rotate_deg = as_vec3(v, "rotate-deg")?,
                "scale" => a.scale = as_scale(v)?,
                "file" => a.file = Some(file_ref(as_str(v, "file")?, &base_dir, "mesh", loader)?),
                "target" | "id" => {
                    return Err(ApplyError::new(format!("'{path}' cannot be swept")).path());
                }
                k => {
                    check_generic(k, v)?;
                    a.params.set(k, v.clone());
                }
            }
        }
        ["override", obj, key] => {
            check_generic(key, v)?;
            match spec.overrides.iter_mut().find(|o| o.object == *obj) {
                Some(o) => o.params.set(*key, v.clone()),
                None => {
                    let mut o = super::spec::Override {
                        object: obj.to_string(),
                        params: Default::default(),
                        span: Default::default(),
                        spans: Default::default(),
                    };
                    o.params.set(*key, v.clone());
                    spec.overrides.push(o);
                }
            }
        }
        ["measure", name, key] => {
            if *key == "input" {
                check_input_name(spec, as_str(v, "input")?)?;
            }
            let Some(m) = spec.measures.iter_mut().find(|m| m.name == *name) else {
                let names: Vec<&str> = spec.measures.iter().map(|m| m.name.as_str()).collect();
                let mut e = ApplyError::new(format!(
                    "'{path}': no measurement named '{name}' (names: {})",
                    names.join(", ")
                ));
                e.help = crate::diag::did_you_mean(name, names.iter().copied())
                    .map(|s| format!("did you mean 'measure.{s}.{key}'?"));
                return Err(e.path());
            };
            match *key {
                "of" => m.of = vec![as_str(v, "of")?.to_string()],
                "name" | "kind" => {
                    return Err(ApplyError::new(format!("'{path}' cannot be swept")).path());
                }
                k => {
                    check_generic(k, v)?;
                    m.params.set(k, v.clone());
                }
            }
        }
        ["tag", name] if !name.is_empty() => {
            spec.tags.insert(name.to_string(), v.clone());
        }
        [root, ..] if !PATH_ROOTS.contains(root) => return Err(bad_root()),
        _ => {
            return Err(ApplyError::new(format!("'{path}' is not a parameter path")).help(
                "paths look like render.spp, camera.position-m, sensor.exposure-s, object.<id>.position-m, measure.<name>.<property>, tag.<name>",
            ).path());
        }
    }
    Ok(())
}

pub fn as_scale(v: &Value) -> R<[f64; 3]> {
    let s = match v {
        Value::Number(_) => {
            let x = as_f64(v, "scale")?;
            [x, x, x]
        }
        _ => as_vec3(v, "scale")?,
    };
    if s.iter().any(|&x| x <= 0.0) {
        return Err(ApplyError::new(format!(
            "'scale' must be > 0, found {}",
            fmt_value(v)
        )));
    }
    Ok(s)
}

/// Camera pose sanity: distinct position and look-at, `up` not parallel to the view.
pub fn check_camera(c: &super::spec::CameraSection) -> R<()> {
    let d = [
        c.look_at_m[0] - c.position_m[0],
        c.look_at_m[1] - c.position_m[1],
        c.look_at_m[2] - c.position_m[2],
    ];
    let dl = (d[0] * d[0] + d[1] * d[1] + d[2] * d[2]).sqrt();
    if dl == 0.0 || !dl.is_finite() {
        return Err(ApplyError::new(
            "camera look-at-m equals position-m: the view direction is undefined",
        ));
    }
    let u = c.up;
    let ul = (u[0] * u[0] + u[1] * u[1] + u[2] * u[2]).sqrt();
    if ul == 0.0 {
        return Err(ApplyError::new("camera up is the zero vector").help("e.g. up=(0 1 0)"));
    }
    let cross = [
        d[1] * u[2] - d[2] * u[1],
        d[2] * u[0] - d[0] * u[2],
        d[0] * u[1] - d[1] * u[0],
    ];
    let cl = (cross[0] * cross[0] + cross[1] * cross[1] + cross[2] * cross[2]).sqrt();
    if cl <= 1e-9 * dl * ul {
        return Err(
            ApplyError::new("camera up is parallel to the view direction")
                .help("choose an up vector across the view, e.g. up=(0 1 0)"),
        );
    }
    Ok(())
}

/// The measured input called `name`, or an error with a did-you-mean.
pub fn check_input_name<'a>(
    spec: &'a ResolvedExperiment,
    name: &str,
) -> Result<&'a super::spec::MeasuredInput, ApplyError> {
    if let Some(c) = spec.measured_input(name) {
        return Ok(c);
    }
    let names: Vec<&str> = spec.measured.iter().map(|c| c.name.as_str()).collect();
    let mut e = ApplyError::new(if names.is_empty() {
        format!("unknown measured input '{name}': the experiment names no captured images")
    } else {
        format!(
            "unknown measured input '{name}'; expected one of: {}",
            names.join(", ")
        )
    });
    e.help = crate::diag::did_you_mean(name, names.iter().copied())
        .map(|s| format!("did you mean '{s}'?"))
        .or_else(|| Some(format!("add measured \"{name}\" file=\"captures/….png\"")));
    Err(e)
}

/// `spec` with a `quality "NAME"` preset's render settings and targets in
/// place (`camsim run --quality NAME`, and `check` of each preset). A
/// preset's target replaces the `render` node's of the same measurement and
/// quantity.
pub fn apply_quality(
    spec: &mut ResolvedExperiment,
    preset: &super::spec::QualityPreset,
    loader: super::source::Loader,
) -> Result<(), (super::source::Span, ApplyError)> {
    for (k, v) in &preset.params.0 {
        apply(spec, &format!("render.{k}"), v, loader)
            .map_err(|e| (preset.spans.value_at(k, preset.span), e))?;
    }
    for t in &preset.targets {
        spec.render.set_target(t.clone());
    }
    spec.render.span = preset.span;
    Ok(())
}
