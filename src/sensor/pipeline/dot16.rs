//! A row's signal rates sixteen pixels at a time with AVX-512 (issue 17 item 5):
//! the same dot products and validity checks as [`super::dot_check`], bit for bit,
//! for spectra of 16 to 32 bands.
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
    if !(L..=2 * L).contains(&nb) || w.iter().any(|wc| wc.len() < nb) {
        return (0, false);
    }
    let n = out.len().min(chans.len()).min(irr.len() / nb);
    let blocks = n / L;
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
