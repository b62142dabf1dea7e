//! Non-negative least squares (Lawson & Hanson 1974, algorithm NNLS) and the
//! paper's QE correction matrix (Eq. 2–3): measured RGB ≈ predicted RGB · M, M ≥ 0,
//! solved per output channel (column of M).
//!
//! The unconstrained subproblems use Householder QR with column pivoting and a
//! rank cut, returning the basic solution (dependent columns get 0), so collinear
//! or all-zero columns give a finite answer, never NaN.

/// Result of an NNLS solve.
#[derive(Clone, Debug, PartialEq)]
pub struct NnlsSolution {
    pub x: Vec<f64>,
    /// ‖A·x − b‖₂.
    pub residual_norm: f64,
    pub iterations: usize,
}

/// Least squares min ‖A x − b‖ for A given as columns (each of length m), by
/// Householder QR with column pivoting; columns whose pivot falls below
/// `1e-12 × largest pivot` are treated as dependent and get x = 0.
pub fn lstsq_columns(cols: &[Vec<f64>], b: &[f64]) -> Vec<f64> {
    let k = cols.len();
    let m = b.len();
    let mut a: Vec<Vec<f64>> = cols.to_vec();
    let mut qb = b.to_vec();
    let mut perm: Vec<usize> = (0..k).collect();
    let mut rank = 0;
    let mut first_pivot = 0.0f64;
    for j in 0..k.min(m) {
        // pivot: largest remaining column norm below row j
        let (mut p, mut best) = (j, -1.0f64);
        for (l, col) in a.iter().enumerate().skip(j) {
            let nrm: f64 = col[j..].iter().map(|v| v * v).sum();
            if nrm > best {
                best = nrm;
                p = l;
            }
        }
        a.swap(j, p);
        perm.swap(j, p);
        let norm = best.max(0.0).sqrt();
        if j == 0 {
            first_pivot = norm;
        }
        if norm <= 1e-12 * first_pivot || norm == 0.0 {
            break;
        }
        let x0 = a[j][j];
        let alpha = if x0 >= 0.0 { -norm } else { norm };
        let mut v: Vec<f64> = a[j][j..].to_vec();
        v[0] -= alpha;
        let vv: f64 = v.iter().map(|x| x * x).sum();
        if vv > 0.0 {
            for col in a.iter_mut().skip(j + 1) {
                let d: f64 = v.iter().zip(&col[j..]).map(|(p, q)| p * q).sum();
                let f = 2.0 * d / vv;
                for (c, vi) in col[j..].iter_mut().zip(&v) {
                    *c -= f * vi;
                }
            }
            let d: f64 = v.iter().zip(&qb[j..]).map(|(p, q)| p * q).sum();
            let f = 2.0 * d / vv;
            for (c, vi) in qb[j..].iter_mut().zip(&v) {
                *c -= f * vi;
            }
        }
        a[j][j] = alpha;
        rank = j + 1;
    }
    // back substitution on R[0..rank, 0..rank]; R[i][l] = a[l][i]
    let mut z = vec![0.0; rank];
    for i in (0..rank).rev() {
        let mut s = qb[i];
        for l in i + 1..rank {
            s -= a[l][i] * z[l];
        }
        z[i] = s / a[i][i];
    }
    let mut x = vec![0.0; k];
    for i in 0..rank {
        x[perm[i]] = z[i];
    }
    x
}

/// Solve min ‖A x − b‖₂ subject to x ≥ 0. `a` is row-major m×n.
pub fn nnls(a: &[f64], m: usize, n: usize, b: &[f64]) -> Result<NnlsSolution, String> {
    if a.len() != m * n || b.len() != m {
        return Err(format!(
            "nnls: A has {} values for {m}×{n}, b has {} for {m}",
            a.len(),
            b.len()
        ));
    }
    if a.iter().chain(b).any(|v| !v.is_finite()) {
        return Err("nnls: A and b must be finite".into());
    }
    let col = |j: usize| -> Vec<f64> { (0..m).map(|i| a[i * n + j]).collect() };
    let cols: Vec<Vec<f64>> = (0..n).map(col).collect();
    let residual = |x: &[f64]| -> Vec<f64> {
        (0..m)
            .map(|i| b[i] - (0..n).map(|j| a[i * n + j] * x[j]).sum::<f64>())
            .collect()
    };
    let grad = |r: &[f64]| -> Vec<f64> {
        (0..n)
            .map(|j| (0..m).map(|i| a[i * n + j] * r[i]).sum())
            .collect()
    };
    let anorm = a.iter().fold(0.0f64, |s, v| s.max(v.abs()));
    let tol = 10.0
        * f64::EPSILON
        * anorm
        * (m.max(n) as f64)
        * b.iter().fold(1.0f64, |s, v| s.max(v.abs()));
    let mut x = vec![0.0; n];
    let mut passive = vec![false; n];
    let mut iterations = 0;
    let max_iter = 30 * n.max(1);
    let mut excluded = vec![false; n];
    loop {
        let w = grad(&residual(&x));
        let cand = (0..n)
            .filter(|&j| !passive[j] && !excluded[j] && w[j] > tol)
            .max_by(|&p, &q| w[p].total_cmp(&w[q]));
        let Some(t) = cand else { break };
        if iterations >= max_iter {
            break;
        }
        passive[t] = true;
        let mut first = true;
        loop {
            iterations += 1;
            let idx: Vec<usize> = (0..n).filter(|&j| passive[j]).collect();
            let sub: Vec<Vec<f64>> = idx.iter().map(|&j| cols[j].clone()).collect();
            let zs = lstsq_columns(&sub, b);
            let mut s = vec![0.0; n];
            for (k, &j) in idx.iter().enumerate() {
                s[j] = zs[k];
            }
            if first && s[t] <= 0.0 {
                // The new column adds nothing (dependent on the passive set): exclude it
                // until x changes, which prevents cycling.
                passive[t] = false;
                excluded[t] = true;
                break;
            }
            first = false;
            if idx.iter().all(|&j| s[j] > 0.0) {
                x = s;
                excluded.iter_mut().for_each(|e| *e = false);
                break;
            }
            let mut alpha = f64::INFINITY;
            for &j in &idx {
                if s[j] <= 0.0 {
                    let d = x[j] - s[j];
                    if d > 0.0 {
                        alpha = alpha.min(x[j] / d);
                    } else {
                        alpha = 0.0;
                    }
                }
            }
            if !alpha.is_finite() {
                alpha = 0.0;
            }
            for &j in &idx {
                x[j] += alpha * (s[j] - x[j]);
                if x[j] <= tol.max(1e-300) {
                    x[j] = 0.0;
                    passive[j] = false;
                }
            }
            excluded.iter_mut().for_each(|e| *e = false);
            if iterations >= max_iter || !passive.iter().any(|&p| p) {
                break;
            }
        }
    }
    let r = residual(&x);
    Ok(NnlsSolution {
        residual_norm: r.iter().map(|v| v * v).sum::<f64>().sqrt(),
        x,
        iterations,
    })
}

/// The QE correction matrix of paper Eq. 2–3: `predicted` and `measured` are k×n
/// (rows = patches × illuminants, columns = channels); returns M (n×n, row = predicted
/// channel, column = corrected channel, all ≥ 0) with measured ≈ predicted · M, and the
/// residual norm per output channel.
pub fn qe_correction_matrix(
    predicted: &[Vec<f64>],
    measured: &[Vec<f64>],
) -> Result<(Vec<Vec<f64>>, Vec<f64>), String> {
    let k = predicted.len();
    if k == 0 || measured.len() != k {
        return Err(format!(
            "qe correction: {} predicted rows vs {} measured rows",
            k,
            measured.len()
        ));
    }
    let n = predicted[0].len();
    if n == 0 || predicted.iter().chain(measured).any(|r| r.len() != n) {
        return Err("qe correction: every row needs the same number of channels".into());
    }
    let a: Vec<f64> = predicted.iter().flatten().copied().collect();
    let mut m = vec![vec![0.0; n]; n];
    let mut res = vec![];
    for c in 0..n {
        let b: Vec<f64> = measured.iter().map(|r| r[c]).collect();
        let s = nnls(&a, k, n, &b)?;
        for (r, row) in m.iter_mut().enumerate() {
            row[c] = s.x[r];
        }
        res.push(s.residual_norm);
    }
    Ok((m, res))
}

#[cfg(test)]
mod tests {
    use super::*;

    #[test]
    fn unconstrained_optimum_inside_is_found() {
        // A = I (3×3), b = (1, 2, 3) → x = b
        let a = [1.0, 0.0, 0.0, 0.0, 1.0, 0.0, 0.0, 0.0, 1.0];
        let s = nnls(&a, 3, 3, &[1.0, 2.0, 3.0]).unwrap();
        assert!(
            s.x.iter()
                .zip([1.0, 2.0, 3.0])
                .all(|(a, b)| (a - b).abs() < 1e-12)
        );
    }

    #[test]
    fn active_constraint_matches_hand_solution() {
        // min (x1 − 1)² + (x2 + 1)² with x ≥ 0 → (1, 0), residual 1
        let a = [1.0, 0.0, 0.0, 1.0];
        let s = nnls(&a, 2, 2, &[1.0, -1.0]).unwrap();
        assert!((s.x[0] - 1.0).abs() < 1e-12 && s.x[1] == 0.0);
        assert!((s.residual_norm - 1.0).abs() < 1e-12);
        // KKT check on a random problem: w = Aᵀ(b − Ax) ≤ 0 where x = 0, ≈ 0 where x > 0
        let m = 20;
        let n = 5;
        let mut r = crate::sensor::rng::PixelRng::new(1, 9, 0);
        let a: Vec<f64> = (0..m * n).map(|_| r.normal()).collect();
        let b: Vec<f64> = (0..m).map(|_| r.normal()).collect();
        let s = nnls(&a, m, n, &b).unwrap();
        let res: Vec<f64> = (0..m)
            .map(|i| b[i] - (0..n).map(|j| a[i * n + j] * s.x[j]).sum::<f64>())
            .collect();
        for j in 0..n {
            let w: f64 = (0..m).map(|i| a[i * n + j] * res[i]).sum();
            assert!(s.x[j] >= 0.0);
            if s.x[j] > 0.0 {
                assert!(w.abs() < 1e-9, "{j}: {w}");
            } else {
                assert!(w <= 1e-9, "{j}: {w}");
            }
        }
    }

    #[test]
    fn collinear_and_zero_columns_give_finite_answers() {
        // columns: c, c (duplicate), 0, 2c
        let c = [1.0, 2.0, 3.0, 4.0];
        let mut a = vec![];
        for v in c {
            a.extend_from_slice(&[v, v, 0.0, 2.0 * v]);
        }
        let b: Vec<f64> = c.iter().map(|v| 3.0 * v).collect();
        let s = nnls(&a, 4, 4, &b).unwrap();
        assert!(s.x.iter().all(|v| v.is_finite() && *v >= 0.0));
        assert!(s.residual_norm < 1e-9, "{s:?}");
        assert_eq!(s.x[2], 0.0);
        // all-zero A and b
        let s = nnls(&[0.0; 6], 3, 2, &[0.0; 3]).unwrap();
        assert_eq!(s.x, vec![0.0, 0.0]);
        let s = nnls(&[0.0; 6], 3, 2, &[1.0, 2.0, 3.0]).unwrap();
        assert_eq!(s.x, vec![0.0, 0.0]);
        assert!(nnls(&[f64::NAN; 4], 2, 2, &[1.0, 1.0]).is_err());
    }
}
