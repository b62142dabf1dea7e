//! The first two normals of many pixels' streams at once (issue 17 item 5): for
//! pixel `c` of a row, outputs 1 and 2 of the stream of (`stream_key`, `item0 + c`)
//! through [`PixelRng::normal_fast`](super::PixelRng::normal_fast) — the fixed
//! pattern's (PRNU, DSNU) and the read and reset noise's common case.
//!
//! Written as a plain loop ([`first_normals`]), the compiler vectorised it two
//! lanes wide at best: the ziggurat's table lookups are gathers, which its cost
//! model declines at AVX-512, so `camsim bench sensor` spent most of the readout's
//! time in 128-bit code (perf annotate). [`first_normals_avx512`] takes eight
//! pixels per instruction: SplitMix64 in 64-bit lanes (`vpmullq`), the table
//! entries by `vgatherqpd`, and the same IEEE operations as `normal_fast` (exact
//! conversion of the top 53 bits, the products and the difference, no fused
//! multiply-add): the same bits
//! (`first_normals_are_normal_fast_at_every_level`). [`first_normals_avx2`] does
//! the same four pixels per instruction with AVX2's 32-bit multiplies and an
//! exact two-part conversion (`camsim bench sensor` at `CAMSIM_SENSOR_ISA=avx2`:
//! 0.94–0.96 of the time before, docs/performance.md). Both share the block
//! driver `in_blocks`.

use super::{GAMMA, ITEM_MUL, MIX_MUL, MIX_SHIFT, PixelRng, ZIG_N};
use crate::sensor::prefetch::Prefetch;

/// Where [`first_normals`] puts a row's normals: pixel c's first normal and
/// whether `normal_fast` accepted it in `x1[c]`, `ok1[c]`, its second in `x2[c]`,
/// `ok2[c]` (the four rows of one length).
pub struct FirstNormals<'a> {
    pub x1: &'a mut [f64],
    pub x2: &'a mut [f64],
    pub ok1: &'a mut [bool],
    pub ok2: &'a mut [bool],
}

/// `normal_fast` of outputs 1 and 2 of the stream of (`stream_key`, `item0 + c`)
/// into `out` for every pixel `c` of its rows. `x_table` is
/// [`ziggurat_x`](super::ziggurat_x).
#[inline(always)]
pub fn first_normals(
    x_table: &[f64; ZIG_N + 1],
    stream_key: u64,
    item0: u64,
    out: FirstNormals<'_>,
    warm: Prefetch<'_>,
) {
    let FirstNormals { x1, x2, ok1, ok2 } = out;
    let mut warm = warm.over(x1.len());
    for (c, (((a, b), oa), ob)) in x1
        .iter_mut()
        .zip(x2.iter_mut())
        .zip(ok1.iter_mut())
        .zip(ok2.iter_mut())
        .enumerate()
    {
        warm.step();
        let item = item0 + c as u64;
        (*a, *oa) = PixelRng::normal_fast(PixelRng::keyed_output(stream_key, item, 1), x_table);
        (*b, *ob) = PixelRng::normal_fast(PixelRng::keyed_output(stream_key, item, 2), x_table);
    }
}

/// [`first_normals`] `W` pixels at a time: `block(item, x1, x2)` writes the
/// normals of the `W` pixels from stream item `item` into `x1` and `x2` and
/// returns their acceptances as lane masks (bit j for lane j); the pixels after
/// the last whole block by the plain loop. `warm` is spread over the blocks.
#[inline(always)]
fn in_blocks<const W: usize>(
    x_table: &[f64; ZIG_N + 1],
    stream_key: u64,
    item0: u64,
    out: FirstNormals<'_>,
    warm: Prefetch<'_>,
    mut block: impl FnMut(u64, &mut [f64], &mut [f64]) -> (u32, u32),
) {
    let FirstNormals { x1, x2, ok1, ok2 } = out;
    let n = x1.len().min(x2.len()).min(ok1.len()).min(ok2.len());
    let whole = n / W * W;
    let mut warm = warm.over(whole / W);
    for c in (0..whole).step_by(W) {
        warm.step();
        let (m1, m2) = block(
            item0.wrapping_add(c as u64),
            &mut x1[c..c + W],
            &mut x2[c..c + W],
        );
        for j in 0..W {
            ok1[c + j] = m1 & (1 << j) != 0;
            ok2[c + j] = m2 & (1 << j) != 0;
        }
    }
    let rest = FirstNormals {
        x1: &mut x1[whole..n],
        x2: &mut x2[whole..n],
        ok1: &mut ok1[whole..n],
        ok2: &mut ok2[whole..n],
    };
    first_normals(
        x_table,
        stream_key,
        item0.wrapping_add(whole as u64),
        rest,
        warm,
    );
}

/// [`first_normals`] eight pixels per instruction.
///
/// # Safety
/// The CPU must have AVX-512F and AVX-512DQ (the readout's `Isa::Avx512`).
#[cfg(target_arch = "x86_64")]
#[target_feature(enable = "avx512f,avx512dq,avx512vl,avx512bw,avx2,fma")]
pub fn first_normals_avx512(
    x_table: &[f64; ZIG_N + 1],
    stream_key: u64,
    item0: u64,
    out: FirstNormals<'_>,
    warm: Prefetch<'_>,
) {
    use std::arch::x86_64::*;
    const W: usize = 8;
    let q = |v: u64| _mm512_set1_epi64(v as i64);
    let (k_item, key) = (q(ITEM_MUL), q(stream_key));
    let (c1, c2) = (q(MIX_MUL[0]), q(MIX_MUL[1]));
    let (g1, g2) = (q(GAMMA), q(GAMMA.wrapping_mul(2)));
    let low8 = q(0xff);
    let one_i = q(1);
    let scale = _mm512_set1_pd(1.0 / (1u64 << 53) as f64);
    let (two, one) = (_mm512_set1_pd(2.0), _mm512_set1_pd(1.0));
    let mix = |z: __m512i| {
        let s0 = _mm512_srli_epi64::<{ MIX_SHIFT[0] }>(z);
        let z = _mm512_mullo_epi64(_mm512_xor_si512(z, s0), c1);
        let s1 = _mm512_srli_epi64::<{ MIX_SHIFT[1] }>(z);
        let z = _mm512_mullo_epi64(_mm512_xor_si512(z, s1), c2);
        _mm512_xor_si512(z, _mm512_srli_epi64::<{ MIX_SHIFT[2] }>(z))
    };
    let table = x_table.as_ptr();
    // (x, |x| < x_table[i + 1]) of one output per lane
    let normal = |bits: __m512i| {
        let i = _mm512_and_si512(bits, low8);
        let top = _mm512_cvtepu64_pd(_mm512_srli_epi64::<11>(bits));
        let u = _mm512_sub_pd(_mm512_mul_pd(two, _mm512_mul_pd(top, scale)), one);
        // SAFETY: i ≤ 255, so i and i + 1 index the table's ZIG_N + 1 = 257 entries.
        let (xi, xi1) = unsafe {
            (
                _mm512_i64gather_pd::<8>(i, table),
                _mm512_i64gather_pd::<8>(_mm512_add_epi64(i, one_i), table),
            )
        };
        let x = _mm512_mul_pd(u, xi);
        (x, _mm512_cmp_pd_mask::<_CMP_LT_OQ>(_mm512_abs_pd(x), xi1))
    };
    let lanes = _mm512_setr_epi64(0, 1, 2, 3, 4, 5, 6, 7);
    in_blocks::<W>(x_table, stream_key, item0, out, warm, |item0, x1, x2| {
        let item = _mm512_add_epi64(q(item0), lanes);
        let start = mix(_mm512_xor_si512(key, _mm512_mullo_epi64(item, k_item)));
        let (xa, ma) = normal(mix(_mm512_add_epi64(start, g1)));
        let (xb, mb) = normal(mix(_mm512_add_epi64(start, g2)));
        // SAFETY: `in_blocks` hands out W = 8 floats in each of x1 and x2.
        unsafe {
            _mm512_storeu_pd(x1.as_mut_ptr(), xa);
            _mm512_storeu_pd(x2.as_mut_ptr(), xb);
        }
        (u32::from(ma), u32::from(mb))
    });
}

/// [`first_normals`] four pixels per instruction with AVX2, where there is
/// neither a 64-bit multiply nor a 64-bit integer to double conversion: the
/// multiply from three 32×32-bit products (`vpmuludq`; the low 64 bits of the
/// product, as `wrapping_mul`), the top 53 bits of an output converted as two
/// exact halves (the high 21 bits and the low 32 bits, each put under an
/// exponent and the exponent taken away, then added: exact below 2⁵³). The
/// table entries by one 16-byte load a lane (x\[i\] and x\[i + 1\] side by side)
/// and `normal_fast`'s IEEE operations as at AVX-512: the same bits.
///
/// # Safety
/// The CPU must have AVX2 (the readout's `Isa::Avx2`).
#[cfg(target_arch = "x86_64")]
#[target_feature(enable = "avx2,fma")]
pub fn first_normals_avx2(
    x_table: &[f64; ZIG_N + 1],
    stream_key: u64,
    item0: u64,
    out: FirstNormals<'_>,
    warm: Prefetch<'_>,
) {
    use std::arch::x86_64::*;
    const W: usize = 4;
    let q = |v: u64| _mm256_set1_epi64x(v as i64);
    // The low 64 bits of z·m for a constant m (its high half `m >> 32`).
    let mul = |z: __m256i, m: u64| {
        let (m_lo, m_hi) = (q(m & 0xffff_ffff), q(m >> 32));
        let lo = _mm256_mul_epu32(z, m_lo);
        let cross = _mm256_add_epi64(
            _mm256_mul_epu32(_mm256_srli_epi64::<32>(z), m_lo),
            _mm256_mul_epu32(z, m_hi),
        );
        _mm256_add_epi64(lo, _mm256_slli_epi64::<32>(cross))
    };
    let key = q(stream_key);
    let (g1, g2) = (q(GAMMA), q(GAMMA.wrapping_mul(2)));
    let low8 = q(0xff);
    let abs_mask = _mm256_castsi256_pd(q(0x7fff_ffff_ffff_ffff));
    // 2⁰ and 2³² as bit patterns, and 2³² + 2 as a double.
    let (e0, e32) = (q(0x3ff0_0000_0000_0000), q(0x41f0_0000_0000_0000));
    let e32_2 = _mm256_set1_pd((1u64 << 32) as f64 + 2.0);
    let low32 = q(0xffff_ffff);
    let mix = |z: __m256i| {
        let s0 = _mm256_srli_epi64::<{ MIX_SHIFT[0] as i32 }>(z);
        let z = mul(_mm256_xor_si256(z, s0), MIX_MUL[0]);
        let s1 = _mm256_srli_epi64::<{ MIX_SHIFT[1] as i32 }>(z);
        let z = mul(_mm256_xor_si256(z, s1), MIX_MUL[1]);
        _mm256_xor_si256(z, _mm256_srli_epi64::<{ MIX_SHIFT[2] as i32 }>(z))
    };
    let table = x_table.as_ptr();
    // (x, |x| < x_table[i + 1]) of one output per lane
    let normal = |bits: __m256i| {
        let i = _mm256_and_si256(bits, low8);
        let top53 = _mm256_srli_epi64::<11>(bits);
        // u = 2·top·2⁻⁵³ − 1 = top·2⁻⁵² − 1 from the top 53 bits' two halves:
        // hi = 2³² + h·2⁻²⁰ and lo = 1 + l·2⁻⁵² (the bits under an exponent);
        // (hi − (2³² + 2)) = h·2⁻²⁰ − 2 is exact, and so is its sum with lo, which
        // is u itself (a multiple of 2⁻⁵² in [−1, 1)): the same bits as
        // `normal_fast`'s conversion, product and difference.
        let hi = _mm256_castsi256_pd(_mm256_or_si256(_mm256_srli_epi64::<32>(top53), e32));
        let lo = _mm256_castsi256_pd(_mm256_or_si256(_mm256_and_si256(top53, low32), e0));
        let u = _mm256_add_pd(_mm256_sub_pd(hi, e32_2), lo);
        // Each lane's x[i] and x[i + 1] are neighbours in the table: one 16-byte
        // load a lane, the four pairs then transposed into (x[i]…) and (x[i + 1]…).
        // Zen 3's `vgatherqpd` took ≈ 8 cycles each (two a normal); this pass is
        // 0.92 of its time with the gathers (docs/performance.md, *Thirtieth pass*).
        // SAFETY: i ≤ 255, so i and i + 1 index the table's ZIG_N + 1 = 257 entries.
        let (xi, xi1) = unsafe {
            let pair = |k: i64| _mm_loadu_pd(table.add(k as usize));
            let (i01, i23) = (_mm256_castsi256_si128(i), _mm256_extracti128_si256::<1>(i));
            let a = pair(_mm_cvtsi128_si64(i01));
            let b = pair(_mm_extract_epi64::<1>(i01));
            let c = pair(_mm_cvtsi128_si64(i23));
            let d = pair(_mm_extract_epi64::<1>(i23));
            let ac = _mm256_insertf128_pd::<1>(_mm256_castpd128_pd256(a), c);
            let bd = _mm256_insertf128_pd::<1>(_mm256_castpd128_pd256(b), d);
            (_mm256_unpacklo_pd(ac, bd), _mm256_unpackhi_pd(ac, bd))
        };
        let x = _mm256_mul_pd(u, xi);
        let ok = _mm256_cmp_pd::<_CMP_LT_OQ>(_mm256_and_pd(x, abs_mask), xi1);
        (x, _mm256_movemask_pd(ok))
    };
    let lanes = _mm256_setr_epi64x(0, 1, 2, 3);
    // One block of four at a time. Measured on a Zen 3 and dropped
    // (docs/performance.md, *Twenty-eighth pass*): two independent blocks per
    // iteration (6 % slower: register spills), the starts in a pass of their
    // own (no faster), a fifth or sixth pixel drawn in scalar code beside the
    // vector (8 % / 17 % slower), the cross products by one `vpmulld` (no faster).
    in_blocks::<W>(x_table, stream_key, item0, out, warm, |item0, x1, x2| {
        let item = _mm256_add_epi64(q(item0), lanes);
        let start = mix(_mm256_xor_si256(key, mul(item, ITEM_MUL)));
        let (xa, ma) = normal(mix(_mm256_add_epi64(start, g1)));
        let (xb, mb) = normal(mix(_mm256_add_epi64(start, g2)));
        // SAFETY: `in_blocks` hands out W = 4 floats in each of x1 and x2.
        unsafe {
            _mm256_storeu_pd(x1.as_mut_ptr(), xa);
            _mm256_storeu_pd(x2.as_mut_ptr(), xb);
        }
        (ma as u32, mb as u32)
    });
}

#[cfg(test)]
mod tests {
    use super::super::ziggurat_x;
    use super::*;

    fn rows<'a>(
        x1: &'a mut [f64],
        x2: &'a mut [f64],
        ok1: &'a mut [bool],
        ok2: &'a mut [bool],
    ) -> FirstNormals<'a> {
        FirstNormals { x1, x2, ok1, ok2 }
    }

    /// Every level gives `normal_fast`'s values and acceptances bit for bit, for
    /// rows of every length around the vector width (tails included), at item
    /// offsets across 2³² and near u64's end, and the draws are the streams'
    /// (a fixed item's first normal is `PixelRng::normal`'s when accepted).
    #[test]
    fn first_normals_are_normal_fast_at_every_level() {
        let zx = ziggurat_x();
        for (key, item0) in [
            (PixelRng::stream_key(3, 1), 0u64),
            (PixelRng::stream_key(9, 4), (1 << 32) - 5),
            (u64::MAX, u64::MAX - 40),
        ] {
            for n in [0usize, 1, 7, 8, 9, 16, 37] {
                let want: Vec<_> = (0..n as u64)
                    .map(|c| {
                        let item = item0.wrapping_add(c);
                        let x1 = PixelRng::normal_fast(PixelRng::keyed_output(key, item, 1), zx);
                        let x2 = PixelRng::normal_fast(PixelRng::keyed_output(key, item, 2), zx);
                        (x1.0.to_bits(), x1.1, x2.0.to_bits(), x2.1)
                    })
                    .collect();
                let check = |a: &[f64], b: &[f64], oa: &[bool], ob: &[bool], level: &str| {
                    for c in 0..n {
                        let got = (a[c].to_bits(), oa[c], b[c].to_bits(), ob[c]);
                        assert_eq!(got, want[c], "{level}: n {n}, pixel {c}");
                    }
                };
                let (mut a, mut b) = (vec![0.0; n], vec![0.0; n]);
                let (mut oa, mut ob) = (vec![false; n], vec![false; n]);
                first_normals(
                    zx,
                    key,
                    item0,
                    rows(&mut a, &mut b, &mut oa, &mut ob),
                    Prefetch::none(),
                );
                check(&a, &b, &oa, &ob, "generic");
                #[cfg(target_arch = "x86_64")]
                if crate::sensor::readout::Isa::detect() == crate::sensor::readout::Isa::Avx512 {
                    let (mut a, mut b) = (vec![0.0; n], vec![0.0; n]);
                    let (mut oa, mut ob) = (vec![true; n], vec![true; n]);
                    let out = rows(&mut a, &mut b, &mut oa, &mut ob);
                    // SAFETY: the CPU has AVX-512 (Isa::detect).
                    unsafe { first_normals_avx512(zx, key, item0, out, Prefetch::none()) };
                    check(&a, &b, &oa, &ob, "avx512");
                }
                #[cfg(target_arch = "x86_64")]
                if crate::sensor::readout::Isa::detect() != crate::sensor::readout::Isa::Baseline {
                    let (mut a, mut b) = (vec![0.0; n], vec![0.0; n]);
                    let (mut oa, mut ob) = (vec![true; n], vec![true; n]);
                    let out = rows(&mut a, &mut b, &mut oa, &mut ob);
                    // SAFETY: the CPU has AVX2 (Isa::detect above baseline).
                    unsafe { first_normals_avx2(zx, key, item0, out, Prefetch::none()) };
                    check(&a, &b, &oa, &ob, "avx2");
                }
            }
        }
        // The streams' own draws: an accepted first normal is `normal()`'s.
        let key = PixelRng::stream_key(3, 1);
        let (mut a, mut b) = (vec![0.0; 64], vec![0.0; 64]);
        let (mut oa, mut ob) = (vec![false; 64], vec![false; 64]);
        first_normals(
            zx,
            key,
            100,
            rows(&mut a, &mut b, &mut oa, &mut ob),
            Prefetch::none(),
        );
        let mut rejected = 0;
        for c in 0..64 {
            let mut r = PixelRng::keyed(key, 100 + c as u64);
            let x1 = r.normal();
            if oa[c] {
                assert_eq!(a[c].to_bits(), x1.to_bits(), "pixel {c}");
                if ob[c] {
                    assert_eq!(b[c].to_bits(), r.normal().to_bits(), "pixel {c}");
                }
            } else {
                rejected += 1;
            }
        }
        assert!(
            rejected < 8,
            "{rejected} of 64 first normals rejected (≈ 1 % expected)"
        );
    }
}
