//! `f32` frame buffers for image planes — the renderer's irradiance and
//! standard errors, the sensor's outputs (DV, electrons, volts, mean
//! electrons) — backed by transparent huge pages where Linux offers them, and
//! handed from one frame of a sequence to the next ([`recycle`],
//! [`for_overwrite`]).
//!
//! A 12-megapixel frame is 48 MB per buffer. A fresh `vec![0f32; n]` of that
//! size is mapped lazily: the first write to each 4 KiB page faults, and the
//! kernel clears and maps it — ≈ 24 000 faults for DV and electrons together,
//! ≈ 5 % of `camsim bench sensor`'s CPU time in a profile (perf, AVX-512 EPYC).
//! Advised `MADV_HUGEPAGE` before the first write, the kernel maps 2 MiB pages
//! instead (512× fewer faults). The renderer's 256×256, 31-band optical image
//! (8 MB) took ≈ 2000 such faults inside the timed render, 3.9 % of
//! `camsim bench render`'s samples on the Xeon (docs/performance.md,
//! *Twenty-fifth pass*). The advice changes neither the values nor the
//! allocation; where it is refused (THP `never`, another OS) the buffer is a
//! plain zeroed vector.

/// Buffers smaller than this are left to the allocator as they are.
const ADVISE_FROM_BYTES: usize = 4 << 20;

/// How many handed-back buffers [`recycle`] keeps (two sensor frames' DV and
/// electrons).
const POOL_BUFFERS: usize = 4;

/// Large buffers handed back by [`recycle`] for [`for_overwrite`].
static POOL: std::sync::Mutex<Vec<Vec<f32>>> = std::sync::Mutex::new(Vec::new());

/// A vector of `n` floats for a caller that writes every element before it
/// reads any: a buffer handed back by [`recycle`] when one of at least `n`
/// floats is held (its elements whatever its last user left in them), else
/// [`zeroed`]`(n)`. A frame after the first of a sequence then writes to
/// pages already mapped: on a virtual machine whose guest memory is backed
/// lazily a fresh 48 MB buffer took 0.2 s to first touch, against 0.005 s for
/// pages the guest had used before (docs/performance.md, *Twenty-ninth pass*).
pub fn for_overwrite(n: usize) -> Vec<f32> {
    if n * std::mem::size_of::<f32>() >= ADVISE_FROM_BYTES {
        let mut pool = POOL.lock().unwrap_or_else(|e| e.into_inner());
        let fit = (0..pool.len())
            .filter(|&i| pool[i].len() >= n)
            .min_by_key(|&i| pool[i].len());
        if let Some(i) = fit {
            let mut v = pool.swap_remove(i);
            v.truncate(n);
            return v;
        }
    }
    zeroed(n)
}

/// Hand a buffer back for [`for_overwrite`] to reuse; small buffers, and any
/// beyond the pool's few, are freed.
pub fn recycle(v: Vec<f32>) {
    if std::mem::size_of_val(v.as_slice()) >= ADVISE_FROM_BYTES {
        let mut pool = POOL.lock().unwrap_or_else(|e| e.into_inner());
        if pool.len() < POOL_BUFFERS {
            pool.push(v);
        }
    }
}

/// A zeroed vector of `n` floats; large ones are advised to use huge pages.
pub fn zeroed(n: usize) -> Vec<f32> {
    let v = vec![0f32; n];
    advise(&v);
    v
}

/// Advise huge pages for a large buffer not yet written (a fresh
/// `vec![0f32; n]`, whose pages are mapped on first write); pages already
/// mapped stay as they are.
pub fn advise(v: &[f32]) {
    if std::mem::size_of_val(v) >= ADVISE_FROM_BYTES {
        advise_huge_pages(v);
    }
}

#[cfg(target_os = "linux")]
fn advise_huge_pages(v: &[f32]) {
    const HUGE: usize = 2 << 20;
    let start = v.as_ptr() as usize;
    let end = start + std::mem::size_of_val(v);
    // madvise needs a page-aligned start; advise the whole 2 MiB pages inside.
    let lo = start.next_multiple_of(HUGE);
    let hi = end / HUGE * HUGE;
    if hi > lo {
        // SAFETY: [lo, hi) lies inside `v`'s allocation, which this process
        // owns; MADV_HUGEPAGE is advice only (no content or mapping changes),
        // and its failure is harmless, so the result is ignored.
        unsafe {
            libc::madvise(lo as *mut libc::c_void, hi - lo, libc::MADV_HUGEPAGE);
        }
    }
}

#[cfg(not(target_os = "linux"))]
fn advise_huge_pages(_: &[f32]) {}

#[cfg(test)]
mod tests {
    use super::*;

    /// A recycled buffer comes back for a request it fits (cut to the asked
    /// length, no new allocation), small ones are not kept, and an empty pool
    /// gives a zeroed buffer.
    #[test]
    fn recycled_buffers_are_reused_at_the_asked_length() {
        let n = ADVISE_FROM_BYTES / 4 + 1000;
        let mut v = zeroed(n + 10);
        v[0] = 7.0;
        let at = v.as_ptr();
        recycle(v);
        let w = for_overwrite(n);
        assert_eq!(w.len(), n);
        // other tests may share the pool: ours is the only one this size
        if w.as_ptr() == at {
            assert_eq!(w[0], 7.0);
        }
        recycle(vec![1.0; 10]);
        assert_eq!(for_overwrite(10), vec![0.0; 10]);
    }

    /// Small and large buffers are zeroed and of the asked length, and a
    /// large one stays writable everywhere after the advice.
    #[test]
    fn zeroed_buffers_are_zero_and_writable() {
        for n in [0usize, 1, 1000, (ADVISE_FROM_BYTES / 4) + 12_345] {
            let mut v = zeroed(n);
            assert_eq!(v.len(), n);
            assert!(v.iter().all(|&x| x == 0.0));
            for (i, x) in v.iter_mut().enumerate().step_by(4096) {
                *x = i as f32;
            }
            if n > 0 {
                assert_eq!(v[0], 0.0);
            }
            if n > 4096 {
                assert_eq!(v[4096], 4096.0);
            }
        }
    }
}
