//! The packet traversal of `bvh4_packet.rs` written with AVX-512 intrinsics
//! (issue 17): 16 rays in one `__m512` per quantity, lane masks in
//! `__mmask16` registers.
//!
//! Why a second copy: the portable lane code (`lanes.rs`, `[f32; 16]` loops
//! that LLVM vectorises inside the AVX-512 copy of the render kernel) turns
//! every comparison into a vector of 0 / −1 and back, and spills the 16-lane
//! arrays of the traversal stack; on the 2-core EPYC (Zen 4) one packet test of
//! the Cornell box's 36 triangles against 16 rays ran 60 ns per ray with
//! intrinsics against 118 ns with the lane arrays, and the packet BVH
//! traversal itself 88 ns per ray (docs/performance.md).
//!
//! Same bits: lane by lane the same IEEE operations in the same order as
//! `bvh4_packet.rs` (hence as the single-ray `bvh4.rs`): `_mm512_min_ps` /
//! `_mm512_max_ps` are `minps` / `maxps`, the NaN-aware max of `max3_abs` is
//! spelled out, nothing is fused (no FMA intrinsics; Rust does not contract).
//! The rare exact-zero edge falls back to the same scalar f64 code, and
//! spheres and disks to the scalar tests. `bvh4_packet::tests` compares this
//! kernel with the portable one and with single-ray queries.

// Lane loops index several per-lane arrays at once.
#![allow(clippy::needless_range_loop)]

use super::bvh4::{Bvh4, EMPTY, LEAF, Node4, STACK, TriPacket};
use super::geometry::{PrimHit, Shape, gamma};
use super::ray_packet::{ALL_LANES, LANES, LaneMask, PacketHits, RayPacket};
use std::arch::x86_64::*;
use std::mem::MaybeUninit;

/// A leaf with at least this many triangles is tested by a `Spread` when at
/// most four of the packet's rays reach it.
const SPREAD_MIN_TRIS: u32 = 2;

/// The exact-zero edge fallback of the watertight test, in f64.
#[inline(never)]
fn edge_f64(ax: f32, ay: f32, bx: f32, by: f32) -> f32 {
    (ax as f64 * by as f64 - ay as f64 * bx as f64) as f32
}

/// Per-packet ray constants (what `PacketPre` holds), in registers.
struct Pre {
    o: [__m512; 3],
    inv: [__m512; 3],
    /// The triangle test's constants, lane `l` for ray `l`.
    tri: TriRays,
}

/// The watertight triangle test's ray constants in sixteen lanes: the
/// permuted origin `op`, the shear `s`, and per lane the position `k` in
/// the vertex registers of its kx, ky, kz components (`TriRays::triangle`).
/// Either each lane is a ray of the packet testing one triangle (`Pre`:
/// `k` is 0, 1 or 2 and the caller broadcasts the triangle's vertices), or
/// up to four rays are spread over a leaf's four triangles (`Spread`: lane
/// 4r + t holds ray slot r, and `k` points into triangle t's 128-bit block
/// of a vertex row `TriPacket::xyz[i]`).
struct TriRays {
    op: [__m512; 3],
    s: [__m512; 3],
    k: [__m512i; 3],
}

/// Triangle hits of a set of lanes: t, edge functions and 1/det per lane.
struct TriHits {
    t: __m512,
    e: [__m512; 3],
    inv_det: __m512,
}

#[target_feature(enable = "avx512f,avx512vl,avx512bw,avx512dq")]
#[inline]
unsafe fn ld(a: &[f32; LANES]) -> __m512 {
    // SAFETY: 16 floats; unaligned load (AVX-512F, enabled by the callers).
    unsafe { _mm512_loadu_ps(a.as_ptr()) }
}

#[target_feature(enable = "avx512f,avx512vl,avx512bw,avx512dq")]
#[inline]
unsafe fn st(v: __m512) -> [f32; LANES] {
    let mut r = [0.0; LANES];
    // SAFETY: 16 floats; unaligned store.
    unsafe { _mm512_storeu_ps(r.as_mut_ptr(), v) };
    r
}

#[target_feature(enable = "avx512f,avx512vl,avx512bw,avx512dq")]
#[inline]
unsafe fn splat(x: f32) -> __m512 {
    _mm512_set1_ps(x)
}

#[target_feature(enable = "avx512f,avx512vl,avx512bw,avx512dq")]
#[inline]
unsafe fn lt(a: __m512, b: __m512) -> __mmask16 {
    _mm512_cmp_ps_mask::<_CMP_LT_OQ>(a, b)
}

#[target_feature(enable = "avx512f,avx512vl,avx512bw,avx512dq")]
#[inline]
unsafe fn le(a: __m512, b: __m512) -> __mmask16 {
    _mm512_cmp_ps_mask::<_CMP_LE_OQ>(a, b)
}

/// `lanes::V::max_wide`: `a` when `b` is NaN or `a > b`, else `b`.
#[target_feature(enable = "avx512f,avx512vl,avx512bw,avx512dq")]
#[inline]
unsafe fn max_wide(a: __m512, b: __m512) -> __m512 {
    let take_a = _mm512_cmp_ps_mask::<_CMP_UNORD_Q>(b, b) | _mm512_cmp_ps_mask::<_CMP_GT_OQ>(a, b);
    _mm512_mask_mov_ps(b, take_a, a)
}

#[target_feature(enable = "avx512f,avx512vl,avx512bw,avx512dq")]
#[inline]
unsafe fn max3_abs(v: &[__m512; 3]) -> __m512 {
    unsafe {
        max_wide(
            max_wide(_mm512_abs_ps(v[0]), _mm512_abs_ps(v[1])),
            _mm512_abs_ps(v[2]),
        )
    }
}

/// The axes (kx, ky, kz) of `bvh4_packet::permute` as component indices per
/// lane: kz = x gives (y, z, x), kz = y (z, x, y), otherwise (x, y, z).
#[target_feature(enable = "avx512f,avx512vl,avx512bw,avx512dq")]
#[inline]
unsafe fn axes(kz0: __mmask16, kz1: __mmask16) -> [__m512i; 3] {
    let pick = |x: i32, y: i32, z: i32| {
        _mm512_mask_mov_epi32(
            _mm512_mask_mov_epi32(_mm512_set1_epi32(x), kz1, _mm512_set1_epi32(z)),
            kz0,
            _mm512_set1_epi32(y),
        )
    };
    // kx: x, or y (kz = x), or z (kz = y); likewise ky and kz.
    [pick(0, 1, 2), pick(1, 2, 0), pick(2, 0, 1)]
}

impl Pre {
    #[target_feature(enable = "avx512f,avx512vl,avx512bw,avx512dq")]
    #[inline]
    unsafe fn new(p: &super::bvh4_packet::PacketPre) -> Self {
        let (o, inv, op, s, kz0, kz1) = p.parts();
        // SAFETY: AVX-512F/DQ, enabled by the callers.
        unsafe {
            Pre {
                o: [ld(o[0]), ld(o[1]), ld(o[2])],
                inv: [ld(inv[0]), ld(inv[1]), ld(inv[2])],
                tri: TriRays {
                    op: [ld(op[0]), ld(op[1]), ld(op[2])],
                    s: [ld(s[0]), ld(s[1]), ld(s[2])],
                    k: axes(
                        _mm512_movepi32_mask(_mm512_loadu_si512(kz0.as_ptr().cast())),
                        _mm512_movepi32_mask(_mm512_loadu_si512(kz1.as_ptr().cast())),
                    ),
                },
            }
        }
    }

    /// `PacketPre::child_box`.
    #[target_feature(enable = "avx512f,avx512vl,avx512bw,avx512dq")]
    #[inline]
    unsafe fn child_box(&self, n: &Node4, c: usize, tmax: __m512) -> (__mmask16, __m512) {
        unsafe {
            let mut tn = splat(0.0);
            let mut tf = tmax;
            for a in 0..3 {
                let lo = splat(n.b[0][a].as_array()[c]);
                let hi = splat(n.b[1][a].as_array()[c]);
                let t0 = _mm512_mul_ps(_mm512_sub_ps(lo, self.o[a]), self.inv[a]);
                let t1 = _mm512_mul_ps(_mm512_sub_ps(hi, self.o[a]), self.inv[a]);
                tn = _mm512_max_ps(tn, _mm512_min_ps(t0, t1));
                tf = _mm512_min_ps(tf, _mm512_max_ps(t0, t1));
            }
            tf = _mm512_mul_ps(tf, splat(1.0 + 2.0 * gamma(3)));
            (le(tn, tf), tn)
        }
    }
}

impl TriRays {
    /// `PacketPre::triangle` against the lanes of `m`: each lane's triangle
    /// has vertex `i` in `v[i]` where the lane's `k` finds its components
    /// (see `TriRays`).
    ///
    /// Always inlined into its two callers, `intersect_packet` and
    /// `unoccluded_packet`, which enable the AVX-512 features it needs (rustc
    /// allows no `#[inline(always)]` beside `#[target_feature]`). Called out of
    /// line, each test spilled the traversal's vector registers around the
    /// call and passed its operands through memory: 1.3 % of the render
    /// (docs/performance.md, *Fifteenth pass*).
    ///
    /// # Safety
    /// Only from a function with AVX-512 F, VL, BW and DQ enabled.
    #[inline(always)]
    unsafe fn triangle(
        &self,
        v: &[__m512; 3],
        tmax: __m512,
        m: __mmask16,
        h: &mut TriHits,
    ) -> __mmask16 {
        unsafe {
            let zero = splat(0.0);
            let mut px = [zero; 3];
            let mut py = [zero; 3];
            let mut pz = [zero; 3];
            for i in 0..3 {
                let vx = _mm512_permutexvar_ps(self.k[0], v[i]);
                let vy = _mm512_permutexvar_ps(self.k[1], v[i]);
                let vz = _mm512_permutexvar_ps(self.k[2], v[i]);
                pz[i] = _mm512_sub_ps(vz, self.op[2]);
                px[i] = _mm512_add_ps(
                    _mm512_sub_ps(vx, self.op[0]),
                    _mm512_mul_ps(self.s[0], pz[i]),
                );
                py[i] = _mm512_add_ps(
                    _mm512_sub_ps(vy, self.op[1]),
                    _mm512_mul_ps(self.s[1], pz[i]),
                );
            }
            let mut e = [
                _mm512_sub_ps(_mm512_mul_ps(px[1], py[2]), _mm512_mul_ps(py[1], px[2])),
                _mm512_sub_ps(_mm512_mul_ps(px[2], py[0]), _mm512_mul_ps(py[2], px[0])),
                _mm512_sub_ps(_mm512_mul_ps(px[0], py[1]), _mm512_mul_ps(py[0], px[1])),
            ];
            let any_zero = m
                & (_mm512_cmp_ps_mask::<_CMP_EQ_OQ>(e[0], zero)
                    | _mm512_cmp_ps_mask::<_CMP_EQ_OQ>(e[1], zero)
                    | _mm512_cmp_ps_mask::<_CMP_EQ_OQ>(e[2], zero));
            if any_zero != 0 {
                // Exact-zero edge: re-evaluate those lanes in f64 (rare).
                let x = [st(px[0]), st(px[1]), st(px[2])];
                let y = [st(py[0]), st(py[1]), st(py[2])];
                let mut ea = [st(e[0]), st(e[1]), st(e[2])];
                for l in 0..LANES {
                    if any_zero & (1 << l) != 0 {
                        ea[0][l] = edge_f64(x[1][l], y[1][l], x[2][l], y[2][l]);
                        ea[1][l] = edge_f64(x[2][l], y[2][l], x[0][l], y[0][l]);
                        ea[2][l] = edge_f64(x[0][l], y[0][l], x[1][l], y[1][l]);
                    }
                }
                e = [ld(&ea[0]), ld(&ea[1]), ld(&ea[2])];
            }
            let neg = lt(e[0], zero) | lt(e[1], zero) | lt(e[2], zero);
            let pos = lt(zero, e[0]) | lt(zero, e[1]) | lt(zero, e[2]);
            let inside = m & !(neg & pos);
            if inside == 0 {
                return 0;
            }
            let det = _mm512_add_ps(_mm512_add_ps(e[0], e[1]), e[2]);
            let sz = self.s[2];
            for z in &mut pz {
                *z = _mm512_mul_ps(*z, sz);
            }
            let ts = _mm512_add_ps(
                _mm512_add_ps(_mm512_mul_ps(e[0], pz[0]), _mm512_mul_ps(e[1], pz[1])),
                _mm512_mul_ps(e[2], pz[2]),
            );
            let tmd = _mm512_mul_ps(tmax, det);
            let in_neg = lt(det, zero) & lt(ts, zero) & le(tmd, ts);
            let in_pos = lt(zero, det) & lt(zero, ts) & le(ts, tmd);
            let hit = inside & (in_neg | in_pos);
            if hit == 0 {
                return 0;
            }
            let inv_det = _mm512_div_ps(splat(1.0), det);
            let t = _mm512_mul_ps(ts, inv_det);
            // Conservative check that t is positive beyond its rounding error (pbrt-v4).
            let max_zt = max3_abs(&pz);
            let max_xt = max3_abs(&px);
            let max_yt = max3_abs(&py);
            let (g2, g3, g5) = (splat(gamma(2)), splat(gamma(3)), splat(gamma(5)));
            let delta_z = _mm512_mul_ps(g3, max_zt);
            let delta_x = _mm512_mul_ps(g5, _mm512_add_ps(max_xt, max_zt));
            let delta_y = _mm512_mul_ps(g5, _mm512_add_ps(max_yt, max_zt));
            let delta_e = _mm512_mul_ps(
                splat(2.0),
                _mm512_add_ps(
                    _mm512_add_ps(
                        _mm512_mul_ps(_mm512_mul_ps(g2, max_xt), max_yt),
                        _mm512_mul_ps(delta_y, max_xt),
                    ),
                    _mm512_mul_ps(delta_x, max_yt),
                ),
            );
            let max_e = max3_abs(&e);
            let delta_t = _mm512_mul_ps(
                _mm512_mul_ps(
                    splat(3.0),
                    _mm512_add_ps(
                        _mm512_add_ps(
                            _mm512_mul_ps(_mm512_mul_ps(g3, max_e), max_zt),
                            _mm512_mul_ps(delta_e, max_zt),
                        ),
                        _mm512_mul_ps(delta_z, max_e),
                    ),
                ),
                _mm512_abs_ps(inv_det),
            );
            h.t = t;
            h.e = e;
            h.inv_det = inv_det;
            hit & lt(delta_t, t)
        }
    }
}

/// Triangle `j` of `p`'s vertices, each as (x, y, z, ·) in every 128-bit
/// block: what `TriRays::triangle` takes with a packet's own `TriRays`.
#[target_feature(enable = "avx512f,avx512vl,avx512bw,avx512dq")]
#[inline]
unsafe fn broadcast_vertices(p: &TriPacket, j: usize) -> [__m512; 3] {
    // SAFETY: 16-byte loads of `p.xyz[i][j]` (AVX-512F, enabled here).
    unsafe { [0, 1, 2].map(|i| _mm512_broadcast_f32x4(_mm_loadu_ps(p.xyz[i][j].as_ptr()))) }
}

/// Up to four rays of a packet spread over a leaf's four triangles, so that
/// one sixteen-lane triangle test does the work of four: lane 4r + t tests
/// the r-th ray of the mask (its slot) against triangle t. The packet
/// traversal reaches a leaf with four of its sixteen lanes active on average
/// (docs/performance.md, *Twenty-fourth pass*), so a test per triangle left
/// most of each test idle. (Five to eight rays spread as 8 × 2 in two tests
/// measured slower than a test per triangle: *Twenty-seventh pass*.)
struct Spread {
    rays: TriRays,
    /// Per lane its ray's `tmax`.
    tmax: __m512,
    /// In each ray lane of the mask, 4 × its slot (0 elsewhere): the lane
    /// of the test holding that ray against triangle 0.
    slot4: __m512i,
    /// The lanes holding a ray and one of the leaf's triangles.
    m: __mmask16,
}

impl Spread {
    /// The rays of `mask` (at most four) with their `tmax`, against a leaf
    /// of `n` triangles.
    #[target_feature(enable = "avx512f,avx512vl,avx512bw,avx512dq")]
    #[inline]
    unsafe fn new(r: &TriRays, mask: __mmask16, n: u32, tmax: __m512) -> Self {
        debug_assert!(mask.count_ones() <= 4 && n <= 4);
        let lane = super::simd::lane_numbers();
        // The ray lane of each slot, then of each lane of the test (lane / 4).
        let ray_of_slot = _mm512_maskz_compress_epi32(mask, lane);
        let ray = _mm512_permutexvar_epi32(_mm512_srli_epi32::<2>(lane), ray_of_slot);
        // Triangle t's block in a vertex row: 4t, t = lane mod 4.
        let block = _mm512_slli_epi32::<2>(_mm512_and_si512(lane, _mm512_set1_epi32(3)));
        let spread = |v: __m512| _mm512_permutexvar_ps(ray, v);
        let kz = |k: __m512i| _mm512_add_epi32(_mm512_permutexvar_epi32(ray, k), block);
        let slots = (1u32 << (4 * mask.count_ones())) - 1;
        let tris = 0x1111u32 * ((1u32 << n) - 1);
        Spread {
            rays: TriRays {
                op: r.op.map(spread),
                s: r.s.map(spread),
                k: r.k.map(kz),
            },
            tmax: spread(tmax),
            slot4: _mm512_maskz_expand_epi32(mask, _mm512_slli_epi32::<2>(lane)),
            m: (slots & tris) as __mmask16,
        }
    }

    /// The ray lanes of `mask` whose lanes for triangle `t` are set in
    /// `hits`.
    #[target_feature(enable = "bmi2")]
    #[inline]
    unsafe fn ray_lanes(hits: __mmask16, t: usize, mask: __mmask16) -> __mmask16 {
        _pdep_u32(_pext_u32(hits as u32, 0x1111 << t), mask as u32) as __mmask16
    }
}

/// A leaf's four triangles' vertices, row `i` holding vertex `i` of
/// triangle t in 128-bit block t: what `TriRays::triangle` takes with a
/// `Spread`'s `TriRays`.
#[target_feature(enable = "avx512f,avx512vl,avx512bw,avx512dq")]
#[inline]
unsafe fn vertex_rows(p: &TriPacket) -> [__m512; 3] {
    // SAFETY: 64-byte loads of `p.xyz[i]` (AVX-512F, enabled here).
    unsafe { [0, 1, 2].map(|i| _mm512_loadu_ps(p.xyz[i].as_ptr().cast())) }
}

/// A packet's closest hits so far: per lane t, barycentrics, primitive.
struct Closest {
    t: __m512,
    b: [__m512; 3],
    prim: __m512i,
}

impl Closest {
    /// The lanes of `closer` take the hit at `t` with barycentrics `b` on
    /// primitive `prim` (every lane's values given; the others keep theirs).
    ///
    /// # Safety
    /// Only from a function with AVX-512 F enabled (inlined, as
    /// `TriRays::triangle`).
    #[inline(always)]
    unsafe fn keep(&mut self, closer: __mmask16, t: __m512, b: [__m512; 3], prim: u32) {
        // SAFETY: AVX-512F, enabled in the caller.
        unsafe {
            self.t = _mm512_mask_mov_ps(self.t, closer, t);
            for (bk, new) in self.b.iter_mut().zip(b) {
                *bk = _mm512_mask_mov_ps(*bk, closer, new);
            }
            self.prim = _mm512_mask_mov_epi32(self.prim, closer, _mm512_set1_epi32(prim as i32));
        }
    }
}

/// `Bvh4::intersect_packet` with AVX-512 intrinsics.
///
/// # Safety
/// The CPU must have AVX-512 F, VL, BW and DQ (`RenderIsa::Avx512`).
#[target_feature(enable = "avx512f,avx512vl,avx512bw,avx512dq,avx2,fma,bmi1,bmi2,lzcnt,popcnt")]
pub(super) unsafe fn intersect_packet(
    bvh: &Bvh4,
    shapes: &[Shape],
    rays: &RayPacket,
    out: &mut PacketHits,
) {
    let active = rays.active & ALL_LANES;
    if active == 0 {
        *out = PacketHits::default();
        return;
    }
    let pre = super::bvh4_packet::PacketPre::new(rays);
    // SAFETY: the caller guarantees the features.
    unsafe {
        let r = Pre::new(&pre);
        let mut best = Closest {
            t: ld(&rays.tmax),
            b: [splat(0.0); 3],
            prim: _mm512_set1_epi32(EMPTY as i32),
        };
        let mut h = TriHits {
            t: splat(0.0),
            e: [splat(0.0); 3],
            inv_det: splat(0.0),
        };
        // Entries: node and per-lane entry distance, NaN in lanes that do
        // not need the node.
        let mut stack = [const { MaybeUninit::<(u32, __m512)>::uninit() }; STACK];
        let mut sp = 0usize;
        let (mut code, mut mask) = (bvh.root, active as __mmask16);
        'visit: loop {
            if code & LEAF != 0 {
                let leaf = &bvh.leaves[(code & !LEAF) as usize];
                if leaf.packet != EMPTY {
                    let p = &bvh.packets[leaf.packet as usize];
                    // Every triangle of the leaf is tested with the closest t
                    // at leaf entry as tmax, as the single-ray 4-triangle test.
                    let tmax = best.t;
                    if mask.count_ones() <= 4 && p.n >= SPREAD_MIN_TRIS {
                        // Up to four rays against all the leaf's triangles in
                        // one test; then the triangles' hits in order, as below.
                        let sp = Spread::new(&r.tri, mask, p.n, tmax);
                        let hit = sp.rays.triangle(&vertex_rows(p), sp.tmax, sp.m, &mut h);
                        if hit != 0 {
                            let b = h.e.map(|e| _mm512_mul_ps(e, h.inv_det));
                            for j in 0..p.n as usize {
                                let lanes = Spread::ray_lanes(hit, j, mask);
                                if lanes == 0 {
                                    continue;
                                }
                                let at = _mm512_add_epi32(sp.slot4, _mm512_set1_epi32(j as i32));
                                let t = _mm512_permutexvar_ps(at, h.t);
                                let closer = lanes & lt(t, best.t);
                                if closer != 0 {
                                    let bj = b.map(|bk| _mm512_permutexvar_ps(at, bk));
                                    best.keep(closer, t, bj, p.prim[j]);
                                }
                            }
                        }
                    } else {
                        for j in 0..p.n as usize {
                            let hit = r
                                .tri
                                .triangle(&broadcast_vertices(p, j), tmax, mask, &mut h);
                            let closer = hit & lt(h.t, best.t);
                            if closer != 0 {
                                let b = h.e.map(|e| _mm512_mul_ps(e, h.inv_det));
                                best.keep(closer, h.t, b, p.prim[j]);
                            }
                        }
                    }
                }
                if leaf.n_others > 0 {
                    // Spheres and disks: the scalar tests, lane by lane.
                    let s = leaf.others as usize;
                    let mut bt = st(best.t);
                    let mut bb = [st(best.b[0]), st(best.b[1]), st(best.b[2])];
                    let mut bp = [0u32; LANES];
                    _mm512_storeu_si512(bp.as_mut_ptr().cast(), best.prim);
                    for &prim in &bvh.others[s..s + leaf.n_others as usize] {
                        for l in (0..LANES).filter(|l| mask & (1 << l) != 0) {
                            let (tri, d) = pre.tri_ray(l);
                            if let Some(hh) = shapes[prim as usize].intersect_pre(&tri, d, bt[l])
                                && hh.t < bt[l]
                            {
                                bt[l] = hh.t;
                                for k in 0..3 {
                                    bb[k][l] = hh.b[k];
                                }
                                bp[l] = prim;
                            }
                        }
                    }
                    best.t = ld(&bt);
                    best.b = [ld(&bb[0]), ld(&bb[1]), ld(&bb[2])];
                    best.prim = _mm512_loadu_si512(bp.as_ptr().cast());
                }
            } else {
                let node = &bvh.nodes[code as usize];
                // Continue into the first child hit, stack the others with
                // their lanes' entry distances.
                let mut next = None;
                for c in 0..4 {
                    if node.valid & (1 << c) == 0 {
                        continue;
                    }
                    let (m, tn) = r.child_box(node, c, best.t);
                    let m = m & mask;
                    if m == 0 {
                        continue;
                    }
                    if next.is_none() {
                        next = Some((node.child[c], m));
                    } else {
                        stack[sp]
                            .write((node.child[c], _mm512_mask_mov_ps(splat(f32::NAN), m, tn)));
                        sp += 1;
                    }
                }
                if let Some((c, m)) = next {
                    code = c;
                    mask = m;
                    continue 'visit;
                }
            }
            // Next stacked node, with the lanes whose entry lies before
            // their closest hit.
            loop {
                if sp == 0 {
                    break 'visit;
                }
                sp -= 1;
                // SAFETY: entries below `sp` were written before being counted.
                let (c, tn) = stack[sp].assume_init();
                let m = le(tn, best.t);
                if m != 0 {
                    code = c;
                    mask = m;
                    continue 'visit;
                }
            }
        }
        write_hits(active, best, out);
    }
}

/// The packet's closest hits into `out`: for each lane of `active` with a
/// hit, its primitive and (t, barycentrics); every other lane as
/// `PacketHits::default()` leaves it (no primitive, zeros). The sixteen
/// `PrimHit`s are written as four registers — (t, b₀, b₁, b₂) transposed
/// from the lanes' columns — instead of five scalar stores a lane.
#[target_feature(enable = "avx512f,avx512vl,avx512bw,avx512dq")]
#[inline]
unsafe fn write_hits(active: LaneMask, best: Closest, out: &mut PacketHits) {
    let Closest { t, b, prim } = best;
    const _: () = assert!(
        std::mem::offset_of!(PrimHit, t) == 0
            && std::mem::offset_of!(PrimHit, b) == 4
            && std::mem::size_of::<PrimHit>() == 16
            && std::mem::size_of::<[PrimHit; LANES]>() == 4 * 64
    );
    // SAFETY: AVX-512F (enabled here); the stores write `out.prim`'s 16
    // words and `out.h`'s 16 × 16 bytes.
    unsafe {
        let none = _mm512_set1_epi32(EMPTY as i32);
        let hit = (active as __mmask16) & _mm512_cmpneq_epi32_mask(prim, none);
        _mm512_storeu_si512(
            out.prim.as_mut_ptr().cast(),
            _mm512_mask_mov_epi32(none, hit, prim),
        );
        let zero = _mm512_setzero_ps();
        let c = [
            _mm512_mask_mov_ps(zero, hit, t),
            _mm512_mask_mov_ps(zero, hit, b[0]),
            _mm512_mask_mov_ps(zero, hit, b[1]),
            _mm512_mask_mov_ps(zero, hit, b[2]),
        ];
        // 4 × 4 transposes within each 128-bit block: block q of row r holds
        // lane 4q + r's (t, b₀, b₁, b₂).
        let t01l = _mm512_unpacklo_ps(c[0], c[1]); // t0 b0_0 t1 b0_1 | …
        let t01h = _mm512_unpackhi_ps(c[0], c[1]); // t2 b0_2 t3 b0_3 | …
        let t23l = _mm512_unpacklo_ps(c[2], c[3]);
        let t23h = _mm512_unpackhi_ps(c[2], c[3]);
        let pd = _mm512_castps_pd;
        let ps = _mm512_castpd_ps;
        let r0 = ps(_mm512_unpacklo_pd(pd(t01l), pd(t23l))); // lane 4q
        let r1 = ps(_mm512_unpackhi_pd(pd(t01l), pd(t23l))); // lane 4q + 1
        let r2 = ps(_mm512_unpacklo_pd(pd(t01h), pd(t23h))); // lane 4q + 2
        let r3 = ps(_mm512_unpackhi_pd(pd(t01h), pd(t23h))); // lane 4q + 3
        // Output register q holds lanes 4q … 4q + 3: block q of r0 … r3.
        let a01 = _mm512_shuffle_f32x4::<0b01_00_01_00>(r0, r1); // r0.q0 r0.q1 r1.q0 r1.q1
        let a23 = _mm512_shuffle_f32x4::<0b01_00_01_00>(r2, r3);
        let b01 = _mm512_shuffle_f32x4::<0b11_10_11_10>(r0, r1); // r0.q2 r0.q3 r1.q2 r1.q3
        let b23 = _mm512_shuffle_f32x4::<0b11_10_11_10>(r2, r3);
        let o0 = _mm512_shuffle_f32x4::<0b10_00_10_00>(a01, a23); // r0.q0 r1.q0 r2.q0 r3.q0
        let o1 = _mm512_shuffle_f32x4::<0b11_01_11_01>(a01, a23); // … q1
        let o2 = _mm512_shuffle_f32x4::<0b10_00_10_00>(b01, b23);
        let o3 = _mm512_shuffle_f32x4::<0b11_01_11_01>(b01, b23);
        let h = out.h.as_mut_ptr().cast::<f32>();
        _mm512_storeu_ps(h, o0);
        _mm512_storeu_ps(h.add(16), o1);
        _mm512_storeu_ps(h.add(32), o2);
        _mm512_storeu_ps(h.add(48), o3);
    }
}

/// `Bvh4::unoccluded_packet` with AVX-512 intrinsics.
///
/// # Safety
/// The CPU must have AVX-512 F, VL, BW and DQ (`RenderIsa::Avx512`).
#[target_feature(enable = "avx512f,avx512vl,avx512bw,avx512dq,avx2,fma,bmi1,bmi2,lzcnt,popcnt")]
pub(super) unsafe fn unoccluded_packet(bvh: &Bvh4, shapes: &[Shape], rays: &RayPacket) -> LaneMask {
    let active = rays.active & ALL_LANES;
    if active == 0 {
        return 0;
    }
    let pre = super::bvh4_packet::PacketPre::new(rays);
    // SAFETY: the caller guarantees the features.
    unsafe {
        let r = Pre::new(&pre);
        let tmax = ld(&rays.tmax);
        let mut h = TriHits {
            t: splat(0.0),
            e: [splat(0.0); 3],
            inv_det: splat(0.0),
        };
        // Lanes not blocked so far.
        let mut free = active as __mmask16;
        let mut stack = [const { MaybeUninit::<(u32, __mmask16)>::uninit() }; STACK];
        let mut sp = 0usize;
        let (mut code, mut mask) = (bvh.root, free);
        'visit: loop {
            if code & LEAF != 0 {
                let leaf = &bvh.leaves[(code & !LEAF) as usize];
                if leaf.packet != EMPTY {
                    let p = &bvh.packets[leaf.packet as usize];
                    if mask.count_ones() <= 4 && p.n >= SPREAD_MIN_TRIS {
                        // Up to four rays against all the leaf's triangles in
                        // one test: a ray is blocked if any of its lanes hit.
                        let sp = Spread::new(&r.tri, mask, p.n, tmax);
                        let hit = sp.rays.triangle(&vertex_rows(p), sp.tmax, sp.m, &mut h);
                        let any = hit | (hit >> 1) | (hit >> 2) | (hit >> 3);
                        let blocked = Spread::ray_lanes(any, 0, mask);
                        free &= !blocked;
                        mask &= !blocked;
                    } else {
                        for j in 0..p.n as usize {
                            let hit = r
                                .tri
                                .triangle(&broadcast_vertices(p, j), tmax, mask, &mut h);
                            free &= !hit;
                            mask &= !hit;
                            if mask == 0 {
                                break;
                            }
                        }
                    }
                }
                if leaf.n_others > 0 {
                    let s = leaf.others as usize;
                    let tm = st(tmax);
                    for &prim in &bvh.others[s..s + leaf.n_others as usize] {
                        let lanes = mask;
                        for l in (0..LANES).filter(|l| lanes & (1 << l) != 0) {
                            let (tri, d) = pre.tri_ray(l);
                            if shapes[prim as usize]
                                .intersect_pre(&tri, d, tm[l])
                                .is_some()
                            {
                                free &= !(1 << l);
                                mask &= !(1 << l);
                            }
                        }
                    }
                }
                if free == 0 {
                    return 0;
                }
            } else {
                let node = &bvh.nodes[code as usize];
                // Continue into the first child hit, stack the others.
                let mut next = None;
                for c in 0..4 {
                    if node.valid & (1 << c) == 0 {
                        continue;
                    }
                    let m = r.child_box(node, c, tmax).0 & mask;
                    if m == 0 {
                        continue;
                    }
                    if next.is_none() {
                        next = Some((node.child[c], m));
                    } else {
                        stack[sp].write((node.child[c], m));
                        sp += 1;
                    }
                }
                if let Some((c, m)) = next {
                    code = c;
                    mask = m;
                    continue 'visit;
                }
            }
            loop {
                if sp == 0 {
                    break 'visit;
                }
                sp -= 1;
                // SAFETY: entries below `sp` were written before being counted.
                let (c, m) = stack[sp].assume_init();
                let m = m & free;
                if m != 0 {
                    code = c;
                    mask = m;
                    continue 'visit;
                }
            }
        }
        free as LaneMask
    }
}
