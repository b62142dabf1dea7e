//! KDL → [`ResolvedExperiment`] + [`Sweep`], strictly: unknown nodes and
//! properties (with suggestions), wrong types, numbers without units,
//! out-of-range values, duplicate ids, missing files, empty sweeps and
//! include cycles are each a [`Located`] error (`file:line:col`, the source
//! line, what was expected, help). The first error of a file is reported.
//!
//! A file holds one top-level node: `experiment "name" { … }` (runnable) or
//! `setup "name" { … }` (a shared base, included with `base "file.kdl"`).
//! The language is documented in `docs/experiment-language.md`.

use super::apply::{self, ApplyError};
use super::source::{Loader, SourceMap, Span, parse_kdl, skip_trivia};
use super::spec::*;
use super::sweep::{Axis, Sweep, SweepItem, range_values};
use crate::diag::{Located, did_you_mean};
use crate::params::{Params, Value};
use kdl::{KdlEntry, KdlNode, KdlValue};
use std::collections::BTreeMap;
use std::path::{Path, PathBuf};

/// What kind of file was parsed.
#[derive(Clone, Copy, Debug, PartialEq, Eq)]
pub enum DocKind {
    Experiment,
    Setup,
}

/// A parsed experiment (or setup) file with everything needed to expand and
/// to report errors later.
#[derive(Clone, Debug)]
pub struct Parsed {
    pub kind: DocKind,
    pub spec: ResolvedExperiment,
    pub sweep: Sweep,
    pub sources: SourceMap,
    pub loader: Loader,
}

const EXPERIMENT_NODES: &[&str] = &[
    "description",
    "base",
    "scene",
    "add",
    "remove",
    "override",
    "camera",
    "lens",
    "sensor",
    "render",
    "sweep",
    "measure",
    "measured",
];
const SINGLETONS: &[&str] = &[
    "description",
    "base",
    "scene",
    "camera",
    "lens",
    "sensor",
    "render",
    "sweep",
];
const MAX_BASE_DEPTH: usize = 16;

/// Parse an experiment or setup file.
pub fn parse_file(path: &Path, loader: Loader) -> Result<Parsed, Located> {
    let text = loader.read(path).map_err(|e| Located {
        file: path.to_path_buf(),
        line: 1,
        col: 1,
        message: format!("cannot read experiment file: {e}"),
        snippet: String::new(),
        len: 1,
        help: None,
    })?;
    parse_source(path, text, loader)
}

/// Parse experiment text as if read from `path` (bases are read through `loader`).
pub fn parse_source(path: &Path, text: String, loader: Loader) -> Result<Parsed, Located> {
    let mut p = P {
        map: SourceMap::default(),
        loader,
        stack: Vec::new(),
    };
    let file = p.map.add(path.to_path_buf(), text);
    let (kind, spec, sweep) = p.parse_doc(file, None)?;
    let parsed = Parsed {
        kind,
        spec,
        sweep,
        sources: p.map,
        loader,
    };
    validate_hooks(&parsed.spec)
        .map_err(|(s, e)| parsed.sources.error(s, e.message).with_help_opt(e.help))?;
    Ok(parsed)
}

/// Build every stage of a resolved spec from its parameters (see [`super::check`]).
pub fn validate_hooks(spec: &ResolvedExperiment) -> Result<(), (Span, ApplyError)> {
    super::check::check_stages(spec)
}

struct P {
    map: SourceMap,
    loader: Loader,
    /// Files being included (for cycle detection), with the include site.
    stack: Vec<PathBuf>,
}

/// One entry of a node, converted.
struct Ent {
    name: Option<(String, Span)>,
    value: Value,
    vspan: Span,
    raw: KdlValue,
}

fn key_of(path: &Path) -> PathBuf {
    std::fs::canonicalize(path).unwrap_or_else(|_| path.to_path_buf())
}

fn err_at(map: &SourceMap, span: Span, msg: impl Into<String>) -> Located {
    map.error(span, msg)
}

impl P {
    fn e(&self, span: Span, msg: impl Into<String>) -> Located {
        err_at(&self.map, span, msg)
    }
    fn ae(&self, span: Span, e: ApplyError) -> Located {
        self.e(span, e.message).with_help_opt(e.help)
    }
    fn node_span(&self, file: usize, node: &KdlNode) -> Span {
        let s = node.name().span();
        Span {
            file,
            offset: s.offset(),
            len: s.len().max(1),
        }
    }
    fn where_(&self, span: Span) -> String {
        let l = self.map.error(span, "");
        format!("{}:{}:{}", l.file.display(), l.line, l.col)
    }

    /// Entries of a node with spans and converted values.
    fn entries(&self, file: usize, node: &KdlNode) -> Result<Vec<Ent>, Located> {
        let text = &self.map.file(file).text;
        let mut out: Vec<Ent> = Vec::new();
        for entry in node.entries() {
            let (name, voff) = match entry.name() {
                Some(id) => {
                    let ns = id.span();
                    let nspan = Span {
                        file,
                        offset: ns.offset(),
                        len: ns.len().max(1),
                    };
                    let mut o = ns.offset() + ns.len();
                    o = skip_trivia(text, o);
                    if text.as_bytes().get(o) == Some(&b'=') {
                        o = skip_trivia(text, o + 1);
                    }
                    (Some((id.value().to_string(), nspan)), o)
                }
                None => (None, skip_trivia(text, entry.span().offset())),
            };
            let vlen = value_len(entry);
            let vspan = Span {
                file,
                offset: voff,
                len: vlen,
            };
            if let Some(ty) = entry.ty() {
                let s = ty.span();
                return Err(self
                    .e(Span { file, offset: s.offset(), len: s.len().max(1) }, format!("type annotation '({})' is not used by camsim", ty.value()))
                    .with_help("remove the annotation; units belong in the property name, e.g. exposure-s=0.2"));
            }
            if let Some((n, s)) = &name
                && let Some(prev) = out
                    .iter()
                    .find(|e| e.name.as_ref().is_some_and(|(m, _)| m == n))
            {
                let first = self.where_(prev.name.as_ref().map(|x| x.1).unwrap_or(*s));
                return Err(self
                    .e(*s, format!("duplicate property '{n}'"))
                    .with_help(format!("first given at {first}")));
            }
            let value = self.convert(file, entry, voff, name.as_ref().map(|n| n.0.as_str()))?;
            out.push(Ent {
                name,
                value,
                vspan,
                raw: entry.value().clone(),
            });
        }
        Ok(out)
    }

    fn convert(
        &self,
        file: usize,
        entry: &KdlEntry,
        voff: usize,
        name: Option<&str>,
    ) -> Result<Value, Located> {
        let what = name.unwrap_or("value");
        let span = Span {
            file,
            offset: voff,
            len: value_len(entry),
        };
        Ok(match entry.value() {
            KdlValue::String(s) => {
                if self.map.file(file).tuples.contains(&voff) {
                    let mut items = Vec::new();
                    let mut pos = voff + 1;
                    for tok in s.split([' ', '\t']) {
                        if tok.is_empty() {
                            pos += 1;
                            continue;
                        }
                        let t = tok.replace('_', "");
                        match t.parse::<f64>() {
                            Ok(x) if x.is_finite() && !t.contains("inf") && !t.contains("nan") => {
                                items.push(Value::Number(x))
                            }
                            _ => {
                                return Err(self
                                    .e(Span { file, offset: pos, len: tok.len() }, format!("'{tok}' in the list '{what}' is not a number"))
                                    .with_help("a list is written (x y z) with numbers separated by spaces"));
                            }
                        }
                        pos += tok.len() + 1;
                    }
                    Value::List(items)
                } else {
                    Value::String(s.clone())
                }
            }
            KdlValue::Integer(i) => {
                if i.unsigned_abs() > (1u128 << 53) {
                    return Err(self.e(
                        span,
                        format!("'{what}': integer {i} is too large (at most 2^53)"),
                    ));
                }
                Value::Number(*i as f64)
            }
            KdlValue::Float(x) => {
                if !x.is_finite() {
                    return Err(
                        self.e(span, format!("'{what}' must be a finite number, found {x}"))
                    );
                }
                Value::Number(*x)
            }
            KdlValue::Bool(b) => Value::Bool(*b),
            KdlValue::Null => {
                return Err(self.e(span, format!("'{what}': #null is not a value camsim uses")));
            }
        })
    }

    fn no_children(&self, file: usize, node: &KdlNode) -> Result<(), Located> {
        if node.children().is_some() {
            return Err(self
                .e(
                    self.node_span(file, node),
                    format!("'{}' takes no {{ … }} block", node.name().value()),
                )
                .with_help(
                    "write its settings as properties on the same line, e.g. render spp=256",
                ));
        }
        Ok(())
    }
    fn no_type(&self, file: usize, node: &KdlNode) -> Result<(), Located> {
        if let Some(ty) = node.ty() {
            let s = ty.span();
            return Err(self.e(
                Span {
                    file,
                    offset: s.offset(),
                    len: s.len().max(1),
                },
                format!("type annotation '({})' is not used by camsim", ty.value()),
            ));
        }
        Ok(())
    }

    /// Parse a document; returns its kind and resolved spec (bases merged).
    fn parse_doc(
        &mut self,
        file: usize,
        include_site: Option<Span>,
    ) -> Result<(DocKind, ResolvedExperiment, Sweep), Located> {
        let path = self.map.file(file).path.clone();
        self.stack.push(key_of(&path));
        let doc = parse_kdl(&self.map, file)?;
        let nodes = doc.nodes();
        let whole = Span {
            file,
            offset: 0,
            len: 1,
        };
        let Some(top) = nodes.first() else {
            return Err(self.e(
                whole,
                "empty file: expected `experiment \"name\" { … }` or `setup \"name\" { … }`",
            ));
        };
        if let Some(second) = nodes.get(1) {
            return Err(self
                .e(self.node_span(file, second), format!("unexpected second top-level node '{}'", second.name().value()))
                .with_help("a file holds exactly one `experiment` or `setup`; put everything inside its { … } block"));
        }
        self.no_type(file, top)?;
        let tspan = self.node_span(file, top);
        let kind = match top.name().value() {
            "experiment" => DocKind::Experiment,
            "setup" => DocKind::Setup,
            other => {
                let help = did_you_mean(other, ["experiment", "setup"])
                    .map(|s| format!("did you mean '{s}'?"));
                return Err(self
                    .e(
                        tspan,
                        format!(
                            "unknown top-level node '{other}'; expected `experiment` or `setup`"
                        ),
                    )
                    .with_help_opt(help.or(Some("write experiment \"name\" { … }".into()))));
            }
        };
        if let (Some(site), DocKind::Experiment) = (include_site, kind) {
            let _ = site;
            return Err(self
                .e(tspan, "a base file must be a `setup`, not an `experiment`")
                .with_help("rename the top-level node to `setup`"));
        }
        let ents = self.entries(file, top)?;
        let mut name: Option<(String, Span)> = None;
        for e in &ents {
            if let Some((n, s)) = &e.name {
                return Err(self
                    .e(
                        *s,
                        format!("unexpected property '{n}' on '{}'", top.name().value()),
                    )
                    .with_help("settings go inside the { … } block"));
            }
            if name.is_some() {
                return Err(self
                    .e(e.vspan, "more than one name given")
                    .with_help("write experiment \"name\" { … }"));
            }
            match &e.value {
                Value::String(s) => name = Some((s.clone(), e.vspan)),
                v => {
                    return Err(self.e(
                        e.vspan,
                        format!(
                            "expected the name as a string, found {}",
                            apply::describe(v)
                        ),
                    ));
                }
            }
        }
        let Some((name, name_span)) = name else {
            return Err(self
                .e(tspan, format!("'{}' needs a name", top.name().value()))
                .with_help("write experiment \"my-experiment\" { … }"));
        };
        if name.is_empty()
            || name.starts_with('.')
            || !name
                .chars()
                .all(|c| c.is_ascii_alphanumeric() || c == '-' || c == '_' || c == '.')
        {
            return Err(self
                .e(
                    name_span,
                    format!("invalid name '{name}': it names the results directory"),
                )
                .with_help("use letters, digits, '-', '_' and '.', not starting with '.'"));
        }
        let Some(children) = top.children() else {
            return Err(self.e(
                tspan,
                format!("'{}' has no {{ … }} block", top.name().value()),
            ));
        };

        // Singletons, then the base, then own nodes in order.
        let mut seen: BTreeMap<&str, Span> = BTreeMap::new();
        for n in children.nodes() {
            let nm = n.name().value();
            self.no_type(file, n)?;
            let sp = self.node_span(file, n);
            if !EXPERIMENT_NODES.contains(&nm) {
                let help = did_you_mean(nm, EXPERIMENT_NODES.iter().copied())
                    .map(|s| format!("did you mean '{s}'?"));
                return Err(self
                    .e(
                        sp,
                        format!(
                            "unknown node '{nm}'; expected one of: {}",
                            EXPERIMENT_NODES.join(", ")
                        ),
                    )
                    .with_help_opt(help));
            }
            if kind == DocKind::Setup && (nm == "sweep" || nm == "measure") {
                return Err(self.e(
                    sp,
                    format!("'{nm}' belongs in an experiment, not in a setup"),
                ));
            }
            if SINGLETONS.contains(&nm) {
                if let Some(prev) = seen.get(nm) {
                    return Err(self
                        .e(sp, format!("duplicate '{nm}' node"))
                        .with_help(format!("first given at {}", self.where_(*prev))));
                }
                seen.insert(nm, sp);
            }
        }
        let dir = path.parent().map(Path::to_path_buf).unwrap_or_default();
        // Indexes for duplicate checks (linear scans would be quadratic in big files).
        let mut own_adds: std::collections::HashSet<String> = Default::default();
        let mut add_spans: std::collections::HashMap<String, Span> = Default::default();
        let mut removed: std::collections::HashSet<String> = Default::default();
        let mut override_at: std::collections::HashMap<String, usize> = Default::default();
        let mut measure_spans: std::collections::HashMap<String, Span> = Default::default();
        // A base is merged as a whole value: the experiment starts from the
        // base's resolved spec and its own nodes change it, so no field of a
        // setup can be forgotten on the way (a field-by-field copy once lost
        // `materials="paper"`).
        let mut spec = match children.nodes().iter().find(|n| n.name().value() == "base") {
            Some(b) => {
                self.no_children(file, b)?;
                let (written, vspan) = self.single_string(file, b, "base file")?;
                let bpath = self.base_path(&written, vspan, &dir)?;
                let text = self.loader.read(&bpath).map_err(|e| {
                    self.e(
                        vspan,
                        format!("cannot read base file '{}': {e}", bpath.display()),
                    )
                })?;
                let bfile = self.map.add(bpath.clone(), text);
                let (_, mut bspec, _) = self.parse_doc(bfile, Some(vspan))?;
                bspec.bases.push(bpath);
                bspec.name = name.clone();
                bspec.file = path.clone();
                bspec
            }
            None => ResolvedExperiment::empty(&name, &path),
        };
        for a in &spec.additions {
            add_spans.insert(a.id.clone(), a.span);
        }
        removed.extend(spec.removals.iter().cloned());
        for (i, o) in spec.overrides.iter().enumerate() {
            override_at.insert(o.object.clone(), i);
        }
        let mut camera_given = false;
        let mut sweep_node = None;
        for n in children.nodes() {
            let sp = self.node_span(file, n);
            match n.name().value() {
                "base" => {}
                "description" => {
                    self.no_children(file, n)?;
                    spec.description = Some(self.single_string(file, n, "description")?.0);
                }
                "scene" => {
                    self.no_children(file, n)?;
                    // a scene node replaces the whole scene section, materials included
                    spec.scene_materials = None;
                    let (w, vs) = self.scene_node(file, n, &mut spec.scene_materials)?;
                    let ext = Path::new(&w)
                        .extension()
                        .and_then(|e| e.to_str())
                        .unwrap_or("");
                    if !matches!(ext, "pbrt" | "kdl" | "gz") {
                        return Err(self.e(
                            vs,
                            format!("scene '{w}': expected a .pbrt or .kdl scene file"),
                        ));
                    }
                    let mut f = apply::file_ref(&w, &dir, "scene", self.loader)
                        .map_err(|e| self.ae(vs, e))?;
                    f.span = vs;
                    spec.scene = Some(f);
                }
                "add" => {
                    self.no_children(file, n)?;
                    let a = self.parse_add(file, n, &dir)?;
                    if let Some(prev) = add_spans.get(&a.id) {
                        return Err(self
                            .e(a.span, format!("duplicate object id '{}'", a.id))
                            .with_help(format!("first added at {}", self.where_(*prev))));
                    }
                    own_adds.insert(a.id.clone());
                    add_spans.insert(a.id.clone(), a.span);
                    spec.additions.push(a);
                }
                "remove" => {
                    self.no_children(file, n)?;
                    let ents = self.entries(file, n)?;
                    if ents.is_empty() {
                        return Err(self
                            .e(sp, "'remove' needs at least one object name")
                            .with_help("e.g. remove \"cube-small\" \"cube-large\""));
                    }
                    for e in ents {
                        if let Some((k, s)) = e.name {
                            return Err(self
                                .e(s, format!("unexpected property '{k}' on 'remove'"))
                                .with_help("write remove \"object\" …"));
                        }
                        let Value::String(id) = e.value else {
                            return Err(self.e(
                                e.vspan,
                                format!(
                                    "expected an object name, found {}",
                                    apply::describe(&e.value)
                                ),
                            ));
                        };
                        if own_adds.contains(&id) {
                            return Err(self.e(
                                e.vspan,
                                format!(
                                    "'{id}' is added in this same file; removing it makes no sense"
                                ),
                            ));
                        }
                        if add_spans.remove(&id).is_some() {
                            spec.additions.retain(|a| a.id != id);
                        } else if removed.contains(&id) {
                            return Err(self.e(e.vspan, format!("'{id}' is removed twice")));
                        } else {
                            removed.insert(id.clone());
                            spec.removals.push(id);
                        }
                    }
                }
                "override" => {
                    self.no_children(file, n)?;
                    let ents = self.entries(file, n)?;
                    let mut object = None;
                    let mut params = Params::new();
                    let mut spans = super::spec::PropSpans::default();
                    for e in ents {
                        match e.name {
                            None => {
                                if object.is_some() {
                                    return Err(self.e(e.vspan, "'override' names one object"));
                                }
                                let Value::String(s) = e.value else {
                                    return Err(self.e(
                                        e.vspan,
                                        format!(
                                            "expected an object name, found {}",
                                            apply::describe(&e.value)
                                        ),
                                    ));
                                };
                                object = Some(s);
                            }
                            Some((k, ks)) => {
                                apply::check_generic(&k, &e.value).map_err(|x| self.ae(ks, x))?;
                                params.set(k.clone(), e.value);
                                spans.insert(&k, ks, e.vspan);
                            }
                        }
                    }
                    let Some(object) = object else {
                        return Err(self.e(sp, "'override' needs the object name").with_help(
                            "e.g. override \"wall-left\" reflectance=\"cbox-red-wall\"",
                        ));
                    };
                    if params.0.is_empty() {
                        return Err(self
                            .e(sp, format!("'override \"{object}\"' changes nothing"))
                            .with_help("add properties, e.g. reflectance=\"cbox-red-wall\""));
                    }
                    if let Some(o) = override_at.get(&object).map(|&i| &mut spec.overrides[i]) {
                        if o.span.file == file {
                            return Err(self
                                .e(sp, format!("duplicate override of '{object}'"))
                                .with_help(format!("first at {}", self.where_(o.span))));
                        }
                        o.params.0.extend(params.0);
                        o.spans.extend(spans);
                        o.span = sp;
                    } else {
                        override_at.insert(object.clone(), spec.overrides.len());
                        spec.overrides.push(Override {
                            object,
                            params,
                            span: sp,
                            spans,
                        });
                    }
                }
                "camera" => {
                    self.no_children(file, n)?;
                    camera_given = true;
                    let ents = self.entries(file, n)?;
                    let mut cam = spec.camera.clone().unwrap_or(CameraSection {
                        position_m: [f64::NAN; 3],
                        look_at_m: [f64::NAN; 3],
                        up: [0.0, 1.0, 0.0],
                        span: sp,
                    });
                    cam.span = sp;
                    for e in &ents {
                        let (k, ks) = self.prop(e, "camera")?;
                        let r = match k.as_str() {
                            "position-m" => {
                                apply::as_vec3(&e.value, &k).map(|v| cam.position_m = v)
                            }
                            "look-at-m" => apply::as_vec3(&e.value, &k).map(|v| cam.look_at_m = v),
                            "up" => apply::as_vec3(&e.value, &k).map(|v| cam.up = v),
                            _ => {
                                return Err(self.unknown_prop(
                                    &k,
                                    ks,
                                    &super::language::CAMERA_SCHEMA.names(),
                                    "camera",
                                    &e.value,
                                ));
                            }
                        };
                        r.map_err(|x| self.ae(e.vspan, x))?;
                    }
                    if cam.position_m[0].is_nan() || cam.look_at_m[0].is_nan() {
                        return Err(self
                            .e(sp, "camera needs position-m=(x y z) and look-at-m=(x y z)")
                            .with_help(
                                "e.g. camera position-m=(0 0.115 -0.40) look-at-m=(0 0.115 0.60)",
                            ));
                    }
                    apply::check_camera(&cam).map_err(|x| self.ae(sp, x))?;
                    spec.camera = Some(cam);
                }
                sec @ ("lens" | "sensor") => {
                    self.no_children(file, n)?;
                    let s = self.parse_config(
                        file,
                        n,
                        &dir,
                        sec,
                        if sec == "lens" {
                            spec.lens.take()
                        } else {
                            spec.sensor.take()
                        },
                    )?;
                    if sec == "lens" {
                        spec.lens = Some(s);
                    } else {
                        spec.sensor = Some(s);
                    }
                }
                "render" => {
                    self.no_children(file, n)?;
                    for e in self.entries(file, n)? {
                        let (k, ks) = self.prop(&e, "render")?;
                        let path = format!("render.{k}");
                        let known = super::language::RENDER_SCHEMA.names();
                        if !known.contains(&k.as_str()) {
                            return Err(self.unknown_prop(&k, ks, &known, "render", &e.value));
                        }
                        if k == "seed"
                            && let KdlValue::Integer(i) = e.raw
                            && (i < 0 || i > u64::MAX as i128)
                        {
                            return Err(self.e(
                                e.vspan,
                                format!("'seed' = {i} is out of range; expected 0…{}", 1u64 << 53),
                            ));
                        }
                        apply::apply(&mut spec, &path, &e.value, self.loader)
                            .map_err(|x| self.ae(e.vspan, x))?;
                    }
                }
                "measure" => {
                    self.no_children(file, n)?;
                    let m = self.parse_measure(file, n)?;
                    if let Some(prev) = measure_spans.get(&m.name) {
                        return Err(self
                            .e(m.span, format!("duplicate measurement name '{}'", m.name))
                            .with_help(format!(
                                "first at {}; give one of them name=\"…\"",
                                self.where_(*prev)
                            )));
                    }
                    measure_spans.insert(m.name.clone(), m.span);
                    spec.measures.push(m);
                }
                "measured" => {
                    self.no_children(file, n)?;
                    let c = self.parse_measured(file, n, &dir)?;
                    if let Some(prev) = spec.measured.iter().find(|p| p.name == c.name) {
                        return Err(self
                            .e(c.span, format!("duplicate measured input '{}'", c.name))
                            .with_help(format!("first given at {}", self.where_(prev.span))));
                    }
                    spec.measured.push(c);
                }
                "sweep" => sweep_node = Some(n),
                _ => unreachable!("checked above"),
            }
        }
        let _ = camera_given;
        super::measured::check_references(&spec).map_err(|(sp, e)| self.ae(sp, e))?;
        if kind == DocKind::Experiment && spec.measures.is_empty() {
            return Err(self
                .e(tspan, format!("experiment '{name}' measures nothing"))
                .with_help("add e.g. measure \"colorimetry\" spectrum=\"cie-d65\""));
        }
        let sweep = match sweep_node {
            Some(n) => self.parse_sweep(file, n, &spec)?,
            None => Sweep::default(),
        };
        self.stack.pop();
        Ok((kind, spec, sweep))
    }

    /// Resolve a `base "file"` reference, refusing include cycles and deep nesting.
    fn base_path(&self, written: &str, vspan: Span, dir: &Path) -> Result<PathBuf, Located> {
        let Some(bpath) = apply::resolve_ref(written, dir, self.loader) else {
            return Err(self
                .e(vspan, format!("base file '{written}' not found"))
                .with_help("relative paths are looked up in the directory of this file, then in each parent directory"));
        };
        let key = key_of(&bpath);
        if let Some(i) = self.stack.iter().position(|k| *k == key) {
            let chain: Vec<String> = self.stack[i..]
                .iter()
                .chain([&key])
                .map(|p| p.display().to_string())
                .collect();
            return Err(self
                .e(vspan, format!("include cycle: {}", chain.join(" → ")))
                .with_help("a setup must not include itself, directly or indirectly"));
        }
        if self.stack.len() >= MAX_BASE_DEPTH {
            return Err(self.e(
                vspan,
                format!("bases nested more than {MAX_BASE_DEPTH} deep"),
            ));
        }
        Ok(bpath)
    }

    fn prop(&self, e: &Ent, node: &str) -> Result<(String, Span), Located> {
        match &e.name {
            Some((k, s)) => Ok((k.clone(), *s)),
            None => Err(self
                .e(
                    e.vspan,
                    format!("unexpected argument on '{node}'; expected name=value properties"),
                )
                .with_help(format!(
                    "e.g. {node} {}",
                    match node {
                        "camera" => "position-m=(0 0.1 -0.4) look-at-m=(0 0.1 0.6)",
                        "render" => "spp=256 max-bounces=5",
                        _ => "name=value",
                    }
                ))),
        }
    }

    fn unknown_prop(&self, k: &str, ks: Span, known: &[&str], node: &str, v: &Value) -> Located {
        let mut help =
            did_you_mean(k, known.iter().copied()).map(|s| format!("did you mean '{s}'?"));
        if matches!(v, Value::Number(_)) && !super::units::has_unit(k) {
            let with = super::units::suggest_unit(k);
            if known.contains(&with.as_str()) || help.is_none() {
                help = Some(super::units::unit_help(k));
            }
        }
        self.e(
            ks,
            format!(
                "unknown property '{k}' on '{node}'; expected one of: {}",
                known.join(", ")
            ),
        )
        .with_help_opt(help)
    }

    /// `scene "file" [materials="paper"|"file"]`.
    fn scene_node(
        &self,
        file: usize,
        n: &KdlNode,
        materials: &mut Option<String>,
    ) -> Result<(String, Span), Located> {
        let ents = self.entries(file, n)?;
        let sp = self.node_span(file, n);
        let mut positional = vec![];
        for e in &ents {
            match &e.name {
                Some((k, s)) if k == "materials" => match &e.value {
                    Value::String(v) if v == "paper" || v == "file" => {
                        *materials = (v == "paper").then(|| v.clone());
                    }
                    v => {
                        return Err(self
                            .e(
                                e.vspan,
                                format!(
                                    "materials: expected \"paper\" or \"file\", found {}",
                                    apply::describe(v)
                                ),
                            )
                            .with_help(
                                "materials=\"paper\" applies the paper's measured spectra",
                            ));
                    }
                },
                Some((k, s)) => {
                    return Err(self
                        .e(*s, format!("unexpected property '{k}' on 'scene'"))
                        .with_help_opt(
                            crate::diag::did_you_mean(k, ["materials"])
                                .map(|m| format!("did you mean '{m}'?")),
                        ));
                }
                None => positional.push(e),
            }
        }
        match positional.as_slice() {
            [e] => match &e.value {
                Value::String(s) => Ok((s.clone(), e.vspan)),
                v => Err(self.e(
                    e.vspan,
                    format!(
                        "scene file: expected a string, found {}",
                        apply::describe(v)
                    ),
                )),
            },
            [] => Err(self
                .e(sp, "'scene' needs the scene file")
                .with_help("write scene \"….pbrt\"")),
            [_, e, ..] => Err(self.e(e.vspan, "'scene' takes one file")),
        }
    }

    fn single_string(
        &self,
        file: usize,
        n: &KdlNode,
        what: &str,
    ) -> Result<(String, Span), Located> {
        let ents = self.entries(file, n)?;
        let sp = self.node_span(file, n);
        let nm = n.name().value();
        if let Some(e) = ents.iter().find(|e| e.name.is_some()) {
            let (k, s) = e.name.clone().unwrap_or_default();
            return Err(self
                .e(s, format!("unexpected property '{k}' on '{nm}'"))
                .with_help(format!("write {nm} \"…\"")));
        }
        match ents.as_slice() {
            [e] => match &e.value {
                Value::String(s) => Ok((s.clone(), e.vspan)),
                v => Err(self.e(
                    e.vspan,
                    format!("{what}: expected a string, found {}", apply::describe(v)),
                )),
            },
            [] => Err(self
                .e(sp, format!("'{nm}' needs the {what}"))
                .with_help(format!("write {nm} \"…\""))),
            [_, e, ..] => Err(self.e(e.vspan, format!("'{nm}' takes one value"))),
        }
    }

    fn parse_add(&self, file: usize, n: &KdlNode, dir: &Path) -> Result<Addition, Located> {
        let sp = self.node_span(file, n);
        let ents = self.entries(file, n)?;
        let mut id = None;
        let mut a = Addition {
            id: String::new(),
            target: Target::Mesh,
            file: None,
            position_m: [0.0; 3],
            rotate_deg: [0.0; 3],
            scale: [1.0; 3],
            params: Params::new(),
            span: sp,
            spans: Default::default(),
        };
        let mut target = None;
        for e in ents {
            match &e.name {
                None => {
                    if id.is_some() {
                        return Err(self
                            .e(e.vspan, "'add' takes one id")
                            .with_help("add \"id\" target=\"…\" …"));
                    }
                    let Value::String(s) = &e.value else {
                        return Err(self.e(
                            e.vspan,
                            format!(
                                "expected the object id as a string, found {}",
                                apply::describe(&e.value)
                            ),
                        ));
                    };
                    if s.is_empty() || s.contains('.') || s.contains(char::is_whitespace) {
                        return Err(self.e(e.vspan, format!("invalid object id '{s}'")).with_help("ids are non-empty and hold no '.' or spaces (they appear in paths like object.<id>.position-m)"));
                    }
                    id = Some(s.clone());
                    a.span = e.vspan;
                }
                Some((k, ks)) => {
                    a.spans.insert(k, *ks, e.vspan);
                    let r = match k.as_str() {
                        "target" => {
                            let s = apply::as_str(&e.value, "target")
                                .map_err(|x| self.ae(e.vspan, x))?;
                            match Target::parse(s) {
                                Some(t) => target = Some(t),
                                None => {
                                    let help = did_you_mean(s, Target::NAMES.iter().copied())
                                        .map(|x| format!("did you mean '{x}'?"));
                                    return Err(self
                                        .e(
                                            e.vspan,
                                            format!(
                                                "unknown target '{s}'; expected one of: {}",
                                                Target::NAMES.join(", ")
                                            ),
                                        )
                                        .with_help_opt(help));
                                }
                            }
                            Ok(())
                        }
                        "position-m" => apply::as_vec3(&e.value, k).map(|v| a.position_m = v),
                        "rotate-deg" => apply::as_vec3(&e.value, k).map(|v| a.rotate_deg = v),
                        "scale" => apply::as_scale(&e.value).map(|v| a.scale = v),
                        "file" => {
                            let s =
                                apply::as_str(&e.value, "file").map_err(|x| self.ae(e.vspan, x))?;
                            let mut f = apply::file_ref(s, dir, "mesh", self.loader)
                                .map_err(|x| self.ae(e.vspan, x))?;
                            f.span = e.vspan;
                            a.file = Some(f);
                            Ok(())
                        }
                        "position" | "rotate" | "rotation" | "rotation-deg" | "translate-m" => {
                            let known = ["target", "position-m", "rotate-deg", "scale", "file"];
                            return Err(self.unknown_prop(k, *ks, &known, "add", &e.value));
                        }
                        _ => {
                            apply::check_generic(k, &e.value).map_err(|x| self.ae(*ks, x))?;
                            a.params.set(k.clone(), e.value.clone());
                            Ok(())
                        }
                    };
                    r.map_err(|x| self.ae(e.vspan, x))?;
                }
            }
        }
        let Some(id) = id else {
            return Err(self
                .e(sp, "'add' needs an object id")
                .with_help("e.g. add \"edge-near\" target=\"slanted-edge\" position-m=(0 0.1 0)"));
        };
        let Some(t) = target else {
            return Err(self.e(
                sp,
                format!(
                    "'add \"{id}\"' needs target=\"…\" (one of: {})",
                    Target::NAMES.join(", ")
                ),
            ));
        };
        a.id = id;
        a.target = t;
        Ok(a)
    }

    fn parse_config(
        &self,
        file: usize,
        n: &KdlNode,
        dir: &Path,
        sec: &str,
        prev: Option<ConfigSection>,
    ) -> Result<ConfigSection, Located> {
        let sp = self.node_span(file, n);
        let ents = self.entries(file, n)?;
        let mut s = prev.unwrap_or_default();
        s.span = sp;
        let mut new_file = None;
        let mut params = Vec::new();
        for e in ents {
            match e.name {
                None => {
                    if new_file.is_some() {
                        return Err(self.e(e.vspan, format!("'{sec}' takes one file")));
                    }
                    let Value::String(w) = &e.value else {
                        return Err(self
                            .e(
                                e.vspan,
                                format!(
                                    "expected the {sec} file as a string, found {}",
                                    apply::describe(&e.value)
                                ),
                            )
                            .with_help(format!("write {sec} \"{sec}s/….\" name-unit=value …")));
                    };
                    let mut f = apply::file_ref(w, dir, sec, self.loader)
                        .map_err(|x| self.ae(e.vspan, x))?;
                    f.span = e.vspan;
                    new_file = Some(f);
                }
                Some((k, ks)) => {
                    apply::check_generic(&k, &e.value).map_err(|x| self.ae(ks, x))?;
                    params.push((k, ks, e.vspan, e.value));
                }
            }
        }
        if let Some(f) = new_file {
            // A new definition file replaces the base's file and its overrides.
            s.file = Some(f);
            s.overrides = Params::new();
            s.spans.clear();
        }
        for (k, ks, vs, v) in params {
            s.overrides.set(k.clone(), v);
            s.spans.insert(&k, ks, vs);
        }
        if s.file.is_none() && s.overrides.0.is_empty() {
            return Err(self.e(sp, format!("'{sec}' is empty")).with_help(format!(
                "name a file (e.g. {sec} \"{sec}s/….kdl\") and/or give properties"
            )));
        }
        Ok(s)
    }

    fn parse_measure(&self, file: usize, n: &KdlNode) -> Result<Measure, Located> {
        let sp = self.node_span(file, n);
        let ents = self.entries(file, n)?;
        let mut kind = None;
        let mut m = Measure {
            name: String::new(),
            kind: String::new(),
            of: vec![],
            params: Params::new(),
            span: sp,
            spans: Default::default(),
        };
        let mut name = None;
        for e in ents {
            match &e.name {
                None => {
                    let Value::String(s) = &e.value else {
                        return Err(self.e(
                            e.vspan,
                            format!("expected a string, found {}", apply::describe(&e.value)),
                        ));
                    };
                    if kind.is_none() {
                        if !MEASURE_KINDS.contains(&s.as_str()) {
                            let help = did_you_mean(s, MEASURE_KINDS.iter().copied())
                                .map(|x| format!("did you mean '{x}'?"));
                            return Err(self
                                .e(
                                    e.vspan,
                                    format!(
                                        "unknown measurement '{s}'; expected one of: {}",
                                        MEASURE_KINDS.join(", ")
                                    ),
                                )
                                .with_help_opt(help));
                        }
                        kind = Some(s.clone());
                        m.span = e.vspan;
                    } else {
                        m.of.push(s.clone());
                    }
                }
                Some((k, ks)) => match k.as_str() {
                    "name" => {
                        let s = apply::as_str(&e.value, "name").map_err(|x| self.ae(e.vspan, x))?;
                        if s.is_empty() || s.contains('.') || s.contains(',') {
                            return Err(self
                                .e(e.vspan, format!("invalid measurement name '{s}'"))
                                .with_help("non-empty, without '.' or ','"));
                        }
                        name = Some(s.to_string());
                    }
                    "of" => {
                        let s = apply::as_str(&e.value, "of").map_err(|x| self.ae(e.vspan, x))?;
                        m.of.insert(0, s.to_string());
                        m.spans.values.insert("of".into(), e.vspan);
                    }
                    _ => {
                        apply::check_generic(k, &e.value).map_err(|x| self.ae(*ks, x))?;
                        m.params.set(k.clone(), e.value.clone());
                        m.spans.insert(k, *ks, e.vspan);
                    }
                },
            }
        }
        let Some(kind) = kind else {
            return Err(self
                .e(sp, "'measure' needs the measurement kind")
                .with_help(format!(
                    "e.g. measure \"colorimetry\" spectrum=\"cie-d65\"; kinds: {}",
                    MEASURE_KINDS.join(", ")
                )));
        };
        m.name = name.unwrap_or_else(|| kind.clone());
        m.kind = kind;
        Ok(m)
    }

    /// `measured "name" file="…" [pixel-um=P] [labels="…png" names="…txt"]`.
    fn parse_measured(
        &self,
        file: usize,
        n: &KdlNode,
        dir: &Path,
    ) -> Result<MeasuredInput, Located> {
        let known = super::language::MEASURED_SCHEMA.names();
        let sp = self.node_span(file, n);
        let mut name: Option<(String, Span)> = None;
        let (mut img, mut labels, mut names, mut pixel_um) = (None, None, None, None);
        for e in self.entries(file, n)? {
            let Some((k, ks)) = &e.name else {
                if name.is_some() {
                    return Err(self
                        .e(e.vspan, "'measured' takes one name")
                        .with_help("write measured \"capture-near\" file=\"captures/edge.dng\""));
                }
                let s = apply::as_str(&e.value, "name").map_err(|x| self.ae(e.vspan, x))?;
                if s.is_empty()
                    || s.contains('.')
                    || s.contains(',')
                    || s.contains(char::is_whitespace)
                {
                    return Err(self
                        .e(e.vspan, format!("invalid measured input name '{s}'"))
                        .with_help("non-empty, without '.', ',' or spaces"));
                }
                name = Some((s.to_string(), e.vspan));
                continue;
            };
            match k.as_str() {
                "file" | "labels" | "names" => {
                    let w = apply::as_str(&e.value, k).map_err(|x| self.ae(e.vspan, x))?;
                    let what = match k.as_str() {
                        "file" => "captured image",
                        "labels" => "label map",
                        _ => "label names",
                    };
                    if k == "file" {
                        let ext = Path::new(w)
                            .extension()
                            .and_then(|x| x.to_str())
                            .unwrap_or("")
                            .to_ascii_lowercase();
                        if !matches!(ext.as_str(), "png" | "exr" | "dng" | "tif" | "tiff") {
                            return Err(self
                                .e(
                                    e.vspan,
                                    format!(
                                        "captured image '{w}': expected a .png, .exr or .dng file"
                                    ),
                                )
                                .with_help(
                                    "PNG (8/16 bit), OpenEXR and DNG/TIFF captures are read",
                                ));
                        }
                    }
                    let mut f = apply::file_ref(w, dir, what, self.loader)
                        .map_err(|x| self.ae(e.vspan, x))?;
                    f.span = e.vspan;
                    match k.as_str() {
                        "file" => img = Some(f),
                        "labels" => labels = Some((f, *ks)),
                        _ => names = Some((f, *ks)),
                    }
                }
                "pixel-um" => {
                    pixel_um =
                        Some(apply::as_positive(&e.value, k).map_err(|x| self.ae(e.vspan, x))?);
                }
                _ => return Err(self.unknown_prop(k, *ks, &known, "measured", &e.value)),
            }
        }
        let Some((name, nspan)) = name else {
            return Err(self
                .e(sp, "'measured' needs a name")
                .with_help("write measured \"capture-near\" file=\"captures/edge.dng\""));
        };
        let Some(img) = img else {
            return Err(self
                .e(nspan, format!("measured input '{name}' needs file=\"…\""))
                .with_help("e.g. file=\"captures/edge_near.dng\" (PNG, EXR or DNG)"));
        };
        match (&labels, &names) {
            (Some((_, s)), None) => {
                return Err(self.e(
                    *s,
                    "labels=\"…png\" needs names=\"…txt\" (line k names label value k)",
                ));
            }
            (None, Some((_, s))) => {
                return Err(self.e(
                    *s,
                    "names=\"…txt\" needs labels=\"…png\" (a grey label map)",
                ));
            }
            _ => {}
        }
        Ok(MeasuredInput {
            name,
            file: img,
            pixel_um,
            labels: labels.map(|l| l.0),
            names: names.map(|l| l.0),
            span: nspan,
        })
    }

    fn parse_axis(
        &self,
        file: usize,
        n: &KdlNode,
        spec: &ResolvedExperiment,
    ) -> Result<Axis, Located> {
        self.no_type(file, n)?;
        let sp = self.node_span(file, n);
        let path = n.name().value().to_string();
        if n.children().is_some() {
            return Err(self
                .e(sp, format!("sweep axis '{path}' takes no {{ … }} block"))
                .with_help("list values after the path, or give start= stop= step="));
        }
        let ents = self.entries(file, n)?;
        let mut values = Vec::new();
        let (mut start, mut stop, mut step) = (None, None, None);
        for e in &ents {
            match &e.name {
                None => values.push((e.value.clone(), e.vspan)),
                Some((k, ks)) => {
                    let slot = match k.as_str() {
                        "start" => &mut start,
                        "stop" => &mut stop,
                        "step" => &mut step,
                        _ => {
                            return Err(self.unknown_prop(
                                k,
                                *ks,
                                &["start", "stop", "step"],
                                "sweep axis",
                                &e.value,
                            ));
                        }
                    };
                    let x = apply::as_f64(&e.value, k).map_err(|x| self.ae(e.vspan, x))?;
                    *slot = Some(x);
                }
            }
        }
        let is_range = start.is_some() || stop.is_some() || step.is_some();
        if is_range && !values.is_empty() {
            return Err(self
                .e(
                    sp,
                    format!("axis '{path}' mixes a value list with start/stop/step"),
                )
                .with_help("use either a list or a range"));
        }
        if is_range {
            let (Some(a), Some(b), Some(c)) = (start, stop, step) else {
                return Err(self.e(
                    sp,
                    format!("range axis '{path}' needs start=, stop= and step="),
                ));
            };
            let vs =
                range_values(a, b, c).map_err(|m| self.e(sp, format!("axis '{path}': {m}")))?;
            values = vs.into_iter().map(|x| (Value::Number(x), sp)).collect();
        }
        if values.is_empty() {
            return Err(self.e(sp, format!("empty sweep axis '{path}'")).with_help(
                "list values (e.g. sensor.exposure-s 0.1 0.2) or give start= stop= step=",
            ));
        }
        // Check path and every value by applying it to the resolved spec.
        for (v, vs) in &values {
            let mut probe = spec.clone();
            apply::apply(&mut probe, &path, v, self.loader).map_err(|x| {
                let at = if x.on_path { sp } else { *vs };
                self.ae(at, x)
            })?;
        }
        Ok(Axis {
            path,
            values,
            span: sp,
        })
    }

    fn parse_sweep(
        &self,
        file: usize,
        n: &KdlNode,
        spec: &ResolvedExperiment,
    ) -> Result<Sweep, Located> {
        let sp = self.node_span(file, n);
        if let Some(e) = self.entries(file, n)?.first() {
            return Err(self.e(
                e.vspan,
                "'sweep' takes no values; put axes inside its { … } block",
            ));
        }
        let Some(children) = n.children() else {
            return Err(self.e(sp, "'sweep' needs a { … } block of axes"));
        };
        let mut sweep = Sweep {
            items: Vec::new(),
            span: sp,
        };
        let mut seen: BTreeMap<String, Span> = BTreeMap::new();
        let mut note = |p: &P, a: &Axis| -> Result<(), Located> {
            if let Some(prev) = seen.get(&a.path) {
                return Err(p
                    .e(a.span, format!("duplicate sweep axis '{}'", a.path))
                    .with_help(format!("first at {}", p.where_(*prev))));
            }
            seen.insert(a.path.clone(), a.span);
            Ok(())
        };
        for c in children.nodes() {
            if c.name().value() == "zip" {
                self.no_type(file, c)?;
                let zs = self.node_span(file, c);
                if let Some(e) = self.entries(file, c)?.first() {
                    return Err(self.e(
                        e.vspan,
                        "'zip' takes no values; put axes inside its { … } block",
                    ));
                }
                let Some(zc) = c.children() else {
                    return Err(self.e(zs, "'zip' needs a { … } block of axes"));
                };
                let mut axes = Vec::new();
                for z in zc.nodes() {
                    if z.name().value() == "zip" {
                        return Err(self.e(self.node_span(file, z), "'zip' cannot be nested"));
                    }
                    let a = self.parse_axis(file, z, spec)?;
                    note(self, &a)?;
                    axes.push(a);
                }
                if axes.is_empty() {
                    return Err(self.e(zs, "empty 'zip' group"));
                }
                let n0 = axes[0].values.len();
                if let Some(bad) = axes.iter().find(|a| a.values.len() != n0) {
                    return Err(self
                        .e(bad.span, format!("zip axes must have equal lengths: '{}' has {n0} values, '{}' has {}", axes[0].path, bad.path, bad.values.len()))
                        .with_help("axes in a zip move together, value by value"));
                }
                sweep.items.push(SweepItem::Zip { axes, span: zs });
            } else {
                let a = self.parse_axis(file, c, spec)?;
                note(self, &a)?;
                sweep.items.push(SweepItem::Axis(a));
            }
        }
        // Repeated values would give two variants with the same id and inputs.
        for item in &sweep.items {
            let axes = item.axes();
            let mut seen_vals: BTreeMap<String, usize> = BTreeMap::new();
            for k in 0..item.len() {
                let key: Vec<String> = axes
                    .iter()
                    .map(|a| apply::fmt_value(&a.values[k].0))
                    .collect();
                let key = key.join("\u{1f}");
                if let Some(first) = seen_vals.insert(key, k) {
                    let (v, vs) = &axes[0].values[k];
                    let msg = if axes.len() > 1 {
                        let combo: Vec<String> = axes
                            .iter()
                            .map(|a| apply::fmt_value(&a.values[k].0))
                            .collect();
                        format!(
                            "repeated value combination ({}) in this zip (same as combination {})",
                            combo.join(", "),
                            first + 1
                        )
                    } else {
                        format!(
                            "repeated value {} in sweep axis '{}' (same as value {})",
                            apply::fmt_value(v),
                            axes[0].path,
                            first + 1
                        )
                    };
                    return Err(self
                        .e(*vs, msg)
                        .with_help("each value of an axis must differ; remove the repetition"));
                }
            }
        }
        if sweep.items.is_empty() {
            return Err(self
                .e(sp, "empty sweep")
                .with_help("add axes, e.g. sensor.exposure-s 0.1 0.2 0.4, or remove the sweep"));
        }
        let count = sweep.count();
        if count > super::sweep::MAX_VARIANTS {
            return Err(self.e(
                sp,
                format!(
                    "the sweep expands to {count} variants; at most {} allowed",
                    super::sweep::MAX_VARIANTS
                ),
            ));
        }
        Ok(sweep)
    }
}

/// Byte length of an entry's value as written (≥ 1).
fn value_len(entry: &KdlEntry) -> usize {
    entry
        .format()
        .map(|f| f.value_repr.len())
        .filter(|&l| l > 0)
        .unwrap_or(1)
}
