//! Linear least squares by Householder QR with column pivoting, for several
//! right-hand sides at once, with an estimate of the 2-norm condition number
//! of the kept columns (power iteration on R and on R⁻¹). Columns whose pivot
//! falls below 1e-13 of the first are dropped (coefficient 0) and counted in
//! [`LstsqSolution::rank`]. Used by the RTF fit (`optics::fit`).

// `!(x > 0.0)` is used on purpose: it also rejects NaN.
#![allow(clippy::neg_cmp_op_on_partial_ord)]

use crate::{Error, Result};
use rayon::prelude::*;

/// Least-squares solution of A x ≈ b_k for several right-hand sides.
pub struct LstsqSolution {
    pub x: Vec<Vec<f64>>,
    pub rank: usize,
    pub condition_number: f64,
}

/// Householder QR with column pivoting. `cols` is column-major (`cols[j][i]`),
/// m rows; each `rhs[k]` has m entries.
pub fn lstsq_qr(mut cols: Vec<Vec<f64>>, mut rhs: Vec<Vec<f64>>) -> Result<LstsqSolution> {
    let n = cols.len();
    let m = cols.first().map_or(0, |c| c.len());
    if m < n || n == 0 {
        return Err(Error::Invalid(format!(
            "least squares: {m} samples for {n} unknowns"
        )));
    }
    if cols
        .iter()
        .flatten()
        .chain(rhs.iter().flatten())
        .any(|v| !v.is_finite())
    {
        return Err(Error::Invalid("least squares: non-finite input".into()));
    }
    let mut perm: Vec<usize> = (0..n).collect();
    let mut rank = n;
    let mut r00 = 0.0;
    for k in 0..n {
        // Pivot on the largest remaining column norm.
        let norms: Vec<f64> = (k..n)
            .map(|j| cols[j][k..].iter().map(|v| v * v).sum::<f64>())
            .collect();
        let (pj, &pn) = norms
            .iter()
            .enumerate()
            .max_by(|a, b| a.1.total_cmp(b.1))
            .unwrap();
        let p = k + pj;
        cols.swap(k, p);
        perm.swap(k, p);
        let norm = pn.sqrt();
        if k == 0 {
            r00 = norm;
        }
        if !(norm > 1e-13 * r00) {
            rank = k;
            break;
        }
        let alpha = if cols[k][k] > 0.0 { -norm } else { norm };
        let mut v: Vec<f64> = cols[k][k..].to_vec();
        v[0] -= alpha;
        let vn2: f64 = v.iter().map(|x| x * x).sum();
        cols[k][k] = alpha;
        for x in cols[k][k + 1..].iter_mut() {
            *x = 0.0;
        }
        if vn2 == 0.0 {
            continue;
        }
        let apply = |c: &mut [f64]| {
            let s: f64 = c.iter().zip(&v).map(|(a, b)| a * b).sum::<f64>() * 2.0 / vn2;
            for (a, b) in c.iter_mut().zip(&v) {
                *a -= s * b;
            }
        };
        let (_, rest) = cols.split_at_mut(k + 1);
        rest.par_iter_mut().for_each(|c| apply(&mut c[k..]));
        for b in rhs.iter_mut() {
            apply(&mut b[k..]);
        }
    }
    let rr = |i: usize, j: usize| cols[j][i];
    let solve_r = |b: &[f64]| -> Vec<f64> {
        let mut x = vec![0.0; rank];
        for i in (0..rank).rev() {
            let s: f64 = (i + 1..rank).map(|j| rr(i, j) * x[j]).sum();
            x[i] = (b[i] - s) / rr(i, i);
        }
        x
    };
    let solve_rt = |b: &[f64]| -> Vec<f64> {
        let mut x = vec![0.0; rank];
        for i in 0..rank {
            let s: f64 = (0..i).map(|j| rr(j, i) * x[j]).sum();
            x[i] = (b[i] - s) / rr(i, i);
        }
        x
    };
    let x = rhs
        .iter()
        .map(|b| {
            let xs = solve_r(&b[..rank]);
            let mut out = vec![0.0; n];
            for (i, v) in xs.into_iter().enumerate() {
                out[perm[i]] = v;
            }
            out
        })
        .collect();
    // Condition number of the kept block: σ_max by power iteration on RᵀR,
    // σ_min by inverse iteration (two triangular solves per step).
    let mul_r = |v: &[f64]| {
        (0..rank)
            .map(|i| (i..rank).map(|j| rr(i, j) * v[j]).sum::<f64>())
            .collect::<Vec<_>>()
    };
    let mul_rt = |v: &[f64]| {
        (0..rank)
            .map(|i| (0..=i).map(|j| rr(j, i) * v[j]).sum::<f64>())
            .collect::<Vec<_>>()
    };
    let unit = |v: Vec<f64>| {
        let n = v.iter().map(|x| x * x).sum::<f64>().sqrt();
        (v.iter().map(|x| x / n).collect::<Vec<_>>(), n)
    };
    let start: Vec<f64> = (0..rank).map(|i| 1.0 + 0.1 * (i as f64).sin()).collect();
    let (mut v, _) = unit(start.clone());
    let mut smax2 = 0.0;
    for _ in 0..60 {
        let (w, n) = unit(mul_rt(&mul_r(&v)));
        v = w;
        smax2 = n;
    }
    let (mut v, _) = unit(start);
    let mut inv2 = 0.0;
    for _ in 0..60 {
        let (w, n) = unit(solve_r(&solve_rt(&v)));
        v = w;
        inv2 = n;
    }
    let cond = (smax2 * inv2).sqrt();
    Ok(LstsqSolution {
        x,
        rank,
        condition_number: if cond.is_finite() { cond } else { f64::MAX },
    })
}

#[cfg(test)]
mod tests {
    use super::*;

    /// QR least squares recovers an exact polynomial and a known condition number.
    #[test]
    fn qr_recovers_known_solution_and_condition() {
        // Columns: diag-like scaled basis with known singular values 1 and 1e-3.
        let m = 50;
        let c0: Vec<f64> = (0..m).map(|i| if i == 0 { 1.0 } else { 0.0 }).collect();
        let c1: Vec<f64> = (0..m).map(|i| if i == 1 { 1e-3 } else { 0.0 }).collect();
        let b: Vec<f64> = (0..m)
            .map(|i| {
                if i == 0 {
                    2.0
                } else if i == 1 {
                    3e-3
                } else {
                    0.0
                }
            })
            .collect();
        let s = lstsq_qr(vec![c0, c1], vec![b]).unwrap();
        assert!((s.x[0][0] - 2.0).abs() < 1e-12 && (s.x[0][1] - 3.0).abs() < 1e-9);
        assert!(
            (s.condition_number / 1e3 - 1.0).abs() < 1e-6,
            "{}",
            s.condition_number
        );
        // A cubic fitted through noiseless samples.
        let xs: Vec<f64> = (0..40).map(|i| -1.0 + 2.0 * i as f64 / 39.0).collect();
        let cols: Vec<Vec<f64>> = (0..4)
            .map(|p| xs.iter().map(|x| x.powi(p)).collect())
            .collect();
        let y: Vec<f64> = xs.iter().map(|x| 1.0 - 2.0 * x + 0.5 * x * x * x).collect();
        let s = lstsq_qr(cols, vec![y]).unwrap();
        for (got, want) in s.x[0].iter().zip([1.0, -2.0, 0.0, 0.5]) {
            assert!((got - want).abs() < 1e-12);
        }
    }
}
