//! The instruction set the path tracer's per-row kernel runs with, chosen at
//! run time (issue 17 item 2): one release binary holds the kernel compiled
//! three times — for x86-64's SSE2 baseline, for AVX2+FMA and for AVX-512 —
//! and `RenderIsa::detect` picks the widest the CPU and the OS support.
//! `CAMSIM_RENDER_ISA=sse|avx2|avx512` lowers it (to compare levels; a level
//! the machine lacks is never used), like `CAMSIM_SENSOR_ISA` for the sensor.
//!
//! How: the film's row kernel (`film::RunJob::run`), the integrator, BVH
//! traversal, light sampling and the BSDFs are `#[inline(always)]` down to
//! the leaves, so each `#[target_feature]` entry point in `film.rs` gets its
//! own copy of the whole kernel, in which the compiler uses the wider registers (the 31-band loops
//! run 8 or 16 bands per instruction) and VEX/EVEX encodings. Only the
//! camera's `sample_ray` (a dynamic call) stays at the baseline.
//!
//! Same bits at every level: Rust never contracts a·b + c into a fused
//! multiply-add and LLVM does not reorder float reductions without fast-math
//! flags, so every level does the same IEEE operations in the same order;
//! `wide`'s 4-lane types are compiled for the baseline either way and libm
//! calls are the same functions. `tests` renders one scene at every level the
//! machine has and compares the images bit for bit.

/// A level of the render kernel (ordered narrow to wide).
#[derive(Clone, Copy, Debug, PartialEq, Eq, PartialOrd, Ord)]
pub enum RenderIsa {
    /// x86-64's SSE2 baseline (also the only level on other architectures).
    Sse,
    /// AVX2 with FMA (FMA is enabled for the encodings; no code fuses).
    Avx2,
    /// AVX-512 F/VL/BW/DQ with AVX2 and FMA.
    Avx512,
}

impl RenderIsa {
    /// The levels, narrow to wide.
    pub const ALL: [RenderIsa; 3] = [RenderIsa::Sse, RenderIsa::Avx2, RenderIsa::Avx512];

    /// True when this CPU and OS support the level.
    pub fn supported(self) -> bool {
        #[cfg(target_arch = "x86_64")]
        {
            let avx2 = || {
                std::arch::is_x86_feature_detected!("avx2")
                    && std::arch::is_x86_feature_detected!("fma")
                    && std::arch::is_x86_feature_detected!("bmi1")
                    && std::arch::is_x86_feature_detected!("bmi2")
                    && std::arch::is_x86_feature_detected!("lzcnt")
                    && std::arch::is_x86_feature_detected!("popcnt")
            };
            match self {
                RenderIsa::Sse => true,
                RenderIsa::Avx2 => avx2(),
                RenderIsa::Avx512 => {
                    avx2()
                        && std::arch::is_x86_feature_detected!("avx512f")
                        && std::arch::is_x86_feature_detected!("avx512vl")
                        && std::arch::is_x86_feature_detected!("avx512bw")
                        && std::arch::is_x86_feature_detected!("avx512dq")
                }
            }
        }
        #[cfg(not(target_arch = "x86_64"))]
        {
            self == RenderIsa::Sse
        }
    }

    /// The widest supported level, no wider than `CAMSIM_RENDER_ISA` asks
    /// (`sse` or `baseline`, `avx2`, `avx512`; anything else is ignored with
    /// a warning on stderr, once).
    pub fn detect() -> Self {
        let cap = std::env::var("CAMSIM_RENDER_ISA").unwrap_or_default();
        let max = match cap.as_str() {
            "sse" | "baseline" => RenderIsa::Sse,
            "avx2" => RenderIsa::Avx2,
            "" | "avx512" => RenderIsa::Avx512,
            _ => {
                static WARNED: std::sync::Once = std::sync::Once::new();
                WARNED.call_once(|| {
                    eprintln!(
                        "warning: CAMSIM_RENDER_ISA=\"{cap}\" ignored (expected sse, avx2 or avx512)"
                    )
                });
                RenderIsa::Avx512
            }
        };
        Self::ALL
            .into_iter()
            .rev()
            .find(|l| *l <= max && l.supported())
            .unwrap_or(RenderIsa::Sse)
    }

    /// The name reported by `camsim bench render` and the run manifest, in
    /// `machine::Cpu::vector`'s words.
    pub fn name(self) -> &'static str {
        match self {
            RenderIsa::Sse => "sse",
            RenderIsa::Avx2 => "avx2+fma",
            RenderIsa::Avx512 => "avx512f",
        }
    }
}

/// The sixteen lanes' own numbers, 0 to 15, for the AVX-512 kernels.
#[cfg(target_arch = "x86_64")]
#[target_feature(enable = "avx512f")]
#[inline]
pub(super) fn lane_numbers() -> std::arch::x86_64::__m512i {
    use std::arch::x86_64::*;
    _mm512_setr_epi32(0, 1, 2, 3, 4, 5, 6, 7, 8, 9, 10, 11, 12, 13, 14, 15)
}

/// For the AVX-512 kernels' gathers from an array of records `stride`
/// 4-byte words long: in each lane k, the offset in words of word `first`
/// of record `index[k]` (`index[k]·stride + first`; the caller keeps it in
/// `i32`).
#[cfg(target_arch = "x86_64")]
#[target_feature(enable = "avx512f")]
#[inline]
pub(super) fn record_offsets(
    index: std::arch::x86_64::__m512i,
    stride: usize,
    first: usize,
) -> std::arch::x86_64::__m512i {
    use std::arch::x86_64::*;
    _mm512_add_epi32(
        _mm512_mullo_epi32(index, _mm512_set1_epi32(stride as i32)),
        _mm512_set1_epi32(first as i32),
    )
}
