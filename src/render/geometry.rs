//! Primitives (triangles, spheres, disks), ray–primitive intersection with
//! floating-point error bounds, robust ray spawning, and the BVH.
//!
//! - Triangles use the watertight test of Woo, Benthin & Wald (JCGT 2013):
//!   translate to the ray origin, permute, shear, then signed edge functions,
//!   re-evaluated in f64 when one is exactly zero. No ray slips through a shared
//!   edge.
//! - Every hit carries a conservative absolute error bound of its position
//!   (`p_err`, per axis). New rays start at the hit point pushed along the
//!   geometric normal by exactly that bound, then rounded one ulp outward
//!   (pbrt-v4's `OffsetRayOrigin`). So the offset scales with the scene: a 1 mm
//!   box gets offsets of ~1e-10 m, a 1 km box ~1e-4 m, and no fixed epsilon is
//!   involved.
//! - Spheres and disks are intersected in f64 and the hit point is re-projected
//!   onto the surface; the bound then covers the final rounding to f32.
//!
//! BVH choice: the renderer uses `BvhKind::Bvh4` (`bvh4.rs`: obvhs' SAH BVH2
//! collapsed to 4-wide nodes, SSE box and 4-triangle tests), ≈ 1.2× the paths
//! per CPU-second of obvhs' BVH2 traversal on the bench scene. The notes below
//! chose between obvhs' own layouts. Measured with `camsim bench render` (Mitsuba
//! `cornell_box()`, 256², 16 spp, 31 bands, 2 threads, this shared 2-core
//! machine): BVH2 0.517 M paths per CPU-second, CWBVH 0.514 (single-thread
//! runs: 0.46 vs 0.48) — no meaningful speed difference for scenes this
//! small. But obvhs' CWBVH clamps the ray's tmin to a fixed 1e-4 in its node
//! test (`cwbvh::node::EPSILON`), so it skips every node that a ray leaves
//! within 0.1 mm: a 1 mm Cornell box lost 8 % of its indirect light with
//! CWBVH and none with BVH2 (test
//! `millimetre_and_kilometre_scenes_stay_finite_and_agree`). That decides it.
//! BVH2 leaves hold ≤ 2 primitives (collapse cost 1), ~15 % faster than
//! obvhs' default of 8 here.

use glam::Vec3;
use obvhs::{Boundable, aabb::Aabb};

const EPS32: f32 = f32::EPSILON * 0.5;

/// pbrt's γ(n) = nε/(1−nε) for f32.
#[inline(always)]
pub fn gamma(n: i32) -> f32 {
    let ne = n as f32 * EPS32;
    ne / (1.0 - ne)
}

/// A primitive shape in world space (f32).
#[derive(Clone, Copy, Debug)]
pub enum Shape {
    Triangle {
        p: [Vec3; 3],
    },
    Sphere {
        center: Vec3,
        radius: f32,
    },
    Disk {
        center: Vec3,
        normal: Vec3,
        radius: f32,
    },
}

impl Boundable for Shape {
    fn aabb(&self) -> Aabb {
        match *self {
            Shape::Triangle { p } => {
                let mn = p[0].min(p[1]).min(p[2]);
                let mx = p[0].max(p[1]).max(p[2]);
                Aabb::new(mn.into(), mx.into())
            }
            Shape::Sphere { center, radius } => {
                let r = Vec3::splat(radius * (1.0 + 4.0 * f32::EPSILON));
                Aabb::new((center - r).into(), (center + r).into())
            }
            Shape::Disk {
                center,
                normal,
                radius,
            } => {
                // Extent of a disk along axis i is r·sqrt(1 − n_i²).
                let e = Vec3::new(
                    (1.0 - normal.x * normal.x).max(0.0).sqrt(),
                    (1.0 - normal.y * normal.y).max(0.0).sqrt(),
                    (1.0 - normal.z * normal.z).max(0.0).sqrt(),
                ) * radius
                    * (1.0 + 4.0 * f32::EPSILON)
                    + Vec3::splat(center.abs().max_element() * 4.0 * f32::EPSILON);
                Aabb::new((center - e).into(), (center + e).into())
            }
        }
    }
}

impl Shape {
    pub fn area(&self) -> f32 {
        match *self {
            Shape::Triangle { p } => 0.5 * (p[1] - p[0]).cross(p[2] - p[0]).length(),
            Shape::Sphere { radius, .. } => 4.0 * std::f32::consts::PI * radius * radius,
            Shape::Disk { radius, .. } => std::f32::consts::PI * radius * radius,
        }
    }
}

/// Result of a primitive test: parametric distance plus whatever the surface
/// needs to rebuild the hit (barycentrics for triangles).
#[derive(Clone, Copy, Debug, Default)]
pub struct PrimHit {
    pub t: f32,
    pub b: [f32; 3],
}

/// Per-ray constants of the watertight test (axis permutation and shear),
/// computed once per ray instead of once per triangle.
#[derive(Clone, Copy, Debug)]
pub struct TriRay {
    pub o: Vec3,
    pub(crate) kz: u8,
    pub(crate) sx: f32,
    pub(crate) sy: f32,
    pub(crate) sz: f32,
}

#[inline(always)]
fn permute(v: Vec3, kz: u8) -> Vec3 {
    match kz {
        0 => Vec3::new(v.y, v.z, v.x),
        1 => Vec3::new(v.z, v.x, v.y),
        _ => v,
    }
}

impl TriRay {
    #[inline(always)]
    pub fn new(o: Vec3, d: Vec3) -> Self {
        // Permute so that the largest |d| component is z, then shear.
        let ad = d.abs();
        let kz = if ad.x > ad.y {
            if ad.x > ad.z { 0 } else { 2 }
        } else if ad.y > ad.z {
            1
        } else {
            2
        };
        let dp = permute(d, kz);
        let sz = 1.0 / dp.z;
        TriRay {
            o,
            kz,
            sx: -dp.x * sz,
            sy: -dp.y * sz,
            sz,
        }
    }
}

/// Watertight ray–triangle test. `d` need not be unit length. Returns t in
/// (0, tmax) and barycentrics.
#[inline(always)]
pub fn intersect_triangle(o: Vec3, d: Vec3, tmax: f32, p: &[Vec3; 3]) -> Option<PrimHit> {
    intersect_triangle_pre(&TriRay::new(o, d), tmax, p)
}

/// Watertight ray–triangle test with precomputed ray constants.
#[inline(always)]
pub fn intersect_triangle_pre(r: &TriRay, tmax: f32, p: &[Vec3; 3]) -> Option<PrimHit> {
    let mut p0t = permute(p[0] - r.o, r.kz);
    let mut p1t = permute(p[1] - r.o, r.kz);
    let mut p2t = permute(p[2] - r.o, r.kz);
    let (sx, sy, sz) = (r.sx, r.sy, r.sz);
    p0t.x += sx * p0t.z;
    p0t.y += sy * p0t.z;
    p1t.x += sx * p1t.z;
    p1t.y += sy * p1t.z;
    p2t.x += sx * p2t.z;
    p2t.y += sy * p2t.z;
    let mut e0 = p1t.x * p2t.y - p1t.y * p2t.x;
    let mut e1 = p2t.x * p0t.y - p2t.y * p0t.x;
    let mut e2 = p0t.x * p1t.y - p0t.y * p1t.x;
    if e0 == 0.0 || e1 == 0.0 || e2 == 0.0 {
        let f = |ax: f32, ay: f32, bx: f32, by: f32| {
            (ax as f64 * by as f64 - ay as f64 * bx as f64) as f32
        };
        e0 = f(p1t.x, p1t.y, p2t.x, p2t.y);
        e1 = f(p2t.x, p2t.y, p0t.x, p0t.y);
        e2 = f(p0t.x, p0t.y, p1t.x, p1t.y);
    }
    if (e0 < 0.0 || e1 < 0.0 || e2 < 0.0) && (e0 > 0.0 || e1 > 0.0 || e2 > 0.0) {
        return None;
    }
    let det = e0 + e1 + e2;
    if det == 0.0 {
        return None;
    }
    p0t.z *= sz;
    p1t.z *= sz;
    p2t.z *= sz;
    let t_scaled = e0 * p0t.z + e1 * p1t.z + e2 * p2t.z;
    if det < 0.0 && (t_scaled >= 0.0 || t_scaled < tmax * det) {
        return None;
    }
    if det > 0.0 && (t_scaled <= 0.0 || t_scaled > tmax * det) {
        return None;
    }
    let inv_det = 1.0 / det;
    let b0 = e0 * inv_det;
    let b1 = e1 * inv_det;
    let b2 = e2 * inv_det;
    let t = t_scaled * inv_det;
    // Conservative check that t is positive beyond its rounding error (pbrt-v4).
    let max_zt = Vec3::new(p0t.z, p1t.z, p2t.z).abs().max_element();
    let delta_z = gamma(3) * max_zt;
    let max_xt = Vec3::new(p0t.x, p1t.x, p2t.x).abs().max_element();
    let max_yt = Vec3::new(p0t.y, p1t.y, p2t.y).abs().max_element();
    let delta_x = gamma(5) * (max_xt + max_zt);
    let delta_y = gamma(5) * (max_yt + max_zt);
    let delta_e = 2.0 * (gamma(2) * max_xt * max_yt + delta_y * max_xt + delta_x * max_yt);
    let max_e = Vec3::new(e0, e1, e2).abs().max_element();
    let delta_t =
        3.0 * (gamma(3) * max_e * max_zt + delta_e * max_zt + delta_z * max_e) * inv_det.abs();
    if t <= delta_t {
        return None;
    }
    Some(PrimHit { t, b: [b0, b1, b2] })
}

/// Ray–sphere in f64 (robust quadratic). `d` need not be unit length.
#[inline(always)]
pub fn intersect_sphere(o: Vec3, d: Vec3, tmax: f32, center: Vec3, radius: f32) -> Option<PrimHit> {
    let oc = o.as_dvec3() - center.as_dvec3();
    let dd = d.as_dvec3();
    let a = dd.length_squared();
    let b = 2.0 * oc.dot(dd);
    let r = radius as f64;
    // c via the difference of squares (oc − proj) for accuracy when o is far away.
    let proj = oc.dot(dd) / a * dd;
    let perp = oc - proj;
    let disc = 4.0 * a * (r * r - perp.length_squared());
    if disc < 0.0 {
        return None;
    }
    let c = oc.length_squared() - r * r;
    let sd = disc.sqrt();
    let q = if b < 0.0 {
        -0.5 * (b - sd)
    } else {
        -0.5 * (b + sd)
    };
    let (mut t0, mut t1) = (q / a, if q != 0.0 { c / q } else { q / a });
    if t0 > t1 {
        std::mem::swap(&mut t0, &mut t1);
    }
    let tmax = tmax as f64;
    let t = if t0 > 0.0 { t0 } else { t1 };
    if t <= 0.0 || t >= tmax {
        return None;
    }
    let t32 = t as f32;
    if t32 <= 0.0 || t32 >= tmax as f32 {
        return None;
    }
    Some(PrimHit {
        t: t32,
        b: [0.0; 3],
    })
}

/// Ray–disk in f64. `d` need not be unit length.
#[inline(always)]
pub fn intersect_disk(
    o: Vec3,
    d: Vec3,
    tmax: f32,
    center: Vec3,
    normal: Vec3,
    radius: f32,
) -> Option<PrimHit> {
    let n = normal.as_dvec3();
    let dn = d.as_dvec3().dot(n);
    if dn == 0.0 {
        return None;
    }
    let t = (center.as_dvec3() - o.as_dvec3()).dot(n) / dn;
    if t <= 0.0 || t >= tmax as f64 {
        return None;
    }
    let p = o.as_dvec3() + d.as_dvec3() * t;
    if (p - center.as_dvec3()).length_squared() > (radius as f64) * (radius as f64) {
        return None;
    }
    let t32 = t as f32;
    if t32 <= 0.0 || t32 >= tmax {
        return None;
    }
    Some(PrimHit {
        t: t32,
        b: [0.0; 3],
    })
}

impl Shape {
    #[inline(always)]
    pub fn intersect(&self, o: Vec3, d: Vec3, tmax: f32) -> Option<PrimHit> {
        self.intersect_pre(&TriRay::new(o, d), d, tmax)
    }

    /// Intersect with precomputed triangle-ray constants (`r.o` is the origin).
    #[inline(always)]
    pub fn intersect_pre(&self, r: &TriRay, d: Vec3, tmax: f32) -> Option<PrimHit> {
        let o = r.o;
        match self {
            Shape::Triangle { p } => intersect_triangle_pre(r, tmax, p),
            Shape::Sphere { center, radius } => intersect_sphere(o, d, tmax, *center, *radius),
            Shape::Disk {
                center,
                normal,
                radius,
            } => intersect_disk(o, d, tmax, *center, *normal, *radius),
        }
    }

    /// Surface point, its error bound and the geometric normal for a hit.
    #[inline(always)]
    pub fn surface(&self, o: Vec3, d: Vec3, h: &PrimHit) -> (Vec3, Vec3, Vec3) {
        match *self {
            Shape::Triangle { p } => {
                let (pt, err) = triangle_point(&p, h.b, HIT_POINT_GAMMA);
                let n = (p[1] - p[0]).cross(p[2] - p[0]).normalize_or_zero();
                (pt, err, n)
            }
            Shape::Sphere { center, radius } => {
                let pd = o.as_dvec3() + d.as_dvec3() * h.t as f64;
                let c = center.as_dvec3();
                let v = pd - c;
                let pd = c + v * (radius as f64 / v.length());
                let pt = pd.as_vec3();
                // f64 re-projection error is far below one f32 ulp; bound the final rounding.
                let err = (pt.abs() + Vec3::splat(radius)) * (4.0 * f32::EPSILON);
                let n = (pd - c).normalize().as_vec3();
                (pt, err, n)
            }
            Shape::Disk { center, normal, .. } => {
                let pd = o.as_dvec3() + d.as_dvec3() * h.t as f64;
                let nd = normal.as_dvec3();
                let pd = pd - nd * (pd - center.as_dvec3()).dot(nd);
                let pt = pd.as_vec3();
                let err = (pt.abs() + center.abs()) * (4.0 * f32::EPSILON);
                (pt, err, normal)
            }
        }
    }
}

/// γ order of a hit point's error bound (barycentric interpolation of the
/// vertices after the watertight test, pbrt-v4).
pub const HIT_POINT_GAMMA: i32 = 7;

/// The point at barycentrics `b` on triangle `p` and its rounding-error bound
/// Σ|pᵢ·bᵢ|·γ(`n`) (pbrt-v4: n = 7 for a ray hit, 6 for a sampled point).
#[inline(always)]
pub fn triangle_point(p: &[Vec3; 3], b: [f32; 3], n: i32) -> (Vec3, Vec3) {
    let pt = p[0] * b[0] + p[1] * b[1] + p[2] * b[2];
    let err = ((p[0] * b[0]).abs() + (p[1] * b[1]).abs() + (p[2] * b[2]).abs()) * gamma(n);
    (pt, err)
}

/// Next representable f32 towards +inf / −inf.
#[inline(always)]
fn next_up(x: f32) -> f32 {
    x.next_up()
}
#[inline(always)]
fn next_down(x: f32) -> f32 {
    x.next_down()
}

/// Offset a ray origin off a surface (pbrt-v4 `OffsetRayOrigin`): push `p` along
/// the geometric normal `n` by the error bound, to the side of `w`, then round
/// one ulp away so the new origin is strictly on that side.
#[inline(always)]
pub fn offset_ray_origin(p: Vec3, p_err: Vec3, n: Vec3, w: Vec3) -> Vec3 {
    let dist = n.abs().dot(p_err);
    let mut off = n * dist;
    if w.dot(n) < 0.0 {
        off = -off;
    }
    let mut po = p + off;
    for i in 0..3 {
        if off[i] > 0.0 {
            po[i] = next_up(po[i]);
        } else if off[i] < 0.0 {
            po[i] = next_down(po[i]);
        }
    }
    po
}

#[cfg(test)]
mod tests {
    use super::*;

    #[test]
    fn watertight_shared_edge_is_never_missed() {
        // Two triangles sharing the diagonal of the unit square; rays aimed exactly at the diagonal.
        let a = [
            Vec3::new(0.0, 0.0, 1.0),
            Vec3::new(1.0, 0.0, 1.0),
            Vec3::new(1.0, 1.0, 1.0),
        ];
        let b = [
            Vec3::new(0.0, 0.0, 1.0),
            Vec3::new(1.0, 1.0, 1.0),
            Vec3::new(0.0, 1.0, 1.0),
        ];
        let o = Vec3::new(0.3, 0.7, 0.0);
        for i in 1..1000 {
            let s = i as f32 / 1000.0;
            let d = Vec3::new(s, s, 1.0) - o;
            let ha = intersect_triangle(o, d, f32::INFINITY, &a);
            let hb = intersect_triangle(o, d, f32::INFINITY, &b);
            assert!(
                ha.is_some() || hb.is_some(),
                "ray through the shared edge at s={s} missed both"
            );
        }
    }

    #[test]
    fn sphere_and_disk_hits() {
        let h = intersect_sphere(
            Vec3::new(0.0, 0.0, -5.0),
            Vec3::Z,
            f32::INFINITY,
            Vec3::ZERO,
            1.0,
        )
        .unwrap();
        assert!((h.t - 4.0).abs() < 1e-6);
        let h = intersect_sphere(Vec3::ZERO, Vec3::Z, f32::INFINITY, Vec3::ZERO, 1.0).unwrap();
        assert!((h.t - 1.0).abs() < 1e-6);
        let h = intersect_disk(
            Vec3::new(0.1, 0.0, -1.0),
            Vec3::Z,
            f32::INFINITY,
            Vec3::ZERO,
            Vec3::Z,
            0.5,
        )
        .unwrap();
        assert!((h.t - 1.0).abs() < 1e-6);
        assert!(
            intersect_disk(
                Vec3::new(0.6, 0.0, -1.0),
                Vec3::Z,
                f32::INFINITY,
                Vec3::ZERO,
                Vec3::Z,
                0.5
            )
            .is_none()
        );
    }
}
