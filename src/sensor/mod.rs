//! The image sensor model: spectral irradiance → electrons → volts → digital values,
//! and the calibration a sensor engineer runs on its output.
//!
//! - [`config`]: sensor definition files (`sensors/*.kdl`) → [`SensorConfig`], overrides;
//! - [`pipeline`]: the model itself ([`simulate`], [`simulate_frame`], [`simulate_flat`]);
//! - [`rng`]: counter-based per-pixel random streams, exact Poisson sampling;
//! - [`output`]: raw 16-bit PNG, DNG, demosaiced preview;
//! - [`nnls`]: Lawson–Hanson NNLS and the paper's QE correction matrix (Eq. 2–3);
//! - [`calibrate`]: Appendix III conversion gain, EMVA 1288 photon transfer;
//! - [`flatfield`]: flat-field sequences on disk (simulate → PNG + settings.csv → read);
//! - [`bench`](mod@bench): the full-frame speed benchmark.

pub mod bench;
pub mod calibrate;
pub mod config;
pub mod flatfield;
pub mod nnls;
pub mod output;
pub mod pipeline;
pub mod rng;

pub use bench::bench_sensor;
pub use config::{Exposure, RelativeIllumination, SensorConfig, Sources};
pub use pipeline::{SensorFrame, simulate, simulate_flat, simulate_frame};
