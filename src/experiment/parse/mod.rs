//! KDL → [`ResolvedExperiment`] + [`Sweep`], strictly: unknown nodes and
//! properties (with suggestions), wrong types, numbers without units,
//! out-of-range values, duplicate ids, missing files, empty sweeps and
//! include cycles are each a [`Located`] error (`file:line:col`, the source
//! line, what was expected, help). The first error of a file is reported.
//!
//! A file holds one top-level node: `experiment "name" { … }` (runnable) or
//! `setup "name" { … }` (a shared base, included with `base "file.kdl"`).
//! The language is documented in `docs/experiment-language.md`.

use super::apply::ApplyError;
use super::source::{Loader, SourceMap, Span};
use super::spec::*;
use super::sweep::Sweep;
use crate::diag::Located;
use crate::params::Value;
use kdl::KdlValue;
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
    "quality",
    "sweep",
    "measure",
    "measured",
    "sanity",
    "save",
    "summary",
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
    "sanity",
    "save",
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

mod document;
mod entries;
mod nodes;
mod render_node;
mod sweep_node;
