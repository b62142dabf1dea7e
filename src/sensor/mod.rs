//! The image sensor model: spectral irradiance → electrons → volts → digital values,
//! and the calibration a sensor engineer runs on its output.
//!
//! - [`config`]: [`SensorConfig`] and the quantities derived from it;
//! - [`config_file`]: sensor definition files (`sensors/*.kdl`) → [`SensorConfig`];
//! - [`sensor_params`]: the properties of a `sensor` ([`SCHEMA`]) and [`sensor_config`]
//!   (file + an experiment's inline properties → [`SensorConfig`]);
//! - [`relative_illumination`]: pixel/microlens relative illumination models;
//! - [`pipeline`]: the model itself ([`simulate`], [`simulate_frame`], [`simulate_flat`]);
//! - [`rng`]: counter-based per-pixel random streams, exact Poisson sampling;
//! - [`prefetch`]: the next row's optical image brought into cache while a row's noise is drawn;
//! - [`output`]: raw 16-bit PNG, DNG, demosaiced preview;
//! - [`nnls`]: Lawson–Hanson NNLS and the paper's QE correction matrix (Eq. 2–3);
//! - [`calibrate`]: Appendix III conversion gain, EMVA 1288 photon transfer;
//! - [`flatfield`]: flat-field sequences on disk (simulate → PNG + settings.csv → read);
//! - [`bench`](mod@bench): the full-frame speed benchmark.

pub mod bench;
pub mod calibrate;
pub mod config;
pub mod config_file;
pub mod flatfield;
pub mod nnls;
pub mod output;
pub mod pipeline;
pub mod prefetch;
pub mod readout;
pub mod relative_illumination;
pub mod rng;
pub mod sensor_params;

pub use bench::bench_sensor;
pub use config::{Exposure, RelativeIllumination, SensorConfig, Sources};
pub use pipeline::{SensorFrame, simulate, simulate_flat, simulate_frame};
pub use sensor_params::{SCHEMA, sensor_config};
