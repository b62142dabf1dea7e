//! Builders for simple meshes in world space: quads (rectangles) and boxes.
//! The front side of a quad (its geometric normal, the emitting side of an
//! area light) is `u × v`.

use super::model::{Emission, MaterialId, Mesh, ObjectId};
use glam::{DMat4, DVec3, Vec3};

/// A parallelogram centred at `center` spanning `±u` and `±v` (half-edge
/// vectors); normal along `u × v`.
pub fn quad(
    center: DVec3,
    u: DVec3,
    v: DVec3,
    material: MaterialId,
    object: ObjectId,
    emission: Option<Emission>,
) -> Mesh {
    let p = [
        center - u - v,
        center + u - v,
        center + u + v,
        center - u + v,
    ];
    Mesh {
        positions: p.iter().map(|x| x.as_vec3()).collect(),
        normals: None,
        uvs: None,
        indices: vec![[0, 1, 2], [0, 2, 3]],
        material,
        object,
        emission,
    }
}

/// An axis-aligned box of half extents `half`, transformed by `to_world`
/// (outward normals; `inward` flips them, for enclosures).
pub fn cuboid(
    half: DVec3,
    to_world: DMat4,
    inward: bool,
    material: MaterialId,
    object: ObjectId,
    emission: Option<Emission>,
) -> Mesh {
    let mut positions: Vec<Vec3> = Vec::with_capacity(24);
    let mut indices = Vec::with_capacity(12);
    // (normal axis, sign) → quad with u × v = sign·axis.
    let faces: [(DVec3, DVec3, DVec3); 6] = [
        (DVec3::X, DVec3::Y, DVec3::Z),
        (-DVec3::X, DVec3::Z, DVec3::Y),
        (DVec3::Y, DVec3::Z, DVec3::X),
        (-DVec3::Y, DVec3::X, DVec3::Z),
        (DVec3::Z, DVec3::X, DVec3::Y),
        (-DVec3::Z, DVec3::Y, DVec3::X),
    ];
    for (n, a, b) in faces {
        let c = n * half;
        let u = a * half;
        let v = b * half;
        let (u, v) = if inward { (v, u) } else { (u, v) };
        let base = positions.len() as u32;
        for p in [c - u - v, c + u - v, c + u + v, c - u + v] {
            positions.push(to_world.transform_point3(p).as_vec3());
        }
        indices.push([base, base + 1, base + 2]);
        indices.push([base, base + 2, base + 3]);
    }
    Mesh {
        positions,
        normals: None,
        uvs: None,
        indices,
        material,
        object,
        emission,
    }
}

#[cfg(test)]
mod tests {
    use super::*;
    #[test]
    fn box_normals_point_outward() {
        let m = cuboid(
            DVec3::new(1.0, 2.0, 3.0),
            DMat4::IDENTITY,
            false,
            0,
            0,
            None,
        );
        for t in &m.indices {
            let p: Vec<Vec3> = t.iter().map(|&i| m.positions[i as usize]).collect();
            let n = (p[1] - p[0]).cross(p[2] - p[0]);
            let c = (p[0] + p[1] + p[2]) / 3.0;
            assert!(n.dot(c) > 0.0, "face normal {n} at {c} points inward");
        }
        let q = quad(DVec3::ZERO, DVec3::X, DVec3::Z, 0, 0, None);
        let n = (q.positions[1] - q.positions[0]).cross(q.positions[2] - q.positions[0]);
        assert!(n.y < 0.0, "X × Z = −Y");
    }
}
