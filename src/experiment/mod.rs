//! The experiment language (KDL) → typed spec → sweep expansion → run plan,
//! and the runner that drives every stage and writes results.
//!
//! - [`source`]: loading, the `(x y z)` tuple pre-pass, KDL errors → file:line:col
//! - [`spec`]: the typed, resolved experiment (with source spans)
//! - [`parse`]: KDL → spec, strictly, with diagnostics; `base` includes
//! - [`apply`]: typed values and parameter paths (shared by parser and sweeps)
//! - [`sweep`]: axes, zip groups, ranges, variant ids
//! - [`plan`](mod@plan): variants + input hashes, JSON
//! - [`measured`]: captured images (`measured` nodes), `compare`, `convergence`
//! - [`stages`]: scene → camera → render → sensor → measure (one function each)
//! - [`run`]: the runner (resume, shards, interruption)
//! - [`sampling`]: error-driven sampling (rounds until every figure meets its target)
//! - [`results`]: CSV, manifest, merge
//! - [`summary`](mod@summary): the cross-variant stage (`summary` nodes) after the whole plan
//! - [`language`]: every node's properties (schemas), the reference tables
//! - [`check`]: every variant's stages built from their parameters at check time
//!
//! The language reference is `docs/experiment-language.md`.

pub mod apply;
pub mod check;
pub mod embedded;
pub mod language;
pub mod measured;
pub mod oi_cache;
pub mod parse;
pub mod plan;
pub mod results;
pub mod run;
pub mod sampling;
pub mod source;
pub mod spec;
pub mod stages;
pub mod summary;
pub mod sweep;
pub mod units;

pub use parse::{DocKind, Parsed, parse_file, parse_source};
pub use plan::{Plan, plan};
pub use source::Loader;
pub use spec::ResolvedExperiment;
pub use sweep::Variant;
