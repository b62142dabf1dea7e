//! A 4-wide BVH traversed with SSE (`wide::f32x4`): one ray against four
//! child boxes, and against four triangles at a time.
//!
//! - Built by obvhs' SAH BVH2 builder, then collapsed: each 4-wide node takes
//!   the two children of a binary node and keeps opening the inner child with
//!   the largest surface area until it holds four.
//! - Leaves hold up to four primitives. Triangles are stored structure-of-arrays
//!   in packets of four and tested together with the same watertight test as
//!   `geometry::intersect_triangle_pre` (Woo, Benthin & Wald), lane by lane the
//!   same operations in the same order, including the exact-zero edge fallback
//!   in f64 and pbrt-v4's conservative `t > δt` check. Spheres and disks keep
//!   the scalar tests.
//! - Box test: slabs, near/far distance per axis by min/max of the two plane
//!   distances (no per-ray index into the node: the same values as choosing
//!   the plane by the direction's sign; empty lanes are masked by the node's
//!   `valid` bits), the inverse direction clamped to ±1e30 (no NaN; a ray lying in a slab plane
//!   counts as inside), and the far distance widened by 1 + 2γ(3) as pbrt does
//!   for robustness.
//! - Closest hit visits children near to far and skips any whose entry
//!   distance lies beyond the closest hit found so far.
//!
//! Why: on the Mitsuba Cornell box (`camsim bench render`) ray casting through
//! obvhs' scalar BVH2 traversal took over half of the render time.

// Lane loops index several per-lane arrays at once.
#![allow(clippy::needless_range_loop)]

use super::geometry::{PrimHit, Shape, TriRay, gamma};
use obvhs::{BvhBuildParams, bvh2::Bvh2};
use std::mem::MaybeUninit;
use wide::f32x4;

pub(super) const LEAF: u32 = 1 << 31;
pub(super) const EMPTY: u32 = u32::MAX;
/// Traversal stack size; a tree whose depth could overflow it is not built
/// (the caller falls back to the binary BVH).
pub(super) const STACK: usize = 256;

#[derive(Clone, Copy)]
#[repr(C, align(16))]
pub(super) struct Node4 {
    /// `b[0]` = box minima, `b[1]` = maxima; `[axis]`; lanes = children.
    pub(super) b: [[f32x4; 3]; 2],
    pub(super) child: [u32; 4],
    /// Bit l set when lane l holds a child.
    pub(super) valid: u32,
}

impl Node4 {
    fn empty() -> Self {
        Node4 {
            b: [
                [f32x4::splat(f32::INFINITY); 3],
                [f32x4::splat(f32::NEG_INFINITY); 3],
            ],
            child: [EMPTY; 4],
            valid: 0,
        }
    }
}

#[derive(Clone, Copy)]
pub(super) struct Leaf {
    pub(super) packet: u32,
    pub(super) others: u32,
    pub(super) n_others: u32,
}

/// Up to four triangles, structure of arrays: `v[vertex][axis]`.
#[derive(Clone, Copy)]
#[repr(C, align(16))]
pub(super) struct TriPacket {
    pub(super) v: [[f32x4; 3]; 3],
    pub(super) prim: [u32; 4],
    /// Lanes `0..n` hold triangles.
    pub(super) n: u32,
    /// The same vertices as points, `xyz[vertex][lane]` = (x, y, z, 0): what
    /// the AVX-512 packet kernel permutes into its lanes — one triangle's
    /// vertex broadcast to every ray, or one vertex of all four triangles
    /// (one 64-byte row) spread over up to four rays.
    pub(super) xyz: [[[f32; 4]; 4]; 3],
}

pub struct Bvh4 {
    pub(super) nodes: Vec<Node4>,
    pub(super) leaves: Vec<Leaf>,
    pub(super) packets: Vec<TriPacket>,
    pub(super) others: Vec<u32>,
    pub(super) root: u32,
}

/// Per-ray constants for the box and triangle tests.
struct RayPre {
    inv: [f32x4; 3],
    os: [f32x4; 3],
    tri: TriRay,
    k: [usize; 3],
}

impl RayPre {
    #[inline(always)]
    fn new(o: glam::Vec3, d: glam::Vec3) -> Self {
        let tri = TriRay::new(o, d);
        let kz = tri.kz as usize;
        let kx = (kz + 1) % 3;
        let ky = (kx + 1) % 3;
        // Inverse direction clamped to ±1e30: a zero (or denormal) component
        // then gives finite slab distances, never 0·∞ = NaN, so the box test
        // can use plain min/max. The clamp only moves slab crossings that lie
        // beyond ~1e30·(distance to the plane), far outside any scene.
        let inv = [d.x, d.y, d.z].map(|c| {
            let i = 1.0 / c;
            if i.abs() <= 1e30 {
                i
            } else {
                1e30f32.copysign(c)
            }
        });
        RayPre {
            inv: inv.map(f32x4::splat),
            os: [f32x4::splat(o.x), f32x4::splat(o.y), f32x4::splat(o.z)],
            tri,
            k: [kx, ky, kz],
        }
    }

    /// Entry distances of the four child boxes and the mask of those hit
    /// within (0, tmax].
    #[inline(always)]
    fn boxes(&self, n: &Node4, tmax: f32) -> (u32, [f32; 4]) {
        let mut tn = f32x4::ZERO;
        let mut tf = f32x4::splat(tmax);
        for a in 0..3 {
            let t0 = (n.b[0][a] - self.os[a]) * self.inv[a];
            let t1 = (n.b[1][a] - self.os[a]) * self.inv[a];
            tn = tn.fast_max(t0.fast_min(t1));
            tf = tf.fast_min(t0.fast_max(t1));
        }
        tf *= f32x4::splat(1.0 + 2.0 * gamma(3));
        (tn.simd_le(tf).to_bitmask() & n.valid, tn.to_array())
    }

    /// Watertight test of four triangles; returns the lane mask of hits in
    /// (0, tmax] and t, b0, b1, b2 per lane.
    #[inline(always)]
    fn packet(&self, p: &TriPacket, tmax: f32) -> (u32, [f32x4; 4]) {
        let [kx, ky, kz] = self.k;
        let (ox, oy, oz) = (self.os[kx], self.os[ky], self.os[kz]);
        let sx = f32x4::splat(self.tri.sx);
        let sy = f32x4::splat(self.tri.sy);
        let sz = f32x4::splat(self.tri.sz);
        let mut pz = [p.v[0][kz] - oz, p.v[1][kz] - oz, p.v[2][kz] - oz];
        let mut px = [p.v[0][kx] - ox, p.v[1][kx] - ox, p.v[2][kx] - ox];
        let mut py = [p.v[0][ky] - oy, p.v[1][ky] - oy, p.v[2][ky] - oy];
        for i in 0..3 {
            px[i] += sx * pz[i];
            py[i] += sy * pz[i];
        }
        let mut e0 = px[1] * py[2] - py[1] * px[2];
        let mut e1 = px[2] * py[0] - py[2] * px[0];
        let mut e2 = px[0] * py[1] - py[0] * px[1];
        let valid = (1u32 << p.n) - 1;
        let zero = f32x4::ZERO;
        let any_zero =
            (e0.simd_eq(zero) | e1.simd_eq(zero) | e2.simd_eq(zero)).to_bitmask() & valid;
        if any_zero != 0 {
            // Exact-zero edge: re-evaluate those lanes in f64 (rare).
            let (pxa, pya) = (px.map(|v| v.to_array()), py.map(|v| v.to_array()));
            let (mut a0, mut a1, mut a2) = (e0.to_array(), e1.to_array(), e2.to_array());
            let f = |ax: f32, ay: f32, bx: f32, by: f32| {
                (ax as f64 * by as f64 - ay as f64 * bx as f64) as f32
            };
            for l in 0..4 {
                if any_zero & (1 << l) != 0 {
                    a0[l] = f(pxa[1][l], pya[1][l], pxa[2][l], pya[2][l]);
                    a1[l] = f(pxa[2][l], pya[2][l], pxa[0][l], pya[0][l]);
                    a2[l] = f(pxa[0][l], pya[0][l], pxa[1][l], pya[1][l]);
                }
            }
            e0 = f32x4::new(a0);
            e1 = f32x4::new(a1);
            e2 = f32x4::new(a2);
        }
        let neg = e0.simd_lt(zero) | e1.simd_lt(zero) | e2.simd_lt(zero);
        let pos = e0.simd_gt(zero) | e1.simd_gt(zero) | e2.simd_gt(zero);
        let inside = !(neg & pos).to_bitmask() & valid;
        if inside == 0 {
            return (0, [zero; 4]);
        }
        let det = e0 + e1 + e2;
        for z in &mut pz {
            *z *= sz;
        }
        let t_scaled = e0 * pz[0] + e1 * pz[1] + e2 * pz[2];
        let tmd = f32x4::splat(tmax) * det;
        let in_neg = det.simd_lt(zero) & t_scaled.simd_lt(zero) & t_scaled.simd_ge_(tmd);
        let in_pos = det.simd_gt(zero) & t_scaled.simd_gt(zero) & t_scaled.simd_le(tmd);
        let mut mask = (in_neg | in_pos).to_bitmask() & inside;
        if mask == 0 {
            return (0, [zero; 4]);
        }
        let inv_det = f32x4::ONE / det;
        let t = t_scaled * inv_det;
        // Conservative check that t is positive beyond its rounding error (pbrt-v4).
        let max3 = |v: &[f32x4; 3]| v[0].abs().max(v[1].abs()).max(v[2].abs());
        let max_zt = max3(&pz);
        let max_xt = max3(&px);
        let max_yt = max3(&py);
        let delta_z = f32x4::splat(gamma(3)) * max_zt;
        let delta_x = f32x4::splat(gamma(5)) * (max_xt + max_zt);
        let delta_y = f32x4::splat(gamma(5)) * (max_yt + max_zt);
        let delta_e = f32x4::splat(2.0)
            * (f32x4::splat(gamma(2)) * max_xt * max_yt + delta_y * max_xt + delta_x * max_yt);
        let max_e = e0.abs().max(e1.abs()).max(e2.abs());
        let delta_t = f32x4::splat(3.0)
            * (f32x4::splat(gamma(3)) * max_e * max_zt + delta_e * max_zt + delta_z * max_e)
            * inv_det.abs();
        mask &= t.simd_gt(delta_t).to_bitmask();
        (mask, [t, e0 * inv_det, e1 * inv_det, e2 * inv_det])
    }
}

/// `a >= b` lane-wise (wide's `CmpGe` is avoided for symmetry with the scalar code).
trait GeExt {
    fn simd_ge_(self, rhs: Self) -> Self;
}
impl GeExt for f32x4 {
    #[inline(always)]
    fn simd_ge_(self, rhs: Self) -> Self {
        rhs.simd_le(self)
    }
}

fn area(a: &obvhs::aabb::Aabb) -> f32 {
    let e = (a.max - a.min).max(glam::Vec3A::ZERO);
    e.x * e.y + e.y * e.z + e.z * e.x
}

impl Bvh4 {
    /// Build over `shapes` (non-empty). `None` when the tree would be too deep
    /// for the fixed traversal stack.
    pub fn build(shapes: &[Shape]) -> Option<Bvh4> {
        let mut t = std::time::Duration::ZERO;
        let mut params = BvhBuildParams::medium_build();
        params.max_prims_per_leaf = 4;
        params.collapse_traversal_cost = 1.0;
        let b2 = obvhs::bvh2::builder::build_bvh2(shapes, params, &mut t);
        if b2.nodes.is_empty() {
            return None;
        }
        let mut out = Bvh4::empty();
        let mut depth = 0;
        out.root = out.collapse(&b2, 0, shapes, 1, &mut depth);
        // A 4-wide traversal leaves at most 3 entries on the stack per level.
        (3 * depth + 4 <= STACK).then_some(out)
    }

    /// No nodes, leaves or primitives yet.
    fn empty() -> Bvh4 {
        Bvh4 {
            nodes: Vec::new(),
            leaves: Vec::new(),
            packets: Vec::new(),
            others: Vec::new(),
            root: EMPTY,
        }
    }

    fn leaf(&mut self, b2: &Bvh2, n: usize, shapes: &[Shape]) -> u32 {
        let node = &b2.nodes[n];
        let first = node.first_index as usize;
        self.leaf_of(
            &b2.primitive_indices[first..first + node.prim_count as usize],
            shapes,
        )
    }

    /// A tree that is one leaf holding every shape (at most four
    /// triangles are packed; the rest go to the scalar tests): the SAH
    /// builder rarely packs more than two triangles in a leaf, so the
    /// traversal tests build this one to reach a full leaf.
    #[cfg(test)]
    pub(super) fn one_leaf(shapes: &[Shape]) -> Bvh4 {
        let mut out = Bvh4::empty();
        let prims: Vec<u32> = (0..shapes.len() as u32).collect();
        out.root = out.leaf_of(&prims, shapes);
        out
    }

    /// A leaf of `prims`: its first four triangles as a packet, the rest in
    /// `others`.
    fn leaf_of(&mut self, prims: &[u32], shapes: &[Shape]) -> u32 {
        let mut packet = TriPacket {
            v: [[f32x4::ZERO; 3]; 3],
            prim: [EMPTY; 4],
            n: 0,
            xyz: [[[0.0; 4]; 4]; 3],
        };
        let mut v = [[[0.0f32; 4]; 3]; 3];
        let others = self.others.len() as u32;
        for &prim in prims {
            match shapes[prim as usize] {
                Shape::Triangle { p } if packet.n < 4 => {
                    let l = packet.n as usize;
                    for (vi, pv) in p.iter().enumerate() {
                        for a in 0..3 {
                            v[vi][a][l] = pv[a];
                        }
                        packet.xyz[vi][l] = [pv.x, pv.y, pv.z, 0.0];
                    }
                    packet.prim[l] = prim;
                    packet.n += 1;
                }
                _ => self.others.push(prim),
            }
        }
        let packet_idx = if packet.n > 0 {
            packet.v = v.map(|axes| axes.map(f32x4::new));
            self.packets.push(packet);
            self.packets.len() as u32 - 1
        } else {
            EMPTY
        };
        self.leaves.push(Leaf {
            packet: packet_idx,
            others,
            n_others: self.others.len() as u32 - others,
        });
        (self.leaves.len() as u32 - 1) | LEAF
    }

    fn collapse(
        &mut self,
        b2: &Bvh2,
        n: usize,
        shapes: &[Shape],
        level: usize,
        depth: &mut usize,
    ) -> u32 {
        *depth = (*depth).max(level);
        let node = &b2.nodes[n];
        if node.prim_count > 0 {
            return self.leaf(b2, n, shapes);
        }
        let f = node.first_index as usize;
        let mut kids = vec![f, f + 1];
        while kids.len() < 4 {
            let open = kids
                .iter()
                .enumerate()
                .filter(|&(_, &k)| b2.nodes[k].prim_count == 0)
                .max_by(|a, b| area(&b2.nodes[*a.1].aabb).total_cmp(&area(&b2.nodes[*b.1].aabb)))
                .map(|(i, _)| i);
            let Some(i) = open else { break };
            let k = kids.remove(i);
            let c = b2.nodes[k].first_index as usize;
            kids.insert(i, c + 1);
            kids.insert(i, c);
        }
        let idx = self.nodes.len();
        self.nodes.push(Node4::empty());
        let mut out = Node4::empty();
        let mut b = [[[f32::INFINITY; 4]; 3], [[f32::NEG_INFINITY; 4]; 3]];
        for (lane, &k) in kids.iter().enumerate() {
            let bb = b2.nodes[k].aabb;
            for a in 0..3 {
                b[0][a][lane] = bb.min[a];
                b[1][a][lane] = bb.max[a];
            }
            out.child[lane] = self.collapse(b2, k, shapes, level + 1, depth);
            out.valid |= 1 << lane;
        }
        out.b = b.map(|axes| axes.map(f32x4::new));
        self.nodes[idx] = out;
        idx as u32
    }

    /// Closest hit along `o + t·d`, t ∈ (0, tmax).
    #[inline(always)]
    pub fn intersect(
        &self,
        shapes: &[Shape],
        o: glam::Vec3,
        d: glam::Vec3,
        tmax: f32,
    ) -> Option<(u32, PrimHit)> {
        let r = RayPre::new(o, d);
        let mut best = PrimHit {
            t: tmax,
            b: [0.0; 3],
        };
        let mut best_prim = EMPTY;
        // Uninitialised: zeroing the stack per ray showed up as memset in profiles.
        let mut stack = [const { MaybeUninit::<(u32, f32)>::uninit() }; STACK];
        let mut sp = 0usize;
        // The node being visited is kept out of the stack: a node with one
        // child hit continues straight into it, several push all but the
        // nearest (far to near) and continue into the nearest.
        let mut code = self.root;
        'visit: loop {
            if code & LEAF != 0 {
                let leaf = &self.leaves[(code & !LEAF) as usize];
                if leaf.packet != EMPTY {
                    let p = &self.packets[leaf.packet as usize];
                    let (mask, [t, b0, b1, b2]) = r.packet(p, best.t);
                    if mask != 0 {
                        let ta = t.to_array();
                        let mut lane = usize::MAX;
                        let mut bt = best.t;
                        for l in 0..4 {
                            if mask & (1 << l) != 0 && ta[l] < bt {
                                bt = ta[l];
                                lane = l;
                            }
                        }
                        if lane != usize::MAX {
                            best = PrimHit {
                                t: bt,
                                b: [
                                    b0.to_array()[lane],
                                    b1.to_array()[lane],
                                    b2.to_array()[lane],
                                ],
                            };
                            best_prim = p.prim[lane];
                        }
                    }
                }
                let s = leaf.others as usize;
                for &prim in &self.others[s..s + leaf.n_others as usize] {
                    if let Some(h) = shapes[prim as usize].intersect_pre(&r.tri, d, best.t)
                        && h.t < best.t
                    {
                        best = h;
                        best_prim = prim;
                    }
                }
            } else {
                let node = &self.nodes[code as usize];
                let (mask, tna) = r.boxes(node, best.t);
                if mask != 0 {
                    if mask.is_power_of_two() {
                        code = node.child[mask.trailing_zeros() as usize];
                        continue 'visit;
                    }
                    // Sort the hit children far to near.
                    let mut hits = [(0u32, 0.0f32); 4];
                    let mut nh = 0;
                    for l in 0..4 {
                        if mask & (1 << l) != 0 {
                            let mut j = nh;
                            while j > 0 && hits[j - 1].1 < tna[l] {
                                hits[j] = hits[j - 1];
                                j -= 1;
                            }
                            hits[j] = (node.child[l], tna[l]);
                            nh += 1;
                        }
                    }
                    for h in &hits[..nh - 1] {
                        stack[sp].write(*h);
                        sp += 1;
                    }
                    code = hits[nh - 1].0;
                    continue 'visit;
                }
            }
            // Next stacked node whose entry lies before the closest hit.
            loop {
                if sp == 0 {
                    break 'visit;
                }
                sp -= 1;
                // SAFETY: entries below `sp` were written before being counted.
                let (c, tn) = unsafe { stack[sp].assume_init() };
                if tn <= best.t {
                    code = c;
                    continue 'visit;
                }
            }
        }
        (best_prim != EMPTY).then_some((best_prim, best))
    }

    /// True when nothing blocks `o + t·d` for t ∈ (0, tmax).
    #[inline(always)]
    pub fn unoccluded(&self, shapes: &[Shape], o: glam::Vec3, d: glam::Vec3, tmax: f32) -> bool {
        let r = RayPre::new(o, d);
        let mut stack = [const { MaybeUninit::<u32>::uninit() }; STACK];
        let mut sp = 0usize;
        let mut code = self.root;
        'visit: loop {
            if code & LEAF != 0 {
                let leaf = &self.leaves[(code & !LEAF) as usize];
                if leaf.packet != EMPTY
                    && r.packet(&self.packets[leaf.packet as usize], tmax).0 != 0
                {
                    return false;
                }
                let s = leaf.others as usize;
                for &prim in &self.others[s..s + leaf.n_others as usize] {
                    if shapes[prim as usize]
                        .intersect_pre(&r.tri, d, tmax)
                        .is_some()
                    {
                        return false;
                    }
                }
            } else {
                let node = &self.nodes[code as usize];
                let (mut mask, _) = r.boxes(node, tmax);
                if mask != 0 {
                    // Continue into the first child hit, stack the others.
                    code = node.child[mask.trailing_zeros() as usize];
                    mask &= mask - 1;
                    while mask != 0 {
                        stack[sp].write(node.child[mask.trailing_zeros() as usize]);
                        sp += 1;
                        mask &= mask - 1;
                    }
                    continue 'visit;
                }
            }
            if sp == 0 {
                break;
            }
            sp -= 1;
            // SAFETY: entries below `sp` were written before being counted.
            code = unsafe { stack[sp].assume_init() };
        }
        true
    }
}

#[cfg(test)]
pub(super) mod tests {
    use super::*;
    use crate::render::sampling::Rng;
    use glam::Vec3;

    /// A point uniform in [−1, 1]³.
    pub(in crate::render) fn point(rng: &mut Rng) -> Vec3 {
        Vec3::new(rng.uniform(), rng.uniform(), rng.uniform()) * 2.0 - 1.0
    }

    /// A test scene for the traversals: 300 random triangles (edges up to
    /// ≈ 0.5) in [−1, 1]³ with 10 spheres and 10 disks among them.
    pub(in crate::render) fn soup(rng: &mut Rng) -> Vec<Shape> {
        let mut v = || point(rng);
        let mut shapes = Vec::new();
        for _ in 0..300 {
            let c = v();
            shapes.push(Shape::Triangle {
                p: [c, c + v() * 0.3, c + v() * 0.3],
            });
        }
        for _ in 0..10 {
            shapes.push(Shape::Sphere {
                center: v(),
                radius: 0.1,
            });
            shapes.push(Shape::Disk {
                center: v(),
                normal: v().normalize(),
                radius: 0.1,
            });
        }
        shapes
    }

    fn brute(shapes: &[Shape], o: Vec3, d: Vec3, tmax: f32) -> Option<(u32, f32)> {
        let mut best: Option<(u32, f32)> = None;
        for (i, s) in shapes.iter().enumerate() {
            if let Some(h) = s.intersect(o, d, tmax)
                && best.is_none_or(|(_, t)| h.t < t)
            {
                best = Some((i as u32, h.t));
            }
        }
        best
    }

    /// The 4-wide traversal must agree with testing every primitive: same
    /// closest distance (bit for bit; ties between coincident primitives may
    /// pick either), same occlusion answer, for triangle soups mixed with
    /// spheres and disks.
    #[test]
    fn bvh4_agrees_with_brute_force() {
        let mut rng = Rng::for_sample(7, 0, 0);
        let shapes = soup(&mut rng);
        let mut v = || point(&mut rng);
        let bvh = Bvh4::build(&shapes).expect("shallow tree");
        let (mut hits, mut blocked) = (0, 0);
        for i in 0..20_000 {
            let o = v() * 1.5;
            let d = v();
            // Some axis-aligned directions exercise zero inverse components.
            let d = if i % 10 == 0 {
                Vec3::new(d.x, 0.0, 0.0)
            } else {
                d
            };
            if d == Vec3::ZERO {
                continue;
            }
            let tmax = if i % 3 == 0 { 0.5 } else { f32::INFINITY };
            let got = bvh.intersect(&shapes, o, d, tmax).map(|(p, h)| (p, h.t));
            let want = brute(&shapes, o, d, tmax);
            assert_eq!(got.map(|g| g.1), want.map(|w| w.1), "ray {i}: {o} {d}");
            assert_eq!(
                bvh.unoccluded(&shapes, o, d, tmax),
                want.is_none(),
                "ray {i}"
            );
            hits += usize::from(want.is_some());
            blocked += usize::from(want.is_some() && tmax < 1.0);
        }
        assert!(
            hits > 2_000 && blocked > 300,
            "test rays too easy: {hits} {blocked}"
        );
    }
}
