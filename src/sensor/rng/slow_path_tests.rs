//! Tests of the samplers' rare paths, each against an independent reference:
//! Hörmann's PTRS constants as the paper states them, the exact normal tail
//! and the ziggurat's wedge acceptance probability in closed form, ln k! from
//! a compensated sum, and streams built to give chosen outputs (SplitMix64's
//! finaliser is a bijection, so a state can be solved for any output).
//! Written for mutants the statistical tests in `tests` cannot see: these
//! paths carry ~1 % of normal draws and 10–25 % of Poisson draws, so a wrong
//! constant there moves a 2·10⁵-draw χ² by less than its noise.

use super::*;

/// The inverse of `mix64` (each step undone in reverse order).
fn unmix64(y: u64) -> u64 {
    fn unxorshift(y: u64, s: u32) -> u64 {
        let mut x = y;
        for _ in 0..(64 / s + 1) {
            x = y ^ (x >> s);
        }
        x
    }
    fn inverse(c: u64) -> u64 {
        // Newton's iteration for 1/c mod 2⁶⁴ (c odd): each step doubles the bits.
        let mut x = c;
        for _ in 0..6 {
            x = x.wrapping_mul(2u64.wrapping_sub(c.wrapping_mul(x)));
        }
        x
    }
    let z = unxorshift(y, 31);
    let z = z.wrapping_mul(inverse(0x94d0_49bb_1331_11eb));
    let z = unxorshift(z, 27);
    let z = z.wrapping_mul(inverse(0xbf58_476d_1ce4_e5b9));
    unxorshift(z, 30)
}

/// A stream whose next output is `out`.
fn stream_giving(out: u64) -> PixelRng {
    PixelRng {
        state: unmix64(out).wrapping_sub(GAMMA),
    }
}

#[test]
fn streams_can_be_built_to_give_an_output() {
    for out in [0u64, 1, u64::MAX, 0x1234_5678_9abc_def0] {
        assert_eq!(stream_giving(out).next_u64(), out);
    }
}

/// PTRS's constants at mean μ as Hörmann (1993) states them, written here
/// from the paper, not from `ptrs_constants`.
struct Hoermann {
    /// b = 0.931 + 2.53·√μ
    b: f64,
    /// a = −0.059 + 0.02483·b
    a: f64,
    /// α⁻¹ = 1.1239 + 1.1328/(b − 3.4)
    inv_alpha: f64,
    /// v_r = 0.9277 − 3.6224/(b − 2)
    v_r: f64,
}

impl Hoermann {
    fn at(mu: f64) -> Self {
        let b = 0.931 + 2.53 * mu.sqrt();
        Hoermann {
            b,
            a: -0.059 + 0.02483 * b,
            inv_alpha: 1.1239 + 1.1328 / (b - 3.4),
            v_r: 0.9277 - 3.6224 / (b - 2.0),
        }
    }
}

/// The code's PTRS constants are the paper's: it returns (a, b, b − 2,
/// v_r·(b − 2)). Tolerance: a few f64 roundings.
#[test]
fn ptrs_constants_are_hoermanns() {
    for mu in [10.0f64, 25.0, 137.5, 5000.0] {
        let Hoermann { a, b, v_r, .. } = Hoermann::at(mu);
        let (ga, gb, gbm2, gv) = ptrs_constants(mu);
        let close = |x: f64, y: f64| (x - y).abs() <= 1e-14 * y.abs().max(1.0);
        assert!(close(ga, a) && close(gb, b), "μ {mu}");
        assert!(close(gbm2, b - 2.0), "μ {mu}: {gbm2}");
        assert!(close(gv / gbm2, v_r), "μ {mu}: {}", gv / gbm2);
    }
}

/// `uniform_open0` is in (0, 1]: output 0 gives 2⁻⁵³, the largest output 1.
#[test]
fn uniform_open0_excludes_zero_and_reaches_one() {
    assert_eq!(stream_giving(0).uniform_open0(), 1.0 / (1u64 << 53) as f64);
    assert_eq!(stream_giving(u64::MAX).uniform_open0(), 1.0);
    assert_eq!(stream_giving(0).uniform(), 0.0);
}

/// The standard normal density.
fn phi(t: f64) -> f64 {
    (-0.5 * t * t).exp() / (2.0 * std::f64::consts::PI).sqrt()
}

/// ∫ₓ^∞ φ by Simpson's rule on [x, x + 14] (the rest < 10⁻⁴⁴), 2·10⁴
/// intervals: error ≲ 10⁻¹⁵ relative for the x used here.
fn upper_tail(x: f64) -> f64 {
    let n = 20_000;
    let h = 14.0 / n as f64;
    let mut s = phi(x) + phi(x + 14.0);
    for j in 1..n {
        s += phi(x + j as f64 * h) * if j % 2 == 1 { 4.0 } else { 2.0 };
    }
    s * h / 3.0
}

/// χ² of `samples` against bin probabilities `p` (edges `edges`, last bin
/// open), and the 5-σ bound for its degrees of freedom.
fn chi2(samples: &[f64], edges: &[f64], p: &[f64]) -> (f64, f64) {
    let mut counts = vec![0.0f64; p.len()];
    for &s in samples {
        let k = edges
            .iter()
            .rposition(|&e| s >= e)
            .expect("below the first edge");
        counts[k] += 1.0;
    }
    let n = samples.len() as f64;
    let c: f64 = counts
        .iter()
        .zip(p)
        .map(|(&o, &q)| (o - n * q).powi(2) / (n * q))
        .sum();
    let dof = (p.len() - 1) as f64;
    (c, dof + 5.0 * (2.0 * dof).sqrt())
}

/// The ziggurat's tail (layer 0 outside the base rectangle): Marsaglia's
/// method must give R + a with the exact conditional law P(X > x | X > R) =
/// Q(x)/Q(R), and the sign of u. 2·10⁵ draws, χ² over 9 bins (5 σ).
#[test]
fn normal_tail_is_the_exact_conditional_tail() {
    let z = ziggurat();
    let r = ZIG_R;
    let q_r = upper_tail(r);
    let edges: Vec<f64> = [0.0, 0.03, 0.07, 0.12, 0.18, 0.26, 0.37, 0.55, 0.85]
        .iter()
        .map(|d| r + d)
        .collect();
    let surv: Vec<f64> = edges.iter().map(|&e| upper_tail(e) / q_r).collect();
    let p: Vec<f64> = (0..edges.len())
        .map(|k| surv[k] - surv.get(k + 1).copied().unwrap_or(0.0))
        .collect();
    let mut samples = Vec::with_capacity(200_000);
    for i in 0..200_000u64 {
        let mut g = PixelRng::new(5, stream::READ, i);
        let (u, sign) = if i % 2 == 0 { (0.5, 1.0) } else { (-0.5, -1.0) };
        let x = g.normal_slow(z, 0, u, u * z.x[0]);
        assert!(x * sign >= r, "{x} for u = {u}");
        samples.push(x.abs());
    }
    let (c, bound) = chi2(&samples, &edges, &p);
    assert!(c < bound, "tail χ² {c} (bound {bound})");
}

/// A point x in the wedge of layer i (x[i+1] < x < x[i]) is kept with
/// probability (f(x) − f[i]) / (f[i+1] − f[i]) (the uniform height under the
/// curve), else the draw starts again (and practically never returns x).
/// 2·10⁴ streams per point; tolerance 5 binomial σ.
#[test]
fn normal_wedges_accept_with_the_exact_probability() {
    let z = ziggurat();
    let f = |x: f64| (-0.5 * x * x).exp();
    for i in [1usize, 40, 128, 200, 254] {
        for t in [0.25, 0.5, 0.75] {
            let x = z.x[i + 1] + t * (z.x[i] - z.x[i + 1]);
            let u = x / z.x[i];
            let xx = u * z.x[i];
            let p = (f(xx) - z.f[i]) / (z.f[i + 1] - z.f[i]);
            let n = 20_000u64;
            let kept = (0..n)
                .filter(|&s| {
                    let mut g = PixelRng::new(11, i as u64, s);
                    g.normal_slow(z, i, u, xx) == xx
                })
                .count() as f64;
            let sd = (p * (1.0 - p) / n as f64).sqrt();
            assert!(
                (kept / n as f64 - p).abs() < 5.0 * sd + 1e-4,
                "layer {i}, x {xx}: kept {} vs {p}",
                kept / n as f64
            );
        }
    }
}

/// Φ on a grid (step 10⁻³ over [−8, 8]) by cumulative Simpson steps, and
/// linear interpolation: error < 10⁻⁷.
struct NormalCdf(Vec<f64>);

impl NormalCdf {
    const H: f64 = 1e-3;
    fn new() -> Self {
        let n = (16.0 / Self::H) as usize;
        let mut c = vec![0.0; n + 1];
        for j in 0..n {
            let a = -8.0 + j as f64 * Self::H;
            c[j + 1] =
                c[j] + Self::H / 6.0 * (phi(a) + 4.0 * phi(a + Self::H / 2.0) + phi(a + Self::H));
        }
        NormalCdf(c)
    }
    fn at(&self, x: f64) -> f64 {
        let s = ((x + 8.0) / Self::H).clamp(0.0, (self.0.len() - 2) as f64);
        let j = s as usize;
        self.0[j] + (s - j as f64) * (self.0[j + 1] - self.0[j])
    }
}

/// After a wedge rejection the draw starts again from a fresh output: what it
/// returns then is a standard normal. A point at the wedge's outer edge is
/// almost always rejected, so 10⁶ calls give ≈ 10⁶ fresh draws, compared
/// with Φ by Kolmogorov–Smirnov (bound 1.95/√n: p ≈ 10⁻³ of a false alarm)
/// and by the counts beyond the tail's start R and beyond the base layer's
/// width x[0] > R (Poisson, 5 σ): only the tail sampler reaches past x[0], so
/// a fresh draw that skipped the layer test would never get there (92
/// expected).
#[test]
fn normal_after_a_wedge_rejection_is_a_fresh_normal() {
    let z = ziggurat();
    let cdf = NormalCdf::new();
    let i = 100;
    let u = 1.0 - 1e-12;
    let xx = u * z.x[i];
    let mut v: Vec<f64> = (0..1_000_000u64)
        .map(|s| PixelRng::new(13, 7, s).normal_slow(z, i, u, xx))
        .filter(|&x| x != xx)
        .collect();
    let n = v.len() as f64;
    assert!(n > 999_000.0, "{n}");
    v.sort_by(f64::total_cmp);
    let d = v
        .iter()
        .enumerate()
        .map(|(j, &x)| {
            let c = cdf.at(x);
            (c - j as f64 / n).abs().max(((j + 1) as f64 / n - c).abs())
        })
        .fold(0.0, f64::max);
    assert!(d < 1.95 / n.sqrt(), "KS D {d} (bound {})", 1.95 / n.sqrt());
    for edge in [ZIG_R, z.x[0]] {
        let beyond = v.iter().filter(|x| x.abs() > edge).count() as f64;
        let want = n * 2.0 * upper_tail(edge);
        assert!(
            (beyond - want).abs() < 5.0 * want.sqrt() + 1.0,
            "beyond {edge}: {beyond} vs {want}"
        );
    }
}

/// ln k! across the table edge (256) against a compensated (Kahan) sum of
/// ln i: each ln i is within 1 ulp (≤ 8.9·10⁻¹⁶ for i < 1000), so the sum is
/// within k·8.9·10⁻¹⁶ ≤ 6.2·10⁻¹³ for k ≤ 700, plus half an ulp of the
/// result (≤ 2.3·10⁻¹³); the tolerance is 2·10⁻¹² absolute. The Stirling
/// series' second term, inv³/360, is 1.6·10⁻¹⁰ at k = 256 and 1.3·10⁻¹¹ at
/// k = 600: a wrong coefficient there shows; the third term (7·10⁻¹⁶ at k =
/// 256) is below the result's ulp and cannot.
#[test]
fn ln_factorial_matches_a_compensated_sum() {
    let (mut s, mut comp) = (0.0f64, 0.0f64);
    for i in 1..=700u32 {
        let y = (i as f64).ln() - comp;
        let t = s + y;
        comp = (t - s) - y;
        s = t;
        if i >= 200 {
            let r = ln_factorial(i as f64);
            assert!((r - s).abs() <= 2e-12, "{i}: {r} vs {s} ({:e})", r - s);
        }
    }
}

/// Hörmann's full acceptance test, the paper's way, for one proposal
/// (k, u_s, v) at mean μ: accept when ln(v·α⁻¹/(a/u_s² + b)) ≤ −μ + k ln μ −
/// ln k!; reject at once when k < 0 or (u_s < 0.013 and v > u_s).
fn hoermann_accepts(mu: f64, k: f64, us: f64, v: f64) -> bool {
    let Hoermann {
        a, b, inv_alpha, ..
    } = Hoermann::at(mu);
    if k < 0.0 || (us < 0.013 && v > us) {
        return false;
    }
    (v * inv_alpha / (a / (us * us) + b)).ln() <= -mu + k * mu.ln() - ln_factorial(k)
}

/// The fraction of 400 streams on which the slow path returns the proposal k
/// it was given (an accepted proposal returns k every time; a rejected one
/// draws afresh, which gives k again with probability P(k) ≤ 0.13 here).
fn kept_fraction(mu: f64, k: f64, us: f64, v: f64) -> f64 {
    let (a, b, bm2, v_r_num) = ptrs_constants(mu);
    let n = 400;
    (0..n)
        .filter(|&s| {
            let mut g = PixelRng::new(17, stream::PHOTON, s);
            g.poisson_ptrs_slow(mu, a, b, bm2, v_r_num, us, v, k) == k
        })
        .count() as f64
        / n as f64
}

/// PTRS's slow path decides each proposal as the paper does: the immediate
/// rejections (k < 0; u_s < 0.013 with v > u_s), and the full test on both
/// sides of its boundary (v at 0.97 and 1.03 of the largest accepted v).
/// Accepted: kept on every stream; rejected: kept on at most 30 % (a fresh
/// draw equals k with probability ≤ 0.13 at these means, binomial over 400).
#[test]
fn ptrs_slow_path_decides_as_hoermann() {
    let mut cases: Vec<(f64, f64, f64, f64)> = vec![
        // k < 0 (a tiny v passes every other test) and k = 0 (accepted).
        (10.0, -1.0, 0.3, 1e-9),
        (10.0, 0.0, 0.3, 1e-9),
        // u_s < 0.013 with v > u_s: rejected; v < u_s: to the full test.
        (10.0, 10.0, 0.01, 0.02),
        (10.0, 10.0, 0.01, 0.005),
    ];
    // The boundary in v of the full test, for proposals above the mode (near
    // it v would pass 1 and every proposal is accepted).
    for (mu, k, us) in [(10.0, 14.0, 0.3), (37.5, 46.0, 0.2), (1000.0, 1040.0, 0.25)] {
        let Hoermann {
            a, b, inv_alpha, ..
        } = Hoermann::at(mu);
        let rhs = -mu + k * f64::ln(mu) - ln_factorial(k);
        let v_max = rhs.exp() * (a / (us * us) + b) / inv_alpha;
        assert!(
            v_max < 1.0 / 1.03,
            "μ {mu}: boundary v {v_max} not inside (0, 1)"
        );
        cases.push((mu, k, us, 0.97 * v_max));
        cases.push((mu, k, us, 1.03 * v_max));
    }
    for (mu, k, us, v) in cases {
        let accept = hoermann_accepts(mu, k, us, v);
        let kept = kept_fraction(mu, k, us, v);
        if accept {
            assert_eq!(
                kept, 1.0,
                "μ {mu}, k {k}, u_s {us}, v {v}: accepted by the paper"
            );
        } else {
            assert!(
                kept < 0.3,
                "μ {mu}, k {k}, u_s {us}, v {v}: kept {kept}, rejected by the paper"
            );
        }
    }
}

/// After a rejected proposal the slow path draws afresh, so its results over
/// many streams are Poisson(μ): mean within 5 standard errors, variance
/// within 5 of its standard errors (2·10⁴ streams).
#[test]
fn ptrs_after_a_rejection_is_poisson() {
    for mu in [10.0f64, 137.5, 5000.0] {
        let (a, b, bm2, v_r_num) = ptrs_constants(mu);
        let n = 20_000u64;
        let ks: Vec<f64> = (0..n)
            .map(|s| {
                // k < 0: rejected at once, whatever us and v are.
                PixelRng::new(19, stream::PHOTON, s)
                    .poisson_ptrs_slow(mu, a, b, bm2, v_r_num, 0.3, 0.5, -1.0)
            })
            .collect();
        let mean = ks.iter().sum::<f64>() / n as f64;
        let var = ks.iter().map(|k| (k - mean).powi(2)).sum::<f64>() / (n - 1) as f64;
        assert!(
            (mean - mu).abs() < 5.0 * (mu / n as f64).sqrt(),
            "μ {mu}: mean {mean}"
        );
        let se = mu * (2.0 / n as f64 + 1.0 / (mu * n as f64)).sqrt();
        assert!((var - mu).abs() < 5.0 * se, "μ {mu}: var {var}");
    }
}

/// Sequential inversion with the largest uniform (1 − 2⁻⁵³): at means where
/// the pmf's running f64 sum stops below it, only the underflow guard ends
/// the search — at the first k > μ with p < 10⁻³⁰⁰. The test finds such
/// means with the same recurrence and checks the count returned.
#[test]
fn poisson_inversion_guard_ends_the_search() {
    let u_max = uniform_from_bits(u64::MAX);
    let mut found = 0;
    for j in 1..200 {
        let mu = j as f64 * 0.0495;
        // The recurrence of `poisson_inversion`, to see where its sum ends.
        let (mut k, mut p, mut cdf) = (0u32, (-mu).exp(), (-mu).exp());
        let mut guard_k = None;
        while k < 100_000 {
            if u_max < cdf {
                break;
            }
            k += 1;
            p *= mu / k as f64;
            cdf += p;
            if p < 1e-300 && k as f64 > mu {
                guard_k = Some(k);
                break;
            }
        }
        let Some(want) = guard_k else { continue };
        found += 1;
        let got = stream_giving(u64::MAX).poisson_inversion(mu);
        assert_eq!(got, want as f64, "μ {mu}");
        // The guard's k: p fell below 10⁻³⁰⁰ there and not one step before.
        assert!(want as f64 > mu);
    }
    assert!(found > 0, "no mean in the sweep needs the guard");
}
