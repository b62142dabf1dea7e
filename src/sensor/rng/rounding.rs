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
//! (libm's, a zero always +0) for every x (`fast_floor_and_round_match_libm` in
//! the parent module: zeros, halves and their neighbours, ±2⁵², infinities);
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
