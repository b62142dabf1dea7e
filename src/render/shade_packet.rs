//! One bounce of a packet's Lambertian hits, shaded together in structure of
//! arrays (issue 17 item 1): the hit point and its error bound, the shading
//! frame, the offset ray origins, the light sample on a triangle area light
//! with its MIS weight and shadow ray (a light of another kind is sampled
//! lane by lane, by `World::sample_chosen_light` as `scatter` samples it),
//! and the cosine-weighted BSDF sample,
//! each computed for all sixteen lanes at once by a plain lane loop that the
//! render kernel's per-instruction-set copies (`simd.rs`) run 16, 8 or 4
//! lanes per instruction. What stays lane by lane is what is per lane by
//! nature: the table lookups (triangle, light choice), the sampler's draws,
//! emission (only lanes that hit an emitter) and the band vectors
//! (next-event contribution, throughput, Russian roulette).
//!
//! Which hits: a triangle with a `Diffuse` material, with or without vertex
//! normals, under lights of any kind (`World::hit_kind`). Before
//! 2026-11-29 only triangles without vertex normals in worlds whose lights
//! were all area lights on triangles: the paper's Cornell box meshes carry
//! normals, so its figures shaded every hit one lane at a time.
//! Every other hit goes through
//! `integrator::scatter` one lane at a time.
//!
//! Same bits as `scatter`: each lane loop calls the very scalar functions
//! `scatter` calls (`triangle_point`, `Frame`, `offset_ray_origin`,
//! `cosine_hemisphere`, `uniform_triangle`, `power_heuristic`, glam's `Vec3`
//! operations) in the same order; sqrt, division, multiplication and addition
//! are correctly rounded IEEE operations in every vector width and Rust never
//! contracts them into FMAs, and the one transcendental (sin/cos in the disk
//! map) is the project's own polynomial. The lanes take the same draws in the
//! same order as `scatter` (light choice and position, lobe, direction,
//! roulette). A branch `scatter` takes becomes a lane mask here: both sides
//! are computed, the lane keeps the side its own values choose.
//! `film::tests::every_isa_level_renders_the_same_bits` renders every
//! instruction-set level one path at a time and in packets and compares the
//! bits.

// Lane loops index several per-lane arrays at once.
#![allow(clippy::needless_range_loop)]

use super::bands;
use super::bsdf::Bsdf;
use super::geometry::{HIT_POINT_GAMMA, Shape, offset_ray_origin, triangle_point};
#[cfg(target_arch = "x86_64")]
use super::hit_lanes_avx512::{self, HitLanes};
use super::path::{PathState, SHADOW_EPS, ShadowRay, add_emitted, roulette};
use super::ray_packet::{LANES, LaneMask, PacketHits, RayPacket, lanes};
use super::sampler::Sampler;
#[cfg(target_arch = "x86_64")]
use super::sampler::{LaneDraws, bounce_draws_sobol_lanes};
use super::sampling::{Frame, cosine_hemisphere, power_heuristic, uniform_triangle};
use super::simd::RenderIsa;
use super::stages::{Clock, Stage};
use super::triangle_lights::Chosen;
use super::world::{LightKind, World};
use glam::Vec3;
use std::f32::consts::PI;

/// Sixteen `Vec3`s, one per lane, as three component arrays.
#[derive(Clone, Copy)]
#[repr(C, align(64))]
struct Lanes3 {
    x: [f32; LANES],
    y: [f32; LANES],
    z: [f32; LANES],
}

impl Lanes3 {
    /// Every lane `v`.
    #[inline(always)]
    fn splat(v: Vec3) -> Self {
        Lanes3 {
            x: [v.x; LANES],
            y: [v.y; LANES],
            z: [v.z; LANES],
        }
    }
    #[inline(always)]
    fn get(&self, l: usize) -> Vec3 {
        Vec3::new(self.x[l], self.y[l], self.z[l])
    }
    #[inline(always)]
    fn set(&mut self, l: usize, v: Vec3) {
        self.x[l] = v.x;
        self.y[l] = v.y;
        self.z[l] = v.z;
    }
}

/// A packet's band vectors: lane `l`'s throughput, radiance and pending
/// next-event contribution are `[l·stride, (l+1)·stride)` of each.
pub(super) struct LaneBands<'a> {
    pub stride: usize,
    pub beta: &'a mut [f32],
    pub l: &'a mut [f32],
    pub pend: &'a mut [f32],
}

/// Shade the hits of the lanes in `todo` (each shadable by `World::hit_kind`):
/// what `scatter` does for each of them, with the next-event shadow rays put
/// in `shadows` and their contributions in `bands.pend`, as `scatter` does
/// with a pending buffer. Returns the lanes whose paths ended. `isa`: the
/// kernel's instruction set; the AVX-512 kernel chooses the lights of
/// all lanes at once (`triangle_lights.rs`), the others lane by lane.
#[allow(clippy::too_many_arguments)]
#[inline(always)]
pub(super) fn shade_diffuse(
    world: &World,
    isa: RenderIsa,
    st: &mut [PathState; LANES],
    hits: &PacketHits,
    todo: LaneMask,
    max_bounces: u32,
    smp: &mut [Sampler],
    bands: LaneBands<'_>,
    shadows: &mut RayPacket,
) -> LaneMask {
    let LaneBands {
        stride,
        beta,
        l: rad,
        pend,
    } = bands;
    // Lanes outside `todo` keep a harmless unit triangle and ray.
    let mut v = [
        Lanes3::splat(Vec3::ZERO),
        Lanes3::splat(Vec3::X),
        Lanes3::splat(Vec3::Y),
    ];
    let mut bary = [[1.0f32; LANES], [0.0; LANES], [0.0; LANES]];
    let mut ng = Lanes3::splat(Vec3::Z);
    // The vertex normals of the lanes whose mesh has them (`has_n`).
    let mut vn = [Lanes3::splat(Vec3::Z); 3];
    let mut has_n = [false; LANES];
    let mut with_normals: LaneMask = 0;
    let mut dir = Lanes3::splat(-Vec3::Z);
    // The bounce's draws, in `scatter`'s order.
    let (mut u1, mut u2) = ([0.5f32; LANES], [0.5f32; LANES]);
    let (mut v1, mut v2, mut u_rr) = ([0.5f32; LANES], [0.5f32; LANES], [0f32; LANES]);
    let mut clock = Clock::start();
    let mut ended: LaneMask = 0;
    let mut go: LaneMask = 0;
    let mut emitters: LaneMask = 0;
    // Lanes whose bounce draws are all Sobol points (`Sampler::bounce_is_sobol`).
    let mut sobol: LaneMask = 0;
    #[cfg(target_arch = "x86_64")]
    let gathered = isa == RenderIsa::Avx512 && hit_lanes_avx512::fits(world);
    #[cfg(not(target_arch = "x86_64"))]
    let gathered = false;
    if gathered {
        #[cfg(target_arch = "x86_64")]
        {
            let [v0, v1, v2] = &mut v;
            let masks = {
                let out = HitLanes {
                    v: [
                        &mut v0.x, &mut v0.y, &mut v0.z, &mut v1.x, &mut v1.y, &mut v1.z,
                        &mut v2.x, &mut v2.y, &mut v2.z,
                    ],
                    bary: &mut bary,
                    ng: [&mut ng.x, &mut ng.y, &mut ng.z],
                    dir: [&mut dir.x, &mut dir.y, &mut dir.z],
                };
                // SAFETY: the AVX-512 kernel runs only where the CPU has
                // AVX-512F; `fits` checked above; the lanes of `todo` hit
                // triangles of `world` (`World::hit_kind`).
                unsafe { hit_lanes_avx512::hit_lanes(world, st, hits, todo, max_bounces, out) }
            };
            for i in lanes(masks.with_normals) {
                let n3 = world.normals[world.info[hits.prim[i] as usize].normals as usize];
                for (k, vk) in vn.iter_mut().enumerate() {
                    vk.set(i, n3[k]);
                }
                has_n[i] = true;
            }
            with_normals = masks.with_normals;
            emitters = masks.emitters;
            ended = masks.at_max_depth;
            go = todo & !masks.at_max_depth;
        }
    } else {
        for i in lanes(todo) {
            let prim = hits.prim[i];
            let Shape::Triangle { p } = world.accel.shapes[prim as usize] else {
                unreachable!("shade_diffuse is given triangles only (World::hit_kind)")
            };
            for (k, vk) in v.iter_mut().enumerate() {
                vk.set(i, p[k]);
                bary[k][i] = hits.h[i].b[k];
            }
            ng.set(i, world.triangle_normal(prim));
            dir.set(i, st[i].d);
            let info = world.info[prim as usize];
            if info.normals != u32::MAX {
                let n3 = world.normals[info.normals as usize];
                for (k, vk) in vn.iter_mut().enumerate() {
                    vk.set(i, n3[k]);
                }
                has_n[i] = true;
                with_normals |= 1 << i;
            }
            if info.light != u32::MAX {
                emitters |= 1 << i;
            }
            if st[i].depth >= max_bounces {
                ended |= 1 << i;
                continue;
            }
            go |= 1 << i;
        }
    }
    // The bounce's draws (the lobe's is taken and not used): the lanes
    // whose draws are all Sobol points, then the others. The AVX-512 kernel
    // takes the Sobol lanes' draws with gathers (`bounce_draws_sobol_lanes`).
    let lane_samplers = if gathered {
        <&mut [Sampler; LANES]>::try_from(&mut *smp).ok()
    } else {
        None
    };
    if let Some(smps) = lane_samplers {
        #[cfg(target_arch = "x86_64")]
        {
            let out = LaneDraws {
                light: [&mut u1, &mut u2],
                dir: [&mut v1, &mut v2],
                rr: &mut u_rr,
            };
            // SAFETY: the AVX-512 kernel runs only where the CPU has AVX-512F.
            sobol = unsafe { bounce_draws_sobol_lanes(smps, go, out) };
        }
        #[cfg(not(target_arch = "x86_64"))]
        let _ = smps;
    } else {
        for i in lanes(go) {
            sobol |= (smp[i].bounce_is_sobol() as LaneMask) << i;
        }
        for i in lanes(go & sobol) {
            let d = smp[i].bounce_draws_sobol();
            ((u1[i], u2[i]), (v1[i], v2[i]), u_rr[i]) = (d.light, d.dir, d.rr);
        }
    }
    for i in lanes(go & !sobol) {
        let d = smp[i].bounce_draws();
        ((u1[i], u2[i]), (v1[i], v2[i]), u_rr[i]) = (d.light, d.dir, d.rr);
    }

    clock.lap(Stage::ShadeLanes);
    // The shading normal, as `scatter` takes it: interpolated from the
    // vertex normals and turned to the geometric normal's side, or the
    // geometric normal (lanes without normals, or whose interpolation
    // vanishes). Skipped when no lane has vertex normals.
    let mut ns_lanes = Lanes3::splat(Vec3::Z);
    let ns_src = if with_normals != 0 {
        for l in 0..LANES {
            let n = ng.get(l);
            let ni =
                (vn[0].get(l) * bary[0][l] + vn[1].get(l) * bary[1][l] + vn[2].get(l) * bary[2][l])
                    .normalize_or_zero();
            let interp = if ni.dot(n) < 0.0 { -ni } else { ni };
            ns_lanes.set(
                l,
                if has_n[l] && ni != Vec3::ZERO {
                    interp
                } else {
                    n
                },
            );
        }
        &ns_lanes
    } else {
        &ng
    };
    // The hit, its frame, the BSDF sample and the continuation ray, all lanes;
    // with the ray's length and the cosine at the hit for emission.
    let mut pt = Lanes3::splat(Vec3::ZERO);
    let mut ng_s = Lanes3::splat(Vec3::Z);
    let mut fs = Lanes3::splat(Vec3::X);
    let mut ft = Lanes3::splat(Vec3::Y);
    let mut fnrm = Lanes3::splat(Vec3::Z);
    let mut origin_front = Lanes3::splat(Vec3::ZERO);
    let mut next_o = Lanes3::splat(Vec3::ZERO);
    let mut next_d = Lanes3::splat(Vec3::Z);
    let mut wo_z = [0f32; LANES];
    let mut bsdf_pdf = [0f32; LANES];
    let mut cont = [false; LANES];
    let (mut ray_len, mut cos_hit) = ([0f32; LANES], [0f32; LANES]);
    for l in 0..LANES {
        let (p, p_err) = triangle_point(
            &[v[0].get(l), v[1].get(l), v[2].get(l)],
            [bary[0][l], bary[1][l], bary[2][l]],
            HIT_POINT_GAMMA,
        );
        let d = dir.get(l);
        let dlen = d.length();
        let wo_w = -d / dlen;
        let n = ng.get(l);
        let cos = n.dot(wo_w);
        // Opaque: face the normals towards wo (`n_s` geometric, the
        // frame's the shading normal).
        let nsh = ns_src.get(l);
        let (n_s, ns_s) = if cos < 0.0 { (-n, -nsh) } else { (n, nsh) };
        let frame = Frame::from_normal(ns_s);
        let wo = frame.to_local(wo_w);
        let front = offset_ray_origin(p, p_err, n_s, n_s);
        let wi = cosine_hemisphere(v1[l], v2[l]);
        let pdf = wi.z / PI;
        let wi_w = frame.to_world(wi).normalize();
        let same_side = wi_w.dot(n_s) * wo_w.dot(n_s) > 0.0;
        let refl_local = wi.z * wo.z > 0.0;
        cont[l] = !(wi.z <= 0.0 || wo.z <= 0.0)
            && (pdf > 0.0 && pdf.is_finite())
            && same_side == refl_local;
        let o_next = if wi_w.dot(n_s) >= 0.0 {
            front
        } else {
            offset_ray_origin(p, p_err, n_s, wi_w)
        };
        pt.set(l, p);
        ng_s.set(l, n_s);
        fs.set(l, frame.s);
        ft.set(l, frame.t);
        fnrm.set(l, frame.n);
        origin_front.set(l, front);
        next_o.set(l, o_next);
        next_d.set(l, wi_w);
        wo_z[l] = wo.z;
        bsdf_pdf[l] = pdf;
        (ray_len[l], cos_hit[l]) = (dlen, cos);
    }

    clock.lap(Stage::ShadeHit);
    // Emission (lanes that hit an emitter), before the throughput changes.
    for i in lanes(emitters) {
        let span = i * stride..(i + 1) * stride;
        add_emitted(
            world,
            &st[i],
            world.info[hits.prim[i] as usize].light,
            cos_hit[i],
            hits.h[i].t * ray_len[i],
            &beta[span.clone()],
            &mut rad[span],
        );
    }
    clock.lap(Stage::ShadeEmission);
    if go == 0 {
        return ended;
    }

    // The light each lane samples (next-event estimation needs wo.z > 0).
    let mut lv = [
        Lanes3::splat(Vec3::ZERO),
        Lanes3::splat(Vec3::X),
        Lanes3::splat(Vec3::Y),
    ];
    let mut nl = Lanes3::splat(Vec3::Z);
    let (mut sel, mut area) = ([1f32; LANES], [1f32; LANES]);
    let mut two_sided = [false; LANES];
    let mut light = [0usize; LANES];
    let mut nee: LaneMask = 0;
    // Lanes whose light is not an area light on a triangle: sampled one by
    // one after the lane loop below.
    let mut other: LaneMask = 0;
    // The AVX-512 kernel chooses for all lanes at once where the world has
    // a table of triangle lights.
    let chosen = match world.tri_lights.as_ref() {
        Some(t) => {
            let [l0, l1, l2] = &mut lv;
            t.choose(
                isa,
                go,
                &wo_z,
                &mut u1,
                Chosen {
                    light: &mut light,
                    sel: &mut sel,
                    v: [
                        [&mut l0.x, &mut l0.y, &mut l0.z],
                        [&mut l1.x, &mut l1.y, &mut l1.z],
                        [&mut l2.x, &mut l2.y, &mut l2.z],
                    ],
                    ng: [&mut nl.x, &mut nl.y, &mut nl.z],
                    area: &mut area,
                    two_sided: &mut two_sided,
                },
            )
        }
        None => None,
    };
    if let Some(took) = chosen {
        nee |= took;
    } else if !world.lights.is_empty() {
        for i in lanes(go) {
            if !(wo_z[i] > 0.0) {
                continue;
            }
            let (idx, s, u_rest) = world.choose_light(u1[i]);
            u1[i] = u_rest;
            if !(s > 0.0) {
                continue;
            }
            (sel[i], light[i]) = (s, idx);
            nee |= 1 << i;
            if let LightKind::Area {
                prim,
                two_sided: ts,
                area: a,
                ..
            } = world.lights[idx]
                && let Shape::Triangle { p } = world.accel.shapes[prim as usize]
            {
                for (k, vk) in lv.iter_mut().enumerate() {
                    vk.set(i, p[k]);
                }
                nl.set(i, world.triangle_normal(prim));
                (area[i], two_sided[i]) = (a, ts);
            } else {
                other |= 1 << i;
            }
        }
    }
    clock.lap(Stage::ShadeLightChoice);
    let mut shadow_d = Lanes3::splat(Vec3::Z);
    let mut tmax = [0f32; LANES];
    let mut scale = [0f32; LANES];
    // Per lane: a shadow ray whose contribution is added if it is unblocked.
    let mut nee_ok = [false; LANES];
    if nee != 0 {
        for l in 0..LANES {
            let (b0, b1, b2) = uniform_triangle(u1[l], u2[l]);
            let (pl, err_l) =
                triangle_point(&[lv[0].get(l), lv[1].get(l), lv[2].get(l)], [b0, b1, b2], 6);
            let n_l = nl.get(l);
            let d = pl - pt.get(l);
            let dist2 = d.length_squared();
            let wi = d / dist2.sqrt();
            let c = -n_l.dot(wi);
            let cos_l = c.abs();
            let pdf = sel[l] * dist2 / (cos_l * area[l]);
            // `c > 0.0 || two_sided` is `sample_light`'s `!(c <= 0.0 && !two_sided)`
            // but for a NaN `c`, which `cos_l > 0.0` rejects either way.
            let light_ok = dist2 > 0.0
                && (c > 0.0 || two_sided[l])
                && cos_l > 0.0
                && pdf > 0.0
                && pdf.is_finite();
            let n_s = ng_s.get(l);
            let frame = Frame {
                s: fs.get(l),
                t: ft.get(l),
                n: fnrm.get(l),
            };
            let wil = frame.to_local(wi);
            let facing = wil.z > 0.0 && wi.dot(n_s) > 0.0;
            let tgt = if n_l == Vec3::ZERO {
                pl
            } else {
                offset_ray_origin(pl, err_l, n_l, -wi)
            };
            let dv = tgt - origin_front.get(l);
            let len = dv.length();
            let pdf_b = wil.z / PI;
            let w = power_heuristic(pdf, pdf_b);
            nee_ok[l] = light_ok && facing && len > 0.0;
            shadow_d.set(l, dv / len);
            tmax[l] = len * (1.0 - SHADOW_EPS);
            scale[l] = wil.z * w / pdf;
        }
    }
    // The other lights' samples (point, spot, distant, infinite, area lights
    // on spheres and disks), lane by lane, as `scatter` takes them.
    for i in lanes(other) {
        let frame = Frame {
            s: fs.get(i),
            t: ft.get(i),
            n: fnrm.get(i),
        };
        let ls = world.sample_chosen_light(light[i], sel[i], pt.get(i), u1[i], u2[i]);
        nee_ok[i] = false;
        let Some(ls) = ls else { continue };
        let wil = frame.to_local(ls.wi);
        if !(wil.z > 0.0 && ls.wi.dot(ng_s.get(i)) > 0.0) {
            continue;
        }
        let Some(r) = ShadowRay::towards(origin_front.get(i), &ls) else {
            continue;
        };
        nee_ok[i] = true;
        shadow_d.set(i, r.d);
        tmax[i] = r.tmax;
        scale[i] = ls.next_event_scale(wil.z, wil.z / PI);
    }

    clock.lap(Stage::ShadeNextEvent);
    // Per lane: the band vectors and the path's state.
    let nb = world.bands;
    for i in lanes(go) {
        let span = i * stride..(i + 1) * stride;
        let Bsdf::Diffuse { r } = &world.bsdfs[world.info[hits.prim[i] as usize].material as usize]
        else {
            unreachable!("shade_diffuse is given Lambertian hits only (World::hit_kind)")
        };
        if nee & (1 << i) != 0 && nee_ok[i] {
            let le = world.lights[light[i]].spectrum();
            bands::lambert_next_event(
                &mut pend[span.clone()],
                &beta[span.clone()],
                r,
                le,
                scale[i],
            );
            shadows.set(i, origin_front.get(i), shadow_d.get(i), tmax[i]);
        }
        if !cont[i] {
            ended |= 1 << i;
            continue;
        }
        let b = &mut beta[span];
        let top = bands::mul_max(b, r);
        let s = &mut st[i];
        s.specular = false;
        s.prev_pdf = bsdf_pdf[i];
        s.o = next_o.get(i);
        s.d = next_d.get(i);
        s.depth += 1;
        ended |= (!roulette(s, nb, top, u_rr[i], b) as LaneMask) << i;
    }
    clock.lap(Stage::ShadeBands);
    ended
}
