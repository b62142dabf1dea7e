//! The sensor pipeline: optical image → digital values, in the order of the
//! paper-era ISETCam model (`sensorCompute` / `sensorComputeImage`):
//!
//! 1. spectral irradiance E(λ) [W/(m²·nm)] → photons/s → mean electrons/s per pixel:
//!    Σ_λ E(λ)·λ/(hc)·QE_c(λ)·Δλ · pixel area · fill factor, with QE_c = channel QE × IR
//!    filter (× correction matrix). Bands are bins of width `step_nm` (ISETCam's sum ×
//!    bin width, not a trapezoid). When the optical image and the sensor have different
//!    pixel grids, each sensor pixel integrates the (piecewise constant) irradiance over
//!    its area; both grids are centred on the optical axis;
//! 2. × relative illumination map (pixel/microlens vignetting) × exposure time;
//! 3. + dark current (dark voltage × time / conversion gain, electrons);
//! 4. photon (shot) noise: exact Poisson of signal + dark electrons;
//! 5. PRNU: × (1 + σ_PRNU·N), a fixed per-pixel field (clamped at 0);
//! 6. clip the charge at full well = min(well capacity, swing / conversion gain);
//! 7. → volts (conversion gain); + DSNU (fixed per-pixel offset field);
//!    column FPN (fixed per-column gain and offset); + read noise; + reset (kTC) noise;
//! 8. × analog gain, → DV with step swing/2^bits, + black level, round, clip to [0, 2^bits − 1].
//!
//! Decision where ISETCam differs: ISETCam clips the voltage to [0, swing] before
//! adding the analog offset, which rectifies the read noise in darkness. Here the
//! charge saturates at the well (6) and the ADC clips the final DV (8), so dark
//! frames keep symmetric noise around the black level, as real raw data does and as
//! EMVA 1288 analysis needs.
//!
//! Randomness is counter-based per full-frame pixel (see [`super::rng`]), so frames
//! are bit-identical for any thread count, and a window of the frame reproduces the
//! same pixels as the full frame. Fixed-pattern fields depend only on
//! `SensorConfig::fpn_seed`; temporal noise on the frame seed.

use super::config::{Exposure, RelativeIllumination, SensorConfig};
use super::prefetch::Prefetch;
use super::readout::{Isa, Readout, RowOut, Scratch};
pub use super::readout::{fpn_column, fpn_pixel};
use crate::diag::{Error, Result};
use crate::frame_buffer;
use crate::image::SensorImage;
use crate::optical_image::{OpticalImage, Rect};
use crate::spectrum::{Spectrum, WavelengthGrid, units};
use rayon::prelude::*;

/// A simulated frame with the intermediate quantities kept for analysis.
#[derive(Clone, Debug)]
pub struct SensorFrame {
    /// Digital values and collected electrons (after shot noise, PRNU and well clipping).
    pub image: SensorImage,
    /// Analog voltage per pixel after all electronic noise, before analog gain and ADC.
    pub volts: Vec<f32>,
    /// Noise-free expected electrons per pixel (signal × relative illumination + dark).
    pub mean_electrons: Vec<f32>,
}

impl SensorFrame {
    /// Hand the frame's buffers back for the next frame of a sequence
    /// ([`frame_buffer::for_overwrite`]).
    pub fn recycle(self) {
        self.image.recycle();
        frame_buffer::recycle(self.volts);
        frame_buffer::recycle(self.mean_electrons);
    }
}

/// Electrons per second per unit irradiance, per channel and band:
/// `w[c][b]` = k·QE_c(λ_b)·λ_b/(hc)·Δλ·A_pixel·FF, in e⁻/s per W/(m²·nm), with
/// k the declared illuminance calibration factor (`illuminance-scale-factor`).
#[allow(clippy::needless_range_loop)]
pub fn channel_weights(cfg: &SensorConfig, grid: &WavelengthGrid) -> Vec<Vec<f64>> {
    let nch = cfg.cfa.channels.len();
    let area = cfg.effective_pixel_area_m2();
    let mut w = vec![vec![0.0; grid.len()]; nch];
    for b in 0..grid.len() {
        let l = grid.wavelength(b);
        let qe = cfg.effective_qe(l);
        let k = cfg.illuminance_scale * grid.step_nm * area / units::photon_energy_j(l);
        for c in 0..nch {
            w[c][b] = qe[c] * k;
        }
    }
    w
}

/// Full sensor size (cols, rows): from the config, or the optical image's field of view.
pub fn sensor_size(cfg: &SensorConfig, oi_full: (u32, u32), oi_pitch_m: f64) -> (u32, u32) {
    let s = oi_pitch_m / cfg.pixel_size_m;
    let cols = cfg
        .cols
        .unwrap_or(((oi_full.0 as f64 * s).round() as u32).max(1));
    let rows = cfg
        .rows
        .unwrap_or(((oi_full.1 as f64 * s).round() as u32).max(1));
    (cols, rows)
}

/// Area weights of optical-image columns (local index, weight summing to 1) for each
/// sensor column of an axis, and the covered sensor range.
struct AxisMap {
    start: u32,
    /// Per sensor pixel along the axis: (OI local index, weight).
    weights: Vec<Vec<(u32, f64)>>,
    /// OI local index under each sensor pixel centre.
    centre: Vec<u32>,
}

fn axis_map(n_sensor: u32, oi_full: u32, oi_win0: u32, oi_win_len: u32, s: f64) -> AxisMap {
    // u(j) = (j − n_sensor/2)·s + oi_full/2 in OI pixel units.
    let u = |j: f64| (j - n_sensor as f64 / 2.0) * s + oi_full as f64 / 2.0;
    let jf = |uu: f64| (uu - oi_full as f64 / 2.0) / s + n_sensor as f64 / 2.0;
    let lo = (jf(oi_win0 as f64) - 1e-9).ceil().max(0.0) as u32;
    let hi = ((jf((oi_win0 + oi_win_len) as f64) + 1e-9).floor().max(0.0) as u32).min(n_sensor);
    let mut weights = vec![];
    let mut centre = vec![];
    for j in lo..hi.max(lo) {
        let u0 = u(j as f64);
        let u1 = u0 + s;
        let mut v = vec![];
        let i0 = u0.floor().max(oi_win0 as f64) as u32;
        let i1 = (u1.ceil() as u32).min(oi_win0 + oi_win_len);
        for i in i0..i1 {
            let ov = (u1.min(i as f64 + 1.0) - u0.max(i as f64)) / s;
            if ov > 1e-12 {
                v.push((i - oi_win0, ov));
            }
        }
        // Renormalise the exact-identity case against round-off.
        let sum: f64 = v.iter().map(|x| x.1).sum();
        if (sum - 1.0).abs() < 1e-9 {
            for x in &mut v {
                x.1 /= sum;
            }
        }
        let c = ((u0 + 0.5 * s).floor().max(oi_win0 as f64) as u32).min(oi_win0 + oi_win_len - 1)
            - oi_win0;
        centre.push(c);
        weights.push(v);
    }
    AxisMap {
        start: lo,
        weights,
        centre,
    }
}

fn check_config(cfg: &SensorConfig) -> Result<()> {
    cfg.validate()
        .map_err(|m| Error::invalid(format!("sensor '{}': {m}", cfg.name)))
}

/// Relative-illumination factor of full-frame pixel (x, y) of a sensor of
/// `full` (cols, rows) pixels (1 when the sensor has none or it is switched off).
pub fn relative_illumination_at(cfg: &SensorConfig, full: (u32, u32), x: u32, y: u32) -> f64 {
    ri_at(cfg, full, x, y)
}

/// Relative-illumination factor of full-frame pixel (x, y).
fn ri_at(cfg: &SensorConfig, full: (u32, u32), x: u32, y: u32) -> f64 {
    if !ri_active(cfg) {
        return 1.0;
    }
    let dx = (x as f64 + 0.5 - full.0 as f64 / 2.0) * cfg.pixel_size_m;
    let dy = (y as f64 + 0.5 - full.1 as f64 / 2.0) * cfg.pixel_size_m;
    cfg.relative_illumination
        .at((dx * dx + dy * dy).sqrt() * 1e3)
}

/// Simulate one frame; keeps DV and electrons. See the module docs for the model.
pub fn simulate(cfg: &SensorConfig, oi: &OpticalImage, seed: u64) -> Result<SensorImage> {
    Ok(run(cfg, oi, seed, false)?.image)
}

/// Simulate one frame and keep volts and the noise-free mean electrons too.
pub fn simulate_frame(cfg: &SensorConfig, oi: &OpticalImage, seed: u64) -> Result<SensorFrame> {
    run(cfg, oi, seed, true)
}

fn run(cfg: &SensorConfig, oi: &OpticalImage, seed: u64, keep: bool) -> Result<SensorFrame> {
    check_config(cfg)?;
    if !(oi.pixel_pitch_m.is_finite() && oi.pixel_pitch_m > 0.0) {
        return Err(Error::invalid(format!(
            "optical image pixel pitch must be > 0 m, found {}",
            oi.pixel_pitch_m
        )));
    }
    let nb = oi.bands();
    if oi.irradiance.len() != oi.window.area() as usize * nb {
        return Err(Error::invalid(
            "optical image irradiance has the wrong length for its window and bands",
        ));
    }
    let full = sensor_size(cfg, (oi.full_width, oi.full_height), oi.pixel_pitch_m);
    let s = cfg.pixel_size_m / oi.pixel_pitch_m;
    let xm = axis_map(full.0, oi.full_width, oi.window.x, oi.window.w, s);
    let ym = axis_map(full.1, oi.full_height, oi.window.y, oi.window.h, s);
    if xm.weights.is_empty() || ym.weights.is_empty() {
        return Err(Error::invalid(format!(
            "the optical image window {:?} covers no whole pixel of the {}×{} sensor",
            oi.window, full.0, full.1
        )));
    }
    let window = Rect::new(
        xm.start,
        ym.start,
        xm.weights.len() as u32,
        ym.weights.len() as u32,
    );
    let w = channel_weights(cfg, &oi.grid);
    let oiw = oi.window.w as usize;
    let irr = &oi.irradiance;
    let identity = xm
        .weights
        .iter()
        .chain(&ym.weights)
        .all(|v| v.len() == 1 && v[0].1 == 1.0)
        && xm.weights.windows(2).all(|p| p[1][0].0 == p[0][0].0 + 1);
    // Signal rate (mean electrons per second, relative illumination included) of
    // one window row; `true` when the row's irradiance is invalid, and the
    // optical image the next row reads (the readout brings it into cache).
    let bad_anywhere;
    let rate_row: Box<RateRow> = if identity {
        // Same grid: one OI pixel per sensor pixel; f32 dot products over the bands,
        // with a finiteness/sign check folded in (sum must be finite, min ≥ 0).
        bad_anywhere = false;
        let wf: Vec<Vec<f32>> = w
            .iter()
            .map(|wc| wc.iter().map(|&v| v as f32).collect())
            .collect();
        let x0 = xm.weights[0][0].0 as usize;
        let phases = channel_rows(cfg, window);
        let use_ri = ri_active(cfg);
        let ym = &ym;
        let isa = Isa::detect();
        Box::new(move |r, row| {
            let yf = window.y + r as u32;
            let oy = ym.weights[r][0].0 as usize;
            let chans = &phases[(yf % cfg.cfa.height) as usize];
            let base = (oy * oiw + x0) * nb;
            let len = row.len() * nb;
            let bad = dot_row(isa, &wf, chans, &irr[base..][..len], nb, row);
            if use_ri {
                for (cix, out) in row.iter_mut().enumerate() {
                    *out = (*out as f64 * ri_at(cfg, full, window.x + cix as u32, yf)) as f32;
                }
            }
            let next = match ym.weights.get(r + 1) {
                Some(w) => Prefetch::of(&irr[(w[0].0 as usize * oiw + x0) * nb..][..len]),
                None => Prefetch::none(),
            };
            (bad, next)
        })
    } else {
        bad_anywhere = irr
            .par_chunks(1 << 16)
            .any(|c| c.iter().any(|v| !(*v >= 0.0 && v.is_finite())));
        let (xm, ym, w) = (&xm, &ym, &w);
        Box::new(move |r, row| {
            let yf = window.y + r as u32;
            for (cix, out) in row.iter_mut().enumerate() {
                let xf = window.x + cix as u32;
                let wc = &w[cfg.cfa.channel_at(xf, yf)];
                let mut acc = 0.0f64;
                for &(iy, wy) in &ym.weights[r] {
                    for &(ix, wx) in &xm.weights[cix] {
                        let p = &irr[(iy as usize * oiw + ix as usize) * nb..][..nb];
                        let mut d = 0.0f64;
                        for b in 0..nb {
                            d += wc[b] * p[b] as f64;
                        }
                        acc += wy * wx * d;
                    }
                }
                *out = (acc * ri_at(cfg, full, xf, yf)) as f32;
            }
            (false, Prefetch::none())
        })
    };
    const BAD_IRRADIANCE: &str = "optical image irradiance has negative or non-finite values";
    if bad_anywhere {
        return Err(Error::invalid(BAD_IRRADIANCE));
    }
    let (mut f, bad) = expose(cfg, full, window, &*rate_row, seed, keep)?;
    if bad {
        return Err(Error::invalid(BAD_IRRADIANCE));
    }
    let labels = if identity
        && window.w == oi.window.w
        && window.h == oi.window.h
        && oi.labels.len() == oi.window.area() as usize
    {
        oi.labels.clone()
    } else if oi.labels.len() == oi.window.area() as usize {
        let mut l = Vec::with_capacity(window.area() as usize);
        for r in 0..window.h as usize {
            for c in 0..window.w as usize {
                l.push(oi.labels[ym.centre[r] as usize * oiw + xm.centre[c] as usize]);
            }
        }
        l
    } else {
        vec![]
    };
    f.image.labels = labels;
    f.image.label_names = oi.label_names.clone();
    Ok(f)
}

/// One window row's signal rates on the same grid: `out[c]` = the weights of
/// column c's channel (`chans[c]`) · its spectrum (`irr`, `nb` bands per
/// pixel), and true when a spectrum is invalid ([`dot_check`]). Runs with the
/// kernel compiled for `isa`, as the readout does (`readout::Isa`): the same
/// IEEE operations in the same order at every level, so the same bits.
fn dot_row(
    isa: Isa,
    w: &[Vec<f32>],
    chans: &[u8],
    irr: &[f32],
    nb: usize,
    out: &mut [f32],
) -> bool {
    #[cfg(target_arch = "x86_64")]
    match isa {
        // SAFETY: `isa` was detected on this CPU (Isa::detect).
        Isa::Avx512 => unsafe { dot_row_avx512(w, chans, irr, nb, out) },
        // SAFETY: as above.
        Isa::Avx2 => unsafe { dot_row_avx2(w, chans, irr, nb, out) },
        Isa::Baseline => dot_row_generic(w, chans, irr, nb, out),
    }
    #[cfg(not(target_arch = "x86_64"))]
    {
        let _ = isa;
        dot_row_generic(w, chans, irr, nb, out)
    }
}

#[cfg(target_arch = "x86_64")]
#[target_feature(enable = "avx512f,avx512dq,avx512vl,avx512bw,avx2,fma,bmi2")]
fn dot_row_avx512(w: &[Vec<f32>], chans: &[u8], irr: &[f32], nb: usize, out: &mut [f32]) -> bool {
    // Whole blocks of 16 pixels reduced together (16–32 bands).
    let blocks = dot16::dot_blocks_avx512(w, chans, irr, nb, out);
    dot_row_after_blocks(blocks, w, chans, irr, nb, out)
}

#[cfg(target_arch = "x86_64")]
#[target_feature(enable = "avx2,fma,bmi2")]
fn dot_row_avx2(w: &[Vec<f32>], chans: &[u8], irr: &[f32], nb: usize, out: &mut [f32]) -> bool {
    // Whole blocks of 8 pixels reduced together (16–32 bands).
    let blocks = dot16::dot_blocks_avx2(w, chans, irr, nb, out);
    dot_row_after_blocks(blocks, w, chans, irr, nb, out)
}

/// The pixels a block kernel left (`blocks`: the pixels it did, and whether one
/// of them was invalid) as at every level: the same bits. Inlined into each
/// level's row function, so compiled for its instruction set.
#[inline(always)]
fn dot_row_after_blocks(
    (done, bad): (usize, bool),
    w: &[Vec<f32>],
    chans: &[u8],
    irr: &[f32],
    nb: usize,
    out: &mut [f32],
) -> bool {
    let rest = dot_row_generic(w, &chans[done..], &irr[done * nb..], nb, &mut out[done..]);
    bad | rest
}

#[inline(always)]
fn dot_row_generic(w: &[Vec<f32>], chans: &[u8], irr: &[f32], nb: usize, out: &mut [f32]) -> bool {
    let mut bad = false;
    for ((o, &ch), p) in out.iter_mut().zip(chans).zip(irr.chunks_exact(nb)) {
        let (d, ok) = dot_check(&w[ch as usize], p);
        bad |= !ok;
        *o = d;
    }
    bad
}

/// Dot product of weights and one pixel's spectrum, and whether the spectrum is
/// valid (finite sum, no negative value).
///
/// Sixteen f32 lanes: lane i adds bands i, i + 16, …; the bands after the last
/// whole block of 16 are read as the spectrum's last 16 with the lanes already
/// counted set to 0, and the lanes are then added as a binary tree (8, 4, 2, 1).
/// Every step stays in vector registers (one 16-lane register with AVX-512,
/// two with AVX2, four with SSE) and each level does the same IEEE operations
/// in the same order, so the same bits (`readout::Isa`). Before, eight lanes
/// summed one after another plus a scalar remainder took ≈ 3× as long per
/// pixel: with 31 bands the per-pixel dependency chain, not memory, set the
/// speed of `camsim bench sensor`'s first pass. Under 16 bands: one pass in
/// order.
#[inline(always)]
fn dot_check(w: &[f32], p: &[f32]) -> (f32, bool) {
    const L: usize = 16;
    let n = p.len();
    let w = &w[..n];
    if n < L {
        let (mut d, mut s, mut neg) = (0f32, 0f32, false);
        for (a, b) in w.iter().zip(p) {
            d += a * b;
            s += b;
            neg |= *b < 0.0;
        }
        return (d, s.is_finite() && !neg);
    }
    let mut acc = [0f32; L];
    let mut sum = [0f32; L];
    let mut neg = [false; L];
    let whole = n / L * L;
    for (a, b) in w[..whole].chunks_exact(L).zip(p[..whole].chunks_exact(L)) {
        for i in 0..L {
            acc[i] += a[i] * b[i];
            sum[i] += b[i];
            neg[i] |= b[i] < 0.0;
        }
    }
    let r = n - whole;
    if r > 0 {
        let (a, b) = (&w[n - L..], &p[n - L..]);
        for i in 0..L {
            let new = i >= L - r;
            let x = if new { b[i] } else { 0.0 };
            let y = if new { a[i] } else { 0.0 };
            acc[i] += y * x;
            sum[i] += x;
            neg[i] |= x < 0.0;
        }
    }
    (
        lane_tree_sum(acc),
        lane_tree_sum(sum).is_finite() && !neg.iter().any(|&x| x),
    )
}

/// The sum of 16 lanes as a binary tree: lanes i and i + 8, then i and i + 4, …
#[inline(always)]
fn lane_tree_sum(mut v: [f32; 16]) -> f32 {
    let mut half = 8;
    while half > 0 {
        for i in 0..half {
            v[i] += v[i + half];
        }
        half /= 2;
    }
    v[0]
}

/// Channel index per window column, for each CFA row phase.
fn channel_rows(cfg: &SensorConfig, window: Rect) -> Vec<Vec<u8>> {
    (0..cfg.cfa.height)
        .map(|py| {
            (0..window.w)
                .map(|c| cfg.cfa.channel_at(window.x + c, py) as u8)
                .collect()
        })
        .collect()
}

fn ri_active(cfg: &SensorConfig) -> bool {
    cfg.sources.pixel_vignetting && cfg.relative_illumination != RelativeIllumination::None
}

/// Simulate a uniform field (integrating sphere): every pixel sees the spectral
/// irradiance `irradiance_w_m2_nm` (sampled on `grid`), over `window` of the full
/// sensor (config rows × cols, required). Same model as [`simulate_frame`].
pub fn simulate_flat(
    cfg: &SensorConfig,
    irradiance_w_m2_nm: &Spectrum,
    grid: &WavelengthGrid,
    window: Rect,
    seed: u64,
) -> Result<SensorFrame> {
    check_config(cfg)?;
    let (Some(cols), Some(rows)) = (cfg.cols, cfg.rows) else {
        return Err(Error::invalid(format!(
            "sensor '{}' needs rows and cols for a flat field",
            cfg.name
        )));
    };
    if window.w == 0 || window.h == 0 || window.x + window.w > cols || window.y + window.h > rows {
        return Err(Error::invalid(format!(
            "window {window:?} is not inside the {cols}×{rows} sensor"
        )));
    }
    let e = irradiance_w_m2_nm.resample(grid).map_err(Error::invalid)?;
    if e.iter().any(|v| !v.is_finite() || *v < 0.0) {
        return Err(Error::invalid(
            "flat-field irradiance has negative or non-finite values",
        ));
    }
    let w = channel_weights(cfg, grid);
    let per_ch: Vec<f64> = w
        .iter()
        .map(|wc| wc.iter().zip(&e).map(|(a, b)| a * b).sum())
        .collect();
    let full = (cols, rows);
    let rate_row = |r: usize, row: &mut [f32]| {
        let yf = window.y + r as u32;
        for (c, out) in row.iter_mut().enumerate() {
            let xf = window.x + c as u32;
            *out = (per_ch[cfg.cfa.channel_at(xf, yf)] * ri_at(cfg, full, xf, yf)) as f32;
        }
        (false, Prefetch::none())
    };
    Ok(expose(cfg, full, window, &rate_row, seed, true)?.0)
}

/// Mean signal electrons per second per CFA channel for a uniform irradiance (on axis).
pub fn flat_rate_e_per_s(
    cfg: &SensorConfig,
    irradiance_w_m2_nm: &Spectrum,
    grid: &WavelengthGrid,
) -> Vec<f64> {
    channel_weights(cfg, grid)
        .iter()
        .map(|wc| {
            (0..grid.len())
                .map(|b| wc[b] * irradiance_w_m2_nm.eval(grid.wavelength(b)))
                .sum()
        })
        .collect()
}

/// The `p`-th percentile (0 < p ≤ 100) of `v` by nearest rank: the value
/// at rank ⌈p/100 · n⌉ of the sorted values (p = 100 is the maximum).
/// Non-finite values are ignored; an empty input gives 0.
fn percentile_nearest_rank(v: &[f32], p: f64) -> f64 {
    let mut x: Vec<f32> = v.iter().copied().filter(|a| a.is_finite()).collect();
    if x.is_empty() {
        return 0.0;
    }
    let n = x.len();
    let rank = ((p / 100.0 * n as f64).ceil() as usize).clamp(1, n);
    let (_, kth, _) = x.select_nth_unstable_by(rank - 1, f32::total_cmp);
    *kth as f64
}

/// The exposure time the config asks for, given the pass-1 signal rates.
pub fn resolve_exposure_s(cfg: &SensorConfig, rate_e_per_s: &[f32]) -> Result<f64> {
    match cfg.exposure {
        Exposure::Seconds(t) => Ok(t),
        Exposure::Auto { level, percentile } => {
            let max = percentile_nearest_rank(rate_e_per_s, percentile);
            if max <= 0.0 {
                return Err(Error::invalid(
                    "auto-exposure: the optical image is black (no signal to expose for)",
                ));
            }
            Ok(level * cfg.full_well_e() / max)
        }
    }
}

/// The signal rate of one window row (index, output row); `true` when the row's
/// irradiance is invalid.
type RateRow<'a> = dyn Fn(usize, &mut [f32]) -> (bool, Prefetch<'a>) + Sync + 'a;

/// Expose `window` of a `full` sensor whose signal rate rows come from `rate_row`
/// (which reports invalid irradiance), and read it out. With a fixed exposure time
/// each row is read out as soon as its rate is known, so the signal is never held
/// as a frame; auto exposure needs every rate first (a percentile), then reads out.
/// Returns the frame and whether any rate row reported invalid irradiance.
fn expose(
    cfg: &SensorConfig,
    full: (u32, u32),
    window: Rect,
    rate_row: &RateRow,
    seed: u64,
    keep: bool,
) -> Result<(SensorFrame, bool)> {
    let n = window.area() as usize;
    let ww = window.w as usize;
    let fixed = match cfg.exposure {
        Exposure::Seconds(t) if t.is_finite() && t >= 0.0 => Some(t),
        _ => None,
    };
    let (rate, t) = match fixed {
        Some(t) => (None, t),
        None => {
            let mut rate = vec![0f32; n];
            let bad = rate
                .par_chunks_mut(ww)
                .enumerate()
                .map(|(r, row)| rate_row(r, row).0)
                .reduce(|| false, |a, b| a || b);
            if bad {
                return Ok((empty_frame(cfg, full, window), true));
            }
            let t = resolve_exposure_s(cfg, &rate)?;
            if !(t.is_finite() && t >= 0.0) {
                return Err(Error::invalid(format!(
                    "exposure time must be finite and ≥ 0 s, found {t}"
                )));
            }
            (Some(rate), t)
        }
    };
    let ro = Readout::new(cfg, full, window, t, seed);
    // Every row below writes every element of its rows of these (a frame made
    // from buffers full of NaN has none: `every_output_element_is_written`).
    let kept = || {
        if keep {
            frame_buffer::for_overwrite(n)
        } else {
            vec![]
        }
    };
    let mut dv = frame_buffer::for_overwrite(n);
    let mut electrons = frame_buffer::for_overwrite(n);
    let mut volts = kept();
    let mut mean = kept();
    // Every output row with its index; volts and mean rows only when kept.
    fn opt_rows(v: &mut [f32], ww: usize, rows: u32) -> Vec<Option<&mut [f32]>> {
        if v.is_empty() {
            (0..rows).map(|_| None).collect()
        } else {
            v.chunks_mut(ww).map(Some).collect()
        }
    }
    let vrows = opt_rows(&mut volts, ww, window.h);
    let mrows = opt_rows(&mut mean, ww, window.h);
    let bad = dv
        .par_chunks_mut(ww)
        .zip(electrons.par_chunks_mut(ww))
        .zip(vrows.into_par_iter())
        .zip(mrows.into_par_iter())
        .enumerate()
        .map_init(
            || (Scratch::default(), vec![0f32; ww]),
            |(scratch, m), (r, (((d, e), v), mr))| {
                let m: &mut [f32] = match mr {
                    Some(mr) => mr,
                    None => m,
                };
                let (bad, next_input) = match &rate {
                    Some(rate) => {
                        m.copy_from_slice(&rate[r * ww..(r + 1) * ww]);
                        (false, Prefetch::none())
                    }
                    None => rate_row(r, m),
                };
                for x in m.iter_mut() {
                    *x = ro.mean_electrons(*x);
                }
                let out = RowOut {
                    dv: d,
                    electrons: e,
                    volts: v,
                };
                ro.row(r, m, out, scratch, next_input);
                bad
            },
        )
        .reduce(|| false, |a, b| a || b);
    let image = SensorImage {
        dv,
        electrons,
        exposure_s: t,
        ..empty_frame(cfg, full, window).image
    };
    Ok((
        SensorFrame {
            image,
            volts,
            mean_electrons: mean,
        },
        bad,
    ))
}

fn empty_frame(cfg: &SensorConfig, full: (u32, u32), window: Rect) -> SensorFrame {
    SensorFrame {
        image: SensorImage {
            full_width: full.0,
            full_height: full.1,
            window,
            pixel_pitch_m: cfg.pixel_size_m,
            cfa: cfg.cfa.clone(),
            dv: vec![],
            electrons: vec![],
            black_level_dv: cfg.black_level_dv,
            white_level_dv: cfg.white_level_dv(),
            conversion_gain_dv_per_e: cfg.conversion_gain_dv_per_e(),
            labels: vec![],
            label_names: vec![],
            exposure_s: 0.0,
        },
        volts: vec![],
        mean_electrons: vec![],
    }
}

mod dot16;
#[cfg(test)]
mod tests;
