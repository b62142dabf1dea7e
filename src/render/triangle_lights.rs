//! The lights of a world lit by one to four triangle area lights, as one
//! table (`TriangleLights`), so that the AVX-512 kernel chooses every lane's
//! light at once (`choose_avx512`): mask operations instead of the light-
//! choice lane loop of `shade_packet.rs`, which stays for every other world
//! and instruction set.
//!
//! Same bits as `World::choose_light` followed by the light's triangle: the
//! light is the first entry of the cumulative table above the draw
//! (`sampling::sample_cdf`; the table is non-decreasing, so that is the
//! light whose entries below are at or below the draw and whose own entry is
//! above it, the last light when none is), and the draw is remapped within
//! the light's slice as `world::remap_in_slice` does, with the same IEEE
//! operations (subtraction, division, the clamp's two comparisons).
//!
//! Why intrinsics: written as portable lane code, LLVM vectorised the
//! choice along the wrong axis (across the lights, or across the looked-up
//! quantities with masked scatters) or left it scalar, and it lost 3–15 %
//! (docs/performance.md, *Eighteenth pass*).

// The light loops index the table's per-light arrays and the masks together.
#![allow(clippy::needless_range_loop)]

use super::ray_packet::{LANES, LaneMask};
use super::sampling::ONE_MINUS_EPSILON;
use super::simd::RenderIsa;
use glam::Vec3;

/// At most this many lights go in the table.
const MAX_LIGHTS: usize = 4;

/// Per light k < n: its slice [lo, hi) of the cumulative table, selection
/// probability, triangle, unit geometric normal, area and sidedness.
pub(super) struct TriangleLights {
    n: usize,
    lo: [f32; MAX_LIGHTS],
    hi: [f32; MAX_LIGHTS],
    pmf: [f32; MAX_LIGHTS],
    v: [[Vec3; 3]; MAX_LIGHTS],
    ng: [Vec3; MAX_LIGHTS],
    area: [f32; MAX_LIGHTS],
    two_sided: [bool; MAX_LIGHTS],
}

/// One area light on a triangle: its vertices, unit geometric normal,
/// area and sidedness.
#[derive(Clone, Copy, Debug)]
pub(super) struct TriangleLight {
    pub v: [Vec3; 3],
    pub ng: Vec3,
    pub area: f32,
    pub two_sided: bool,
}

/// Where `choose_avx512` writes, per lane: the light's index, selection
/// probability, vertices (x, y, z columns of each), normal, area and
/// sidedness. Lanes that sample no light keep what they held.
pub(super) struct Chosen<'a> {
    pub light: &'a mut [usize; LANES],
    pub sel: &'a mut [f32; LANES],
    pub v: [[&'a mut [f32; LANES]; 3]; 3],
    pub ng: [&'a mut [f32; LANES]; 3],
    pub area: &'a mut [f32; LANES],
    pub two_sided: &'a mut [bool; LANES],
}

impl TriangleLights {
    /// The table, when the CPU has AVX-512 (only its kernel uses the
    /// table) and there are 1 to `MAX_LIGHTS` lights, every one a triangle
    /// light (`pmf`, `cdf`: the world's selection table).
    pub(super) fn build(lights: &[TriangleLight], pmf: &[f32], cdf: &[f32]) -> Option<Self> {
        let n = lights.len();
        if !RenderIsa::Avx512.supported() || n == 0 || n > MAX_LIGHTS {
            return None;
        }
        let mut t = TriangleLights {
            n,
            lo: [0.0; MAX_LIGHTS],
            hi: [0.0; MAX_LIGHTS],
            pmf: [0.0; MAX_LIGHTS],
            v: [[Vec3::ZERO; 3]; MAX_LIGHTS],
            ng: [Vec3::ZERO; MAX_LIGHTS],
            area: [0.0; MAX_LIGHTS],
            two_sided: [false; MAX_LIGHTS],
        };
        for (k, l) in lights.iter().enumerate() {
            t.lo[k] = if k == 0 { 0.0 } else { cdf[k - 1] };
            t.hi[k] = cdf[k];
            t.pmf[k] = pmf[k];
            t.v[k] = l.v;
            t.ng[k] = l.ng;
            t.area[k] = l.area;
            t.two_sided[k] = l.two_sided;
        }
        Some(t)
    }

    /// `choose_avx512` when the kernel running is AVX-512's (`isa`);
    /// `None` at every other level, whose kernel chooses lane by lane.
    #[inline(always)]
    pub(super) fn choose(
        &self,
        isa: RenderIsa,
        go: LaneMask,
        wo_z: &[f32; LANES],
        u1: &mut [f32; LANES],
        out: Chosen<'_>,
    ) -> Option<LaneMask> {
        #[cfg(target_arch = "x86_64")]
        if isa == RenderIsa::Avx512 {
            // SAFETY: a table is built only where the CPU has AVX-512
            // (`build`).
            return Some(unsafe { self.choose_avx512(go, wo_z, u1, out) });
        }
        let _ = (isa, go, wo_z, u1, out);
        None
    }

    /// Choose the light of the lanes of `go` whose `wo_z` is positive, with
    /// their draws `u1` (remapped in place, as `World::choose_light` remaps
    /// them), and write what the lanes whose light has a positive
    /// probability sample into `out`. Returns those lanes.
    ///
    /// # Safety
    /// The CPU must have AVX-512 F, VL, BW and DQ (`RenderIsa::Avx512`).
    #[cfg(target_arch = "x86_64")]
    #[target_feature(enable = "avx512f,avx512vl,avx512bw,avx512dq")]
    #[inline]
    pub(super) unsafe fn choose_avx512(
        &self,
        go: LaneMask,
        wo_z: &[f32; LANES],
        u1: &mut [f32; LANES],
        out: Chosen<'_>,
    ) -> LaneMask {
        use std::arch::x86_64::*;
        // SAFETY: 16-float loads and stores of 16-float arrays; the
        // features are the caller's guarantee.
        unsafe {
            let zero = _mm512_setzero_ps();
            let ask = (go as __mmask16)
                & _mm512_cmp_ps_mask::<_CMP_GT_OQ>(_mm512_loadu_ps(wo_z.as_ptr()), zero);
            let u = _mm512_loadu_ps(u1.as_ptr());
            // Light k: entries below k at or below the draw, entry k above it.
            let mut pick = [0 as __mmask16; MAX_LIGHTS];
            let mut below_prev: __mmask16 = 0xFFFF;
            for k in 0..self.n {
                let below = if k + 1 < self.n {
                    _mm512_cmp_ps_mask::<_CMP_LE_OQ>(_mm512_set1_ps(self.hi[k]), u)
                } else {
                    0
                };
                pick[k] = below_prev & !below;
                below_prev = below;
            }
            let each = |f: &dyn Fn(usize) -> f32| {
                let mut q = _mm512_set1_ps(f(0));
                for k in 1..self.n {
                    q = _mm512_mask_mov_ps(q, pick[k], _mm512_set1_ps(f(k)));
                }
                q
            };
            let (lo, hi, pm) = (
                each(&|k| self.lo[k]),
                each(&|k| self.hi[k]),
                each(&|k| self.pmf[k]),
            );
            // `remap_in_slice`: ((u − lo) / width).clamp(0, ONE_MINUS_EPSILON)
            // when width > 0, else 0.
            let width = _mm512_sub_ps(hi, lo);
            let r = _mm512_div_ps(_mm512_sub_ps(u, lo), width);
            let top = _mm512_set1_ps(ONE_MINUS_EPSILON);
            let r = _mm512_mask_mov_ps(r, _mm512_cmp_ps_mask::<_CMP_LT_OQ>(r, zero), zero);
            let r = _mm512_mask_mov_ps(r, _mm512_cmp_ps_mask::<_CMP_GT_OQ>(r, top), top);
            let rest = _mm512_maskz_mov_ps(_mm512_cmp_ps_mask::<_CMP_GT_OQ>(width, zero), r);
            _mm512_mask_storeu_ps(u1.as_mut_ptr(), ask, rest);
            let take = ask & _mm512_cmp_ps_mask::<_CMP_GT_OQ>(pm, zero);
            _mm512_mask_storeu_ps(out.sel.as_mut_ptr(), take, pm);
            let [v0, v1, v2] = out.v;
            for (j, [x, y, z]) in [v0, v1, v2].into_iter().enumerate() {
                _mm512_mask_storeu_ps(x.as_mut_ptr(), take, each(&|k| self.v[k][j].x));
                _mm512_mask_storeu_ps(y.as_mut_ptr(), take, each(&|k| self.v[k][j].y));
                _mm512_mask_storeu_ps(z.as_mut_ptr(), take, each(&|k| self.v[k][j].z));
            }
            let [nx, ny, nz] = out.ng;
            _mm512_mask_storeu_ps(nx.as_mut_ptr(), take, each(&|k| self.ng[k].x));
            _mm512_mask_storeu_ps(ny.as_mut_ptr(), take, each(&|k| self.ng[k].y));
            _mm512_mask_storeu_ps(nz.as_mut_ptr(), take, each(&|k| self.ng[k].z));
            _mm512_mask_storeu_ps(out.area.as_mut_ptr(), take, each(&|k| self.area[k]));
            let mut t = take as LaneMask;
            while t != 0 {
                let l = t.trailing_zeros() as usize;
                t &= t - 1;
                let k = (0..self.n).find(|&k| pick[k] & (1 << l) != 0).unwrap_or(0);
                out.light[l] = k;
                out.two_sided[l] = self.two_sided[k];
            }
            take as LaneMask
        }
    }
}
