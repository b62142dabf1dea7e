//! Small statistics helpers shared by the measurements: mean, sample standard
//! deviation, median, least squares by Householder QR (well conditioned for the
//! centred, scaled polynomial bases used here) and the jackknife.

/// Arithmetic mean (NaN for an empty slice).
pub fn mean(v: &[f64]) -> f64 {
    v.iter().sum::<f64>() / v.len() as f64
}

/// Sample standard deviation (n − 1); 0 for fewer than two values.
pub fn std_dev(v: &[f64]) -> f64 {
    if v.len() < 2 {
        return 0.0;
    }
    let m = mean(v);
    (v.iter().map(|x| (x - m) * (x - m)).sum::<f64>() / (v.len() - 1) as f64).sqrt()
}

/// Median (NaN for an empty slice); values must be finite.
pub fn median(v: &[f64]) -> f64 {
    if v.is_empty() {
        return f64::NAN;
    }
    let mut s = v.to_vec();
    s.sort_by(|a, b| a.total_cmp(b));
    let n = s.len();
    if n % 2 == 1 {
        s[n / 2]
    } else {
        0.5 * (s[n / 2 - 1] + s[n / 2])
    }
}

/// Least-squares solution of `a·x ≈ b` (`a` row-major, `rows`×`cols`) by
/// Householder QR. Returns None when the system is rank deficient.
pub fn least_squares(a: &[f64], rows: usize, cols: usize, b: &[f64]) -> Option<Vec<f64>> {
    if rows < cols || a.len() != rows * cols || b.len() != rows {
        return None;
    }
    let mut m = a.to_vec();
    let mut y = b.to_vec();
    let scale: f64 = m.iter().fold(0.0, |s, v| s.max(v.abs()));
    for k in 0..cols {
        let norm: f64 = (k..rows)
            .map(|i| m[i * cols + k].powi(2))
            .sum::<f64>()
            .sqrt();
        if norm <= 1e-12 * scale.max(1e-300) {
            return None;
        }
        let alpha = if m[k * cols + k] > 0.0 { -norm } else { norm };
        let mut v: Vec<f64> = (k..rows).map(|i| m[i * cols + k]).collect();
        v[0] -= alpha;
        let vn: f64 = v.iter().map(|x| x * x).sum();
        if vn == 0.0 {
            continue;
        }
        for j in k..cols {
            let d: f64 = (k..rows).map(|i| v[i - k] * m[i * cols + j]).sum::<f64>() * 2.0 / vn;
            for i in k..rows {
                m[i * cols + j] -= d * v[i - k];
            }
        }
        let d: f64 = (k..rows).map(|i| v[i - k] * y[i]).sum::<f64>() * 2.0 / vn;
        for i in k..rows {
            y[i] -= d * v[i - k];
        }
    }
    let mut x = vec![0.0; cols];
    for k in (0..cols).rev() {
        let s: f64 = ((k + 1)..cols).map(|j| m[k * cols + j] * x[j]).sum();
        x[k] = (y[k] - s) / m[k * cols + k];
    }
    x.iter().all(|v| v.is_finite()).then_some(x)
}

/// Jackknife standard error from leave-one-group-out estimates:
/// sqrt((g − 1)/g · Σ (θᵢ − θ̄)²).
pub fn jackknife_se(estimates: &[f64]) -> f64 {
    let g = estimates.len() as f64;
    if g < 2.0 {
        return 0.0;
    }
    let m = mean(estimates);
    ((g - 1.0) / g * estimates.iter().map(|e| (e - m) * (e - m)).sum::<f64>()).sqrt()
}

#[cfg(test)]
mod tests {
    use super::*;
    #[test]
    fn basics_and_qr_fit() {
        assert_eq!(median(&[3.0, 1.0, 2.0]), 2.0);
        assert_eq!(median(&[4.0, 1.0, 2.0, 3.0]), 2.5);
        assert!((std_dev(&[1.0, 2.0, 3.0, 4.0]) - 1.2909944487358056).abs() < 1e-12);
        // y = 2 + 3x − x² exactly
        let xs: Vec<f64> = (0..6).map(|i| i as f64 - 2.5).collect();
        let a: Vec<f64> = xs.iter().flat_map(|&x| [1.0, x, x * x]).collect();
        let b: Vec<f64> = xs.iter().map(|&x| 2.0 + 3.0 * x - x * x).collect();
        let c = least_squares(&a, 6, 3, &b).unwrap();
        assert!(
            (c[0] - 2.0).abs() < 1e-12 && (c[1] - 3.0).abs() < 1e-12 && (c[2] + 1.0).abs() < 1e-12
        );
        assert!(least_squares(&[1.0, 1.0, 1.0, 1.0], 2, 2, &[1.0, 2.0]).is_none());
    }
}

/// SplitMix64: a small deterministic generator for sampling regions and
/// hold-out sets (seeded per measurement, so results are reproducible).
#[derive(Clone, Debug)]
pub struct SplitMix64(pub u64);

impl SplitMix64 {
    pub fn next_u64(&mut self) -> u64 {
        self.0 = self.0.wrapping_add(0x9E3779B97F4A7C15);
        let mut z = self.0;
        z = (z ^ (z >> 30)).wrapping_mul(0xBF58476D1CE4E5B9);
        z = (z ^ (z >> 27)).wrapping_mul(0x94D049BB133111EB);
        z ^ (z >> 31)
    }
    /// Uniform in [0, 1).
    pub fn next_f64(&mut self) -> f64 {
        (self.next_u64() >> 11) as f64 / (1u64 << 53) as f64
    }
    /// Uniform integer in [0, n).
    pub fn below(&mut self, n: u64) -> u64 {
        ((self.next_u64() as u128 * n as u128) >> 64) as u64
    }
    /// Standard normal (Box–Muller).
    pub fn gauss(&mut self) -> f64 {
        let u = self.next_f64().max(1e-300);
        (-2.0 * u.ln()).sqrt() * (2.0 * std::f64::consts::PI * self.next_f64()).cos()
    }
}

/// Ordinary least-squares line y = a + b·x with standard errors of a and b.
pub fn line_fit(x: &[f64], y: &[f64]) -> Option<(f64, f64, f64, f64)> {
    let n = x.len();
    if n < 3 || y.len() != n {
        return None;
    }
    let (mx, my) = (mean(x), mean(y));
    let sxx: f64 = x.iter().map(|v| (v - mx).powi(2)).sum();
    if sxx <= 0.0 {
        return None;
    }
    let b = x
        .iter()
        .zip(y)
        .map(|(a, c)| (a - mx) * (c - my))
        .sum::<f64>()
        / sxx;
    let a = my - b * mx;
    let s2 = x
        .iter()
        .zip(y)
        .map(|(xi, yi)| (yi - a - b * xi).powi(2))
        .sum::<f64>()
        / (n - 2) as f64;
    let se_b = (s2 / sxx).sqrt();
    let se_a = (s2 * (1.0 / n as f64 + mx * mx / sxx)).sqrt();
    Some((a, b, se_a, se_b))
}
