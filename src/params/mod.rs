//! Parameters: how a property written in KDL reaches the stage that uses it.
//!
//! In the spirit of pbrt-v4's `ParameterDictionary`: a stage reads its
//! properties through a [`ParamDict`] with typed look-ups that mark each one
//! used, against the stage's [`Schema`] (the one list of its properties, from
//! which the language reference's tables and the parameter-reach test are
//! generated). [`ParamDict::finish`] turns every property nobody read into an
//! "unknown property" error listing the accepted names, with a did-you-mean.
//! A [`ParamError`] names the property; the experiment layer, which knows where
//! each property was written, turns it into a `file:line:col` diagnostic.
//!
//! - `value`: [`Value`], [`Params`] (the values as written)
//! - `error`: [`ParamError`]
//! - `schema`: [`ParamSpec`], [`Schema`], [`Kind`]
//! - `dict`: [`ParamDict`]

pub mod dict;
pub mod error;
pub mod schema;
pub mod value;

pub use dict::ParamDict;
pub use error::ParamError;
pub use schema::{Kind, ParamSpec, Schema};
pub use value::{Params, Value};
