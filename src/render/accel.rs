//! The acceleration structure over a scene's shapes: which BVH layout is
//! built ([`BvhKind`]; the choice and its measurements are in `geometry.rs`'s
//! notes) and the closest-hit query the integrator asks of it.

use super::geometry::{PrimHit, Shape, TriRay};
use super::ray_packet::{LaneMask, PacketHits, RayPacket, lanes};
use super::simd::RenderIsa;
use glam::{Vec3, Vec3A};
use obvhs::{BvhBuildParams, bvh2::Bvh2, cwbvh::CwBvh, ray::Ray, ray::RayHit};

/// Which BVH layout to build.
#[derive(Clone, Copy, Debug, PartialEq, Eq)]
pub enum BvhKind {
    Bvh2,
    Cwbvh,
    /// 4-wide SSE BVH (`bvh4.rs`), the renderer's default; falls back to
    /// BVH2 for a tree too deep for its fixed traversal stack.
    Bvh4,
}

enum Tree {
    Four(super::bvh4::Bvh4),
    Two(Bvh2),
    Cw(CwBvh),
    Empty,
}

/// The acceleration structure over a list of shapes.
pub struct Accel {
    pub shapes: Vec<Shape>,
    tree: Tree,
    /// The instruction set of the packet traversal's kernel
    /// (`RenderIsa::detect` at build time; every level gives the same bits).
    isa: RenderIsa,
}

/// Closest hit: primitive index (into `shapes`) and the primitive hit.
#[derive(Clone, Copy, Debug)]
pub struct Hit {
    pub prim: u32,
    pub h: PrimHit,
}

impl Accel {
    pub fn build(shapes: Vec<Shape>, kind: BvhKind) -> Self {
        if shapes.is_empty() {
            return Accel {
                shapes,
                tree: Tree::Empty,
                isa: RenderIsa::Sse,
            };
        }
        let mut t = std::time::Duration::ZERO;
        // Small leaves: the watertight triangle test is dearer than a node test
        // (measured on the Mitsuba Cornell box: leaves of ≤ 2 with collapse cost 1
        // beat obvhs' default 8 / 3.0 by ~15 %).
        let mut params = BvhBuildParams::medium_build();
        params.max_prims_per_leaf = 2;
        params.collapse_traversal_cost = 1.0;
        let tree = match kind {
            BvhKind::Bvh4 => match super::bvh4::Bvh4::build(&shapes) {
                Some(b) => Tree::Four(b),
                None => Tree::Two(obvhs::bvh2::builder::build_bvh2(&shapes, params, &mut t)),
            },
            BvhKind::Bvh2 => Tree::Two(obvhs::bvh2::builder::build_bvh2(&shapes, params, &mut t)),
            BvhKind::Cwbvh => Tree::Cw(obvhs::cwbvh::builder::build_cwbvh(&shapes, params, &mut t)),
        };
        Accel {
            shapes,
            tree,
            isa: RenderIsa::detect(),
        }
    }

    /// Closest hit along `o + t·d`, t ∈ (0, tmax).
    #[inline(always)]
    pub fn intersect(&self, o: Vec3, d: Vec3, tmax: f32) -> Option<Hit> {
        if let Tree::Four(b) = &self.tree {
            return b
                .intersect(&self.shapes, o, d, tmax)
                .map(|(prim, h)| Hit { prim, h });
        }
        let ray = Ray::new(Vec3A::from(o), Vec3A::from(d), 0.0, tmax);
        let mut best = PrimHit {
            t: tmax,
            b: [0.0; 3],
        };
        let mut best_prim = u32::MAX;
        let mut hit = RayHit::none();
        let shapes = &self.shapes;
        let tr = TriRay::new(o, d);
        let mut f = |r: &Ray, idx: usize, indices: &[u32]| -> f32 {
            let prim = indices[idx];
            match shapes[prim as usize].intersect_pre(&tr, d, r.tmax) {
                Some(h) if h.t < best.t => {
                    best = h;
                    best_prim = prim;
                    h.t
                }
                _ => f32::INFINITY,
            }
        };
        match &self.tree {
            Tree::Two(b) => {
                b.ray_traverse(ray, &mut hit, |r, i| f(r, i, &b.primitive_indices));
            }
            Tree::Cw(b) => {
                b.ray_traverse(ray, &mut hit, |r, i| f(r, i, &b.primitive_indices));
            }
            Tree::Empty | Tree::Four(_) => {}
        }
        (best_prim != u32::MAX).then_some(Hit {
            prim: best_prim,
            h: best,
        })
    }

    /// True when nothing blocks `o + t·d` for t ∈ (0, tmax).
    #[inline(always)]
    pub fn unoccluded(&self, o: Vec3, d: Vec3, tmax: f32) -> bool {
        if let Tree::Four(b) = &self.tree {
            return b.unoccluded(&self.shapes, o, d, tmax);
        }
        let ray = Ray::new(Vec3A::from(o), Vec3A::from(d), 0.0, tmax);
        let shapes = &self.shapes;
        let tr = TriRay::new(o, d);
        let f = |r: &Ray, idx: usize, indices: &[u32]| -> f32 {
            match shapes[indices[idx] as usize].intersect_pre(&tr, d, r.tmax) {
                Some(h) => h.t,
                None => f32::INFINITY,
            }
        };
        match &self.tree {
            Tree::Two(b) => b.ray_traverse_miss(ray, |r, i| f(r, i, &b.primitive_indices)),
            Tree::Cw(b) => b.ray_traverse_miss(ray, |r, i| f(r, i, &b.primitive_indices)),
            Tree::Empty | Tree::Four(_) => true,
        }
    }

    /// Closest hits of every active lane of `rays`: lane `l` of `out` is
    /// `intersect` of ray `l` (same primitive and same bits of t and the
    /// barycentrics; between primitives at exactly the same t, or within a
    /// few ulps of it on coplanar overlapping faces, either may be reported:
    /// `bvh4_packet.rs`). Inactive lanes report no hit.
    #[inline(always)]
    pub fn intersect_packet(&self, rays: &RayPacket, out: &mut PacketHits) {
        if let Tree::Four(b) = &self.tree {
            return intersect_packet_at(b, self.isa, &self.shapes, rays, out);
        }
        *out = PacketHits::default();
        for l in lanes(rays.active) {
            let (o, d, tmax) = rays.get(l);
            if let Some(h) = self.intersect(o, d, tmax) {
                out.prim[l] = h.prim;
                out.h[l] = h.h;
            }
        }
    }

    /// The active lanes of `rays` along which nothing blocks the ray (each
    /// lane as `unoccluded`).
    #[inline(always)]
    pub fn unoccluded_packet(&self, rays: &RayPacket) -> LaneMask {
        if let Tree::Four(b) = &self.tree {
            return unoccluded_packet_at(b, self.isa, &self.shapes, rays);
        }
        let mut free = 0;
        for l in lanes(rays.active) {
            let (o, d, tmax) = rays.get(l);
            if self.unoccluded(o, d, tmax) {
                free |= 1 << l;
            }
        }
        free
    }
}

/// `Bvh4::intersect_packet` with the kernel of `isa`: the AVX-512 intrinsics
/// of `bvh4_packet_avx512.rs` at that level, else the portable lane code of
/// `bvh4_packet.rs` (the same bits).
#[inline(always)]
pub(super) fn intersect_packet_at(
    bvh: &super::bvh4::Bvh4,
    isa: RenderIsa,
    shapes: &[Shape],
    rays: &RayPacket,
    out: &mut PacketHits,
) {
    #[cfg(target_arch = "x86_64")]
    if isa == RenderIsa::Avx512 {
        // SAFETY: `isa` is a level this CPU supports (`RenderIsa::detect`).
        return unsafe { super::bvh4_packet_avx512::intersect_packet(bvh, shapes, rays, out) };
    }
    let _ = isa;
    bvh.intersect_packet(shapes, rays, out)
}

/// `Bvh4::unoccluded_packet` with the kernel of `isa` (as `intersect_packet_at`).
#[inline(always)]
pub(super) fn unoccluded_packet_at(
    bvh: &super::bvh4::Bvh4,
    isa: RenderIsa,
    shapes: &[Shape],
    rays: &RayPacket,
) -> LaneMask {
    #[cfg(target_arch = "x86_64")]
    if isa == RenderIsa::Avx512 {
        // SAFETY: `isa` is a level this CPU supports (`RenderIsa::detect`).
        return unsafe { super::bvh4_packet_avx512::unoccluded_packet(bvh, shapes, rays) };
    }
    let _ = isa;
    bvh.unoccluded_packet(shapes, rays)
}
