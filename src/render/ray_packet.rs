//! A packet of rays from different paths, structure of arrays: what the
//! integrator hands the acceleration structure when it traces many paths in
//! lockstep (issue 17 item 1). Lane `l` of every array belongs to the same
//! ray; lanes whose bit is clear in `active` hold no ray and are neither
//! traced nor reported.
//!
//! The packet width is fixed at 16 (one AVX-512 register of f32). The lane
//! loops are plain array loops compiled inside the render kernel's
//! per-instruction-set copies (`simd.rs`), so they run 16, 8 or 4 lanes per
//! instruction with AVX-512, AVX2 or SSE.

use super::geometry::PrimHit;

/// Rays per packet.
pub const LANES: usize = 16;

/// Lane mask of a packet (bit `l` = lane `l`).
pub type LaneMask = u32;

/// Every lane set.
pub const ALL_LANES: LaneMask = (1 << LANES) - 1;

/// The lanes set in `m`, lowest first: `for l in lanes(m) { … }`.
///
/// An iterator, not a callback: a closure's body is compiled for the
/// baseline instruction set, not for the `#[target_feature]` render kernel it
/// is called from (`simd.rs`), so per-lane work in a closure ran 4 bands wide
/// inside the AVX-512 kernel; the loop body of a `for` is the caller's code.
#[inline(always)]
pub fn lanes(m: LaneMask) -> Lanes {
    Lanes(m)
}

/// Iterator of [`lanes`].
pub struct Lanes(LaneMask);

impl Iterator for Lanes {
    type Item = usize;
    #[inline(always)]
    fn next(&mut self) -> Option<usize> {
        if self.0 == 0 {
            return None;
        }
        let l = self.0.trailing_zeros() as usize;
        self.0 &= self.0 - 1;
        Some(l)
    }
}

/// Up to `LANES` rays `o + t·d`, t ∈ (0, tmax).
#[derive(Clone, Copy, Debug)]
#[repr(C, align(64))]
pub struct RayPacket {
    /// Origins, `o[axis][lane]`.
    pub o: [[f32; LANES]; 3],
    /// Directions, `d[axis][lane]` (not necessarily unit length).
    pub d: [[f32; LANES]; 3],
    /// Far end of each ray (may be ∞).
    pub tmax: [f32; LANES],
    /// Lanes holding a ray.
    pub active: LaneMask,
}

impl Default for RayPacket {
    fn default() -> Self {
        RayPacket {
            o: [[0.0; LANES]; 3],
            d: [[0.0; LANES]; 3],
            tmax: [0.0; LANES],
            active: 0,
        }
    }
}

impl RayPacket {
    /// Put a ray in lane `l` and mark it active.
    #[inline(always)]
    pub fn set(&mut self, l: usize, o: glam::Vec3, d: glam::Vec3, tmax: f32) {
        for a in 0..3 {
            self.o[a][l] = o[a];
            self.d[a][l] = d[a];
        }
        self.tmax[l] = tmax;
        self.active |= 1 << l;
    }

    /// The ray in lane `l`: origin, direction, tmax.
    #[inline(always)]
    pub fn get(&self, l: usize) -> (glam::Vec3, glam::Vec3, f32) {
        (
            glam::Vec3::new(self.o[0][l], self.o[1][l], self.o[2][l]),
            glam::Vec3::new(self.d[0][l], self.d[1][l], self.d[2][l]),
            self.tmax[l],
        )
    }
}

/// Closest hits of a packet: lane `l` is what `Accel::intersect` returns for
/// ray `l` (`prim[l] == u32::MAX`: no hit, or lane inactive).
#[derive(Clone, Copy, Debug)]
pub struct PacketHits {
    pub prim: [u32; LANES],
    pub h: [PrimHit; LANES],
}

impl Default for PacketHits {
    fn default() -> Self {
        PacketHits {
            prim: [u32::MAX; LANES],
            h: [PrimHit::default(); LANES],
        }
    }
}
