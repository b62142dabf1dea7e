//! Scenes: the model, loaders (meshes, pbrt), and measurement targets.

pub mod camera_params;
pub mod edits;
pub mod intersections;
pub mod kdl_scene;
pub mod mesh_io;
pub mod model;
pub mod pbrt;
pub mod shapes;
pub mod targets;

pub use model::*;
