//! Sixteen f32 lanes (`V`) and lane masks (`M`) as plain arrays with
//! lane-by-lane operations: inside the render kernel's per-instruction-set
//! copies (`simd.rs`) LLVM turns each into one AVX-512 instruction, two AVX2
//! or four SSE ones, where `wide`'s 16-lane types stay compiled for the SSE
//! baseline. Lanes are rays of a packet (`bvh4_packet.rs`).
//!
//! Lessons from making LLVM vectorise them: masks are vectors of 0 / −1
//! tested with `any` (one `kortest` / `movmsk`; a bit mask built lane by lane
//! becomes a shuffle-and-or chain); no closures or `array::map` in lane code
//! (they stay out-of-line calls); three-iteration loops are written out
//! (`unroll3!`), or the AVX-512 cost model vectorises across them with masked
//! scatters.

// Lane loops index several per-lane arrays at once.
#![allow(clippy::needless_range_loop)]

use super::ray_packet::{LANES, LaneMask};
use std::ops::{Add, BitAnd, BitOr, Div, Mul, Not, Sub};

/// `body` once for each of `$i` = 0, 1, 2, written out: LLVM's AVX-512 cost
/// model would otherwise vectorise a 3-trip loop of 16-lane code across its
/// iterations, with masked scatters.
macro_rules! unroll3 {
    ($i:ident => $body:block) => {{
        {
            let $i = 0usize;
            $body
        }
        {
            let $i = 1usize;
            $body
        }
        {
            let $i = 2usize;
            $body
        }
    }};
}
pub(super) use unroll3;

/// One f32 per lane.
#[derive(Clone, Copy)]
#[repr(C, align(64))]
pub(super) struct V(pub(super) [f32; LANES]);

/// A lane mask: 0 or −1 per lane.
#[derive(Clone, Copy)]
#[repr(C, align(64))]
pub(super) struct M(pub(super) [i32; LANES]);

macro_rules! lanewise {
    ($t:ident, $tr:ident, $f:ident, $op:tt) => {
        impl $tr for $t {
            type Output = $t;
            #[inline(always)]
            fn $f(self, b: $t) -> $t {
                let mut r = self;
                for l in 0..LANES {
                    r.0[l] = self.0[l] $op b.0[l];
                }
                r
            }
        }
    };
}
lanewise!(V, Add, add, +);
lanewise!(V, Sub, sub, -);
lanewise!(V, Mul, mul, *);
lanewise!(V, Div, div, /);
lanewise!(M, BitAnd, bitand, &);
lanewise!(M, BitOr, bitor, |);

impl Not for M {
    type Output = M;
    #[inline(always)]
    fn not(self) -> M {
        let mut r = self;
        for l in 0..LANES {
            r.0[l] = !self.0[l];
        }
        r
    }
}

/// `V` comparisons giving masks.
macro_rules! compare {
    ($f:ident, $op:tt) => {
        #[inline(always)]
        pub(super) fn $f(self, b: V) -> M {
            let mut r = [0; LANES];
            for l in 0..LANES {
                r[l] = -((self.0[l] $op b.0[l]) as i32);
            }
            M(r)
        }
    };
}

impl M {
    /// Lanes set in a bit mask.
    #[inline(always)]
    pub(super) fn from_bits(b: LaneMask) -> M {
        let mut r = [0; LANES];
        for l in 0..LANES {
            r[l] = -((b >> l) as i32 & 1);
        }
        M(r)
    }

    /// True when some lane is set (one `kortest` / `movmsk`).
    #[inline(always)]
    pub(super) fn any(self) -> bool {
        let mut r = 0;
        for l in 0..LANES {
            r |= self.0[l];
        }
        r != 0
    }

    #[inline(always)]
    pub(super) fn get(&self, l: usize) -> bool {
        self.0[l] != 0
    }

    /// As a bit mask (scalar; outside the hot loops).
    #[inline(always)]
    pub(super) fn bits(self) -> LaneMask {
        let mut b = 0;
        for l in 0..LANES {
            if self.get(l) {
                b |= 1 << l;
            }
        }
        b
    }
}

impl V {
    #[inline(always)]
    pub(super) fn splat(x: f32) -> V {
        V([x; LANES])
    }

    compare!(lt, <);
    compare!(le, <=);
    compare!(gt, >);
    compare!(eq, ==);

    /// `a` in the lanes of `m`, `self` elsewhere.
    #[inline(always)]
    pub(super) fn blend(self, m: M, a: V) -> V {
        let mut r = self;
        for l in 0..LANES {
            let (x, y) = (a.0[l], self.0[l]);
            r.0[l] = if m.0[l] != 0 { x } else { y };
        }
        r
    }

    /// x86 `maxps` (what `wide`'s `fast_max` compiles to): `a` when `a > b`, else `b`.
    #[inline(always)]
    pub(super) fn maxps(self, b: V) -> V {
        let mut r = self;
        for l in 0..LANES {
            let (x, y) = (self.0[l], b.0[l]);
            r.0[l] = if x > y { x } else { y };
        }
        r
    }

    /// x86 `minps` (`wide`'s `fast_min`): `a` when `a < b`, else `b`.
    #[inline(always)]
    pub(super) fn minps(self, b: V) -> V {
        let mut r = self;
        for l in 0..LANES {
            let (x, y) = (self.0[l], b.0[l]);
            r.0[l] = if x < y { x } else { y };
        }
        r
    }

    /// `wide`'s NaN-aware `max`: `a` when `b` is NaN, else `maxps(a, b)`.
    #[inline(always)]
    pub(super) fn max_wide(self, b: V) -> V {
        let mut r = self;
        for l in 0..LANES {
            let (x, y) = (self.0[l], b.0[l]);
            r.0[l] = if y.is_nan() | (x > y) { x } else { y };
        }
        r
    }

    #[inline(always)]
    pub(super) fn abs(self) -> V {
        let mut r = self;
        for l in 0..LANES {
            r.0[l] = self.0[l].abs();
        }
        r
    }

    #[inline(always)]
    pub(super) fn neg(self) -> V {
        let mut r = self;
        for l in 0..LANES {
            r.0[l] = -self.0[l];
        }
        r
    }
}

/// Lane-wise max of the absolute values of three vectors (`wide`'s NaN-aware
/// `max`, as the 4-lane code did).
#[inline(always)]
pub(super) fn max3_abs(v: &[V; 3]) -> V {
    v[0].abs().max_wide(v[1].abs()).max_wide(v[2].abs())
}
