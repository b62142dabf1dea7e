//! The readout of one sensor row: mean electrons → collected charge → volts → DV
//! (steps 3–8 of the pipeline in [`super::pipeline`]): photon shot noise, PRNU, well
//! clipping, conversion gain, DSNU, column FPN, read and reset noise, analog gain,
//! black level, quantisation and ADC clipping.
//!
//! Every pixel draws from its own counter-based streams (photon, fixed pattern,
//! read), so rows are independent and a row's values do not depend on which thread
//! computes it or in what order. Within a row the work is split into passes over
//! the row (photon counts, fixed-pattern gains and offsets, read-noise normals, then
//! the arithmetic that combines them), each a short loop whose iterations do not
//! depend on one another, instead of one long per-pixel chain: the CPU overlaps many
//! pixels, and the Poisson draws whose first PTRS proposal is rejected (an
//! unpredictable branch: 1 − 0.86·v_r of them, 65 % at μ = 10, 33 % at 100, 24 % at
//! 1000, 22 % at 6000) are finished in separate loops: gathered, then side by
//! side by [`ptrs_after_rejected_all`] (PTRS's full test without libm, exact to the
//! bit, then the next proposal; two rounds, from the first pass's proposals), the
//! few it leaves by the exact path. Each pixel sees
//! exactly the operations, in the same order, of a pixel-by-pixel evaluation, so
//! the split changes no value.

use super::config::SensorConfig;
use super::prefetch::Prefetch;
#[cfg(target_arch = "x86_64")]
use super::rng::RoundInsn;
use super::rng::{
    FirstNormals, PixelRng, Proposal, RejectedDraws, RoundBits, Rounding, ZIG_N, first_normals,
    ln_factorial_table, ptrs_after_rejected_all, stream, ziggurat_x,
};
#[cfg(target_arch = "x86_64")]
use super::rng::{first_normals_avx2, first_normals_avx512};
use crate::optical_image::Rect;

/// PRNU gain and DSNU offset (volts) of full-frame pixel index `gi`, as drawn
/// (before switches): (1 + σ_PRNU·n₁, σ_DSNU·n₂).
#[inline]
pub fn fpn_pixel(cfg: &SensorConfig, gi: u64) -> (f64, f64) {
    fpn_pixel_keyed(
        cfg.prnu,
        cfg.dsnu_v,
        PixelRng::stream_key(cfg.fpn_seed, stream::FPN_PIXEL),
        gi,
    )
}

#[inline(always)]
fn fpn_pixel_keyed(prnu: f64, dsnu_v: f64, key: u64, gi: u64) -> (f64, f64) {
    let mut r = PixelRng::keyed(key, gi);
    let n1 = r.normal();
    let n2 = r.normal();
    ((1.0 + prnu * n1).max(0.0), dsnu_v * n2)
}

/// Column FPN gain and offset (volts) of full-frame column `x`.
#[inline]
pub fn fpn_column(cfg: &SensorConfig, x: u32) -> (f64, f64) {
    let mut r = PixelRng::new(cfg.fpn_seed, stream::FPN_COLUMN, x as u64);
    let n1 = r.normal();
    let n2 = r.normal();
    (1.0 + cfg.column_fpn_gain * n1, cfg.column_fpn_offset_v * n2)
}

/// The readout model of one frame: everything but the per-row mean electrons,
/// resolved once (exposure, switches, stream keys, column FPN of the window).
pub struct Readout {
    photon_noise: bool,
    clipping: bool,
    quantization: bool,
    use_prnu: bool,
    use_dsnu: bool,
    use_read: bool,
    use_reset: bool,
    use_col: bool,
    prnu: f64,
    dsnu_v: f64,
    read_noise_v: f64,
    reset_noise_v: f64,
    /// Exposure time, seconds, and dark electrons over it.
    pub t: f64,
    dark_e: f64,
    cg: f64,
    full_well: f64,
    dv_per_v: f64,
    white: f64,
    black: f64,
    /// Column FPN (gain, offset volts) per window column.
    cols: Vec<(f64, f64)>,
    k_photon: u64,
    k_read: u64,
    k_fpn: u64,
    full_w: u64,
    window: Rect,
    isa: Isa,
}

/// The instruction set the row kernel is compiled for, chosen at run time: the same
/// code, in which the compiler vectorises the first passes across pixels (8 lanes
/// of u64/f64 with AVX-512, 4 with AVX2), except the first two normals of each
/// pixel's streams, which have a hand-written kernel per level
/// ([`first_normals_avx512`], [`first_normals_avx2`]). Every lane does the scalar code's IEEE
/// operations (no fused multiply-add: Rust never contracts), so every level gives
/// the same bits.
#[derive(Clone, Copy, Debug, PartialEq, Eq)]
pub enum Isa {
    Baseline,
    Avx2,
    Avx512,
}

impl Isa {
    /// The widest level this CPU supports (`CAMSIM_SENSOR_ISA=baseline|avx2|avx512`
    /// lowers it, to compare levels).
    pub fn detect() -> Self {
        #[cfg(target_arch = "x86_64")]
        {
            let has = |f: &str| match f {
                "avx512" => {
                    std::arch::is_x86_feature_detected!("avx512f")
                        && std::arch::is_x86_feature_detected!("avx512dq")
                        && std::arch::is_x86_feature_detected!("avx512vl")
                        && std::arch::is_x86_feature_detected!("avx512bw")
                        && std::arch::is_x86_feature_detected!("avx2")
                        && std::arch::is_x86_feature_detected!("fma")
                        && std::arch::is_x86_feature_detected!("bmi2")
                }
                _ => {
                    std::arch::is_x86_feature_detected!("avx2")
                        && std::arch::is_x86_feature_detected!("fma")
                        && std::arch::is_x86_feature_detected!("bmi2")
                }
            };
            let cap = std::env::var("CAMSIM_SENSOR_ISA").unwrap_or_default();
            if !Self::cap_is_known(&cap) {
                static WARNED: std::sync::Once = std::sync::Once::new();
                WARNED.call_once(|| {
                    eprintln!(
                        "warning: CAMSIM_SENSOR_ISA=\"{cap}\" ignored (expected baseline, avx2 or avx512)"
                    )
                });
            }
            Self::level(&cap, has("avx512"), has("avx2"))
        }
        #[cfg(not(target_arch = "x86_64"))]
        Isa::Baseline
    }

    /// Whether `cap` is a value `CAMSIM_SENSOR_ISA` accepts ("" is no cap).
    fn cap_is_known(cap: &str) -> bool {
        ["", "baseline", "avx2", "avx512"].contains(&cap)
    }

    /// The widest level at most `cap` (an unknown cap is none) on a CPU that
    /// has the AVX-512 and AVX2 feature sets or not.
    fn level(cap: &str, avx512: bool, avx2: bool) -> Self {
        if cap != "baseline" && cap != "avx2" && avx512 {
            return Isa::Avx512;
        }
        if cap != "baseline" && avx2 {
            return Isa::Avx2;
        }
        Isa::Baseline
    }

    pub fn name(self) -> &'static str {
        match self {
            Isa::Baseline => "baseline",
            Isa::Avx2 => "avx2+fma",
            Isa::Avx512 => "avx512f",
        }
    }
}

/// Which scratch rows [`Readout::first_normals`] fills.
#[derive(Clone, Copy)]
enum NormalRows {
    /// `gain` and `offset` (the fixed pattern's two normals).
    Fpn,
    /// `n1` and `n2` (read and reset noise).
    Read,
}

/// Per-thread scratch rows of a [`Readout`].
#[derive(Default)]
pub struct Scratch {
    e: Vec<f64>,
    gain: Vec<f64>,
    offset: Vec<f64>,
    n1: Vec<f64>,
    n2: Vec<f64>,
    /// Volts.
    v: Vec<f64>,
    /// Per pixel: the vectorised first pass was enough.
    ok: Vec<bool>,
    /// Per pixel: the first and second normal of a stream took the ziggurat's
    /// common case ([`first_normals`]).
    ok_a: Vec<bool>,
    ok_b: Vec<bool>,
    /// Per pixel: its first PTRS proposal, a row per field but `k` (in `e`),
    /// which the vectorised first pass writes whole registers of.
    first_start: Vec<u64>,
    first_b: Vec<f64>,
    first_us: Vec<f64>,
    first_v: Vec<f64>,
    /// The pixels whose first PTRS proposal failed the fast test (`at`: column
    /// indices) and what `ptrs_after_rejected_all` made of them.
    slow: SlowRound,
    /// Those of them whose second proposal's full test comes next (`at`:
    /// indices into `slow`).
    slow2: SlowRound,
}

/// The PTRS proposals of one round of [`Readout::finish_slow_photons`]: where
/// each came from, its mean and proposal, and its draw
/// ([`ptrs_after_rejected_all`]).
#[derive(Default)]
struct SlowRound {
    at: Vec<u32>,
    mu: Vec<f64>,
    prop: Vec<Proposal>,
    k: Vec<f64>,
    done: Vec<bool>,
    next: Vec<Proposal>,
    pending: Vec<bool>,
}

impl SlowRound {
    /// The draws of `prop` (with means `mu`), each followed by the proposal from
    /// outputs `n_next` and `n_next + 1` of its stream.
    #[inline(always)]
    fn draw<R: Rounding>(&mut self, n_next: u64) {
        let n = self.prop.len();
        self.k.resize(n, 0.0);
        self.done.resize(n, false);
        self.next.resize(n, Proposal::default());
        self.pending.resize(n, false);
        let out = RejectedDraws {
            k: &mut self.k,
            done: &mut self.done,
            next: &mut self.next,
            pending: &mut self.pending,
        };
        ptrs_after_rejected_all::<R>(ln_factorial_table(), &self.prop, &self.mu, n_next, out);
    }
}

impl Scratch {
    /// Rows of `n` pixels. Rows of the length already held are not cleared:
    /// every pass of [`Readout::row`] writes a row in full before any pass reads
    /// it (clearing them was ≈ 3 % of `camsim bench sensor`, docs/performance.md),
    /// so no value of one image row reaches the next (the row tests start from
    /// poisoned rows).
    fn fit(&mut self, n: usize) {
        fn fit_to<T: Copy + Default>(v: &mut Vec<T>, n: usize) {
            if v.len() != n {
                v.clear();
                v.resize(n, T::default());
            }
        }
        for v in [
            &mut self.e,
            &mut self.gain,
            &mut self.offset,
            &mut self.n1,
            &mut self.n2,
            &mut self.v,
        ] {
            fit_to(v, n);
        }
        for v in [&mut self.ok, &mut self.ok_a, &mut self.ok_b] {
            fit_to(v, n);
        }
        fit_to(&mut self.first_start, n);
        for v in [&mut self.first_b, &mut self.first_us, &mut self.first_v] {
            fit_to(v, n);
        }
    }
}

/// `f(c)` for every `c` with `flags[c]` false, in order. Eight flags are read
/// as one word and skipped together when all are true (a pixel's fast path
/// fails for ≈ 1–2 % of pixels, so most words are skipped with one
/// well-predicted branch; a test per pixel mispredicted often enough to show in
/// perf).
#[inline(always)]
fn for_each_false(flags: &[bool], mut f: impl FnMut(usize)) {
    const ONES: u64 = 0x0101_0101_0101_0101;
    let words = flags.chunks_exact(8);
    let rest = words.remainder();
    for (w, chunk) in words.enumerate() {
        // bool is one byte, 0 or 1: the word has 1 in byte j where flags[8w + j].
        let word = u64::from_le_bytes(std::array::from_fn(|j| u8::from(chunk[j])));
        let mut missing = !word & ONES;
        while missing != 0 {
            f(8 * w + missing.trailing_zeros() as usize / 8);
            missing &= missing - 1;
        }
    }
    let base = flags.len() - rest.len();
    for (j, &ok) in rest.iter().enumerate() {
        if !ok {
            f(base + j);
        }
    }
}

/// One row's outputs: DV, collected electrons and (optionally) volts.
pub struct RowOut<'a> {
    pub dv: &'a mut [f32],
    pub electrons: &'a mut [f32],
    pub volts: Option<&'a mut [f32]>,
}

impl Readout {
    /// The readout of `window` of a `full` (cols, rows) sensor exposed for `t` seconds
    /// (finite, ≥ 0), temporal noise from `seed`.
    pub fn new(cfg: &SensorConfig, full: (u32, u32), window: Rect, t: f64, seed: u64) -> Self {
        let src = cfg.sources;
        let cg = cfg.conversion_gain_v_per_e();
        let use_col =
            src.column_fpn && (cfg.column_fpn_gain > 0.0 || cfg.column_fpn_offset_v > 0.0);
        Self {
            photon_noise: src.photon_noise,
            clipping: src.clipping,
            quantization: src.quantization,
            use_prnu: src.prnu && cfg.prnu > 0.0,
            use_dsnu: src.dsnu && cfg.dsnu_v > 0.0,
            use_read: src.read_noise && cfg.read_noise_v > 0.0,
            use_reset: src.reset_noise && cfg.reset_noise_v > 0.0,
            use_col,
            prnu: cfg.prnu,
            dsnu_v: cfg.dsnu_v,
            read_noise_v: cfg.read_noise_v,
            reset_noise_v: cfg.reset_noise_v,
            t,
            dark_e: if src.dark_current {
                cfg.dark_voltage_v_per_s * t / cg
            } else {
                0.0
            },
            cg,
            full_well: cfg.full_well_e(),
            dv_per_v: cfg.analog_gain / cfg.quantization_step_v(),
            white: cfg.white_level_dv(),
            black: cfg.black_level_dv,
            cols: (0..window.w)
                .map(|c| {
                    if use_col {
                        fpn_column(cfg, window.x + c)
                    } else {
                        (1.0, 0.0)
                    }
                })
                .collect(),
            k_photon: PixelRng::stream_key(seed, stream::PHOTON),
            k_read: PixelRng::stream_key(seed, stream::READ),
            k_fpn: PixelRng::stream_key(cfg.fpn_seed, stream::FPN_PIXEL),
            full_w: full.0 as u64,
            window,
            isa: Isa::detect(),
        }
    }

    /// Noise-free mean electrons of a pixel with signal rate `rate` e⁻/s.
    #[inline]
    pub fn mean_electrons(&self, rate: f32) -> f32 {
        (rate as f64 * self.t + self.dark_e) as f32
    }

    /// Read out window row `r` whose mean electrons are `mean`. `next_input` is
    /// memory the caller reads after this row (the next row's optical image):
    /// the noise passes bring it into cache as they go ([`Prefetch`]).
    pub fn row(
        &self,
        r: usize,
        mean: &[f32],
        out: RowOut<'_>,
        s: &mut Scratch,
        next_input: Prefetch<'_>,
    ) {
        #[cfg(target_arch = "x86_64")]
        match self.isa {
            // SAFETY: `isa` was detected on this CPU (Isa::detect).
            Isa::Avx512 => unsafe { self.row_avx512(r, mean, out, s, next_input) },
            Isa::Avx2 => unsafe { self.row_avx2(r, mean, out, s, next_input) },
            Isa::Baseline => self.row_generic::<RoundBits>(r, mean, out, s, next_input),
        }
        #[cfg(not(target_arch = "x86_64"))]
        self.row_generic::<RoundBits>(r, mean, out, s, next_input)
    }

    #[cfg(target_arch = "x86_64")]
    #[target_feature(enable = "avx512f,avx512dq,avx512vl,avx512bw,avx2,fma,bmi2")]
    fn row_avx512(
        &self,
        r: usize,
        mean: &[f32],
        out: RowOut<'_>,
        s: &mut Scratch,
        warm: Prefetch<'_>,
    ) {
        self.row_generic::<RoundInsn>(r, mean, out, s, warm)
    }

    #[cfg(target_arch = "x86_64")]
    #[target_feature(enable = "avx2,fma,bmi2")]
    fn row_avx2(
        &self,
        r: usize,
        mean: &[f32],
        out: RowOut<'_>,
        s: &mut Scratch,
        warm: Prefetch<'_>,
    ) {
        self.row_generic::<RoundInsn>(r, mean, out, s, warm)
    }

    /// The row in passes: each first pass takes every pixel's common case
    /// branch-free (so it vectorises), and records the pixels that need more.
    /// `warm` is brought into cache by the two normal passes, half each (the
    /// passes with the most arithmetic per byte: 0.5 MB over ≈ 2 × 1000
    /// blocks of a 4032-pixel row). `R` is how the kernel rounds (the same
    /// values either way: [`Rounding`]).
    #[inline(always)]
    fn row_generic<R: Rounding>(
        &self,
        r: usize,
        mean: &[f32],
        out: RowOut<'_>,
        s: &mut Scratch,
        warm: Prefetch<'_>,
    ) {
        let n = mean.len();
        let (warm_fpn, warm_read) = warm.halves();
        s.fit(n);
        let gi0 = (self.window.y as u64 + r as u64) * self.full_w + self.window.x as u64;
        let zx = ziggurat_x();
        // Photon counts: PTRS's first proposal where μ ≥ 10; everything else (small or
        // non-finite means, rejected proposals) drawn in full after.
        if self.photon_noise {
            let kp = self.k_photon;
            let n = mean.len();
            let (start, b) = (&mut s.first_start[..n], &mut s.first_b[..n]);
            let (us, v) = (&mut s.first_us[..n], &mut s.first_v[..n]);
            let (e, ok) = (&mut s.e[..n], &mut s.ok[..n]);
            for c in 0..n {
                let mu = mean[c] as f64;
                let (p, fast) = Proposal::new::<R>(kp, gi0 + c as u64, mu);
                e[c] = p.k;
                ok[c] = (10.0..f64::INFINITY).contains(&mu) & !p.k.is_nan() & fast;
                (start[c], b[c], us[c], v[c]) = (p.start, p.b, p.us, p.v);
            }
            self.finish_slow_photons::<R>(gi0, mean, s);
        } else {
            for (e, &m) in s.e.iter_mut().zip(mean) {
                *e = m as f64;
            }
        }
        if self.use_prnu || self.use_dsnu {
            let (kf, prnu, dsnu) = (self.k_fpn, self.prnu, self.dsnu_v);
            // The two normals into `gain` and `offset`, then made gain and offset.
            self.first_normals(zx, kf, gi0, s, NormalRows::Fpn, warm_fpn);
            for (((g, o), ok), (&ok1, &ok2)) in s
                .gain
                .iter_mut()
                .zip(s.offset.iter_mut())
                .zip(s.ok.iter_mut())
                .zip(s.ok_a.iter().zip(&s.ok_b))
            {
                *g = (1.0 + prnu * *g).max(0.0);
                *o *= dsnu;
                *ok = ok1 & ok2;
            }
            for_each_false(&s.ok, |c| {
                (s.gain[c], s.offset[c]) = fpn_pixel_keyed(prnu, dsnu, kf, gi0 + c as u64);
            });
        }
        if self.use_read || self.use_reset {
            // read noise is the stream's first normal, reset noise its second,
            // so switching one off leaves the other's values unchanged
            let (kr, reset) = (self.k_read, self.use_reset);
            self.first_normals(zx, kr, gi0, s, NormalRows::Read, warm_read);
            for (ok, (&ok1, &ok2)) in s.ok.iter_mut().zip(s.ok_a.iter().zip(&s.ok_b)) {
                *ok = ok1 & (ok2 | !reset);
            }
            for_each_false(&s.ok, |c| {
                let mut rr = PixelRng::keyed(kr, gi0 + c as u64);
                s.n1[c] = rr.normal();
                if reset {
                    s.n2[c] = rr.normal();
                }
            });
        }
        // The rest in passes over the row, one per switched-on step, so each is a
        // plain loop the compiler vectorises (one loop with a test per step per
        // pixel stayed scalar). Per pixel the same operations in the same order.
        let RowOut {
            dv,
            electrons,
            volts,
        } = out;
        let e = &mut s.e[..n];
        if self.use_prnu {
            for (e, &g) in e.iter_mut().zip(&s.gain) {
                *e *= g;
            }
        }
        if self.clipping {
            let fw = self.full_well;
            for e in e.iter_mut() {
                *e = e.min(fw);
            }
        }
        let v = &mut s.v[..n];
        for (v, &e) in v.iter_mut().zip(e.iter()) {
            *v = e * self.cg;
        }
        if self.use_dsnu {
            for (v, &o) in v.iter_mut().zip(&s.offset) {
                *v += o;
            }
        }
        if self.use_col {
            for (v, &(cgn, coff)) in v.iter_mut().zip(&self.cols) {
                *v = *v * cgn + coff;
            }
        }
        if self.use_read {
            let rn = self.read_noise_v;
            for (v, &x) in v.iter_mut().zip(&s.n1) {
                *v += rn * x;
            }
        }
        if self.use_reset {
            let rs = self.reset_noise_v;
            for (v, &x) in v.iter_mut().zip(&s.n2) {
                *v += rs * x;
            }
        }
        match (self.quantization, self.clipping) {
            (false, false) => self.to_dv::<R, false, false>(v, dv),
            (false, true) => self.to_dv::<R, false, true>(v, dv),
            (true, false) => self.to_dv::<R, true, false>(v, dv),
            (true, true) => self.to_dv::<R, true, true>(v, dv),
        }
        for (o, &e) in electrons.iter_mut().zip(e.iter()) {
            *o = e as f32;
        }
        if let Some(vr) = volts {
            for (o, &v) in vr.iter_mut().zip(v.iter()) {
                *o = v as f32;
            }
        }
    }

    /// The first two normals of every pixel's stream `key` of the row starting at
    /// full-frame index `gi0` ([`first_normals`]), into `gain` and `offset`
    /// (`NormalRows::Fpn`) or `n1` and `n2` (`NormalRows::Read`), their acceptances into
    /// `ok_a` and `ok_b`: eight pixels per instruction at the AVX-512 level, four
    /// at the AVX2 level.
    #[inline(always)]
    fn first_normals(
        &self,
        zx: &[f64; ZIG_N + 1],
        key: u64,
        gi0: u64,
        s: &mut Scratch,
        to: NormalRows,
        warm: Prefetch<'_>,
    ) {
        let (x1, x2) = match to {
            NormalRows::Fpn => (&mut s.gain, &mut s.offset),
            NormalRows::Read => (&mut s.n1, &mut s.n2),
        };
        let out = FirstNormals {
            x1,
            x2,
            ok1: &mut s.ok_a,
            ok2: &mut s.ok_b,
        };
        #[cfg(target_arch = "x86_64")]
        match self.isa {
            // SAFETY: `isa` was detected on this CPU (Isa::detect).
            Isa::Avx512 => unsafe { first_normals_avx512(zx, key, gi0, out, warm) },
            // SAFETY: as above.
            Isa::Avx2 => unsafe { first_normals_avx2(zx, key, gi0, out, warm) },
            Isa::Baseline => first_normals(zx, key, gi0, out, warm),
        }
        #[cfg(not(target_arch = "x86_64"))]
        first_normals(zx, key, gi0, out, warm);
    }

    /// The photon counts whose first PTRS proposal failed the fast test: gathered,
    /// finished side by side by [`ptrs_after_rejected_all`] where it can (the same
    /// values as the exact path), the others by the exact path.
    #[inline(always)]
    fn finish_slow_photons<R: Rounding>(&self, gi0: u64, mean: &[f32], s: &mut Scratch) {
        let kp = self.k_photon;
        // Gathered without a branch (a fifth of the pixels, at random): every
        // pixel is written at the next free place, which moves on past the slow ones.
        let n = mean.len();
        let r1 = &mut s.slow;
        r1.at.resize(n + 1, 0);
        r1.mu.resize(n + 1, 0.0);
        let mut m_slow = 0;
        // The rows as local slices: written through `s`, the loop reloaded
        // their addresses every pixel (perf annotate).
        let (at, slow_mu) = (&mut r1.at[..=n], &mut r1.mu[..=n]);
        for (c, (&ok, &m)) in s.ok.iter().zip(mean).enumerate() {
            at[m_slow] = c as u32;
            slow_mu[m_slow] = m as f64;
            m_slow += usize::from(!ok);
        }
        r1.at.truncate(m_slow);
        r1.mu.truncate(m_slow);
        r1.prop.clear();
        r1.prop.extend(r1.at.iter().map(|&c| {
            let c = c as usize;
            Proposal {
                start: s.first_start[c],
                b: s.first_b[c],
                k: s.e[c],
                us: s.first_us[c],
                v: s.first_v[c],
            }
        }));
        r1.draw::<R>(3);
        // The second proposals whose full test comes next (≈ 10 % of the first
        // round at μ ≥ 1000): a second round, as the exact path's next step.
        let r2 = &mut s.slow2;
        r2.at.clear();
        r2.mu.clear();
        r2.prop.clear();
        for (j, &p) in r1.pending.iter().enumerate() {
            if p {
                r2.at.push(j as u32);
                r2.mu.push(r1.mu[j]);
                r2.prop.push(r1.next[j]);
            }
        }
        r2.draw::<R>(5);
        for (&j, (&k, &done)) in r2.at.iter().zip(r2.k.iter().zip(&r2.done)) {
            if done {
                (r1.k[j as usize], r1.done[j as usize]) = (k, true);
            }
        }
        for ((&c, &mu), (&k, &done)) in r1.at.iter().zip(&r1.mu).zip(r1.k.iter().zip(&r1.done)) {
            s.e[c as usize] = if done {
                k
            } else {
                PixelRng::keyed(kp, gi0 + c as u64).poisson(mu)
            };
        }
    }

    /// Digital values from volts: gain and black level, then rounding
    /// (`QUANTIZE`) and clipping to [0, white] (`CLIP`).
    #[inline(always)]
    fn to_dv<R: Rounding, const QUANTIZE: bool, const CLIP: bool>(
        &self,
        v: &[f64],
        dv: &mut [f32],
    ) {
        for (o, &v) in dv.iter_mut().zip(v) {
            let mut d = v * self.dv_per_v + self.black;
            if QUANTIZE {
                d = R::round(d);
            }
            if CLIP {
                d = d.clamp(0.0, self.white);
            }
            *o = d as f32;
        }
    }
}

#[cfg(test)]
mod tests {
    use super::*;
    use crate::sensor::config::{Exposure, Sources};

    /// The shipped IMX363 sensor file.
    fn imx363() -> SensorConfig {
        SensorConfig::parse(
            include_str!(concat!(env!("CARGO_MANIFEST_DIR"), "/sensors/imx363.kdl")),
            std::path::Path::new("sensors/imx363.kdl"),
        )
        .unwrap()
    }

    /// Every false flag is visited once, in order, for rows of every length
    /// around the word size and every pattern of one word.
    #[test]
    fn for_each_false_visits_exactly_the_false_flags() {
        let mut rows: Vec<Vec<bool>> = (0..256u32)
            .map(|p| (0..8).map(|j| p & (1 << j) != 0).collect())
            .collect();
        for n in [0, 1, 7, 9, 15, 16, 17, 63, 100] {
            rows.push((0..n).map(|i| (i * 7919 + n) % 5 != 0).collect());
        }
        for flags in rows {
            let mut seen = vec![];
            for_each_false(&flags, |c| seen.push(c));
            let want: Vec<usize> = (0..flags.len()).filter(|&c| !flags[c]).collect();
            assert_eq!(seen, want, "{flags:?}");
        }
    }

    /// Scratch rows of `n` pixels holding what a stale row could: NaN in every
    /// value row, `true` ("the fast path was enough") in every flag row. A pass
    /// that read a row before writing it would take these instead of its own.
    fn poisoned(n: usize) -> Scratch {
        let mut s = Scratch::default();
        s.fit(n);
        for v in [
            &mut s.e,
            &mut s.gain,
            &mut s.offset,
            &mut s.n1,
            &mut s.n2,
            &mut s.v,
        ] {
            v.fill(f64::NAN);
        }
        for v in [&mut s.ok, &mut s.ok_a, &mut s.ok_b] {
            v.fill(true);
        }
        s
    }

    /// One pixel read out the direct way, draw after draw on each pixel's streams
    /// (the model as the pipeline's module docs state it).
    fn pixel_by_pixel(ro: &Readout, cfg: &SensorConfig, gi: u64, c: usize, mu: f64) -> [f32; 3] {
        let mut e = PixelRng::keyed(ro.k_photon, gi).poisson(mu);
        let (g, off) = fpn_pixel(cfg, gi);
        e *= g;
        e = e.min(ro.full_well);
        let mut v = e * ro.cg + off;
        let (cgn, coff) = ro.cols[c];
        v = v * cgn + coff;
        let mut rr = PixelRng::keyed(ro.k_read, gi);
        v += cfg.read_noise_v * rr.normal();
        v += cfg.reset_noise_v * rr.normal();
        let d = (v * ro.dv_per_v + ro.black).round().clamp(0.0, ro.white);
        [d as f32, e as f32, v as f32]
    }

    /// The row passes (every instruction-set level this CPU has) give exactly the
    /// pixel-by-pixel values, over means on both sides of the Poisson sampler's
    /// switch (10), zero, huge and infinite means, with every noise source on.
    #[test]
    fn row_passes_equal_pixel_by_pixel_at_every_level() {
        let mut cfg = imx363();
        cfg.exposure = Exposure::Seconds(0.01);
        cfg.reset_noise_v = 3e-4;
        cfg.column_fpn_gain = 0.01;
        cfg.column_fpn_offset_v = 2e-4;
        let full = (4032, 3024);
        let window = Rect::new(17, 1000, 700, 2);
        let means: Vec<f32> = (0..700)
            .map(|i| match i % 10 {
                0 => 0.0,
                1 => 3.7,
                2 => 9.999,
                3 => 10.0,
                4 => f32::INFINITY,
                5 => 1e9,
                _ => (i as f32 * 7.3) % 6500.0,
            })
            .collect();
        let levels: Vec<Isa> = [Isa::Baseline, Isa::Avx2, Isa::Avx512]
            .into_iter()
            .filter(|&l| l as u8 <= Isa::detect() as u8)
            .collect();
        for isa in levels {
            let mut ro = Readout::new(&cfg, full, window, 0.01, 99);
            ro.isa = isa;
            let (mut dv, mut e, mut v) = (vec![0f32; 700], vec![0f32; 700], vec![0f32; 700]);
            let out = RowOut {
                dv: &mut dv,
                electrons: &mut e,
                volts: Some(&mut v),
            };
            ro.row(1, &means, out, &mut poisoned(700), Prefetch::none());
            for c in 0..700 {
                let gi = 1001 * 4032 + 17 + c as u64;
                let want = pixel_by_pixel(&ro, &cfg, gi, c, means[c] as f64);
                let got = [dv[c], e[c], v[c]];
                assert_eq!(
                    got.map(f32::to_bits),
                    want.map(f32::to_bits),
                    "{isa:?} pixel {c} mean {}",
                    means[c]
                );
            }
        }
    }

    /// One pixel by the model with only the switched-on sources, written
    /// out step by step (pipeline module docs, steps 4–8).
    fn direct(cfg: &SensorConfig, ro: &Readout, gi: u64, x: u32, mu: f64) -> [f32; 3] {
        let src = cfg.sources;
        let mut e = if src.photon_noise {
            PixelRng::keyed(ro.k_photon, gi).poisson(mu)
        } else {
            mu
        };
        let (g, off) = fpn_pixel(cfg, gi);
        if src.prnu {
            e *= g;
        }
        if src.clipping {
            e = e.min(cfg.full_well_e());
        }
        let mut v = e * cfg.conversion_gain_v_per_e();
        if src.dsnu {
            v += off;
        }
        if src.column_fpn {
            let (cg, co) = fpn_column(cfg, x);
            v = v * cg + co;
        }
        let mut rr = PixelRng::keyed(ro.k_read, gi);
        let (n1, n2) = (rr.normal(), rr.normal());
        if src.read_noise {
            v += cfg.read_noise_v * n1;
        }
        if src.reset_noise {
            v += cfg.reset_noise_v * n2;
        }
        let mut d = v * cfg.analog_gain / cfg.quantization_step_v() + cfg.black_level_dv;
        if src.quantization {
            d = d.round();
        }
        if src.clipping {
            d = d.clamp(0.0, cfg.white_level_dv());
        }
        [d as f32, e as f32, v as f32]
    }

    /// Each source alone (and none, and all) changes exactly its own step:
    /// the row equals the direct model with only that source on, over means
    /// from dark to beyond the full well.
    #[test]
    fn each_source_switches_only_its_own_step() {
        let mut base = imx363();
        base.reset_noise_v = 3e-4;
        base.column_fpn_gain = 0.01;
        base.column_fpn_offset_v = 2e-4;
        base.prnu = 0.02;
        base.dsnu_v = 1e-3;
        let none = Sources::none();
        let one = |f: fn(&mut Sources)| {
            let mut s = none;
            f(&mut s);
            s
        };
        let cases = [
            none,
            Sources::all(),
            one(|s| s.photon_noise = true),
            one(|s| s.prnu = true),
            one(|s| s.dsnu = true),
            one(|s| s.column_fpn = true),
            one(|s| s.read_noise = true),
            one(|s| s.reset_noise = true),
            one(|s| s.clipping = true),
            one(|s| s.quantization = true),
        ];
        let full = (4032, 3024);
        let window = Rect::new(5, 7, 64, 1);
        let means: Vec<f32> = (0..64).map(|i| (i * i * i) as f32 * 0.9).collect();
        for src in cases {
            let mut cfg = base.clone();
            cfg.sources = src;
            let ro = Readout::new(&cfg, full, window, 0.01, 4);
            let (mut dv, mut e, mut v) = (vec![0f32; 64], vec![0f32; 64], vec![0f32; 64]);
            let out = RowOut {
                dv: &mut dv,
                electrons: &mut e,
                volts: Some(&mut v),
            };
            ro.row(0, &means, out, &mut poisoned(64), Prefetch::none());
            for c in 0..64 {
                let gi = 7 * 4032 + 5 + c as u64;
                let want = direct(&cfg, &ro, gi, 5 + c as u32, means[c] as f64);
                assert_eq!(
                    [dv[c], e[c], v[c]].map(f32::to_bits),
                    want.map(f32::to_bits),
                    "{src:?} pixel {c}"
                );
            }
        }
    }

    /// Dark electrons over the exposure join the mean only with dark current on.
    #[test]
    fn dark_current_adds_its_electrons_to_the_mean() {
        let mut cfg = imx363();
        cfg.dark_voltage_v_per_s = 2e-3;
        let w = Rect::new(0, 0, 4, 1);
        let ro = Readout::new(&cfg, (4, 1), w, 0.5, 1);
        let dark = 2e-3 * 0.5 / cfg.conversion_gain_v_per_e();
        assert_eq!(ro.mean_electrons(100.0), (100.0 * 0.5 + dark) as f32);
        cfg.sources.dark_current = false;
        let ro = Readout::new(&cfg, (4, 1), w, 0.5, 1);
        assert_eq!(ro.mean_electrons(100.0), 50.0);
    }

    /// Column FPN is (1 + σ_g·n₁, σ_o·n₂) with n₁, n₂ the first two normals of
    /// the column's own stream (seed, FPN_COLUMN, column). Over 20 000 columns
    /// the gains have mean 1 and standard deviation σ_g, the offsets mean 0 and
    /// standard deviation σ_o: within 4 standard errors (σ/√n for a mean,
    /// σ/√(2n) for a standard deviation of normal draws).
    #[test]
    fn column_fpn_is_gain_and_offset_from_the_columns_stream() {
        let mut cfg = imx363();
        cfg.column_fpn_gain = 0.01;
        cfg.column_fpn_offset_v = 2e-4;
        cfg.fpn_seed = 7;
        for x in [0u32, 1, 4031] {
            let mut r = PixelRng::new(7, stream::FPN_COLUMN, x as u64);
            let (n1, n2) = (r.normal(), r.normal());
            assert_eq!(
                fpn_column(&cfg, x),
                (1.0 + 0.01 * n1, 2e-4 * n2),
                "column {x}"
            );
        }
        let n = 20_000;
        let (g, o): (Vec<f64>, Vec<f64>) = (0..n).map(|x| fpn_column(&cfg, x)).unzip();
        let stats = |v: &[f64]| {
            let m = v.iter().sum::<f64>() / v.len() as f64;
            let sd = (v.iter().map(|x| (x - m).powi(2)).sum::<f64>() / (v.len() - 1) as f64).sqrt();
            (m, sd)
        };
        let nf = n as f64;
        let (mg, sg) = stats(&g);
        assert!((mg - 1.0).abs() < 4.0 * 0.01 / nf.sqrt(), "gain mean {mg}");
        assert!(
            (sg - 0.01).abs() < 4.0 * 0.01 / (2.0 * nf).sqrt(),
            "gain sd {sg}"
        );
        let (mo, so) = stats(&o);
        assert!(mo.abs() < 4.0 * 2e-4 / nf.sqrt(), "offset mean {mo}");
        assert!(
            (so - 2e-4).abs() < 4.0 * 2e-4 / (2.0 * nf).sqrt(),
            "offset sd {so}"
        );
    }

    /// The level a cap allows on CPUs with and without AVX-512 and AVX2, and
    /// the caps `CAMSIM_SENSOR_ISA` knows; each level's name.
    #[test]
    fn isa_level_follows_the_cpu_and_the_cap() {
        use Isa::*;
        for (cap, want) in [
            ("", [Avx512, Avx2, Baseline]),
            ("avx512", [Avx512, Avx2, Baseline]),
            ("bogus", [Avx512, Avx2, Baseline]),
            ("avx2", [Avx2, Avx2, Baseline]),
            ("baseline", [Baseline, Baseline, Baseline]),
        ] {
            let got = [
                Isa::level(cap, true, true),
                Isa::level(cap, false, true),
                Isa::level(cap, false, false),
            ];
            assert_eq!(got, want, "cap {cap:?}");
        }
        for cap in ["", "baseline", "avx2", "avx512"] {
            assert!(Isa::cap_is_known(cap), "{cap}");
        }
        for cap in ["bogus", "AVX2", "sse"] {
            assert!(!Isa::cap_is_known(cap), "{cap}");
        }
        assert_eq!(
            [Baseline, Avx2, Avx512].map(Isa::name),
            ["baseline", "avx2+fma", "avx512f"]
        );
    }

    /// The vectorised first passes take the common case, as the module docs
    /// say: a photon count is finished in the first pass exactly when PTRS's
    /// first proposal is accepted (μ ≥ 10 and finite; rng's own
    /// `poisson_ptrs_first`), and read noise exactly when its first normal's
    /// fast case holds (and, with reset noise on, the second's too). A pass
    /// that sent every pixel to the exact second pass would give the same
    /// values, only slower, so this is what tells the two apart.
    #[test]
    fn first_passes_finish_the_common_case() {
        let mut cfg = imx363();
        let n = 4000;
        let means: Vec<f32> = (0..n)
            .map(|i| match i % 4 {
                0 => 5.0,
                1 => 10.0,
                2 => 100.0 + i as f32,
                _ => 1000.0 + i as f32,
            })
            .collect();
        let window = Rect::new(0, 3, n as u32, 1);
        let run = |cfg: &SensorConfig| {
            let ro = Readout::new(cfg, (n as u32, 8), window, 0.01, 5);
            let (mut dv, mut e) = (vec![0f32; n], vec![0f32; n]);
            let out = RowOut {
                dv: &mut dv,
                electrons: &mut e,
                volts: None,
            };
            let mut s = poisoned(n);
            ro.row(0, &means, out, &mut s, Prefetch::none());
            (ro, s.ok)
        };
        let gi0 = 3 * n as u64;
        cfg.sources = Sources::none();
        cfg.sources.photon_noise = true;
        let (ro, ok) = run(&cfg);
        let mut accepted = 0;
        for c in 0..n {
            let mu = means[c] as f64;
            let want = mu >= 10.0
                && PixelRng::keyed(ro.k_photon, gi0 + c as u64)
                    .poisson_ptrs_first(mu)
                    .accepted;
            assert_eq!(ok[c], want, "pixel {c}, mean {mu}");
            accepted += usize::from(want);
        }
        // The module docs' rejection rates (65 % at μ = 10, 33 % at 100, 24 % at
        // 1000, fewer above) leave ≥ 1780 of the 3000 pixels with μ ≥ 10 in the
        // first pass; less 4 binomial standard deviations (4·√(3000·¼) ≈ 110).
        assert!(accepted >= 1670, "{accepted}");
        for reset in [false, true] {
            cfg.sources = Sources::none();
            cfg.sources.read_noise = true;
            cfg.sources.reset_noise = reset;
            cfg.reset_noise_v = 3e-4;
            let (ro, ok) = run(&cfg);
            let zx = ziggurat_x();
            for (c, &ok) in ok.iter().enumerate() {
                let gi = gi0 + c as u64;
                let first = PixelRng::normal_fast(PixelRng::keyed_output(ro.k_read, gi, 1), zx).1;
                let second = PixelRng::normal_fast(PixelRng::keyed_output(ro.k_read, gi, 2), zx).1;
                assert_eq!(ok, first && (second || !reset), "pixel {c}, reset {reset}");
            }
        }
    }
}
