//! How the sensor's vector kernels round to integers: the same values two ways.
//!
//! The PTRS proposal's ⌊x⌋ (the photon pass) and the readout's rounding of DV
//! run once per pixel. The release binary is built for baseline x86-64, which
//! has no rounding instruction (SSE4.1's `roundpd` came later): there `f64::floor`
//! and `f64::round` are libm calls, which keep a loop from vectorising, so the
//! baseline kernels round by adding and taking away 2⁵² ([`fast_floor`],
//! [`fast_round`]; five to seven operations a value, and a branch on |x| ≥ 2⁵²
//! that kept the DV loop scalar). The AVX2 and AVX-512 kernels are compiled with
//! SSE4.1 enabled, where `f64::floor` and `f64::trunc` are one `vroundpd` each;
//! they take [`RoundInsn`]. On the AVX2 EPYC (Zen 3) that took ≈ 7 % off the
//! readout row kernel's time (docs/performance.md, *Thirtieth pass*).
//!
//! Both give every value bit for bit as `x.floor() + 0.0` and `x.round() + 0.0`
//! (libm's, a zero always +0) for every x (`rounding_levels_agree_with_libm`);
//! which one a kernel takes changes its speed only. [`RoundInsn`] called from
//! code compiled without SSE4.1 is correct, a libm call a value.

use super::{fast_round, floor_below_2_52};

/// Rounding to integers for a vector kernel; see the module docs.
pub trait Rounding {
    /// ⌊x⌋ (+0 for a zero) where |x| < 2⁵²; a finite value or NaN otherwise
    /// (callers check that range themselves: PTRS's `exact`).
    fn floor_below_2_52(x: f64) -> f64;
    /// round(x), halves away from zero, +0 for a zero; exact for every x.
    fn round(x: f64) -> f64;
}

/// Without a rounding instruction (baseline x86-64): 2⁵² added and taken away.
pub struct RoundBits;

/// With SSE4.1's `roundpd` (the AVX2 and AVX-512 kernels; any non-x86 CPU has
/// an instruction of its own).
pub struct RoundInsn;

impl Rounding for RoundBits {
    #[inline(always)]
    fn floor_below_2_52(x: f64) -> f64 {
        floor_below_2_52(x)
    }
    #[inline(always)]
    fn round(x: f64) -> f64 {
        fast_round(x)
    }
}

impl Rounding for RoundInsn {
    #[inline(always)]
    fn floor_below_2_52(x: f64) -> f64 {
        // + 0.0 makes floor(−0) +0, as the bit version gives it
        x.floor() + 0.0
    }
    #[inline(always)]
    fn round(x: f64) -> f64 {
        // The truncation and the fraction are exact for every finite x (|x| ≥ 2⁵²:
        // x itself, fraction 0); the halves step the truncation away from zero,
        // and adding a 0 or 1 makes a zero +0. ±∞ keep their value (fraction NaN,
        // both tests false), NaN stays NaN.
        let t = x.trunc();
        let f = x - t;
        t + f64::from(u8::from(f >= 0.5)) - f64::from(u8::from(f <= -0.5))
    }
}

#[cfg(test)]
mod tests {
    use super::super::{PixelRng, TWO52, fast_floor};
    use super::*;

    /// Both ways give libm's floor and round bit for bit (a zero as +0) at
    /// zeros, halves and their neighbours, near and beyond 2⁵², at infinities
    /// and at 10⁵ random values; NaN stays NaN. Below 2⁵² for the floor, as
    /// the callers use it.
    #[test]
    fn rounding_levels_agree_with_libm() {
        let mut xs = vec![
            0.0,
            -0.0,
            1e-300,
            -1e-300,
            0.49999999999999994,
            -0.49999999999999994,
            TWO52 - 0.5,
            -(TWO52 - 0.5),
            TWO52,
            -TWO52,
            4.6e15,
            -4.6e15,
            1e300,
            -1e300,
            f64::INFINITY,
            f64::NEG_INFINITY,
        ];
        for k in -40..=40 {
            let h = k as f64 + 0.5;
            xs.extend([k as f64, h, k as f64 + 0.25, k as f64 - 0.25]);
            xs.extend([
                f64::from_bits(h.to_bits() + 1),
                f64::from_bits(h.to_bits() - 1),
            ]);
        }
        let mut r = PixelRng::new(4, 4, 4);
        xs.extend((0..100_000).map(|_| (r.uniform() - 0.5) * 2e4));
        for x in xs {
            let round = (x.round() + 0.0).to_bits();
            assert_eq!(RoundBits::round(x).to_bits(), round, "bits round {x}");
            assert_eq!(RoundInsn::round(x).to_bits(), round, "insn round {x}");
            if x.abs() < TWO52 {
                let floor = (x.floor() + 0.0).to_bits();
                assert_eq!(fast_floor(x).to_bits(), floor, "fast floor {x}");
                assert_eq!(RoundBits::floor_below_2_52(x).to_bits(), floor, "bits {x}");
                assert_eq!(RoundInsn::floor_below_2_52(x).to_bits(), floor, "insn {x}");
            }
        }
        assert!(RoundInsn::round(f64::NAN).is_nan() && RoundBits::round(f64::NAN).is_nan());
        assert!(RoundInsn::floor_below_2_52(f64::NAN).is_nan());
    }
}
