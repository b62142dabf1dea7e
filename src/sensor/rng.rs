//! Counter-based random numbers for the sensor: every pixel draws from its own
//! stream, keyed by (seed, noise source, full-frame pixel index), so a frame is
//! bit-identical for any thread count and any window of the frame.
//!
//! - [`PixelRng`]: SplitMix64 stream (Steele et al. 2014) started from a mixed key.
//! - [`PixelRng::normal`]: Box–Muller, both values used.
//! - [`PixelRng::poisson`]: exact Poisson at every mean: sequential inversion for
//!   μ < 10, Hörmann's PTRS transformed rejection (1993) for μ ≥ 10. No Gaussian
//!   approximation anywhere.

use std::sync::OnceLock;

/// Stream identifiers (one per noise source) so sources never share numbers.
pub mod stream {
    pub const PHOTON: u64 = 0x1;
    pub const READ: u64 = 0x2;
    pub const FPN_PIXEL: u64 = 0x3;
    pub const FPN_COLUMN: u64 = 0x4;
}

#[inline]
fn mix64(mut z: u64) -> u64 {
    z = (z ^ (z >> 30)).wrapping_mul(0xbf58_476d_1ce4_e5b9);
    z = (z ^ (z >> 27)).wrapping_mul(0x94d0_49bb_1331_11eb);
    z ^ (z >> 31)
}

/// A small random stream for one (seed, source, item).
#[derive(Clone, Debug)]
pub struct PixelRng {
    state: u64,
    spare: Option<f64>,
}

const GAMMA: u64 = 0x9e37_79b9_7f4a_7c15;

impl PixelRng {
    /// The stream for `item` (e.g. full-frame pixel index) of `source` under `seed`.
    #[inline]
    pub fn new(seed: u64, source: u64, item: u64) -> Self {
        let k = mix64(seed.wrapping_add(GAMMA.wrapping_mul(source.wrapping_add(1))));
        let k = mix64(k ^ item.wrapping_mul(0xd1b5_4a32_d192_ed03));
        Self {
            state: k,
            spare: None,
        }
    }
    #[inline]
    pub fn next_u64(&mut self) -> u64 {
        self.state = self.state.wrapping_add(GAMMA);
        mix64(self.state)
    }
    /// Uniform in [0, 1) with 53 random bits.
    #[inline]
    pub fn uniform(&mut self) -> f64 {
        (self.next_u64() >> 11) as f64 * (1.0 / (1u64 << 53) as f64)
    }
    /// Uniform in (0, 1].
    #[inline]
    fn uniform_open0(&mut self) -> f64 {
        ((self.next_u64() >> 11) + 1) as f64 * (1.0 / (1u64 << 53) as f64)
    }
    /// Standard normal (Box–Muller; the second value is kept for the next call).
    #[inline]
    pub fn normal(&mut self) -> f64 {
        if let Some(z) = self.spare.take() {
            return z;
        }
        let u1 = self.uniform_open0();
        let u2 = self.uniform();
        let r = (-2.0 * u1.ln()).sqrt();
        let (s, c) = (std::f64::consts::TAU * u2).sin_cos();
        self.spare = Some(r * s);
        r * c
    }
    /// Exact Poisson variate with mean `mu` (≥ 0; non-finite or negative gives 0).
    #[inline]
    pub fn poisson(&mut self, mu: f64) -> f64 {
        if mu.is_nan() || mu <= 0.0 {
            return 0.0;
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
    fn poisson_ptrs(&mut self, mu: f64) -> f64 {
        let smu = mu.sqrt();
        let b = 0.931 + 2.53 * smu;
        let a = -0.059 + 0.02483 * b;
        let inv_alpha = 1.1239 + 1.1328 / (b - 3.4);
        let v_r = 0.9277 - 3.6224 / (b - 2.0);
        let log_mu = mu.ln();
        loop {
            let u = self.uniform() - 0.5;
            let v = self.uniform();
            let us = 0.5 - u.abs();
            let k = ((2.0 * a / us + b) * u + mu + 0.43).floor();
            if us >= 0.07 && v <= v_r {
                return k;
            }
            if k < 0.0 || (us < 0.013 && v > us) {
                continue;
            }
            let lhs = (v * inv_alpha / (a / (us * us) + b)).ln();
            let rhs = -mu + k * log_mu - ln_factorial(k);
            if lhs <= rhs {
                return k;
            }
        }
    }
}

/// ln(k!) for integer-valued k ≥ 0: exact table below 256, Stirling series above
/// (truncation error < 1e-16 relative there).
pub fn ln_factorial(k: f64) -> f64 {
    static TABLE: OnceLock<Vec<f64>> = OnceLock::new();
    let t = TABLE.get_or_init(|| {
        let mut v = vec![0.0f64; 256];
        for i in 1..256 {
            v[i] = v[i - 1] + (i as f64).ln();
        }
        v
    });
    if k < 256.0 {
        return t[k.max(0.0) as usize];
    }
    let n = k + 1.0; // ln Γ(n)
    let inv = 1.0 / n;
    let inv2 = inv * inv;
    (n - 0.5) * n.ln() - n
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
        assert!(PixelRng::new(0, 0, 0).poisson(f64::NAN) == 0.0);
        assert!(PixelRng::new(0, 0, 0).poisson(-1.0) == 0.0);
    }
}
