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
//! back to the packets the rays came from.
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
use super::world::World;
use glam::Vec3;

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

    /// Sort the active rays of `ray(p)` for every packet p into `order`
    /// (a stable counting sort by key).
    #[inline(always)]
    fn sort<'a>(&mut self, n: usize, ray: impl Fn(usize) -> &'a RayPacket) {
        self.counts.fill(0);
        for p in 0..n {
            let r = ray(p);
            let mut k = [0u16; LANES];
            self.keys_of(r, &mut k);
            self.keys[p * LANES..(p + 1) * LANES].copy_from_slice(&k);
            for l in lanes(r.active) {
                self.counts[k[l] as usize + 1] += 1;
            }
        }
        // The first place of each key (counts[k + 1] held key k's count): a
        // running sum in a register, not `counts[k + 1] += counts[k]`, whose
        // every step waited on the store before it (2.3 % of perf's samples).
        let mut start = 0u32;
        for c in self.counts.iter_mut() {
            start += *c;
            *c = start;
        }
        let total = self.counts[KEYS] as usize;
        self.order.resize(total, 0);
        for p in 0..n {
            for l in lanes(ray(p).active) {
                let id = p * LANES + l;
                let k = self.keys[id] as usize;
                self.order[self.counts[k] as usize] = id as u32;
                self.counts[k] += 1;
            }
        }
    }

    /// Copy the next (up to) 16 rays of `order` from `start` — ray ids,
    /// packet × 16 + lane, of `ray(p)` — into `self.packet`; returns where
    /// the next packet starts.
    #[inline(always)]
    fn gather<'a>(&mut self, start: usize, ray: impl Fn(usize) -> &'a RayPacket) -> usize {
        let end = (start + LANES).min(self.order.len());
        let pk = &mut self.packet;
        for (k, &id) in self.order[start..end].iter().enumerate() {
            let (p, l) = (id as usize / LANES, id as usize % LANES);
            let r = ray(p);
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
    pub fn intersect(&mut self, world: &World, scs: &mut [PacketScratch]) {
        self.sort(scs.len(), |p| &scs[p].rays);
        let mut start = 0;
        while start < self.order.len() {
            let end = self.gather(start, |p| &scs[p].rays);
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
    pub fn unoccluded(&mut self, world: &World, scs: &[PacketScratch], free: &mut [LaneMask]) {
        free.fill(0);
        self.sort(scs.len(), |p| &scs[p].shadows);
        let mut start = 0;
        while start < self.order.len() {
            let end = self.gather(start, |p| &scs[p].shadows);
            let f = world.accel.unoccluded_packet(&self.packet);
            for k in lanes(f) {
                let id = self.order[start + k] as usize;
                free[id / LANES] |= 1 << (id % LANES);
            }
            start = end;
        }
    }
}
