//! What `shade_packet::shade_diffuse` reads per lane before it shades a
//! packet's Lambertian hits — the hit triangle's vertices and geometric
//! normal, the hit's barycentrics, the ray's direction, and whether the
//! triangle emits, carries vertex normals or ends the path at its depth —
//! fetched for all sixteen lanes with AVX-512 gathers (issue 17), one
//! instruction per quantity and axis, instead of the lane loop's scalar loads
//! and stores.
//!
//! Why: that loop cost ≈ 5 % of the bench's render (run twice it took 1.053
//! of the time; docs/performance.md, *Twenty-sixth pass*), and its scalar
//! stores are read back as whole vectors by the lane loops after it.
//!
//! Same values: each gathered float is the very float the lane loop copies
//! (a gather is a load); lanes outside `todo` keep the defaults the caller
//! set, as in the lane loop. Vertex normals (rare: meshes that carry them)
//! stay with the caller, lane by lane. Addresses are offsets in floats from
//! each table's own pointer; the caller checks that they fit in `i32`
//! (`fits`). `film::tests::every_isa_level_renders_the_same_bits` compares
//! this kernel's images bit for bit with one path at a time.

use super::geometry::{PrimHit, Shape};
use super::path::PathState;
use super::ray_packet::{LANES, LaneMask, PacketHits, RayPacket};
use super::simd::{lane_numbers, record_offsets};
use super::world::{PrimInfo, World};
use glam::Vec3;
use std::mem::{offset_of, size_of};

/// Sixteen lanes' hit geometry (`shade_diffuse`'s arrays, component-wise).
pub(super) struct HitLanes<'a> {
    /// Vertex k of the hit triangle, axis a: `v[k][a]`.
    pub v: [&'a mut [f32; LANES]; 9],
    /// Barycentric k of the hit.
    pub bary: &'a mut [[f32; LANES]; 3],
    /// The triangle's unit geometric normal, per axis.
    pub ng: [&'a mut [f32; LANES]; 3],
    /// The ray's direction, per axis.
    pub dir: [&'a mut [f32; LANES]; 3],
}

/// The lanes of `todo` that hit an emitter, that carry vertex normals, and
/// that are at `max_bounces` (their paths end here).
pub(super) struct HitMasks {
    pub emitters: LaneMask,
    pub with_normals: LaneMask,
    pub at_max_depth: LaneMask,
}

/// Offset in bytes of a triangle's vertices inside `Shape` (the enum's
/// layout is the compiler's; measured on a value, the same for every one).
fn triangle_vertices_offset() -> usize {
    let s = Shape::Triangle { p: [Vec3::ZERO; 3] };
    match &s {
        Shape::Triangle { p } => p.as_ptr() as usize - (&s as *const Shape as usize),
        _ => unreachable!("constructed as a triangle"),
    }
}

const SHAPE_FLOATS: usize = size_of::<Shape>() / 4;
const INFO_WORDS: usize = size_of::<PrimInfo>() / 4;
const STATE_FLOATS: usize = size_of::<PathState>() / 4;
const HIT_FLOATS: usize = size_of::<PrimHit>() / 4;
const _: () = assert!(
    size_of::<Shape>().is_multiple_of(4)
        && size_of::<PrimInfo>().is_multiple_of(4)
        && size_of::<PathState>().is_multiple_of(4)
        && size_of::<PrimHit>().is_multiple_of(4)
        && size_of::<Vec3>() == 12
);

/// Whether every primitive's offsets fit the gathers' 32-bit indices.
pub(super) fn fits(world: &World) -> bool {
    let n = world.accel.shapes.len();
    n.checked_mul(SHAPE_FLOATS.max(INFO_WORDS).max(3) + 1)
        .is_some_and(|m| m < i32::MAX as usize)
}

/// Fill `out` for the lanes of `todo` (hits on triangles: `World::hit_kind`)
/// and return their masks.
///
/// # Safety
/// The CPU has AVX-512F; `fits(world)`; every lane of `todo` holds a hit on
/// a triangle primitive of `world` (`hits.prim[l]` < the primitive count).
#[cfg(target_arch = "x86_64")]
#[target_feature(enable = "avx512f")]
pub(super) unsafe fn hit_lanes(
    world: &World,
    st: &[PathState; LANES],
    hits: &PacketHits,
    todo: LaneMask,
    max_bounces: u32,
    out: HitLanes<'_>,
) -> HitMasks {
    use std::arch::x86_64::*;
    let m = todo as __mmask16;
    let lane = lane_numbers();
    // SAFETY (every gather below): the masked lanes are those of `todo`,
    // whose primitive indices lie inside `world`'s tables (caller), and lane
    // indices below 16 inside `st` and `hits`; each base pointer is derived
    // from the table it addresses; offsets fit in i32 (`fits`). Stores write
    // 16 floats into 16-float arrays.
    unsafe {
        let prim = _mm512_maskz_loadu_epi32(m, hits.prim.as_ptr().cast());
        let at = |stride: usize, first: usize| record_offsets(prim, stride, first);
        let shapes = world
            .accel
            .shapes
            .as_ptr()
            .cast::<u8>()
            .add(triangle_vertices_offset())
            .cast::<f32>();
        let HitLanes { v, bary, ng, dir } = out;
        for (j, d) in v.into_iter().enumerate() {
            gather_into(d, m, at(SHAPE_FLOATS, j), shapes);
        }
        let tri_ng = world.tri_ng_ptr();
        for (a, d) in ng.into_iter().enumerate() {
            gather_into(d, m, at(3, a), tri_ng);
        }
        let h = hits
            .h
            .as_ptr()
            .cast::<u8>()
            .add(offset_of!(PrimHit, b))
            .cast::<f32>();
        let by_lane = |stride: usize, first: usize| record_offsets(lane, stride, first);
        for (k, d) in bary.iter_mut().enumerate() {
            gather_into(d, m, by_lane(HIT_FLOATS, k), h);
        }
        let sp = st.as_ptr().cast::<u8>();
        let d_at = sp.add(offset_of!(PathState, d)).cast::<f32>();
        for (a, d) in dir.into_iter().enumerate() {
            gather_into(d, m, by_lane(STATE_FLOATS, a), d_at);
        }
        let depth = _mm512_mask_i32gather_epi32::<4>(
            _mm512_setzero_si512(),
            m,
            by_lane(STATE_FLOATS, 0),
            sp.add(offset_of!(PathState, depth)).cast::<i32>(),
        );
        let info = world.info.as_ptr().cast::<u8>();
        let none = _mm512_set1_epi32(-1);
        let light = _mm512_mask_i32gather_epi32::<4>(
            none,
            m,
            at(INFO_WORDS, 0),
            info.add(offset_of!(PrimInfo, light)).cast::<i32>(),
        );
        let normals = _mm512_mask_i32gather_epi32::<4>(
            none,
            m,
            at(INFO_WORDS, 0),
            info.add(offset_of!(PrimInfo, normals)).cast::<i32>(),
        );
        HitMasks {
            emitters: _mm512_mask_cmpneq_epi32_mask(m, light, none) as LaneMask,
            with_normals: _mm512_mask_cmpneq_epi32_mask(m, normals, none) as LaneMask,
            at_max_depth: _mm512_mask_cmpge_epu32_mask(
                m,
                depth,
                _mm512_set1_epi32(max_bounces as i32),
            ) as LaneMask,
        }
    }
}

/// Into `dst`, in the lanes of `m`, the float `idx[k]` floats past `base`;
/// `dst` keeps its own value in the other lanes (a masked gather whose
/// source is `dst`, stored whole).
///
/// # Safety
/// The CPU has AVX-512F; every masked lane's address is inside the table
/// `base` points into.
#[cfg(target_arch = "x86_64")]
#[target_feature(enable = "avx512f")]
#[inline]
unsafe fn gather_into(
    dst: &mut [f32; LANES],
    m: std::arch::x86_64::__mmask16,
    idx: std::arch::x86_64::__m512i,
    base: *const f32,
) {
    use std::arch::x86_64::*;
    // SAFETY: the caller's addresses; 16-float loads and stores of `dst`.
    unsafe {
        let g = _mm512_mask_i32gather_ps::<4>(_mm512_loadu_ps(dst.as_ptr()), m, idx, base);
        _mm512_storeu_ps(dst.as_mut_ptr(), g);
    }
}

/// `integrator::packet_rays` for the AVX-512 kernel: the rays of the lanes
/// `alive` — origin and direction from their path states, far end ∞ — into
/// `rays`, one gather per component; the other lanes keep their values, as
/// in the lane loop.
///
/// # Safety
/// The CPU has AVX-512F.
#[cfg(target_arch = "x86_64")]
#[target_feature(enable = "avx512f")]
pub(super) unsafe fn packet_rays(st: &[PathState; LANES], alive: LaneMask, rays: &mut RayPacket) {
    use std::arch::x86_64::*;
    let m = alive as __mmask16;
    // SAFETY: lane indices below 16 address `st`'s 16 states from its own
    // pointer; loads and stores are of 16-float arrays.
    unsafe {
        let sp = st.as_ptr().cast::<u8>();
        let o = sp.add(offset_of!(PathState, o)).cast::<f32>();
        let d = sp.add(offset_of!(PathState, d)).cast::<f32>();
        for a in 0..3 {
            let idx = record_offsets(lane_numbers(), STATE_FLOATS, a);
            gather_into(&mut rays.o[a], m, idx, o);
            gather_into(&mut rays.d[a], m, idx, d);
        }
        _mm512_mask_storeu_ps(rays.tmax.as_mut_ptr(), m, _mm512_set1_ps(f32::INFINITY));
    }
    rays.active = alive;
}
