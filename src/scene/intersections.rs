//! Objects that intersect one another: a bunny pushed into a wall, a chart
//! sunk into a cube. `camsim check` reports them (paper Fig. 4 places a bunny
//! beside two cubes; it must stand free).
//!
//! Two objects **intersect** when a triangle of one crosses a triangle of the
//! other (an edge of either passes through the other) *and* one penetrates the
//! other by more than a tolerance: a point of A (a vertex or a triangle
//! centroid) lies inside B, farther than the tolerance from B's surface, when
//! B is closed (every edge shared by exactly two triangles; inside by ray
//! parity); or, when B is an open sheet (a wall, a hood), A reaches through
//! one of the sheet's crossed triangles by more than the tolerance on both
//! sides of it (of A's points that project onto that triangle, the smaller
//! of the largest distances in front and behind). Surfaces that only touch or rest on one another — the
//! Cornell box's cubes stand 0.3 mm into its floor, its walls overlap at their
//! edges by 0.3 mm — are contacts, not intersections, below a tolerance of
//! 1 mm ([`DEFAULT_TOLERANCE_M`]).
//!
//! Triangle meshes (and instanced meshes) are checked; spheres and disks
//! (analytic shapes of pbrt scenes) are not.

use crate::scene::Scene;
use glam::DVec3;
use std::collections::HashMap;

/// Penetration below this is contact (objects resting on, or butting against, each other).
pub const DEFAULT_TOLERANCE_M: f64 = 1e-3;

/// Two objects that intersect, and how deep.
#[derive(Clone, Debug, PartialEq)]
pub struct Intersection {
    pub a: String,
    pub b: String,
    /// Largest penetration found (of either into the other), metres.
    pub depth_m: f64,
}

type Tri = [DVec3; 3];

struct Solid {
    name: String,
    tris: Vec<Tri>,
    lo: DVec3,
    hi: DVec3,
    closed: bool,
}

fn bounds(tris: &[Tri]) -> (DVec3, DVec3) {
    let mut lo = DVec3::splat(f64::INFINITY);
    let mut hi = DVec3::splat(f64::NEG_INFINITY);
    for t in tris {
        for p in t {
            lo = lo.min(*p);
            hi = hi.max(*p);
        }
    }
    (lo, hi)
}

/// Every edge shared by exactly two triangles (positions matched to 1e-9 m).
fn is_closed(tris: &[Tri]) -> bool {
    let key = |p: DVec3| {
        let q = (p * 1e9).round();
        (q.x as i64, q.y as i64, q.z as i64)
    };
    type Key = (i64, i64, i64);
    let mut edges: HashMap<(Key, Key), u32> = HashMap::new();
    for t in tris {
        for i in 0..3 {
            let (a, b) = (key(t[i]), key(t[(i + 1) % 3]));
            let e = if a < b { (a, b) } else { (b, a) };
            *edges.entry(e).or_default() += 1;
        }
    }
    !edges.is_empty() && edges.values().all(|&n| n == 2)
}

/// The triangles of each object, in world space.
fn solids(scene: &Scene) -> Vec<Solid> {
    let mut per: Vec<Vec<Tri>> = vec![vec![]; scene.objects.len()];
    let tri_of = |m: &crate::scene::Mesh, ix: &[u32; 3]| -> Tri {
        ix.map(|i| m.positions[i as usize].as_dvec3())
    };
    for m in &scene.meshes {
        if let Some(v) = per.get_mut(m.object as usize) {
            v.extend(m.indices.iter().map(|ix| tri_of(m, ix)));
        }
    }
    for inst in &scene.instances {
        for &k in &inst.prototype {
            let Some(m) = scene.meshes.get(k) else {
                continue;
            };
            let obj = inst.object.unwrap_or(m.object) as usize;
            if let Some(v) = per.get_mut(obj) {
                v.extend(
                    m.indices
                        .iter()
                        .map(|ix| tri_of(m, ix).map(|p| inst.to_world.transform_point3(p))),
                );
            }
        }
    }
    per.into_iter()
        .enumerate()
        .filter(|(_, t)| !t.is_empty())
        .map(|(i, tris)| {
            let (lo, hi) = bounds(&tris);
            Solid {
                name: scene.objects[i].name.clone(),
                closed: is_closed(&tris),
                tris,
                lo,
                hi,
            }
        })
        .collect()
}

/// Does segment p→q pass through triangle t (Möller–Trumbore, 0 ≤ s ≤ 1)?
fn segment_hits(p: DVec3, q: DVec3, t: &Tri) -> bool {
    ray_hit(p, q - p, t).is_some_and(|s| (0.0..=1.0).contains(&s))
}

/// Parameter s of the hit of p + s·d with triangle t.
fn ray_hit(p: DVec3, d: DVec3, t: &Tri) -> Option<f64> {
    let (e1, e2) = (t[1] - t[0], t[2] - t[0]);
    let h = d.cross(e2);
    let a = e1.dot(h);
    if a.abs() < 1e-30 {
        return None;
    }
    let f = 1.0 / a;
    let s = p - t[0];
    let u = f * s.dot(h);
    if !(0.0..=1.0).contains(&u) {
        return None;
    }
    let q = s.cross(e1);
    let v = f * d.dot(q);
    if v < 0.0 || u + v > 1.0 {
        return None;
    }
    Some(f * e2.dot(q))
}

fn crosses(a: &Tri, b: &Tri) -> bool {
    (0..3).any(|i| segment_hits(a[i], a[(i + 1) % 3], b))
        || (0..3).any(|i| segment_hits(b[i], b[(i + 1) % 3], a))
}

/// Closest point of triangle t to p (Ericson, Real-Time Collision Detection 5.1.5).
fn closest_on_triangle(p: DVec3, t: &Tri) -> DVec3 {
    let (a, b, c) = (t[0], t[1], t[2]);
    let (ab, ac, ap) = (b - a, c - a, p - a);
    let (d1, d2) = (ab.dot(ap), ac.dot(ap));
    if d1 <= 0.0 && d2 <= 0.0 {
        return a;
    }
    let bp = p - b;
    let (d3, d4) = (ab.dot(bp), ac.dot(bp));
    if d3 >= 0.0 && d4 <= d3 {
        return b;
    }
    let vc = d1 * d4 - d3 * d2;
    if vc <= 0.0 && d1 >= 0.0 && d3 <= 0.0 {
        return a + ab * (d1 / (d1 - d3));
    }
    let cp = p - c;
    let (d5, d6) = (ab.dot(cp), ac.dot(cp));
    if d6 >= 0.0 && d5 <= d6 {
        return c;
    }
    let vb = d5 * d2 - d1 * d6;
    if vb <= 0.0 && d2 >= 0.0 && d6 <= 0.0 {
        return a + ac * (d2 / (d2 - d6));
    }
    let va = d3 * d6 - d5 * d4;
    if va <= 0.0 && (d4 - d3) >= 0.0 && (d5 - d6) >= 0.0 {
        return b + (c - b) * ((d4 - d3) / ((d4 - d3) + (d5 - d6)));
    }
    let denom = 1.0 / (va + vb + vc);
    a + ab * (vb * denom) + ac * (vc * denom)
}

/// How far `p` lies inside the closed solid `b` (0 outside): its distance to
/// b's surface when an odd number of b's triangles lie along a fixed ray.
fn inside_depth(p: DVec3, b: &Solid) -> f64 {
    // a direction no modelled mesh is aligned with
    let d = DVec3::new(0.577_215_664_9, 0.618_033_988_7, 0.533_701_3).normalize();
    let hits = b
        .tris
        .iter()
        .filter(|t| ray_hit(p, d, t).is_some_and(|s| s > 0.0))
        .count();
    if hits % 2 == 0 {
        return 0.0;
    }
    b.tris
        .iter()
        .map(|t| (closest_on_triangle(p, t) - p).length())
        .fold(f64::INFINITY, f64::min)
}

/// How far the points `ps` pass through the sheet triangle `t`: of the points
/// that project onto t, the smaller of the largest distances in front of and
/// behind its plane (a sheet is passed through only by what reaches both sides).
fn through_depth(ps: &[DVec3], t: &Tri) -> f64 {
    let n = (t[1] - t[0]).cross(t[2] - t[0]);
    let len = n.length();
    if len == 0.0 {
        return 0.0;
    }
    let n = n / len;
    let (mut front, mut back) = (0.0f64, 0.0f64);
    for &p in ps {
        let dist = (p - t[0]).dot(n);
        if ray_hit(p, -n * dist.signum(), t).is_none() && dist != 0.0 {
            continue;
        }
        if dist > 0.0 {
            front = front.max(dist);
        } else {
            back = back.max(-dist);
        }
    }
    front.min(back)
}

fn overlaps(lo1: DVec3, hi1: DVec3, lo2: DVec3, hi2: DVec3, pad: f64) -> bool {
    (lo1 - pad).cmple(hi2).all() && (lo2 - pad).cmple(hi1).all()
}

/// Sample points of `a` near `b`: vertices and centroids of a's triangles
/// that overlap b's bounding box.
fn samples_near(a: &Solid, b: &Solid) -> Vec<DVec3> {
    a.tris
        .iter()
        .filter(|t| {
            let (lo, hi) = bounds(std::slice::from_ref(*t));
            overlaps(lo, hi, b.lo, b.hi, 0.0)
        })
        .flat_map(|t| [t[0], t[1], t[2], (t[0] + t[1] + t[2]) / 3.0])
        .collect()
}

/// Penetration of `a` into `b`: into b's volume when b is closed, else
/// through the triangles of b that a crosses (`crossed`).
fn depth_into(a: &Solid, b: &Solid, crossed: &[Tri]) -> f64 {
    let ps = samples_near(a, b);
    if b.closed {
        ps.iter()
            .filter(|p| p.cmpge(b.lo).all() && p.cmple(b.hi).all())
            .map(|&p| inside_depth(p, b))
            .fold(0.0, f64::max)
    } else {
        crossed
            .iter()
            .map(|t| through_depth(&ps, t))
            .fold(0.0, f64::max)
    }
}

/// Pairs of objects of `scene` that intersect by more than `tolerance_m` (see the module docs).
pub fn intersecting_objects(scene: &Scene, tolerance_m: f64) -> Vec<Intersection> {
    let s = solids(scene);
    let mut out = vec![];
    for i in 0..s.len() {
        for j in i + 1..s.len() {
            let (a, b) = (&s[i], &s[j]);
            if !overlaps(a.lo, a.hi, b.lo, b.hi, tolerance_m) {
                continue;
            }
            let near = |x: &Solid, y: &Solid| -> Vec<Tri> {
                x.tris
                    .iter()
                    .filter(|t| {
                        let (lo, hi) = bounds(std::slice::from_ref(*t));
                        overlaps(lo, hi, y.lo, y.hi, 0.0)
                    })
                    .copied()
                    .collect()
            };
            let (ta, tb) = (near(a, b), near(b, a));
            // the triangles of each that cross a triangle of the other
            let (mut xa, mut xb): (Vec<Tri>, Vec<Tri>) = (vec![], vec![]);
            for x in &ta {
                let (lo, hi) = bounds(std::slice::from_ref(x));
                for y in &tb {
                    let (lo2, hi2) = bounds(std::slice::from_ref(y));
                    if overlaps(lo, hi, lo2, hi2, 0.0) && crosses(x, y) {
                        if !xa.contains(x) {
                            xa.push(*x);
                        }
                        if !xb.contains(y) {
                            xb.push(*y);
                        }
                    }
                }
            }
            if xa.is_empty() {
                continue;
            }
            let depth = depth_into(a, b, &xb).max(depth_into(b, a, &xa));
            if depth > tolerance_m {
                out.push(Intersection {
                    a: a.name.clone(),
                    b: b.name.clone(),
                    depth_m: depth,
                });
            }
        }
    }
    out
}

#[cfg(test)]
mod tests {
    use super::*;
    use crate::scene::Mesh;
    use glam::Vec3;

    /// An axis-aligned box as a closed mesh (12 triangles, outward winding).
    fn cube(scene: &mut Scene, name: &str, c: [f32; 3], h: f32) {
        let obj = scene.object(name);
        let p: Vec<Vec3> = (0..8)
            .map(|i| {
                Vec3::new(
                    c[0] + if i & 1 == 1 { h } else { -h },
                    c[1] + if i & 2 == 2 { h } else { -h },
                    c[2] + if i & 4 == 4 { h } else { -h },
                )
            })
            .collect();
        let q = |a, b, c, d| [[a, b, c], [a, c, d]];
        let mut ix = vec![];
        for f in [
            q(0, 2, 3, 1),
            q(4, 5, 7, 6),
            q(0, 1, 5, 4),
            q(2, 6, 7, 3),
            q(0, 4, 6, 2),
            q(1, 3, 7, 5),
        ] {
            ix.extend(f);
        }
        scene.meshes.push(Mesh {
            positions: p,
            normals: None,
            uvs: None,
            indices: ix,
            material: 0,
            object: obj,
            emission: None,
        });
    }

    /// A floor rectangle at height y, normal +y (winding counter-clockwise from above).
    fn floor(scene: &mut Scene, y: f32) {
        let obj = scene.object("floor");
        scene.meshes.push(Mesh {
            positions: vec![
                Vec3::new(-1.0, y, -1.0),
                Vec3::new(-1.0, y, 1.0),
                Vec3::new(1.0, y, 1.0),
                Vec3::new(1.0, y, -1.0),
            ],
            normals: None,
            uvs: None,
            indices: vec![[0, 1, 2], [0, 2, 3]],
            material: 0,
            object: obj,
            emission: None,
        });
    }

    #[test]
    fn resting_is_contact_sinking_is_intersection() {
        // a 10 cm cube resting 0.3 mm into the floor: contact
        let mut s = Scene::default();
        floor(&mut s, 0.0003);
        cube(&mut s, "cube", [0.0, 0.05, 0.0], 0.05);
        assert!(is_closed(&solids(&s)[1].tris));
        assert_eq!(intersecting_objects(&s, DEFAULT_TOLERANCE_M), vec![]);
        // sunk 2 cm: the cube's bottom corners lie 2 cm behind the floor
        let mut s = Scene::default();
        floor(&mut s, 0.02);
        cube(&mut s, "cube", [0.0, 0.05, 0.0], 0.05);
        let v = intersecting_objects(&s, DEFAULT_TOLERANCE_M);
        assert_eq!(v.len(), 1);
        assert!((v[0].depth_m - 0.02).abs() < 1e-6, "{v:?}");
    }

    #[test]
    fn overlapping_cubes_intersect_and_separate_ones_do_not() {
        let mut s = Scene::default();
        cube(&mut s, "a", [0.0, 0.0, 0.0], 0.05);
        cube(&mut s, "b", [0.08, 0.0, 0.0], 0.05);
        let v = intersecting_objects(&s, DEFAULT_TOLERANCE_M);
        assert_eq!(v.len(), 1);
        // b's corner at x = 0.03 lies 0.02 inside a (its nearest face is x = 0.05)
        assert!((v[0].depth_m - 0.02).abs() < 1e-6, "{v:?}");
        let mut s = Scene::default();
        cube(&mut s, "a", [0.0, 0.0, 0.0], 0.05);
        cube(&mut s, "b", [0.1005, 0.0, 0.0], 0.05);
        assert_eq!(intersecting_objects(&s, DEFAULT_TOLERANCE_M), vec![]);
        // a small cube entirely inside a big one crosses no triangle: not reported
        // (nested solids are a modelling choice, e.g. a label volume)
        let mut s = Scene::default();
        cube(&mut s, "a", [0.0, 0.0, 0.0], 0.05);
        cube(&mut s, "b", [0.0, 0.0, 0.0], 0.01);
        assert_eq!(intersecting_objects(&s, DEFAULT_TOLERANCE_M), vec![]);
    }
}
