//! Surface scattering on the wavelength grid.
//!
//! All BSDFs work in a local shading frame with the normal on +z. Spectral
//! values are `&mut [f32]` of the grid length (all bands of the path at once);
//! sampling decisions use band-independent probabilities, so the same
//! direction serves every band and a non-dispersive scene has no colour noise.
//! A dispersive dielectric needs one wavelength: the integrator then passes
//! `hero = Some(band)` and only that band is meaningful.
//!
//! `DiffuseSpecular` (the paper's walls and cubes, pbrt-v3 `uber` Kd/Ks) is a
//! Lambertian lobe plus a GGX (Trowbridge–Reitz) microfacet lobe with a
//! dielectric Fresnel term for η = 1.5 (as pbrt-v3's uber), Smith shadowing.
//! The lobes are sampled in proportion to their mean albedo estimate (kd vs ks)
//! and the pdf is the matching mixture, so MIS stays exact.

use glam::Vec3;
use std::f32::consts::PI;

/// A material resampled onto the render grid.
#[derive(Clone, Debug)]
pub enum Bsdf {
    Diffuse {
        r: Vec<f32>,
    },
    DiffuseSpecular {
        kd: Vec<f32>,
        ks: Vec<f32>,
        alpha: f32,
        p_spec: f32,
    },
    Mirror {
        r: Vec<f32>,
    },
    Dielectric {
        eta: Vec<f32>,
        dispersive: bool,
    },
    Conductor {
        eta: Vec<f32>,
        k: Vec<f32>,
        alpha: f32,
    },
    Black,
}

/// Outcome of sampling: direction (local), pdf (solid angle; 0 for… never —
/// delta lobes report pdf = 1 and `delta = true`), and `weight` = f·|cos|/pdf
/// written into the caller's buffer.
#[derive(Clone, Copy, Debug)]
pub struct BsdfSample {
    pub wi: Vec3,
    pub pdf: f32,
    pub delta: bool,
    /// Relative index of refraction crossed (1 for reflection), for RR scaling.
    pub eta_scale: f32,
}

/// Smallest microfacet alpha; below it a lobe is treated as smooth-ish but
/// still sampled as a (very sharp) microfacet lobe to keep MIS finite.
const MIN_ALPHA: f32 = 1e-3;

#[inline]
fn ggx_d(h: Vec3, alpha: f32) -> f32 {
    let c2 = h.z * h.z;
    let a2 = alpha * alpha;
    let den = c2 * (a2 - 1.0) + 1.0;
    a2 / (PI * den * den)
}
#[inline]
fn smith_g1(w: Vec3, alpha: f32) -> f32 {
    let c2 = w.z * w.z;
    if c2 <= 0.0 {
        return 0.0;
    }
    let t2 = (1.0 - c2).max(0.0) / c2;
    2.0 / (1.0 + (1.0 + alpha * alpha * t2).sqrt())
}
#[inline]
fn ggx_sample_h(alpha: f32, u: f32, v: f32) -> Vec3 {
    let t2 = alpha * alpha * u / (1.0 - u).max(1e-12);
    let cos = 1.0 / (1.0 + t2).sqrt();
    let sin = (1.0 - cos * cos).max(0.0).sqrt();
    let phi = 2.0 * PI * v;
    Vec3::new(sin * phi.cos(), sin * phi.sin(), cos)
}

/// Unpolarised Fresnel reflectance of a dielectric interface; `eta` = η_t/η_i,
/// `cos_i` ≥ 0 on the incident side.
#[inline]
pub fn fresnel_dielectric(cos_i: f32, eta: f32) -> f32 {
    let cos_i = cos_i.clamp(0.0, 1.0);
    let sin2_t = (1.0 - cos_i * cos_i) / (eta * eta);
    if sin2_t >= 1.0 {
        return 1.0;
    }
    let cos_t = (1.0 - sin2_t).max(0.0).sqrt();
    let rs = (cos_i - eta * cos_t) / (cos_i + eta * cos_t);
    let rp = (eta * cos_i - cos_t) / (eta * cos_i + cos_t);
    0.5 * (rs * rs + rp * rp)
}

/// Unpolarised Fresnel reflectance of a conductor with complex index η + ik.
#[inline]
pub fn fresnel_conductor(cos_i: f32, eta: f32, k: f32) -> f32 {
    let c = cos_i.clamp(0.0, 1.0) as f64;
    let (eta, k) = (eta as f64, k as f64);
    let c2 = c * c;
    let s2 = 1.0 - c2;
    let e2 = eta * eta;
    let k2 = k * k;
    let t0 = e2 - k2 - s2;
    let a2b2 = (t0 * t0 + 4.0 * e2 * k2).sqrt();
    let t1 = a2b2 + c2;
    let a = (0.5 * (a2b2 + t0)).max(0.0).sqrt();
    let t2 = 2.0 * c * a;
    let rs = (t1 - t2) / (t1 + t2);
    let t3 = c2 * a2b2 + s2 * s2;
    let t4 = t2 * s2;
    let rp = rs * (t3 - t4) / (t3 + t4);
    (0.5 * (rp + rs)) as f32
}

/// Mean of a band vector (0 when empty); also the light powers in `world.rs`.
pub(super) fn mean(v: &[f32]) -> f32 {
    if v.is_empty() {
        0.0
    } else {
        v.iter().sum::<f32>() / v.len() as f32
    }
}

impl Bsdf {
    /// Extend every spectrum to `n` bands (`n` ≥ the grid length) so the
    /// integrator's band loops run over a multiple of the SIMD width without
    /// a scalar tail. Reflectances pad with 0; indices of refraction and
    /// extinction with their last band (finite, never used: the path's
    /// throughput is 0 in the padding bands).
    pub fn pad_bands(&mut self, n: usize) {
        let pad_last = |v: &mut Vec<f32>| {
            let last = v.last().copied().unwrap_or(1.0);
            v.resize(n.max(v.len()), last);
        };
        match self {
            Bsdf::Diffuse { r } | Bsdf::Mirror { r } => r.resize(n.max(r.len()), 0.0),
            Bsdf::DiffuseSpecular { kd, ks, .. } => {
                kd.resize(n.max(kd.len()), 0.0);
                ks.resize(n.max(ks.len()), 0.0);
            }
            Bsdf::Dielectric { eta, .. } => pad_last(eta),
            Bsdf::Conductor { eta, k, .. } => {
                pad_last(eta);
                pad_last(k);
            }
            Bsdf::Black => {}
        }
    }

    pub fn diffuse_specular(kd: Vec<f32>, ks: Vec<f32>, roughness: f32) -> Self {
        let md = mean(&kd).max(0.0);
        let ms = mean(&ks).max(0.0);
        let p_spec = if md + ms > 0.0 {
            (ms / (md + ms)).clamp(0.05, 0.95)
        } else {
            0.5
        };
        Bsdf::DiffuseSpecular {
            kd,
            ks,
            alpha: roughness.max(MIN_ALPHA),
            p_spec,
        }
    }

    /// True when the BSDF has only delta lobes (NEE is pointless).
    pub fn is_delta(&self) -> bool {
        match self {
            Bsdf::Mirror { .. } | Bsdf::Dielectric { .. } => true,
            Bsdf::Conductor { alpha, .. } => *alpha <= 0.0,
            _ => false,
        }
    }
    pub fn is_black(&self) -> bool {
        matches!(self, Bsdf::Black)
    }
    /// True for materials that transmit (the shading frame must not be flipped).
    pub fn is_transmissive(&self) -> bool {
        matches!(self, Bsdf::Dielectric { .. })
    }
    pub fn is_dispersive(&self) -> bool {
        matches!(
            self,
            Bsdf::Dielectric {
                dispersive: true,
                ..
            }
        )
    }

    /// Evaluate f(wo, wi) into `f` (no cosine) and return the sampling pdf of wi.
    /// Both directions local, wo.z > 0 (reflection-only materials).
    pub fn eval(&self, wo: Vec3, wi: Vec3, f: &mut [f32]) -> f32 {
        if wo.z <= 0.0 || wi.z <= 0.0 {
            f.iter_mut().for_each(|x| *x = 0.0);
            return 0.0;
        }
        match self {
            Bsdf::Diffuse { r } => {
                for (o, &ri) in f.iter_mut().zip(r) {
                    *o = ri * (1.0 / PI);
                }
                wi.z / PI
            }
            Bsdf::DiffuseSpecular {
                kd,
                ks,
                alpha,
                p_spec,
            } => {
                let h = (wo + wi).normalize();
                let d = ggx_d(h, *alpha);
                let g = smith_g1(wo, *alpha) * smith_g1(wi, *alpha);
                let fr = fresnel_dielectric(wi.dot(h), 1.5);
                let spec = d * g * fr / (4.0 * wo.z * wi.z);
                for ((o, &a), &b) in f.iter_mut().zip(kd).zip(ks) {
                    *o = a * (1.0 / PI) + b * spec;
                }
                let pdf_spec = d * h.z / (4.0 * wo.dot(h));
                (1.0 - p_spec) * wi.z / PI + p_spec * pdf_spec
            }
            Bsdf::Conductor { eta, k, alpha } if *alpha > 0.0 => {
                let h = (wo + wi).normalize();
                let d = ggx_d(h, *alpha);
                let g = smith_g1(wo, *alpha) * smith_g1(wi, *alpha);
                let s = d * g / (4.0 * wo.z * wi.z);
                let c = wi.dot(h);
                for ((o, &e), &kk) in f.iter_mut().zip(eta).zip(k) {
                    *o = fresnel_conductor(c, e, kk) * s;
                }
                d * h.z / (4.0 * wo.dot(h))
            }
            _ => {
                f.iter_mut().for_each(|x| *x = 0.0);
                0.0
            }
        }
    }

    /// Sample wi given wo (local). Writes f·|cos|/pdf into `w`. For the
    /// dielectric, wo.z may be negative (inside); elsewhere wo.z > 0.
    pub fn sample(
        &self,
        wo: Vec3,
        u0: f32,
        u1: f32,
        u2: f32,
        hero: Option<usize>,
        w: &mut [f32],
    ) -> Option<BsdfSample> {
        match self {
            Bsdf::Diffuse { r } => {
                let wi = crate::render::sampling::cosine_hemisphere(u1, u2);
                if wi.z <= 0.0 || wo.z <= 0.0 {
                    return None;
                }
                w.copy_from_slice(r);
                Some(BsdfSample {
                    wi,
                    pdf: wi.z / PI,
                    delta: false,
                    eta_scale: 1.0,
                })
            }
            Bsdf::DiffuseSpecular { alpha, p_spec, .. } => {
                if wo.z <= 0.0 {
                    return None;
                }
                let wi = if u0 < *p_spec {
                    let h = ggx_sample_h(*alpha, u1, u2);
                    let wi = 2.0 * wo.dot(h) * h - wo;
                    if wi.z <= 0.0 {
                        return None;
                    }
                    wi
                } else {
                    crate::render::sampling::cosine_hemisphere(u1, u2)
                };
                let pdf = self.eval(wo, wi, w);
                if !(pdf > 0.0) || !pdf.is_finite() {
                    return None;
                }
                let s = wi.z / pdf;
                w.iter_mut().for_each(|x| *x *= s);
                Some(BsdfSample {
                    wi,
                    pdf,
                    delta: false,
                    eta_scale: 1.0,
                })
            }
            Bsdf::Mirror { r } => {
                if wo.z <= 0.0 {
                    return None;
                }
                w.copy_from_slice(r);
                Some(BsdfSample {
                    wi: Vec3::new(-wo.x, -wo.y, wo.z),
                    pdf: 1.0,
                    delta: true,
                    eta_scale: 1.0,
                })
            }
            Bsdf::Conductor { eta, k, alpha } => {
                if wo.z <= 0.0 {
                    return None;
                }
                if *alpha <= 0.0 {
                    for ((o, &e), &kk) in w.iter_mut().zip(eta).zip(k) {
                        *o = fresnel_conductor(wo.z, e, kk);
                    }
                    return Some(BsdfSample {
                        wi: Vec3::new(-wo.x, -wo.y, wo.z),
                        pdf: 1.0,
                        delta: true,
                        eta_scale: 1.0,
                    });
                }
                let h = ggx_sample_h(*alpha, u1, u2);
                let wi = 2.0 * wo.dot(h) * h - wo;
                if wi.z <= 0.0 {
                    return None;
                }
                let pdf = self.eval(wo, wi, w);
                if !(pdf > 0.0) || !pdf.is_finite() {
                    return None;
                }
                let s = wi.z / pdf;
                w.iter_mut().for_each(|x| *x *= s);
                Some(BsdfSample {
                    wi,
                    pdf,
                    delta: false,
                    eta_scale: 1.0,
                })
            }
            Bsdf::Dielectric { eta, .. } => {
                let e = match hero {
                    Some(b) => eta[b],
                    None => eta[0],
                };
                let entering = wo.z > 0.0;
                let etap = if entering { e } else { 1.0 / e };
                let cos_o = wo.z.abs();
                let fr = fresnel_dielectric(cos_o, etap);
                if u0 < fr {
                    w.iter_mut().for_each(|x| *x = 1.0);
                    return Some(BsdfSample {
                        wi: Vec3::new(-wo.x, -wo.y, wo.z),
                        pdf: fr,
                        delta: true,
                        eta_scale: 1.0,
                    });
                }
                // Refraction (Snell), n on the side of wo.
                let sin2_i = (1.0 - cos_o * cos_o).max(0.0);
                let sin2_t = sin2_i / (etap * etap);
                if sin2_t >= 1.0 {
                    return None;
                }
                let cos_t = (1.0 - sin2_t).sqrt();
                let nz = if entering { 1.0 } else { -1.0 };
                let n = Vec3::new(0.0, 0.0, nz);
                let wi = -wo / etap + (cos_o / etap - cos_t) * n;
                // Radiance transport scales by 1/η'² across the interface.
                let s = 1.0 / (etap * etap);
                w.iter_mut().for_each(|x| *x = s);
                Some(BsdfSample {
                    wi: wi.normalize(),
                    pdf: 1.0 - fr,
                    delta: true,
                    eta_scale: etap * etap,
                })
            }
            Bsdf::Black => None,
        }
    }
}

#[cfg(test)]
mod tests {
    use super::*;
    use crate::render::sampling::Rng;

    /// Albedo of each sampled BSDF estimated by its own sampling routine must
    /// match the albedo estimated by uniform hemisphere integration of `eval`
    /// (checks that sample weights, eval and pdf agree).
    #[test]
    fn sampling_matches_eval() {
        let m = Bsdf::diffuse_specular(vec![0.5], vec![0.3], 0.2);
        let wo = Vec3::new(0.4, 0.1, 0.9).normalize();
        let mut rng = Rng::for_sample(7, 0, 0);
        let n = 400_000;
        let (mut a_is, mut a_u) = (0.0f64, 0.0f64);
        let mut w = [0.0f32];
        for _ in 0..n {
            if let Some(_s) = m.sample(
                wo,
                rng.uniform(),
                rng.uniform(),
                rng.uniform(),
                None,
                &mut w,
            ) {
                a_is += w[0] as f64;
            }
            let wi = crate::render::sampling::uniform_sphere(rng.uniform(), rng.uniform());
            if wi.z > 0.0 {
                m.eval(wo, wi, &mut w);
                a_u += (w[0] * wi.z) as f64 * 4.0 * std::f64::consts::PI;
            }
        }
        let (a_is, a_u) = (a_is / n as f64, a_u / n as f64);
        // Uniform-sphere estimate of a peaked lobe has ~1% stderr here; 3% tolerance.
        assert!(
            (a_is - a_u).abs() < 0.03 * a_u,
            "importance {a_is} vs uniform {a_u}"
        );
        // Lambert part alone is 0.5; specular adds a little, never more than 0.3.
        assert!(a_is > 0.5 && a_is < 0.8, "{a_is}");
    }

    #[test]
    fn fresnel_limits() {
        assert!((fresnel_dielectric(1.0, 1.5) - 0.04).abs() < 1e-6);
        assert_eq!(fresnel_dielectric(0.1, 1.0 / 1.5), 1.0);
        // Conductor with k = 0 reduces to the dielectric at normal incidence.
        assert!((fresnel_conductor(1.0, 1.5, 0.0) - 0.04).abs() < 1e-6);
    }
}
