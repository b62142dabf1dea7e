//! The rays of several packets cast together, regrouped into coherent
//! packets first (issue 17: ray-stream reordering).
//!
//! A packet of 16 bounce rays from 16 unrelated paths reaches each BVH leaf
//! with 2.4 of its lanes on the bench's Cornell box, so a triangle test, run
//! for all 16 lanes, does mostly nothing. With several packets' paths in
//! flight, their rays are sorted by a small key — the direction's octant and
//! the origin's cell in a 4 × 4 × 4 grid over the scene's bounding sphere —
//! and cast 16 at a time in that order: rays leaving the same region in the
//! same general direction meet the same nodes and leaves, so fewer nodes are
//! visited per packet and more lanes are busy in each test. The results go
//! back to the packets the rays came from. In the AVX-512 kernel the
//! regrouped packet is filled with one gather per ray component (seven for
//! sixteen rays) instead of a load and a store per component and ray:
//! 0.97–0.98 of the render's time (docs/performance.md, *Twenty-fifth
//! pass*); where the CPU also has conflict detection and a vector popcount,
//! the counting sort counts and places sixteen rays at a time (0.98).
//!
//! Same bits: a ray's closest hit and its occlusion do not depend on the
//! other rays of its packet (`bvh4_packet`'s kernels give every lane the
//! single-ray answer; `bvh4_packet::tests`; the one exception its notes
//! describe, two primitives within a few ulps of each other along the ray,
//! may resolve by visiting order), and the sort is a stable
//! counting sort of the packets' lanes in order, so the grouping is the same
//! for any thread count. `film::tests` render with 1 and 32 packets in flight
//! and one path at a time and compare the bits.

// Lane loops index several per-lane arrays at once.
#![allow(clippy::needless_range_loop)]

use super::integrator::PacketScratch;
use super::ray_packet::{LANES, LaneMask, PacketHits, RayPacket, lanes};
use super::simd::RenderIsa;
use super::world::World;
use glam::Vec3;

/// Which rays of the packets a cast takes.
#[derive(Clone, Copy)]
enum Cast {
    /// The bounce rays (`PacketScratch::rays`).
    Rays,
    /// The next-event shadow rays (`PacketScratch::shadows`).
    Shadows,
}

impl Cast {
    #[inline(always)]
    fn of(self, sc: &PacketScratch) -> &RayPacket {
        match self {
            Cast::Rays => &sc.rays,
            Cast::Shadows => &sc.shadows,
        }
    }

    /// Byte offset of the rays in a `PacketScratch`.
    #[cfg(target_arch = "x86_64")]
    fn offset(self) -> usize {
        match self {
            Cast::Rays => std::mem::offset_of!(PacketScratch, rays),
            Cast::Shadows => std::mem::offset_of!(PacketScratch, shadows),
        }
    }
}

/// Floats in a `PacketScratch`: the gather's stride from one packet's rays
/// to the next's.
#[cfg(target_arch = "x86_64")]
const SCRATCH_FLOATS: usize = std::mem::size_of::<PacketScratch>() / 4;
#[cfg(target_arch = "x86_64")]
const _: () = assert!(std::mem::size_of::<PacketScratch>().is_multiple_of(4));

/// Most packets whose rays `gather_avx512` can address with 32-bit float
/// offsets (far more than are ever in flight; more go the scalar way).
#[cfg(target_arch = "x86_64")]
const MAX_GATHER_PACKETS: usize = (i32::MAX as usize / SCRATCH_FLOATS) - 1;

/// `RayStream::gather`'s copy for the AVX-512 kernel: ray `ids[k]` (packet
/// × 16 + lane) of `cast.of(&scs[p])` into lane `k` of `pk`, one gather per
/// ray component; lanes past `ids` are zeroed (inactive).
#[cfg(target_arch = "x86_64")]
#[target_feature(enable = "avx512f")]
fn gather_avx512(ids: &[u32], scs: &[PacketScratch], cast: Cast, pk: &mut RayPacket) {
    use std::arch::x86_64::*;
    debug_assert!(ids.len() <= LANES && scs.len() <= MAX_GATHER_PACKETS);
    let m: __mmask16 = ((1u32 << ids.len()) - 1) as __mmask16;
    // SAFETY: every id is p × 16 + l of a ray the sort took from `scs`
    // (p < scs.len(), l < 16), so each gathered float — component `a`,
    // lane `l` of packet p's rays, `p·SCRATCH_FLOATS + (offset + 64·a)/4 + l`
    // floats past the start of `scs` — lies inside `scs`, whose pointer the
    // base is derived from; the masked load reads `ids.len()` values; the
    // offsets fit in i32 (`MAX_GATHER_PACKETS`); the stores write 16 floats
    // of `pk`'s arrays.
    unsafe {
        let id = _mm512_maskz_loadu_epi32(m, ids.as_ptr().cast());
        let p = _mm512_srli_epi32::<4>(id);
        let l = _mm512_and_si512(id, _mm512_set1_epi32(LANES as i32 - 1));
        let at = _mm512_add_epi32(
            _mm512_mullo_epi32(p, _mm512_set1_epi32(SCRATCH_FLOATS as i32)),
            l,
        );
        let base = scs.as_ptr().cast::<u8>().add(cast.offset()).cast::<f32>();
        // Float `first + at[k]` past `base` for each lane k of `m` (0 elsewhere).
        macro_rules! row {
            ($first:expr) => {
                _mm512_mask_i32gather_ps::<4>(
                    _mm512_setzero_ps(),
                    m,
                    _mm512_add_epi32(at, _mm512_set1_epi32($first as i32)),
                    base,
                )
            };
        }
        const O: usize = std::mem::offset_of!(RayPacket, o) / 4;
        const D: usize = std::mem::offset_of!(RayPacket, d) / 4;
        const T: usize = std::mem::offset_of!(RayPacket, tmax) / 4;
        for a in 0..3 {
            _mm512_storeu_ps(pk.o[a].as_mut_ptr(), row!(O + a * LANES));
            _mm512_storeu_ps(pk.d[a].as_mut_ptr(), row!(D + a * LANES));
        }
        _mm512_storeu_ps(pk.tmax.as_mut_ptr(), row!(T));
    }
}

/// The CPU has AVX-512F, CD (conflict detection) and VPOPCNTDQ, which
/// `sort_avx512` uses.
fn conflict_sort_supported() -> bool {
    #[cfg(target_arch = "x86_64")]
    {
        std::arch::is_x86_feature_detected!("avx512f")
            && std::arch::is_x86_feature_detected!("avx512cd")
            && std::arch::is_x86_feature_detected!("avx512vpopcntdq")
    }
    #[cfg(not(target_arch = "x86_64"))]
    false
}

/// `RayStream::sort`'s counting and placing, sixteen rays at a time: each
/// active lane's rank among the earlier active lanes of its packet with the
/// same key (`vpconflictd`, then a popcount) plus the count of its key so
/// far (a gather), the counts written back by a scatter (of lanes with one
/// key, the last lane's write lands: scatters write in lane order); then
/// each ray's place, its key's start plus its rank, scattered into `order`.
/// The same stable order as the scalar loops, without their chain through
/// `counts[k] += 1`.
#[cfg(target_arch = "x86_64")]
#[target_feature(enable = "avx512f,avx512cd,avx512vpopcntdq")]
fn sort_avx512(rs: &mut RayStream, scs: &[PacketScratch], cast: Cast) {
    use std::arch::x86_64::*;
    let n = scs.len();
    debug_assert!(rs.rank.len() >= n * LANES && rs.keys.len() >= n * LANES);
    // SAFETY: keys are below KEYS (`keys_of`), so `counts[k + 1]` is inside
    // `counts` (KEYS + 1 entries); ranks and keys are read and written at
    // p·16 + lane, p < n, inside `rank` and `keys` (`new` sized them for
    // every packet); each place is below the rays' total, `order`'s length.
    unsafe {
        let one = _mm512_set1_epi32(1);
        let lane_ids = super::simd::lane_numbers();
        for p in 0..n {
            let m = cast.of(&scs[p]).active as __mmask16;
            let k =
                _mm512_cvtepu16_epi32(_mm256_loadu_si256(rs.keys.as_ptr().add(p * LANES).cast()));
            let k1 = _mm512_add_epi32(k, one);
            let earlier = _mm512_and_si512(_mm512_conflict_epi32(k), _mm512_set1_epi32(m as i32));
            let before = _mm512_popcnt_epi32(earlier);
            let c = _mm512_mask_i32gather_epi32::<4>(
                _mm512_setzero_si512(),
                m,
                k1,
                rs.counts.as_ptr().cast(),
            );
            let rank = _mm512_add_epi32(c, before);
            _mm512_mask_storeu_epi32(rs.rank.as_mut_ptr().add(p * LANES).cast(), m, rank);
            _mm512_mask_i32scatter_epi32::<4>(
                rs.counts.as_mut_ptr().cast(),
                m,
                k1,
                _mm512_add_epi32(rank, one),
            );
        }
        let total = rs.starts();
        rs.order.resize(total, 0);
        for p in 0..n {
            let m = cast.of(&scs[p]).active as __mmask16;
            let k =
                _mm512_cvtepu16_epi32(_mm256_loadu_si256(rs.keys.as_ptr().add(p * LANES).cast()));
            let start = _mm512_mask_i32gather_epi32::<4>(
                _mm512_setzero_si512(),
                m,
                k,
                rs.counts.as_ptr().cast(),
            );
            let rank = _mm512_maskz_loadu_epi32(m, rs.rank.as_ptr().add(p * LANES).cast());
            let place = _mm512_add_epi32(start, rank);
            let id = _mm512_add_epi32(lane_ids, _mm512_set1_epi32((p * LANES) as i32));
            _mm512_mask_i32scatter_epi32::<4>(rs.order.as_mut_ptr().cast(), m, place, id);
        }
    }
}

/// Sort keys: 3 bits of direction octant, 2 bits of origin cell per axis.
const KEYS: usize = 1 << 9;

/// Reusable buffers of the regrouping (one per thread).
pub struct RayStream {
    center: Vec3,
    /// Cells per unit length: the grid spans the bounding sphere's diameter
    /// in four cells.
    scale: f32,
    /// Rays per key, then the first place of each key.
    counts: Vec<u32>,
    /// Per ray (packet × 16 + lane): its key.
    keys: Vec<u16>,
    /// Rays in key order.
    order: Vec<u32>,
    /// Per ray: how many rays before it have its key (`sort_avx512`).
    rank: Vec<u32>,
    /// The CPU has what `sort_avx512` needs.
    conflict_sort: bool,
    packet: RayPacket,
    hits: PacketHits,
}

impl RayStream {
    /// Buffers for up to `packets` packets of `world`'s rays.
    pub fn new(world: &World, packets: usize) -> Self {
        let r = if world.radius.is_finite() && world.radius > 0.0 {
            world.radius
        } else {
            1.0
        };
        RayStream {
            center: if world.center.is_finite() {
                world.center
            } else {
                Vec3::ZERO
            },
            scale: 2.0 / r,
            counts: vec![0; KEYS + 1],
            keys: vec![0; packets * LANES],
            order: Vec::with_capacity(packets * LANES),
            rank: vec![0; packets * LANES],
            conflict_sort: conflict_sort_supported(),
            packet: RayPacket::default(),
            hits: PacketHits::default(),
        }
    }

    /// The sort keys of the 16 lanes of `r` (inactive lanes too; a plain
    /// lane loop, vectorised by the render kernel).
    // `max`/`min` rather than `clamp`: they return the number when the
    // origin is NaN (clamp would keep the NaN).
    #[allow(clippy::manual_clamp)]
    #[inline(always)]
    fn keys_of(&self, r: &RayPacket, out: &mut [u16; LANES]) {
        // Cell = ⌊(v − centre)·scale + 2⌋ clamped to 0..=3, as v·scale + shift
        // (no closure: a closure is compiled for the baseline instruction
        // set, not the render kernel's; `ray_packet::lanes`).
        let sc = self.scale;
        let shift = Vec3::splat(2.0) - self.center * sc;
        let mut k = [0f32; LANES];
        for l in 0..LANES {
            let cx = (r.o[0][l] * sc + shift.x).max(0.0).min(3.0).floor();
            let cy = (r.o[1][l] * sc + shift.y).max(0.0).min(3.0).floor();
            let cz = (r.o[2][l] * sc + shift.z).max(0.0).min(3.0).floor();
            let bx = if r.d[0][l] > 0.0 { 64.0 } else { 0.0 };
            let by = if r.d[1][l] > 0.0 { 128.0 } else { 0.0 };
            let bz = if r.d[2][l] > 0.0 { 256.0 } else { 0.0 };
            k[l] = bx + by + bz + cx * 16.0 + cy * 4.0 + cz;
        }
        for (o, &x) in out.iter_mut().zip(&k) {
            // SAFETY: `x` is a whole number in 0..512: `max` and `min` return
            // the number when the other operand is NaN, so a NaN or infinite
            // origin lands in cell 0 or 3, and a NaN direction compares false.
            *o = unsafe { x.to_int_unchecked::<i32>() } as u16;
        }
    }

    /// Sort the active rays of `cast.of(&scs[p])` for every packet p into
    /// `order` (a stable counting sort by key). The AVX-512 kernel counts and
    /// places sixteen rays at a time where the CPU has conflict detection
    /// and vector popcount (`sort_avx512`); the result is the same order.
    #[inline(always)]
    fn sort(&mut self, isa: RenderIsa, scs: &[PacketScratch], cast: Cast) {
        let n = scs.len();
        self.counts.fill(0);
        for p in 0..n {
            let mut k = [0u16; LANES];
            self.keys_of(cast.of(&scs[p]), &mut k);
            self.keys[p * LANES..(p + 1) * LANES].copy_from_slice(&k);
        }
        #[cfg(target_arch = "x86_64")]
        if isa == RenderIsa::Avx512 && self.conflict_sort && n <= MAX_GATHER_PACKETS {
            // SAFETY: `conflict_sort` is set only where the CPU has
            // AVX-512F, CD and VPOPCNTDQ; ray ids fit in i32 below
            // `MAX_GATHER_PACKETS` packets.
            unsafe { sort_avx512(self, scs, cast) };
            return;
        }
        let _ = isa;
        for p in 0..n {
            for l in lanes(cast.of(&scs[p]).active) {
                self.counts[self.keys[p * LANES + l] as usize + 1] += 1;
            }
        }
        let total = self.starts();
        self.order.resize(total, 0);
        for p in 0..n {
            for l in lanes(cast.of(&scs[p]).active) {
                let id = p * LANES + l;
                let k = self.keys[id] as usize;
                self.order[self.counts[k] as usize] = id as u32;
                self.counts[k] += 1;
            }
        }
    }

    /// With `counts[k + 1]` holding key k's count: the first place of each
    /// key into `counts[k]`; returns the rays' total. A running sum in a
    /// register, not `counts[k + 1] += counts[k]`, whose every step waited
    /// on the store before it (2.3 % of perf's samples).
    #[inline(always)]
    fn starts(&mut self) -> usize {
        let mut start = 0u32;
        for c in self.counts.iter_mut() {
            start += *c;
            *c = start;
        }
        self.counts[KEYS] as usize
    }

    /// Copy the next (up to) 16 rays of `order` from `start` — ray ids,
    /// packet × 16 + lane, of `cast.of(&scs[p])` — into `self.packet`;
    /// returns where the next packet starts. The AVX-512 kernel gathers
    /// each component of the 16 rays with one instruction.
    #[inline(always)]
    fn gather(&mut self, isa: RenderIsa, start: usize, scs: &[PacketScratch], cast: Cast) -> usize {
        let end = (start + LANES).min(self.order.len());
        let ids = &self.order[start..end];
        let pk = &mut self.packet;
        #[cfg(target_arch = "x86_64")]
        if isa == RenderIsa::Avx512 && scs.len() <= MAX_GATHER_PACKETS {
            // SAFETY: the AVX-512 kernel runs only on a CPU with AVX-512F;
            // `scs` is short enough for 32-bit float offsets.
            unsafe { gather_avx512(ids, scs, cast, pk) };
            pk.active = (1u32 << (end - start)) - 1;
            return end;
        }
        let _ = isa;
        for (k, &id) in ids.iter().enumerate() {
            let (p, l) = (id as usize / LANES, id as usize % LANES);
            let r = cast.of(&scs[p]);
            for a in 0..3 {
                pk.o[a][k] = r.o[a][l];
                pk.d[a][k] = r.d[a][l];
            }
            pk.tmax[k] = r.tmax[l];
        }
        pk.active = (1u32 << (end - start)) - 1;
        end
    }

    /// The closest hit of every ray `scs[p].rays`, into `scs[p].hits`.
    #[inline(always)]
    pub fn intersect(&mut self, isa: RenderIsa, world: &World, scs: &mut [PacketScratch]) {
        self.sort(isa, scs, Cast::Rays);
        let mut start = 0;
        while start < self.order.len() {
            let end = self.gather(isa, start, scs, Cast::Rays);
            world.accel.intersect_packet(&self.packet, &mut self.hits);
            for (k, &id) in self.order[start..end].iter().enumerate() {
                let (p, l) = (id as usize / LANES, id as usize % LANES);
                scs[p].hits.prim[l] = self.hits.prim[k];
                scs[p].hits.h[l] = self.hits.h[k];
            }
            start = end;
        }
    }

    /// Which shadow rays `scs[p].shadows` are unblocked: `free[p]`.
    #[inline(always)]
    pub fn unoccluded(
        &mut self,
        isa: RenderIsa,
        world: &World,
        scs: &[PacketScratch],
        free: &mut [LaneMask],
    ) {
        free.fill(0);
        self.sort(isa, scs, Cast::Shadows);
        let mut start = 0;
        while start < self.order.len() {
            let end = self.gather(isa, start, scs, Cast::Shadows);
            let f = world.accel.unoccluded_packet(&self.packet);
            for k in lanes(f) {
                let id = self.order[start + k] as usize;
                free[id / LANES] |= 1 << (id % LANES);
            }
            start = end;
        }
    }
}

#[cfg(test)]
mod tests {
    use super::*;
    use crate::render::BvhKind;
    use crate::render::sampling::Rng;
    use crate::scene::shapes::quad;
    use crate::scene::{Material, Scene};
    use crate::spectrum::{Spectrum, WavelengthGrid};
    use glam::DVec3;

    /// At every level this machine has, the sort puts each active ray once,
    /// by key, rays of one key in packet-and-lane order (checked against the
    /// keys themselves, not against another sort), and the regrouped packets
    /// hold exactly those rays' origins, directions and far ends.
    #[test]
    fn sort_and_gather_follow_the_keys_at_every_level() {
        let mut scene = Scene::default();
        let m = scene.material(
            "m",
            Material::Diffuse {
                reflectance: Spectrum::constant("r", 0.5),
            },
        );
        let o = scene.object("floor");
        scene
            .meshes
            .push(quad(DVec3::ZERO, DVec3::X, DVec3::Y, m, o, None));
        let grid = WavelengthGrid::new(500.0, 600.0, 50.0).unwrap();
        let world = World::build(&scene, &grid, BvhKind::Bvh4).unwrap();
        let n = 7;
        let mut rng = Rng::for_sample(3, 0, 0);
        let mut scs: Vec<PacketScratch> = (0..n)
            .map(|_| PacketScratch::new(world.bands_padded))
            .collect();
        for sc in &mut scs {
            for r in [&mut sc.rays, &mut sc.shadows] {
                // Three origins and three directions, so that keys repeat
                // within a packet (the ranks among equal keys matter).
                let os = [Vec3::ZERO, Vec3::new(0.4, -0.3, 0.2), Vec3::splat(-0.5)];
                let ds = [
                    Vec3::Z,
                    Vec3::new(-1.0, 0.5, -0.2),
                    Vec3::new(0.3, -0.7, 0.1),
                ];
                for l in 0..LANES {
                    let i = (rng.uniform() * 3.0) as usize % 3;
                    let j = (rng.uniform() * 3.0) as usize % 3;
                    let jitter = Vec3::splat(1e-3 * l as f32);
                    r.set(l, os[i] + jitter, ds[j], 1.0 + l as f32);
                }
                // Some lanes idle.
                r.active = (rng.uniform() * 65536.0) as u32 & 0xffff;
            }
        }
        // Keys do repeat within packets.
        let mut k = [0u16; LANES];
        RayStream::new(&world, n).keys_of(&scs[0].rays, &mut k);
        assert!((1..LANES).any(|l| k[..l].contains(&k[l])), "keys {k:?}");
        for isa in RenderIsa::ALL.into_iter().filter(|i| i.supported()) {
            for cast in [Cast::Rays, Cast::Shadows] {
                let mut rs = RayStream::new(&world, n);
                rs.sort(isa, &scs, cast);
                let want: usize = scs
                    .iter()
                    .map(|s| cast.of(s).active.count_ones() as usize)
                    .sum();
                assert_eq!(rs.order.len(), want, "{isa:?}");
                let key = |id: u32| rs.keys[id as usize];
                for w in rs.order.windows(2) {
                    let (a, b) = (w[0], w[1]);
                    assert!(
                        key(a) < key(b) || (key(a) == key(b) && a < b),
                        "{isa:?}: {a} (key {}) before {b} (key {})",
                        key(a),
                        key(b)
                    );
                }
                for &id in &rs.order {
                    let (p, l) = (id as usize / LANES, id as usize % LANES);
                    assert!(
                        cast.of(&scs[p]).active >> l & 1 == 1,
                        "{isa:?}: idle ray {id}"
                    );
                }
                let mut start = 0;
                while start < rs.order.len() {
                    let end = rs.gather(isa, start, &scs, cast);
                    for (k, &id) in rs.order[start..end].iter().enumerate() {
                        let (p, l) = (id as usize / LANES, id as usize % LANES);
                        assert_eq!(rs.packet.get(k), cast.of(&scs[p]).get(l), "{isa:?}");
                    }
                    assert_eq!(rs.packet.active, (1 << (end - start)) - 1);
                    start = end;
                }
            }
        }
    }
}
