//! The lights of a world lit by one to four triangle area lights, as one
//! table (`TriangleLights`), so that the AVX-512 kernel chooses every lane's
//! light at once (`choose_avx512`): mask operations instead of the light-
//! choice lane loop of `shade_packet.rs`, which stays for every other world
//! and instruction set.
//!
//! Same bits as `World::choose_light` followed by the light's triangle: the
//! light is the first entry of the cumulative table above the draw
//! (`sampling::sample_cdf`; the table is non-decreasing, so that is the
//! light whose entries below are at or below the draw and whose own entry is
//! above it, the last light when none is), and the draw is remapped within
//! the light's slice as `world::remap_in_slice` does, with the same IEEE
//! operations (subtraction, division, the clamp's two comparisons).
//!
//! Why intrinsics: written as portable lane code, LLVM vectorised the
//! choice along the wrong axis (across the lights, or across the looked-up
//! quantities with masked scatters) or left it scalar, and it lost 3–15 %
//! (docs/performance.md, *Eighteenth pass*).

// The light loops index the table's per-light arrays and the masks together.
#![allow(clippy::needless_range_loop)]

use super::geometry::Shape;
use super::ray_packet::{LANES, LaneMask};
use super::world::LightKind;
use glam::Vec3;

/// At most this many lights go in the table.
const MAX_LIGHTS: usize = 4;

/// Per light k < n: its slice [lo, hi) of the cumulative table, selection
/// probability, triangle, unit geometric normal, area and sidedness.
pub(super) struct TriangleLights {
    n: usize,
    lo: [f32; MAX_LIGHTS],
    hi: [f32; MAX_LIGHTS],
    pmf: [f32; MAX_LIGHTS],
    v: [[Vec3; 3]; MAX_LIGHTS],
    ng: [Vec3; MAX_LIGHTS],
    area: [f32; MAX_LIGHTS],
    two_sided: [bool; MAX_LIGHTS],
}

/// Where `choose_avx512` writes, per lane: the light's index, selection
/// probability, vertices (x, y, z columns of each), normal, area and
/// sidedness. Lanes that sample no light keep what they held.
pub(super) struct Chosen<'a> {
    pub light: &'a mut [usize; LANES],
    pub sel: &'a mut [f32; LANES],
    pub v: [[&'a mut [f32; LANES]; 3]; 3],
    pub ng: [&'a mut [f32; LANES]; 3],
    pub area: &'a mut [f32; LANES],
    pub two_sided: &'a mut [bool; LANES],
}

impl TriangleLights {
    /// The table, when every light is an area light on a triangle and there
    /// are 1 to `MAX_LIGHTS` of them (`pmf`, `cdf`: the world's selection
    /// table; `tri_ng`: each primitive's unit normal).
    pub(super) fn build(
        lights: &[LightKind],
        pmf: &[f32],
        cdf: &[f32],
        shapes: &[Shape],
        tri_ng: &[Vec3],
    ) -> Option<Self> {
        let n = lights.len();
        if n == 0 || n > MAX_LIGHTS {
            return None;
        }
        let mut t = TriangleLights {
            n,
            lo: [0.0; MAX_LIGHTS],
            hi: [0.0; MAX_LIGHTS],
            pmf: [0.0; MAX_LIGHTS],
            v: [[Vec3::ZERO; 3]; MAX_LIGHTS],
            ng: [Vec3::ZERO; MAX_LIGHTS],
            area: [0.0; MAX_LIGHTS],
            two_sided: [false; MAX_LIGHTS],
        };
        for (k, l) in lights.iter().enumerate() {
            let LightKind::Area {
                prim,
                two_sided,
                area,
                ..
            } = *l
            else {
                return None;
            };
            let Shape::Triangle { p } = shapes[prim as usize] else {
                return None;
            };
            t.lo[k] = if k == 0 { 0.0 } else { cdf[k - 1] };
            t.hi[k] = cdf[k];
            t.pmf[k] = pmf[k];
            t.v[k] = p;
            t.ng[k] = tri_ng[prim as usize];
            t.area[k] = area;
            t.two_sided[k] = two_sided;
        }
        Some(t)
    }

    /// Choose the light of the lanes of `go` whose `wo_z` is positive, with
    /// their draws `u1` (remapped in place, as `World::choose_light` remaps
    /// them), and write what the lanes whose light has a positive
    /// probability sample into `out`. Returns those lanes.
    ///
    /// # Safety
    /// The CPU must have AVX-512 F, VL, BW and DQ (`RenderIsa::Avx512`).
    #[cfg(target_arch = "x86_64")]
    #[target_feature(enable = "avx512f,avx512vl,avx512bw,avx512dq")]
    #[inline]
    pub(super) unsafe fn choose_avx512(
        &self,
        go: LaneMask,
        wo_z: &[f32; LANES],
        u1: &mut [f32; LANES],
        out: Chosen<'_>,
    ) -> LaneMask {
        use std::arch::x86_64::*;
        // SAFETY: 16-float loads and stores of 16-float arrays; the
        // features are the caller's guarantee.
        unsafe {
            let zero = _mm512_setzero_ps();
            let ask = (go as __mmask16)
                & _mm512_cmp_ps_mask::<_CMP_GT_OQ>(_mm512_loadu_ps(wo_z.as_ptr()), zero);
            let u = _mm512_loadu_ps(u1.as_ptr());
            // Light k: entries below k at or below the draw, entry k above it.
            let mut pick = [0 as __mmask16; MAX_LIGHTS];
            let mut below_prev: __mmask16 = 0xFFFF;
            for k in 0..self.n {
                let below = if k + 1 < self.n {
                    _mm512_cmp_ps_mask::<_CMP_LE_OQ>(_mm512_set1_ps(self.hi[k]), u)
                } else {
                    0
                };
                pick[k] = below_prev & !below;
                below_prev = below;
            }
            let each = |f: &dyn Fn(usize) -> f32| {
                let mut q = _mm512_set1_ps(f(0));
                for k in 1..self.n {
                    q = _mm512_mask_mov_ps(q, pick[k], _mm512_set1_ps(f(k)));
                }
                q
            };
            let (lo, hi, pm) = (
                each(&|k| self.lo[k]),
                each(&|k| self.hi[k]),
                each(&|k| self.pmf[k]),
            );
            // `remap_in_slice`: ((u − lo) / width).clamp(0, ONE_MINUS_EPSILON)
            // when width > 0, else 0.
            let width = _mm512_sub_ps(hi, lo);
            let r = _mm512_div_ps(_mm512_sub_ps(u, lo), width);
            let top = _mm512_set1_ps(super::world::ONE_MINUS_EPSILON);
            let r = _mm512_mask_mov_ps(r, _mm512_cmp_ps_mask::<_CMP_LT_OQ>(r, zero), zero);
            let r = _mm512_mask_mov_ps(r, _mm512_cmp_ps_mask::<_CMP_GT_OQ>(r, top), top);
            let rest = _mm512_maskz_mov_ps(_mm512_cmp_ps_mask::<_CMP_GT_OQ>(width, zero), r);
            _mm512_mask_storeu_ps(u1.as_mut_ptr(), ask, rest);
            let take = ask & _mm512_cmp_ps_mask::<_CMP_GT_OQ>(pm, zero);
            _mm512_mask_storeu_ps(out.sel.as_mut_ptr(), take, pm);
            let [v0, v1, v2] = out.v;
            for (j, [x, y, z]) in [v0, v1, v2].into_iter().enumerate() {
                _mm512_mask_storeu_ps(x.as_mut_ptr(), take, each(&|k| self.v[k][j].x));
                _mm512_mask_storeu_ps(y.as_mut_ptr(), take, each(&|k| self.v[k][j].y));
                _mm512_mask_storeu_ps(z.as_mut_ptr(), take, each(&|k| self.v[k][j].z));
            }
            let [nx, ny, nz] = out.ng;
            _mm512_mask_storeu_ps(nx.as_mut_ptr(), take, each(&|k| self.ng[k].x));
            _mm512_mask_storeu_ps(ny.as_mut_ptr(), take, each(&|k| self.ng[k].y));
            _mm512_mask_storeu_ps(nz.as_mut_ptr(), take, each(&|k| self.ng[k].z));
            _mm512_mask_storeu_ps(out.area.as_mut_ptr(), take, each(&|k| self.area[k]));
            let mut t = take as LaneMask;
            while t != 0 {
                let l = t.trailing_zeros() as usize;
                t &= t - 1;
                let k = (0..self.n).find(|&k| pick[k] & (1 << l) != 0).unwrap_or(0);
                out.light[l] = k;
                out.two_sided[l] = self.two_sided[k];
            }
            take as LaneMask
        }
    }
}

#[cfg(all(test, target_arch = "x86_64"))]
mod tests {
    use super::*;
    use crate::render::BvhKind;
    use crate::render::sampling::Rng;
    use crate::render::simd::RenderIsa;
    use crate::render::world::World;
    use crate::scene::shapes::quad;
    use crate::scene::{Emission, Material, Scene};
    use crate::spectrum::{Spectrum, WavelengthGrid};
    use glam::DVec3;

    /// A world lit by one triangle light per entry of `radiances`, each half
    /// of a unit square at its own height (odd ones two-sided).
    fn lit(radiances: &[f64]) -> World {
        let mut scene = Scene::default();
        let m = scene.material(
            "black",
            Material::Diffuse {
                reflectance: Spectrum::constant("zero", 0.0),
            },
        );
        for (k, &le) in radiances.iter().enumerate() {
            let o = scene.object(&format!("light{k}"));
            let mut q = quad(
                DVec3::new(0.0, 0.0, 1.0 + k as f64),
                DVec3::X * (0.5 + 0.1 * k as f64),
                DVec3::Y * 0.5,
                m,
                o,
                Some(Emission {
                    radiance: Spectrum::constant("le", le),
                    two_sided: k % 2 == 1,
                }),
            );
            q.indices.truncate(1);
            scene.meshes.push(q);
        }
        let grid = WavelengthGrid::new(500.0, 600.0, 50.0).unwrap();
        World::build(&scene, &grid, BvhKind::Bvh4).unwrap()
    }

    /// Every lane's choice equals `World::choose_light` and the light's own
    /// triangle, normal, area and sidedness; lanes not asked, or whose light
    /// has no probability, keep what they held; draws on the table's
    /// entries choose as `sample_cdf` does.
    #[test]
    fn every_lane_chooses_as_choose_light() {
        if !RenderIsa::Avx512.supported() {
            eprintln!("skipped: no AVX-512");
            return;
        }
        let mut rng = Rng::for_sample(5, 0, 0);
        for radiances in [
            vec![1.0],
            vec![1.0, 3.0],
            vec![2.0, 0.0, 5.0],
            vec![1.0, 1.0, 0.5, 4.0],
        ] {
            let w = lit(&radiances);
            let t = w
                .tri_lights
                .as_ref()
                .expect("a table for 1 to 4 triangle lights");
            for round in 0..200 {
                let mut u1 = [0f32; LANES];
                let mut wo_z = [1f32; LANES];
                for l in 0..LANES {
                    u1[l] = if round == 0 && l < w.light_cdf.len() {
                        w.light_cdf[l]
                    } else {
                        rng.uniform()
                    };
                    if l % 5 == 3 {
                        wo_z[l] = -0.5;
                    }
                }
                let go: LaneMask = 0xFFFF & !(1 << 7);
                let before = u1;
                let (mut light, mut sel, mut area) =
                    ([99usize; LANES], [-1f32; LANES], [-2f32; LANES]);
                let mut v = [[[-3f32; LANES]; 3]; 3];
                let mut ng = [[-4f32; LANES]; 3];
                let mut ts = [true; LANES];
                let [v0, v1, v2] = &mut v;
                let [v0x, v0y, v0z] = v0;
                let [v1x, v1y, v1z] = v1;
                let [v2x, v2y, v2z] = v2;
                let [nx, ny, nz] = &mut ng;
                // SAFETY: AVX-512 checked above.
                let took = unsafe {
                    t.choose_avx512(
                        go,
                        &wo_z,
                        &mut u1,
                        Chosen {
                            light: &mut light,
                            sel: &mut sel,
                            v: [[v0x, v0y, v0z], [v1x, v1y, v1z], [v2x, v2y, v2z]],
                            ng: [nx, ny, nz],
                            area: &mut area,
                            two_sided: &mut ts,
                        },
                    )
                };
                for l in 0..LANES {
                    let asked = go & (1 << l) != 0 && wo_z[l] > 0.0;
                    if !asked {
                        assert_eq!(u1[l].to_bits(), before[l].to_bits());
                        assert_eq!(took & (1 << l), 0);
                        assert_eq!(light[l], 99);
                        continue;
                    }
                    let (idx, s, rest) = w.choose_light(before[l]);
                    assert_eq!(u1[l].to_bits(), rest.to_bits(), "draw {}", before[l]);
                    if !(s > 0.0) {
                        assert_eq!(took & (1 << l), 0);
                        assert_eq!((light[l], sel[l]), (99, -1.0));
                        continue;
                    }
                    assert_ne!(took & (1 << l), 0);
                    assert_eq!((light[l], sel[l].to_bits()), (idx, s.to_bits()));
                    let LightKind::Area {
                        prim,
                        two_sided,
                        area: a,
                        ..
                    } = w.lights[idx]
                    else {
                        unreachable!()
                    };
                    let Shape::Triangle { p } = w.accel.shapes[prim as usize] else {
                        unreachable!()
                    };
                    for j in 0..3 {
                        assert_eq!([v[j][0][l], v[j][1][l], v[j][2][l]], p[j].to_array());
                    }
                    assert_eq!(
                        [ng[0][l], ng[1][l], ng[2][l]],
                        w.triangle_normal(prim).to_array()
                    );
                    assert_eq!((area[l], ts[l]), (a, two_sided));
                }
            }
        }
    }
}
