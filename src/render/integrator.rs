//! Unidirectional path tracing with next-event estimation and multiple
//! importance sampling (power heuristic), Russian roulette and a bounce limit.
//!
//! Bounce counting follows pbrt: `max_bounces = 0` shows emitters only,
//! `1` adds direct lighting, … Mitsuba's `max_depth = d` equals
//! `max_bounces = d − 1`.
//!
//! Each path carries every band of the grid. When it meets a dispersive
//! dielectric (ior varies with λ) it keeps one uniformly chosen band (the hero
//! wavelength), scaled by the band count, and terminates the others — unbiased,
//! and only dispersive paths pay the colour noise.

use super::accel::Hit;
use super::bands;
use super::geometry::offset_ray_origin;
use super::path::{PathState, ShadowRay, add_emitted, roulette};
use super::ray_packet::{LANES, LaneMask, PacketHits, RayPacket, lanes};
use super::sampler::{BounceDraws, Sampler};
use super::sampling::{Frame, power_heuristic};
use super::shade_packet::{LaneBands, shade_diffuse};
use super::simd::RenderIsa;
use super::world::{LightKind, World};
use glam::Vec3;

/// Per-thread buffers: one allocation per tile row, none per ray.
pub struct Scratch {
    pub beta: Vec<f32>,
    pub l: Vec<f32>,
    f: Vec<f32>,
}

impl Scratch {
    pub fn new(nb: usize) -> Self {
        Scratch {
            beta: vec![0.0; nb],
            l: vec![0.0; nb],
            f: vec![0.0; nb],
        }
    }
}

/// Result of the first intersection (for labels and depth).
pub struct FirstHit {
    pub t: f32,
    pub object: u32,
}

#[inline(always)]
pub fn first_hit(world: &World, o: Vec3, d: Vec3) -> Option<FirstHit> {
    world
        .accel
        .intersect(o, d, f32::INFINITY)
        .map(|h| FirstHit {
            t: h.h.t,
            object: world.info[h.prim as usize].object,
        })
}

/// The path escaped the scene: add what the infinite lights send along it.
#[inline(always)]
pub fn escape(world: &World, st: &PathState, beta: &[f32], l: &mut [f32]) {
    for &li in &world.infinite {
        if let LightKind::Infinite { l: le } = &world.lights[li as usize] {
            let w = if st.specular {
                1.0
            } else {
                let pl = world.light_pmf[li as usize] / (4.0 * std::f32::consts::PI);
                power_heuristic(st.prev_pdf, pl)
            };
            bands::add_scaled(l, beta, le, w);
        }
    }
}

/// One bounce at the hit `hit` of the path's ray: emission into `l`, the
/// next-event estimate, BSDF sampling and Russian roulette into `st` and
/// `beta`. Returns the shadow ray still to test (if any) and whether the path
/// goes on. `f` is scratch. With `pend = None` the shadow ray is tested here
/// and an unblocked light's contribution added to `l`; with `Some` it is
/// written to `pend` and the ray returned, for the caller to test later, in a
/// packet: the draws are taken in the same order whatever happens, so adding
/// `pend` to `l` when the ray is unblocked, before the path's next hit, gives
/// the same result.
#[allow(clippy::too_many_arguments)]
#[inline(always)]
pub fn scatter(
    world: &World,
    st: &mut PathState,
    hit: &Hit,
    max_bounces: u32,
    smp: &mut Sampler,
    beta: &mut [f32],
    l: &mut [f32],
    f: &mut [f32],
    pend: Option<&mut [f32]>,
) -> (Option<ShadowRay>, bool) {
    let nb = world.bands;
    let (o, d) = (st.o, st.d);
    let info = world.info[hit.prim as usize];
    let (p, p_err, ng) = world.surface(hit.prim, o, d, &hit.h);
    let dlen = d.length();
    let wo_w = -d / dlen;
    // Emission.
    if info.light != u32::MAX {
        add_emitted(world, st, info.light, ng.dot(wo_w), hit.h.t * dlen, beta, l);
    }
    if st.depth >= max_bounces {
        return (None, false);
    }
    let bsdf = &world.bsdfs[info.material as usize];
    if bsdf.is_black() {
        return (None, false);
    }
    // Shading normal: interpolated if the mesh has normals, else geometric.
    let mut ns = ng;
    if info.normals != u32::MAX {
        let n3 = world.normals[info.normals as usize];
        let b = hit.h.b;
        let n = (n3[0] * b[0] + n3[1] * b[1] + n3[2] * b[2]).normalize_or_zero();
        if n != Vec3::ZERO {
            ns = if n.dot(ng) < 0.0 { -n } else { n };
        }
    }
    // Opaque materials are two-sided: face the normals towards wo.
    let transmissive = bsdf.is_transmissive();
    let (ng_s, ns_s) = if !transmissive && ng.dot(wo_w) < 0.0 {
        (-ng, -ns)
    } else {
        (ng, ns)
    };
    let frame = Frame::from_normal(ns_s);
    let wo = frame.to_local(wo_w);

    if bsdf.is_dispersive() && st.hero.is_none() {
        // From the sample's own stream: a draw taken by some samples
        // only would shift the Sobol draws of the rest of the path.
        let b = ((smp.get1d_independent() * nb as f32) as usize).min(nb - 1);
        for (j, x) in beta.iter_mut().enumerate() {
            *x = if j == b { *x * nb as f32 } else { 0.0 };
        }
        st.hero = Some(b);
    }

    // Ray origin for directions on the front side of `ng_s`: shared by the
    // shadow ray and a reflected continuation ray.
    let origin_front = offset_ray_origin(p, p_err, ng_s, ng_s);

    // Every bounce takes the same draws in the same order (light choice and
    // position from one 2-D point, lobe, direction, roulette) whether or not
    // it uses them, so draw k of every sample of a batch samples the same
    // dimension of the path (sampler.rs).
    let BounceDraws {
        light: (u1, u2),
        lobe: u_lobe,
        dir: (v1, v2),
        rr: u_rr,
    } = smp.bounce_draws();

    // Next-event estimation: the contribution if the light is visible.
    let mut shadow = None;
    if !bsdf.is_delta()
        && wo.z > 0.0
        && let Some(ls) = world.sample_light(p, u1, u2)
    {
        let wi = frame.to_local(ls.wi);
        if wi.z > 0.0 && ls.wi.dot(ng_s) > 0.0 {
            shadow = ShadowRay::towards(origin_front, &ls);
            // Tested here (one path: the BSDF is evaluated for unblocked
            // rays only) or later by the caller with the packet's other
            // shadow rays (the contribution waits in `pend`).
            let contributes = match shadow {
                None => false,
                Some(r) if pend.is_none() => {
                    shadow = None;
                    world.accel.unoccluded(r.o, r.d, r.tmax)
                }
                Some(_) => true,
            };
            if contributes {
                let pdf_b = bsdf.eval(wo, wi, f);
                let s = ls.next_event_scale(wi.z, pdf_b);
                match pend {
                    Some(pend) => bands::next_event(pend, beta, f, ls.spec, s),
                    None => bands::add_next_event(l, beta, f, ls.spec, s),
                }
            }
        }
    }

    // BSDF sampling.
    let Some(bs) = bsdf.sample(wo, u_lobe, v1, v2, st.hero, f) else {
        return (shadow, false);
    };
    if !(bs.pdf > 0.0) || !bs.pdf.is_finite() {
        return (shadow, false);
    }
    let wi_w = frame.to_world(bs.wi).normalize();
    // Reject light leaks: reflection must stay on the geometric side of wo.
    let same_side = wi_w.dot(ng_s) * wo_w.dot(ng_s) > 0.0;
    let refl_local = bs.wi.z * wo.z > 0.0;
    if same_side != refl_local {
        return (shadow, false);
    }
    let top = bands::mul_max(beta, f);
    st.specular = bs.delta;
    st.prev_pdf = bs.pdf;
    st.eta_scale *= bs.eta_scale;
    st.o = if wi_w.dot(ng_s) >= 0.0 {
        origin_front
    } else {
        offset_ray_origin(p, p_err, ng_s, wi_w)
    };
    st.d = wi_w;
    st.depth += 1;
    (shadow, roulette(st, nb, top, u_rr, beta))
}

/// Trace one path. On entry `sc.beta` holds the initial throughput (1 for all
/// bands, or one-hot for a hero camera sample with `hero = Some(band)`).
/// On return `sc.l` holds the radiance estimate.
#[inline(always)]
pub fn trace(
    world: &World,
    o: Vec3,
    d: Vec3,
    max_bounces: u32,
    hero: Option<usize>,
    smp: &mut Sampler,
    sc: &mut Scratch,
) {
    sc.l.iter_mut().for_each(|x| *x = 0.0);
    let mut st = PathState::camera(o, d, hero);
    loop {
        let Some(hit) = world.accel.intersect(st.o, st.d, f32::INFINITY) else {
            escape(world, &st, &sc.beta, &mut sc.l);
            break;
        };
        let (_, alive) = scatter(
            world,
            &mut st,
            &hit,
            max_bounces,
            smp,
            &mut sc.beta,
            &mut sc.l,
            &mut sc.f,
            None,
        );
        if !alive {
            break;
        }
    }
}

/// Per-thread buffers of a packet of paths: lane `l`'s band vectors are
/// `[l·stride, (l+1)·stride)` of `beta`, `l` and `pend`.
pub struct PacketScratch {
    stride: usize,
    beta: Vec<f32>,
    l: Vec<f32>,
    pend: Vec<f32>,
    f: Vec<f32>,
    /// This bounce's rays, their closest hits and the shadow rays.
    pub(super) rays: RayPacket,
    pub(super) hits: PacketHits,
    pub(super) shadows: RayPacket,
}

impl PacketScratch {
    pub fn new(nb: usize) -> Self {
        PacketScratch {
            stride: nb,
            beta: vec![0.0; nb * LANES],
            l: vec![0.0; nb * LANES],
            pend: vec![0.0; nb * LANES],
            f: vec![0.0; nb],
            rays: RayPacket::default(),
            hits: PacketHits::default(),
            shadows: RayPacket::default(),
        }
    }

    /// Lane `lane`'s radiance, all `stride` bands.
    #[inline(always)]
    pub fn radiance(&self, lane: usize) -> &[f32] {
        &self.l[lane * self.stride..(lane + 1) * self.stride]
    }

    /// Lane `lane`'s throughput, for a new path to set.
    #[inline(always)]
    pub fn beta_mut(&mut self, lane: usize) -> &mut [f32] {
        &mut self.beta[lane * self.stride..(lane + 1) * self.stride]
    }

    /// Clear lane `lane`'s radiance for a new path.
    #[inline(always)]
    pub fn clear_radiance(&mut self, lane: usize) {
        bands::zero(&mut self.l[lane * self.stride..(lane + 1) * self.stride]);
    }
}

// One bounce of a packet's paths (issue 17 item 1) is three steps, so that a
// row can cast the rays of several packets together (`ray_stream`):
// `packet_rays` (the live lanes' rays), the closest hits, `shade_hits` (the
// lanes whose hits `World::hit_kind` calls shadable — Lambertian triangles
// — shaded together in structure of arrays by
// `shade_packet::shade_diffuse`, every other lane on its own by `scatter`;
// their shadow rays), the shadow rays' occlusion, then `add_unblocked`. Lane
// `l` continues from `st[l]` with its throughput and radiance in the packet's
// `PacketScratch`. Each lane takes the same draws and does the same
// operations in the same order as `trace` does for that path, so a path
// traced bounce by bounce this way, in any lane and beside any other paths,
// gives `trace`'s bits.

/// A bounce's first step: the rays of the lanes `alive` into `sc.rays`
/// (gathered in the AVX-512 kernel).
#[inline(always)]
pub fn packet_rays(
    isa: RenderIsa,
    st: &[PathState; LANES],
    alive: LaneMask,
    sc: &mut PacketScratch,
) {
    #[cfg(target_arch = "x86_64")]
    if isa == RenderIsa::Avx512 {
        // SAFETY: the AVX-512 kernel runs only where the CPU has AVX-512F.
        unsafe { super::hit_lanes_avx512::packet_rays(st, alive, &mut sc.rays) };
        return;
    }
    let _ = isa;
    sc.rays.active = 0;
    for i in lanes(alive) {
        sc.rays.set(i, st[i].o, st[i].d, f32::INFINITY);
    }
}

/// A bounce's second step, once `sc.hits` holds the closest hits: shade the
/// lanes `alive` — emission, next-event shadow rays into `sc.shadows` with
/// their contributions pending, the next ray. Returns the lanes whose paths
/// ended. `isa`: the kernel's instruction set, whose own code
/// `shade_diffuse` may take (AVX-512 intrinsics).
#[inline(always)]
#[allow(clippy::too_many_arguments)]
pub fn shade_hits(
    world: &World,
    isa: RenderIsa,
    st: &mut [PathState; LANES],
    alive: LaneMask,
    max_bounces: u32,
    smp: &mut [Sampler],
    sc: &mut PacketScratch,
) -> LaneMask {
    let n = sc.stride;
    let mut ended: LaneMask = 0;
    sc.shadows.active = 0;
    // Which lanes missed, and which hits `shade_diffuse` takes, as masks
    // made without a branch per lane (whether a ray hit is data the branch
    // predictor cannot learn).
    let (mut missed, mut together): (LaneMask, LaneMask) = (0, 0);
    for i in lanes(alive) {
        let (hit, shadable) = world.hit_kind(sc.hits.prim[i]);
        missed |= (!hit as LaneMask) << i;
        together |= (shadable as LaneMask) << i;
    }
    ended |= missed;
    if !world.infinite.is_empty() {
        for i in lanes(missed) {
            let span = i * n..(i + 1) * n;
            escape(world, &st[i], &sc.beta[span.clone()], &mut sc.l[span]);
        }
    }
    for i in lanes(alive & !missed & !together) {
        let span = i * n..(i + 1) * n;
        let prim = sc.hits.prim[i];
        let hit = Hit {
            prim,
            h: sc.hits.h[i],
        };
        let (shadow, go_on) = scatter(
            world,
            &mut st[i],
            &hit,
            max_bounces,
            &mut smp[i],
            &mut sc.beta[span.clone()],
            &mut sc.l[span.clone()],
            &mut sc.f,
            Some(&mut sc.pend[span]),
        );
        if let Some(r) = shadow {
            sc.shadows.set(i, r.o, r.d, r.tmax);
        }
        if !go_on {
            ended |= 1 << i;
        }
    }
    if together != 0 {
        let bands = LaneBands {
            stride: n,
            beta: &mut sc.beta,
            l: &mut sc.l,
            pend: &mut sc.pend,
        };
        ended |= shade_diffuse(
            world,
            isa,
            st,
            &sc.hits,
            together,
            max_bounces,
            smp,
            bands,
            &mut sc.shadows,
        );
    }
    ended
}

/// Add the pending next-event contributions of the lanes `free` (shadow rays
/// of `sc.shadows` found unblocked; a bounce's last step).
#[inline(always)]
pub fn add_unblocked(free: LaneMask, sc: &mut PacketScratch) {
    let n = sc.stride;
    for i in lanes(free) {
        bands::add(&mut sc.l[i * n..(i + 1) * n], &sc.pend[i * n..(i + 1) * n]);
    }
}

#[cfg(test)]
mod tests {
    use super::*;
    use crate::render::BvhKind;
    use crate::render::sampling::Rng;
    use crate::render::world::selection_pmf;
    use crate::scene::shapes::quad;
    use crate::scene::{Light, Material, Scene};
    use crate::spectrum::{Spectrum, WavelengthGrid};
    use glam::DVec3;

    /// Lights above the selection floor keep their f32 power shares bit for
    /// bit; a light below it gets max(P/ΣP, 10⁻³/N) renormalised.
    #[test]
    fn selection_floor_only_lifts_lights_below_it() {
        assert_eq!(selection_pmf(&[1.0, 3.0]), vec![0.25, 0.75]);
        assert_eq!(selection_pmf(&[0.0, 3.0]), vec![0.0, 1.0]);
        let p = selection_pmf(&[1e8, 1.0]);
        let floor = 1e-3 / 2.0;
        let want = [1.0 / (1.0 + floor), floor / (1.0 + floor)];
        for (g, w) in p.iter().zip(want) {
            assert!((*g as f64 - w).abs() < 1e-7 * w, "{p:?}");
        }
    }

    /// One draw picks the light and, remapped, places the sample on it: the
    /// light is the cumulative table's partition point, and the draws that
    /// pick one light, remapped, spread evenly over [0, 1) (so a stratified
    /// point stays stratified on each light; pbrt-v4 and Mitsuba reuse the
    /// draw the same way).
    #[test]
    fn light_choice_reuses_its_draw_uniformly() {
        let mut scene = Scene::default();
        for (k, i) in [1.0, 2.0, 5.0].into_iter().enumerate() {
            scene.lights.push(Light::Point {
                position: DVec3::new(k as f64, 0.0, 1.0),
                intensity: Spectrum::constant("i", i),
            });
        }
        let grid = WavelengthGrid::new(500.0, 600.0, 50.0).unwrap();
        let world = World::build(&scene, &grid, BvhKind::Bvh4).unwrap();
        let n = 8000;
        let mut per_light = vec![Vec::new(); 3];
        for k in 0..n {
            let u = (k as f32 + 0.5) / n as f32;
            let (idx, sel, rest) = world.choose_light(u);
            assert_eq!(idx, world.light_cdf.partition_point(|&c| c <= u), "u = {u}");
            assert_eq!(sel, world.light_pmf[idx]);
            assert!((0.0..1.0).contains(&rest), "u = {u}: remapped {rest}");
            per_light[idx].push(rest);
        }
        for (idx, want_p) in [1.0 / 8.0, 2.0 / 8.0, 5.0 / 8.0].into_iter().enumerate() {
            let r = &per_light[idx];
            let m = r.len();
            assert!(
                (m as f64 / n as f64 - want_p).abs() < 1e-3,
                "light {idx}: {m} of {n}"
            );
            // Increasing with u, and within a grid step of the even spread.
            assert!(r.windows(2).all(|w| w[0] < w[1]), "light {idx}");
            for (j, &x) in r.iter().enumerate() {
                let even = (j as f64 + 0.5) / m as f64;
                assert!(
                    (x as f64 - even).abs() < 1.0 / m as f64,
                    "light {idx}: {j}th at {x}"
                );
            }
        }
        // The largest draw below 1 stays below 1 after the remap.
        let (_, _, rest) = world.choose_light(1.0 - f32::EPSILON / 2.0);
        assert!(rest < 1.0);
    }

    /// A point light 10⁸ dimmer than another, lighting a Lambertian floor
    /// that the bright one (below the floor) cannot reach: the floor's
    /// radiance is the closed form ρ/π · I·cosθ/r² of the dim light alone.
    /// With the f32 power-proportional table the dim light was never picked
    /// (10⁻⁸ < f32 resolution near 1) and the estimate was exactly 0.
    ///
    /// Only next-event estimation sees a point light, and it picks the dim
    /// one with probability p ≈ 5·10⁻⁴ (the floor 10⁻³/2), scoring L/p: over
    /// n paths the relative standard error is √((1−p)/(n·p)) ≈ 3.2 % for
    /// n = 2·10⁶; the tolerance is 5 of those.
    #[test]
    fn very_dim_point_light_beside_a_bright_one_is_unbiased() {
        const RHO: f64 = 0.5;
        const I_DIM: f64 = 1.0;
        let mut scene = Scene::default();
        let m = scene.material(
            "floor",
            Material::Diffuse {
                reflectance: Spectrum::constant("rho", RHO),
            },
        );
        let o = scene.object("floor");
        // u × v = X × Y = +Z: the floor z = 0 faces up.
        scene.meshes.push(quad(
            DVec3::ZERO,
            DVec3::X * 10.0,
            DVec3::Y * 10.0,
            m,
            o,
            None,
        ));
        let dim_at = DVec3::new(0.5, 0.0, 1.0);
        scene.lights.push(Light::Point {
            position: DVec3::new(0.0, 0.0, -1.0),
            intensity: Spectrum::constant("bright", 1e8 * I_DIM),
        });
        scene.lights.push(Light::Point {
            position: dim_at,
            intensity: Spectrum::constant("dim", I_DIM),
        });
        let grid = WavelengthGrid::new(500.0, 600.0, 50.0).unwrap();
        let world = World::build(&scene, &grid, BvhKind::Bvh4).unwrap();
        // The selection probability the floor promises (not read back from
        // the world: the tolerance must not widen if the floor is lost).
        let floor = 1e-3 / 2.0;
        let p = floor / (1.0 + floor);
        assert!((world.light_pmf[1] as f64 / p - 1.0).abs() < 1e-6);
        let r2 = dim_at.length_squared();
        let want = RHO / std::f64::consts::PI * I_DIM * (dim_at.z / r2.sqrt()) / r2;
        let n = 2_000_000u64;
        let nb = world.bands;
        let mut sc = Scratch::new(world.bands_padded);
        let mut sum = 0.0f64;
        for i in 0..n {
            sc.beta[..nb].fill(1.0);
            sc.beta[nb..].fill(0.0);
            let mut smp = Sampler::independent(Rng::for_sample(5, 0, i));
            trace(&world, Vec3::Z, -Vec3::Z, 1, None, &mut smp, &mut sc);
            sum += sc.l[0] as f64;
        }
        let got = sum / n as f64;
        let rel_se = ((1.0 - p) / (n as f64 * p)).sqrt();
        assert!(
            (got / want - 1.0).abs() < 5.0 * rel_se,
            "L = {got:e}, closed form {want:e} (±{:.1} %, selection p = {:e})",
            100.0 * rel_se,
            world.light_pmf[1]
        );
    }
}
