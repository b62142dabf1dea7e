//! Band vectors: a path's throughput and radiance, its pending next-event
//! contribution and the spectra they meet (reflectances, emission), all
//! `World::bands_padded` long — the grid's bands rounded up to a multiple of
//! `BAND_PAD`, the extra bands zero in every spectrum and throughput.
//!
//! Every operation here walks its vectors in fixed blocks of `BAND_PAD`
//! bands (`<[f32]>::as_chunks`), so the compiler emits a whole number of
//! vector instructions per block at every instruction set level (one
//! AVX-512 register, two AVX2, four SSE) and no loop over the run-time
//! length: a loop of run-time length is vectorised for long vectors (four
//! AVX-512 registers a step, 64 bands), so a 32-band vector ran its 8-wide
//! remainder loop instead (docs/performance.md, *Twenty-third pass*). Each
//! band gets the same IEEE operations in the same order as a plain loop, so
//! the results are the same bits.
//!
//! The vectors of one call must have the same length, a multiple of
//! `BAND_PAD`: `World` pads every spectrum it builds and the integrator's
//! buffers are `bands_padded` long. An input shorter than the output panics
//! (a bounds check); a length not a multiple of `BAND_PAD` is a bug of the
//! caller, caught by the debug assertions (in tests) — the blocks would
//! leave its tail untouched.

/// Band vectors are padded to a multiple of this: one AVX-512 register of
/// f32, two AVX2, four SSE.
pub const BAND_PAD: usize = 16;

/// One block of bands.
type Block = [f32; BAND_PAD];

#[inline(always)]
fn blocks(v: &[f32]) -> &[Block] {
    let (b, tail) = v.as_chunks::<BAND_PAD>();
    debug_assert!(tail.is_empty(), "band vector of {} bands", v.len());
    b
}

#[inline(always)]
fn blocks_mut(v: &mut [f32]) -> &mut [Block] {
    let n = v.len();
    let (b, tail) = v.as_chunks_mut::<BAND_PAD>();
    debug_assert!(tail.is_empty(), "band vector of {n} bands");
    b
}

/// The first `n` blocks of a vector, as a slice of the same kind: what
/// `by_blocks` and `set_blocks` give their bodies, so that with `n` a
/// constant the compiler knows every block index is in bounds.
trait First {
    fn first(self, n: usize) -> Self;
}

impl<T> First for &[T] {
    #[inline(always)]
    fn first(self, n: usize) -> Self {
        &self[..n]
    }
}

impl<T> First for &mut [T] {
    #[inline(always)]
    fn first(self, n: usize) -> Self {
        &mut self[..n]
    }
}

/// `$body` for every block index `$k` of the vectors `$v` (the first one's
/// block count; the others must have as many), with the count a constant
/// for one to three blocks (16 to 48 bands; the 31-band grid is two). With
/// the count known the compiler writes each block as whole vector
/// instructions; with a run-time count its loop vectoriser took the loop
/// over blocks and treated each block's bands as scalars (sixteen scalar
/// operations a block; docs/performance.md, *Twenty-third pass*). Macros,
/// not closures: closures (and `std::array::from_fn`'s) were not inlined
/// into the instruction-set copies of the kernel.
macro_rules! by_blocks {
    (@n $n:expr, ($($v:ident),+), $k:ident => $body:expr) => {{
        $(let $v = First::first($v, $n);)+
        for $k in 0..$n {
            $body
        }
    }};
    (($first:ident $(, $v:ident)*), $k:ident => $body:expr) => {
        match $first.len() {
            2 => by_blocks!(@n 2, ($first $(, $v)*), $k => $body),
            1 => by_blocks!(@n 1, ($first $(, $v)*), $k => $body),
            3 => by_blocks!(@n 3, ($first $(, $v)*), $k => $body),
            n => by_blocks!(@n n, ($first $(, $v)*), $k => $body),
        }
    };
}

/// Band `$j` of block `$k` of the vector `$o` set to `$e`, which may read
/// `$o` and the vectors `$v`: every block is computed before any is stored,
/// so the compiler need not fear that a store changes a later block's
/// inputs (it split a block into scalar operations when it did).
macro_rules! set_blocks {
    (@n $n:expr, $o:ident = ($($v:ident),*), $k:ident, $j:ident => $e:expr) => {{
        $(let $v = First::first($v, $n);)*
        let $o = First::first($o, $n);
        let mut t = [[0.0f32; BAND_PAD]; $n];
        for $k in 0..$n {
            for $j in 0..BAND_PAD {
                t[$k][$j] = $e;
            }
        }
        $o.copy_from_slice(&t);
    }};
    ($o:ident = ($($v:ident),*), $k:ident, $j:ident => $e:expr) => {
        match $o.len() {
            2 => set_blocks!(@n 2, $o = ($($v),*), $k, $j => $e),
            1 => set_blocks!(@n 1, $o = ($($v),*), $k, $j => $e),
            3 => set_blocks!(@n 3, $o = ($($v),*), $k, $j => $e),
            n => {
                $(let $v = First::first($v, n);)*
                for $k in 0..n {
                    let mut t = [0.0f32; BAND_PAD];
                    for $j in 0..BAND_PAD {
                        t[$j] = $e;
                    }
                    $o[$k] = t;
                }
            }
        }
    };
}

/// `o = x` in every band.
#[inline(always)]
pub fn copy(o: &mut [f32], x: &[f32]) {
    let (o, x) = (blocks_mut(o), blocks(x));
    set_blocks!(o = (x), k, j => x[k][j]);
}

/// `o = 1` in the first `n` bands, 0 in the rest.
#[inline(always)]
pub fn ones(o: &mut [f32], n: usize) {
    let o = blocks_mut(o);
    set_blocks!(o = (), k, j => if k * BAND_PAD + j < n { 1.0 } else { 0.0 });
}

/// `o = 0` in every band.
#[inline(always)]
pub fn zero(o: &mut [f32]) {
    let o = blocks_mut(o);
    set_blocks!(o = (), _k, _j => 0.0);
}

/// `o += x` in every band.
#[inline(always)]
pub fn add(o: &mut [f32], x: &[f32]) {
    let (o, x) = (blocks_mut(o), blocks(x));
    set_blocks!(o = (x), k, j => o[k][j] + x[k][j]);
}

/// `o *= s` in every band.
#[inline(always)]
pub fn scale(o: &mut [f32], s: f32) {
    let o = blocks_mut(o);
    set_blocks!(o = (), k, j => o[k][j] * s);
}

/// `o += (b · e) · s` in every band: what a path whose throughput is `b`
/// gathers from an emitter of radiance `e`, weighted by `s`.
#[inline(always)]
pub fn add_scaled(o: &mut [f32], b: &[f32], e: &[f32], s: f32) {
    let (o, b, e) = (blocks_mut(o), blocks(b), blocks(e));
    set_blocks!(o = (b, e), k, j => o[k][j] + b[k][j] * e[k][j] * s);
}

/// `o = ((b · f) · e) · s` in every band: a next-event contribution through
/// a path of throughput `b`, a BSDF value `f` and an emitter's radiance `e`,
/// weighted by `s`.
#[inline(always)]
pub fn next_event(o: &mut [f32], b: &[f32], f: &[f32], e: &[f32], s: f32) {
    let (o, b, f, e) = (blocks_mut(o), blocks(b), blocks(f), blocks(e));
    set_blocks!(o = (b, f, e), k, j => b[k][j] * f[k][j] * e[k][j] * s);
}

/// `o += ((b · f) · e) · s` in every band: `next_event`'s term added.
#[inline(always)]
pub fn add_next_event(o: &mut [f32], b: &[f32], f: &[f32], e: &[f32], s: f32) {
    let (o, b, f, e) = (blocks_mut(o), blocks(b), blocks(f), blocks(e));
    set_blocks!(o = (b, f, e), k, j => o[k][j] + b[k][j] * f[k][j] * e[k][j] * s);
}

/// `o = ((b · (r / π)) · e) · s` in every band: a Lambertian surface of
/// reflectance `r` lit by an emitter of radiance `e` through a path of
/// throughput `b`, weighted by `s` (a next-event contribution).
#[inline(always)]
pub fn lambert_next_event(o: &mut [f32], b: &[f32], r: &[f32], e: &[f32], s: f32) {
    let (o, b, r, e) = (blocks_mut(o), blocks(b), blocks(r), blocks(e));
    let pi_inv = 1.0 / std::f32::consts::PI;
    set_blocks!(o = (b, r, e), k, j => b[k][j] * (r[k][j] * pi_inv) * e[k][j] * s);
}

/// Largest band value (at least 0). For finite values the same as folding
/// with `f32::max`: non-negative floats order as their bit patterns read as
/// signed integers, and negative ones read negative, so an integer maximum
/// from 0 (which vectorises across all the bands; the float one did not)
/// picks the same band. A NaN band may be returned (the path then ends; its
/// non-finite result is counted and dropped either way).
#[inline(always)]
pub fn max(v: &[f32]) -> f32 {
    let v = blocks(v);
    let mut m = [0i32; BAND_PAD];
    by_blocks!((v), k => {
        for j in 0..BAND_PAD {
            m[j] = m[j].max(v[k][j].to_bits() as i32);
        }
    });
    max_of(m)
}

/// `o *= x` in every band, and the largest band of the result (`max`'s),
/// taken from the products before they are stored.
#[inline(always)]
pub fn mul_max(o: &mut [f32], x: &[f32]) -> f32 {
    let (o, x) = (blocks_mut(o), blocks(x));
    let mut m = [0i32; BAND_PAD];
    by_blocks!((o, x), k => {
        let mut t = [0.0f32; BAND_PAD];
        for j in 0..BAND_PAD {
            t[j] = o[k][j] * x[k][j];
            m[j] = m[j].max(t[j].to_bits() as i32);
        }
        o[k] = t;
    });
    max_of(m)
}

/// `acc += l · w` in every band, in f64 (a finished path's radiance `l`,
/// weighted by its camera weight `w`, added to its pixel's batch totals),
/// unless a band of `l` is not finite: then `acc` is left as it was and
/// the result is false. The check is the largest magnitude's bits over
/// every band (an integer maximum, which vectorises; `is_finite` per band
/// did not): not finite when at least the infinity's.
#[inline(always)]
pub fn add_finite_f64(acc: &mut [f64], l: &[f32], w: f64) -> bool {
    let (acc, l) = (acc.as_chunks_mut::<BAND_PAD>().0, blocks(l));
    let mut top = [0u32; BAND_PAD];
    by_blocks!((l), k => {
        for j in 0..BAND_PAD {
            top[j] = top[j].max(l[k][j].to_bits() & 0x7fff_ffff);
        }
    });
    if top.into_iter().fold(0, u32::max) >= f32::INFINITY.to_bits() {
        return false;
    }
    by_blocks!((l, acc), k => {
        let mut t = acc[k];
        for j in 0..BAND_PAD {
            t[j] += l[k][j] as f64 * w;
        }
        acc[k] = t;
    });
    true
}

/// The float whose bits are the largest of `m` (from 0).
#[inline(always)]
fn max_of(m: [i32; BAND_PAD]) -> f32 {
    f32::from_bits(m.into_iter().fold(0i32, i32::max) as u32)
}

#[cfg(test)]
mod tests {
    use super::*;
    use crate::render::sampling::Rng;

    /// Band vectors of `n` blocks with values of every kind the integrator
    /// meets (zeros of both signs, subnormals, large and small numbers).
    fn vector(rng: &mut Rng, n: usize) -> Vec<f32> {
        (0..n * BAND_PAD)
            .map(|k| match rng.next_u32() % 6 {
                0 => 0.0,
                1 => -0.0,
                2 => f32::from_bits(rng.next_u32() & 0x007f_ffff),
                _ => rng.uniform() * 10f32.powi((rng.next_u32() % 20) as i32 - 10) * (k % 3) as f32,
            })
            .collect()
    }

    /// Each operation gives, band by band, the bits of the plain expression
    /// written out element by element, for one to three blocks.
    #[test]
    fn every_operation_is_the_plain_loop_bit_for_bit() {
        let mut rng = Rng::for_sample(11, 2, 3);
        let pi = std::f32::consts::PI;
        for n in 1..=3 {
            for _ in 0..40 {
                let (o0, b, r, e) = (
                    vector(&mut rng, n),
                    vector(&mut rng, n),
                    vector(&mut rng, n),
                    vector(&mut rng, n),
                );
                let s = rng.uniform() * 3.0;
                let same = |got: &[f32], want: Vec<f32>, what: &str| {
                    let (g, w): (Vec<u32>, Vec<u32>) = (
                        got.iter().map(|x| x.to_bits()).collect(),
                        want.iter().map(|x| x.to_bits()).collect(),
                    );
                    assert_eq!(g, w, "{what}, {n} blocks");
                };
                let mut o = o0.clone();
                add(&mut o, &b);
                same(&o, (0..o0.len()).map(|j| o0[j] + b[j]).collect(), "add");
                let mut o = o0.clone();
                let top = mul_max(&mut o, &r);
                same(&o, (0..o0.len()).map(|j| o0[j] * r[j]).collect(), "mul_max");
                assert_eq!(top.to_bits(), max(&o).to_bits(), "mul_max's maximum");
                let mut o = o0.clone();
                scale(&mut o, s);
                same(&o, o0.iter().map(|x| x * s).collect(), "scale");
                let mut o = o0.clone();
                add_scaled(&mut o, &b, &e, s);
                let want = (0..o0.len()).map(|j| o0[j] + b[j] * e[j] * s).collect();
                same(&o, want, "add_scaled");
                let mut o = o0.clone();
                next_event(&mut o, &b, &r, &e, s);
                let want = (0..o0.len()).map(|j| b[j] * r[j] * e[j] * s).collect();
                same(&o, want, "next_event");
                let mut o = o0.clone();
                add_next_event(&mut o, &b, &r, &e, s);
                let want = (0..o0.len())
                    .map(|j| o0[j] + b[j] * r[j] * e[j] * s)
                    .collect();
                same(&o, want, "add_next_event");
                let mut o = o0.clone();
                lambert_next_event(&mut o, &b, &r, &e, s);
                let want = (0..o0.len())
                    .map(|j| b[j] * (r[j] * (1.0 / pi)) * e[j] * s)
                    .collect();
                same(&o, want, "lambert_next_event");
                let acc0: Vec<f64> = b.iter().map(|&x| x as f64 * 1.5).collect();
                let mut acc = acc0.clone();
                let w = s as f64 * 0.7;
                assert!(add_finite_f64(&mut acc, &e, w));
                let want: Vec<f64> = (0..o0.len()).map(|j| acc0[j] + e[j] as f64 * w).collect();
                let bits = |v: &[f64]| v.iter().map(|x| x.to_bits()).collect::<Vec<_>>();
                assert_eq!(bits(&acc), bits(&want), "add_finite_f64, {n} blocks");
                for bad in [f32::INFINITY, f32::NEG_INFINITY, f32::NAN] {
                    let mut l = e.clone();
                    let at = rng.next_u32() as usize % l.len();
                    l[at] = bad;
                    let mut acc = acc0.clone();
                    assert!(!add_finite_f64(&mut acc, &l, w), "{bad} passed");
                    assert_eq!(bits(&acc), bits(&acc0), "{bad} changed the totals");
                }
                let mut o = o0.clone();
                copy(&mut o, &e);
                same(&o, e.clone(), "copy");
                zero(&mut o);
                same(&o, vec![0.0; o0.len()], "zero");
                for k in [0, 1, 15, 16, 17, n * BAND_PAD] {
                    ones(&mut o, k);
                    let want = (0..o0.len()).map(|j| if j < k { 1.0 } else { 0.0 });
                    same(&o, want.collect(), "ones");
                }
            }
        }
    }

    /// `max` is the float maximum from 0 for bands of any sign and size
    /// (subnormals, zeros of both signs, infinity), for one to three blocks,
    /// wherever the largest band sits.
    #[test]
    fn max_is_the_float_maximum_from_zero() {
        let mut rng = Rng::for_sample(3, 1, 4);
        for n in 1..=3 {
            for trial in 0..200 {
                let mut v: Vec<f32> = (0..n * BAND_PAD)
                    .map(|k| match (trial + k) % 9 {
                        0 => -rng.uniform() * 3.0,
                        1 => -0.0,
                        2 => 0.0,
                        3 => f32::from_bits(rng.next_u32() & 0x007f_ffff),
                        _ => rng.uniform() * 10f32.powi((rng.next_u32() % 20) as i32 - 10),
                    })
                    .collect();
                if trial % 50 == 7 {
                    let k = rng.next_u32() as usize % v.len();
                    v[k] = f32::INFINITY;
                }
                if trial % 50 == 9 {
                    v.iter_mut().for_each(|x| *x = -x.abs());
                }
                let want = v.iter().fold(0.0f32, |m, &x| m.max(x));
                let got = max(&v);
                assert_eq!(got, want, "{v:?}");
                assert!(got >= 0.0 && got.is_sign_positive());
            }
        }
    }
}
