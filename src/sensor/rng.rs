//! Counter-based random numbers for the sensor: every pixel draws from its own
//! stream, keyed by (seed, noise source, full-frame pixel index), so a frame is
//! bit-identical for any thread count and any window of the frame.
//!
//! - [`PixelRng`]: SplitMix64 stream (Steele et al. 2014) started from a mixed key.
//! - [`PixelRng::normal`]: exact ziggurat (Marsaglia & Tsang 2000).
//! - [`PixelRng::poisson`]: exact Poisson at every mean: sequential inversion for
//!   μ < 10, Hörmann's PTRS transformed rejection (1993) for μ ≥ 10. No Gaussian
//!   approximation anywhere.

use std::sync::OnceLock;

mod first_normals;
mod ptrs_squeeze;
mod rounding;
pub use first_normals::{FirstNormals, first_normals};
#[cfg(target_arch = "x86_64")]
pub use first_normals::{first_normals_avx2, first_normals_avx512};
pub use ptrs_squeeze::{
    Proposal, RejectedDraws, ln_near, ptrs_after_first, ptrs_after_rejected_all,
};
pub use rounding::{RoundBits, RoundInsn, Rounding};

/// Stream identifiers (one per noise source) so sources never share numbers.
pub mod stream {
    pub const PHOTON: u64 = 0x1;
    pub const READ: u64 = 0x2;
    pub const FPN_PIXEL: u64 = 0x3;
    pub const FPN_COLUMN: u64 = 0x4;
}

/// One proposal of Hörmann's PTRS Poisson sampler (see [`PixelRng::poisson_ptrs_first`]).
#[derive(Clone, Copy, Debug)]
pub struct PtrsProposal {
    /// The proposed count.
    pub k: f64,
    us: f64,
    v: f64,
    /// The fast acceptance test passed: `k` is the draw.
    pub accepted: bool,
}

/// PTRS constants (a, b, b − 2, v_r·(b − 2)) for mean `mu` ≥ 10. The fast acceptance
/// v ≤ v_r = 0.9277 − 3.6224/(b − 2) is multiplied out (b − 2 > 6.9 for μ ≥ 10) to keep
/// a division off the common path.
#[inline(always)]
pub fn ptrs_constants(mu: f64) -> (f64, f64, f64, f64) {
    ptrs_constants_from_b(0.931 + 2.53 * mu.sqrt())
}

/// [`ptrs_constants`] from its b = 0.931 + 2.53·√μ (the rest follows from b).
#[inline(always)]
pub(super) fn ptrs_constants_from_b(b: f64) -> (f64, f64, f64, f64) {
    let a = -0.059 + 0.02483 * b;
    let bm2 = b - 2.0;
    (a, b, bm2, 0.9277 * bm2 - 3.6224)
}

/// SplitMix64's finaliser: its two multipliers and three shifts (`mix64`;
/// `first_normals_avx512` takes the same ones in vector lanes).
const MIX_MUL: [u64; 2] = [0xbf58_476d_1ce4_e5b9, 0x94d0_49bb_1331_11eb];
const MIX_SHIFT: [u32; 3] = [30, 27, 31];

#[inline]
fn mix64(mut z: u64) -> u64 {
    z = (z ^ (z >> MIX_SHIFT[0])).wrapping_mul(MIX_MUL[0]);
    z = (z ^ (z >> MIX_SHIFT[1])).wrapping_mul(MIX_MUL[1]);
    z ^ (z >> MIX_SHIFT[2])
}

/// A small random stream for one (seed, source, item).
#[derive(Clone, Debug)]
pub struct PixelRng {
    state: u64,
}

const GAMMA: u64 = 0x9e37_79b9_7f4a_7c15;

/// What an item is multiplied by before it is mixed with its stream key.
const ITEM_MUL: u64 = 0xd1b5_4a32_d192_ed03;

/// The starting state of the stream of (`stream_key`, `item`).
#[inline(always)]
fn stream_start(stream_key: u64, item: u64) -> u64 {
    mix64(stream_key ^ item.wrapping_mul(ITEM_MUL))
}

/// Output `n` (n ≥ 1) of the stream that starts at `start`.
#[inline(always)]
fn output_at(start: u64, n: u64) -> u64 {
    mix64(start.wrapping_add(GAMMA.wrapping_mul(n)))
}

impl PixelRng {
    /// The stream for `item` (e.g. full-frame pixel index) of `source` under `seed`.
    #[inline]
    pub fn new(seed: u64, source: u64, item: u64) -> Self {
        Self::keyed(Self::stream_key(seed, source), item)
    }
    /// The per-(seed, source) half of the key, to hoist out of per-pixel loops:
    /// `keyed(stream_key(s, src), i)` equals `new(s, src, i)`.
    #[inline]
    pub fn stream_key(seed: u64, source: u64) -> u64 {
        mix64(seed.wrapping_add(GAMMA.wrapping_mul(source.wrapping_add(1))))
    }
    #[inline]
    pub fn keyed(stream_key: u64, item: u64) -> Self {
        Self {
            state: stream_start(stream_key, item),
        }
    }
    /// The `n`-th output (n ≥ 1) of `keyed(stream_key, item)`, computed directly
    /// (SplitMix64's state after n steps is the start + n·γ): what the n-th
    /// `next_u64` returns. Lets a loop over pixels draw without a per-pixel state.
    #[inline(always)]
    pub fn keyed_output(stream_key: u64, item: u64, n: u64) -> u64 {
        output_at(stream_start(stream_key, item), n)
    }
    #[inline]
    pub fn next_u64(&mut self) -> u64 {
        self.state = self.state.wrapping_add(GAMMA);
        mix64(self.state)
    }
    /// Uniform in [0, 1) with 53 random bits.
    #[inline]
    pub fn uniform(&mut self) -> f64 {
        uniform_from_bits(self.next_u64())
    }
    /// Uniform in (0, 1].
    #[inline]
    fn uniform_open0(&mut self) -> f64 {
        ((self.next_u64() >> 11) + 1) as f64 * (1.0 / (1u64 << 53) as f64)
    }
    /// Standard normal, exact, by the ziggurat method (Marsaglia & Tsang 2000;
    /// 256 layers, f64, the layer index and the abscissa from disjoint bits). The
    /// common case (≈ 99 %: inside a layer's rectangle) is inlined; wedges and the
    /// tail go to a cold path.
    #[inline(always)]
    pub fn normal(&mut self) -> f64 {
        let z = ziggurat();
        let bits = self.next_u64();
        let i = (bits & 0xff) as usize;
        let u = ziggurat_u(bits);
        let x = u * z.x[i];
        if x.abs() < z.x[i + 1] {
            return x;
        }
        self.normal_slow(z, i, u, x)
    }

    /// The common case of [`Self::normal`] for one 64-bit output `bits` of a stream:
    /// (x, accepted). When accepted, x is what `normal` returns for a stream whose
    /// next output is `bits`; when not, `normal` needs more outputs (≈ 1 % of draws).
    /// `x_table` is [`ziggurat_x`]. Branch-free, so a loop of these vectorises.
    #[inline(always)]
    pub fn normal_fast(bits: u64, x_table: &[f64; ZIG_N + 1]) -> (f64, bool) {
        let i = (bits & 0xff) as usize;
        let u = ziggurat_u(bits);
        let x = u * x_table[i];
        (x, x.abs() < x_table[i + 1])
    }

    #[cold]
    #[inline(never)]
    fn normal_slow(&mut self, z: &Ziggurat, mut i: usize, mut u: f64, mut x: f64) -> f64 {
        loop {
            if i == 0 {
                // tail beyond R (Marsaglia 1964)
                loop {
                    let a = -self.uniform_open0().ln() / ZIG_R;
                    let b = -self.uniform_open0().ln();
                    if 2.0 * b > a * a {
                        return if u < 0.0 { -(ZIG_R + a) } else { ZIG_R + a };
                    }
                }
            }
            let y = z.f[i] + self.uniform() * (z.f[i + 1] - z.f[i]);
            if y < (-0.5 * x * x).exp() {
                return x;
            }
            let bits = self.next_u64();
            i = (bits & 0xff) as usize;
            u = ziggurat_u(bits);
            x = u * z.x[i];
            if x.abs() < z.x[i + 1] {
                return x;
            }
        }
    }

    /// Exact Poisson variate with mean `mu` (NaN or ≤ 0 gives 0; +∞ gives +∞, which
    /// the pipeline's well clipping then bounds).
    #[inline(always)]
    pub fn poisson(&mut self, mu: f64) -> f64 {
        if mu.is_nan() || mu <= 0.0 {
            return 0.0;
        }
        if mu == f64::INFINITY {
            return mu;
        }
        if mu < 10.0 {
            self.poisson_inversion(mu)
        } else {
            self.poisson_ptrs(mu)
        }
    }
    /// Sequential search inversion (exact; expected μ+1 steps).
    fn poisson_inversion(&mut self, mu: f64) -> f64 {
        let u = self.uniform();
        let mut k = 0u32;
        let mut p = (-mu).exp();
        let mut cdf = p;
        while u >= cdf {
            k += 1;
            p *= mu / k as f64;
            cdf += p;
            // Guard against round-off leaving cdf < u forever (p underflows to 0).
            if p < 1e-300 && k as f64 > mu {
                break;
            }
        }
        k as f64
    }
    /// Hörmann (1993), "The transformed rejection method for generating Poisson
    /// random variables", algorithm PTRS; exact for μ ≥ 10.
    #[inline(always)]
    fn poisson_ptrs(&mut self, mu: f64) -> f64 {
        let p = self.poisson_ptrs_first(mu);
        if p.accepted {
            return p.k;
        }
        self.poisson_ptrs_rest(mu, p)
    }

    /// The first PTRS proposal for mean `mu` (≥ 10, finite) and whether its fast
    /// acceptance test passed. When it did not, [`Self::poisson_ptrs_rest`] on the same
    /// stream finishes the draw: `first` then `rest` is exactly [`Self::poisson`] for
    /// that mean. Splitting the two lets a row of pixels take the branch-free common
    /// case in one loop and the rejected proposals (1 − 0.86·v_r: 24 % at μ = 1000)
    /// in a second one.
    #[inline(always)]
    pub fn poisson_ptrs_first(&mut self, mu: f64) -> PtrsProposal {
        let (a, b, bm2, v_r_num) = ptrs_constants(mu);
        let u = self.uniform() - 0.5;
        let v = self.uniform();
        let us = 0.5 - u.abs();
        let k = fast_floor((2.0 * a / us + b) * u + mu + 0.43);
        PtrsProposal {
            k,
            us,
            v,
            accepted: (us >= 0.07) & (v * bm2 <= v_r_num),
        }
    }

    /// Finish a PTRS draw whose first proposal `p` (from [`Self::poisson_ptrs_first`]
    /// with the same `mu`, on this stream) failed the fast acceptance test.
    pub fn poisson_ptrs_rest(&mut self, mu: f64, p: PtrsProposal) -> f64 {
        let (a, b, bm2, v_r_num) = ptrs_constants(mu);
        self.poisson_ptrs_slow(mu, a, b, bm2, v_r_num, p.us, p.v, p.k)
    }

    /// The rest of PTRS after a failed fast acceptance (same random sequence).
    #[cold]
    #[inline(never)]
    #[allow(clippy::too_many_arguments)]
    fn poisson_ptrs_slow(
        &mut self,
        mu: f64,
        a: f64,
        b: f64,
        bm2: f64,
        v_r_num: f64,
        mut us: f64,
        mut v: f64,
        mut k: f64,
    ) -> f64 {
        let log_mu = mu.ln();
        let inv_alpha = 1.1239 + 1.1328 / (b - 3.4);
        loop {
            if !(k < 0.0 || (us < 0.013 && v > us)) {
                let lhs = (v * inv_alpha / (a / (us * us) + b)).ln();
                let rhs = -mu + k * log_mu - ln_factorial(k);
                if lhs <= rhs {
                    return k;
                }
            }
            let u = self.uniform() - 0.5;
            v = self.uniform();
            us = 0.5 - u.abs();
            k = fast_floor((2.0 * a / us + b) * u + mu + 0.43);
            if us >= 0.07 && v * bm2 <= v_r_num {
                return k;
            }
        }
    }
}

/// Ziggurat layers.
pub const ZIG_N: usize = 256;
const ZIG_R: f64 = 3.654_152_885_361_009;
const ZIG_V: f64 = 0.004_928_673_233_99;

struct Ziggurat {
    /// Layer widths x[0] (base: V/f(R)) > x[1] = R > … > x[256] = 0.
    x: [f64; ZIG_N + 1],
    /// f(x[i]) = exp(−x[i]²/2).
    f: [f64; ZIG_N + 1],
}

/// The ziggurat's layer widths, for [`PixelRng::normal_fast`].
pub fn ziggurat_x() -> &'static [f64; ZIG_N + 1] {
    &ziggurat().x
}

/// Uniform in [0, 1) from one 64-bit output (its top 53 bits), as [`PixelRng::uniform`].
#[inline(always)]
pub fn uniform_from_bits(bits: u64) -> f64 {
    u53_to_f64(bits >> 11) * (1.0 / (1u64 << 53) as f64)
}

/// The ziggurat's abscissa factor u in [−1, 1) from one 64-bit output (its top
/// 53 bits; the layer comes from its low 8): what `normal`, `normal_fast` and
/// `normal_slow` multiply a layer's edge by, and what `first_normals_avx512` /
/// `first_normals_avx2` compute in vector lanes.
#[inline(always)]
fn ziggurat_u(bits: u64) -> f64 {
    2.0 * uniform_from_bits(bits) - 1.0
}

/// `x as f64` for x < 2⁵³ (exact, the same value), in operations every vector
/// level has: the high 21 bits and the low 32 bits each put under an exponent
/// (2⁸⁴ and 2⁵²), the exponents taken away, the halves added — each step
/// exact, as in `first_normals_avx2`. Before AVX-512DQ there is no vector
/// conversion from 64-bit integers, and the compiler converted each lane of
/// the photon pass's uniforms in scalar code (extract, `vcvtsi2sd`, insert):
/// ≈ 10 % of that pass's samples in perf on an AVX2 EPYC.
#[inline(always)]
pub fn u53_to_f64(x: u64) -> f64 {
    const E84: u64 = 0x4530_0000_0000_0000;
    const E52: u64 = 0x4330_0000_0000_0000;
    let hi = f64::from_bits((x >> 32) | E84);
    let lo = f64::from_bits((x & 0xffff_ffff) | E52);
    (hi - ((1u128 << 84) as f64 + (1u64 << 52) as f64)) + lo
}

fn ziggurat() -> &'static Ziggurat {
    static Z: OnceLock<Ziggurat> = OnceLock::new();
    Z.get_or_init(|| {
        let f = |x: f64| (-0.5 * x * x).exp();
        let mut x = [0.0; ZIG_N + 1];
        x[0] = ZIG_V / f(ZIG_R);
        x[1] = ZIG_R;
        for i in 2..ZIG_N {
            x[i] = (-2.0 * (ZIG_V / x[i - 1] + f(x[i - 1])).ln()).sqrt();
        }
        x[ZIG_N] = 0.0;
        let fx = x.map(f);
        Ziggurat { x, f: fx }
    })
}

/// 2⁵²: below it, adding and taking away 2⁵² of a value's sign rounds it to an
/// integer exactly (floats in [2⁵², 2⁵³) are one apart).
pub(super) const TWO52: f64 = 4_503_599_627_370_496.0;

/// x rounded to an integer, ties to even, for |x| < 2⁵²; +0 (never −0) for a
/// zero. The floor and truncation below start from it instead of from the
/// truncating cast `x as i64`, which gives the same values there but saturates
/// beyond i64's range, which LLVM lowers one lane at a time (a scalar
/// conversion with two compares per lane): these few operations vectorise at
/// every level.
#[inline(always)]
fn round_even_below_2_52(x: f64) -> f64 {
    let m = TWO52.copysign(x);
    (x + m) - m
}

/// ⌊x⌋ for |x| < 2⁵² (+0 for a zero); a finite value or NaN otherwise. Branch-free
/// (one less where the rounding went up): the sign and fraction of x are data.
#[inline(always)]
pub(super) fn floor_below_2_52(x: f64) -> f64 {
    let r = round_even_below_2_52(x);
    r - f64::from(u8::from(r > x))
}

/// x truncated toward zero for |x| < 2⁵² (+0 for a zero): one nearer zero where
/// the rounding went away from it.
#[inline(always)]
fn trunc_below_2_52(x: f64) -> f64 {
    let r = round_even_below_2_52(x);
    r - f64::from(u8::from(r.abs() > x.abs())).copysign(x)
}

/// floor(x) without a libm call on baseline x86-64 (no SSE4.1 `roundsd`): exact for
/// |x| < 2^52 (+0 for a zero), `f64::floor` otherwise.
#[inline]
pub fn fast_floor(x: f64) -> f64 {
    if x.abs() < TWO52 {
        floor_below_2_52(x)
    } else {
        x.floor()
    }
}

/// round(x), halves away from zero (as `f64::round`), without a libm call: exact for
/// |x| < 2^52 (+0 for a zero), `f64::round` otherwise.
#[inline]
pub fn fast_round(x: f64) -> f64 {
    if x.abs() < TWO52 {
        let t = trunc_below_2_52(x);
        let f = x - t; // exact: |x| < 2^52
        // Branch-free: the fraction of a DV is noise, so a branch on it mispredicts
        // half the time. t is an integer-valued f64 (never −0), t ± 1 and t ± 0 are exact.
        t + f64::from(u8::from(f >= 0.5)) - f64::from(u8::from(f <= -0.5))
    } else {
        x.round()
    }
}

/// ln k! for k = 0…255, each the sum of the logarithms up to k in order (what
/// [`ln_factorial`] returns below 256).
pub fn ln_factorial_table() -> &'static [f64; 256] {
    static TABLE: OnceLock<[f64; 256]> = OnceLock::new();
    TABLE.get_or_init(|| {
        let mut v = [0.0f64; 256];
        for i in 1..256 {
            v[i] = v[i - 1] + (i as f64).ln();
        }
        v
    })
}

/// ln(k!) for integer-valued k ≥ 0: exact table below 256, Stirling series above
/// (truncation error < 1e-16 relative there).
pub fn ln_factorial(k: f64) -> f64 {
    let t = ln_factorial_table();
    if k < 256.0 {
        return t[k.max(0.0) as usize];
    }
    let n = k + 1.0; // ln Γ(n)
    ln_gamma_stirling(n, n.ln())
}

/// ln Γ(n) by the Stirling series, given `ln_n` = ln n (libm's in
/// [`ln_factorial`], `ln_near`'s in the squeeze): one expression for both, so
/// they differ by the logarithm alone.
#[inline(always)]
fn ln_gamma_stirling(n: f64, ln_n: f64) -> f64 {
    let inv = 1.0 / n;
    let inv2 = inv * inv;
    (n - 0.5) * ln_n - n
        + 0.5 * std::f64::consts::TAU.ln()
        + inv * (1.0 / 12.0 - inv2 * (1.0 / 360.0 - inv2 * (1.0 / 1260.0 - inv2 / 1680.0)))
}

#[cfg(test)]
mod tests {
    use super::*;

    #[test]
    fn ln_factorial_matches_direct_sum_across_table_edge() {
        let mut s = 0.0f64;
        for i in 1..2000u32 {
            s += (i as f64).ln();
            let r = ln_factorial(i as f64);
            assert!((r - s).abs() <= 1e-12 * s.max(1.0), "{i}: {r} vs {s}");
        }
    }

    /// Chi-square goodness of fit of the sampler against the exact Poisson pmf,
    /// on both sides of the inversion/PTRS switch and far from it.
    #[test]
    fn poisson_is_exact_by_chi_square() {
        for &mu in &[0.3, 3.0, 9.99, 10.0, 25.0, 137.5, 5000.0] {
            let n = 200_000usize;
            let mut counts = std::collections::BTreeMap::<i64, f64>::new();
            let mut sum = 0.0;
            let mut sum2 = 0.0;
            for i in 0..n {
                let mut r = PixelRng::new(42, stream::PHOTON, i as u64);
                let k = r.poisson(mu);
                assert_eq!(k, k.floor());
                sum += k;
                sum2 += k * k;
                *counts.entry(k as i64).or_default() += 1.0;
            }
            let mean = sum / n as f64;
            let var = sum2 / n as f64 - mean * mean;
            // mean SE = sqrt(mu/n); 5 sigma
            assert!(
                (mean - mu).abs() < 5.0 * (mu / n as f64).sqrt(),
                "mu {mu}: mean {mean}"
            );
            // var SE ≈ mu·sqrt(2/n + 1/(mu n)); 5 sigma
            let se = mu * (2.0 / n as f64 + 1.0 / (mu * n as f64)).sqrt();
            assert!((var - mu).abs() < 5.0 * se, "mu {mu}: var {var}");
            // chi-square over bins with expected count ≥ 20, tails pooled
            let pmf = |k: i64| (-mu + k as f64 * mu.ln() - ln_factorial(k as f64)).exp();
            let lo = (mu - 6.0 * mu.sqrt()).floor().max(0.0) as i64;
            let hi = (mu + 6.0 * mu.sqrt()).ceil() as i64 + 10;
            let mut chi2 = 0.0;
            let mut dof = 0usize;
            let mut pool_e = 0.0;
            let mut pool_o = 0.0;
            for k in lo..=hi {
                let e = pmf(k) * n as f64;
                let o = counts.get(&k).copied().unwrap_or(0.0);
                if e >= 20.0 {
                    chi2 += (o - e) * (o - e) / e;
                    dof += 1;
                } else {
                    pool_e += e;
                    pool_o += o;
                }
            }
            if pool_e > 5.0 {
                chi2 += (pool_o - pool_e).powi(2) / pool_e;
                dof += 1;
            }
            // Chi-square with d dof: mean d, sd sqrt(2d); accept below d + 5 sd
            // (p < 1e-5 of a false alarm for these dof).
            let bound = dof as f64 + 5.0 * (2.0 * dof as f64).sqrt();
            assert!(
                chi2 < bound,
                "mu {mu}: chi2 {chi2} with {dof} bins (bound {bound})"
            );
        }
    }

    #[test]
    fn normal_moments() {
        let n = 200_000;
        let mut r = PixelRng::new(7, stream::READ, 0);
        let (mut s, mut s2, mut s4) = (0.0, 0.0, 0.0);
        for _ in 0..n {
            let z = r.normal();
            s += z;
            s2 += z * z;
            s4 += z * z * z * z;
        }
        let nf = n as f64;
        assert!((s / nf).abs() < 5.0 / nf.sqrt());
        assert!((s2 / nf - 1.0).abs() < 5.0 * (2.0 / nf).sqrt());
        assert!((s4 / nf - 3.0).abs() < 5.0 * (96.0 / nf).sqrt());
    }

    /// Binned chi-square of the normal sampler against Φ, including both tails and the
    /// ziggurat's base/tail boundary at 3.654.
    #[test]
    fn normal_is_exact_by_chi_square() {
        let erf = |x: f64| {
            // Abramowitz & Stegun 7.1.26, |error| < 1.5e-7
            let t = 1.0 / (1.0 + 0.3275911 * x.abs());
            let y = 1.0
                - t * (0.254829592
                    + t * (-0.284496736
                        + t * (1.421413741 + t * (-1.453152027 + t * 1.061405429))))
                    * (-x * x).exp();
            if x >= 0.0 { y } else { -y }
        };
        let phi = |x: f64| 0.5 * (1.0 + erf(x / std::f64::consts::SQRT_2));
        let edges: Vec<f64> = (-16..=16)
            .map(|i| i as f64 * 0.25)
            .chain([-3.654, 3.654])
            .collect::<Vec<_>>();
        let mut e = edges.clone();
        e.sort_by(|a, b| a.total_cmp(b));
        let n = 1_000_000usize;
        let mut counts = vec![0.0f64; e.len() + 1];
        let mut r = PixelRng::new(11, stream::READ, 3);
        for _ in 0..n {
            let z = r.normal();
            counts[e.partition_point(|&b| b <= z)] += 1.0;
        }
        let mut chi2 = 0.0;
        for k in 0..counts.len() {
            let lo = if k == 0 { f64::NEG_INFINITY } else { e[k - 1] };
            let hi = if k == e.len() { f64::INFINITY } else { e[k] };
            let p = (if hi.is_finite() { phi(hi) } else { 1.0 })
                - (if lo.is_finite() { phi(lo) } else { 0.0 });
            let ex = p * n as f64;
            chi2 += (counts[k] - ex).powi(2) / ex;
        }
        let dof = (counts.len() - 1) as f64;
        assert!(
            chi2 < dof + 5.0 * (2.0 * dof).sqrt(),
            "chi2 {chi2} on {dof}"
        );
    }

    #[test]
    fn fast_floor_and_round_match_libm() {
        let mut r = PixelRng::new(3, 3, 3);
        let specials = [
            0.0,
            -0.0,
            0.5,
            -0.5,
            1.5,
            -1.5,
            2.5,
            -2.5,
            0.49999999999999994,
            -0.49999999999999994,
            1e15 + 0.5,
            -1e15 - 0.5,
            4.6e15,
            -4.6e15,
            1e300,
            f64::INFINITY,
            f64::NEG_INFINITY,
        ];
        // Integers, halves (where ties to even go either way) and their
        // neighbours, quarters, both signs, and values just under 2⁵².
        let mut near = vec![1e-300, -1e-300, 0.3, -0.3, 0.7, -0.7];
        for k in -40..=40 {
            let h = k as f64 + 0.5;
            near.extend([k as f64, h, k as f64 + 0.25, k as f64 - 0.25]);
            near.extend([
                f64::from_bits(h.to_bits() + 1),
                f64::from_bits(h.to_bits() - 1),
            ]);
        }
        for x in [TWO52 - 0.5, TWO52 - 1.0, TWO52 - 1.5, 2.5e15 + 0.5] {
            near.extend([x, -x]);
        }
        for &x in specials.iter().chain(&near).chain(
            (0..100_000)
                .map(|_| (r.uniform() - 0.5) * 2e4)
                .collect::<Vec<_>>()
                .iter(),
        ) {
            // Bit for bit, a zero as +0 (libm keeps −0: floor(−0), round(−0.3)).
            assert_eq!(
                fast_floor(x).to_bits(),
                (x.floor() + 0.0).to_bits(),
                "floor {x}"
            );
            assert_eq!(
                fast_round(x).to_bits(),
                (x.round() + 0.0).to_bits(),
                "round {x}"
            );
            // The vector kernels' two ways (`Rounding`), the floor where its
            // callers use it.
            for (round, way) in [(RoundBits::round(x), "bits"), (RoundInsn::round(x), "insn")] {
                assert_eq!(
                    round.to_bits(),
                    (x.round() + 0.0).to_bits(),
                    "{way} round {x}"
                );
            }
            if x.abs() < TWO52 {
                for (floor, way) in [
                    (RoundBits::floor_below_2_52(x), "bits"),
                    (RoundInsn::floor_below_2_52(x), "insn"),
                ] {
                    assert_eq!(
                        floor.to_bits(),
                        (x.floor() + 0.0).to_bits(),
                        "{way} floor {x}"
                    );
                }
            }
        }
        assert!(fast_floor(f64::NAN).is_nan() && fast_round(f64::NAN).is_nan());
        assert!(
            RoundInsn::round(f64::NAN).is_nan() && RoundInsn::floor_below_2_52(f64::NAN).is_nan()
        );
    }

    #[test]
    fn streams_differ_and_repeat() {
        let a: Vec<u64> = (0..4)
            .map(|i| PixelRng::new(1, stream::PHOTON, i).next_u64())
            .collect();
        let b: Vec<u64> = (0..4)
            .map(|i| PixelRng::new(1, stream::PHOTON, i).next_u64())
            .collect();
        let c: Vec<u64> = (0..4)
            .map(|i| PixelRng::new(1, stream::READ, i).next_u64())
            .collect();
        assert_eq!(a, b);
        assert!(a.iter().zip(&c).all(|(x, y)| x != y));
        let k = PixelRng::stream_key(1, stream::PHOTON);
        let d: Vec<u64> = (0..4).map(|i| PixelRng::keyed(k, i).next_u64()).collect();
        assert_eq!(a, d);
        assert!(PixelRng::new(0, 0, 0).poisson(f64::NAN) == 0.0);
        assert!(PixelRng::new(0, 0, 0).poisson(-1.0) == 0.0);
        assert!(PixelRng::new(0, 0, 0).poisson(f64::INFINITY).is_infinite());
        let k = PixelRng::new(0, 0, 0).poisson(1e15);
        assert!((k - 1e15).abs() < 1e9, "{k}");
    }

    /// The stream is Steele et al.'s SplitMix64: from state 0 it gives the
    /// published first outputs of Vigna's reference `splitmix64.c`.
    #[test]
    fn splitmix64_reference_outputs() {
        let mut r = PixelRng { state: 0 };
        let got: Vec<u64> = (0..4).map(|_| r.next_u64()).collect();
        assert_eq!(
            got,
            [
                0xE220_A839_7B1D_CDAF,
                0x6E78_9E6A_A1B9_65F4,
                0x06C4_5D18_8009_454F,
                0xF88B_B8A8_724C_81EC
            ]
        );
    }

    /// `keyed_output(k, i, n)` is the n-th output of `keyed(k, i)`, and the
    /// uniforms built from outputs are those of the stream.
    #[test]
    fn direct_outputs_are_the_streams() {
        for (key, item) in [(0u64, 0u64), (PixelRng::stream_key(7, stream::READ), 12345)] {
            let mut r = PixelRng::keyed(key, item);
            for n in 1..=6 {
                let bits = PixelRng::keyed_output(key, item, n);
                assert_eq!(bits, r.clone().next_u64(), "n = {n}");
                assert_eq!(uniform_from_bits(bits), r.uniform());
            }
        }
        // The conversion is exact: `as f64` at every power of two and its
        // neighbours below 2⁵³, and at a spread of values between.
        let mut x = 0x0123_4567_89ab_cdefu64;
        for k in 0..53 {
            for v in [1u64 << k, (1u64 << k) - 1, (1u64 << k) + 1] {
                let v = v.min((1 << 53) - 1);
                assert_eq!(u53_to_f64(v).to_bits(), (v as f64).to_bits(), "{v}");
            }
        }
        for _ in 0..10_000 {
            x = mix64(x);
            let v = x >> 11;
            assert_eq!(u53_to_f64(v).to_bits(), (v as f64).to_bits(), "{v}");
        }
        // 53 bits: the largest uniform is 1 − 2⁻⁵³, never 1.
        assert_eq!(uniform_from_bits(u64::MAX), 1.0 - f64::EPSILON / 2.0);
        assert_eq!(uniform_from_bits(0), 0.0);
    }

    /// Where the vectorisable first step accepts, it gives what `normal`
    /// gives; where it does not, `normal` needed more than the rectangle
    /// (≈ 1 % of draws; at least one in 10⁴ here).
    #[test]
    fn fast_normal_agrees_with_normal() {
        let z = ziggurat_x();
        let key = PixelRng::stream_key(3, stream::READ);
        let mut rejected = 0;
        for i in 0..10_000u64 {
            let (x, ok) = PixelRng::normal_fast(PixelRng::keyed_output(key, i, 1), z);
            let full = PixelRng::keyed(key, i).normal();
            if ok {
                assert_eq!(x, full, "{i}");
            } else {
                rejected += 1;
            }
        }
        assert!(rejected > 0 && rejected < 300, "{rejected}");
    }

    /// PTRS split in two (`first`, then `rest` when the fast test fails) is
    /// exactly `poisson` on the same stream.
    #[test]
    fn split_ptrs_is_poisson() {
        for mu in [10.0, 37.5, 1000.0] {
            let mut rejected = 0;
            for i in 0..5_000u64 {
                let want = PixelRng::new(9, stream::PHOTON, i).poisson(mu);
                let mut r = PixelRng::new(9, stream::PHOTON, i);
                let p = r.poisson_ptrs_first(mu);
                let got = if p.accepted {
                    p.k
                } else {
                    rejected += 1;
                    r.poisson_ptrs_rest(mu, p)
                };
                assert_eq!(got, want, "μ {mu}, stream {i}");
            }
            assert!(rejected > 0, "μ {mu}");
        }
    }

    /// Sequential inversion at a tiny mean: P(0) = e^−μ, so almost every
    /// draw is 0; at μ = 1e-300 the underflow guard still ends the search.
    #[test]
    fn poisson_at_tiny_means() {
        let zeros = (0..10_000u64)
            .filter(|&i| PixelRng::new(1, stream::PHOTON, i).poisson(1e-3) == 0.0)
            .count();
        // Expected 9990, binomial σ ≈ 3.2.
        assert!(zeros >= 9975, "{zeros}");
        for i in 0..1000u64 {
            let k = PixelRng::new(2, stream::PHOTON, i).poisson(1e-300);
            assert!(k == 0.0 || k == 1.0, "{k}");
        }
    }
}

#[cfg(test)]
mod slow_path_tests;
