//! The spectral path tracer: BVH, materials, lights, integrator, film.
//!
//! `render(scene, camera, film, settings)` returns the spectral irradiance at
//! the sensor plane in W/(m²·nm) (`OpticalImage`), with per-pixel object
//! labels, depth and per-band Monte Carlo standard error.
//!
//! - Units: scene radiance W/(sr·m²·nm); the camera's weight turns it into film
//!   irradiance (see `optics` conventions); geometry in metres.
//! - Pixel estimate: box filter over the pixel area; `spp` samples split
//!   round-robin into `batches` independent batches; the standard error is the
//!   spread of the batch means, √(Σ(mₖ−m)²/(B(B−1))).
//! - Sampler (`sampler.rs`, `RenderSettings::sampler`): by default each
//!   batch's samples are the points of an Owen-scrambled 2-D Sobol net in
//!   every draw of the camera and the first two bounces (film position, lens
//!   position, light choice and position, lobe, direction, roulette), so they
//!   are stratified over the pixel, the pupil, the light and the hemisphere;
//!   every batch and pixel is scrambled independently, so each sample is still
//!   uniform and the batch means stay independent. The stratification covers
//!   `spp / batches` points: fewer batches give a less noisy image and a
//!   coarser standard error. `independent` draws every number from PCG32.
//! - Determinism: sample `s` of pixel `(x, y)` uses a PCG32 stream keyed by
//!   `(seed, y·width + x, s)` and Sobol scrambles keyed by
//!   `(seed, y·width + x, batch)`, and pixels are reduced in a fixed order, so any
//!   thread count and any region of interest give bit-identical pixels.
//! - Non-finite samples are dropped (counted in `nan_count`), never written.
//! - Samples with pdf = 0 terminate the path (zero contribution).
//! - Labels and depth come from one extra ray through the pixel centre and the
//!   pupil centre (u = ½, ½) at the middle wavelength of the grid; depth is the
//!   distance along that ray in metres (∞ when it escapes).
//! - `FilmSpec::crop_window` is not applied here; use `RenderSettings::roi`.
//! - Spectra: every path carries all bands of the grid (no colour noise). A
//!   dispersive camera (`Camera::is_dispersive`) makes each camera sample pick
//!   one band uniformly (hero wavelength, weight = band count); a dielectric
//!   with a wavelength-dependent ior does the same when a path first meets it.
//! - Bounces: `max_bounces` counts scattering events as pbrt's maxdepth;
//!   Mitsuba's `max_depth = d` equals `max_bounces = d − 1`. Russian roulette
//!   starts after the second bounce with survival probability min(1, m/m₁):
//!   the throughput's largest band relative to the same after the first
//!   bounce (`path::roulette`).
//! - Instruction set: the row kernel runs at the widest level of the CPU
//!   (`simd::RenderIsa`: sse, avx2+fma, avx512f; `CAMSIM_RENDER_ISA` lowers
//!   it), with the same bits at every level.
//! - Paths one at a time or in packets (`film::Kernel`): at AVX2 and AVX-512
//!   a run of rows' samples (`film::rows_per_run`, ≈ 32 768 paths) are
//!   traced 16 at a time, 32 packets in flight
//!   (`film::packets_in_flight`; one bounce of every live path is
//!   `integrator::packet_rays`, `shade_hits`, `add_unblocked`): the live
//!   paths' rays of all the run's packets are sorted by direction octant and
//!   origin cell and cast 16 at a time in that order (`ray_stream.rs`), each
//!   `RayPacket` through the packet traversal (`bvh4_packet.rs`, SIMD across
//!   rays; AVX-512 intrinsics in `bvh4_packet_avx512.rs` at that level,
//!   where up to four rays reaching a leaf are tested against its triangles
//!   in one sixteen-lane test, `Spread`), the
//!   hits on Lambertian triangles are shaded together in structure of arrays
//!   (`shade_packet.rs`: hit points, frames, triangle-light samples, MIS,
//!   cosine BSDF samples across the 16 lanes; at AVX-512 each lane's hit
//!   geometry, ray and Sobol draws fetched by gathers, `hit_lanes_avx512.rs`
//!   and `sampler::bounce_draws_sobol_lanes`) and any other hit lane by lane
//!   (`integrator::scatter`), then their shadow rays are sorted and cast the
//!   same way;
//!   a lane whose path ends takes the next sample of the run's stream, of
//!   the same pixel or the next (`film::RunJob::run_packets`), and each
//!   pixel is accumulated in sample order when its last path ends. At SSE,
//!   or with `CAMSIM_RENDER_PACKETS=0`, each path is traced alone
//!   (`integrator::trace`; `=1` forces packets). Both render the same bits.
//!   Measured gains: docs/performance.md.
//! - Light selection: proportional to power, each emitting light at least
//!   10⁻³/N (`world::selection_pmf`), with the draw that places the sample
//!   on the light (`World::choose_light`).
//! - Performance: `bench/mitsuba_compare.sh` (Mitsuba `cornell_box()`, 256²,
//!   max_depth 7 = max_bounces 6, 2 threads, CIE Y against one converged
//!   Mitsuba reference, box filter, 4 seeds). The current figures per
//!   machine are in the README (*Performance by machine*), their history in
//!   docs/performance.md. On the 2-core AVX-512 EPYC (2026-11-29, 16 paths
//!   at a time, shading in structure of arrays, relative roulette, rays
//!   regrouped across 32 packets, render jobs of several rows) camsim runs
//!   1.25× Mitsuba's paths/s (31 bands per path against 4 wavelengths), and
//!   with the Sobol sampler in one batch its equal-time RMSE is 0.39 of
//!   Mitsuba's over all pixels and 0.72 for light transport (emitter edge
//!   excluded).
//!   Converged images agree (mean Y ratio 0.9999, 16×16 blocks 0.38 % RMS).
//!   Mitsuba's LLVM `render()` returns before its kernels run: time it to
//!   completion. Russian roulette relative to the first bounce's
//!   throughput (`path::roulette`) removed the green wall's excess noise
//!   (`bench.rs`).

// `!(x > 0.0)` is deliberate throughout: it also rejects NaN.
#![allow(clippy::neg_cmp_op_on_partial_ord)]

pub mod accel;
mod bands;
pub mod bench;
pub mod bsdf;
pub mod bvh4;
pub mod bvh4_packet;
#[cfg(target_arch = "x86_64")]
mod bvh4_packet_avx512;
pub mod film;
pub mod geometry;
#[cfg(target_arch = "x86_64")]
mod hit_lanes_avx512;
pub mod integrator;
mod lanes;
pub mod output;
pub mod path;
pub mod ray_packet;
mod ray_stream;
pub mod sampler;
pub mod sampling;
pub mod settings;
mod shade_packet;
pub mod simd;
mod stages;
mod triangle_lights;
pub mod world;

use crate::Result;
use crate::optical_image::{OpticalImage, Rect};
use crate::optics::Camera;
use crate::scene::{FilmSpec, Scene};

pub use accel::BvhKind;
pub use sampler::SamplerKind;
pub use settings::RenderSettings;
pub use world::World;

/// Render `scene` through `camera` onto `film`. The camera's world pose is
/// `scene.camera.to_world` (identity when the scene has no camera).
pub fn render(
    scene: &Scene,
    camera: &dyn Camera,
    film: &FilmSpec,
    settings: &RenderSettings,
) -> Result<OpticalImage> {
    let world = World::build(scene, &settings.grid, BvhKind::Bvh4)?; // see geometry.rs and bvh4.rs
    let to_world = scene
        .camera
        .as_ref()
        .map(|c| c.to_world)
        .unwrap_or(glam::DMat4::IDENTITY);
    let names = scene.objects.iter().map(|o| o.name.clone()).collect();
    film::render_world(&world, camera, &to_world, film, settings, names)
}

/// Render several pixel rectangles of the same film (what measurements read),
/// building the BVH once. Each result is bit-identical to the same pixels of
/// a full render with the same settings; `settings.roi` is ignored.
pub fn render_regions(
    scene: &Scene,
    camera: &dyn Camera,
    film: &FilmSpec,
    settings: &RenderSettings,
    regions: &[Rect],
) -> Result<Vec<OpticalImage>> {
    let world = World::build(scene, &settings.grid, BvhKind::Bvh4)?;
    let to_world = scene
        .camera
        .as_ref()
        .map(|c| c.to_world)
        .unwrap_or(glam::DMat4::IDENTITY);
    let names: Vec<String> = scene.objects.iter().map(|o| o.name.clone()).collect();
    regions
        .iter()
        .map(|r| {
            let s = RenderSettings {
                roi: Some(*r),
                ..settings.clone()
            };
            film::render_world(&world, camera, &to_world, film, &s, names.clone())
        })
        .collect()
}
