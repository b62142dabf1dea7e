//! The nodes with properties of their own: `scene`, `add`, `lens`/`sensor`,
//! `measure`, `measured`.

use super::*;
use crate::diag::{Located, did_you_mean};
use crate::experiment::apply;
use crate::experiment::source::Span;
use crate::params::{Params, Value};
use kdl::KdlNode;
use std::path::Path;

impl P {
    /// `scene "file" [materials="paper"|"file"]`.
    pub(super) fn scene_node(
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

    pub(super) fn parse_add(
        &self,
        file: usize,
        n: &KdlNode,
        dir: &Path,
    ) -> Result<Addition, Located> {
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

    pub(super) fn parse_config(
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

    pub(super) fn parse_measure(&self, file: usize, n: &KdlNode) -> Result<Measure, Located> {
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
    pub(super) fn parse_measured(
        &self,
        file: usize,
        n: &KdlNode,
        dir: &Path,
    ) -> Result<MeasuredInput, Located> {
        let known = crate::experiment::language::MEASURED_SCHEMA.names();
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

    /// `save "dng" …`: extra images written for every variant (see
    /// [`super::super::spec::SAVE_KINDS`]); no properties.
    pub(super) fn parse_save(&self, file: usize, n: &KdlNode) -> Result<Vec<String>, Located> {
        let sp = self.node_span(file, n);
        let kinds = super::super::spec::SAVE_KINDS;
        let mut out: Vec<String> = vec![];
        for e in self.entries(file, n)? {
            let at = e.name.as_ref().map(|(_, s)| *s).unwrap_or(e.vspan);
            match (&e.name, &e.value) {
                (None, Value::String(k)) if kinds.contains(&k.as_str()) => {
                    if out.contains(k) {
                        return Err(self.e(e.vspan, format!("'{k}' is listed twice")));
                    }
                    out.push(k.clone());
                }
                (None, v) => {
                    return Err(self
                        .e(
                            at,
                            format!("save {}: expected one of {kinds:?}", apply::describe(v)),
                        )
                        .with_help_opt(match v {
                            Value::String(s) => crate::diag::did_you_mean(s, kinds.iter().copied())
                                .map(|x| format!("did you mean '{x}'?")),
                            _ => None,
                        }));
                }
                (Some((k, _)), _) => {
                    return Err(self
                        .e(at, format!("'save' takes no properties, found '{k}'"))
                        .with_help("write save \"dng\""));
                }
            }
        }
        if out.is_empty() {
            return Err(self
                .e(sp, "'save' needs what to save")
                .with_help(format!("one or more of {kinds:?}, e.g. save \"dng\"")));
        }
        Ok(out)
    }

    /// `sanity "pov" [min-iou=…] [width-px=…] [height-px=…] [through=…]`.
    pub(super) fn parse_sanity(&self, file: usize, n: &KdlNode) -> Result<Measure, Located> {
        let sp = self.node_span(file, n);
        let mut kind = None;
        let mut params = Params::new();
        let mut spans = PropSpans::default();
        for e in self.entries(file, n)? {
            match e.name {
                None => match &e.value {
                    Value::String(k) if k == "pov" && kind.is_none() => kind = Some(k.clone()),
                    v => {
                        return Err(self
                            .e(
                                e.vspan,
                                format!("sanity check {}: expected \"pov\"", apply::describe(v)),
                            )
                            .with_help("write sanity \"pov\" [min-iou=0.98]"));
                    }
                },
                Some((k, ks)) => {
                    apply::check_generic(&k, &e.value).map_err(|x| self.ae(ks, x))?;
                    params.set(k.clone(), e.value);
                    spans.insert(&k, ks, e.vspan);
                }
            }
        }
        let Some(kind) = kind else {
            return Err(self
                .e(sp, "'sanity' needs the check's name")
                .with_help("write sanity \"pov\""));
        };
        Ok(Measure {
            name: "sanity-pov".into(),
            kind,
            of: vec![],
            params,
            span: sp,
            spans,
        })
    }

    /// `summary "kind" [name="…"] of="<measurement>" name=value …`.
    pub(super) fn parse_summary(&self, file: usize, n: &KdlNode) -> Result<Measure, Located> {
        let kinds = crate::summary::KINDS;
        let sp = self.node_span(file, n);
        let mut kind: Option<String> = None;
        let mut name = None;
        let mut m = Measure {
            name: String::new(),
            kind: String::new(),
            of: vec![],
            params: Params::new(),
            span: sp,
            spans: Default::default(),
        };
        for e in self.entries(file, n)? {
            match &e.name {
                None => {
                    let Value::String(s) = &e.value else {
                        return Err(self.e(
                            e.vspan,
                            format!("expected a string, found {}", apply::describe(&e.value)),
                        ));
                    };
                    if kind.is_some() {
                        return Err(self
                            .e(e.vspan, "'summary' takes one kind")
                            .with_help("write summary \"steps\" of=\"mcc\" …"));
                    }
                    if !kinds.contains(&s.as_str()) {
                        let help = did_you_mean(s, kinds.iter().copied())
                            .map(|x| format!("did you mean '{x}'?"));
                        return Err(self
                            .e(
                                e.vspan,
                                format!(
                                    "unknown summary '{s}'; expected one of: {}",
                                    kinds.join(", ")
                                ),
                            )
                            .with_help_opt(help));
                    }
                    kind = Some(s.clone());
                    m.span = e.vspan;
                }
                Some((k, ks)) => match k.as_str() {
                    "name" => {
                        let s = apply::as_str(&e.value, "name").map_err(|x| self.ae(e.vspan, x))?;
                        if s.is_empty() || s.contains('.') || s.contains(',') || s.contains('/') {
                            return Err(self
                                .e(e.vspan, format!("invalid summary name '{s}'"))
                                .with_help("non-empty, without '.', ',' or '/'"));
                        }
                        name = Some(s.to_string());
                    }
                    "of" => {
                        let s = apply::as_str(&e.value, "of").map_err(|x| self.ae(e.vspan, x))?;
                        m.of = vec![s.to_string()];
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
                .e(sp, "'summary' needs the summary kind")
                .with_help(format!(
                    "e.g. summary \"steps\" of=\"mcc\" axis=\"tag.step\" reference=\"measured\"; kinds: {}",
                    kinds.join(", ")
                )));
        };
        m.name = name.unwrap_or_else(|| kind.clone());
        m.kind = kind;
        Ok(m)
    }
}
