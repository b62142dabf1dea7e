//! The sampler: the random numbers one pixel sample consumes.
//!
//! Two kinds (`SamplerKind`):
//! - `Independent`: every number from the sample's own PCG32 stream
//!   (`sampling::Rng`), keyed by (seed, pixel, sample).
//! - `Sobol` (the default): randomised quasi-Monte Carlo. The `n` samples of
//!   one batch take `n` of the first 2^m ≥ n points of a 2-D Sobol sequence
//!   (its first two dimensions, a (0,2)-sequence in base 2; all of them, a
//!   (0,m,2)-net, when n is a power of two), and each 2-D draw of a path (film
//!   position, lens position, light choice and position, BSDF direction, …) takes its
//!   own copy of that sequence, randomised independently. 1-D draws (lobe
//!   choice, roulette, a dispersive camera's band) are the first
//!   coordinate of a copy of their own; a band chosen inside the scene (a
//!   dispersive dielectric, met by some samples only) comes from PCG32. This is "padding" as in pbrt's `PaddedSobolSampler`;
//!   the randomisation is Owen's nested uniform scrambling, in the hash-based
//!   form of Burley (2020, "Practical Hash-based Owen Scrambling", JCGT 9(4)):
//!   - the point index is shuffled by a nested uniform scramble of its bits
//!     (so every copy visits the points in a different order and the copies
//!     are independent of one another), and
//!   - each coordinate is then nested-uniform scrambled.
//!
//! Why it is unbiased and why batches stay independent: after a nested
//! uniform scramble each point is uniform on [0,1)², so every sample is still
//! a uniform draw; the copies of one sample are independent, and every batch
//! (and every pixel) takes its own scramble seeds, so the batch means stay
//! independent and their spread remains an honest standard error. For one
//! 2-D draw on its own, Owen (1997) bounds a scrambled (0,m,2)-net's variance
//! by e ≈ 2.718 times plain Monte Carlo's and shows it is o(1/n) for any
//! square-integrable integrand; the padded copies make no such promise for
//! the path as a whole, which is why the gain is measured (docs/performance.md), not
//! assumed. What it buys: the `n` points of a batch are stratified in every
//! elementary interval at once (2×2, 4×1, 1×4 cells for n = 4; 8×4, 4×8, … for
//! 32), so soft shadows, emitter edges and the first indirect bounce converge
//! faster than n^(−1/2). The gain grows with the samples per batch: a render
//! of `spp` samples in `batches` batches gets the stratification of
//! `spp / batches` points.
//!
//! Determinism: the numbers depend only on (seed, pixel, batch, index in the
//! batch, draw), never on the thread or tile.
//!
//! Draws past `LD_DRAWS` (the camera and the first two bounces) come from the
//! PCG32 stream: deep bounces carry little of the image and gain little from
//! stratification, while each scrambled draw costs three hash permutations.

use super::sampling::{Rng, mix64, unit_f32 as to_unit};
use serde::{Deserialize, Serialize};

/// Which random numbers the renderer uses (`RenderSettings::sampler`).
#[derive(Clone, Copy, Debug, Default, PartialEq, Eq, Serialize, Deserialize)]
#[serde(rename_all = "lowercase")]
pub enum SamplerKind {
    /// Independent uniform numbers (PCG32 per sample).
    Independent,
    /// Owen-scrambled, shuffled 2-D Sobol points, one copy per draw (padded).
    #[default]
    Sobol,
}

impl SamplerKind {
    /// Every kind, the default first.
    pub const ALL: [SamplerKind; 2] = [SamplerKind::Sobol, SamplerKind::Independent];
    /// Their names, in the order of `ALL` (the KDL choice and `--sampler`).
    pub const NAMES: [&'static str; 2] = [Self::ALL[0].name(), Self::ALL[1].name()];

    pub const fn name(self) -> &'static str {
        match self {
            SamplerKind::Independent => "independent",
            SamplerKind::Sobol => "sobol",
        }
    }
    /// The kind named `s` (one of `NAMES`).
    pub fn parse(s: &str) -> Option<Self> {
        Self::ALL.into_iter().find(|k| k.name() == s)
    }
}

/// Draws (1-D or 2-D) per sample taken from scrambled Sobol copies; later
/// draws come from the sample's PCG32 stream. A path uses 2 camera draws
/// (film, lens; a third for a dispersive camera's band) and then 4 per bounce
/// (light choice and position from one 2-D point, lobe, direction, roulette):
/// 10 covers the camera and the first two bounces. Measured on the Mitsuba Cornell box at
/// 32 spp in one batch (`camsim bench render`, 4 seeds, RMSE of Y against
/// Mitsuba's converged image, light transport): 7 draws 13.97 %, 12 draws
/// 13.71 %, 32 draws 13.68 %, at 2 %, 4 % and 12 % more time than the
/// independent sampler.
pub const LD_DRAWS: usize = 10;

/// Lanes of the per-sample point arrays: `LD_DRAWS` rounded up to a vector
/// width (16 f32/u32 = one AVX-512 register, two AVX2, four SSE).
const LANES: usize = 16;
const _: () = assert!(LD_DRAWS <= LANES);

/// The scramble seeds one (pixel, batch) shares across its samples: every
/// sample of the batch must see the same scrambled copy in a draw for the
/// batch to be stratified. Built once per batch (`new`), so a sample's draws
/// cost no hashing. Stored draw-major per seed kind, so a sample computes
/// all its scrambled draws at once, one draw per vector lane.
pub struct BatchScramble {
    /// Per draw: index shuffle seed.
    shuffle: [u32; LANES],
    /// Per draw: x (dimension 0) and y (dimension 1) scramble seeds.
    sx: [u32; LANES],
    sy: [u32; LANES],
    /// m: the low bits of the shuffled index kept, enough for the batch's
    /// samples. Any aligned block of 2^m points of the sequence is a
    /// (0, m, 2)-net; a shorter index keeps the Sobol evaluation short.
    bits: u32,
}

impl BatchScramble {
    /// Seeds of batch `batch` (of `n` samples) of the pixel whose key is
    /// `Rng::pixel_key(seed, pixel)`.
    pub fn new(pixel_key: u64, batch: u64, n: usize) -> Self {
        let key = mix64(pixel_key ^ mix64(batch ^ 0x536F_626F_6C00_0000));
        let (mut shuffle, mut sx, mut sy) = ([0u32; LANES], [0u32; LANES], [0u32; LANES]);
        for d in 0..LD_DRAWS {
            let h = mix64(key ^ (d as u64).wrapping_mul(0x9E37_79B9_7F4A_7C15));
            let h2 = mix64(h);
            (shuffle[d], sx[d], sy[d]) = (h as u32, (h >> 32) as u32, h2 as u32);
        }
        let bits = (usize::BITS - n.saturating_sub(1).leading_zeros()).min(32);
        BatchScramble {
            shuffle,
            sx,
            sy,
            bits,
        }
    }

    /// The low `bits` bits set.
    #[inline(always)]
    fn mask(&self) -> u32 {
        u32::MAX.checked_shr(32 - self.bits).unwrap_or(0)
    }

    /// Every scrambled draw of sample `index`: (x, y) of draw d in lane d.
    /// Plain loops over the lanes, which the per-ISA row kernels vectorise;
    /// integer arithmetic only, so every ISA level gives the same bits.
    #[inline(always)]
    fn points(&self, index: u32) -> ([f32; LANES], [f32; LANES]) {
        let (rk, mask) = (index.reverse_bits(), self.mask());
        // The Sobol index: Burley's shuffle, nus(k) = reverse(lk(reverse(k))).
        let mut i = [0u32; LANES];
        for (o, &s) in i.iter_mut().zip(&self.shuffle) {
            *o = lk_permutation(rk, s).reverse_bits() & mask;
        }
        // x = nus(reverse(i)) = reverse(lk(i)): dimension 0 is the
        // bit-reversed index, and the scramble's own reversals cancel.
        let mut x = [0f32; LANES];
        for ((o, &il), &s) in x.iter_mut().zip(&i).zip(&self.sx) {
            *o = to_unit(lk_permutation(il, s).reverse_bits());
        }
        // y = nus(sobol1(i)) = reverse(lk(reverse(sobol1(i)))), reverse(sobol1)
        // being the XOR of the bit-reversed columns selected by i's bits.
        let mut yr = i;
        for o in &mut yr {
            *o = sobol1_reversed(*o);
        }
        let mut y = [0f32; LANES];
        for ((o, &v), &s) in y.iter_mut().zip(&yr).zip(&self.sy) {
            *o = to_unit(lk_permutation(v, s).reverse_bits());
        }
        (x, y)
    }
}

/// The numbers of one pixel sample.
#[derive(Clone)]
pub struct Sampler {
    rng: Rng,
    /// Scrambled Sobol draws (draw d in lane d) of this sample.
    x: [f32; LANES],
    y: [f32; LANES],
    /// Next draw.
    draw: usize,
    /// Draws taken from `x`, `y` (0: independent sampler).
    ld_draws: usize,
}

impl Sampler {
    /// Sample `index` of the batch scrambled by `ld` (`None`: every number
    /// from the PCG32 stream). `pixel_key` is `Rng::pixel_key(seed, pixel)`
    /// and `sample` the sample's number in the pixel: they key its PCG32
    /// stream.
    #[inline(always)]
    pub fn for_sample(ld: Option<&BatchScramble>, pixel_key: u64, index: u32, sample: u64) -> Self {
        let rng = Rng::for_pixel_sample(pixel_key, sample);
        match ld {
            Some(ld) => {
                let (x, y) = ld.points(index);
                Sampler {
                    rng,
                    x,
                    y,
                    draw: 0,
                    ld_draws: LD_DRAWS,
                }
            }
            None => Self::independent(rng),
        }
    }

    /// Every number from `rng`.
    #[inline(always)]
    pub fn independent(rng: Rng) -> Self {
        Sampler {
            rng,
            x: [0.0; LANES],
            y: [0.0; LANES],
            draw: 0,
            ld_draws: 0,
        }
    }

    /// Uniform in [0, 1).
    #[inline(always)]
    pub fn get1d(&mut self) -> f32 {
        if self.draw < self.ld_draws {
            self.draw += 1;
            self.x[self.draw - 1]
        } else {
            self.rng.uniform()
        }
    }

    /// Uniform in [0, 1) from the sample's PCG32 stream, whatever the kind:
    /// for draws that only some samples take.
    #[inline(always)]
    pub fn get1d_independent(&mut self) -> f32 {
        self.rng.uniform()
    }

    /// Two uniforms in [0, 1), stratified jointly across the batch.
    #[inline(always)]
    pub fn get2d(&mut self) -> (f32, f32) {
        if self.draw < self.ld_draws {
            self.draw += 1;
            (self.x[self.draw - 1], self.y[self.draw - 1])
        } else {
            self.rng.uniform2()
        }
    }
}

/// A bounce's four draws, in the order every bounce takes them (whether or
/// not it uses them): the light choice and position from one 2-D point, the
/// lobe, the BSDF direction, Russian roulette.
#[derive(Clone, Copy, Debug)]
pub struct BounceDraws {
    pub light: (f32, f32),
    pub lobe: f32,
    pub dir: (f32, f32),
    pub rr: f32,
}

impl Sampler {
    /// Whether the next bounce's four draws all come from the scrambled
    /// Sobol copies (then `bounce_draws_sobol` takes them).
    #[inline(always)]
    pub fn bounce_is_sobol(&self) -> bool {
        self.draw + 4 <= self.ld_draws
    }

    /// The next bounce's four draws: what `get2d`, `get1d`, `get2d`,
    /// `get1d` give in turn.
    #[inline(always)]
    pub fn bounce_draws(&mut self) -> BounceDraws {
        if self.bounce_is_sobol() {
            self.bounce_draws_sobol()
        } else {
            BounceDraws {
                light: self.get2d(),
                lobe: self.get1d(),
                dir: self.get2d(),
                rr: self.get1d(),
            }
        }
    }

    /// `bounce_draws` for a sampler whose `bounce_is_sobol()` holds, with no
    /// branch: the packet kernel takes the draws of such lanes in a loop of
    /// their own, so that lanes at different depths (some past `LD_DRAWS`)
    /// do not cost a mispredicted branch each.
    #[inline(always)]
    pub fn bounce_draws_sobol(&mut self) -> BounceDraws {
        debug_assert!(self.bounce_is_sobol());
        // `draw` itself when `bounce_is_sobol()`; the bound keeps the
        // reads in the arrays without a check.
        let d = self.draw.min(LANES - 4);
        self.draw = d + 4;
        BounceDraws {
            light: (self.x[d], self.y[d]),
            lobe: self.x[d + 1],
            dir: (self.x[d + 2], self.y[d + 2]),
            rr: self.x[d + 3],
        }
    }
}

/// The bounce draws of one packet's lanes (`shade_packet::shade_diffuse`'s
/// arrays): light point, BSDF direction, Russian roulette.
#[cfg(target_arch = "x86_64")]
pub(super) struct LaneDraws<'a> {
    pub light: [&'a mut [f32; 16]; 2],
    pub dir: [&'a mut [f32; 16]; 2],
    pub rr: &'a mut [f32; 16],
}

/// Floats in a `Sampler`: the gathers' stride from one lane's sampler to
/// the next.
#[cfg(target_arch = "x86_64")]
const SAMPLER_FLOATS: usize = std::mem::size_of::<Sampler>() / 4;
#[cfg(target_arch = "x86_64")]
const _: () = assert!(std::mem::size_of::<Sampler>().is_multiple_of(4));

/// For the AVX-512 kernel: of the lanes `go` of a packet's samplers `smps`,
/// those whose next bounce's draws are all Sobol points
/// (`bounce_is_sobol`) take them as `bounce_draws_sobol` does — the same
/// floats, into `out` (the lobe's draw is taken and not used, as in
/// `shade_diffuse`) — one gather per draw for the sixteen lanes instead of
/// a load and a store per draw and lane. Returns those lanes; the others'
/// samplers and `out` lanes are untouched.
///
/// # Safety
/// The CPU has AVX-512F.
#[cfg(target_arch = "x86_64")]
#[target_feature(enable = "avx512f")]
pub(super) unsafe fn bounce_draws_sobol_lanes(
    smps: &mut [Sampler; 16],
    go: u32,
    out: LaneDraws<'_>,
) -> u32 {
    use std::arch::x86_64::*;
    use std::mem::offset_of;
    // SAFETY: lane l's offsets address sampler l of `smps` (from its own
    // pointer): its `draw` and `ld_draws` (the low 32 bits, little endian;
    // both stay far below 2³²) and, for Sobol lanes, `x[d..d + 4]` and
    // `y[d..d + 4]` with d ≤ LANES − 4, as `bounce_draws_sobol` bounds it.
    // The stores write 16-float arrays under the lanes' mask.
    unsafe {
        let lane = super::simd::record_offsets(super::simd::lane_numbers(), SAMPLER_FLOATS, 0);
        let base = smps.as_mut_ptr().cast::<u8>();
        let word = |off: usize| base.add(off).cast::<i32>();
        let g = go as __mmask16;
        let draw = _mm512_mask_i32gather_epi32::<4>(
            _mm512_setzero_si512(),
            g,
            lane,
            word(offset_of!(Sampler, draw)),
        );
        let ld = _mm512_mask_i32gather_epi32::<4>(
            _mm512_setzero_si512(),
            g,
            lane,
            word(offset_of!(Sampler, ld_draws)),
        );
        let four = _mm512_set1_epi32(4);
        let m = _mm512_mask_cmple_epu32_mask(g, _mm512_add_epi32(draw, four), ld);
        let d = _mm512_min_epu32(draw, _mm512_set1_epi32(LANES as i32 - 4));
        let at = _mm512_add_epi32(lane, d);
        let take = |field: usize, k: i32, dst: &mut [f32; 16]| {
            let v = _mm512_mask_i32gather_ps::<4>(
                _mm512_setzero_ps(),
                m,
                _mm512_add_epi32(at, _mm512_set1_epi32(k)),
                base.add(field).cast::<f32>(),
            );
            _mm512_mask_storeu_ps(dst.as_mut_ptr(), m, v);
        };
        let (x, y) = (offset_of!(Sampler, x), offset_of!(Sampler, y));
        let LaneDraws { light, dir, rr } = out;
        let [l0, l1] = light;
        let [d0, d1] = dir;
        take(x, 0, l0);
        take(y, 0, l1);
        take(x, 2, d0);
        take(y, 2, d1);
        take(x, 3, rr);
        _mm512_mask_i32scatter_epi32::<4>(
            word(offset_of!(Sampler, draw)),
            m,
            lane,
            _mm512_add_epi32(d, four),
        );
        m as u32
    }
}

/// reverse(sobol1(i)): the XOR of the bit-reversed columns wⱼ (below) that
/// the bits of `i` select. Bit k of wⱼ is C(j, k) mod 2, odd exactly when
/// the bits of k are a subset of those of j (Lucas), so bit k of the result
/// is the XOR of the bits j ⊇ k of `i`: a superset-sum transform, done as a
/// butterfly over the five bits of a bit position (15 operations for any
/// number of index bits, against 5 per index bit summing the columns).
#[inline(always)]
fn sobol1_reversed(i: u32) -> u32 {
    let mut y = i;
    y ^= (y >> 1) & 0x5555_5555;
    y ^= (y >> 2) & 0x3333_3333;
    y ^= (y >> 4) & 0x0F0F_0F0F;
    y ^= (y >> 8) & 0x00FF_00FF;
    y ^= (y >> 16) & 0x0000_FFFF;
    y
}

/// Laine–Karras style hash permutation: every output bit depends only on the
/// input bits below it (the multiplications carry upwards only), which is
/// what makes it a nested uniform (Owen) scramble when applied to the
/// bit-reversed value.
#[inline(always)]
fn lk_permutation(mut x: u32, seed: u32) -> u32 {
    x ^= x.wrapping_mul(0x3D20_ADEA);
    x = x.wrapping_add(seed);
    x = x.wrapping_mul((seed >> 16) | 1);
    x ^= x.wrapping_mul(0x0552_6C56);
    x ^= x.wrapping_mul(0x53A2_2864);
    x
}

#[cfg(test)]
mod tests {
    use super::*;

    // The textbook forms the renderer's fast form is checked against.

    /// Second dimension of the Sobol sequence (the first is the bit-reversed
    /// index, van der Corput): generator matrix = Pascal's triangle mod 2, whose
    /// column j is built from the previous one by v ^= v >> 1.
    #[inline(always)]
    fn sobol_dim1(mut i: u32) -> u32 {
        let mut v = 1u32 << 31;
        let mut r = 0u32;
        while i != 0 {
            if i & 1 != 0 {
                r ^= v;
            }
            i >>= 1;
            v ^= v >> 1;
        }
        r
    }

    /// Bit-reversed Sobol dimension-1 columns: w₀ = 1, wⱼ = wⱼ₋₁ ⊕ (wⱼ₋₁ ≪ 1)
    /// (the reversal of vⱼ = vⱼ₋₁ ⊕ (vⱼ₋₁ ≫ 1), v₀ = 2³¹).
    const fn sobol1_rev_columns() -> [u32; 32] {
        let mut w = [0u32; 32];
        w[0] = 1;
        let mut j = 1;
        while j < 32 {
            w[j] = w[j - 1] ^ (w[j - 1] << 1);
            j += 1;
        }
        w
    }

    const SOBOL1_REV_COLUMNS: [u32; 32] = sobol1_rev_columns();

    /// The butterfly equals the column sum it replaces and the textbook
    /// dimension 1, bit-reversed, for every 16-bit index and random 32-bit ones.
    #[test]
    fn sobol1_butterfly_equals_the_column_sum() {
        let column_sum = |i: u32| {
            (0..32)
                .filter(|j| i >> j & 1 != 0)
                .fold(0u32, |y, j| y ^ SOBOL1_REV_COLUMNS[j])
        };
        let mut h = 0x1234_5678u32;
        for k in 0..(1u32 << 16) + 4096 {
            let i = if k < 1 << 16 {
                k
            } else {
                h = h.wrapping_mul(0x9E37_79B9).wrapping_add(0x7F4A_7C15) ^ (h >> 15);
                h
            };
            assert_eq!(sobol1_reversed(i), column_sum(i), "i = {i:#x}");
            assert_eq!(
                sobol1_reversed(i),
                sobol_dim1(i).reverse_bits(),
                "i = {i:#x}"
            );
        }
    }

    /// Owen's nested uniform scramble of a 32-bit fixed-point value: bit k is
    /// flipped by a hash of the bits above it (Burley 2020).
    #[inline(always)]
    fn nested_uniform_scramble(x: u32, seed: u32) -> u32 {
        lk_permutation(x.reverse_bits(), seed).reverse_bits()
    }

    /// The first 2^m points of dimensions (0, 1) form a (0, m, 2)-net: every
    /// elementary interval of area 2^−m (2^a × 2^(m−a) cells) holds exactly one
    /// point — checked by counting, for m ≤ 8.
    fn assert_net(pts: &[(u32, u32)], m: u32) {
        for a in 0..=m {
            let (bx, by) = (a, m - a);
            let mut seen = vec![false; 1 << m];
            for &(x, y) in pts {
                let cx = if bx == 0 { 0 } else { x >> (32 - bx) };
                let cy = if by == 0 { 0 } else { y >> (32 - by) };
                let c = ((cx << by) | cy) as usize;
                assert!(!seen[c], "m={m} a={a}: two points in cell {c}");
                seen[c] = true;
            }
        }
    }

    #[test]
    fn sobol_prefixes_are_0_m_2_nets() {
        for m in 0..=8u32 {
            let pts: Vec<(u32, u32)> = (0..1u32 << m)
                .map(|i| (i.reverse_bits(), sobol_dim1(i)))
                .collect();
            assert_net(&pts, m);
        }
        // By hand from the Pascal matrix mod 2 (columns .1, .11, .101 in
        // binary), index bits applied in natural (not Gray-code) order.
        let want = [0.0, 0.5, 0.75, 0.25, 0.625, 0.125, 0.375, 0.875];
        for (i, w) in want.iter().enumerate() {
            assert_eq!(sobol_dim1(i as u32) as f64 / 4294967296.0, *w, "i={i}");
        }
    }

    /// The renderer's fast form (all draws at once, index reversed once per
    /// sample, reversed Sobol columns, cancelled reversals) gives exactly the textbook
    /// composition nus(sobol(nus(i) mod 2^m)) of Burley's shuffled, scrambled
    /// Sobol, for short and long (> 2¹⁶, the loop) indices.
    #[test]
    fn fast_form_equals_the_textbook_composition() {
        let mut r = Rng::for_sample(3, 1, 4);
        for n in [1usize, 2, 5, 32, 1000, 1 << 20, 1 << 31] {
            let scr = BatchScramble::new(r.next_u32() as u64, 9, n);
            for _ in 0..200 {
                let index = r.next_u32() % n as u32;
                let mut smp = Sampler::for_sample(Some(&scr), 1, index, 0);
                for d in 0..LD_DRAWS {
                    let (s0, s1, s2) = (scr.shuffle[d], scr.sx[d], scr.sy[d]);
                    let i = nested_uniform_scramble(index, s0) & scr.mask();
                    let x = to_unit(nested_uniform_scramble(i.reverse_bits(), s1));
                    let y = to_unit(nested_uniform_scramble(sobol_dim1(i), s2));
                    if d % 3 == 2 {
                        assert_eq!(smp.get1d(), x, "n={n} index={index} draw {d}");
                    } else {
                        assert_eq!(smp.get2d(), (x, y), "n={n} index={index} draw {d}");
                    }
                }
            }
        }
    }

    /// A batch of 2^m samples is a (0, m, 2)-net in every 2-D draw (the
    /// scrambles permute each level's cells within their parent), whatever
    /// the pixel and batch.
    #[test]
    fn every_draw_of_a_power_of_two_batch_is_a_net() {
        for key in [0u64, 1, 0xDEAD_BEEF, u64::MAX] {
            for m in 0..=8u32 {
                let n = 1usize << m;
                let scr = BatchScramble::new(key, m as u64, n);
                let mut smps: Vec<Sampler> = (0..n as u32)
                    .map(|i| Sampler::for_sample(Some(&scr), key, i, i as u64))
                    .collect();
                for _ in 0..LD_DRAWS {
                    let pts: Vec<(u32, u32)> = smps
                        .iter_mut()
                        .map(|s| {
                            let (x, y) = s.get2d();
                            (
                                ((x * 16_777_216.0) as u32) << 8,
                                ((y * 16_777_216.0) as u32) << 8,
                            )
                        })
                        .collect();
                    assert_net(&pts, m);
                }
            }
        }
    }

    /// Bit k of the scrambled value depends only on bits above k of the input
    /// (the defining property of a nested scramble): changing low bits never
    /// changes high ones.
    #[test]
    fn scramble_is_nested() {
        let mut r = Rng::for_sample(11, 0, 0);
        for _ in 0..20_000 {
            let (x, seed) = (r.next_u32(), r.next_u32());
            let k = r.next_u32() % 32;
            let low = if k == 0 { 0 } else { u32::MAX >> (32 - k) };
            let y = x ^ (r.next_u32() & low);
            let (sx, sy) = (
                nested_uniform_scramble(x, seed),
                nested_uniform_scramble(y, seed),
            );
            let hi = !low;
            assert_eq!(sx & hi, sy & hi, "x={x:#x} y={y:#x} k={k}");
        }
    }

    /// Over independent scramble seeds one point is uniform on [0,1)²: the
    /// counts in an 8×8 grid pass a χ² test (63 degrees of freedom; the 99.9 %
    /// quantile is 103.4), for several indices of the sequence.
    #[test]
    fn one_scrambled_point_is_uniform() {
        for index in [0u32, 1, 5, 31] {
            let n = 64_000u64;
            let mut counts = [0u32; 64];
            for s in 0..n {
                let scr = BatchScramble::new(mix64(s), 3, 32);
                let mut smp = Sampler::for_sample(Some(&scr), mix64(s), index, 0);
                let (x, y) = smp.get2d();
                counts[((x * 8.0) as usize) * 8 + (y * 8.0) as usize] += 1;
            }
            let e = n as f64 / 64.0;
            let chi2: f64 = counts.iter().map(|&c| (c as f64 - e).powi(2) / e).sum();
            assert!(chi2 < 103.4, "index {index}: χ² = {chi2}");
        }
    }

    /// Different draws of one sample and different batches of one pixel are
    /// uncorrelated: the sample correlation of x over 10⁵ pixels is within
    /// 4.5/√n of 0.
    #[test]
    fn draws_and_batches_are_uncorrelated() {
        let n = 100_000u64;
        let (mut a, mut b, mut c) = (Vec::new(), Vec::new(), Vec::new());
        for p in 0..n {
            let (b0, b1) = (
                BatchScramble::new(mix64(p), 0, 4),
                BatchScramble::new(mix64(p), 1, 4),
            );
            let mut s0 = Sampler::for_sample(Some(&b0), mix64(p), 2, 0);
            let mut s1 = Sampler::for_sample(Some(&b1), mix64(p), 2, 0);
            a.push(s0.get1d() as f64);
            b.push(s0.get1d() as f64);
            c.push(s1.get1d() as f64);
        }
        let corr = |u: &[f64], v: &[f64]| {
            let (mu, mv) = (
                u.iter().sum::<f64>() / n as f64,
                v.iter().sum::<f64>() / n as f64,
            );
            let cov: f64 = u.iter().zip(v).map(|(x, y)| (x - mu) * (y - mv)).sum();
            let vu: f64 = u.iter().map(|x| (x - mu).powi(2)).sum();
            let vv: f64 = v.iter().map(|y| (y - mv).powi(2)).sum();
            cov / (vu * vv).sqrt()
        };
        let lim = 4.5 / (n as f64).sqrt();
        assert!(corr(&a, &b).abs() < lim, "draws: {}", corr(&a, &b));
        assert!(corr(&a, &c).abs() < lim, "batches: {}", corr(&a, &c));
    }

    /// The points a batch's samples take in one draw form a net: the batch's
    /// 16 samples fall one per cell of a 4×4 grid in every 2-D draw.
    #[test]
    fn a_batch_is_stratified_in_every_draw() {
        let key = Rng::pixel_key(7, 123);
        let scr = BatchScramble::new(key, 2, 16);
        let mut samplers: Vec<Sampler> = (0..16)
            .map(|i| Sampler::for_sample(Some(&scr), key, i, i as u64))
            .collect();
        for draw in 0..LD_DRAWS {
            let mut seen = [false; 16];
            for s in samplers.iter_mut() {
                let (x, y) = s.get2d();
                let c = (x * 4.0) as usize * 4 + (y * 4.0) as usize;
                assert!(!seen[c], "draw {draw}: cell {c} twice");
                seen[c] = true;
            }
        }
        // Past LD_DRAWS the numbers come from the PCG streams.
        let mut s = Sampler::for_sample(Some(&scr), key, 0, 0);
        for _ in 0..LD_DRAWS {
            s.get1d();
        }
        let mut r = Rng::for_pixel_sample(key, 0);
        assert_eq!(s.get1d(), r.uniform());
    }

    /// A bounce's four draws taken at once are the draws taken one by one,
    /// from every starting draw (before, across and past `LD_DRAWS`) and for
    /// both kinds; `bounce_is_sobol` says exactly when all four are Sobol
    /// points.
    #[test]
    fn bounce_draws_are_the_draws_one_by_one() {
        let ld = BatchScramble::new(77, 1, 16);
        for kind in [Some(&ld), None] {
            for skip in 0..14 {
                let mk = || {
                    let mut s = Sampler::for_sample(kind, 77, 5, 9);
                    for _ in 0..skip {
                        s.get1d();
                    }
                    s
                };
                let (mut a, mut b) = (mk(), mk());
                let sobol = a.bounce_is_sobol();
                assert_eq!(sobol, kind.is_some() && skip + 4 <= LD_DRAWS);
                let d = if sobol {
                    a.bounce_draws_sobol()
                } else {
                    a.bounce_draws()
                };
                let want = (b.get2d(), b.get1d(), b.get2d(), b.get1d());
                assert_eq!((d.light, d.lobe, d.dir, d.rr), want, "skip {skip}");
                assert_eq!(a.get1d(), b.get1d(), "the draw after, skip {skip}");
            }
        }
    }
}
