//! Packet traversal of the 4-wide BVH (`bvh4.rs`): 16 rays from different
//! paths at once (`RayPacket`), SIMD across the rays.
//!
//! - Every lane does the same IEEE operations in the same order as the
//!   single-ray `Bvh4::intersect` / `unoccluded` of its ray: the same
//!   per-ray constants (`TriRay::new`'s axis permutation and shear, the
//!   inverse direction clamped to ±1e30), the same slab test (`maxps`/`minps`
//!   semantics, far distance widened by 1 + 2γ(3)), the same watertight
//!   triangle test (exact-zero edges re-evaluated in f64, pbrt-v4's `t > δt`)
//!   with the lane's closest t at leaf entry as tmax, the same closest-hit
//!   rule (strictly closer, triangles of a leaf in order). The per-lane axis
//!   permutation of the triangle test selects the vertex components per
//!   lane. Spheres and disks keep the scalar tests, lane by lane.
//! - Traversal: a stack of (node, per-lane entry distance, NaN in lanes that
//!   do not need the node). An inner node tests each child box against the
//!   node's lanes (each lane's tmax = its closest hit so far), continues into
//!   the first child hit by some lane and stacks the others; a popped node
//!   keeps only the lanes whose entry is not beyond their closest hit.
//!   Ordering the children by their lanes' nearest entry was measured slower
//!   on Cornell box bounces: with incoherent rays no order suits most lanes,
//!   and the reduction and sort cost more than they save. Occlusion drops
//!   blocked lanes from every mask and stops when none is left.
//! - Lane loops are plain loops over `[f32; 16]` / `[i32; 16]` (`V`, `M`),
//!   `#[inline(always)]` down to the leaves, so the render kernel's
//!   per-instruction-set copies (`simd.rs`) vectorise them 16, 8 or 4 lanes
//!   wide. What keeps LLVM's code vector-wide: lane masks are vectors of
//!   0 / −1 tested with `any` only (one `kortest` / `movmsk`; a 16-bit mask
//!   built lane by lane becomes a long shuffle-and-or reduction), no
//!   closures or `array::map` in lane code (left as calls), 3-trip loops
//!   written out (`unroll3`), and the rare f64 edge fallback kept scalar (as
//!   a vector blend LLVM computed it on every triangle test).
//!
//! Kernels: `Accel::intersect_packet` / `unoccluded_packet` run this
//! portable lane code at the SSE and AVX2 levels and, at `RenderIsa::Avx512`,
//! the same traversal written with AVX-512 intrinsics (`bvh4_packet_avx512.rs`: masks
//! in `__mmask16` registers, where the lane code round-trips every
//! comparison through a vector of 0 / −1), lane for lane the same IEEE
//! operations, so the same bits (`tests::check` compares every kernel the
//! CPU has with this one).
//!
//! Results per lane equal the single-ray query's bit for bit (t,
//! barycentrics, primitive; between primitives at exactly the same t either
//! may be reported), with one exception inherent to the single-ray traversal
//! itself: the lanes visit leaves in another order, and a box is culled when
//! its entry distance (rounded differently from a triangle's t) lies beyond
//! the closest hit so far. So for two primitives within a few ulps of each
//! other along a ray (coplanar overlapping faces, e.g. a box's bottom lying
//! on the floor, seen from inside the box) either query may report either
//! one; each reports that primitive's own exact hit. The tests saw 2 such
//! rays in 21 500 random Cornell box rays and none among path-traced bounces.
//!
//! Why: in small scenes such as the Cornell box, single-ray traversal of
//! incoherent secondary rays is dominated by unpredictable branches; a packet
//! replaces most of them with lane masks.

// Lane loops index several per-lane arrays at once.
#![allow(clippy::needless_range_loop)]

use super::bvh4::{Bvh4, EMPTY, LEAF, Node4, STACK};
use super::geometry::{PrimHit, Shape, TriRay, gamma};
use super::lanes::{M, V, max3_abs, unroll3};
use super::ray_packet::{ALL_LANES, LANES, LaneMask, PacketHits, RayPacket};
use std::mem::MaybeUninit;

/// The three components permuted per lane as the triangle test's axes
/// (kx, ky, kz): kz = 0 gives (y, z, x), kz = 1 (z, x, y), kz = 2 (x, y, z).
#[inline(always)]
fn permute(v: [V; 3], kz0: M, kz1: M) -> [V; 3] {
    [
        v[0].blend(kz1, v[2]).blend(kz0, v[1]),
        v[1].blend(kz1, v[0]).blend(kz0, v[2]),
        v[2].blend(kz1, v[1]).blend(kz0, v[0]),
    ]
}

/// Per-lane ray constants: what `RayPre::new` computes for each ray.
pub(super) struct PacketPre {
    o: [V; 3],
    d: [V; 3],
    /// Inverse direction, clamped to ±1e30.
    inv: [V; 3],
    /// Origin in the triangle test's permuted axes: `o[kx]`, `o[ky]`, `o[kz]`.
    op: [V; 3],
    /// `TriRay`'s shear `sx`, `sy`, `sz`.
    s: [V; 3],
    /// Lanes whose dominant direction axis (`TriRay::kz`) is x, resp. y
    /// (neither: z).
    kz0: M,
    kz1: M,
}

/// Triangle hits of a set of lanes: t, edge functions and 1/det per lane.
struct TriHits {
    t: V,
    e: [V; 3],
    inv_det: V,
}

impl PacketPre {
    /// Origin, clamped inverse direction, permuted origin, shear and the
    /// two axis masks, lane by lane (for the AVX-512 kernel).
    #[allow(clippy::type_complexity)]
    #[inline(always)]
    pub(super) fn parts(
        &self,
    ) -> (
        [&[f32; LANES]; 3],
        [&[f32; LANES]; 3],
        [&[f32; LANES]; 3],
        [&[f32; LANES]; 3],
        &[i32; LANES],
        &[i32; LANES],
    ) {
        (
            [&self.o[0].0, &self.o[1].0, &self.o[2].0],
            [&self.inv[0].0, &self.inv[1].0, &self.inv[2].0],
            [&self.op[0].0, &self.op[1].0, &self.op[2].0],
            [&self.s[0].0, &self.s[1].0, &self.s[2].0],
            &self.kz0.0,
            &self.kz1.0,
        )
    }

    #[inline(always)]
    pub(super) fn new(r: &RayPacket) -> Self {
        let o = [V(r.o[0]), V(r.o[1]), V(r.o[2])];
        let d = [V(r.d[0]), V(r.d[1]), V(r.d[2])];
        // As `TriRay::new`: the largest |d| component becomes z.
        let [ax, ay, az] = [d[0].abs(), d[1].abs(), d[2].abs()];
        let x_y = ax.gt(ay);
        let kz0 = x_y & ax.gt(az);
        let kz1 = !x_y & ay.gt(az);
        let dp = permute(d, kz0, kz1);
        let sz = V::splat(1.0) / dp[2];
        // As `RayPre::new`.
        let mut inv = [V::splat(0.0); 3];
        unroll3!(a => {
            inv[a] = V::splat(1.0) / d[a];
            for l in 0..LANES {
                let (i, c) = (inv[a].0[l], d[a].0[l]);
                inv[a].0[l] = if i.abs() <= 1e30 {
                    i
                } else {
                    1e30f32.copysign(c)
                };
            }
        });
        PacketPre {
            o,
            d,
            inv,
            op: permute(o, kz0, kz1),
            s: [dp[0].neg() * sz, dp[1].neg() * sz, sz],
            kz0,
            kz1,
        }
    }

    /// The lane's `TriRay` and direction (for the scalar sphere and disk tests).
    #[inline(always)]
    pub(super) fn tri_ray(&self, l: usize) -> (TriRay, glam::Vec3) {
        let o = glam::Vec3::new(self.o[0].0[l], self.o[1].0[l], self.o[2].0[l]);
        let d = glam::Vec3::new(self.d[0].0[l], self.d[1].0[l], self.d[2].0[l]);
        let kz = if self.kz0.get(l) {
            0
        } else if self.kz1.get(l) {
            1
        } else {
            2
        };
        let tri = TriRay {
            o,
            kz,
            sx: self.s[0].0[l],
            sy: self.s[1].0[l],
            sz: self.s[2].0[l],
        };
        (tri, d)
    }

    /// Slab test of child `c` of `n` for every lane: the lanes hitting the
    /// box within (0, tmax] and their entry distances (`RayPre::boxes`).
    #[inline(always)]
    fn child_box(&self, n: &Node4, c: usize, tmax: V) -> (M, V) {
        let mut tn = V::splat(0.0);
        let mut tf = tmax;
        unroll3!(a => {
            let lo = V::splat(n.b[0][a].as_array()[c]);
            let hi = V::splat(n.b[1][a].as_array()[c]);
            let t0 = (lo - self.o[a]) * self.inv[a];
            let t1 = (hi - self.o[a]) * self.inv[a];
            tn = tn.maxps(t0.minps(t1));
            tf = tf.minps(t0.maxps(t1));
        });
        tf = tf * V::splat(1.0 + 2.0 * gamma(3));
        (tn.le(tf), tn)
    }

    /// Watertight test of triangle `v[vertex][axis]` against the lanes of
    /// `m` (`RayPre::packet` for one triangle and 16 rays). Returns the lanes
    /// that hit it in (δt, tmax] and fills `h` for them.
    #[inline(always)]
    fn triangle(&self, v: &[[f32; 3]; 3], tmax: V, m: M, h: &mut TriHits) -> M {
        let mut px = [V::splat(0.0); 3];
        let mut py = px;
        let mut pz = px;
        unroll3!(i => {
            let [x, y, z] = [V::splat(v[i][0]), V::splat(v[i][1]), V::splat(v[i][2])];
            let [vx, vy, vz] = permute([x, y, z], self.kz0, self.kz1);
            pz[i] = vz - self.op[2];
            px[i] = (vx - self.op[0]) + self.s[0] * pz[i];
            py[i] = (vy - self.op[1]) + self.s[1] * pz[i];
        });
        let mut e = [
            px[1] * py[2] - py[1] * px[2],
            px[2] * py[0] - py[2] * px[0],
            px[0] * py[1] - py[0] * px[1],
        ];
        let zero = V::splat(0.0);
        let any_zero = m & (e[0].eq(zero) | e[1].eq(zero) | e[2].eq(zero));
        if any_zero.any() {
            // Exact-zero edge: re-evaluate those lanes in f64 (rare).
            let f = |ax: f32, ay: f32, bx: f32, by: f32| {
                (ax as f64 * by as f64 - ay as f64 * bx as f64) as f32
            };
            for l in 0..LANES {
                if any_zero.get(l) {
                    let x = [px[0].0[l], px[1].0[l], px[2].0[l]];
                    let y = [py[0].0[l], py[1].0[l], py[2].0[l]];
                    e[0].0[l] = f(x[1], y[1], x[2], y[2]);
                    e[1].0[l] = f(x[2], y[2], x[0], y[0]);
                    e[2].0[l] = f(x[0], y[0], x[1], y[1]);
                }
            }
        }
        let neg = e[0].lt(zero) | e[1].lt(zero) | e[2].lt(zero);
        let pos = e[0].gt(zero) | e[1].gt(zero) | e[2].gt(zero);
        let inside = m & !(neg & pos);
        if !inside.any() {
            return inside;
        }
        let det = e[0] + e[1] + e[2];
        let sz = self.s[2];
        unroll3!(i => {
            pz[i] = pz[i] * sz;
        });
        let ts = e[0] * pz[0] + e[1] * pz[1] + e[2] * pz[2];
        let tmd = tmax * det;
        let in_neg = det.lt(zero) & ts.lt(zero) & tmd.le(ts);
        let in_pos = det.gt(zero) & ts.gt(zero) & ts.le(tmd);
        let hit = inside & (in_neg | in_pos);
        if !hit.any() {
            return hit;
        }
        let inv_det = V::splat(1.0) / det;
        let t = ts * inv_det;
        // Conservative check that t is positive beyond its rounding error (pbrt-v4).
        let max_zt = max3_abs(&pz);
        let max_xt = max3_abs(&px);
        let max_yt = max3_abs(&py);
        let (g2, g3, g5) = (V::splat(gamma(2)), V::splat(gamma(3)), V::splat(gamma(5)));
        let delta_z = g3 * max_zt;
        let delta_x = g5 * (max_xt + max_zt);
        let delta_y = g5 * (max_yt + max_zt);
        let delta_e = V::splat(2.0) * (g2 * max_xt * max_yt + delta_y * max_xt + delta_x * max_yt);
        let max_e = max3_abs(&e);
        let delta_t = V::splat(3.0)
            * (g3 * max_e * max_zt + delta_e * max_zt + delta_z * max_e)
            * inv_det.abs();
        h.t = t;
        h.e = e;
        h.inv_det = inv_det;
        hit & t.gt(delta_t)
    }
}

/// Vertex `[vertex][axis]` of triangle `j` of a leaf's packet.
#[inline(always)]
fn vertices(p: &super::bvh4::TriPacket, j: usize) -> [[f32; 3]; 3] {
    let mut v = [[0.0; 3]; 3];
    unroll3!(i => {
        unroll3!(a => {
            v[i][a] = p.v[i][a].as_array()[j];
        });
    });
    v
}

impl Bvh4 {
    /// Closest hits of the active lanes of `rays` (`PacketHits` per lane as
    /// `intersect` of the lane's ray; inactive lanes report no hit).
    #[inline(always)]
    pub fn intersect_packet(&self, shapes: &[Shape], rays: &RayPacket, out: &mut PacketHits) {
        *out = PacketHits::default();
        let active = rays.active & ALL_LANES;
        if active == 0 {
            return;
        }
        let r = PacketPre::new(rays);
        let mut best_t = V(rays.tmax);
        let mut best_b = [V::splat(0.0); 3];
        let mut best_prim = [EMPTY; LANES];
        let mut h = TriHits {
            t: V::splat(0.0),
            e: [V::splat(0.0); 3],
            inv_det: V::splat(0.0),
        };
        // Uninitialised: zeroing it per packet would cost more than the
        // traversal of a small scene. Entries: node and per-lane entry
        // distance, NaN in lanes that do not need the node.
        let mut stack = [const { MaybeUninit::<(u32, V)>::uninit() }; STACK];
        let mut sp = 0usize;
        // As in `intersect`, the node being visited is kept out of the stack.
        let (mut code, mut mask) = (self.root, M::from_bits(active));
        'visit: loop {
            if code & LEAF != 0 {
                let leaf = &self.leaves[(code & !LEAF) as usize];
                if leaf.packet != EMPTY {
                    let p = &self.packets[leaf.packet as usize];
                    // Every triangle of the leaf is tested with the closest t
                    // at leaf entry as tmax, as the single-ray 4-triangle test.
                    let tmax = best_t;
                    for j in 0..p.n as usize {
                        let hit = r.triangle(&vertices(p, j), tmax, mask, &mut h);
                        let closer = hit & h.t.lt(best_t);
                        if closer.any() {
                            best_t = best_t.blend(closer, h.t);
                            unroll3!(k => {
                                best_b[k] = best_b[k].blend(closer, h.e[k] * h.inv_det);
                            });
                            let prim = p.prim[j];
                            for l in 0..LANES {
                                let b = best_prim[l];
                                best_prim[l] = if closer.0[l] != 0 { prim } else { b };
                            }
                        }
                    }
                }
                let s = leaf.others as usize;
                if leaf.n_others > 0 {
                    let lanes = mask.bits();
                    for &prim in &self.others[s..s + leaf.n_others as usize] {
                        for l in (0..LANES).filter(|l| lanes & (1 << l) != 0) {
                            let (tri, d) = r.tri_ray(l);
                            if let Some(hh) =
                                shapes[prim as usize].intersect_pre(&tri, d, best_t.0[l])
                                && hh.t < best_t.0[l]
                            {
                                best_t.0[l] = hh.t;
                                unroll3!(k => {
                                    best_b[k].0[l] = hh.b[k];
                                });
                                best_prim[l] = prim;
                            }
                        }
                    }
                }
            } else {
                let node = &self.nodes[code as usize];
                // Continue into the first child hit, stack the others with
                // their lanes' entry distances. (Ordering the children by
                // their lanes' nearest entry measured slower: with
                // incoherent rays no order suits most lanes.)
                let mut next = None;
                for c in 0..4 {
                    if node.valid & (1 << c) == 0 {
                        continue;
                    }
                    let (m, tn) = r.child_box(node, c, best_t);
                    let m = m & mask;
                    if !m.any() {
                        continue;
                    }
                    if next.is_none() {
                        next = Some((node.child[c], m));
                    } else {
                        stack[sp].write((node.child[c], V::splat(f32::NAN).blend(m, tn)));
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
                let (c, tn) = unsafe { stack[sp].assume_init() };
                let m = tn.le(best_t);
                if m.any() {
                    code = c;
                    mask = m;
                    continue 'visit;
                }
            }
        }
        for l in 0..LANES {
            if active & (1 << l) != 0 && best_prim[l] != EMPTY {
                out.prim[l] = best_prim[l];
                out.h[l] = PrimHit {
                    t: best_t.0[l],
                    b: [best_b[0].0[l], best_b[1].0[l], best_b[2].0[l]],
                };
            }
        }
    }

    /// The active lanes of `rays` along which nothing blocks the ray (each
    /// lane as `unoccluded`).
    #[inline(always)]
    pub fn unoccluded_packet(&self, shapes: &[Shape], rays: &RayPacket) -> LaneMask {
        let active = rays.active & ALL_LANES;
        if active == 0 {
            return 0;
        }
        let r = PacketPre::new(rays);
        let tmax = V(rays.tmax);
        let mut h = TriHits {
            t: V::splat(0.0),
            e: [V::splat(0.0); 3],
            inv_det: V::splat(0.0),
        };
        // Lanes not blocked so far.
        let mut free = M::from_bits(active);
        let mut stack = [const { MaybeUninit::<(u32, M)>::uninit() }; STACK];
        let mut sp = 0usize;
        let (mut code, mut mask) = (self.root, free);
        'visit: loop {
            if code & LEAF != 0 {
                let leaf = &self.leaves[(code & !LEAF) as usize];
                if leaf.packet != EMPTY {
                    let p = &self.packets[leaf.packet as usize];
                    for j in 0..p.n as usize {
                        let hit = r.triangle(&vertices(p, j), tmax, mask, &mut h);
                        free = free & !hit;
                        mask = mask & !hit;
                        if !mask.any() {
                            break;
                        }
                    }
                }
                let s = leaf.others as usize;
                if leaf.n_others > 0 {
                    for &prim in &self.others[s..s + leaf.n_others as usize] {
                        let lanes = mask.bits();
                        for l in (0..LANES).filter(|l| lanes & (1 << l) != 0) {
                            let (tri, d) = r.tri_ray(l);
                            if shapes[prim as usize]
                                .intersect_pre(&tri, d, tmax.0[l])
                                .is_some()
                            {
                                free.0[l] = 0;
                                mask.0[l] = 0;
                            }
                        }
                    }
                }
                if !free.any() {
                    return 0;
                }
            } else {
                let node = &self.nodes[code as usize];
                // Continue into the first child hit, stack the others.
                let mut next = None;
                for c in 0..4 {
                    if node.valid & (1 << c) == 0 {
                        continue;
                    }
                    let m = r.child_box(node, c, tmax).0 & mask;
                    if !m.any() {
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
                let (c, m) = unsafe { stack[sp].assume_init() };
                let m = m & free;
                if m.any() {
                    code = c;
                    mask = m;
                    continue 'visit;
                }
            }
        }
        free.bits()
    }
}

#[cfg(test)]
mod tests {
    use super::*;
    use crate::render::accel::BvhKind;
    use crate::render::geometry::offset_ray_origin;
    use crate::render::sampling::{Frame, Rng, cosine_hemisphere};
    use crate::render::world::World;
    use crate::spectrum::WavelengthGrid;
    use glam::Vec3;

    use crate::render::accel::{intersect_packet_at, unoccluded_packet_at};
    use crate::render::simd::RenderIsa;

    fn cornell() -> World {
        let (scene, _) = crate::render::bench::mitsuba_cornell_box();
        let grid = WavelengthGrid::new(500.0, 600.0, 50.0).unwrap();
        World::build(&scene, &grid, BvhKind::Bvh4).unwrap()
    }

    /// Every active lane of the packet queries must equal the single-ray
    /// queries: t and barycentrics bit for bit, the same primitive unless
    /// another lies at exactly the same t; inactive lanes report nothing.
    /// The one exception (see the module notes): two primitives within a
    /// few ulps of each other, where the box test's rounding makes the
    /// answer depend on the visiting order; then the packet's hit must be
    /// that primitive's own exact hit. Returns the number of hits, of active
    /// lanes and of such near ties.
    fn check(bvh: &Bvh4, shapes: &[Shape], rays: &RayPacket) -> [usize; 3] {
        // Garbage in the previous result must not leak through.
        let mut out = PacketHits {
            prim: [7; LANES],
            ..Default::default()
        };
        bvh.intersect_packet(shapes, rays, &mut out);
        let free = bvh.unoccluded_packet(shapes, rays);
        assert_eq!(free & !rays.active, 0, "inactive lanes reported free");
        // Every kernel this CPU has gives the portable kernel's bits.
        for isa in RenderIsa::ALL.into_iter().filter(|l| l.supported()) {
            let mut o2 = PacketHits {
                prim: [9; LANES],
                ..Default::default()
            };
            intersect_packet_at(bvh, isa, shapes, rays, &mut o2);
            assert_eq!(o2.prim, out.prim, "{isa:?}");
            for l in 0..LANES {
                let bits = |h: &PrimHit| [h.t, h.b[0], h.b[1], h.b[2]].map(f32::to_bits);
                assert_eq!(bits(&o2.h[l]), bits(&out.h[l]), "{isa:?} lane {l}");
            }
            assert_eq!(
                unoccluded_packet_at(bvh, isa, shapes, rays),
                free,
                "{isa:?}"
            );
        }
        let mut n = [0; 3];
        for l in 0..LANES {
            if rays.active & (1 << l) == 0 {
                assert_eq!(out.prim[l], EMPTY, "inactive lane {l} reported a hit");
                continue;
            }
            let (o, d, tmax) = rays.get(l);
            let want = bvh.intersect(shapes, o, d, tmax);
            match want {
                None => assert_eq!(out.prim[l], EMPTY, "lane {l}: {o} {d} {tmax}"),
                Some((prim, w)) => {
                    let g = out.h[l];
                    assert_ne!(out.prim[l], EMPTY, "lane {l}: missed {o} {d} {tmax}");
                    let bits = |h: &PrimHit| (h.t.to_bits(), h.b.map(f32::to_bits));
                    if out.prim[l] == prim {
                        assert_eq!(bits(&g), bits(&w), "lane {l}: {o} {d} {tmax}");
                    } else {
                        // A different primitive: its own hit, at the same t
                        // or (near tie) within a few ulps.
                        let own = shapes[out.prim[l] as usize].intersect(o, d, tmax);
                        assert_eq!(own.map(|h| bits(&h)), Some(bits(&g)), "lane {l}");
                        if g.t != w.t {
                            assert!(
                                (g.t - w.t).abs() <= 1e-6 * w.t,
                                "lane {l}: {o} {d} {tmax}: {} against {}",
                                g.t,
                                w.t
                            );
                            n[2] += 1;
                        }
                    }
                    n[0] += 1;
                }
            }
            let u = bvh.unoccluded(shapes, o, d, tmax);
            assert_eq!(free & (1 << l) != 0, u, "lane {l}: {o} {d} {tmax}");
            n[1] += 1;
        }
        n
    }

    /// Packets of several kinds over `shapes` inside about [-1, 1]³.
    fn packets(shapes: &[Shape], bvh: &Bvh4, seed: u64, n: usize) -> [usize; 3] {
        let mut rng = Rng::for_sample(seed, 0, 0);
        let mut v = || Vec3::new(rng.uniform(), rng.uniform(), rng.uniform()) * 2.0 - 1.0;
        let mut counts = [0; 3];
        for i in 0..n {
            let mut rays = RayPacket {
                // Garbage (NaN) in lanes left inactive.
                o: [[f32::NAN; LANES]; 3],
                d: [[f32::NAN; LANES]; 3],
                tmax: [f32::NAN; LANES],
                active: 0,
            };
            let common_o = v() * 1.5;
            let common_d = v();
            for l in 0..LANES {
                let kind = i % 4;
                let (o, mut d) = match kind {
                    // Incoherent.
                    0 | 3 => (v() * 1.5, v()),
                    // Coherent: one origin, nearby directions.
                    1 => (common_o, common_d + v() * 0.05),
                    // Shared origin, any direction.
                    _ => (common_o, v()),
                };
                // Axis-aligned directions exercise zero inverse components.
                match (i + l) % 7 {
                    0 => d = Vec3::new(d.x, 0.0, 0.0),
                    1 => d = Vec3::new(0.0, d.y, d.z),
                    _ => {}
                }
                if d == Vec3::ZERO {
                    d = Vec3::Y;
                }
                let tmax = match (i + 3 * l) % 3 {
                    0 => 0.5,
                    1 => f32::INFINITY,
                    _ => 1.0 + v().x,
                };
                // Partial masks in every third packet.
                if i % 3 != 2 || (l * 7 + i) % 3 != 0 {
                    rays.set(l, o, d, tmax);
                }
            }
            let c = check(bvh, shapes, &rays);
            for k in 0..3 {
                counts[k] += c[k];
            }
        }
        counts
    }

    #[test]
    fn packet_agrees_with_single_ray_on_soups() {
        for seed in [7, 8] {
            let mut rng = Rng::for_sample(seed, 1, 0);
            let shapes = super::super::bvh4::tests::soup(&mut rng);
            let bvh = Bvh4::build(&shapes).expect("shallow tree");
            let [hits, n, ties] = packets(&shapes, &bvh, seed, 1500);
            assert!(
                hits > n / 10 && n - hits > n / 10,
                "test rays too easy: {hits} of {n}"
            );
            assert!(ties <= n / 1000, "{ties} near ties in {n} rays");
        }
    }

    /// One leaf of four triangles met by packets of one to sixteen rays in
    /// scattered lanes, their far ends before, between or beyond the
    /// triangles: the AVX-512 kernel tests up to four rays against a leaf's
    /// triangles at once (`bvh4_packet_avx512::Spread`), and each
    /// triangle's place in that test must give the single-ray answers,
    /// closest hits and shadow rays. The four triangles halve one square
    /// two ways, each tilted at random, so that each is somewhere the
    /// nearest and the only one before a ray's far end; the tree is one
    /// leaf of two, three or four of them (`Bvh4::one_leaf`).
    #[test]
    fn packet_agrees_with_single_ray_on_one_leaf() {
        let corners = [
            [(0.0, 0.0), (2.0, 0.0), (0.0, 2.0)],
            [(2.0, 0.0), (2.0, 2.0), (0.0, 2.0)],
            [(0.0, 0.0), (2.0, 0.0), (2.0, 2.0)],
            [(0.0, 0.0), (2.0, 2.0), (0.0, 2.0)],
        ];
        let mut rng = Rng::for_sample(21, 0, 0);
        let mut counts = [0; 3];
        for trial in 0..48 {
            // Each triangle's corners at depths 1.0, 1.15 and 1.3 in a random
            // order; two, three or four triangles.
            let n = 2 + trial % 3;
            let shapes: Vec<Shape> = corners[..n]
                .iter()
                .map(|c| {
                    let mut z = [1.0f32, 1.15, 1.3];
                    for k in (1..3).rev() {
                        z.swap(k, ((rng.uniform() * (k + 1) as f32) as usize).min(k));
                    }
                    Shape::Triangle {
                        p: [0, 1, 2].map(|v| Vec3::new(c[v].0, c[v].1, z[v])),
                    }
                })
                .collect();
            let bvh = Bvh4::one_leaf(&shapes);
            for i in 0..100 {
                let mut rays = RayPacket {
                    o: [[f32::NAN; LANES]; 3],
                    d: [[f32::NAN; LANES]; 3],
                    tmax: [f32::NAN; LANES],
                    active: 0,
                };
                let want = 1 + (i % LANES) as u32;
                while rays.active.count_ones() < want {
                    let l = ((rng.uniform() * LANES as f32) as usize).min(LANES - 1);
                    let o = Vec3::new(2.2 * rng.uniform() - 0.1, 2.2 * rng.uniform() - 0.1, 0.0);
                    let d = Vec3::new(
                        0.02 * rng.uniform() - 0.01,
                        0.02 * rng.uniform() - 0.01,
                        1.0,
                    );
                    rays.set(l, o, d, 0.95 + 0.4 * rng.uniform());
                }
                let c = check(&bvh, &shapes, &rays);
                for k in 0..3 {
                    counts[k] += c[k];
                }
            }
        }
        let [hits, n, ties] = counts;
        assert!(hits > n / 4 && n - hits > n / 4, "{hits} of {n}");
        assert_eq!(ties, 0);
    }

    #[test]
    fn packet_agrees_with_single_ray_in_cornell_box() {
        let world = cornell();
        let shapes = &world.accel.shapes;
        let bvh = Bvh4::build(shapes).expect("shallow tree");
        // Random rays, some starting inside the boxes, whose bottoms lie in
        // the floor's plane: near ties between coplanar faces.
        let [hits, n, ties] = packets(shapes, &bvh, 3, 1500);
        assert!(hits > n / 10 && n - hits > n / 10, "{hits} of {n}");
        assert!(ties <= n / 1000, "{ties} near ties in {n} rays");
        // Path-traced bounces and shadow rays, as the renderer casts them:
        // no near ties there.
        let (sec, shadow) = bounce_rays(&world, &bvh, 3000);
        for rays in sec.iter().chain(&shadow) {
            assert_eq!(check(&bvh, shapes, rays)[2], 0);
        }
    }

    /// Packets of secondary rays (from random surface points of the Cornell
    /// box, cosine-distributed) and of shadow rays from the same points to
    /// random points on the light.
    fn bounce_rays(world: &World, bvh: &Bvh4, n: usize) -> (Vec<RayPacket>, Vec<RayPacket>) {
        let shapes = &world.accel.shapes;
        let mut rng = Rng::for_sample(11, 0, 0);
        let (mut sec, mut shadow) = (Vec::new(), Vec::new());
        let (mut a, mut b) = (RayPacket::default(), RayPacket::default());
        let mut l = 0;
        while sec.len() < n {
            // A surface point: where a random ray from inside the box lands.
            let o = Vec3::new(rng.uniform(), rng.uniform(), rng.uniform()) * 1.8 - 0.9;
            let (u, v) = rng.uniform2();
            let d = crate::render::sampling::uniform_sphere(u, v);
            let Some((prim, h)) = bvh.intersect(shapes, o, d, f32::INFINITY) else {
                continue;
            };
            let (p, err, mut nrm) = world.surface(prim, o, d, &h);
            if nrm.dot(d) > 0.0 {
                nrm = -nrm;
            }
            let (u, v) = rng.uniform2();
            let wi = Frame::from_normal(nrm).to_world(cosine_hemisphere(u, v));
            a.set(l, offset_ray_origin(p, err, nrm, wi), wi, f32::INFINITY);
            // Light: x ∈ ±0.23, y = 0.99, z ∈ 0.01 ± 0.19.
            let (u, v) = rng.uniform2();
            let q = Vec3::new(u * 0.46 - 0.23, 0.99, 0.01 + v * 0.38 - 0.19);
            let ps = offset_ray_origin(p, err, nrm, q - p);
            b.set(l, ps, q - ps, 1.0 - 1e-4);
            l += 1;
            if l == LANES {
                sec.push(a);
                shadow.push(b);
                l = 0;
            }
        }
        (sec, shadow)
    }

    /// Seconds for: single-ray closest hits, packet closest hits, single-ray
    /// occlusion, packet occlusion; and a checksum.
    #[inline(always)]
    fn timing(bvh: &Bvh4, shapes: &[Shape], sec: &[RayPacket], shadow: &[RayPacket]) -> [f64; 7] {
        let mut sum = 0.0f64;
        let mut t = [0.0f64; 7];
        let now = std::time::Instant::now();
        for p in sec {
            for l in 0..LANES {
                let (o, d, tmax) = p.get(l);
                if let Some((_, h)) = bvh.intersect(shapes, o, d, tmax) {
                    sum += h.t as f64;
                }
            }
        }
        t[0] = now.elapsed().as_secs_f64();
        let now = std::time::Instant::now();
        let mut out = PacketHits::default();
        for p in sec {
            bvh.intersect_packet(shapes, p, &mut out);
            sum += out.h[0].t as f64;
        }
        t[1] = now.elapsed().as_secs_f64();
        let now = std::time::Instant::now();
        let mut n = 0u32;
        for p in shadow {
            for l in 0..LANES {
                let (o, d, tmax) = p.get(l);
                n += bvh.unoccluded(shapes, o, d, tmax) as u32;
            }
        }
        t[2] = now.elapsed().as_secs_f64();
        let now = std::time::Instant::now();
        for p in shadow {
            n += bvh.unoccluded_packet(shapes, p).count_ones();
        }
        t[3] = now.elapsed().as_secs_f64();
        // The AVX-512 intrinsics kernel where the CPU has it.
        if RenderIsa::Avx512.supported() {
            let now = std::time::Instant::now();
            for p in sec {
                intersect_packet_at(bvh, RenderIsa::Avx512, shapes, p, &mut out);
                sum += out.h[0].t as f64;
            }
            t[5] = now.elapsed().as_secs_f64();
            let now = std::time::Instant::now();
            for p in shadow {
                n += unoccluded_packet_at(bvh, RenderIsa::Avx512, shapes, p).count_ones();
            }
            t[6] = now.elapsed().as_secs_f64();
        }
        t[4] = sum + n as f64;
        t
    }

    #[cfg(target_arch = "x86_64")]
    #[target_feature(enable = "avx2,fma,bmi1,bmi2,lzcnt,popcnt")]
    fn timing_avx2(b: &Bvh4, s: &[Shape], sec: &[RayPacket], sh: &[RayPacket]) -> [f64; 7] {
        timing(b, s, sec, sh)
    }

    #[cfg(target_arch = "x86_64")]
    #[target_feature(enable = "avx512f,avx512vl,avx512bw,avx512dq,avx2,fma,bmi1,bmi2,lzcnt,popcnt")]
    fn timing_avx512(b: &Bvh4, s: &[Shape], sec: &[RayPacket], sh: &[RayPacket]) -> [f64; 7] {
        timing(b, s, sec, sh)
    }

    /// Single-ray against packet queries on Cornell box bounces, in the order
    /// drawn and sorted by `sorted_by_cell`; prints ns per ray (`cargo test
    /// --release --lib bvh4_packet -- --ignored --nocapture`).
    /// `bench/mitsuba_trace.sh` runs it beside Mitsuba's traversal of the same
    /// kind of rays.
    #[test]
    #[ignore]
    #[cfg(target_arch = "x86_64")]
    fn packet_timing_cornell_box() {
        use crate::render::simd::RenderIsa;
        let world = cornell();
        let shapes = &world.accel.shapes;
        let bvh = Bvh4::build(shapes).expect("shallow tree");
        let (sec, shadow) = bounce_rays(&world, &bvh, 1 << 14);
        let nrays = (sec.len() * LANES) as f64;
        let by_key = (sorted_by_cell(&sec), sorted_by_cell(&shadow));
        for (order, (sec, shadow)) in [
            ("as drawn", (sec, shadow)),
            ("sorted by octant and origin cell", by_key),
        ] {
            println!("rays {order}:");
            let (sec, shadow) = (&sec[..], &shadow[..]);
            for isa in RenderIsa::ALL {
                if !isa.supported() {
                    continue;
                }
                let mut best = [f64::INFINITY; 7];
                for _ in 0..5 {
                    let t = match isa {
                        RenderIsa::Sse => timing(&bvh, shapes, sec, shadow),
                        // SAFETY: the CPU supports the features.
                        RenderIsa::Avx2 => unsafe { timing_avx2(&bvh, shapes, sec, shadow) },
                        // SAFETY: as above.
                        RenderIsa::Avx512 => unsafe { timing_avx512(&bvh, shapes, sec, shadow) },
                    };
                    for k in 0..7 {
                        best[k] = best[k].min(t[k]);
                    }
                }
                let ns = best.map(|s| s * 1e9 / nrays);
                println!(
                    "{:>8}: closest single {:.1} packet {:.1} ns/ray ({:.2}x); occlusion single {:.1} packet {:.1} ns/ray ({:.2}x)",
                    isa.name(),
                    ns[0],
                    ns[1],
                    ns[0] / ns[1],
                    ns[2],
                    ns[3],
                    ns[2] / ns[3]
                );
                if isa == RenderIsa::Avx512 {
                    println!(
                        "  avx512 intrinsics kernel: closest packet {:.1} ns/ray ({:.2}x single), occlusion packet {:.1} ns/ray ({:.2}x)",
                        ns[5],
                        ns[0] / ns[5],
                        ns[6],
                        ns[2] / ns[6]
                    );
                }
            }
        }
    }

    /// The rays of `ps` repacked in the order of a key (stable): direction
    /// octant, then origin cell of a 4 × 4 × 4 grid over [−1, 1]³ (the
    /// Mitsuba box). `bench/mitsuba_trace.py` sorts its rays by the same key,
    /// so the two traversals are timed on rays of the same coherence.
    fn sorted_by_cell(ps: &[RayPacket]) -> Vec<RayPacket> {
        let cell = |x: f32| (((x + 1.0) * 2.0) as i32).clamp(0, 3) as u32;
        let mut v: Vec<(u32, Vec3, Vec3, f32)> = Vec::new();
        for p in ps {
            for l in 0..LANES {
                let (o, d, t) = p.get(l);
                let octant = (d.x < 0.0) as u32 + 2 * (d.y < 0.0) as u32 + 4 * (d.z < 0.0) as u32;
                let key = octant * 64 + cell(o.x) * 16 + cell(o.y) * 4 + cell(o.z);
                v.push((key, o, d, t));
            }
        }
        v.sort_by_key(|x| x.0);
        v.chunks(LANES)
            .map(|ch| {
                let mut p = RayPacket::default();
                for (l, &(_, o, d, t)) in ch.iter().enumerate() {
                    p.set(l, o, d, t);
                }
                p
            })
            .collect()
    }
}
