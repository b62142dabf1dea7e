//! One path between bounces: the state a path carries from one hit to the
//! next (its ray, MIS state, bounce count, refraction scale, hero band), the
//! next-event shadow ray a bounce may leave to test, and what every bounce
//! does with a path's throughput (emission gathered, Russian roulette),
//! whether one path is shaded at a time (`integrator::scatter`) or a
//! packet's diffuse hits together (`shade_packet`); the band arithmetic
//! itself is `bands.rs`'s.

use super::bands;
use super::geometry::offset_ray_origin;
use super::sampling::power_heuristic;
use super::world::{LightKind, LightSample, World};
use glam::Vec3;

/// Fraction of a shadow ray's length left untested at its far end, so it does
/// not hit the light it aims at (pbrt's ShadowEpsilon).
pub(super) const SHADOW_EPS: f32 = 1e-4;

/// One path between bounces: the ray it follows next and what its next
/// hit needs to know (MIS state, bounce count, refraction scale, hero band).
#[derive(Clone, Copy, Debug)]
pub struct PathState {
    pub o: Vec3,
    pub d: Vec3,
    pub(super) specular: bool,
    pub(super) prev_pdf: f32,
    pub(super) eta_scale: f32,
    pub(super) depth: u32,
    pub hero: Option<usize>,
    /// Russian roulette's reference: the throughput's largest band after the
    /// first bounce (at most 1; 1 before it). See `roulette`.
    pub(super) rr_ref: f32,
}

impl PathState {
    /// A path leaving the camera along `o + t·d`.
    #[inline(always)]
    pub fn camera(o: Vec3, d: Vec3, hero: Option<usize>) -> Self {
        PathState {
            o,
            d,
            specular: true,
            prev_pdf: 0.0,
            eta_scale: 1.0,
            depth: 0,
            hero,
            rr_ref: 1.0,
        }
    }
}

/// A next-event shadow ray `o + t·d`, t ∈ (0, tmax), whose contribution
/// waits in the path's pending buffer until the ray is found unblocked.
#[derive(Clone, Copy, Debug)]
pub struct ShadowRay {
    pub o: Vec3,
    pub d: Vec3,
    pub tmax: f32,
}

impl ShadowRay {
    /// The shadow ray from `origin` (already offset off the shading point's
    /// surface) to light sample `ls`: to its point, offset off the light's
    /// surface when it has one and stopped `SHADOW_EPS` short, or along its
    /// direction without end (direction-only lights). `None` when the point
    /// is the origin. The direction is a unit vector: obvhs' slab test clamps
    /// tiny inverse components, which would misbehave for short unnormalised
    /// vectors (mm scenes).
    #[inline(always)]
    pub(super) fn towards(origin: Vec3, ls: &LightSample<'_>) -> Option<ShadowRay> {
        match ls.target {
            Some((pl, err_l, nl)) => {
                let tgt = if nl == Vec3::ZERO {
                    pl
                } else {
                    offset_ray_origin(pl, err_l, nl, -ls.wi)
                };
                let dv = tgt - origin;
                let len = dv.length();
                (len > 0.0).then(|| ShadowRay {
                    o: origin,
                    d: dv / len,
                    tmax: len * (1.0 - SHADOW_EPS),
                })
            }
            None => Some(ShadowRay {
                o: origin,
                d: ls.wi,
                tmax: f32::INFINITY,
            }),
        }
    }
}

/// The path's ray hit area light `light` at distance `dist` (along the ray,
/// in scene units) where the cosine between the light's normal and the
/// direction back along the ray is `cos_l`: add what it emits, MIS-weighted
/// against the next-event estimate of the bounce before, to `l`.
#[inline(always)]
pub(super) fn add_emitted(
    world: &World,
    st: &PathState,
    light: u32,
    cos_l: f32,
    dist: f32,
    beta: &[f32],
    l: &mut [f32],
) {
    if let LightKind::Area { le, two_sided, .. } = &world.lights[light as usize]
        && (cos_l > 0.0 || (*two_sided && cos_l < 0.0))
    {
        let w = if st.specular {
            1.0
        } else {
            let pl = world.area_light_pdf(light, dist, cos_l);
            power_heuristic(st.prev_pdf, pl)
        };
        bands::add_scaled(l, beta, le, w);
    }
}

/// Russian roulette on the throughput `beta` (with refraction scaling undone;
/// `nb` bands, a hero path's one band scaled by `nb`) after the bounce that
/// made `st.depth`, with draw `u_rr`: false when the path ends, else the
/// survivor's throughput is scaled up by 1/(1 − q). `top` is `beta`'s
/// largest band (`bands::max`), which the caller has from the bounce's
/// product (`bands::mul_max`): reading the throughput back just after
/// writing it stalled on the stores (docs/performance.md, *Twenty-third
/// pass*).
///
/// From the second bounce on, a path survives with probability
/// p = min(1, m / m₁): m is the throughput's largest band and m₁ the same
/// after the first bounce (at most 1), i.e. the throughput relative to what
/// the surface the pixel sees lets through. pbrt-v4 (and camsim before)
/// takes p = min(1, m): behind a dark or saturated first surface (the
/// Cornell box's green wall, largest band 0.38) every later bounce was a
/// likely kill, and there camsim's MSE was 1.4–2.2× Mitsuba's (32-px
/// blocks, bench), which starts roulette only at depth 5. Normalising by m₁ is the pixel-relative
/// roulette of Vorba & Křivánek (2016, ADRRS) with the pixel's value
/// approximated by the first surface's reflectance. Unbiased for any p > 0;
/// p ≥ min(1, m), so it never ends a path that pbrt's rule would keep.
///
/// Without a branch on the draw or on whether the roulette is played (the
/// packet kernel's lanes are unrelated paths, so their outcomes are data the
/// branch predictor cannot learn): q is 0 when it is not played, and the
/// throughput is scaled by 1/(1 − q) either way — by exactly 1 then, which
/// leaves its bits, and a path that ends is never read again. On the
/// EPYC a branch-free form measured +0.6 % (*Tenth pass*); on the Xeon this
/// one measured 0.980 of the bench's time (*Twenty-fourth pass*).
#[inline(always)]
pub(super) fn roulette(
    st: &mut PathState,
    nb: usize,
    top: f32,
    u_rr: f32,
    beta: &mut [f32],
) -> bool {
    debug_assert_eq!(top.to_bits(), bands::max(beta).to_bits());
    let mut m = top * st.eta_scale;
    if st.hero.is_some() {
        m /= nb as f32;
    }
    if !(m > 0.0) {
        return false;
    }
    st.rr_ref = if st.depth == 1 { m.min(1.0) } else { st.rr_ref };
    let m = m / st.rr_ref;
    let q = if m < 1.0 && st.depth > 1 {
        (1.0 - m).max(0.0)
    } else {
        0.0
    };
    bands::scale(beta, 1.0 / (1.0 - q));
    !(u_rr < q)
}

#[cfg(test)]
mod tests {
    use super::*;

    /// Russian roulette against its rule stated plainly (survive with
    /// p = min(1, m/m₁) from the second bounce, m₁ set at the first, the
    /// survivor scaled by 1/(1 − q), q = 1 − p): the same decision and the
    /// same band bits for every draw, the throughput's bits untouched when
    /// the roulette is not played; and over stratified draws the expected
    /// throughput is the throughput (unbiased) within the strata's 1/N.
    #[test]
    fn roulette_follows_its_rule_and_is_unbiased() {
        let n = 4000usize;
        for depth in 1..=3u32 {
            for rr_ref in [1.0f32, 0.38, 0.5] {
                for top in [0.05f32, 0.3, 0.38, 0.9, 1.0, 1.7] {
                    let beta0: Vec<f32> = (0..32)
                        .map(|b| {
                            if b < 31 {
                                top * (0.2 + 0.8 * (b % 5) as f32 / 4.0)
                            } else {
                                0.0
                            }
                        })
                        .collect();
                    // The rule, plainly: it does not depend on the draw.
                    let m = beta0.iter().fold(0.0f32, |a, &b| a.max(b));
                    let m1 = if depth == 1 { m.min(1.0) } else { rr_ref };
                    let p = m / m1;
                    let played = p < 1.0 && depth > 1;
                    let q = (1.0 - p).max(0.0);
                    let mut mean = vec![0.0f64; 32];
                    let mut survived = 0usize;
                    for k in 0..n {
                        let u = (k as f32 + 0.5) / n as f32;
                        let mut st = PathState::camera(Vec3::ZERO, Vec3::Z, None);
                        (st.depth, st.rr_ref) = (depth, rr_ref);
                        let mut beta = beta0.clone();
                        let top = bands::max(&beta);
                        let lives = roulette(&mut st, 31, top, u, &mut beta);
                        assert_eq!(st.rr_ref, m1);
                        assert_eq!(
                            lives,
                            !(played && u < q),
                            "depth {depth} m {m} m1 {m1} u {u}"
                        );
                        if !lives {
                            continue;
                        }
                        survived += 1;
                        for (b, (&got, &b0)) in beta.iter().zip(&beta0).enumerate() {
                            let want = if played { b0 * (1.0 / (1.0 - q)) } else { b0 };
                            assert_eq!(got.to_bits(), want.to_bits(), "band {b}");
                            mean[b] += got as f64 / n as f64;
                        }
                    }
                    assert!(survived > 0);
                    let p = p.min(1.0) as f64;
                    for (b, (&mb, &b0)) in mean.iter().zip(&beta0).enumerate() {
                        let tol = 2.0 / (n as f64 * p) * b0 as f64 + 1e-7;
                        assert!(
                            (mb - b0 as f64).abs() <= tol,
                            "band {b}: E[beta] {mb} against {b0}"
                        );
                    }
                }
            }
        }
    }
}
