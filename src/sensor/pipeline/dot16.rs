//! A row's signal rates sixteen pixels at a time with AVX-512, eight with AVX2
//! (issue 17 item 5): the same dot products and validity checks as
//! [`super::dot_check`], bit for bit, for spectra of 16 to 32 bands.
//!
//! [`super::dot_check`] ends every pixel with two horizontal sums over its sixteen
//! lanes (products and bands), each a four-level binary tree whose levels depend on
//! one another: per pixel a chain of shuffles and adds the compiler could not
//! overlap with the next pixel's loads (`camsim bench sensor`: the pass took ≈ 2× the
//! time a plain read of the optical image takes). Here the sixteen pixels of a block
//! are reduced together: each tree level adds the halves of two registers at once
//! (`_mm512_shuffle_f32x4` for the 8- and 4-lane halves, `_mm512_shuffle_ps` for the
//! 2- and 1-lane ones), so a level costs two shuffles and one add per pair of
//! pixels, and the sixteen results come out in one register (then put in pixel
//! order). Every lane of every pixel is added to the same partner, with the lower
//! half as the first operand, as `lane_tree_sum` does: the same IEEE operations in
//! the same order, so the same bits (`dot_row_gives_the_same_bits_at_every_level`).
//! The AVX2 kernel ([`dot_blocks_avx2`]) keeps a pixel's 16 lanes in two 256-bit
//! registers and reduces eight pixels together the same way.

#[cfg(target_arch = "x86_64")]
use std::arch::x86_64::*;

/// The dot products of the pixels of `out` (`chans[c]`: column c's weights in `w`;
/// `irr`: `nb` bands per pixel, 16 ≤ nb ≤ 32), whole blocks of 16 pixels only;
/// returns the pixels done (a multiple of 16) and whether any of them is invalid.
///
/// # Safety
/// The CPU must have AVX-512F (the caller's `Isa::Avx512`).
#[cfg(target_arch = "x86_64")]
#[target_feature(enable = "avx512f,avx512dq,avx512vl,avx512bw,avx2,fma")]
pub(super) fn dot_blocks_avx512(
    w: &[Vec<f32>],
    chans: &[u8],
    irr: &[f32],
    nb: usize,
    out: &mut [f32],
) -> (usize, bool) {
    const L: usize = 16;
    let blocks = block_pixels(w, chans, irr, nb, out) / L;
    // Lanes of the spectrum's last 16 bands that the first 16 did not cover.
    let r = nb - L;
    let tail: __mmask16 = !(((1u32 << (L - r)) - 1) as u16);
    let zero = _mm512_setzero_ps();
    // Output lane p = 4m + j of the reduced register holds pixel 4j + m.
    let order = _mm512_setr_epi32(0, 4, 8, 12, 1, 5, 9, 13, 2, 6, 10, 14, 3, 7, 11, 15);
    let mut neg: __mmask16 = 0;
    let mut sums_finite = true;
    for b in 0..blocks {
        let mut acc = [zero; L];
        let mut sum = [zero; L];
        for g in 0..L {
            let c = b * L + g;
            let wc = &w[chans[c] as usize][..nb];
            let p = &irr[c * nb..(c + 1) * nb];
            // SAFETY: `p` and `wc` hold nb ≥ 16 floats, so [0, 16) and
            // [nb − 16, nb) are inside both.
            let (p0, w0, p1, w1) = unsafe {
                (
                    _mm512_loadu_ps(p.as_ptr()),
                    _mm512_loadu_ps(wc.as_ptr()),
                    _mm512_maskz_loadu_ps(tail, p.as_ptr().add(nb - L)),
                    _mm512_maskz_loadu_ps(tail, wc.as_ptr().add(nb - L)),
                )
            };
            // acc = (0 + w·p) + w'·p' and sum = (0 + p) + p', lane by lane, as
            // `dot_check` (its lanes outside the tail add 0·0 and 0).
            let a = _mm512_add_ps(zero, _mm512_mul_ps(w0, p0));
            acc[g] = _mm512_add_ps(a, _mm512_mul_ps(w1, p1));
            sum[g] = _mm512_add_ps(_mm512_add_ps(zero, p0), p1);
            neg |= _mm512_cmp_ps_mask::<_CMP_LT_OQ>(p0, zero)
                | _mm512_cmp_ps_mask::<_CMP_LT_OQ>(p1, zero);
        }
        let d = _mm512_permutexvar_ps(order, tree16(&acc));
        let s = tree16(&sum);
        // finite: |s| < ∞ (false for NaN too)
        let abs = _mm512_abs_ps(s);
        let fin = _mm512_cmp_ps_mask::<_CMP_LT_OQ>(abs, _mm512_set1_ps(f32::INFINITY));
        sums_finite &= fin == 0xFFFF;
        // SAFETY: block b's 16 outputs are inside `out` (b < n / 16).
        unsafe { _mm512_storeu_ps(out.as_mut_ptr().add(b * L), d) };
    }
    (blocks * L, neg != 0 || !sums_finite)
}

/// The pixels the block kernels may take: those with an output, a channel and a
/// whole spectrum, when a spectrum has 16 to 32 bands and every channel's
/// weights at least as many (what makes their loads of bands [0, 16) and
/// [nb − 16, nb) sound); none otherwise.
#[cfg(target_arch = "x86_64")]
fn block_pixels(w: &[Vec<f32>], chans: &[u8], irr: &[f32], nb: usize, out: &[f32]) -> usize {
    const L: usize = 16;
    if !(L..=2 * L).contains(&nb) || w.iter().any(|wc| wc.len() < nb) {
        return 0;
    }
    out.len().min(chans.len()).min(irr.len() / nb)
}

/// The sixteen lane sums of `v` (one register per pixel) as `lane_tree_sum` adds
/// them: lanes i and i + 8, then i and i + 4, i and i + 2, i and i + 1, the lower
/// lane first. Pixel 4j + m's sum is in lane 4m + j.
#[cfg(target_arch = "x86_64")]
#[target_feature(enable = "avx512f")]
fn tree16(v: &[__m512; 16]) -> __m512 {
    // Level 8: pixels 2k, 2k + 1 → lanes 0–7 and 8–15 of h8[k].
    let mut h8 = [_mm512_setzero_ps(); 8];
    for k in 0..8 {
        let (a, b) = (v[2 * k], v[2 * k + 1]);
        let lo = _mm512_shuffle_f32x4::<0x44>(a, b);
        let hi = _mm512_shuffle_f32x4::<0xEE>(a, b);
        h8[k] = _mm512_add_ps(lo, hi);
    }
    // Level 4: quarter q of h4[m] is pixel 4m + q's four partial sums.
    let mut h4 = [_mm512_setzero_ps(); 4];
    for m in 0..4 {
        let (a, b) = (h8[2 * m], h8[2 * m + 1]);
        let lo = _mm512_shuffle_f32x4::<0x88>(a, b);
        let hi = _mm512_shuffle_f32x4::<0xDD>(a, b);
        h4[m] = _mm512_add_ps(lo, hi);
    }
    // Level 2: in quarter j, lanes 0–1 from h4[2n] and 2–3 from h4[2n + 1].
    let mut h2 = [_mm512_setzero_ps(); 2];
    for n in 0..2 {
        let (a, b) = (h4[2 * n], h4[2 * n + 1]);
        let lo = _mm512_shuffle_ps::<0x44>(a, b);
        let hi = _mm512_shuffle_ps::<0xEE>(a, b);
        h2[n] = _mm512_add_ps(lo, hi);
    }
    // Level 1: lane 4j + m is pixel 4m + j.
    let lo = _mm512_shuffle_ps::<0x88>(h2[0], h2[1]);
    let hi = _mm512_shuffle_ps::<0xDD>(h2[0], h2[1]);
    _mm512_add_ps(lo, hi)
}

/// [`dot_blocks_avx512`] for AVX2: whole blocks of 8 pixels, each pixel's 16
/// lanes in two 256-bit registers. The tree's first level (lanes i and i + 8) is
/// one add of a pixel's two registers; the next three (4, 2, 1) reduce the 8
/// pixels together as [`tree16`] does the 16 (`_mm256_permute2f128_ps` for the
/// 4-lane halves, `_mm256_shuffle_ps` for the 2- and 1-lane ones). The same IEEE
/// operations on the same lanes as `lane_tree_sum`: the same bits.
///
/// # Safety
/// The CPU must have AVX2 (the caller's `Isa::Avx2`).
#[cfg(target_arch = "x86_64")]
#[target_feature(enable = "avx2,fma")]
pub(super) fn dot_blocks_avx2(
    w: &[Vec<f32>],
    chans: &[u8],
    irr: &[f32],
    nb: usize,
    out: &mut [f32],
) -> (usize, bool) {
    const L: usize = 16;
    const P: usize = 8;
    let blocks = block_pixels(w, chans, irr, nb, out) / P;
    // Lanes of the spectrum's last 16 bands that the first 16 did not cover
    // (lane i ≥ 16 − r), as the two halves' load masks.
    let r = (nb - L) as i32;
    let lane = _mm256_setr_epi32(0, 1, 2, 3, 4, 5, 6, 7);
    let first_new = _mm256_set1_epi32(L as i32 - r - 1);
    let tail_lo = _mm256_cmpgt_epi32(lane, first_new);
    let tail_hi = _mm256_cmpgt_epi32(_mm256_add_epi32(lane, _mm256_set1_epi32(8)), first_new);
    let zero = _mm256_setzero_ps();
    // Output lane 4h + j of the reduced register holds pixel 2j + h.
    let order = _mm256_setr_epi32(0, 4, 1, 5, 2, 6, 3, 7);
    let mut neg = zero;
    let mut sums_finite = true;
    for b in 0..blocks {
        let mut acc = [zero; P];
        let mut sum = [zero; P];
        for g in 0..P {
            let c = b * P + g;
            let wc = &w[chans[c] as usize][..nb];
            let p = &irr[c * nb..(c + 1) * nb];
            // SAFETY: `p` and `wc` hold nb ≥ 16 floats, so [0, 16) and
            // [nb − 16, nb) are inside both.
            let (p0, p0h, w0, w0h, p1, p1h, w1, w1h) = unsafe {
                let (pp, wp) = (p.as_ptr(), wc.as_ptr());
                let (pt, wt) = (pp.add(nb - L), wp.add(nb - L));
                (
                    _mm256_loadu_ps(pp),
                    _mm256_loadu_ps(pp.add(8)),
                    _mm256_loadu_ps(wp),
                    _mm256_loadu_ps(wp.add(8)),
                    _mm256_maskload_ps(pt, tail_lo),
                    _mm256_maskload_ps(pt.add(8), tail_hi),
                    _mm256_maskload_ps(wt, tail_lo),
                    _mm256_maskload_ps(wt.add(8), tail_hi),
                )
            };
            // Per lane acc = (0 + w·p) + w'·p', sum = (0 + p) + p' (as
            // [`dot_blocks_avx512`]); then lanes i and i + 8 added.
            let a_lo = _mm256_add_ps(
                _mm256_add_ps(zero, _mm256_mul_ps(w0, p0)),
                _mm256_mul_ps(w1, p1),
            );
            let a_hi = _mm256_add_ps(
                _mm256_add_ps(zero, _mm256_mul_ps(w0h, p0h)),
                _mm256_mul_ps(w1h, p1h),
            );
            acc[g] = _mm256_add_ps(a_lo, a_hi);
            let s_lo = _mm256_add_ps(_mm256_add_ps(zero, p0), p1);
            let s_hi = _mm256_add_ps(_mm256_add_ps(zero, p0h), p1h);
            sum[g] = _mm256_add_ps(s_lo, s_hi);
            let lt = _mm256_or_ps(
                _mm256_or_ps(
                    _mm256_cmp_ps::<_CMP_LT_OQ>(p0, zero),
                    _mm256_cmp_ps::<_CMP_LT_OQ>(p0h, zero),
                ),
                _mm256_or_ps(
                    _mm256_cmp_ps::<_CMP_LT_OQ>(p1, zero),
                    _mm256_cmp_ps::<_CMP_LT_OQ>(p1h, zero),
                ),
            );
            neg = _mm256_or_ps(neg, lt);
        }
        let d = _mm256_permutevar8x32_ps(tree8(&acc), order);
        let s = tree8(&sum);
        // finite: |s| < ∞ (false for NaN too)
        let abs = _mm256_andnot_ps(_mm256_set1_ps(-0.0), s);
        let fin = _mm256_cmp_ps::<_CMP_LT_OQ>(abs, _mm256_set1_ps(f32::INFINITY));
        sums_finite &= _mm256_movemask_ps(fin) == 0xFF;
        // SAFETY: block b's 8 outputs are inside `out` (b < n / 8).
        unsafe { _mm256_storeu_ps(out.as_mut_ptr().add(b * P), d) };
    }
    (blocks * P, _mm256_movemask_ps(neg) != 0 || !sums_finite)
}

/// The eight 8-lane sums of `v` (one register per pixel, lanes i and i + 8 of
/// its 16 already added) as `lane_tree_sum` goes on: lanes i and i + 4, i and
/// i + 2, i and i + 1, the lower lane first. Pixel 2j + h's sum is in lane 4h + j.
#[cfg(target_arch = "x86_64")]
#[target_feature(enable = "avx2")]
fn tree8(v: &[__m256; 8]) -> __m256 {
    // Level 4: the low 128 bits of h4[k] are pixel 2k's four partial sums, the
    // high 128 bits pixel 2k + 1's.
    let mut h4 = [_mm256_setzero_ps(); 4];
    for k in 0..4 {
        let (a, b) = (v[2 * k], v[2 * k + 1]);
        let lo = _mm256_permute2f128_ps::<0x20>(a, b);
        let hi = _mm256_permute2f128_ps::<0x31>(a, b);
        h4[k] = _mm256_add_ps(lo, hi);
    }
    // Level 2: in each 128-bit half, lanes 0–1 from h4[2n] and 2–3 from h4[2n + 1].
    let mut h2 = [_mm256_setzero_ps(); 2];
    for n in 0..2 {
        let (a, b) = (h4[2 * n], h4[2 * n + 1]);
        let lo = _mm256_shuffle_ps::<0x44>(a, b);
        let hi = _mm256_shuffle_ps::<0xEE>(a, b);
        h2[n] = _mm256_add_ps(lo, hi);
    }
    // Level 1: lane 4h + j is pixel 2j + h.
    let lo = _mm256_shuffle_ps::<0x88>(h2[0], h2[1]);
    let hi = _mm256_shuffle_ps::<0xDD>(h2[0], h2[1]);
    _mm256_add_ps(lo, hi)
}
