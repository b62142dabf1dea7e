//! The typed experiment: what a parsed and resolved KDL file means.
//!
//! Every part keeps the [`Span`] it came from (skipped when serialising), so a
//! later check — a sweep value, a validator hook, a missing file — can still
//! point at `file:line:col`. The serialised form (JSON) is what `camsim plan
//! --json` prints and what the run's input hash is computed from, so
//! reformatting a file or editing comments never invalidates results.

use super::source::Span;
use crate::params::{Params, Value};
use crate::spectrum::WavelengthGrid;
use serde::Serialize;
use std::collections::BTreeMap;
use std::path::PathBuf;

/// Where each property of a node was written: the span of its name and of its
/// value (diagnostics point at one or the other).
#[derive(Clone, Debug, PartialEq, Default)]
pub struct PropSpans {
    pub names: BTreeMap<String, Span>,
    pub values: BTreeMap<String, Span>,
}

impl PropSpans {
    pub fn insert(&mut self, key: &str, name: Span, value: Span) {
        self.names.insert(key.to_string(), name);
        self.values.insert(key.to_string(), value);
    }
    pub fn extend(&mut self, other: PropSpans) {
        self.names.extend(other.names);
        self.values.extend(other.values);
    }
    pub fn clear(&mut self) {
        self.names.clear();
        self.values.clear();
    }
    /// The span of property `key`'s name, else `whole`.
    pub fn name_at(&self, key: &str, whole: Span) -> Span {
        self.names.get(key).copied().unwrap_or(whole)
    }
    /// The span of property `key`'s value, else `whole`.
    pub fn value_at(&self, key: &str, whole: Span) -> Span {
        self.values.get(key).copied().unwrap_or(whole)
    }
}

/// A reference to a file as written, and as resolved against the referring file's directory.
#[derive(Clone, Debug, PartialEq, Serialize)]
pub struct FileRef {
    pub written: String,
    pub path: PathBuf,
    #[serde(skip)]
    pub span: Span,
}

pub use crate::scene::edits::Target;

/// An object added to the scene (`add "edge-near" target="slanted-edge" …`).
#[derive(Clone, Debug, PartialEq, Serialize)]
pub struct Addition {
    pub id: String,
    pub target: Target,
    /// Mesh file (required for `target="mesh"`).
    pub file: Option<FileRef>,
    pub position_m: [f64; 3],
    /// Rotation about x, then y, then z, in degrees.
    pub rotate_deg: [f64; 3],
    /// Scale factors (a single `scale=` number applies to all three axes).
    pub scale: [f64; 3],
    /// Further target-specific properties (e.g. `tilt-deg`, `size-m`, `reflectance`).
    pub params: Params,
    #[serde(skip)]
    pub span: Span,
    /// Spans of the property names and values.
    #[serde(skip)]
    pub spans: PropSpans,
}

/// Changes to an object of the base scene (`override "wall-left" reflectance="cbox-red-wall"`).
#[derive(Clone, Debug, PartialEq, Serialize)]
pub struct Override {
    pub object: String,
    pub params: Params,
    #[serde(skip)]
    pub span: Span,
    /// Spans of the property names and values.
    #[serde(skip)]
    pub spans: PropSpans,
}

/// Camera pose in scene coordinates (metres).
#[derive(Clone, Debug, PartialEq, Serialize)]
pub struct CameraSection {
    pub position_m: [f64; 3],
    pub look_at_m: [f64; 3],
    pub up: [f64; 3],
    #[serde(skip)]
    pub span: Span,
}

/// A lens or sensor: an optional definition file plus inline overrides.
/// The names inside `overrides` belong to the optics / sensor modules, which
/// read them (see [`super::check`]).
#[derive(Clone, Debug, PartialEq, Serialize, Default)]
pub struct ConfigSection {
    pub file: Option<FileRef>,
    pub overrides: Params,
    #[serde(skip)]
    pub span: Span,
    /// Spans of the property names and values.
    #[serde(skip)]
    pub spans: PropSpans,
}

/// Render settings.
#[derive(Clone, Debug, PartialEq, Serialize)]
pub struct RenderSettings {
    /// Samples per pixel (≥ 1).
    pub spp: u64,
    /// Maximum path length in bounces (0 = emitters seen directly only).
    pub max_bounces: u32,
    /// Random seed of the variant (`--seed` replaces it for every variant).
    pub seed: u64,
    /// Wavelength grid `wavelength-nm=(start stop step)`.
    pub wavelength: WavelengthGrid,
    /// `sampler="sobol"|"independent"`: the renderer's random numbers.
    pub sampler: crate::render::SamplerKind,
    /// `target-stderr=…`: error-driven sampling. With a target, `spp` is the
    /// first round and the render goes on in rounds until every figure meets
    /// its target (or a budget is spent); see [`super::sampling`].
    #[serde(skip_serializing_if = "Option::is_none")]
    pub target_stderr: Option<StderrTarget>,
    /// Per-measurement (or per-figure) targets: `target "NAME" stderr=…`
    /// children of `render`; they replace `target_stderr` for those figures.
    #[serde(skip_serializing_if = "Vec::is_empty")]
    pub targets: Vec<FigureTarget>,
    /// `max-s=…`: wall-time budget of error-driven sampling (render and
    /// measurements of all rounds). A run stopped by it is marked and is not
    /// reproducible (it depends on the machine's speed).
    #[serde(skip_serializing_if = "Option::is_none")]
    pub max_s: Option<f64>,
    /// `max-spp=…`: sample budget of error-driven sampling (deterministic).
    #[serde(skip_serializing_if = "Option::is_none")]
    pub max_spp: Option<u64>,
    /// Where the `render` node was written (errors about its settings point here).
    #[serde(skip)]
    pub span: Span,
}

impl RenderSettings {
    /// Does the variant sample until a standard-error target is met?
    pub fn error_driven(&self) -> bool {
        self.target_stderr.is_some() || !self.targets.is_empty()
    }

    /// Add a `target` child; it replaces an earlier target of the same
    /// measurement and quantity (a base's, or the `render` node's for a
    /// quality preset).
    pub fn set_target(&mut self, t: FigureTarget) {
        self.targets.retain(|o| {
            (o.measurement.as_str(), o.quantity.as_deref())
                != (t.measurement.as_str(), t.quantity.as_deref())
        });
        self.targets.push(t);
    }
}

impl Default for RenderSettings {
    fn default() -> Self {
        Self {
            spp: 64,
            max_bounces: 5,
            seed: 0,
            wavelength: WavelengthGrid::default(),
            sampler: crate::render::SamplerKind::default(),
            target_stderr: None,
            targets: Vec::new(),
            max_s: None,
            max_spp: None,
            span: Span::default(),
        }
    }
}

/// A standard-error target: absolute, in each figure's own unit
/// (`target-stderr=0.5`), or relative to the figure's magnitude
/// (`target-stderr="1%"`: stderr ≤ 0.01·|value|).
#[derive(Clone, Copy, Debug, PartialEq, Serialize)]
#[serde(rename_all = "lowercase")]
pub enum StderrTarget {
    Absolute(f64),
    Relative(f64),
}

impl StderrTarget {
    /// The largest standard error that meets the target for a figure of `value`.
    pub fn allowed(&self, value: f64) -> f64 {
        match *self {
            StderrTarget::Absolute(a) => a,
            StderrTarget::Relative(r) => r * value.abs(),
        }
    }
}

impl std::fmt::Display for StderrTarget {
    fn fmt(&self, f: &mut std::fmt::Formatter<'_>) -> std::fmt::Result {
        match self {
            StderrTarget::Absolute(a) => write!(f, "{a}"),
            StderrTarget::Relative(r) => write!(f, "{}%", r * 100.0),
        }
    }
}

/// `render { target "MEASUREMENT" [quantity="Q"] stderr=… }`: the target of
/// one measurement's figures (all of them, or the quantity `Q`: its exact
/// name or a trailing `/…` part of it).
#[derive(Clone, Debug, PartialEq, Serialize)]
pub struct FigureTarget {
    pub measurement: String,
    #[serde(skip_serializing_if = "Option::is_none")]
    pub quantity: Option<String>,
    pub stderr: StderrTarget,
    #[serde(skip)]
    pub span: Span,
}

impl FigureTarget {
    /// Does this target apply to figure (`measurement`, `quantity`)? The
    /// quantity matches its exact name or a trailing `/…` part of it
    /// (`mtf50` matches `edge-near/mtf50`, `g/r` matches `mcc/patch04/g/r`).
    pub fn applies(&self, measurement: &str, quantity: &str) -> bool {
        self.measurement == measurement
            && self.quantity.as_deref().is_none_or(|q| {
                quantity == q
                    || quantity
                        .strip_suffix(q)
                        .is_some_and(|head| head.ends_with('/'))
            })
    }
}

/// `quality "NAME" spp=… target-stderr=… max-s=…`: render settings that
/// `camsim run --quality NAME` puts in place of the `render` node's (before
/// sweeps, so a swept `render.*` value still wins).
#[derive(Clone, Debug, PartialEq, Default)]
pub struct QualityPreset {
    pub name: String,
    pub params: Params,
    /// `target` children: they replace the `render` node's target of the
    /// same measurement and quantity.
    pub targets: Vec<FigureTarget>,
    pub span: Span,
    pub spans: PropSpans,
}

/// One requested measurement.
#[derive(Clone, Debug, PartialEq, Serialize)]
pub struct Measure {
    /// Name used in results (`name=`; defaults to the kind).
    pub name: String,
    /// Kind: `colorimetry`, `sfr`, `ri`, `noise`, `profile`, `mcc`, `compare`, `convergence`.
    pub kind: String,
    /// Objects measured (`of="edge-near"` and/or further arguments).
    pub of: Vec<String>,
    pub params: Params,
    #[serde(skip)]
    pub span: Span,
    /// Spans of the property names and values.
    #[serde(skip)]
    pub spans: PropSpans,
}

/// A captured image named by the experiment (`measured "capture-near"
/// file="captures/edge.dng" [pixel-um=1.4] [labels="…png" names="…txt"]`).
/// Measurements read it with `input="capture-near"` instead of the simulated
/// sensor image. A label map (grey PNG, value k = the object on line k of
/// `names`) gives the capture object labels for `mcc` and `profile`.
#[derive(Clone, Debug, PartialEq, Serialize)]
pub struct MeasuredInput {
    pub name: String,
    pub file: FileRef,
    /// Pixel pitch in µm (for cy/mm figures).
    #[serde(skip_serializing_if = "Option::is_none")]
    pub pixel_um: Option<f64>,
    #[serde(skip_serializing_if = "Option::is_none")]
    pub labels: Option<FileRef>,
    #[serde(skip_serializing_if = "Option::is_none")]
    pub names: Option<FileRef>,
    #[serde(skip)]
    pub span: Span,
}

/// What `save` can write for every variant: `dng`, the raw sensor mosaic as a
/// DNG (`previews/<variant>/sensor.dng`, linked from the report) with a grey
/// picture of the mosaic beside the white-balanced preview.
pub const SAVE_KINDS: &[&str] = &["dng"];

/// Known measurement kinds (the measurement layer's list).
pub use crate::measure::request::KINDS as MEASURE_KINDS;

/// An experiment with its base setups merged in, before sweeps are applied.
#[derive(Clone, Debug, PartialEq, Serialize)]
pub struct ResolvedExperiment {
    pub name: String,
    /// The experiment file.
    pub file: PathBuf,
    pub description: Option<String>,
    /// Base setups included, outermost first.
    pub bases: Vec<PathBuf>,
    pub scene: Option<FileRef>,
    /// `scene "…" materials="paper"`: replace the pbrt scene's placeholder
    /// materials by the paper's measured spectra (Cornell box walls, lamp).
    #[serde(skip_serializing_if = "Option::is_none")]
    pub scene_materials: Option<String>,
    pub additions: Vec<Addition>,
    pub removals: Vec<String>,
    pub overrides: Vec<Override>,
    pub camera: Option<CameraSection>,
    pub lens: Option<ConfigSection>,
    pub sensor: Option<ConfigSection>,
    pub render: RenderSettings,
    pub measures: Vec<Measure>,
    /// Captured images (`measured "name" file="…"`), read by measurements with `input="name"`.
    #[serde(skip_serializing_if = "Vec::is_empty")]
    pub measured: Vec<MeasuredInput>,
    /// `sanity "pov" …`: the POV-Ray geometry check of every variant (its
    /// properties in `params`; `kind` is "pov").
    #[serde(skip_serializing_if = "Option::is_none")]
    pub sanity: Option<Measure>,
    /// `save "dng"`: extra images of every variant ([`SAVE_KINDS`]).
    #[serde(skip_serializing_if = "Vec::is_empty")]
    pub save: Vec<String>,
    /// Values of label-only sweep axes (`tag.<name>`), for ids and results.
    pub tags: BTreeMap<String, Value>,
    /// `summary "kind" of="…" …`: cross-variant summaries, run once the whole
    /// plan has results. Not part of a variant's inputs (not serialised, so
    /// not hashed): a summary is recomputed from the results on every run.
    #[serde(skip)]
    pub summaries: Vec<Measure>,
    /// `quality "NAME" …` presets (applied by `camsim run --quality NAME`
    /// before planning; the applied settings are in `render`, so hashed).
    #[serde(skip)]
    pub qualities: Vec<QualityPreset>,
}

impl ResolvedExperiment {
    /// An experiment called `name` defined in `file`, with nothing in it yet.
    pub fn empty(name: &str, file: &std::path::Path) -> Self {
        Self {
            name: name.to_string(),
            file: file.to_path_buf(),
            description: None,
            bases: Vec::new(),
            scene: None,
            scene_materials: None,
            additions: Vec::new(),
            removals: Vec::new(),
            overrides: Vec::new(),
            camera: None,
            lens: None,
            sensor: None,
            render: RenderSettings::default(),
            measures: Vec::new(),
            measured: Vec::new(),
            sanity: None,
            save: Vec::new(),
            tags: BTreeMap::new(),
            summaries: Vec::new(),
            qualities: Vec::new(),
        }
    }

    /// The captured image called `name`.
    pub fn measured_input(&self, name: &str) -> Option<&MeasuredInput> {
        self.measured.iter().find(|c| c.name == name)
    }

    /// Files whose contents are inputs of a variant (hashed for resume), besides
    /// the resolved spec itself.
    pub fn referenced_files(&self) -> Vec<PathBuf> {
        let mut v = Vec::new();
        if let Some(s) = &self.scene {
            v.push(s.path.clone());
        }
        for a in &self.additions {
            if let Some(f) = &a.file {
                v.push(f.path.clone());
            }
        }
        for s in [&self.lens, &self.sensor].into_iter().flatten() {
            if let Some(f) = &s.file {
                v.push(f.path.clone());
            }
        }
        // Bases are not hashed as files: everything they set is in the resolved
        // spec, so an experiment written with a base and the same experiment
        // written out inline have the same inputs (and the same hash).
        for c in &self.measured {
            v.push(c.file.path.clone());
            v.extend(
                [&c.labels, &c.names]
                    .into_iter()
                    .flatten()
                    .map(|f| f.path.clone()),
            );
        }
        // Spectra read from CSV files (`spectrum="data.csv#column"`).
        let dir = self.file.parent().unwrap_or(std::path::Path::new(""));
        for m in &self.measures {
            for val in m.params.0.values() {
                if let Value::String(s) = val
                    && let Some((file, _)) = s.split_once('#')
                    && file.ends_with(".csv")
                {
                    v.push(dir.join(file));
                }
            }
        }
        v
    }
}
