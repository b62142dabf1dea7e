//! Packet traversal of the 4-wide BVH (issue 17): up to eight rays walk the
//! tree together, structure of arrays, one lane per ray. Each node's four
//! child boxes are tested against all the packet's rays, each leaf's
//! triangles against all of them, in lane loops over `[f32; 8]` arrays that
//! the compiler turns into 8-wide vector instructions inside the render
//! kernel's AVX2/AVX-512 copies (`simd.rs`).
//!
//! Per ray the arithmetic is `bvh4.rs`'s, operation for operation: the same
//! slab test with the same clamped inverse direction and widened far
//! distance, the same watertight triangle test (exact-zero edges in f64,
//! pbrt-v4's conservative `t > δt`), min/max with SSE's operand order. A
//! ray's closest hit is therefore the single-ray traversal's, bit for bit,
//! except between surfaces whose hit distances tie (or differ in the last
//! rounding of the `t ≤ tmax` test): the packet visits the tree in an order
//! shared by its rays, so a tie may go to the other primitive.
//!
//! Pays for coherent rays — a pixel's camera rays, which cross the same
//! nodes: the traversal's bookkeeping (stack, ordering) is done once for
//! the packet, and the box and triangle tests run eight rays per
//! instruction.

// Lane loops index several per-lane arrays at once.
#![allow(clippy::needless_range_loop)]

use super::bvh4::{Bvh4, EMPTY, LEAF, STACK, TriPacket};
use super::geometry::{PrimHit, Shape, TriRay, gamma};
use glam::Vec3;
use std::mem::MaybeUninit;

/// Rays per packet.
pub const LANES: usize = 8;

type F = [f32; LANES];

/// SSE `maxps(a, b)` per lane: `b` unless `a > b` (as `f32x4::fast_max`).
#[inline(always)]
fn vmax(a: F, b: F) -> F {
    std::array::from_fn(|l| if a[l] > b[l] { a[l] } else { b[l] })
}

/// SSE `minps(a, b)` per lane: `b` unless `a < b` (as `f32x4::fast_min`).
#[inline(always)]
fn vmin(a: F, b: F) -> F {
    std::array::from_fn(|l| if a[l] < b[l] { a[l] } else { b[l] })
}

/// The packet's rays, structure of arrays.
struct Rays {
    /// Origin per axis.
    o: [F; 3],
    /// Clamped inverse direction per axis (as `bvh4::RayPre`).
    inv: [F; 3],
    /// Watertight test: axis permutation (x, y, z after permuting) and shear.
    k: [[u8; LANES]; 3],
    /// The permutation when every lane shares it.
    same_k: Option<[u8; 3]>,
    /// Origin per permuted axis.
    op: [F; 3],
    sx: F,
    sy: F,
    sz: F,
    /// Per-ray constants for spheres and disks (scalar tests).
    tri: [TriRay; LANES],
    d: [Vec3; LANES],
}

impl Rays {
    #[inline(always)]
    fn new(o: &[Vec3], d: &[Vec3]) -> Self {
        let n = o.len();
        // Spare lanes repeat the first ray; they are never active.
        let ray = |l: usize| if l < n { (o[l], d[l]) } else { (o[0], d[0]) };
        let tri: [TriRay; LANES] = std::array::from_fn(|l| {
            let (o, d) = ray(l);
            TriRay::new(o, d)
        });
        let dd: [Vec3; LANES] = std::array::from_fn(|l| ray(l).1);
        let oo: [Vec3; LANES] = std::array::from_fn(|l| ray(l).0);
        let inv_c = |c: f32| {
            let i = 1.0 / c;
            if i.abs() <= 1e30 {
                i
            } else {
                1e30f32.copysign(c)
            }
        };
        let mut k = [[0u8; LANES]; 3];
        for l in 0..LANES {
            let kz = tri[l].kz;
            let kx = (kz + 1) % 3;
            k[0][l] = kx;
            k[1][l] = (kx + 1) % 3;
            k[2][l] = kz;
        }
        let same_k = (0..n)
            .all(|l| (0..3).all(|a| k[a][l] == k[a][0]))
            .then_some([k[0][0], k[1][0], k[2][0]]);
        let op = [0, 1, 2].map(|ax| std::array::from_fn(|l| oo[l][k[ax][l] as usize]));
        Rays {
            same_k,
            op,
            o: [0, 1, 2].map(|a| std::array::from_fn(|l| oo[l][a])),
            inv: [0, 1, 2].map(|a| std::array::from_fn(|l| inv_c(dd[l][a]))),
            k,
            sx: std::array::from_fn(|l| tri[l].sx),
            sy: std::array::from_fn(|l| tri[l].sy),
            sz: std::array::from_fn(|l| tri[l].sz),
            tri,
            d: dd,
        }
    }

    /// Entry distance of child `c`'s box per ray and the mask of rays that
    /// hit it within (0, tmax[l]] (as `RayPre::boxes`, one child, eight rays).
    #[inline(always)]
    fn child(&self, b: &[[wide::f32x4; 3]; 2], c: usize, tmax: &F, active: u32) -> (u32, F) {
        let mut tn = [0.0f32; LANES];
        let mut tf = *tmax;
        for a in 0..3 {
            let lo = b[0][a].to_array()[c];
            let hi = b[1][a].to_array()[c];
            let t0: F = std::array::from_fn(|l| (lo - self.o[a][l]) * self.inv[a][l]);
            let t1: F = std::array::from_fn(|l| (hi - self.o[a][l]) * self.inv[a][l]);
            tn = vmax(tn, vmin(t0, t1));
            tf = vmin(tf, vmax(t0, t1));
        }
        let widen = 1.0 + 2.0 * gamma(3);
        let mut mask = 0u32;
        for l in 0..LANES {
            mask |= u32::from(tn[l] <= tf[l] * widen) << l;
        }
        (mask & active, tn)
    }

    /// Triangle `j` of a leaf packet against every ray: the mask of rays
    /// hitting it within (0, tmax[l]] and t, b0, b1, b2 per ray (as
    /// `RayPre::packet`, one triangle, eight rays).
    #[inline(always)]
    fn triangle(&self, p: &TriPacket, j: usize, tmax: &F, active: u32) -> (u32, [F; 4]) {
        // Vertex i, axis a, of triangle j.
        let v = |i: usize, a: usize| p.v[i][a].to_array()[j];
        let vert: [[f32; 3]; 3] = std::array::from_fn(|i| [v(i, 0), v(i, 1), v(i, 2)]);
        // Permuted, translated vertex coordinates per ray: q[axis'][vertex].
        let mut q = [[[0.0f32; LANES]; 3]; 3];
        if let Some(k) = self.same_k {
            // All rays permute alike (coherent packets): a broadcast per vertex.
            for (ax, qa) in q.iter_mut().enumerate() {
                for (i, qi) in qa.iter_mut().enumerate() {
                    let c = vert[i][k[ax] as usize];
                    for l in 0..LANES {
                        qi[l] = c - self.op[ax][l];
                    }
                }
            }
        } else {
            for (ax, qa) in q.iter_mut().enumerate() {
                for (i, qi) in qa.iter_mut().enumerate() {
                    for l in 0..LANES {
                        qi[l] = vert[i][self.k[ax][l] as usize] - self.op[ax][l];
                    }
                }
            }
        }
        let [mut px, mut py, mut pz] = q;
        for i in 0..3 {
            for l in 0..LANES {
                px[i][l] += self.sx[l] * pz[i][l];
                py[i][l] += self.sy[l] * pz[i][l];
            }
        }
        let cross = |a: usize, b: usize| -> F {
            std::array::from_fn(|l| px[a][l] * py[b][l] - py[a][l] * px[b][l])
        };
        let (mut e0, mut e1, mut e2) = (cross(1, 2), cross(2, 0), cross(0, 1));
        let mut any_zero = 0u32;
        for l in 0..LANES {
            any_zero |= u32::from(e0[l] == 0.0 || e1[l] == 0.0 || e2[l] == 0.0) << l;
        }
        any_zero &= active;
        if any_zero != 0 {
            // Exact-zero edge: re-evaluate those rays in f64 (rare).
            let f = |ax: f32, ay: f32, bx: f32, by: f32| {
                (ax as f64 * by as f64 - ay as f64 * bx as f64) as f32
            };
            for l in 0..LANES {
                if any_zero & (1 << l) != 0 {
                    e0[l] = f(px[1][l], py[1][l], px[2][l], py[2][l]);
                    e1[l] = f(px[2][l], py[2][l], px[0][l], py[0][l]);
                    e2[l] = f(px[0][l], py[0][l], px[1][l], py[1][l]);
                }
            }
        }
        let mut inside = 0u32;
        for l in 0..LANES {
            let neg = e0[l] < 0.0 || e1[l] < 0.0 || e2[l] < 0.0;
            let pos = e0[l] > 0.0 || e1[l] > 0.0 || e2[l] > 0.0;
            inside |= u32::from(!(neg && pos)) << l;
        }
        inside &= active;
        let zero = [[0.0; LANES]; 4];
        if inside == 0 {
            return (0, zero);
        }
        let det: F = std::array::from_fn(|l| e0[l] + e1[l] + e2[l]);
        for z in &mut pz {
            for l in 0..LANES {
                z[l] *= self.sz[l];
            }
        }
        let t_scaled: F =
            std::array::from_fn(|l| e0[l] * pz[0][l] + e1[l] * pz[1][l] + e2[l] * pz[2][l]);
        let mut mask = 0u32;
        for l in 0..LANES {
            let tmd = tmax[l] * det[l];
            let in_neg = det[l] < 0.0 && t_scaled[l] < 0.0 && tmd <= t_scaled[l];
            let in_pos = det[l] > 0.0 && t_scaled[l] > 0.0 && t_scaled[l] <= tmd;
            mask |= u32::from(in_neg || in_pos) << l;
        }
        mask &= inside;
        if mask == 0 {
            return (0, zero);
        }
        let inv_det: F = std::array::from_fn(|l| 1.0 / det[l]);
        let t: F = std::array::from_fn(|l| t_scaled[l] * inv_det[l]);
        // Conservative check that t is positive beyond its rounding error (pbrt-v4),
        // with `bvh4.rs`'s order of operations.
        let max3 = |v: &[F; 3]| -> F {
            std::array::from_fn(|l| v[0][l].abs().max(v[1][l].abs()).max(v[2][l].abs()))
        };
        let (max_zt, max_xt, max_yt) = (max3(&pz), max3(&px), max3(&py));
        let mut hit = 0u32;
        for l in 0..LANES {
            let delta_z = gamma(3) * max_zt[l];
            let delta_x = gamma(5) * (max_xt[l] + max_zt[l]);
            let delta_y = gamma(5) * (max_yt[l] + max_zt[l]);
            let delta_e = 2.0
                * (gamma(2) * max_xt[l] * max_yt[l] + delta_y * max_xt[l] + delta_x * max_yt[l]);
            let max_e = e0[l].abs().max(e1[l].abs()).max(e2[l].abs());
            let delta_t = 3.0
                * (gamma(3) * max_e * max_zt[l] + delta_e * max_zt[l] + delta_z * max_e)
                * inv_det[l].abs();
            hit |= u32::from(t[l] > delta_t) << l;
        }
        mask &= hit;
        let b = |e: &F| -> F { std::array::from_fn(|l| e[l] * inv_det[l]) };
        (mask, [t, b(&e0), b(&e1), b(&e2)])
    }
}

impl Bvh4 {
    /// Closest hits of up to `LANES` rays `o[l] + t·d[l]`, t ∈ (0, tmax), in
    /// one traversal; `out[l]` as `intersect` would answer for ray `l` (up
    /// to ties, see the module notes).
    #[inline(always)]
    pub fn intersect_packet(
        &self,
        shapes: &[Shape],
        o: &[Vec3],
        d: &[Vec3],
        tmax: f32,
        out: &mut [Option<(u32, PrimHit)>],
    ) {
        let n = o.len();
        assert!(n <= LANES && d.len() == n && out.len() == n);
        if n == 0 {
            return;
        }
        let r = Rays::new(o, d);
        let all = (1u32 << n) - 1;
        let mut best_t = [tmax; LANES];
        let mut best_b = [[0.0f32; 3]; LANES];
        let mut best_prim = [EMPTY; LANES];
        // Entries: node, the rays that enter it and their entry distances.
        let mut stack = [const { MaybeUninit::<(u32, u32, F)>::uninit() }; STACK];
        let mut sp = 0usize;
        let mut code = self.root;
        let mut active = all;
        'visit: loop {
            if code & LEAF != 0 {
                let leaf = &self.leaves[(code & !LEAF) as usize];
                if leaf.packet != EMPTY {
                    let p = &self.packets[leaf.packet as usize];
                    // As the single-ray test: all triangles against the
                    // closest distance on entry, the nearest wins (first on ties).
                    let entry_t = best_t;
                    for j in 0..p.n as usize {
                        let (mask, [t, b0, b1, b2]) = r.triangle(p, j, &entry_t, active);
                        if mask == 0 {
                            continue;
                        }
                        for l in 0..LANES {
                            if mask & (1 << l) != 0 && t[l] < best_t[l] {
                                best_t[l] = t[l];
                                best_b[l] = [b0[l], b1[l], b2[l]];
                                best_prim[l] = p.prim[j];
                            }
                        }
                    }
                }
                let s = leaf.others as usize;
                for &prim in &self.others[s..s + leaf.n_others as usize] {
                    for l in 0..n {
                        if active & (1 << l) != 0
                            && let Some(h) =
                                shapes[prim as usize].intersect_pre(&r.tri[l], r.d[l], best_t[l])
                            && h.t < best_t[l]
                        {
                            best_t[l] = h.t;
                            best_b[l] = h.b;
                            best_prim[l] = prim;
                        }
                    }
                }
            } else {
                let node = &self.nodes[code as usize];
                // Children hit by at least one ray, far to near by their
                // nearest entry distance over the packet.
                let mut hits = [(0u32, 0u32, [0.0f32; LANES], 0.0f32); 4];
                let mut nh = 0;
                for c in 0..4 {
                    if node.valid & (1 << c) == 0 {
                        continue;
                    }
                    let (mask, tn) = r.child(&node.b, c, &best_t, active);
                    if mask == 0 {
                        continue;
                    }
                    let mut near = f32::INFINITY;
                    let mut tns = [f32::INFINITY; LANES];
                    for l in 0..LANES {
                        if mask & (1 << l) != 0 {
                            tns[l] = tn[l];
                            near = near.min(tn[l]);
                        }
                    }
                    let mut j = nh;
                    while j > 0 && hits[j - 1].3 < near {
                        hits[j] = hits[j - 1];
                        j -= 1;
                    }
                    hits[j] = (node.child[c], mask, tns, near);
                    nh += 1;
                }
                if nh > 0 {
                    for h in &hits[..nh - 1] {
                        stack[sp].write((h.0, h.1, h.2));
                        sp += 1;
                    }
                    code = hits[nh - 1].0;
                    active = hits[nh - 1].1;
                    continue 'visit;
                }
            }
            // Next stacked node that some ray enters before its closest hit.
            loop {
                if sp == 0 {
                    break 'visit;
                }
                sp -= 1;
                // SAFETY: entries below `sp` were written before being counted.
                let (c, entering, tn) = unsafe { stack[sp].assume_init() };
                let mut m = 0u32;
                for l in 0..LANES {
                    m |= u32::from(tn[l] <= best_t[l]) << l;
                }
                m &= entering;
                if m != 0 {
                    code = c;
                    active = m;
                    continue 'visit;
                }
            }
        }
        for l in 0..n {
            out[l] = (best_prim[l] != EMPTY).then_some((
                best_prim[l],
                PrimHit {
                    t: best_t[l],
                    b: best_b[l],
                },
            ));
        }
    }
}

#[cfg(test)]
mod tests {
    use super::*;
    use crate::render::sampling::Rng;

    /// Every ray of a packet gets the single-ray traversal's closest hit:
    /// same distance and barycentrics bit for bit, same primitive unless
    /// two primitives tie. Packets of incoherent rays (random origins and
    /// directions over a triangle soup with spheres and disks, some
    /// axis-aligned, some with a finite tmax) and of coherent ones (a bundle
    /// around one direction, as a pixel's camera rays), packets of 1–8 rays.
    #[test]
    fn packet_hits_match_single_rays() {
        let mut rng = Rng::for_sample(11, 0, 0);
        let mut v = || Vec3::new(rng.uniform(), rng.uniform(), rng.uniform()) * 2.0 - 1.0;
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
        let bvh = Bvh4::build(&shapes).expect("shallow tree");
        let (mut hits, mut rays, mut ties) = (0usize, 0usize, 0usize);
        for pk in 0..6000 {
            let n = 1 + pk % LANES;
            let coherent = pk % 2 == 0;
            let (o0, d0) = (v() * 1.5, v());
            let mut o = Vec::new();
            let mut d = Vec::new();
            for i in 0..n {
                let (oi, di) = if coherent {
                    (o0 + v() * 1e-3, d0 + v() * 0.02)
                } else {
                    (v() * 1.5, v())
                };
                let di = if i == 3 && pk % 5 == 0 {
                    Vec3::new(di.x, 0.0, 0.0)
                } else {
                    di
                };
                if di == Vec3::ZERO {
                    continue;
                }
                o.push(oi);
                d.push(di);
            }
            if o.is_empty() {
                continue;
            }
            let tmax = if pk % 3 == 0 { 0.5 } else { f32::INFINITY };
            let mut out = vec![None; o.len()];
            bvh.intersect_packet(&shapes, &o, &d, tmax, &mut out);
            for l in 0..o.len() {
                let want = bvh.intersect(&shapes, o[l], d[l], tmax);
                rays += 1;
                match (out[l], want) {
                    (None, None) => {}
                    (Some((gp, g)), Some((wp, w))) => {
                        hits += 1;
                        assert_eq!(g.t.to_bits(), w.t.to_bits(), "packet {pk} ray {l}");
                        if gp == wp {
                            assert_eq!(g.b.map(f32::to_bits), w.b.map(f32::to_bits));
                        } else {
                            ties += 1;
                        }
                    }
                    (g, w) => panic!("packet {pk} ray {l}: {g:?} vs {w:?}"),
                }
            }
        }
        assert!(hits > rays / 10, "test rays too easy: {hits} of {rays}");
        assert!(ties * 1000 < hits, "{ties} ties in {hits} hits");
    }
}
