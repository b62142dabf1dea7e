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
//!   permutation of the triangle test is done by selecting the vertex
//!   components per lane. Spheres and disks keep the scalar tests, lane by
//!   lane.
//! - Traversal: a stack of (node, lane mask, per-lane entry distance). An
//!   inner node tests each child box against all lanes of its mask (each
//!   lane's tmax = its closest hit so far); the children hit by some lane are
//!   visited nearest first (by the smallest entry distance over their lanes).
//!   A popped node keeps only the lanes whose entry distance is not beyond
//!   their closest hit. Occlusion drops blocked lanes from every mask and
//!   stops when none is left.
//! - Lane loops are plain loops over `[f32; 16]`, `#[inline(always)]` down to
//!   the leaves, so the render kernel's per-instruction-set copies
//!   (`simd.rs`) vectorise them 16, 8 or 4 lanes wide.
//!
//! Results per lane equal the single-ray query's bit for bit, with one
//! caveat shared with the single-ray traversal itself: the lanes visit leaves
//! in a different order, so when two primitives' distances lie within a few
//! ulps of each other the rounding of the `t ≤ tmax` test against the closest
//! hit so far could differ (not seen in the tests); between primitives at
//! exactly the same t either may be reported.
//!
//! Why: in small scenes such as the Cornell box, single-ray traversal of
//! incoherent secondary rays is dominated by unpredictable branches; a packet
//! replaces most of them with lane masks.

// Lane loops index several per-lane arrays at once.
#![allow(clippy::needless_range_loop)]

use super::bvh4::{Bvh4, EMPTY, LEAF, Node4, STACK};
use super::geometry::{PrimHit, Shape, TriRay, gamma};
use super::ray_packet::{ALL_LANES, LANES, LaneMask, PacketHits, RayPacket};
use std::mem::MaybeUninit;

/// One f32 per lane.
type F = [f32; LANES];

/// x86 `maxps` (what `wide`'s `fast_max` compiles to): `a` when `a > b`, else `b`.
#[inline(always)]
fn maxps(a: f32, b: f32) -> f32 {
    if a > b { a } else { b }
}

/// x86 `minps` (`wide`'s `fast_min`): `a` when `a < b`, else `b`.
#[inline(always)]
fn minps(a: f32, b: f32) -> f32 {
    if a < b { a } else { b }
}

/// `wide`'s NaN-aware `max`: `a` when `b` is NaN, else `maxps(a, b)`.
#[inline(always)]
fn max_wide(a: f32, b: f32) -> f32 {
    if b.is_nan() || a > b { a } else { b }
}

/// Lane mask of the lanes where `f` holds.
#[inline(always)]
fn bits(f: impl Fn(usize) -> bool) -> LaneMask {
    let mut m = 0;
    for l in 0..LANES {
        m |= (f(l) as LaneMask) << l;
    }
    m
}

/// `a` in the lanes of `m`, `b` elsewhere.
#[inline(always)]
fn select(m: LaneMask, a: &F, b: &F) -> F {
    std::array::from_fn(|l| if m & (1 << l) != 0 { a[l] } else { b[l] })
}

/// The smallest of `v` over the lanes of `m` (∞ for none).
#[inline(always)]
fn min_over(m: LaneMask, v: &F) -> f32 {
    let mut a: F = std::array::from_fn(|l| {
        if m & (1 << l) != 0 {
            v[l]
        } else {
            f32::INFINITY
        }
    });
    // Pairwise, so it vectorises (the order does not matter for a minimum
    // used only to order the traversal).
    let mut w = LANES / 2;
    while w > 0 {
        for l in 0..w {
            a[l] = minps(a[l], a[l + w]);
        }
        w /= 2;
    }
    a[0]
}

/// Iterate over the set bits of a lane mask.
#[inline(always)]
fn lanes(mut m: LaneMask) -> impl Iterator<Item = usize> {
    std::iter::from_fn(move || {
        (m != 0).then(|| {
            let l = m.trailing_zeros() as usize;
            m &= m - 1;
            l
        })
    })
}

/// Per-lane ray constants: what `RayPre::new` computes for each ray.
struct PacketPre {
    o: [F; 3],
    d: [F; 3],
    /// Inverse direction, clamped to ±1e30.
    inv: [F; 3],
    /// Origin permuted as the triangle test's axes: `o[kx]`, `o[ky]`, `o[kz]`.
    op: [F; 3],
    /// Shear `sx`, `sy`, `sz` of `TriRay`.
    s: [F; 3],
    /// Dominant axis of the direction (`TriRay::kz`).
    kz: [u32; LANES],
}

/// A lane set of triangle hits: t, edge functions and 1/det per lane.
struct TriHits {
    t: F,
    e: [F; 3],
    inv_det: F,
}

impl PacketPre {
    #[inline(always)]
    fn new(r: &RayPacket) -> Self {
        let mut p = PacketPre {
            o: r.o,
            d: r.d,
            inv: [[0.0; LANES]; 3],
            op: [[0.0; LANES]; 3],
            s: [[0.0; LANES]; 3],
            kz: [0; LANES],
        };
        for l in 0..LANES {
            let d = [r.d[0][l], r.d[1][l], r.d[2][l]];
            let o = [r.o[0][l], r.o[1][l], r.o[2][l]];
            // As `TriRay::new`: the largest |d| component becomes z.
            let (ax, ay, az) = (d[0].abs(), d[1].abs(), d[2].abs());
            let kz = if ax > ay {
                if ax > az { 0 } else { 2 }
            } else if ay > az {
                1
            } else {
                2
            };
            let perm = |v: [f32; 3]| match kz {
                0 => [v[1], v[2], v[0]],
                1 => [v[2], v[0], v[1]],
                _ => v,
            };
            let dp = perm(d);
            let op = perm(o);
            let sz = 1.0 / dp[2];
            p.s[0][l] = -dp[0] * sz;
            p.s[1][l] = -dp[1] * sz;
            p.s[2][l] = sz;
            p.kz[l] = kz;
            for a in 0..3 {
                p.op[a][l] = op[a];
                // As `RayPre::new`.
                let i = 1.0 / d[a];
                p.inv[a][l] = if i.abs() <= 1e30 {
                    i
                } else {
                    1e30f32.copysign(d[a])
                };
            }
        }
        p
    }

    /// The lane's `TriRay` (for the scalar sphere and disk tests).
    #[inline(always)]
    fn tri_ray(&self, l: usize) -> (TriRay, glam::Vec3) {
        let o = glam::Vec3::new(self.o[0][l], self.o[1][l], self.o[2][l]);
        let d = glam::Vec3::new(self.d[0][l], self.d[1][l], self.d[2][l]);
        let tri = TriRay {
            o,
            kz: self.kz[l] as u8,
            sx: self.s[0][l],
            sy: self.s[1][l],
            sz: self.s[2][l],
        };
        (tri, d)
    }

    /// Slab test of child `c` of `n` for every lane: entry distances and the
    /// mask of lanes hitting the box within (0, tmax] (`RayPre::boxes`).
    #[inline(always)]
    fn child_box(&self, n: &Node4, c: usize, tmax: &F) -> (LaneMask, F) {
        let mut tn = [0.0f32; LANES];
        let mut tf = *tmax;
        for a in 0..3 {
            let lo = n.b[0][a].as_array()[c];
            let hi = n.b[1][a].as_array()[c];
            for l in 0..LANES {
                let t0 = (lo - self.o[a][l]) * self.inv[a][l];
                let t1 = (hi - self.o[a][l]) * self.inv[a][l];
                tn[l] = maxps(tn[l], minps(t0, t1));
                tf[l] = minps(tf[l], maxps(t0, t1));
            }
        }
        let w = 1.0 + 2.0 * gamma(3);
        (bits(|l| tn[l] <= tf[l] * w), tn)
    }

    /// Watertight test of triangle `v[vertex][axis]` against the lanes of
    /// `m` (`RayPre::packet`, one triangle, 16 rays). Returns the lanes that
    /// hit it in (δt, tmax] and fills `h` for them.
    #[inline(always)]
    fn triangle(&self, v: &[[f32; 3]; 3], tmax: &F, m: LaneMask, h: &mut TriHits) -> LaneMask {
        let mut px = [[0.0f32; LANES]; 3];
        let mut py = [[0.0f32; LANES]; 3];
        let mut pz = [[0.0f32; LANES]; 3];
        for i in 0..3 {
            let [x, y, z] = v[i];
            for l in 0..LANES {
                // The vertex in the lane's permuted axes (kx, ky, kz).
                let k = self.kz[l];
                let vx = if k == 0 {
                    y
                } else if k == 1 {
                    z
                } else {
                    x
                };
                let vy = if k == 0 {
                    z
                } else if k == 1 {
                    x
                } else {
                    y
                };
                let vz = if k == 0 {
                    x
                } else if k == 1 {
                    y
                } else {
                    z
                };
                let zt = vz - self.op[2][l];
                px[i][l] = (vx - self.op[0][l]) + self.s[0][l] * zt;
                py[i][l] = (vy - self.op[1][l]) + self.s[1][l] * zt;
                pz[i][l] = zt;
            }
        }
        let mut e = [[0.0f32; LANES]; 3];
        for l in 0..LANES {
            e[0][l] = px[1][l] * py[2][l] - py[1][l] * px[2][l];
            e[1][l] = px[2][l] * py[0][l] - py[2][l] * px[0][l];
            e[2][l] = px[0][l] * py[1][l] - py[0][l] * px[1][l];
        }
        let zero = m & bits(|l| (e[0][l] == 0.0) | (e[1][l] == 0.0) | (e[2][l] == 0.0));
        if zero != 0 {
            // Exact-zero edge: re-evaluate those lanes in f64 (rare).
            let f = |ax: f32, ay: f32, bx: f32, by: f32| {
                (ax as f64 * by as f64 - ay as f64 * bx as f64) as f32
            };
            for l in lanes(zero) {
                e[0][l] = f(px[1][l], py[1][l], px[2][l], py[2][l]);
                e[1][l] = f(px[2][l], py[2][l], px[0][l], py[0][l]);
                e[2][l] = f(px[0][l], py[0][l], px[1][l], py[1][l]);
            }
        }
        let [e0, e1, e2] = &e;
        let inside = m & !bits(|l| {
            let neg = (e0[l] < 0.0) | (e1[l] < 0.0) | (e2[l] < 0.0);
            let pos = (e0[l] > 0.0) | (e1[l] > 0.0) | (e2[l] > 0.0);
            neg & pos
        });
        if inside == 0 {
            return 0;
        }
        let mut det = [0.0f32; LANES];
        let mut ts = [0.0f32; LANES];
        for l in 0..LANES {
            det[l] = e0[l] + e1[l] + e2[l];
            for z in &mut pz {
                z[l] *= self.s[2][l];
            }
            ts[l] = e0[l] * pz[0][l] + e1[l] * pz[1][l] + e2[l] * pz[2][l];
        }
        let mut hit = inside
            & bits(|l| {
                let tmd = tmax[l] * det[l];
                let neg = (det[l] < 0.0) & (ts[l] < 0.0) & (tmd <= ts[l]);
                let pos = (det[l] > 0.0) & (ts[l] > 0.0) & (ts[l] <= tmd);
                neg | pos
            });
        if hit == 0 {
            return 0;
        }
        // Conservative check that t is positive beyond its rounding error (pbrt-v4).
        let max3 =
            |v: &[F; 3], l: usize| max_wide(max_wide(v[0][l].abs(), v[1][l].abs()), v[2][l].abs());
        for l in 0..LANES {
            let inv_det = 1.0 / det[l];
            let t = ts[l] * inv_det;
            let max_zt = max3(&pz, l);
            let max_xt = max3(&px, l);
            let max_yt = max3(&py, l);
            let delta_z = gamma(3) * max_zt;
            let delta_x = gamma(5) * (max_xt + max_zt);
            let delta_y = gamma(5) * (max_yt + max_zt);
            let delta_e = 2.0 * (gamma(2) * max_xt * max_yt + delta_y * max_xt + delta_x * max_yt);
            let max_e = max3(&e, l);
            let delta_t = 3.0
                * (gamma(3) * max_e * max_zt + delta_e * max_zt + delta_z * max_e)
                * inv_det.abs();
            h.t[l] = t;
            h.inv_det[l] = inv_det;
            // Stored as a flag in `det` (free after this loop).
            det[l] = if t > delta_t { 1.0 } else { 0.0 };
        }
        hit &= bits(|l| det[l] != 0.0);
        h.e = e;
        hit
    }
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
        let mut best_t = rays.tmax;
        let mut best_b = [[0.0f32; LANES]; 3];
        let mut best_prim = [EMPTY; LANES];
        let mut h = TriHits {
            t: [0.0; LANES],
            e: [[0.0; LANES]; 3],
            inv_det: [0.0; LANES],
        };
        // Uninitialised: (node, lanes) and the lanes' entry distances.
        let mut stack = [const { MaybeUninit::<(u32, LaneMask)>::uninit() }; STACK];
        let mut stack_tn = [const { MaybeUninit::<F>::uninit() }; STACK];
        let mut sp = 0usize;
        // As in `intersect`, the node being visited is kept out of the stack.
        let (mut code, mut mask) = (self.root, active);
        'visit: loop {
            if code & LEAF != 0 {
                let leaf = &self.leaves[(code & !LEAF) as usize];
                if leaf.packet != EMPTY {
                    let p = &self.packets[leaf.packet as usize];
                    // Every triangle of the leaf is tested with the closest t
                    // at leaf entry as tmax, as the single-ray 4-triangle test.
                    let tmax = best_t;
                    for j in 0..p.n as usize {
                        let v = [0, 1, 2].map(|i| [0, 1, 2].map(|a| p.v[i][a].as_array()[j]));
                        let hit = r.triangle(&v, &tmax, mask, &mut h);
                        let closer = hit & bits(|l| h.t[l] < best_t[l]);
                        if closer != 0 {
                            best_t = select(closer, &h.t, &best_t);
                            for k in 0..3 {
                                let b: F = std::array::from_fn(|l| h.e[k][l] * h.inv_det[l]);
                                best_b[k] = select(closer, &b, &best_b[k]);
                            }
                            let prim = p.prim[j];
                            for l in 0..LANES {
                                if closer & (1 << l) != 0 {
                                    best_prim[l] = prim;
                                }
                            }
                        }
                    }
                }
                let s = leaf.others as usize;
                for &prim in &self.others[s..s + leaf.n_others as usize] {
                    for l in lanes(mask) {
                        let (tri, d) = r.tri_ray(l);
                        if let Some(hh) = shapes[prim as usize].intersect_pre(&tri, d, best_t[l])
                            && hh.t < best_t[l]
                        {
                            best_t[l] = hh.t;
                            for k in 0..3 {
                                best_b[k][l] = hh.b[k];
                            }
                            best_prim[l] = prim;
                        }
                    }
                }
            } else {
                let node = &self.nodes[code as usize];
                // Hit children, far to near by their nearest lane's entry.
                let mut kids = [(0usize, 0 as LaneMask, 0.0f32); 4];
                let mut tns = [[0.0f32; LANES]; 4];
                let mut nk = 0;
                for c in 0..4 {
                    if node.valid & (1 << c) == 0 {
                        continue;
                    }
                    let (m, tn) = r.child_box(node, c, &best_t);
                    let m = m & mask;
                    if m == 0 {
                        continue;
                    }
                    tns[c] = tn;
                    let key = min_over(m, &tn);
                    let mut j = nk;
                    while j > 0 && kids[j - 1].2 < key {
                        kids[j] = kids[j - 1];
                        j -= 1;
                    }
                    kids[j] = (c, m, key);
                    nk += 1;
                }
                if nk > 0 {
                    for &(c, m, _) in &kids[..nk - 1] {
                        stack[sp].write((node.child[c], m));
                        stack_tn[sp].write(tns[c]);
                        sp += 1;
                    }
                    let (c, m, _) = kids[nk - 1];
                    code = node.child[c];
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
                let (c, m) = unsafe { stack[sp].assume_init() };
                let tn = unsafe { stack_tn[sp].assume_init_ref() };
                let m = m & bits(|l| tn[l] <= best_t[l]);
                if m != 0 {
                    code = c;
                    mask = m;
                    continue 'visit;
                }
            }
        }
        for l in lanes(active) {
            if best_prim[l] != EMPTY {
                out.prim[l] = best_prim[l];
                out.h[l] = PrimHit {
                    t: best_t[l],
                    b: [best_b[0][l], best_b[1][l], best_b[2][l]],
                };
            }
        }
    }

    /// The active lanes of `rays` along which nothing blocks the ray (each
    /// lane as `unoccluded`).
    #[inline(always)]
    pub fn unoccluded_packet(&self, shapes: &[Shape], rays: &RayPacket) -> LaneMask {
        let mut free = rays.active & ALL_LANES;
        if free == 0 {
            return 0;
        }
        let r = PacketPre::new(rays);
        let tmax = &rays.tmax;
        let mut h = TriHits {
            t: [0.0; LANES],
            e: [[0.0; LANES]; 3],
            inv_det: [0.0; LANES],
        };
        let mut stack = [const { MaybeUninit::<(u32, LaneMask)>::uninit() }; STACK];
        let mut sp = 0usize;
        let (mut code, mut mask) = (self.root, free);
        'visit: loop {
            if code & LEAF != 0 {
                let leaf = &self.leaves[(code & !LEAF) as usize];
                if leaf.packet != EMPTY {
                    let p = &self.packets[leaf.packet as usize];
                    for j in 0..p.n as usize {
                        let m = mask & free;
                        if m == 0 {
                            break;
                        }
                        let v = [0, 1, 2].map(|i| [0, 1, 2].map(|a| p.v[i][a].as_array()[j]));
                        free &= !r.triangle(&v, tmax, m, &mut h);
                    }
                }
                let s = leaf.others as usize;
                for &prim in &self.others[s..s + leaf.n_others as usize] {
                    for l in lanes(mask & free) {
                        let (tri, d) = r.tri_ray(l);
                        if shapes[prim as usize]
                            .intersect_pre(&tri, d, tmax[l])
                            .is_some()
                        {
                            free &= !(1 << l);
                        }
                    }
                }
                if free == 0 {
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
                let (c, m) = unsafe { stack[sp].assume_init() };
                let m = m & free;
                if m != 0 {
                    code = c;
                    mask = m;
                    continue 'visit;
                }
            }
        }
        free
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

    fn cornell() -> World {
        let (scene, _) = crate::render::bench::mitsuba_cornell_box();
        let grid = WavelengthGrid::new(500.0, 600.0, 50.0).unwrap();
        World::build(&scene, &grid, BvhKind::Bvh4).unwrap()
    }

    /// Every active lane of the packet queries must equal the single-ray
    /// queries: t and barycentrics bit for bit, the same primitive unless
    /// another lies at exactly the same t; inactive lanes report nothing.
    fn check(bvh: &Bvh4, shapes: &[Shape], rays: &RayPacket) -> (usize, usize) {
        let mut out = PacketHits::default();
        // Garbage in the previous result must not leak through.
        out.prim = [7; LANES];
        bvh.intersect_packet(shapes, rays, &mut out);
        let free = bvh.unoccluded_packet(shapes, rays);
        assert_eq!(free & !rays.active, 0, "inactive lanes reported free");
        let (mut hits, mut blocked) = (0, 0);
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
                    assert_eq!(g.t.to_bits(), w.t.to_bits(), "lane {l}: {o} {d} {tmax}");
                    if out.prim[l] == prim {
                        for k in 0..3 {
                            assert_eq!(g.b[k].to_bits(), w.b[k].to_bits(), "lane {l}");
                        }
                    } else {
                        // A different primitive at exactly the same t.
                        let other = shapes[out.prim[l] as usize].intersect(o, d, tmax);
                        assert_eq!(other.map(|h| h.t.to_bits()), Some(w.t.to_bits()));
                    }
                    hits += 1;
                }
            }
            let u = bvh.unoccluded(shapes, o, d, tmax);
            assert_eq!(free & (1 << l) != 0, u, "lane {l}: {o} {d} {tmax}");
            blocked += usize::from(!u);
        }
        (hits, blocked)
    }

    /// Packets of several kinds over `shapes` inside about [-1, 1]³.
    fn packets(shapes: &[Shape], bvh: &Bvh4, seed: u64, n: usize) -> (usize, usize) {
        let mut rng = Rng::for_sample(seed, 0, 0);
        let mut v = || Vec3::new(rng.uniform(), rng.uniform(), rng.uniform()) * 2.0 - 1.0;
        let (mut hits, mut blocked) = (0, 0);
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
            let (h, b) = check(bvh, shapes, &rays);
            hits += h;
            blocked += b;
        }
        (hits, blocked)
    }

    #[test]
    fn packet_agrees_with_single_ray_on_soups() {
        for seed in [7, 8] {
            let mut rng = Rng::for_sample(seed, 1, 0);
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
            let (hits, blocked) = packets(&shapes, &bvh, seed, 1500);
            assert!(
                hits > 8_000 && blocked > 4_000,
                "test rays too easy: {hits} {blocked}"
            );
        }
    }

    #[test]
    fn packet_agrees_with_single_ray_in_cornell_box() {
        let world = cornell();
        let shapes = &world.accel.shapes;
        let bvh = Bvh4::build(shapes).expect("shallow tree");
        let (hits, blocked) = packets(shapes, &bvh, 3, 1500);
        assert!(hits > 10_000 && blocked > 5_000, "{hits} {blocked}");
        // Path-traced bounces and shadow rays, as the renderer casts them.
        let (sec, shadow) = bounce_rays(&world, &bvh, 3000);
        for rays in sec.iter().chain(&shadow) {
            check(&bvh, shapes, rays);
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
    fn timing(bvh: &Bvh4, shapes: &[Shape], sec: &[RayPacket], shadow: &[RayPacket]) -> [f64; 5] {
        let mut sum = 0.0f64;
        let mut t = [0.0f64; 5];
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
        t[4] = sum + n as f64;
        t
    }

    #[cfg(target_arch = "x86_64")]
    #[target_feature(enable = "avx2,fma,bmi1,bmi2,lzcnt,popcnt")]
    fn timing_avx2(b: &Bvh4, s: &[Shape], sec: &[RayPacket], sh: &[RayPacket]) -> [f64; 5] {
        timing(b, s, sec, sh)
    }

    #[cfg(target_arch = "x86_64")]
    #[target_feature(enable = "avx512f,avx512vl,avx512bw,avx512dq,avx2,fma,bmi1,bmi2,lzcnt,popcnt")]
    fn timing_avx512(b: &Bvh4, s: &[Shape], sec: &[RayPacket], sh: &[RayPacket]) -> [f64; 5] {
        timing(b, s, sec, sh)
    }

    /// Single-ray against packet queries on Cornell box bounces; prints ns
    /// per ray (`cargo test --release --lib bvh4_packet -- --ignored --nocapture`).
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
        for isa in RenderIsa::ALL {
            if !isa.supported() {
                continue;
            }
            let mut best = [f64::INFINITY; 4];
            for _ in 0..5 {
                let t = match isa {
                    RenderIsa::Sse => timing(&bvh, shapes, &sec, &shadow),
                    // SAFETY: the CPU supports the features.
                    RenderIsa::Avx2 => unsafe { timing_avx2(&bvh, shapes, &sec, &shadow) },
                    // SAFETY: as above.
                    RenderIsa::Avx512 => unsafe { timing_avx512(&bvh, shapes, &sec, &shadow) },
                };
                for k in 0..4 {
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
        }
    }
}
