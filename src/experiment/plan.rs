//! The run plan: every variant of an experiment with its resolved parameters
//! and input hash. `camsim plan --json` prints it; the same inputs always give
//! byte-identical JSON (ordered maps, no timestamps).

use super::parse::Parsed;
use super::sweep::{self, Variant};
use crate::diag::Located;
use serde::Serialize;
use sha2::{Digest, Sha256};
use std::path::PathBuf;

/// A planned variant: the variant plus the hash of all its inputs.
#[derive(Clone, Debug, Serialize)]
pub struct PlannedVariant {
    #[serde(flatten)]
    pub variant: Variant,
    /// SHA-256 (hex) over camsim's version, the resolved spec, the id, the swept
    /// values and the contents of every referenced file.
    pub hash: String,
}

impl PlannedVariant {
    /// Short hash used to name the per-variant results file.
    pub fn short_hash(&self) -> &str {
        &self.hash[..16]
    }
}

#[derive(Clone, Debug, Serialize)]
pub struct Plan {
    pub experiment: String,
    pub file: PathBuf,
    pub camsim_version: String,
    /// Swept parameter paths in file order (the results' parameter columns).
    pub axes: Vec<String>,
    pub variants: Vec<PlannedVariant>,
    /// The experiment's `summary` nodes, run after every variant has results.
    #[serde(skip_serializing_if = "Vec::is_empty")]
    pub summaries: Vec<super::summary::SummaryRecord>,
    /// The quality asked for (`--quality NAME`) and whether the experiment
    /// defines it: `NAME`, or `NAME (not defined: the render node's settings)`.
    #[serde(skip_serializing_if = "Option::is_none")]
    pub quality: Option<String>,
}

/// Run-wide replacements applied to every variant before hashing (`camsim run
/// --seed S --max-spp N --quality Q`): they change the resolved spec, so the
/// input hash.
#[derive(Clone, Debug, Default, PartialEq)]
pub struct PlanOverrides {
    /// Replaces `render.seed`.
    pub seed: Option<u64>,
    /// Caps `render.spp` and the sample budget `render.max-spp` of
    /// error-driven sampling (a quicker run of the same experiment, e.g. the
    /// test baselines).
    pub max_spp: Option<u64>,
    /// `--quality NAME`: the experiment's `quality "NAME"` render settings
    /// replace its `render` node's (before sweeps). An experiment without
    /// that preset runs at its own settings ([`Plan::quality`] says so).
    pub quality: Option<String>,
}

/// Expand and check every variant. `seed` replaces `render.seed` everywhere.
pub fn plan(parsed: &Parsed, seed: Option<u64>) -> Result<Plan, Located> {
    plan_with(
        parsed,
        PlanOverrides {
            seed,
            ..Default::default()
        },
    )
}

/// [`plan`] with run-wide overrides.
pub fn plan_with(parsed: &Parsed, o: PlanOverrides) -> Result<Plan, Located> {
    let (base, quality) = with_quality(parsed, o.quality.as_deref())?;
    let mut variants = sweep::expand(&base, &parsed.sweep, parsed.loader)
        .map_err(|(s, e)| parsed.sources.error(s, e.message).with_help_opt(e.help))?;
    let mut out = Vec::with_capacity(variants.len());
    let mut file_digests = std::collections::BTreeMap::new();
    let mut memo = super::check::CheckMemo::default();
    for v in variants.drain(..) {
        let mut v = v;
        if let Some(s) = o.seed {
            v.spec.render.seed = s;
        }
        if let Some(n) = o.max_spp {
            let n = n.max(1);
            v.spec.render.spp = v.spec.render.spp.min(n);
            if v.spec.render.error_driven() {
                v.spec.render.max_spp = Some(v.spec.render.max_spp.map_or(n, |m| m.min(n)));
            }
        }
        if !parsed.sweep.items.is_empty() {
            super::check::check_stages_with(&v.spec, &mut memo).map_err(|(s, e)| {
                parsed
                    .sources
                    .error(s, format!("variant '{}': {}", v.id, e.message))
                    .with_help_opt(e.help)
            })?;
        }
        let hash = input_hash_cached(&v, parsed, &mut file_digests);
        out.push(PlannedVariant { variant: v, hash });
    }
    Ok(Plan {
        experiment: parsed.spec.name.clone(),
        file: parsed.spec.file.clone(),
        camsim_version: crate::version().to_string(),
        axes: parsed.sweep.paths(),
        variants: out,
        summaries: parsed
            .spec
            .summaries
            .iter()
            .map(super::summary::SummaryRecord::from_node)
            .collect(),
        quality,
    })
}

/// The experiment's spec with the `quality "NAME"` preset applied, and the
/// plan's quality line.
fn with_quality<'a>(
    parsed: &'a Parsed,
    quality: Option<&str>,
) -> Result<
    (
        std::borrow::Cow<'a, super::spec::ResolvedExperiment>,
        Option<String>,
    ),
    Located,
> {
    use std::borrow::Cow;
    let Some(q) = quality else {
        return Ok((Cow::Borrowed(&parsed.spec), None));
    };
    let Some(preset) = parsed.spec.qualities.iter().find(|p| p.name == q) else {
        return Ok((
            Cow::Borrowed(&parsed.spec),
            Some(format!("{q} (not defined: the render node's settings)")),
        ));
    };
    let mut spec = parsed.spec.clone();
    super::apply::apply_quality(&mut spec, preset, parsed.loader)
        .map_err(|(sp, e)| parsed.sources.error(sp, e.message).with_help_opt(e.help))?;
    Ok((Cow::Owned(spec), Some(q.to_string())))
}

/// Hash of everything a variant's results depend on: camsim's version, the
/// resolved spec (without file-system paths, so the same experiment run from
/// another directory or checkout hashes the same), the id and swept values, and
/// the *contents* of every referenced file.
pub fn input_hash(v: &Variant, parsed: &Parsed) -> String {
    input_hash_cached(v, parsed, &mut Default::default())
}

/// [`input_hash`] with a cache of file digests (each file is read once per plan).
fn input_hash_cached(
    v: &Variant,
    parsed: &Parsed,
    cache: &mut std::collections::BTreeMap<PathBuf, Vec<u8>>,
) -> String {
    let mut h = Sha256::new();
    h.update(b"camsim ");
    h.update(crate::version().as_bytes());
    h.update(b"\n");
    let mut spec = serde_json::to_value(&v.spec).unwrap_or_default();
    strip_paths(&mut spec, true);
    h.update(serde_json::to_vec(&spec).unwrap_or_default());
    h.update(b"\n");
    h.update(v.id.as_bytes());
    h.update(serde_json::to_vec(&v.params).unwrap_or_default());
    for f in v.spec.referenced_files() {
        let d = cache
            .entry(f.clone())
            .or_insert_with(|| match parsed.loader.read(&f) {
                Ok(t) => Sha256::digest(t.as_bytes()).to_vec(),
                Err(_) => match std::fs::read(&f) {
                    Ok(b) => Sha256::digest(&b).to_vec(),
                    Err(_) => b"<missing>".to_vec(),
                },
            });
        h.update(&d[..]);
    }
    hex::encode(h.finalize())
}

/// Remove resolved paths: the experiment's `file` and `bases` (top level) and
/// the `path` of every file reference (which keeps its `written` form).
fn strip_paths(v: &mut serde_json::Value, top: bool) {
    match v {
        serde_json::Value::Object(m) => {
            if top {
                m.remove("file");
                m.remove("bases");
            }
            if m.contains_key("written") {
                m.remove("path");
            }
            for x in m.values_mut() {
                strip_paths(x, false);
            }
        }
        serde_json::Value::Array(a) => a.iter_mut().for_each(|x| strip_paths(x, false)),
        _ => {}
    }
}

impl Plan {
    /// Canonical JSON (pretty, ordered) with a trailing newline.
    pub fn to_json(&self) -> String {
        let mut s = serde_json::to_string_pretty(self)
            .unwrap_or_else(|e| format!("{{\"error\": \"{e}\"}}"));
        s.push('\n');
        s
    }
    /// A human-readable table: one line per variant.
    pub fn to_table(&self) -> String {
        let mut s = format!(
            "# {} ({} variants) from {}\n",
            self.experiment,
            self.variants.len(),
            self.file.display()
        );
        s.push_str("index\thash\tid\n");
        for v in &self.variants {
            s.push_str(&format!(
                "{}\t{}\t{}\n",
                v.variant.index,
                v.short_hash(),
                v.variant.id
            ));
        }
        s
    }
}
