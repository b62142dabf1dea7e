//! The renderer's settings: samples, bounces, wavelength grid, seed, batches,
//! threads, region of interest, standard-error weights and sampler.

use super::sampler::SamplerKind;
use crate::optical_image::Rect;
use crate::spectrum::WavelengthGrid;
use serde::{Deserialize, Serialize};

/// Render settings.
#[derive(Clone, Debug, Serialize, Deserialize)]
pub struct RenderSettings {
    /// Samples per pixel.
    pub spp: u32,
    /// Scattering events per path (pbrt's maxdepth; Mitsuba max_depth − 1).
    pub max_bounces: u32,
    pub grid: WavelengthGrid,
    pub seed: u64,
    /// Independent sample batches for the standard error (clamped to [1, spp]).
    pub batches: u32,
    /// Worker threads; 0 = rayon's default.
    pub threads: usize,
    /// Render only this pixel rectangle of the film.
    pub roi: Option<Rect>,
    /// Band weight sets (one weight per band each) whose weighted band sums
    /// get a per-pixel standard error too (`OpticalImage::weighted_stderr`),
    /// e.g. a sensor's channel electron rates. Empty: none.
    #[serde(default)]
    pub stderr_weights: Vec<Vec<f32>>,
    /// The random numbers of a sample (`sampler.rs`): Owen-scrambled Sobol
    /// (default) or independent.
    #[serde(default)]
    pub sampler: SamplerKind,
}

impl Default for RenderSettings {
    fn default() -> Self {
        Self {
            spp: 64,
            max_bounces: 6,
            grid: WavelengthGrid::default(),
            seed: 0,
            batches: 8,
            threads: 0,
            roi: None,
            stderr_weights: vec![],
            sampler: SamplerKind::default(),
        }
    }
}
