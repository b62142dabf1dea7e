//! One experiment or setup file: its top-level node, its base (merged as a
//! whole value) and its nodes in order.

use super::*;
use crate::diag::{Located, did_you_mean};
use crate::experiment::apply;
use crate::experiment::source::{Span, parse_kdl};
use crate::experiment::sweep::Sweep;
use crate::params::{Params, Value};
use std::collections::BTreeMap;
use std::path::{Path, PathBuf};

impl P {
    /// Parse a document; returns its kind and resolved spec (bases merged).
    pub(super) fn parse_doc(
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
            if kind == DocKind::Setup && (nm == "sweep" || nm == "measure" || nm == "summary") {
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
                    let mut spans = crate::experiment::spec::PropSpans::default();
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
                                    &crate::experiment::language::CAMERA_SCHEMA.names(),
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
                "render" => self.parse_render(file, n, &mut spec)?,
                "quality" => {
                    let q = self.parse_quality(file, n, &spec)?;
                    spec.qualities.retain(|p| p.name != q.name);
                    spec.qualities.push(q);
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
                "sanity" => {
                    self.no_children(file, n)?;
                    spec.sanity = Some(self.parse_sanity(file, n)?);
                }
                "save" => {
                    self.no_children(file, n)?;
                    spec.save = self.parse_save(file, n)?;
                }
                "summary" => {
                    self.no_children(file, n)?;
                    let m = self.parse_summary(file, n)?;
                    if let Some(prev) = spec.summaries.iter().find(|p| p.name == m.name) {
                        return Err(self
                            .e(m.span, format!("duplicate summary name '{}'", m.name))
                            .with_help(format!(
                                "first at {}; give one of them name=\"…\"",
                                self.where_(prev.span)
                            )));
                    }
                    spec.summaries.push(m);
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
        for m in &spec.summaries {
            if let Some(prev) = measure_spans.get(&m.name) {
                return Err(self
                    .e(
                        m.span,
                        format!("summary name '{}' is also a measurement's", m.name),
                    )
                    .with_help(format!(
                        "the measurement is at {}; give the summary name=\"…\"",
                        self.where_(*prev)
                    )));
            }
            // (a missing of= is reported by check, after misspelt properties)
            let Some(of) = m.of.first().map(String::as_str) else {
                continue;
            };
            if !spec.measures.iter().any(|x| x.name == of) {
                let at = m.spans.values.get("of").copied().unwrap_or(m.span);
                let names: Vec<&str> = spec.measures.iter().map(|x| x.name.as_str()).collect();
                return Err(self
                    .e(
                        at,
                        format!(
                            "summary '{}': of=\"{of}\" is not a measurement of this experiment",
                            m.name
                        ),
                    )
                    .with_help_opt(
                        did_you_mean(of, names.iter().copied())
                            .map(|x| format!("did you mean '{x}'?"))
                            .or_else(|| Some(format!("measurements: {}", names.join(", ")))),
                    ));
            }
        }
        crate::experiment::measured::check_references(&spec).map_err(|(sp, e)| self.ae(sp, e))?;
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
    pub(super) fn base_path(
        &self,
        written: &str,
        vspan: Span,
        dir: &Path,
    ) -> Result<PathBuf, Located> {
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
}
