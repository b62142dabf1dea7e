//! The film: pixel sampling, camera weights, batch statistics, labels and
//! depth, parallel over image rows with per-pixel seeding.

use super::bands;
use super::integrator::{
    PacketScratch, Scratch, add_unblocked, first_hit, packet_rays, shade_hits, trace,
};
use super::path::PathState;
use super::ray_packet::{ALL_LANES, LANES, LaneMask, lanes};
use super::ray_stream::RayStream;
use super::sampler::{BatchScramble, Sampler, SamplerKind};
use super::sampling::Rng;
use super::settings::RenderSettings;
use super::simd::RenderIsa;
use super::stages::{Clock, Stage};
use super::world::World;
use crate::optical_image::{OpticalImage, Rect};
use crate::optics::{Camera, CameraRay};
use crate::scene::FilmSpec;
use crate::{Error, Result};
use glam::{DMat4, DVec2, DVec3, Vec3};
use rayon::prelude::*;

/// One run of image rows (`rows_per_run`): (run index, irradiance,
/// stderr), labels, depth.
type RunSlices<'a> = (
    (((usize, &'a mut [f32]), &'a mut [f32]), &'a mut [u32]),
    &'a mut [f32],
);

/// World-space ray for a film point (None: vignetted).
#[inline(always)]
fn camera_ray(
    camera: &dyn Camera,
    to_world: &DMat4,
    film_m: DVec2,
    u: DVec2,
    lambda_nm: f64,
) -> Option<(Vec3, Vec3, f64)> {
    world_ray(to_world, camera.sample_ray(film_m, u, lambda_nm))
}

/// `d` scaled to unit length, or zero (`DVec3::normalize_or_zero`), but
/// left as it is when its squared length is already 1 within a few f64
/// rounding errors: what a unit camera direction (the pinhole's, the thin
/// lens's) turned by a rigid camera-to-world matrix gives. Its length then
/// differs from 1 by about 1e-16, a billionth of the f32 rounding the path
/// tracer's ray gets next, and the square root and division per camera
/// ray are saved (they were ≈ 3 % of the bench's render: docs/performance.md,
/// *Twenty-seventh pass*).
#[inline(always)]
fn unit(d: DVec3) -> DVec3 {
    let l2 = d.length_squared();
    if (l2 - 1.0).abs() <= 8.0 * f64::EPSILON {
        d
    } else {
        d.normalize_or_zero()
    }
}

/// The world-space ray of camera ray `r` (None: vignetted, or a weight or
/// ray the film cannot use).
#[inline(always)]
fn world_ray(to_world: &DMat4, r: Option<CameraRay>) -> Option<(Vec3, Vec3, f64)> {
    let r = r?;
    if !(r.weight > 0.0) || !r.weight.is_finite() {
        return None;
    }
    let o = to_world.transform_point3(r.origin);
    let d = unit(to_world.transform_vector3(r.direction));
    if d == DVec3::ZERO || !o.is_finite() {
        return None;
    }
    Some((o.as_vec3(), d.as_vec3(), r.weight))
}

/// Render a window of the film. See `render` for the contract. The kernel
/// runs at the widest instruction set level of this machine
/// (`RenderIsa::detect`).
pub fn render_world(
    world: &World,
    camera: &dyn Camera,
    to_world: &DMat4,
    film: &FilmSpec,
    s: &RenderSettings,
    label_names: Vec<String>,
) -> Result<OpticalImage> {
    render_world_at(
        Kernel::detect(),
        world,
        camera,
        to_world,
        film,
        s,
        label_names,
    )
}

/// How the row kernel runs: its instruction set, whether a pixel's paths
/// are traced 16 at a time (`packets`) or one by one, and how many packets
/// a run of rows keeps in flight (`in_flight`, whose rays are regrouped before
/// each cast; `ray_stream`). Every choice renders the same bits.
#[derive(Clone, Copy, Debug, PartialEq, Eq)]
pub struct Kernel {
    pub isa: RenderIsa,
    pub packets: bool,
    pub in_flight: usize,
}

impl Kernel {
    /// The widest instruction set of this machine (`RenderIsa::detect`), its
    /// default path mode or `CAMSIM_RENDER_PACKETS` (`packets_enabled`), and
    /// `packets_in_flight`.
    pub fn detect() -> Self {
        let isa = RenderIsa::detect();
        Kernel {
            isa,
            packets: packets_enabled(isa),
            in_flight: packets_in_flight(),
        }
    }

    /// Packets in flight per run of rows as reported (bench line, manifest): 0 when
    /// paths are traced one at a time.
    pub fn reported_in_flight(&self) -> usize {
        if self.packets { self.in_flight } else { 0 }
    }
}

/// `render_world` with `kernel` (compiled for its instruction set; the
/// baseline when this CPU lacks it).
pub fn render_world_at(
    kernel: Kernel,
    world: &World,
    camera: &dyn Camera,
    to_world: &DMat4,
    film: &FilmSpec,
    s: &RenderSettings,
    label_names: Vec<String>,
) -> Result<OpticalImage> {
    let start = std::time::Instant::now();
    if film.width_px == 0 || film.height_px == 0 || !(film.pixel_pitch_m > 0.0) {
        return Err(Error::invalid(format!(
            "film {}×{} px with pitch {} m is empty or invalid",
            film.width_px, film.height_px, film.pixel_pitch_m
        )));
    }
    let roi = s
        .roi
        .unwrap_or(Rect::new(0, 0, film.width_px, film.height_px));
    if roi.w == 0
        || roi.h == 0
        || roi.x as u64 + roi.w as u64 > film.width_px as u64
        || roi.y as u64 + roi.h as u64 > film.height_px as u64
    {
        return Err(Error::invalid(format!(
            "region {},{},{},{} is empty or outside the {}×{} film",
            roi.x, roi.y, roi.w, roi.h, film.width_px, film.height_px
        )));
    }
    if s.spp == 0 {
        return Err(Error::invalid("spp must be ≥ 1"));
    }
    let nb = world.bands;
    let grid = &s.grid;
    if grid.len() != nb {
        return Err(Error::invalid(
            "settings grid differs from the world's grid",
        ));
    }
    let batches = s.batches.clamp(1, s.spp) as usize;
    let mut img = OpticalImage::new(
        film.width_px,
        film.height_px,
        roi,
        film.pixel_pitch_m,
        grid.clone(),
    );
    // The render writes every irradiance value once: huge pages spare it
    // the page faults of a fresh buffer (`frame_buffer`). Advised here, not
    // in `OpticalImage::new`: on every optical image, `camsim bench sensor`'s
    // 1.5 GB input on huge pages made its simulation slower (0.38 s against
    // 0.32 s; docs/performance.md, *Twenty-fifth pass*).
    crate::frame_buffer::advise(&img.irradiance);
    img.stderr = crate::frame_buffer::zeroed(img.irradiance.len());
    img.label_names = label_names;
    img.spp = s.spp;
    let dispersive_cam = camera.is_dispersive();
    let mid_nm = grid.wavelength(nb / 2);
    let rows_per_run = rows_per_run(roi, s.spp);
    // Pixels of one job, and their band values.
    let run_px = roi.w as usize * rows_per_run;
    let run_len = run_px * nb;

    // Standard errors of weighted band sums (e.g. a sensor channel's electron
    // rate), from the same batch means: bands of one path are correlated, so
    // these cannot be formed from the per-band errors afterwards.
    let wsets: Vec<&[f32]> = s
        .stderr_weights
        .iter()
        .map(|w| w.as_slice())
        .filter(|w| w.len() == nb)
        .collect();
    if wsets.len() != s.stderr_weights.len() {
        return Err(Error::invalid(format!(
            "stderr weights must have one value per band ({nb})"
        )));
    }
    let job = RunJob {
        world,
        camera,
        to_world,
        film,
        s,
        roi,
        batches,
        dispersive_cam,
        mid_nm,
        wsets: &wsets,
        packets: kernel.packets,
        in_flight: kernel.in_flight.max(1),
        rows_per_run,
        isa: if kernel.isa.supported() {
            kernel.isa
        } else {
            RenderIsa::Sse
        },
    };
    let work = |r: RunSlices| job.run_at(job.isa, r);

    let run = |img: &mut OpticalImage| -> Vec<(u64, Vec<f32>)> {
        img.irradiance
            .par_chunks_mut(run_len)
            .enumerate()
            .zip(img.stderr.par_chunks_mut(run_len))
            .zip(img.labels.par_chunks_mut(run_px))
            .zip(img.depth_m.par_chunks_mut(run_px))
            .map(work)
            .collect::<Vec<_>>()
    };
    let rows = if s.threads > 0 {
        let pool = rayon::ThreadPoolBuilder::new()
            .num_threads(s.threads)
            .build()
            .map_err(|e| Error::invalid(format!("thread pool: {e}")))?;
        pool.install(|| run(&mut img))
    } else {
        run(&mut img)
    };
    let nan = rows.iter().map(|r| r.0).sum();
    if !wsets.is_empty() && batches > 1 {
        img.weighted_stderr = rows.into_iter().flat_map(|r| r.1).collect();
    }
    img.nan_count = nan;
    img.render_s = start.elapsed().as_secs_f64();
    Ok(img)
}

/// Add a finished path's radiance `l` (`bands_padded` long), scaled by the
/// camera weight, to its batch total `acc` (as long); a path with a
/// non-finite band is dropped and counted (returns 1).
#[inline(always)]
fn accumulate(acc: &mut [f64], l: &[f32], weight: f64) -> u64 {
    u64::from(!bands::add_finite_f64(acc, l, weight))
}

/// Whether a run's samples are traced 16 paths at a time
/// (packet traversal of the rays of `packets_in_flight` packets regrouped by
/// `ray_stream`, Lambertian hits shaded in structure of arrays, lanes
/// refilled from the run's stream as paths end)
/// at instruction set `isa`, or one by one. Same image bits either way.
/// `CAMSIM_RENDER_PACKETS=1` / `=0` forces the choice (anything else is
/// ignored with a warning); by default packets at AVX2 and AVX-512, where
/// they measured faster on the bench's Cornell box (AVX-512 ≈ 35 %, AVX2
/// ≈ 21 % more paths/s), one by one at SSE, where the packet traversal is
/// slower (≈ 20 % fewer paths/s; docs/performance.md).
pub fn packets_enabled(isa: RenderIsa) -> bool {
    static P: std::sync::OnceLock<Option<bool>> = std::sync::OnceLock::new();
    let forced = *P.get_or_init(|| match std::env::var("CAMSIM_RENDER_PACKETS") {
        Err(_) => None,
        Ok(v) if v == "1" => Some(true),
        Ok(v) if v == "0" => Some(false),
        Ok(v) => {
            eprintln!("warning: CAMSIM_RENDER_PACKETS=\"{v}\" ignored (expected 0 or 1)");
            None
        }
    });
    forced.unwrap_or(isa >= RenderIsa::Avx2)
}

/// Packets of 16 paths a run of rows keeps in flight in packet mode
/// (`RunJob::run_packets`): 32 by default, or `CAMSIM_PACKETS_IN_FLIGHT`
/// (1 to 256; anything else is ignored with a warning). Their rays are
/// sorted by direction and origin before each cast (`ray_stream`): the more
/// packets, the more coherent the regrouped ones, against more path state
/// per thread (≈ 9 KB a packet). On the bench's Cornell box (2026-11-28,
/// AVX-512 EPYC, M paths/s, three rounds): 16 / 32 / 64 / 128 packets
/// 3.63–3.80 / 3.86–3.90 / 3.84–3.89 / 3.72–3.79, one packet as before
/// 3.74–3.80 (docs/performance.md).
pub fn packets_in_flight() -> usize {
    static P: std::sync::OnceLock<usize> = std::sync::OnceLock::new();
    *P.get_or_init(|| match std::env::var("CAMSIM_PACKETS_IN_FLIGHT") {
        Err(_) => DEFAULT_IN_FLIGHT,
        Ok(v) => match v.parse::<usize>() {
            Ok(n) if (1..=256).contains(&n) => n,
            _ => {
                eprintln!(
                    "warning: CAMSIM_PACKETS_IN_FLIGHT=\"{v}\" ignored (expected 1 to 256); using {DEFAULT_IN_FLIGHT}"
                );
                DEFAULT_IN_FLIGHT
            }
        },
    })
}

/// `packets_in_flight`'s default.
const DEFAULT_IN_FLIGHT: usize = 32;

/// What every run of rows (one job) of one render shares.
struct RunJob<'a> {
    world: &'a World,
    camera: &'a dyn Camera,
    to_world: &'a DMat4,
    film: &'a FilmSpec,
    s: &'a RenderSettings,
    roi: Rect,
    batches: usize,
    dispersive_cam: bool,
    mid_nm: f64,
    wsets: &'a [&'a [f32]],
    /// Trace a run's paths 16 at a time (`run_packets`).
    packets: bool,
    /// Packets in flight per run in packet mode.
    in_flight: usize,
    /// Rows of one job (`rows_per_run`).
    rows_per_run: usize,
    /// The kernel's instruction set where this CPU has it, else the
    /// baseline: the copy `run_at` runs, and what `shade_hits` may use
    /// beyond the compiler's vectors.
    isa: RenderIsa,
}

impl RunJob<'_> {
    /// Render one run of rows with the kernel compiled for `isa` (`simd.rs`).
    fn run_at(&self, isa: RenderIsa, r: RunSlices) -> (u64, Vec<f32>) {
        #[cfg(target_arch = "x86_64")]
        {
            match isa {
                // SAFETY: the CPU supports the features the copy is built for.
                RenderIsa::Avx512 if isa.supported() => return unsafe { self.run_avx512(r) },
                // SAFETY: as above.
                RenderIsa::Avx2 if isa.supported() => return unsafe { self.run_avx2(r) },
                _ => {}
            }
        }
        let _ = isa;
        self.run(r)
    }

    #[cfg(target_arch = "x86_64")]
    #[target_feature(enable = "avx2,fma,bmi1,bmi2,lzcnt,popcnt")]
    unsafe fn run_avx2(&self, r: RunSlices) -> (u64, Vec<f32>) {
        self.run(r)
    }

    #[cfg(target_arch = "x86_64")]
    #[target_feature(enable = "avx512f,avx512vl,avx512bw,avx512dq,avx2,fma,bmi1,bmi2,lzcnt,popcnt")]
    unsafe fn run_avx512(&self, r: RunSlices) -> (u64, Vec<f32>) {
        self.run(r)
    }

    /// Start sample `j` of batch `bi` of pixel (`px`, `py`): its sampler
    /// and its camera ray (`sample_draws`, `sample_path`). `None`: the
    /// camera vignettes it. The path's initial throughput is `init_beta`'s.
    #[inline(always)]
    fn start_sample(
        &self,
        px: u32,
        py: u32,
        pixel_key: u64,
        scrambles: &[BatchScramble],
        (bi, j): (u32, u32),
        smp: &mut Sampler,
    ) -> Option<(PathState, f64)> {
        let d = self.sample_draws(px, py, pixel_key, scrambles, (bi, j), smp);
        let ray = self.camera.sample_ray(d.film_m, d.u, d.lambda_nm);
        self.sample_path(ray, d.hero)
    }

    /// The camera's draws of sample `j` of batch `bi` of pixel (`px`,
    /// `py`), from its sampler, made in `smp` (point j of the batch's
    /// scrambled Sobol copies, so the batch's film positions are stratified
    /// over the pixel; sampler.rs): where on the film, where in the pupil,
    /// and at which wavelength its camera ray is drawn.
    #[inline(always)]
    fn sample_draws(
        &self,
        px: u32,
        py: u32,
        pixel_key: u64,
        scrambles: &[BatchScramble],
        (bi, j): (u32, u32),
        smp: &mut Sampler,
    ) -> CameraDraws {
        let (world, film, s) = (self.world, self.film, self.s);
        let nb = world.bands;
        let (fw, fh, pitch) = (
            film.width_px as f64,
            film.height_px as f64,
            film.pixel_pitch_m,
        );
        // Samples of batch `bi` are si = bi, bi + batches, … (the same
        // split and accumulation order as a plain round-robin loop).
        let si = bi as u64 + j as u64 * self.batches as u64;
        *smp = Sampler::for_sample(scrambles.get(bi as usize), pixel_key, j, si);
        let (fx, fy) = smp.get2d();
        let (ua, ub) = smp.get2d();
        let film_m = DVec2::new(
            (px as f64 + fx as f64 - fw / 2.0) * pitch,
            (fh / 2.0 - (py as f64 + fy as f64)) * pitch,
        );
        let (hero, lambda_nm) = if self.dispersive_cam {
            let b = ((smp.get1d() * nb as f32) as usize).min(nb - 1);
            (Some(b), s.grid.wavelength(b))
        } else {
            (None, self.mid_nm)
        };
        CameraDraws {
            film_m,
            u: DVec2::new(ua as f64, ub as f64),
            lambda_nm,
            hero,
        }
    }

    /// The path of a sample whose camera ray is `ray` (hero band `hero`),
    /// and the sample's weight; None: vignetted.
    #[inline(always)]
    fn sample_path(&self, ray: Option<CameraRay>, hero: Option<usize>) -> Option<(PathState, f64)> {
        let (o, d, weight) = world_ray(self.to_world, ray)?;
        Some((PathState::camera(o, d, hero), weight))
    }

    /// A new path's throughput: 1 in every band, or `nb` in its hero band
    /// alone (a dispersive camera's sample).
    #[inline(always)]
    fn init_beta(&self, hero: Option<usize>, beta: &mut [f32]) {
        let nb = self.world.bands;
        match hero {
            Some(b) => beta
                .iter_mut()
                .enumerate()
                .for_each(|(j, x)| *x = if j == b { nb as f32 } else { 0.0 }),
            // Padding bands (≥ nb) carry no throughput.
            None => bands::ones(beta, nb),
        }
    }

    /// Film pixel (px, py) of pixel `i` of the run whose first row is `y0`.
    #[inline(always)]
    fn pixel_xy(&self, y0: u32, i: usize) -> (u32, u32) {
        let w = self.roi.w as usize;
        (self.roi.x + (i % w) as u32, y0 + (i / w) as u32)
    }

    /// Label and depth of film pixel (`px`, `py`), pixel `ix` of the run,
    /// from the ray through the pixel centre, pupil centre, and the pixel's
    /// PCG32 key.
    #[inline(always)]
    fn pixel_start(
        &self,
        ix: usize,
        (px, py): (u32, u32),
        lab: &mut [u32],
        dep: &mut [f32],
    ) -> u64 {
        let (film, camera) = (self.film, self.camera);
        let pixel_id = py as u64 * film.width_px as u64 + px as u64;
        let fc = DVec2::new(
            (px as f64 + 0.5 - film.width_px as f64 / 2.0) * film.pixel_pitch_m,
            (film.height_px as f64 / 2.0 - (py as f64 + 0.5)) * film.pixel_pitch_m,
        );
        if let Some((o, d, _)) =
            camera_ray(camera, self.to_world, fc, DVec2::splat(0.5), self.mid_nm)
            && let Some(h) = first_hit(self.world, o, d)
        {
            lab[ix] = h.object;
            dep[ix] = h.t;
        }
        Rng::pixel_key(self.s.seed, pixel_id)
    }

    /// The scrambles of a pixel's batches (none for the independent sampler).
    #[inline(always)]
    fn pixel_scrambles(&self, pixel_key: u64, out: &mut Vec<BatchScramble>) {
        out.clear();
        if self.s.sampler == SamplerKind::Sobol {
            out.extend((0..self.batches).map(|bi| {
                BatchScramble::new(
                    pixel_key,
                    bi as u64,
                    batch_len(self.s.spp, self.batches, bi),
                )
            }));
        }
    }

    /// One run of image rows (`rows_per_run`; its pixels row after row):
    /// every sample of every pixel, then the pixel means and standard
    /// errors. Returns the non-finite sample count and the weighted standard
    /// errors.
    #[inline(always)]
    fn run(&self, ((((run, irr), se), lab), dep): RunSlices) -> (u64, Vec<f32>) {
        let (world, s, roi, batches) = (self.world, self.s, self.roi, self.batches);
        // Pixels of this run (its last may have fewer rows).
        let n_px = lab.len();
        let nb = world.bands;
        let nsets = self.wsets.len();
        let mut out = PixelOut {
            irr,
            se,
            wse: vec![0f32; if batches > 1 { n_px * nsets } else { 0 }],
            mean_px: vec![0.0f64; nb],
            ss_px: vec![0.0f64; nb],
            acc: vec![0.0f64; world.bands_padded * batches],
            counts: (0..batches)
                .map(|bi| batch_len(s.spp, batches, bi) as u32)
                .collect(),
            batch_w: vec![0.0f64; batches],
            nan: 0,
        };
        let y0 = roi.y + (run * self.rows_per_run) as u32;
        // (batch, index in batch) of the pixel's samples in accumulation order.
        let order: Vec<(u32, u32)> = (0..batches)
            .flat_map(|bi| (0..batch_len(s.spp, batches, bi)).map(move |j| (bi as u32, j as u32)))
            .collect();
        if self.packets {
            self.run_packets(y0, &order, lab, dep, &mut out);
        } else {
            let nbp = world.bands_padded;
            let mut sc = Scratch::new(nbp);
            let mut smp = Sampler::independent(Rng::for_sample(0, 0, 0));
            let mut scrambles: Vec<BatchScramble> = Vec::with_capacity(batches);
            for ix in 0..n_px {
                let (px, py) = self.pixel_xy(y0, ix);
                let pixel_key = self.pixel_start(ix, (px, py), lab, dep);
                self.pixel_scrambles(pixel_key, &mut scrambles);
                out.acc.fill(0.0);
                for &(bi, j) in &order {
                    if let Some((st, w)) =
                        self.start_sample(px, py, pixel_key, &scrambles, (bi, j), &mut smp)
                    {
                        self.init_beta(st.hero, &mut sc.beta);
                        trace(world, st.o, st.d, s.max_bounces, st.hero, &mut smp, &mut sc);
                        let a = &mut out.acc[bi as usize * nbp..(bi as usize + 1) * nbp];
                        out.nan += accumulate(a, &sc.l, w);
                    }
                }
                self.finish_pixel(ix, &mut out);
            }
        }
        (out.nan, out.wse)
    }

    /// The run's pixels traced 16 paths at a time, `in_flight` packets in
    /// flight, as one stream of samples: pixel by pixel, each pixel's samples
    /// in batch order, and a lane whose path ends takes the next sample of
    /// the stream at once, of the same pixel or of the next ones, so the
    /// packets stay full across pixel boundaries. Each bounce casts the rays
    /// of all packets together, regrouped by direction and origin
    /// (`ray_stream`), then shades each packet (`integrator::shade_hits`) and
    /// casts their shadow rays together. Each sample's radiance waits in its
    /// pixel's slot until all the pixel's samples are traced; then the
    /// samples are accumulated in order and the pixel finished: every pixel
    /// is bit for bit what tracing its samples one by one gives.
    #[inline(always)]
    fn run_packets(
        &self,
        y0: u32,
        order: &[(u32, u32)],
        lab: &mut [u32],
        dep: &mut [f32],
        out: &mut PixelOut<'_>,
    ) {
        let (world, s) = (self.world, self.s);
        let nbp = world.bands_padded;
        // No more packets than the run has samples to fill (both ≥ 1).
        let np = self
            .in_flight
            .min((lab.len() * order.len()).div_ceil(LANES));
        // Per packet its paths and lanes; its band buffers and rays in `scs`,
        // one slice for `ray_stream`.
        let mut pk: Vec<InFlight> = (0..np).map(|_| InFlight::new()).collect();
        let mut scs: Vec<PacketScratch> = (0..np)
            .map(|_| PacketScratch::new(world.bands_padded))
            .collect();
        let mut unblocked: Vec<LaneMask> = vec![0; np];
        let mut stream = RayStream::new(world, np);
        // The camera draws and rays of the samples being issued.
        let mut cam = CameraBatch::new(np);
        // Pixels in flight (slots reused through `free`).
        let mut slots: Vec<PixelSlot> = Vec::new();
        let mut free: Vec<usize> = Vec::new();
        // The pixel whose samples are being issued, and its slot.
        let mut next_ix = 0usize;
        let mut issuing: Option<usize> = None;
        let mut clock = Clock::start();
        loop {
            // Every idle lane takes the run's next sample that the camera
            // lets through, packet after packet and lane after lane, as
            // when samples are issued one at a time (a vignetted sample
            // leaves its lane to the next one). So that the camera can work
            // on many rays side by side (`Camera::sample_rays`), as many
            // samples as there are idle lanes are drawn first, their camera
            // rays made together, and the ones that pass handed out in
            // order; vignetted ones leave lanes idle for another round.
            // The camera stage's parts (`clock` times the whole).
            let mut sub = Clock::start();
            loop {
                let want: usize = pk
                    .iter()
                    .map(|p| (!p.alive & ALL_LANES).count_ones() as usize)
                    .sum();
                if want == 0 {
                    break;
                }
                // The next `want` samples of the run: (slot, sample) and draws.
                cam.who.clear();
                while cam.who.len() < want {
                    let k = match issuing {
                        Some(k) => k,
                        None if next_ix < lab.len() => {
                            let k = free.pop().unwrap_or_else(|| {
                                slots.push(PixelSlot::default());
                                slots.len() - 1
                            });
                            let xy = self.pixel_xy(y0, next_ix);
                            let pixel_key = self.pixel_start(next_ix, xy, lab, dep);
                            let slot = &mut slots[k];
                            slot.ix = next_ix;
                            slot.xy = xy;
                            slot.pixel_key = pixel_key;
                            self.pixel_scrambles(pixel_key, &mut slot.scrambles);
                            slot.next = 0;
                            slot.tracing = 0;
                            slot.weights.clear();
                            slot.weights.resize(order.len(), None);
                            slot.radiance.resize(order.len() * nbp, 0.0);
                            next_ix += 1;
                            issuing = Some(k);
                            k
                        }
                        None => break,
                    };
                    // A pixel is visited once a round: drawn to its end, or
                    // the round's last (its next sample is `slot.next`).
                    let slot = &slots[k];
                    let m = (want - cam.who.len()).min(order.len() - slot.next);
                    let (px, py) = slot.xy;
                    for (n, &bj) in order.iter().enumerate().skip(slot.next).take(m) {
                        let j = cam.who.len();
                        let d = self.sample_draws(
                            px,
                            py,
                            slot.pixel_key,
                            &slot.scrambles,
                            bj,
                            &mut cam.smps[j],
                        );
                        (cam.film_m[j], cam.u[j], cam.lambda_nm[j]) = (d.film_m, d.u, d.lambda_nm);
                        cam.hero[j] = d.hero;
                        cam.who.push((k, n));
                    }
                    if slot.next + m == order.len() {
                        issuing = None;
                    }
                }
                let drawn = cam.who.len();
                sub.lap(Stage::CameraDraws);
                if drawn == 0 {
                    break;
                }
                self.camera.sample_rays(
                    &cam.film_m[..drawn],
                    &cam.u[..drawn],
                    &cam.lambda_nm[..drawn],
                    &mut cam.rays[..drawn],
                );
                sub.lap(Stage::CameraRays);
                // Hand the samples that pass to the idle lanes in order.
                let mut pi = 0;
                for j in 0..drawn {
                    let (k, n) = cam.who[j];
                    let slot = &mut slots[k];
                    slot.next = n + 1;
                    if let Some((st, w)) = self.sample_path(cam.rays[j], cam.hero[j]) {
                        while pk[pi].alive & ALL_LANES == ALL_LANES {
                            pi += 1;
                        }
                        let (p, sc) = (&mut pk[pi], &mut scs[pi]);
                        let lane = (!p.alive & ALL_LANES).trailing_zeros() as usize;
                        p.smps[lane].clone_from(&cam.smps[j]);
                        self.init_beta(st.hero, sc.beta_mut(lane));
                        p.paths[lane] = st;
                        slot.weights[n] = Some(w);
                        slot.tracing += 1;
                        p.slot[lane] = k;
                        p.sample[lane] = n;
                        sc.clear_radiance(lane);
                        p.alive |= 1 << lane;
                    }
                    if slot.next == order.len() {
                        self.finish_if_traced(slot, k, order, out, &mut free);
                    }
                }
                sub.lap(Stage::CameraHandOut);
            }
            clock.lap(Stage::Camera);
            if pk.iter().all(|p| p.alive == 0) {
                break;
            }
            for (p, sc) in pk.iter().zip(scs.iter_mut()) {
                packet_rays(self.isa, &p.paths, p.alive, sc);
            }
            clock.lap(Stage::PacketRays);
            stream.intersect(self.isa, world, &mut scs);
            clock.lap(Stage::ClosestHits);
            for (p, sc) in pk.iter_mut().zip(scs.iter_mut()) {
                p.ended = shade_hits(
                    world,
                    self.isa,
                    &mut p.paths,
                    p.alive,
                    s.max_bounces,
                    &mut p.smps,
                    sc,
                );
            }
            clock.lap(Stage::Shade);
            stream.unoccluded(self.isa, world, &scs, &mut unblocked);
            clock.lap(Stage::ShadowRays);
            let mut sub = Clock::start();
            for ((p, sc), &free_lanes) in pk.iter_mut().zip(scs.iter_mut()).zip(&unblocked) {
                add_unblocked(free_lanes, sc);
                sub.lap(Stage::EndUnblocked);
                for lane in lanes(p.ended) {
                    let (k, n) = (p.slot[lane], p.sample[lane]);
                    let slot = &mut slots[k];
                    bands::copy(
                        &mut slot.radiance[n * nbp..(n + 1) * nbp],
                        sc.radiance(lane),
                    );
                    slot.tracing -= 1;
                    self.finish_if_traced(slot, k, order, out, &mut free);
                }
                p.alive &= !p.ended;
                sub.lap(Stage::EndPaths);
            }
            clock.lap(Stage::BounceEnd);
        }
    }

    /// Once every sample of the pixel in slot `k` is issued and traced,
    /// finish the pixel and put the slot on the `free` list.
    #[inline(always)]
    fn finish_if_traced(
        &self,
        slot: &PixelSlot,
        k: usize,
        order: &[(u32, u32)],
        out: &mut PixelOut<'_>,
        free: &mut Vec<usize>,
    ) {
        if slot.tracing == 0 && slot.next == order.len() {
            self.finish_slot(slot, order, out);
            free.push(k);
        }
    }

    /// Accumulate a traced pixel's samples in order and finish it.
    #[inline(always)]
    fn finish_slot(&self, slot: &PixelSlot, order: &[(u32, u32)], out: &mut PixelOut<'_>) {
        let nbp = self.world.bands_padded;
        out.acc.fill(0.0);
        for (k, &(bi, _)) in order.iter().enumerate() {
            if let Some(w) = slot.weights[k] {
                let a = &mut out.acc[bi as usize * nbp..(bi as usize + 1) * nbp];
                out.nan += accumulate(a, &slot.radiance[k * nbp..(k + 1) * nbp], w);
            }
        }
        self.finish_pixel(slot.ix, out);
    }

    /// Mean and standard error of pixel `ix` from its batch totals
    /// `out.acc`. Totals add the batches in order 0, 1, … for every band.
    #[inline(always)]
    fn finish_pixel(&self, ix: usize, out: &mut PixelOut<'_>) {
        let (nb, nbp) = (self.world.bands, self.world.bands_padded);
        let batches = self.batches;
        let nsets = self.wsets.len();
        let PixelOut {
            irr,
            se,
            wse,
            mean_px,
            ss_px,
            acc,
            counts,
            batch_w,
            ..
        } = out;
        let n = self.s.spp as f64;
        let irr_px = &mut irr[ix * nb..(ix + 1) * nb];
        mean_px.fill(0.0);
        for a in acc.chunks_exact(nbp) {
            for (t, &x) in mean_px.iter_mut().zip(a) {
                *t += x;
            }
        }
        for (m, o) in mean_px.iter_mut().zip(irr_px.iter_mut()) {
            *m /= n;
            *o = *m as f32;
        }
        if batches > 1 {
            ss_px.fill(0.0);
            for (a, &c) in acc.chunks_exact(nbp).zip(counts.iter()) {
                let c = c.max(1) as f64;
                for ((q, &x), &mean) in ss_px.iter_mut().zip(a).zip(mean_px.iter()) {
                    let m = x / c;
                    *q += (m - mean) * (m - mean);
                }
            }
            let denom = batches as f64 * (batches as f64 - 1.0);
            for (o, &q) in se[ix * nb..(ix + 1) * nb].iter_mut().zip(ss_px.iter()) {
                *o = (q / denom).sqrt() as f32;
            }
            for (k, w) in self.wsets.iter().enumerate() {
                let mw: f64 = w
                    .iter()
                    .zip(mean_px.iter())
                    .map(|(&a, &m)| a as f64 * m)
                    .sum();
                // Each batch's weighted mean, summed over the bands in order
                // from −0.0 as `Iterator::sum` does, the batches side by side
                // (independent sums the core overlaps; same bits).
                batch_w.fill(-0.0);
                for (j, &wb) in w.iter().enumerate() {
                    for ((m, a), &c) in batch_w.iter_mut().zip(acc.chunks_exact(nbp)).zip(&*counts)
                    {
                        *m += wb as f64 * a[j] / c.max(1) as f64;
                    }
                }
                let mut q = 0.0f64;
                for &m in batch_w.iter() {
                    q += (m - mw) * (m - mw);
                }
                wse[ix * nsets + k] = (q / denom).sqrt() as f32;
            }
        }
    }
}

/// Rows a render job takes (one `RunJob::run` call): enough for about
/// `PATHS_PER_RUN` paths, so that the packet kernel's pipeline of paths in flight
/// fills and drains once per run instead of once per row, and its buffers
/// are set up once; at most a sixteenth of the region's rows, so that the
/// threads still share the work evenly. Each pixel's samples and their
/// accumulation are the same whatever the run: same bits.
fn rows_per_run(roi: Rect, spp: u32) -> usize {
    let per_row = roi.w as usize * spp as usize;
    PATHS_PER_RUN
        .div_ceil(per_row.max(1))
        .min(roi.h as usize / 16)
        .max(1)
}

/// `rows_per_run`'s target paths per job.
const PATHS_PER_RUN: usize = 1 << 15;

/// Samples in batch `bi` of a pixel's `spp` split into `batches`: batch
/// `bi` holds samples bi, bi + batches, …
#[inline(always)]
fn batch_len(spp: u32, batches: usize, bi: usize) -> usize {
    (spp as usize - bi).div_ceil(batches)
}

/// A run's outputs and the per-pixel buffers that fill them.
struct PixelOut<'a> {
    irr: &'a mut [f32],
    se: &'a mut [f32],
    /// Weighted standard errors, `wsets` per pixel.
    wse: Vec<f32>,
    mean_px: Vec<f64>,
    ss_px: Vec<f64>,
    /// The pixel's batch totals, batch-major, `bands_padded` per batch.
    acc: Vec<f64>,
    /// Samples per batch (vignetted ones included).
    counts: Vec<u32>,
    /// Per batch: the pixel's weighted mean (one weight set at a time).
    batch_w: Vec<f64>,
    /// Non-finite samples dropped.
    nan: u64,
}

/// One packet of paths in flight in `run_packets`: per lane its path, its
/// sampler, and the pixel slot and sample it traces.
struct InFlight {
    paths: [PathState; LANES],
    smps: Vec<Sampler>,
    slot: [usize; LANES],
    sample: [usize; LANES],
    /// Lanes tracing a path, and those whose path ended this bounce.
    alive: LaneMask,
    ended: LaneMask,
}

impl InFlight {
    fn new() -> Self {
        InFlight {
            paths: [PathState::camera(Vec3::ZERO, Vec3::Z, None); LANES],
            smps: (0..LANES)
                .map(|_| Sampler::independent(Rng::for_sample(0, 0, 0)))
                .collect(),
            slot: [0; LANES],
            sample: [0; LANES],
            alive: 0,
            ended: 0,
        }
    }
}

/// What the camera needs to draw one sample's ray (`RunJob::sample_draws`),
/// and the sample's hero band.
struct CameraDraws {
    film_m: DVec2,
    u: DVec2,
    lambda_nm: f64,
    hero: Option<usize>,
}

/// The samples `run_packets` issues together: their samplers, their
/// `CameraDraws` in columns (as `Camera::sample_rays` takes them) and their
/// camera rays.
struct CameraBatch {
    /// Per sample: its pixel's slot and its number in the pixel.
    who: Vec<(usize, usize)>,
    smps: Vec<Sampler>,
    film_m: Vec<DVec2>,
    u: Vec<DVec2>,
    lambda_nm: Vec<f64>,
    hero: Vec<Option<usize>>,
    rays: Vec<Option<CameraRay>>,
}

impl CameraBatch {
    /// Room for one sample per lane of `packets` packets.
    fn new(packets: usize) -> Self {
        let n = packets * LANES;
        CameraBatch {
            who: Vec::with_capacity(n),
            smps: (0..n)
                .map(|_| Sampler::independent(Rng::for_sample(0, 0, 0)))
                .collect(),
            film_m: vec![DVec2::ZERO; n],
            u: vec![DVec2::ZERO; n],
            lambda_nm: vec![0.0; n],
            hero: vec![None; n],
            rays: vec![None; n],
        }
    }
}

/// A pixel in flight in `run_packets`.
#[derive(Default)]
struct PixelSlot {
    /// Index in the run.
    ix: usize,
    /// Its film pixel (px, py).
    xy: (u32, u32),
    pixel_key: u64,
    scrambles: Vec<BatchScramble>,
    /// The next of its samples to issue (index into the order).
    next: usize,
    /// Its samples being traced now.
    tracing: u32,
    /// Each sample's camera weight (`None`: vignetted, or not yet issued).
    weights: Vec<Option<f64>>,
    /// Each traced sample's radiance, `bands_padded` per sample.
    radiance: Vec<f32>,
}

#[cfg(test)]
mod tests {
    use super::*;
    use crate::optics::pinhole::Pinhole;
    use crate::render::BvhKind;
    use crate::render::bench::mitsuba_cornell_box;

    /// `unit` against normalising: a unit direction turned by a rigid
    /// camera-to-world matrix is kept as it is, and its f32 ray (what the
    /// path tracer gets) is the normalised direction's within one f32 ulp
    /// per component; anything else (scaled, sheared, zero, NaN) is
    /// normalised exactly as `normalize_or_zero` does.
    #[test]
    fn camera_directions_already_unit_are_kept() {
        let mut rng = crate::render::sampling::Rng::for_sample(5, 0, 0);
        let (mut kept, mut same_bits) = (0usize, 0usize);
        let n = 20_000;
        for _ in 0..n {
            let mut g = || rng.uniform() as f64 * 2.0 - 1.0;
            let axis = DVec3::new(g(), g(), g()).normalize();
            let m = DMat4::from_translation(DVec3::new(g(), g(), g()))
                * DMat4::from_axis_angle(axis, 3.0 * g());
            let d = DVec3::new(0.3 * g(), 0.3 * g(), 1.0).normalize();
            let w = m.transform_vector3(d);
            let u = unit(w);
            let want = w.normalize_or_zero();
            if u == w {
                kept += 1;
            }
            let (a, b) = (u.as_vec3(), want.as_vec3());
            for k in 0..3 {
                let ulps = (a[k].to_bits() as i64 - b[k].to_bits() as i64).abs();
                assert!(ulps <= 1, "{w}: {a} against {b}");
            }
            same_bits += usize::from(a == b);
            // Not unit: normalised as before, bit for bit.
            for s in [2.0, 0.5, 1.0 + 1e-12, 1.0 - 1e-12] {
                let v = w * s;
                assert_eq!(unit(v), v.normalize_or_zero(), "{v}");
            }
            let shear = DMat4::from_cols_array(&[
                1.0, 0.0, 0.0, 0.0, 0.3, 1.0, 0.0, 0.0, 0.0, 0.0, 1.0, 0.0, 0.0, 0.0, 0.0, 1.0,
            ]);
            let v = (shear * m).transform_vector3(d);
            assert_eq!(unit(v), v.normalize_or_zero());
        }
        assert!(kept > n * 9 / 10, "{kept} of {n} kept");
        assert!(
            same_bits > n * 99 / 100,
            "{same_bits} of {n} with the same f32 bits"
        );
        assert_eq!(unit(DVec3::ZERO), DVec3::ZERO);
        assert_eq!(unit(DVec3::new(f64::NAN, 0.0, 1.0)), DVec3::ZERO);
        assert_eq!(unit(DVec3::new(f64::INFINITY, 0.0, 1.0)), DVec3::ZERO);
    }

    /// Every instruction set level this machine has, with paths traced one by
    /// one or 16 at a time, renders the same image bit for bit (irradiance,
    /// standard errors, labels, depth): the levels do the same IEEE
    /// operations in the same order (`simd.rs`), and a path in a packet the
    /// same operations as alone (`integrator::shade_hits`), in any packet of
    /// any number in flight (`ray_stream`). The Cornell box
    /// exercises diffuse and area-light paths, roulette and MIS; 40 spp in 3
    /// batches (14, 13, 13 samples) fill the 16 lanes, refill each lane as its
    /// path ends (from the next pixel too), and leave lanes empty at the
    /// run's end.
    #[test]
    fn every_isa_level_renders_the_same_bits() {
        let (scene, film) = mitsuba_cornell_box();
        every_level_renders(&scene, &film);
    }

    /// The same with a light of every other kind beside the box's area
    /// light (point, spot, distant and infinite, the last two reaching in
    /// through the box's open front): the packets' Lambertian hits sample
    /// them lane by lane (`shade_packet`), and must give the bits `scatter`
    /// gives one path at a time.
    #[test]
    fn every_isa_level_renders_the_same_bits_under_every_light_kind() {
        use crate::scene::Light;
        use crate::spectrum::Spectrum;
        let (mut scene, film) = mitsuba_cornell_box();
        let plain = every_level_renders(&scene, &film);
        scene.lights.extend([
            Light::Point {
                position: DVec3::new(0.3, 0.6, 0.2),
                intensity: Spectrum::constant("point", 1.0),
            },
            Light::Spot {
                position: DVec3::new(-0.5, 0.8, 0.0),
                direction: DVec3::new(0.1, -1.0, -0.2),
                cone_angle_deg: 40.0,
                falloff_start_deg: 25.0,
                intensity: Spectrum::constant("spot", 2.0),
            },
            Light::Distant {
                direction: DVec3::new(0.2, -0.3, -1.0).normalize(),
                irradiance: Spectrum::constant("distant", 0.5),
            },
            Light::Infinite {
                radiance: Spectrum::constant("sky", 0.1),
            },
        ]);
        let lit = every_level_renders(&scene, &film);
        // The extra lights reach the window's pixels.
        let total = |v: &[f32]| v.iter().map(|&x| x as f64).sum::<f64>();
        assert!(total(&lit.irradiance) > 1.2 * total(&plain.irradiance));
    }

    /// The same on meshes with vertex normals: bent differently at each
    /// vertex, so the shading normal is interpolated; on one wall turned
    /// against the face (the shading normal is flipped to the geometric
    /// side) and on another all zero (the geometric normal is used), as
    /// `scatter` takes them.
    #[test]
    fn every_isa_level_renders_the_same_bits_with_vertex_normals() {
        let (mut scene, film) = mitsuba_cornell_box();
        let plain = every_level_renders(&scene, &film);
        let bends = [
            Vec3::new(0.3, 0.0, 0.1),
            Vec3::new(-0.2, 0.25, 0.0),
            Vec3::new(0.0, -0.15, 0.3),
        ];
        for (k, m) in scene.meshes.iter_mut().enumerate() {
            if m.emission.is_some() {
                continue;
            }
            let mut normals = vec![Vec3::ZERO; m.positions.len()];
            for t in &m.indices {
                let p = t.map(|i| m.positions[i as usize]);
                let face = (p[1] - p[0]).cross(p[2] - p[0]).normalize();
                for (j, &i) in t.iter().enumerate() {
                    normals[i as usize] = match k % 3 {
                        0 => (face + bends[j]).normalize(),
                        1 => -(face + bends[j]).normalize(),
                        _ => Vec3::ZERO,
                    };
                }
            }
            m.normals = Some(normals);
        }
        let bent = every_level_renders(&scene, &film);
        assert!(
            plain.irradiance != bent.irradiance,
            "the vertex normals change the image"
        );
    }

    /// The same with glossy surfaces beside Lambertian ones, so that a
    /// packet mixes lanes shaded together (`shade_packet`) with lanes shaded
    /// one by one (`scatter`): the red and white walls Lambertian with a
    /// glossy lobe (the paper's walls), the green one a rough conductor,
    /// every other mesh with bent vertex normals, under the area light and a
    /// point light.
    #[test]
    fn every_isa_level_renders_the_same_bits_with_glossy_surfaces() {
        use crate::scene::{Light, Material};
        use crate::spectrum::Spectrum;
        let (mut scene, film) = mitsuba_cornell_box();
        let plain = every_level_renders(&scene, &film);
        for nm in &mut scene.materials {
            let glossy = match nm.name.as_str() {
                "red" | "white" => {
                    let Material::Diffuse { reflectance } = &nm.material else {
                        continue;
                    };
                    Material::DiffuseSpecular {
                        diffuse: reflectance.clone(),
                        specular: reflectance.clone().scaled(0.5),
                        roughness: 0.2,
                    }
                }
                "green" => Material::Conductor {
                    eta: Spectrum::constant("eta", 0.2),
                    k: Spectrum::constant("k", 3.0),
                    roughness: 0.3,
                },
                _ => continue,
            };
            nm.material = glossy;
        }
        let bend = Vec3::new(0.2, 0.1, -0.1);
        for (k, m) in scene.meshes.iter_mut().enumerate() {
            if k % 2 == 0 && m.emission.is_none() {
                let n: Vec<Vec3> = (0..m.positions.len())
                    .map(|j| {
                        let t = &m.indices[0];
                        let p = t.map(|i| m.positions[i as usize]);
                        let face = (p[1] - p[0]).cross(p[2] - p[0]).normalize();
                        (face + bend * j as f32).normalize()
                    })
                    .collect();
                m.normals = Some(n);
            }
        }
        scene.lights.push(Light::Point {
            position: DVec3::new(0.3, 0.6, 0.2),
            intensity: Spectrum::constant("point", 1.0),
        });
        let glossy = every_level_renders(&scene, &film);
        assert!(
            plain.irradiance != glossy.irradiance,
            "the glossy surfaces change the image"
        );
    }

    /// Render `scene`'s window (96, 16)–(128, 48) at every instruction set
    /// level, one path at a time and in packets, assert the images' bits are
    /// the same, and return the first.
    fn every_level_renders(scene: &crate::scene::Scene, film: &FilmSpec) -> OpticalImage {
        let cam = Pinhole::new(39.3077, 1.0, film).unwrap();
        every_level_renders_with(scene, film, &cam)
    }

    /// A pinhole that says it is dispersive: every sample carries one band
    /// (a hero band), as behind a real lens with dispersion.
    struct HeroPinhole(Pinhole);
    impl Camera for HeroPinhole {
        fn sample_ray(&self, f: DVec2, u: DVec2, l: f64) -> Option<CameraRay> {
            self.0.sample_ray(f, u, l)
        }
        fn is_dispersive(&self) -> bool {
            true
        }
        fn describe(&self) -> String {
            "hero-band test pinhole".into()
        }
    }

    /// The same with one band per sample (a dispersive camera): its path's
    /// throughput is one-hot and Russian roulette divides its largest band
    /// by the band count.
    #[test]
    fn every_isa_level_renders_the_same_bits_with_hero_bands() {
        let (scene, film) = mitsuba_cornell_box();
        let cam = HeroPinhole(Pinhole::new(39.3077, 1.0, &film).unwrap());
        every_level_renders_with(&scene, &film, &cam);
    }

    fn every_level_renders_with(
        scene: &crate::scene::Scene,
        film: &FilmSpec,
        cam: &dyn Camera,
    ) -> OpticalImage {
        let to_world = scene.camera.as_ref().map(|c| c.to_world).unwrap();
        let s = RenderSettings {
            spp: 40,
            batches: 3,
            threads: 2,
            roi: Some(Rect::new(96, 16, 32, 32)),
            ..Default::default()
        };
        let world = World::build(scene, &s.grid, BvhKind::Bvh4).unwrap();
        let levels: Vec<Kernel> = RenderIsa::ALL
            .into_iter()
            .filter(|l| l.supported())
            .flat_map(|isa| {
                [(false, 1), (true, 1), (true, DEFAULT_IN_FLIGHT)].map(|(packets, in_flight)| {
                    Kernel {
                        isa,
                        packets,
                        in_flight,
                    }
                })
            })
            .collect();
        let mut imgs: Vec<OpticalImage> = levels
            .iter()
            .map(|&l| render_world_at(l, &world, cam, &to_world, film, &s, vec![]).unwrap())
            .collect();
        let bits = |v: &[f32]| v.iter().map(|x| x.to_bits()).collect::<Vec<_>>();
        assert!(imgs[0].irradiance.iter().any(|&x| x > 0.0));
        for (l, img) in levels.iter().zip(&imgs).skip(1) {
            assert!(
                bits(&img.irradiance) == bits(&imgs[0].irradiance),
                "{l:?} irradiance"
            );
            assert!(bits(&img.stderr) == bits(&imgs[0].stderr), "{l:?} stderr");
            assert_eq!(img.labels, imgs[0].labels, "{l:?}");
            assert!(bits(&img.depth_m) == bits(&imgs[0].depth_m), "{l:?} depth");
        }
        imgs.swap_remove(0)
    }

    /// A job renders a run of rows (`rows_per_run`): a pixel's bits must not
    /// depend on which run it falls in. A 32-row region goes in runs of two
    /// rows; the same pixels rendered as four 8-row regions go one row at a
    /// time, the runs starting on other rows.
    #[test]
    fn pixels_do_not_depend_on_the_run_of_rows() {
        assert_eq!(rows_per_run(Rect::new(0, 0, 256, 256), 32), 4);
        assert_eq!(rows_per_run(Rect::new(0, 0, 32, 32), 40), 2);
        assert_eq!(rows_per_run(Rect::new(0, 0, 32, 8), 40), 1);
        assert_eq!(rows_per_run(Rect::new(0, 0, 4000, 3000), 64), 1);
        let (scene, film) = mitsuba_cornell_box();
        let cam = Pinhole::new(39.3077, 1.0, &film).unwrap();
        let to_world = scene.camera.as_ref().map(|c| c.to_world).unwrap();
        let region = Rect::new(100, 20, 32, 32);
        let s = RenderSettings {
            spp: 40,
            batches: 3,
            threads: 2,
            roi: Some(region),
            ..Default::default()
        };
        let world = World::build(&scene, &s.grid, BvhKind::Bvh4).unwrap();
        let whole = render_world(&world, &cam, &to_world, &film, &s, vec![]).unwrap();
        let nb = world.bands;
        for k in 0..4 {
            let part_roi = Rect::new(region.x, region.y + 8 * k, region.w, 8);
            let sk = RenderSettings {
                roi: Some(part_roi),
                ..s.clone()
            };
            let part = render_world(&world, &cam, &to_world, &film, &sk, vec![]).unwrap();
            let off = (8 * k * region.w) as usize;
            let n = part.labels.len();
            let bits = |v: &[f32]| v.iter().map(|x| x.to_bits()).collect::<Vec<_>>();
            assert!(
                bits(&part.irradiance) == bits(&whole.irradiance[off * nb..(off + n) * nb]),
                "rows {}..{}",
                8 * k,
                8 * k + 8
            );
            assert!(bits(&part.stderr) == bits(&whole.stderr[off * nb..(off + n) * nb]));
            assert_eq!(part.labels, whole.labels[off..off + n]);
        }
    }

    /// Packets refill a lane with the pixel's next sample as a path ends,
    /// skipping samples the camera vignettes: through the Pixel 4a RTF on a
    /// film wider than its field, some pixels lose part of their samples,
    /// and both path modes must still give the same bits.
    #[test]
    fn packets_refill_around_vignetted_samples() {
        let (scene, _) = mitsuba_cornell_box();
        let dir = std::path::Path::new(env!("CARGO_MANIFEST_DIR"));
        let lens = crate::optics::analysis::load_lens(
            &dir.join("lenses/rtf/pixel4a-rearcamera-ellipse-raytransfer.json"),
        )
        .unwrap();
        let cam = match crate::optics::analysis::lens_camera(lens, Some(0.465136), None, 550.0)
            .unwrap()
        {
            crate::optics::analysis::LensCamera::Rtf(c) => c,
            _ => unreachable!("an RTF file"),
        };
        let film = FilmSpec {
            width_px: 24,
            height_px: 24,
            pixel_pitch_m: 300e-6,
            crop_window: None,
        };
        let to_world = scene.camera.as_ref().map(|c| c.to_world).unwrap();
        let s = RenderSettings {
            spp: 40,
            batches: 2,
            threads: 2,
            ..Default::default()
        };
        let world = World::build(&scene, &s.grid, BvhKind::Bvh4).unwrap();
        let isa = RenderIsa::detect();
        let render = |packets, in_flight| {
            render_world_at(
                Kernel {
                    isa,
                    packets,
                    in_flight,
                },
                &world,
                &cam,
                &to_world,
                &film,
                &s,
                vec![],
            )
            .unwrap()
        };
        let (one, packed, streamed) = (
            render(false, 1),
            render(true, 1),
            render(true, DEFAULT_IN_FLIGHT),
        );
        let nb = world.bands;
        let lit = |img: &OpticalImage| {
            img.irradiance
                .chunks(nb)
                .filter(|p| p.iter().any(|&x| x > 0.0))
                .count()
        };
        // Some pixels see the box, some lie outside the lens's field.
        let n = lit(&one);
        assert!(n > 0 && n < 24 * 24, "{n} lit pixels");
        let bits = |v: &[f32]| v.iter().map(|x| x.to_bits()).collect::<Vec<_>>();
        for img in [&packed, &streamed] {
            assert!(bits(&one.irradiance) == bits(&img.irradiance));
            assert!(bits(&one.stderr) == bits(&img.stderr));
        }
    }
}
