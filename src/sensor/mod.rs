//! The image sensor model: spectral irradiance → electrons → volts → digital values.
//!
//! - [`config`]: sensor definition files (`sensors/*.kdl`) → [`SensorConfig`], overrides;
//! - [`pipeline`]: the model itself ([`simulate`], [`simulate_frame`], [`simulate_flat`]);
//! - [`rng`]: counter-based per-pixel random streams, exact Poisson sampling.

pub mod config;
pub mod output;
pub mod pipeline;
pub mod rng;

pub use config::{Exposure, RelativeIllumination, SensorConfig, Sources};
pub use pipeline::{SensorFrame, simulate, simulate_flat, simulate_frame};
