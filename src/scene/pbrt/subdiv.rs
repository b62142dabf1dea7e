//! One level of Loop subdivision (pbrt's `loopsubdiv`), without the final projection
//! to the limit surface.
//!
//! Rules (Loop 1987): a new edge vertex is 3/8·(a+b) + 1/8·(c+d) for an interior edge
//! with opposite vertices c, d, the midpoint on a boundary edge; an old interior
//! vertex of valence n moves to (1−nβ)v + βΣneighbours with β = 3/16 for n = 3, else
//! 3/(8n); an old boundary vertex to 3/4·v + 1/8·(its two boundary neighbours).
//! Non-manifold vertices and edges keep their position / midpoint.

use glam::DVec3;
use std::collections::HashMap;

pub fn loop_once(p: &[DVec3], tri: &[[u32; 3]]) -> (Vec<DVec3>, Vec<[u32; 3]>) {
    // edge (min, max) -> list of opposite vertices
    let mut edges: HashMap<(u32, u32), Vec<u32>> = HashMap::new();
    for t in tri {
        for k in 0..3 {
            let (a, b, c) = (t[k], t[(k + 1) % 3], t[(k + 2) % 3]);
            edges.entry((a.min(b), a.max(b))).or_default().push(c);
        }
    }
    let n = p.len();
    let mut neighbours: Vec<Vec<u32>> = vec![vec![]; n];
    let mut boundary_nb: Vec<Vec<u32>> = vec![vec![]; n];
    let mut nonmanifold = vec![false; n];
    let mut keys: Vec<(u32, u32)> = edges.keys().copied().collect();
    keys.sort_unstable();
    for &(a, b) in &keys {
        neighbours[a as usize].push(b);
        neighbours[b as usize].push(a);
        match edges[&(a, b)].len() {
            1 => {
                boundary_nb[a as usize].push(b);
                boundary_nb[b as usize].push(a);
            }
            2 => {}
            _ => {
                nonmanifold[a as usize] = true;
                nonmanifold[b as usize] = true;
            }
        }
    }
    let mut out: Vec<DVec3> = (0..n)
        .map(|i| {
            let v = p[i];
            if nonmanifold[i] || neighbours[i].is_empty() {
                return v;
            }
            match boundary_nb[i].len() {
                0 => {
                    let k = neighbours[i].len() as f64;
                    let beta = if neighbours[i].len() == 3 {
                        3.0 / 16.0
                    } else {
                        3.0 / (8.0 * k)
                    };
                    let sum: DVec3 = neighbours[i].iter().map(|&j| p[j as usize]).sum();
                    (1.0 - k * beta) * v + beta * sum
                }
                2 => {
                    0.75 * v
                        + 0.125 * (p[boundary_nb[i][0] as usize] + p[boundary_nb[i][1] as usize])
                }
                _ => v,
            }
        })
        .collect();
    let mut edge_vertex: HashMap<(u32, u32), u32> = HashMap::with_capacity(keys.len());
    for &(a, b) in &keys {
        let opp = &edges[&(a, b)];
        let (pa, pb) = (p[a as usize], p[b as usize]);
        let q = if opp.len() == 2 {
            0.375 * (pa + pb) + 0.125 * (p[opp[0] as usize] + p[opp[1] as usize])
        } else {
            0.5 * (pa + pb)
        };
        edge_vertex.insert((a, b), out.len() as u32);
        out.push(q);
    }
    let ev = |a: u32, b: u32| edge_vertex[&(a.min(b), a.max(b))];
    let mut tris = Vec::with_capacity(tri.len() * 4);
    for t in tri {
        let [a, b, c] = *t;
        let (ab, bc, ca) = (ev(a, b), ev(b, c), ev(c, a));
        tris.push([a, ab, ca]);
        tris.push([ab, b, bc]);
        tris.push([ca, bc, c]);
        tris.push([ab, bc, ca]);
    }
    (out, tris)
}

#[cfg(test)]
mod tests {
    use super::*;
    #[test]
    fn tetrahedron_counts_and_positions() {
        let p = vec![
            DVec3::new(1.0, 1.0, 1.0),
            DVec3::new(1.0, -1.0, -1.0),
            DVec3::new(-1.0, 1.0, -1.0),
            DVec3::new(-1.0, -1.0, 1.0),
        ];
        let t = vec![[0, 1, 2], [0, 3, 1], [0, 2, 3], [1, 3, 2]];
        let (q, tt) = loop_once(&p, &t);
        assert_eq!(q.len(), 10);
        assert_eq!(tt.len(), 16);
        // valence 3, β = 3/16: v' = (1 − 9/16) v + 3/16 Σ others = 7/16 v − 3/16 v = v/4 (Σ all = 0).
        assert!((q[0] - p[0] * 0.25).length() < 1e-12);
        // edge (0,1): 3/8 (p0+p1) + 1/8 (p2+p3) = 3/8 (2,0,0) + 1/8 (-2,0,0) = (0.5,0,0)
        assert!(
            q.iter()
                .any(|v| (*v - DVec3::new(0.5, 0.0, 0.0)).length() < 1e-12)
        );
    }
}
