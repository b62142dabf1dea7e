//! Memory brought into cache while arithmetic runs. The sensor's first pass
//! over a row reads the row's optical image (31 bands: 0.5 MB for a 4032-pixel
//! row) as fast as memory delivers it, and the noise passes after it hardly
//! touch memory at all; so the noise passes of one row ask for the next row's
//! optical image a few cache lines at a time ([`Prefetch::step`]), and its
//! first pass then reads from cache. Prefetching reads nothing and writes
//! nothing: no value depends on it. `camsim bench sensor` on an AVX2 EPYC
//! (Zen 3): 0.90 of the time without it (docs/performance.md, *Twenty-ninth
//! pass*).

use std::marker::PhantomData;

/// Bytes a cache line holds on the x86-64 CPUs this targets.
const LINE: usize = 64;

/// A span of memory to bring into cache `per_step` lines at a time.
#[derive(Clone, Copy, Debug)]
pub struct Prefetch<'a> {
    next: usize,
    end: usize,
    per_step: usize,
    _span: PhantomData<&'a [u8]>,
}

impl<'a> Prefetch<'a> {
    /// Nothing to bring in.
    pub fn none() -> Self {
        Self {
            next: 0,
            end: 0,
            per_step: 0,
            _span: PhantomData,
        }
    }

    /// All of `data`, one line a step until [`Self::over`] says otherwise.
    pub fn of<T>(data: &'a [T]) -> Self {
        let next = data.as_ptr() as usize;
        Self {
            next,
            end: next + std::mem::size_of_val(data),
            per_step: 1,
            _span: PhantomData,
        }
    }

    /// The span's first and second halves (at a line boundary).
    pub fn halves(self) -> (Self, Self) {
        let mid = (self.next + self.end.saturating_sub(self.next) / 2).next_multiple_of(LINE);
        let mid = mid.min(self.end);
        (Self { end: mid, ..self }, Self { next: mid, ..self })
    }

    /// The same span spread over `steps` steps (all of it by the last).
    pub fn over(self, steps: usize) -> Self {
        Self {
            per_step: self.lines_left().div_ceil(steps.max(1)),
            ..self
        }
    }

    /// Lines not yet asked for.
    pub fn lines_left(&self) -> usize {
        self.end.saturating_sub(self.next).div_ceil(LINE)
    }

    /// Ask for the next `per_step` lines (fewer at the end of the span).
    #[inline(always)]
    pub fn step(&mut self) {
        for _ in 0..self.per_step {
            if self.next >= self.end {
                return;
            }
            #[cfg(target_arch = "x86_64")]
            // SAFETY: a prefetch is a hint: it reads no value into the program
            // and cannot fault, whatever the address; SSE is in every x86-64 CPU.
            unsafe {
                use std::arch::x86_64::{_MM_HINT_T0, _mm_prefetch};
                _mm_prefetch::<_MM_HINT_T0>(self.next as *const i8);
            }
            self.next += LINE;
        }
    }
}

#[cfg(test)]
mod tests {
    use super::*;

    /// Steps cover the span: `over(k)` asks for every line within k steps and
    /// none after; halves split it with nothing lost or doubled; none is empty.
    #[test]
    fn steps_cover_the_span_and_stop() {
        let data = vec![0f32; 4032 * 31];
        let whole = Prefetch::of(&data);
        let lines = whole.lines_left();
        assert_eq!(lines, (4032 * 31 * 4usize).div_ceil(LINE));
        for steps in [1usize, 7, 1008, lines, 3 * lines] {
            let mut p = whole.over(steps);
            for _ in 0..steps {
                p.step();
            }
            assert_eq!(p.lines_left(), 0, "{steps} steps");
            p.step();
            assert_eq!(p.lines_left(), 0);
        }
        let (a, b) = whole.halves();
        // an unaligned start can split one line between the halves
        let sum = a.lines_left() + b.lines_left();
        assert!(sum == lines || sum == lines + 1, "{sum} vs {lines}");
        assert!(a.lines_left().abs_diff(b.lines_left()) <= 2);
        let mut n = Prefetch::none();
        n.step();
        assert_eq!(n.lines_left(), 0);
        let mut one = Prefetch::of(&data[..1]).over(5);
        one.step();
        assert_eq!(one.lines_left(), 0);
    }
}
