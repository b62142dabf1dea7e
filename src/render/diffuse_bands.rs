//! The band step of a packet's Lambertian bounce (`shade_packet::shade_diffuse`)
//! for all lanes at once, in the AVX-512 kernel: each lane's next-event
//! contribution and new throughput, band vector by band vector, its largest
//! band, then Russian roulette decided for the sixteen lanes together with
//! mask operations, and the survivors' throughput rescaled. Every other
//! instruction set keeps the lane loop of `shade_diffuse`.
//!
//! Why: in that lane loop each lane took two or three branches that follow
//! its own random draws (is the light sample unblocked-able, does the path
//! continue, does it survive roulette), and its band loops ran over a length
//! known only at run time; here the lanes' choices are masks and the band
//! loops are whole 16-band vectors, with the last one masked when the padded
//! band count is not a multiple of 16.
//!
//! Same bits as the lane loop: the same IEEE operations on the same
//! operands in the same order — the contribution `((β·(ρ·(1/π)))·Lₑ)·s`,
//! the throughput `β·ρ`, the largest band as `path::max_band` takes it (the
//! integer maximum of the bit patterns from 0), and `path::roulette`'s
//! arithmetic (the product with the refraction scale, the quotient by the
//! band count for a hero path, the reference, `1 − m`, `1/(1 − q)`).
//! `film::tests::every_isa_level_renders_the_same_bits` compares the levels.

use super::ray_packet::{LANES, LaneMask};

/// What the band step reads and writes: the packet's band vectors (lane
/// `l` owns `[l·stride, (l+1)·stride)` of `beta` and `pend`), and per lane
/// the reflectance of its material and the spectrum of its light, each at
/// least `stride` bands (a lane without a light sample may give its
/// reflectance), and its next-event scale.
pub(super) struct Bands<'a> {
    pub stride: usize,
    pub beta: &'a mut [f32],
    pub pend: &'a mut [f32],
    pub refl: &'a [&'a [f32]; LANES],
    pub emit: &'a [&'a [f32]; LANES],
    pub scale: &'a [f32; LANES],
}

/// Per lane, the path state roulette reads (after the bounce's depth
/// increment) and the reference it may set: the refraction scale, the
/// depth, the reference (updated in place for paths at their first bounce),
/// the roulette draw; and the lanes whose path carries a hero band.
pub(super) struct RouletteLanes<'a> {
    pub eta_scale: &'a [f32; LANES],
    pub depth: &'a [u32; LANES],
    pub rr_ref: &'a mut [f32; LANES],
    pub u_rr: &'a [f32; LANES],
    pub hero: LaneMask,
    /// The world's band count (a hero path's largest band is divided by it).
    pub bands: usize,
}

/// Lanes of `go`: write the next-event contribution of the lanes of `lit`
/// into `pend`, multiply the throughput of the lanes of `cont` by their
/// reflectance, then play Russian roulette on the lanes of `cont` as
/// `path::roulette` does and rescale the survivors' throughput. Returns the
/// lanes of `cont` whose path ends at roulette.
///
/// # Safety
/// The CPU must have AVX-512 F, VL, BW and DQ (`RenderIsa::Avx512`);
/// `lit` and `cont` are subsets of `go`; for every lane of `go`, its spans
/// of `beta` and `pend` and its `refl` and `emit` slices hold `stride`
/// bands.
#[cfg(target_arch = "x86_64")]
#[target_feature(enable = "avx512f,avx512vl,avx512bw,avx512dq")]
#[inline]
pub(super) unsafe fn step_avx512(
    go: LaneMask,
    lit: LaneMask,
    cont: LaneMask,
    b: Bands<'_>,
    rr: RouletteLanes<'_>,
) -> LaneMask {
    use std::arch::x86_64::*;
    let stride = b.stride;
    // The band vectors of one lane: full 16-band masks, the last one cut to
    // the bands left.
    let chunk_mask = |c: usize| -> __mmask16 {
        let left = stride - c;
        if left >= 16 {
            0xFFFF
        } else {
            ((1u32 << left) - 1) as __mmask16
        }
    };
    let mut max_bits = [0i32; LANES];
    // SAFETY: every load and store is masked to the lane's `stride` bands
    // (the caller's guarantee that they exist); the features are the
    // caller's guarantee.
    unsafe {
        let inv_pi = _mm512_set1_ps(1.0 / std::f32::consts::PI);
        let mut t = go;
        while t != 0 {
            let i = t.trailing_zeros() as usize;
            t &= t - 1;
            let base = i * stride;
            let beta = b.beta.as_mut_ptr().add(base);
            let pend = b.pend.as_mut_ptr().add(base);
            let (r, e) = (b.refl[i].as_ptr(), b.emit[i].as_ptr());
            let s = _mm512_set1_ps(b.scale[i]);
            // All bands of the lane, or none.
            let k_lit = (((lit >> i) & 1) as u16).wrapping_neg();
            let k_cont = (((cont >> i) & 1) as u16).wrapping_neg();
            let mut mx = _mm512_setzero_si512();
            let mut c = 0;
            while c < stride {
                let k = chunk_mask(c);
                let bv = _mm512_maskz_loadu_ps(k, beta.add(c));
                let rv = _mm512_maskz_loadu_ps(k, r.add(c));
                let ev = _mm512_maskz_loadu_ps(k & k_lit, e.add(c));
                let f = _mm512_mul_ps(rv, inv_pi);
                let p = _mm512_mul_ps(_mm512_mul_ps(_mm512_mul_ps(bv, f), ev), s);
                _mm512_mask_storeu_ps(pend.add(c), k & k_lit, p);
                let nb = _mm512_mul_ps(bv, rv);
                _mm512_mask_storeu_ps(beta.add(c), k & k_cont, nb);
                // Masked-off bands load as +0, which never raises the
                // maximum from 0.
                mx = _mm512_max_epi32(mx, _mm512_castps_si512(nb));
                c += 16;
            }
            max_bits[i] = _mm512_reduce_max_epi32(mx);
        }

        // Russian roulette, all lanes of `cont` at once (`path::roulette`).
        let zero = _mm512_setzero_ps();
        let one = _mm512_set1_ps(1.0);
        let live = cont as __mmask16;
        let m = _mm512_mul_ps(
            _mm512_castsi512_ps(_mm512_loadu_si512(max_bits.as_ptr().cast())),
            _mm512_loadu_ps(rr.eta_scale.as_ptr()),
        );
        let m = _mm512_mask_div_ps(m, rr.hero as __mmask16, m, _mm512_set1_ps(rr.bands as f32));
        // `!(m > 0)`: the path ends (a NaN maximum included).
        let pos = live & _mm512_cmp_ps_mask::<_CMP_GT_OQ>(m, zero);
        let depth = _mm512_loadu_si512(rr.depth.as_ptr().cast());
        let first = pos & _mm512_cmpeq_epu32_mask(depth, _mm512_set1_epi32(1));
        let later = pos & _mm512_cmpgt_epu32_mask(depth, _mm512_set1_epi32(1));
        // m > 0 is not NaN, so `min` is `f32::min`.
        let rr_ref = _mm512_mask_mov_ps(
            _mm512_loadu_ps(rr.rr_ref.as_ptr()),
            first,
            _mm512_min_ps(m, one),
        );
        _mm512_mask_storeu_ps(rr.rr_ref.as_mut_ptr(), first, rr_ref);
        let m = _mm512_div_ps(m, rr_ref);
        let play = later & _mm512_cmp_ps_mask::<_CMP_LT_OQ>(m, one);
        // m < 1 on these lanes, so 1 − m > 0 and `max` with 0 is `f32::max`.
        let q = _mm512_max_ps(_mm512_sub_ps(one, m), zero);
        let die = play & _mm512_cmp_ps_mask::<_CMP_LT_OQ>(_mm512_loadu_ps(rr.u_rr.as_ptr()), q);
        let rescale = play & !die;
        let mut sv = [0f32; LANES];
        _mm512_storeu_ps(sv.as_mut_ptr(), _mm512_div_ps(one, _mm512_sub_ps(one, q)));
        let mut t = rescale as LaneMask;
        while t != 0 {
            let i = t.trailing_zeros() as usize;
            t &= t - 1;
            let beta = b.beta.as_mut_ptr().add(i * stride);
            let s = _mm512_set1_ps(sv[i]);
            let mut c = 0;
            while c < stride {
                let k = chunk_mask(c);
                let bv = _mm512_maskz_loadu_ps(k, beta.add(c));
                _mm512_mask_storeu_ps(beta.add(c), k, _mm512_mul_ps(bv, s));
                c += 16;
            }
        }
        (live & !(pos & !die)) as LaneMask
    }
}
