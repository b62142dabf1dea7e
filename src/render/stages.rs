//! Where the packet kernel's time goes, stage by stage (a developer's
//! measurement, compiled in only with the cargo feature `stage-timing`).
//!
//! perf's cpu-clock samples land on the instruction after a slow one (skid),
//! which smears a bounce's stages into each other; here each stage of
//! `film::RunJob::run_packets` and of `shade_packet::shade_diffuse` adds the
//! processor's time-stamp counter across it to a counter of its own, and
//! `camsim bench render` prints the shares of its timed render
//! (docs/performance.md, *Fifteenth* and *Sixteenth pass*):
//!
//! ```text
//! cargo build --release --features stage-timing
//! target/release/camsim bench render --spp 32 --batches 1 --bvh bvh4 --threads 1
//! ```
//!
//! Without the feature every call here is empty and `report` returns `None`,
//! so the shipped kernel carries no counter. The counters are process-wide
//! and shared by the render's threads (relaxed atomic adds, once per stage of
//! a whole run of packets or of one packet's shading).

/// A stage of a bounce (`run_packets`) or of a packet's diffuse shading
/// (`shade_diffuse`).
#[derive(Clone, Copy, Debug, PartialEq, Eq)]
pub(super) enum Stage {
    /// Drawing samples, the camera's rays, handing the paths to lanes.
    Camera,
    /// The packets' rays (`integrator::packet_rays`).
    PacketRays,
    /// Closest hits: regrouping, packet traversal, results back.
    ClosestHits,
    /// Shading every packet (`integrator::shade_hits`).
    Shade,
    /// Shadow rays: regrouping and occlusion.
    ShadowRays,
    /// Unblocked next-event terms, finished paths and pixels.
    BounceEnd,
    /// Within `Shade`: the first lane loop (triangle, flags, draws).
    ShadeLanes,
    /// Within `Shade`: hit point, frame, BSDF sample, all lanes.
    ShadeHit,
    /// Within `Shade`: emission of lanes that hit a light.
    ShadeEmission,
    /// Within `Shade`: the light each lane samples.
    ShadeLightChoice,
    /// Within `Shade`: the light sample, MIS weight and shadow ray, all lanes.
    ShadeNextEvent,
    /// Within `Shade`: band vectors, bounce count, Russian roulette.
    ShadeBands,
    /// Within `Camera`: the samples' draws (and each new pixel's start).
    CameraDraws,
    /// Within `Camera`: the camera's rays of the drawn samples.
    CameraRays,
    /// Within `Camera`: the paths handed to idle lanes.
    CameraHandOut,
    /// Within `BounceEnd`: the unblocked next-event terms added.
    EndUnblocked,
    /// Within `BounceEnd`: finished paths stored, finished pixels summed.
    EndPaths,
}

impl Stage {
    /// The stage of a bounce this one is part of (None: a bounce's own).
    #[cfg(feature = "stage-timing")]
    const fn parent(self) -> Option<Stage> {
        match self {
            Stage::ShadeLanes
            | Stage::ShadeHit
            | Stage::ShadeEmission
            | Stage::ShadeLightChoice
            | Stage::ShadeNextEvent
            | Stage::ShadeBands => Some(Stage::Shade),
            Stage::CameraDraws | Stage::CameraRays | Stage::CameraHandOut => Some(Stage::Camera),
            Stage::EndUnblocked | Stage::EndPaths => Some(Stage::BounceEnd),
            _ => None,
        }
    }
}

/// Stages in report order.
#[cfg(feature = "stage-timing")]
const ALL: [Stage; 17] = [
    Stage::Camera,
    Stage::PacketRays,
    Stage::ClosestHits,
    Stage::Shade,
    Stage::ShadowRays,
    Stage::BounceEnd,
    Stage::ShadeLanes,
    Stage::ShadeHit,
    Stage::ShadeEmission,
    Stage::ShadeLightChoice,
    Stage::ShadeNextEvent,
    Stage::ShadeBands,
    Stage::CameraDraws,
    Stage::CameraRays,
    Stage::CameraHandOut,
    Stage::EndUnblocked,
    Stage::EndPaths,
];

// Every stage is in `ALL`, in declaration order (a stage indexes its counter).
#[cfg(feature = "stage-timing")]
const _: () = {
    let mut i = 0;
    while i < ALL.len() {
        assert!(ALL[i] as usize == i);
        i += 1;
    }
    assert!(Stage::EndPaths as usize + 1 == ALL.len());
};

#[cfg(feature = "stage-timing")]
mod imp {
    use super::{ALL, Stage};
    use std::sync::atomic::{AtomicU64, Ordering};

    static TICKS: [AtomicU64; ALL.len()] = [const { AtomicU64::new(0) }; ALL.len()];

    #[inline(always)]
    fn now() -> u64 {
        #[cfg(target_arch = "x86_64")]
        {
            // SAFETY: RDTSC exists on every x86_64 CPU.
            unsafe { std::arch::x86_64::_rdtsc() }
        }
        #[cfg(not(target_arch = "x86_64"))]
        {
            use std::sync::OnceLock;
            static T0: OnceLock<std::time::Instant> = OnceLock::new();
            T0.get_or_init(std::time::Instant::now).elapsed().as_nanos() as u64
        }
    }

    /// A running stage clock.
    pub(in crate::render) struct Clock(u64);

    impl Clock {
        #[inline(always)]
        pub(in crate::render) fn start() -> Self {
            Clock(now())
        }
        /// The time since the last lap (or the start) goes to `stage`.
        #[inline(always)]
        pub(in crate::render) fn lap(&mut self, stage: Stage) {
            let t = now();
            TICKS[stage as usize].fetch_add(t.wrapping_sub(self.0), Ordering::Relaxed);
            self.0 = t;
        }
    }

    pub(in crate::render) fn reset() {
        TICKS.iter().for_each(|t| t.store(0, Ordering::Relaxed));
    }

    pub(in crate::render) fn report() -> Option<String> {
        let t: Vec<f64> = TICKS
            .iter()
            .map(|t| t.load(Ordering::Relaxed) as f64)
            .collect();
        // Shares of the bounce's own stages' total.
        let total: f64 = ALL
            .iter()
            .filter(|s| s.parent().is_none())
            .map(|&s| t[s as usize])
            .sum();
        if !(total > 0.0) {
            return None;
        }
        let part = |s: &Stage| format!("{:?} {:.1} %", s, 100.0 * t[*s as usize] / total);
        let within = |p: Option<Stage>| -> Vec<String> {
            ALL.iter().filter(|s| s.parent() == p).map(part).collect()
        };
        let mut out = format!(
            "stage times (time-stamp counter, share of the packet kernel): {}\n",
            within(None).join(", ")
        );
        // Each stage of a bounce that has parts, with them.
        for &p in ALL.iter().filter(|s| s.parent().is_none()) {
            let parts = within(Some(p));
            if !parts.is_empty() {
                out += &format!("  of which in {p:?}: {}\n", parts.join(", "));
            }
        }
        Some(out)
    }
}

#[cfg(not(feature = "stage-timing"))]
mod imp {
    use super::Stage;

    /// Without the feature: no clock.
    pub(in crate::render) struct Clock;

    impl Clock {
        #[inline(always)]
        pub(in crate::render) fn start() -> Self {
            Clock
        }
        #[inline(always)]
        pub(in crate::render) fn lap(&mut self, _: Stage) {}
    }

    pub(in crate::render) fn reset() {}

    pub(in crate::render) fn report() -> Option<String> {
        None
    }
}

pub(super) use imp::{Clock, report, reset};
