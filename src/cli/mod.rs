//! Subcommand implementations, one file per area. Each returns the process
//! exit code (see `main.rs`) or an error (exit 3).

pub mod experiment;
pub mod lens;
pub mod measure;
pub mod pov;
pub mod render;
pub mod report;
pub mod scene;
pub mod sensor;
pub mod slurm;
