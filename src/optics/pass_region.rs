//! The pass region of an RTF: the part of the pass plane through which rays
//! from one input radius get through the lens, as traced boundary points,
//! turned into the representations an RTF file stores: the minimum-area
//! enclosing ellipse (Khachiyan), the axis-aligned ellipse with the region's
//! radial extent and area, or one vignetting circle per blocking aperture
//! (Goossens et al.). Which one the fit writes, and why: docs/rtf-fit.md
//! ("Pass/no-pass").

// `!(x > 0.0)` is used on purpose: it also rejects NaN.
#![allow(clippy::neg_cmp_op_on_partial_ord)]

use super::lstsq::lstsq_qr;
use super::rtf::{Circles, PassNoPass};
use glam::DVec2;

/// Minimum-area enclosing ellipse (Khachiyan). Returns (centre, A) with
/// (p−c)ᵀA(p−c) ≤ 1 for every point (scaled to guarantee containment).
pub fn min_area_ellipse(points: &[DVec2], tol: f64) -> Option<(DVec2, [[f64; 2]; 2])> {
    let n = points.len();
    if n < 3 {
        return None;
    }
    let mut u = vec![1.0 / n as f64; n];
    for _ in 0..100_000 {
        // X = Σ u q qᵀ with q = (x, y, 1).
        let mut x = [[0.0; 3]; 3];
        for (p, &w) in points.iter().zip(&u) {
            let q = [p.x, p.y, 1.0];
            for a in 0..3 {
                for b in 0..3 {
                    x[a][b] += w * q[a] * q[b];
                }
            }
        }
        let xi = inv3(&x)?;
        let (mut jmax, mut mmax) = (0, f64::NEG_INFINITY);
        for (j, p) in points.iter().enumerate() {
            let q = [p.x, p.y, 1.0];
            let mut m = 0.0;
            for a in 0..3 {
                for b in 0..3 {
                    m += q[a] * xi[a][b] * q[b];
                }
            }
            if m > mmax {
                mmax = m;
                jmax = j;
            }
        }
        let step = (mmax - 3.0) / (3.0 * (mmax - 1.0));
        for w in u.iter_mut() {
            *w *= 1.0 - step;
        }
        u[jmax] += step;
        if step < tol {
            break;
        }
    }
    let c = points
        .iter()
        .zip(&u)
        .fold(DVec2::ZERO, |a, (p, &w)| a + *p * w);
    let mut s = [[0.0; 2]; 2];
    for (p, &w) in points.iter().zip(&u) {
        let d = *p - c;
        s[0][0] += w * d.x * d.x;
        s[0][1] += w * d.x * d.y;
        s[1][1] += w * d.y * d.y;
    }
    s[1][0] = s[0][1];
    let det = s[0][0] * s[1][1] - s[0][1] * s[1][0];
    if !(det > 0.0) {
        return None;
    }
    // A = (1/d)·S⁻¹ with d = 2.
    let mut a = [
        [s[1][1] / det / 2.0, -s[0][1] / det / 2.0],
        [-s[1][0] / det / 2.0, s[0][0] / det / 2.0],
    ];
    let q = |p: &DVec2| {
        let d = *p - c;
        a[0][0] * d.x * d.x + 2.0 * a[0][1] * d.x * d.y + a[1][1] * d.y * d.y
    };
    let worst = points.iter().map(q).fold(0.0, f64::max);
    if worst > 1.0 {
        for row in a.iter_mut() {
            for v in row.iter_mut() {
                *v /= worst;
            }
        }
    }
    Some((c, a))
}

fn inv3(m: &[[f64; 3]; 3]) -> Option<[[f64; 3]; 3]> {
    let c =
        |r0: usize, r1: usize, c0: usize, c1: usize| m[r0][c0] * m[r1][c1] - m[r0][c1] * m[r1][c0];
    let cof = [
        [c(1, 2, 1, 2), -c(1, 2, 0, 2), c(1, 2, 0, 1)],
        [-c(0, 2, 1, 2), c(0, 2, 0, 2), -c(0, 2, 0, 1)],
        [c(0, 1, 1, 2), -c(0, 1, 0, 2), c(0, 1, 0, 1)],
    ];
    let det = m[0][0] * cof[0][0] + m[0][1] * cof[0][1] + m[0][2] * cof[0][2];
    if !(det.abs() > 1e-300) {
        return None;
    }
    let mut inv = [[0.0; 3]; 3];
    for i in 0..3 {
        for j in 0..3 {
            inv[i][j] = cof[j][i] / det;
        }
    }
    Some(inv)
}

/// Axis-aligned ellipse with the region's radial (y) extent and its area:
/// cy, ry from the extreme y of the boundary, rx = area/(π·ry), cx = 0. The
/// boundary points come in angular order around an interior point as pairs
/// (p, mirrored p); the even ones form a star-shaped polygon (shoelace area).
pub fn area_matched_ellipse(pts: &[DVec2]) -> Option<(DVec2, [f64; 2])> {
    let poly: Vec<DVec2> = pts.iter().step_by(2).copied().collect();
    let n = poly.len();
    if n < 3 {
        return None;
    }
    let area = 0.5
        * (0..n)
            .map(|i| poly[i].perp_dot(poly[(i + 1) % n]))
            .sum::<f64>()
            .abs();
    let ymin = pts.iter().map(|p| p.y).fold(f64::INFINITY, f64::min);
    let ymax = pts.iter().map(|p| p.y).fold(f64::NEG_INFINITY, f64::max);
    let ry = 0.5 * (ymax - ymin);
    if !(ry > 0.0 && area > 0.0) {
        return None;
    }
    Some((
        DVec2::new(0.0, 0.5 * (ymin + ymax)),
        [area / (std::f64::consts::PI * ry), ry],
    ))
}

/// Fit one circle per blocking surface to boundary points (r, p, surface):
/// x² + (y − s·r)² = R², linear least squares for a start, then Gauss–Newton
/// on the geometric distance. Surfaces with fewer than 8 points are skipped.
pub fn vignetting_circles(
    pts: &[(f64, DVec2, usize)],
    plane_distance_mm: f64,
    max_input_radius_mm: f64,
) -> Option<PassNoPass> {
    let mut surfaces: Vec<usize> = pts.iter().map(|p| p.2).collect();
    surfaces.sort_unstable();
    surfaces.dedup();
    let (mut radii, mut sens) = (Vec::new(), Vec::new());
    for s in surfaces {
        let g: Vec<(f64, DVec2)> = pts
            .iter()
            .filter(|p| p.2 == s)
            .map(|p| (p.0, p.1))
            .collect();
        if g.len() < 8 {
            continue;
        }
        // x² + y² = A + B·(r·y) + C·r²  with A = R², B = 2s, C = −s².
        let cols = vec![
            g.iter().map(|_| 1.0).collect::<Vec<_>>(),
            g.iter().map(|(r, p)| r * p.y).collect(),
            g.iter().map(|(r, _)| r * r).collect(),
        ];
        let rhs = vec![
            g.iter()
                .map(|(_, p)| p.length_squared())
                .collect::<Vec<_>>(),
        ];
        let sol = lstsq_qr(cols, rhs).ok()?;
        let (mut rr, mut ss) = (sol.x[0][0].max(1e-12).sqrt(), 0.5 * sol.x[0][1]);
        for _ in 0..30 {
            let (mut a, mut b, mut c, mut g0, mut g1) = (0.0, 0.0, 0.0, 0.0, 0.0);
            for (r, p) in &g {
                let dy = p.y - ss * r;
                let rho = (p.x * p.x + dy * dy).sqrt().max(1e-12);
                let e = rho - rr;
                let (j0, j1) = (-1.0, -dy * r / rho);
                a += j0 * j0;
                b += j0 * j1;
                c += j1 * j1;
                g0 += j0 * e;
                g1 += j1 * e;
            }
            let det = a * c - b * b;
            if !(det.abs() > 1e-300) {
                // s undetermined (all points at r = 0): fit R only.
                rr -= g0 / a;
                continue;
            }
            rr -= (c * g0 - b * g1) / det;
            ss -= (a * g1 - b * g0) / det;
        }
        if !(rr > 0.0 && rr.is_finite() && ss.is_finite()) {
            return None;
        }
        radii.push(rr);
        sens.push(ss);
    }
    (!radii.is_empty()).then_some(PassNoPass::Circles(Circles {
        radii_mm: radii,
        sensitivities: sens,
        plane_distance_mm,
        max_input_radius_mm: Some(max_input_radius_mm),
    }))
}

#[cfg(test)]
mod tests {
    use super::*;

    /// Khachiyan: points on a known ellipse give that ellipse back.
    #[test]
    fn min_area_ellipse_recovers_ellipse() {
        let pts: Vec<DVec2> = (0..64)
            .map(|k| {
                let t = std::f64::consts::TAU * k as f64 / 64.0;
                DVec2::new(0.3 + 2.0 * t.cos(), -1.0 + 0.5 * t.sin())
            })
            .collect();
        let (c, a) = min_area_ellipse(&pts, 1e-9).unwrap();
        assert!((c - DVec2::new(0.3, -1.0)).length() < 1e-4);
        assert!(
            (1.0 / a[0][0].sqrt() - 2.0).abs() < 1e-3 && (1.0 / a[1][1].sqrt() - 0.5).abs() < 1e-3
        );
        assert!(a[0][1].abs() < 1e-4);
    }

    /// Vignetting circles: boundary points of an intersection of two known
    /// circles (radius R, centre (0, s·r)) over several input radii give
    /// those circles back.
    #[test]
    fn vignetting_circles_recover_known_circles() {
        let truth = [(0usize, 2.0, 0.0), (3usize, 2.5, 0.3)];
        let mut pts = Vec::new();
        for k in 0..6 {
            let r = 1.5 * k as f64;
            for a in 0..64 {
                let th = std::f64::consts::TAU * (a as f64 + 0.5) / 64.0;
                for &(surf, rad, s) in &truth {
                    let p = DVec2::new(rad * th.cos(), s * r + rad * th.sin());
                    // Keep the part of each circle inside the other one.
                    let inside = truth.iter().all(|&(_, r2, s2)| {
                        p.x * p.x + (p.y - s2 * r).powi(2) <= r2 * r2 * (1.0 + 1e-12)
                    });
                    if inside {
                        pts.push((r, p, surf));
                    }
                }
            }
        }
        let Some(PassNoPass::Circles(c)) = vignetting_circles(&pts, 10.0, 7.5) else {
            panic!("no circles");
        };
        assert_eq!(c.radii_mm.len(), 2);
        for (k, &(_, rad, s)) in truth.iter().enumerate() {
            assert!((c.radii_mm[k] - rad).abs() < 1e-9, "{:?}", c);
            assert!((c.sensitivities[k] - s).abs() < 1e-9, "{:?}", c);
        }
        assert_eq!(c.max_input_radius_mm, Some(7.5));
    }
}
