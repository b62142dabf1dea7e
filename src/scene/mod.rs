//! Scenes: the model, loaders (meshes, pbrt), and measurement targets.

pub mod model;
pub mod pbrt;
pub mod targets;

pub use model::*;
