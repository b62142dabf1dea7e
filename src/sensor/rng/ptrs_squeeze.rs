//! PTRS's rejected first proposals finished without libm (issue 17 item 5).
//!
//! About a fifth of the Poisson draws at μ ≥ 10 fail PTRS's fast acceptance
//! (22 % at μ = 6000), and the full acceptance test of
//! [`PixelRng::poisson`](super::PixelRng::poisson) then takes three libm
//! logarithms per draw (ln μ, the proposal's log-density, and ln n in the
//! Stirling series of ln k!) behind a branch on random data: a quarter of the
//! sensor stage's time in `camsim bench sensor`.
//!
//! [`ptrs_after_first`] takes those draws without a libm call: it evaluates the
//! same test with [`ln_near`], a branch-free logarithm within 10⁻¹⁵·max(1, |ln x|)
//! of libm's (tested below over every binade of the normal range), and decides
//! only when the two sides differ by more than a margin δ that bounds, with a
//! factor of at least ten to spare, what the two logarithms and the roundings
//! of the expressions built on them can move either side. A decided draw is
//! therefore the one [`PixelRng::poisson`](super::PixelRng::poisson) returns,
//! bit for bit: the squeeze changes no value, only which code computes it.
//! When the first proposal is rejected it also takes the second proposal if
//! that passes the fast test; where the second fails it, a second round does
//! the same with the second proposal's full test and the third's fast test.
//! Everything else (a margin within δ, a fourth proposal, a proposal beyond
//! ±2⁵², a log-density of 0) is left to the exact path: 1.3 % of the draws that
//! failed the fast test at μ = 6000, 6 % at μ = 10 (11 % and 25 % with the
//! first round alone).
//!
//! The readout's first pass keeps what its first proposals were drawn from
//! ([`Proposal`]: the stream's start, PTRS's b, the proposal), and
//! [`ptrs_after_rejected_all`] goes on from there for the pixels it gathers
//! instead of drawing their first proposals again (with `ln_near`'s shorter
//! series the photon pass 0.93 of its time on the AVX2 EPYC,
//! docs/performance.md, *Thirtieth pass*).

use super::{
    Rounding, TWO52, ln_gamma_stirling, output_at, ptrs_constants, ptrs_constants_from_b,
    stream_start, uniform_from_bits,
};

/// ln x for positive normal finite x, within 10⁻¹⁵·max(1, |ln x|) of libm's
/// (`ln_near_tracks_libm_over_every_binade`); NaN for any other x. Branch-free
/// (x = 2ᵉ·m with m in [√½, √2), ln m = 2·atanh(s), s = (m − 1)/(m + 1),
/// |s| ≤ 0.1716, by its odd series to s²³), so a loop of these vectorises.
#[inline(always)]
pub fn ln_near(x: f64) -> f64 {
    let bits = x.to_bits();
    let valid = (f64::MIN_POSITIVE..f64::INFINITY).contains(&x);
    let m1 = f64::from_bits((bits & 0x000f_ffff_ffff_ffff) | 0x3ff0_0000_0000_0000);
    let big = m1 > std::f64::consts::SQRT_2;
    let m = if big { 0.5 * m1 } else { m1 };
    // i32, not i64: the conversion below then vectorises (`vcvtdq2pd`); from
    // i64 the compiler converted lane by lane in scalar code before AVX-512.
    let e = ((bits >> 52) & 0x7ff) as i32 - 1023 + i32::from(big);
    let f = m - 1.0;
    let s = f / (2.0 + f);
    let z = s * s;
    // 2·atanh(s) = 2s·Σ z^j/(2j+1); z ≤ 0.0295, so the terms from z¹⁰/21 ≤ 2.4·10⁻¹⁷
    // on are left off. Estrin's scheme: pairs, then pairs of pairs, so the
    // dependent chain is four multiply-adds deep instead of Horner's nine.
    let c = |j: i32| 1.0 / (2 * j + 1) as f64;
    let (z2, z4) = (z * z, (z * z) * (z * z));
    let z8 = z4 * z4;
    let q = |j: i32| c(j) + c(j + 1) * z;
    let p = ((q(0) + q(2) * z2) + (q(4) + q(6) * z2) * z4) + q(8) * z8;
    let ln_m = 2.0 * s * p;
    let r = f64::from(e) * std::f64::consts::LN_2 + ln_m;
    if valid { r } else { f64::NAN }
}

/// ln k! as [`ln_factorial`](super::ln_factorial) computes it, with [`ln_near`]
/// in place of libm's logarithm in the Stirling series (k ≥ 256); below 256 the
/// same `table` ([`ln_factorial_table`](super::ln_factorial_table)).
#[inline(always)]
fn ln_factorial_near(table: &[f64; 256], k: f64) -> f64 {
    let n = k + 1.0;
    let stirling = ln_gamma_stirling(n, ln_near(n));
    // Both read, one kept: a loop of these has no branch to vectorise around.
    // The entry: k (an integer wherever the result is used) clamped to 0…255
    // is the low byte of k + 2⁵²'s bits; the cast `as u8` gave the same index
    // but converted lane by lane.
    let tabled = table[((k.clamp(0.0, 255.0) + TWO52).to_bits() & 0xff) as usize];
    if k < 256.0 { tabled } else { stirling }
}

/// One PTRS proposal from outputs `n` and `n + 1` of a stream, branch-free (so
/// a loop of these vectorises): what `PixelRng::poisson_ptrs_first` computes
/// from those outputs, its floor exact while `exact`. The readout's first pass
/// ([`Proposal`]) and [`ptrs_after_first`] both take their proposals from
/// here.
#[derive(Clone, Copy)]
struct LaneProposal {
    /// The proposed count, ⌊x⌋.
    k: f64,
    us: f64,
    v: f64,
    /// PTRS's fast acceptance test passed: `k` is the draw.
    fast: bool,
    /// |x| < 2⁵², where `k`, the floor of x, is exact.
    exact: bool,
}

/// A PTRS proposal of a pixel's stream whose fast test failed, kept for its
/// full test: the first, as the readout's first pass keeps it (so that
/// [`ptrs_after_rejected_all`] goes on from it instead of drawing it again),
/// or the second, when the first was rejected and the second failed its fast test.
#[derive(Clone, Copy, Debug, Default)]
pub struct Proposal {
    /// The stream's start (its mixed key), for the later proposals.
    pub start: u64,
    /// [`ptrs_constants`]' b for the pixel's mean (the others follow from it).
    pub b: f64,
    /// ⌊x⌋, NaN where that floor is not exact (|x| ≥ 2⁵²).
    pub k: f64,
    pub us: f64,
    pub v: f64,
}

impl Proposal {
    /// The first proposal (outputs 1 and 2) of the stream of (`stream_key`,
    /// `item`) for mean `mu`, and whether PTRS's fast test accepted its `k`
    /// (then the draw, when μ is in PTRS's range and `k` is not NaN); the floor
    /// the [`Rounding`] `R` way (the same value either way). Branch-free.
    #[inline(always)]
    pub fn new<R: Rounding>(stream_key: u64, item: u64, mu: f64) -> (Self, bool) {
        let start = stream_start(stream_key, item);
        let consts = ptrs_constants(mu);
        let p = LaneProposal::from_start::<R>(start, 1, mu, consts);
        let first = Proposal {
            start,
            b: consts.1,
            k: if p.exact { p.k } else { f64::NAN },
            us: p.us,
            v: p.v,
        };
        (first, p.fast)
    }
}

impl LaneProposal {
    #[inline(always)]
    fn from_start<R: Rounding>(
        start: u64,
        n: u64,
        mu: f64,
        (a, b, bm2, v_r): (f64, f64, f64, f64),
    ) -> Self {
        let u = uniform_from_bits(output_at(start, n)) - 0.5;
        let v = uniform_from_bits(output_at(start, n + 1));
        let us = 0.5 - u.abs();
        let x = (2.0 * a / us + b) * u + mu + 0.43;
        LaneProposal {
            k: R::floor_below_2_52(x),
            us,
            v,
            fast: (us >= 0.07) & (v * bm2 <= v_r),
            exact: x.abs() < TWO52,
        }
    }
}

/// The Poisson draw of mean `mu` (10 ≤ μ < ∞) on the stream of (`stream_key`,
/// `item`), as `PixelRng::keyed(stream_key, item).poisson(mu)` returns it, when
/// PTRS accepts its first proposal or, that rejected, its second by the fast
/// test: (k, true). (·, false) when the draw needs the exact path. `table` is
/// [`ln_factorial_table`](super::ln_factorial_table); `R` rounds the proposals.
/// Branch-free, so a loop of these vectorises.
#[inline(always)]
pub fn ptrs_after_first<R: Rounding>(
    table: &[f64; 256],
    stream_key: u64,
    item: u64,
    mu: f64,
) -> (f64, bool) {
    let (first, fast) = Proposal::new::<R>(stream_key, item, mu);
    let (k, done, _, _) = after_rejected::<R>(table, mu, first, 3);
    (
        if fast { first.k } else { k },
        !first.k.is_nan() & (fast | done),
    )
}

/// A proposal `p` whose fast test failed: its full test, then the fast test of
/// the next proposal, from outputs `n_next` and `n_next + 1` of the stream
/// (3 after the first proposal, 5 after the second): (k, true) when either
/// decides the draw; then the next proposal, and whether its full test comes
/// next (the full test rejected `p` and the next failed its fast test but is
/// exact). The next proposal is meant only where that flag is set: elsewhere its
/// `k` may be an inexact floor, not the NaN [`Proposal`] keeps for one (a select
/// here measured 1.02–1.06× the bench's time). Branch-free.
#[inline(always)]
fn after_rejected<R: Rounding>(
    table: &[f64; 256],
    mu: f64,
    p: Proposal,
    n_next: u64,
) -> (f64, bool, Proposal, bool) {
    let Proposal { start, b, k, us, v } = p;
    let exact = !k.is_nan();
    let consts = ptrs_constants_from_b(b);
    let a = consts.0;
    // The full test of proposal p, as `poisson_ptrs_slow` writes it.
    let skip = (k < 0.0) | ((us < 0.013) & (v > us));
    let log_mu = ln_near(mu);
    let inv_alpha = 1.1239 + 1.1328 / (b - 3.4);
    let lhs = ln_near(v * inv_alpha / (a / (us * us) + b));
    let lf = ln_factorial_near(table, k);
    let k_log_mu = k * log_mu;
    let rhs = -mu + k_log_mu - lf;
    // What separates these sides from the exact path's: its logarithms and
    // `ln_near`'s differ by at most 10⁻¹⁵·max(1, |ln|) (as tested), which moves
    // lhs by ≤ 10⁻¹⁵·(|lhs| + 1), k·ln μ by ≤ ½·10⁻¹⁵ of its `scale` term and
    // (n − ½)·ln n (n·ln n ≈ |ln k!| + n) by ≤ 10⁻¹⁵·(|ln k!| + k + 1); the seven
    // roundings after the logarithms differ by at most 2·2⁻⁵³ of `scale` each.
    // In all ≤ 4·10⁻¹⁵ of `scale`; δ is 25× that.
    let scale = mu + 2.0 * k.abs() * log_mu.abs().max(1.0) + lf.abs() + k.abs() + lhs.abs() + 2.0;
    let delta = 1e-13 * scale;
    let accept1 = !skip & (lhs + delta < rhs);
    let reject1 = skip | (lhs > rhs + delta);
    let second = LaneProposal::from_start::<R>(start, n_next, mu, consts);
    let take2 = reject1 & second.fast & second.exact;
    let pending = exact & reject1 & !second.fast & second.exact;
    (
        if accept1 { k } else { second.k },
        exact & (accept1 | take2),
        Proposal {
            start,
            b,
            k: second.k,
            us: second.us,
            v: second.v,
        },
        pending,
    )
}

/// Where [`ptrs_after_rejected_all`] puts the draws of its proposals (rows of
/// their length): `k[j]` and `done[j]` for proposal j, and where its next
/// proposal's full test comes next (`pending[j]`), that proposal in `next[j]`.
pub struct RejectedDraws<'a> {
    pub k: &'a mut [f64],
    pub done: &'a mut [bool],
    pub next: &'a mut [Proposal],
    pub pending: &'a mut [bool],
}

/// The proposals `props` (with means `mus`) whose fast tests failed, each
/// followed by the proposal from outputs `n_next`, `n_next + 1` (see
/// `after_rejected`): their draws as the exact path makes them where decided;
/// nothing is done or pending wherever μ is outside PTRS's range [10, ∞). For
/// first proposals (`n_next` = 3) the draws are [`ptrs_after_first`]'s. The
/// lanes are computed 16 at a time into local arrays, which the compiler can
/// prove apart from the ln k! table it gathers from, so the loop vectorises.
#[inline(always)]
pub fn ptrs_after_rejected_all<R: Rounding>(
    table: &[f64; 256],
    props: &[Proposal],
    mus: &[f64],
    n_next: u64,
    out: RejectedDraws<'_>,
) {
    const W: usize = 16;
    let RejectedDraws {
        k,
        done,
        next,
        pending,
    } = out;
    for ((((props, mus), k), done), (next, pending)) in props
        .chunks(W)
        .zip(mus.chunks(W))
        .zip(k.chunks_mut(W))
        .zip(done.chunks_mut(W))
        .zip(next.chunks_mut(W).zip(pending.chunks_mut(W)))
    {
        let (mut kk, mut dd, mut pp) = ([0f64; W], [false; W], [false; W]);
        let (mut ff, mut mm) = ([Proposal::default(); W], [10f64; W]);
        let mut nn = [Proposal::default(); W];
        for (j, (&f, &m)) in props.iter().zip(mus).enumerate() {
            (ff[j], mm[j]) = (f, m);
        }
        for j in 0..W {
            let (kj, dj, nj, pj) = after_rejected::<R>(table, mm[j], ff[j], n_next);
            let in_range = (10.0..f64::INFINITY).contains(&mm[j]);
            (kk[j], dd[j], nn[j], pp[j]) = (kj, dj & in_range, nj, pj & in_range);
        }
        let n = props.len();
        k.copy_from_slice(&kk[..n]);
        done.copy_from_slice(&dd[..n]);
        next.copy_from_slice(&nn[..n]);
        pending.copy_from_slice(&pp[..n]);
    }
}

#[cfg(test)]
mod tests {
    use super::super::{PixelRng, RoundBits, RoundInsn};
    use super::*;

    /// Within 10⁻¹⁵·max(1, |ln x|) of libm over every binade of the normal
    /// range (100 points each, both ends included) and densely around 1, where
    /// ln x → 0; NaN outside the normal range.
    #[test]
    fn ln_near_tracks_libm_over_every_binade() {
        let mut worst = 0.0f64;
        let mut check = |x: f64| {
            let (got, want) = (ln_near(x), x.ln());
            let err = (got - want).abs() / want.abs().max(1.0);
            worst = worst.max(err);
            assert!(err <= 1e-15, "ln({x:e}): {got:e} against libm {want:e}");
        };
        let mut r = PixelRng::new(5, 9, 0);
        for e in -1022..=1023i32 {
            let base = 2f64.powi(e);
            check(base);
            check(f64::from_bits(base.to_bits() | 0x000f_ffff_ffff_ffff));
            for _ in 0..100 {
                check(base * (1.0 + r.uniform()));
            }
        }
        for i in 0..200_000 {
            check(1.0 + (i as f64 - 100_000.0) * 1e-6);
            check(1.0 + (r.uniform() - 0.5) * 1e-12);
        }
        for x in [
            std::f64::consts::SQRT_2,
            std::f64::consts::FRAC_1_SQRT_2,
            f64::MAX,
        ] {
            check(x);
            check(f64::from_bits(x.to_bits() - 1));
        }
        assert!(worst > 0.0, "ln_near is libm's own function?");
        for x in [0.0, -1.0, f64::MIN_POSITIVE / 2.0, f64::INFINITY, f64::NAN] {
            assert!(ln_near(x).is_nan(), "ln_near({x:e}) should be NaN");
        }
    }

    /// Every decided draw is the exact path's, bit for bit, over 4·10⁵ streams
    /// at means from PTRS's threshold to 10⁹; the squeeze decides the fast-test
    /// failures it should (the first proposal's full test and a second
    /// proposal that passes the fast test: 75 % of them at μ = 10, 85–89 %
    /// from μ = 137.5 on), and every fast-accepted draw. The second round (the
    /// second proposal's full test, then the third's fast test) decides the
    /// exact path's draw too, and most of what the first left pending (75 % at
    /// μ = 10, 84–88 % from μ = 137.5 to 10⁹; the test asks for 60 %).
    #[test]
    fn decided_draws_are_the_exact_draws() {
        let key = PixelRng::stream_key(77, 1);
        for &mu in &[
            10.0, 10.5, 17.25, 137.5, 1000.0, 6000.0, 1.0e5, 3.3e7, 1.0e9,
        ] {
            let (mut slow, mut decided) = (0usize, 0usize);
            let (mut pending, mut decided2) = (0usize, 0usize);
            for item in 0..400_000u64 {
                let want = PixelRng::keyed(key, item).poisson(mu);
                let table = super::super::ln_factorial_table();
                let (got, done) = ptrs_after_first::<RoundBits>(table, key, item, mu);
                // the other rounding gives the same draws and decisions
                let (got_i, done_i) = ptrs_after_first::<RoundInsn>(table, key, item, mu);
                assert_eq!(
                    (got_i.to_bits(), done_i),
                    (got.to_bits(), done),
                    "μ {mu}, {item}"
                );
                let first = PixelRng::keyed(key, item).poisson_ptrs_first(mu);
                if done {
                    assert_eq!(got.to_bits(), want.to_bits(), "μ {mu}, item {item}");
                }
                if first.accepted {
                    assert!(done, "μ {mu}, item {item}: a fast-accepted draw");
                } else {
                    slow += 1;
                    decided += usize::from(done);
                    let (p1, _) = Proposal::new::<RoundInsn>(key, item, mu);
                    let (_, _, p2, wait) = after_rejected::<RoundInsn>(table, mu, p1, 3);
                    if wait {
                        assert!(!done, "μ {mu}, item {item}: decided and pending");
                        pending += 1;
                        let (k2, done2, _, _) = after_rejected::<RoundInsn>(table, mu, p2, 5);
                        if done2 {
                            decided2 += 1;
                            assert_eq!(k2.to_bits(), want.to_bits(), "μ {mu}, {item}, round 2");
                        }
                    }
                }
            }
            let frac = decided as f64 / slow as f64;
            let want_frac = if mu < 20.0 { 0.74 } else { 0.84 };
            assert!(
                frac > want_frac,
                "μ {mu}: decided {decided} of {slow} slow draws"
            );
            assert!(
                pending > 0 && decided2 as f64 > 0.6 * pending as f64,
                "μ {mu}: the second round decided {decided2} of {pending}"
            );
        }
    }
}
