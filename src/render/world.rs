//! The render-ready world: shapes in a BVH, per-primitive material / object /
//! light ids, BSDFs and light spectra resampled onto the wavelength grid, and
//! the light-selection distribution (proportional to emitted power, with a
//! floor: `selection_pmf`).
//!
//! Instances are flattened into world-space triangles. A mesh referenced by any
//! instance is treated as a prototype only and is not rendered by itself.

use super::accel::{Accel, BvhKind};
use super::bands;
use super::bsdf::{Bsdf, mean};
use super::geometry::{HIT_POINT_GAMMA, PrimHit, Shape, triangle_point};
use super::sampling::{
    Frame, ONE_MINUS_EPSILON, power_heuristic, sample_cdf, uniform_sphere, uniform_triangle,
};
use super::triangle_lights::{TriangleLight, TriangleLights};
use crate::scene::{Emission, Light, Material, Scene};
use crate::spectrum::{Spectrum, WavelengthGrid};
use crate::{Error, Result};
use glam::{DVec3, Vec3};
use std::f32::consts::PI;

/// Per-primitive attributes.
#[derive(Clone, Copy, Debug)]
pub struct PrimInfo {
    pub material: u32,
    pub object: u32,
    /// Index into `World::lights`, or u32::MAX.
    pub light: u32,
    /// Index into `World::normals` (per-vertex shading normals), or u32::MAX.
    pub normals: u32,
}

/// A light resampled on the grid.
#[derive(Clone, Debug)]
pub enum LightKind {
    Area {
        prim: u32,
        le: Vec<f32>,
        two_sided: bool,
        /// Surface area of the primitive (m²), precomputed for the pdfs.
        area: f32,
    },
    Point {
        p: Vec3,
        i: Vec<f32>,
    },
    Spot {
        p: Vec3,
        frame: Frame,
        cos_total: f32,
        cos_start: f32,
        i: Vec<f32>,
    },
    Distant {
        dir: Vec3,
        e: Vec<f32>,
    },
    Infinite {
        l: Vec<f32>,
    },
}

impl LightKind {
    /// The light's spectrum, the one its samples reference
    /// (`LightSample::spec`): radiance, intensity or irradiance by kind.
    #[inline(always)]
    pub(super) fn spectrum(&self) -> &[f32] {
        match self {
            LightKind::Area { le, .. } => le,
            LightKind::Point { i, .. } | LightKind::Spot { i, .. } => i,
            LightKind::Distant { e, .. } => e,
            LightKind::Infinite { l } => l,
        }
    }

    /// `spectrum`, to change (the bands' padding at build).
    fn spectrum_mut(&mut self) -> &mut Vec<f32> {
        match self {
            LightKind::Area { le, .. } => le,
            LightKind::Point { i, .. } | LightKind::Spot { i, .. } => i,
            LightKind::Distant { e, .. } => e,
            LightKind::Infinite { l } => l,
        }
    }
}

/// A light sample seen from a shading point. The incident spectral radiance
/// (or irradiance, for delta lights) is `scale · spec`.
pub struct LightSample<'a> {
    pub spec: &'a [f32],
    pub scale: f32,
    /// Unit direction towards the light.
    pub wi: Vec3,
    /// Solid-angle pdf including the light selection probability (delta: the
    /// selection probability only).
    pub pdf: f32,
    pub delta: bool,
    /// Target point (area / point / spot) or None (direction-only lights).
    pub target: Option<(Vec3, Vec3, Vec3)>,
}

impl LightSample<'_> {
    /// What multiplies `beta · f · spec` in a next-event estimate with this
    /// sample: the cosine `cos_wi` at the shading point (shading frame), the
    /// MIS weight against BSDF sampling of pdf `pdf_bsdf` (power heuristic;
    /// 1 for a delta light) and the sample's `scale / pdf`.
    #[inline(always)]
    pub(super) fn next_event_scale(&self, cos_wi: f32, pdf_bsdf: f32) -> f32 {
        let w = if self.delta {
            1.0
        } else {
            power_heuristic(self.pdf, pdf_bsdf)
        };
        cos_wi * w * self.scale / self.pdf
    }
}

/// Draw `u` in the slice [`lo`, `hi`) of a cumulative table, remapped to
/// [0, 1) (0 for an empty slice). `TriangleLights::choose_avx512` does the
/// same with vectors.
#[inline(always)]
fn remap_in_slice(u: f32, lo: f32, hi: f32) -> f32 {
    let width = hi - lo;
    if width > 0.0 {
        ((u - lo) / width).clamp(0.0, ONE_MINUS_EPSILON)
    } else {
        0.0
    }
}

pub struct World {
    pub accel: Accel,
    pub info: Vec<PrimInfo>,
    pub normals: Vec<[Vec3; 3]>,
    /// Unit geometric normal of each triangle primitive (zero for other
    /// shapes), computed once at build: the same operations as
    /// `Shape::surface`, so results are unchanged.
    tri_ng: Vec<Vec3>,
    /// Per primitive: a triangle with a Lambertian material, which
    /// `shade_packet` shades with the packet's other such hits.
    diffuse_tri: Vec<bool>,
    pub bsdfs: Vec<Bsdf>,
    pub lights: Vec<LightKind>,
    pub light_pmf: Vec<f32>,
    pub(super) light_cdf: Vec<f32>,
    /// The lights as one table, when all are area lights on triangles (at
    /// most four) and the CPU has AVX-512, for the AVX-512 kernel
    /// (`shade_packet.rs`).
    pub(super) tri_lights: Option<TriangleLights>,
    pub infinite: Vec<u32>,
    pub center: Vec3,
    pub radius: f32,
    pub bands: usize,
    /// Length of every band vector in the world (`bands` rounded up to a
    /// multiple of `bands::BAND_PAD`; the extra bands are zero in emission and
    /// reflectance, and the integrator keeps their throughput at 0).
    pub bands_padded: usize,
    /// A dielectric with wavelength-dependent ior is present.
    pub dispersive: bool,
}

fn resample(s: &Spectrum, grid: &WavelengthGrid, what: &str) -> Result<Vec<f32>> {
    let v = s
        .resample(grid)
        .map_err(|e| Error::invalid(format!("{what}: {e}")))?;
    if v.iter().any(|x| !x.is_finite()) {
        return Err(Error::invalid(format!(
            "{what}: spectrum '{}' has non-finite values",
            s.name
        )));
    }
    Ok(v.into_iter().map(|x| x as f32).collect())
}

fn finite3(v: DVec3) -> bool {
    v.is_finite()
}

impl World {
    pub fn build(scene: &Scene, grid: &WavelengthGrid, kind: BvhKind) -> Result<World> {
        if grid.is_empty() {
            return Err(Error::invalid("wavelength grid is empty"));
        }
        let nb = grid.len();
        let mut bsdfs = Vec::with_capacity(scene.materials.len());
        let mut dispersive = false;
        for m in &scene.materials {
            let what = format!("material '{}'", m.name);
            let b = match &m.material {
                Material::Diffuse { reflectance } => Bsdf::Diffuse {
                    r: resample(reflectance, grid, &what)?,
                },
                Material::DiffuseSpecular {
                    diffuse,
                    specular,
                    roughness,
                } => Bsdf::diffuse_specular(
                    resample(diffuse, grid, &what)?,
                    resample(specular, grid, &what)?,
                    *roughness as f32,
                ),
                Material::Mirror { reflectance } => Bsdf::Mirror {
                    r: resample(reflectance, grid, &what)?,
                },
                Material::Dielectric { ior } => {
                    let eta = resample(ior, grid, &what)?;
                    if eta.iter().any(|&e| e <= 0.0) {
                        return Err(Error::invalid(format!("{what}: ior must be > 0")));
                    }
                    let d = eta.iter().any(|&e| e != eta[0]);
                    dispersive |= d;
                    Bsdf::Dielectric { eta, dispersive: d }
                }
                Material::Conductor { eta, k, roughness } => Bsdf::Conductor {
                    eta: resample(eta, grid, &what)?,
                    k: resample(k, grid, &what)?,
                    alpha: *roughness as f32,
                },
                Material::Black => Bsdf::Black,
            };
            bsdfs.push(b);
        }
        let nmat = bsdfs.len() as u32;
        let check_mat = |m: u32, what: &str| -> Result<()> {
            if m >= nmat {
                return Err(Error::invalid(format!(
                    "{what} refers to material {m}, but the scene has {nmat}"
                )));
            }
            Ok(())
        };

        let mut shapes = Vec::new();
        let mut info = Vec::new();
        let mut normals = Vec::new();
        let mut lights = Vec::new();
        let mut emitters: Vec<(usize, Emission)> = Vec::new();
        let mut prototype = vec![false; scene.meshes.len()];
        for inst in &scene.instances {
            for &p in &inst.prototype {
                if p >= scene.meshes.len() {
                    return Err(Error::invalid(format!(
                        "instance refers to mesh {p}, but the scene has {}",
                        scene.meshes.len()
                    )));
                }
                prototype[p] = true;
            }
        }
        let mut add_mesh =
            |mesh: &crate::scene::Mesh, xf: Option<glam::DMat4>, object: u32| -> Result<()> {
                let oname = scene
                    .objects
                    .get(object as usize)
                    .map(|o| o.name.as_str())
                    .unwrap_or("?");
                check_mat(mesh.material, &format!("mesh of object '{oname}'"))?;
                let nrm_xf = xf.map(|m| m.inverse().transpose());
                for tri in &mesh.indices {
                    let mut p = [Vec3::ZERO; 3];
                    for k in 0..3 {
                        let idx = tri[k] as usize;
                        let v = *mesh.positions.get(idx).ok_or_else(|| {
                            Error::invalid(format!(
                                "mesh of object '{oname}': index {idx} out of range ({} vertices)",
                                mesh.positions.len()
                            ))
                        })?;
                        let v = v.as_dvec3();
                        let v = match xf {
                            Some(m) => m.transform_point3(v),
                            None => v,
                        };
                        if !finite3(v) {
                            return Err(Error::invalid(format!(
                                "mesh of object '{oname}': vertex {idx} is not finite"
                            )));
                        }
                        p[k] = v.as_vec3();
                    }
                    let area = (p[1] - p[0]).cross(p[2] - p[0]).length();
                    if !(area > 0.0) {
                        continue; // degenerate: never hit, never sampled
                    }
                    let nidx = match &mesh.normals {
                        Some(ns) if ns.len() == mesh.positions.len() => {
                            let mut n3 = [Vec3::ZERO; 3];
                            for k in 0..3 {
                                let n = ns[tri[k] as usize].as_dvec3();
                                let n = match nrm_xf {
                                    Some(m) => m.transform_vector3(n),
                                    None => n,
                                };
                                n3[k] = n.as_vec3().normalize_or_zero();
                            }
                            if n3.iter().all(|n| n.is_finite() && n.length_squared() > 0.5) {
                                normals.push(n3);
                                (normals.len() - 1) as u32
                            } else {
                                u32::MAX
                            }
                        }
                        _ => u32::MAX,
                    };
                    let prim = shapes.len();
                    shapes.push(Shape::Triangle { p });
                    info.push(PrimInfo {
                        material: mesh.material,
                        object,
                        light: u32::MAX,
                        normals: nidx,
                    });
                    if let Some(e) = &mesh.emission {
                        emitters.push((prim, e.clone()));
                    }
                }
                Ok(())
            };
        for (i, m) in scene.meshes.iter().enumerate() {
            if !prototype[i] {
                add_mesh(m, None, m.object)?;
            }
        }
        for inst in &scene.instances {
            for &p in &inst.prototype {
                let m = &scene.meshes[p];
                add_mesh(m, Some(inst.to_world), inst.object.unwrap_or(m.object))?;
            }
        }
        for s in &scene.spheres {
            check_mat(s.material, "sphere")?;
            if !(s.radius > 0.0) || !s.center.is_finite() || !s.radius.is_finite() {
                return Err(Error::invalid(format!(
                    "sphere with radius {} at {:?} is invalid",
                    s.radius, s.center
                )));
            }
            let prim = shapes.len();
            shapes.push(Shape::Sphere {
                center: s.center.as_vec3(),
                radius: s.radius as f32,
            });
            info.push(PrimInfo {
                material: s.material,
                object: s.object,
                light: u32::MAX,
                normals: u32::MAX,
            });
            if let Some(e) = &s.emission {
                emitters.push((prim, e.clone()));
            }
        }
        for d in &scene.disks {
            check_mat(d.material, "disk")?;
            let n = d.normal.normalize_or_zero();
            if !(d.radius > 0.0)
                || !d.center.is_finite()
                || n == DVec3::ZERO
                || !d.radius.is_finite()
            {
                return Err(Error::invalid(format!(
                    "disk with radius {} normal {:?} is invalid",
                    d.radius, d.normal
                )));
            }
            let prim = shapes.len();
            shapes.push(Shape::Disk {
                center: d.center.as_vec3(),
                normal: n.as_vec3(),
                radius: d.radius as f32,
            });
            info.push(PrimInfo {
                material: d.material,
                object: d.object,
                light: u32::MAX,
                normals: u32::MAX,
            });
            if let Some(e) = &d.emission {
                emitters.push((prim, e.clone()));
            }
        }
        // Scene bounds (for distant / infinite light power).
        let (mut lo, mut hi) = (Vec3::splat(f32::INFINITY), Vec3::splat(f32::NEG_INFINITY));
        for s in &shapes {
            let b = obvhs::Boundable::aabb(s);
            lo = lo.min(Vec3::from(b.min));
            hi = hi.max(Vec3::from(b.max));
        }
        let (center, radius) = if shapes.is_empty() {
            (Vec3::ZERO, 1.0)
        } else {
            ((lo + hi) * 0.5, ((hi - lo) * 0.5).length().max(1e-30))
        };

        let mut power = Vec::new();
        for (prim, e) in &emitters {
            let le = resample(&e.radiance, grid, "emission")?;
            let area = shapes[*prim].area();
            let pw = mean(&le) * area * PI * if e.two_sided { 2.0 } else { 1.0 };
            info[*prim].light = lights.len() as u32;
            lights.push(LightKind::Area {
                prim: *prim as u32,
                le,
                two_sided: e.two_sided,
                area,
            });
            power.push(pw);
        }
        let mut infinite = Vec::new();
        for l in &scene.lights {
            match l {
                Light::Point {
                    position,
                    intensity,
                } => {
                    let i = resample(intensity, grid, "point light")?;
                    power.push(4.0 * PI * mean(&i));
                    lights.push(LightKind::Point {
                        p: position.as_vec3(),
                        i,
                    });
                }
                Light::Spot {
                    position,
                    direction,
                    cone_angle_deg,
                    falloff_start_deg,
                    intensity,
                } => {
                    let i = resample(intensity, grid, "spot light")?;
                    let dir = direction.normalize_or_zero();
                    if dir == DVec3::ZERO {
                        return Err(Error::invalid("spot light direction is zero"));
                    }
                    let cos_total = (cone_angle_deg.to_radians().cos()) as f32;
                    let cos_start =
                        (falloff_start_deg.min(*cone_angle_deg).to_radians().cos()) as f32;
                    power.push(mean(&i) * 2.0 * PI * (1.0 - 0.5 * (cos_start + cos_total)));
                    lights.push(LightKind::Spot {
                        p: position.as_vec3(),
                        frame: Frame::from_normal(dir.as_vec3()),
                        cos_total,
                        cos_start,
                        i,
                    });
                }
                Light::Distant {
                    direction,
                    irradiance,
                } => {
                    let e = resample(irradiance, grid, "distant light")?;
                    let dir = direction.normalize_or_zero();
                    if dir == DVec3::ZERO {
                        return Err(Error::invalid("distant light direction is zero"));
                    }
                    power.push(mean(&e) * PI * radius * radius);
                    lights.push(LightKind::Distant {
                        dir: dir.as_vec3(),
                        e,
                    });
                }
                Light::Infinite { radiance } => {
                    let l = resample(radiance, grid, "infinite light")?;
                    power.push(mean(&l) * 4.0 * PI * PI * radius * radius);
                    infinite.push(lights.len() as u32);
                    lights.push(LightKind::Infinite { l });
                }
            }
        }
        let light_pmf = selection_pmf(&power);
        let mut acc = 0.0;
        let mut light_cdf: Vec<f32> = light_pmf
            .iter()
            .map(|p| {
                acc += p;
                acc
            })
            .collect();
        if let Some(l) = light_cdf.last_mut() {
            *l = 1.0;
        }
        // Pad every band vector (after all means above are taken).
        let nbp = nb.next_multiple_of(bands::BAND_PAD);
        for b in &mut bsdfs {
            b.pad_bands(nbp);
        }
        for l in &mut lights {
            l.spectrum_mut().resize(nbp, 0.0);
        }
        let tri_ng: Vec<Vec3> = shapes
            .iter()
            .map(|s| match *s {
                Shape::Triangle { p } => (p[1] - p[0]).cross(p[2] - p[0]).normalize_or_zero(),
                _ => Vec3::ZERO,
            })
            .collect();
        // Every light a triangle light, or no table.
        let tri_lights = lights
            .iter()
            .map(|l| match *l {
                LightKind::Area {
                    prim,
                    two_sided,
                    area,
                    ..
                } => match shapes[prim as usize] {
                    Shape::Triangle { p } => Some(TriangleLight {
                        v: p,
                        ng: tri_ng[prim as usize],
                        area,
                        two_sided,
                    }),
                    _ => None,
                },
                _ => None,
            })
            .collect::<Option<Vec<_>>>()
            .and_then(|each| TriangleLights::build(&each, &light_pmf, &light_cdf));
        let diffuse_tri = shapes
            .iter()
            .zip(&info)
            .map(|(s, i)| {
                matches!(s, Shape::Triangle { .. })
                    && matches!(bsdfs[i.material as usize], Bsdf::Diffuse { .. })
            })
            .collect();
        Ok(World {
            accel: Accel::build(shapes, kind),
            diffuse_tri,
            info,
            normals,
            tri_ng,
            bsdfs,
            lights,
            light_pmf,
            light_cdf,
            tri_lights,
            infinite,
            center,
            radius,
            bands: nb,
            bands_padded: nbp,
            dispersive,
        })
    }

    /// Surface point, error bound and geometric normal of a hit on primitive
    /// `prim` (`Shape::surface` with the triangle normal precomputed).
    #[inline(always)]
    pub fn surface(&self, prim: u32, o: Vec3, d: Vec3, h: &PrimHit) -> (Vec3, Vec3, Vec3) {
        match self.accel.shapes[prim as usize] {
            Shape::Triangle { p } => {
                let (pt, err) = triangle_point(&p, h.b, HIT_POINT_GAMMA);
                (pt, err, self.tri_ng[prim as usize])
            }
            ref s => s.surface(o, d, h),
        }
    }

    /// Whether `prim` (a closest hit's primitive, `u32::MAX` for a miss) is a
    /// hit, and whether that hit can be shaded by `shade_packet`: a
    /// Lambertian triangle (with or without vertex normals, lit by lights of
    /// any kind). No branch on the miss (a missed lane reads the first
    /// primitive's entry and drops it): whether a ray hit is data the branch
    /// predictor cannot learn (docs/performance.md, *Twenty-fourth pass*).
    #[inline(always)]
    pub(super) fn hit_kind(&self, prim: u32) -> (bool, bool) {
        let hit = prim != u32::MAX;
        let i = if hit { prim as usize } else { 0 };
        let shadable = self.diffuse_tri.get(i).copied().unwrap_or(false);
        (hit, hit & shadable)
    }

    /// Unit geometric normal of triangle primitive `prim`.
    #[inline(always)]
    pub(super) fn triangle_normal(&self, prim: u32) -> Vec3 {
        self.tri_ng[prim as usize]
    }

    /// The triangle normals as floats, three per primitive (x, y, z), for
    /// the AVX-512 kernel's gathers (`hit_lanes_avx512`).
    #[cfg(target_arch = "x86_64")]
    pub(super) fn tri_ng_ptr(&self) -> *const f32 {
        self.tri_ng.as_ptr().cast()
    }

    /// The light that draw `u` selects, its selection probability, and `u`
    /// remapped to [0, 1) within the light's slice of the table, so one 2-D
    /// point both picks the light and places the sample on it (a stratified
    /// point stays stratified over every light's area, as the sample reuse of
    /// pbrt-v4 and Mitsuba). Needs at least one light.
    #[inline(always)]
    pub(super) fn choose_light(&self, u: f32) -> (usize, f32, f32) {
        let idx = sample_cdf(&self.light_cdf, u);
        let lo = if idx == 0 {
            0.0
        } else {
            self.light_cdf[idx - 1]
        };
        (
            idx,
            self.light_pmf[idx],
            remap_in_slice(u, lo, self.light_cdf[idx]),
        )
    }

    /// Pick a light with draw `u1` and sample a direction to it from point
    /// `p` with (`u1` remapped, `u2`). The sample references the light's
    /// spectrum: radiance arriving at `p` (unoccluded) is `scale · spec`.
    #[inline(always)]
    pub fn sample_light(&self, p: Vec3, u1: f32, u2: f32) -> Option<LightSample<'_>> {
        if self.lights.is_empty() {
            return None;
        }
        let (idx, sel, u1) = self.choose_light(u1);
        if !(sel > 0.0) {
            return None;
        }
        self.sample_chosen_light(idx, sel, p, u1, u2)
    }

    /// `sample_light` once the light is chosen: light `idx`, selected with
    /// probability `sel` (> 0), sampled from `p` with the remapped draw `u1`
    /// and `u2`.
    #[inline(always)]
    pub(super) fn sample_chosen_light(
        &self,
        idx: usize,
        sel: f32,
        p: Vec3,
        u1: f32,
        u2: f32,
    ) -> Option<LightSample<'_>> {
        match &self.lights[idx] {
            LightKind::Area {
                prim,
                le,
                two_sided,
                area,
            } => {
                let shape = &self.accel.shapes[*prim as usize];
                let (pl, err, nl) = match *shape {
                    super::geometry::Shape::Triangle { p: v } => {
                        let (b0, b1, b2) = uniform_triangle(u1, u2);
                        let (pt, err) = triangle_point(&v, [b0, b1, b2], 6);
                        (pt, err, self.tri_ng[*prim as usize])
                    }
                    super::geometry::Shape::Sphere { center, radius } => {
                        let n = uniform_sphere(u1, u2);
                        let pt = center + n * radius;
                        (
                            pt,
                            (pt.abs() + Vec3::splat(radius)) * (4.0 * f32::EPSILON),
                            n,
                        )
                    }
                    super::geometry::Shape::Disk {
                        center,
                        normal,
                        radius,
                    } => {
                        let (x, y) = super::sampling::square_to_disk(u1, u2);
                        let f = Frame::from_normal(normal);
                        let pt = center + f.to_world(Vec3::new(x * radius, y * radius, 0.0));
                        (pt, (pt.abs() + center.abs()) * (4.0 * f32::EPSILON), normal)
                    }
                };
                let d = pl - p;
                let dist2 = d.length_squared();
                if !(dist2 > 0.0) {
                    return None;
                }
                let wi = d / dist2.sqrt();
                let cos_l = -nl.dot(wi);
                if cos_l <= 0.0 && !two_sided {
                    return None;
                }
                let cos_l = cos_l.abs();
                if !(cos_l > 0.0) {
                    return None;
                }
                let pdf = sel * dist2 / (cos_l * area);
                if !(pdf > 0.0) || !pdf.is_finite() {
                    return None;
                }
                Some(LightSample {
                    spec: le,
                    scale: 1.0,
                    wi,
                    pdf,
                    delta: false,
                    target: Some((pl, err, nl)),
                })
            }
            LightKind::Point { p: lp, i } => {
                let d = *lp - p;
                let dist2 = d.length_squared();
                if !(dist2 > 0.0) {
                    return None;
                }
                Some(LightSample {
                    spec: i,
                    scale: 1.0 / dist2,
                    wi: d / dist2.sqrt(),
                    pdf: sel,
                    delta: true,
                    target: Some((*lp, Vec3::ZERO, Vec3::ZERO)),
                })
            }
            LightKind::Spot {
                p: lp,
                frame,
                cos_total,
                cos_start,
                i,
            } => {
                let d = *lp - p;
                let dist2 = d.length_squared();
                if !(dist2 > 0.0) {
                    return None;
                }
                let wi = d / dist2.sqrt();
                let c = frame.n.dot(-wi);
                let fall = smooth_falloff(c, *cos_total, *cos_start);
                if fall <= 0.0 {
                    return None;
                }
                Some(LightSample {
                    spec: i,
                    scale: fall / dist2,
                    wi,
                    pdf: sel,
                    delta: true,
                    target: Some((*lp, Vec3::ZERO, Vec3::ZERO)),
                })
            }
            LightKind::Distant { dir, e } => Some(LightSample {
                spec: e,
                scale: 1.0,
                wi: -*dir,
                pdf: sel,
                delta: true,
                target: None,
            }),
            LightKind::Infinite { l } => {
                let wi = uniform_sphere(u1, u2);
                Some(LightSample {
                    spec: l,
                    scale: 1.0,
                    wi,
                    pdf: sel / (4.0 * PI),
                    delta: false,
                    target: None,
                })
            }
        }
    }

    /// Solid-angle pdf with which `sample_light` would have produced the hit
    /// on area light `light` at distance `dist` with cosine `cos_l` there.
    #[inline(always)]
    pub fn area_light_pdf(&self, light: u32, dist: f32, cos_l: f32) -> f32 {
        let LightKind::Area { area, .. } = self.lights[light as usize] else {
            return 0.0;
        };
        self.light_pmf[light as usize] * dist * dist / (cos_l.abs() * area)
    }
}

/// Smallest selection probability of a light that emits, as a fraction of
/// 1/N (N lights): `MIN_SELECTION / N`.
pub const MIN_SELECTION: f64 = 1e-3;

/// Light selection probabilities, proportional to emitted power, with every
/// light of positive power selected with probability at least
/// `MIN_SELECTION / N`.
///
/// Without the floor a light 10⁸ dimmer than another got a probability of
/// 10⁻⁸, below the f32 resolution of the cumulative table near 1 (6·10⁻⁸):
/// it was never picked, so a dim point light (which only next-event
/// estimation can find) contributed nothing at all — a bias, not noise.
///
/// When every light is above the floor the probabilities are the f32
/// power shares as before (shipped scenes keep bit-identical images);
/// otherwise each share is max(P/ΣP, floor), computed in f64 and
/// renormalised. A light of zero power is never picked (it adds nothing).
/// The cumulative table then resolves each step (≥ 10⁻³/N ≫ 6·10⁻⁸ for
/// N < 10⁴ lights).
pub fn selection_pmf(power: &[f32]) -> Vec<f32> {
    let n = power.len();
    let total: f32 = power.iter().map(|p| p.max(0.0)).sum();
    if !(total > 0.0 && total.is_finite()) {
        return vec![1.0 / n.max(1) as f32; n];
    }
    let floor = MIN_SELECTION / n as f64;
    let total64: f64 = power.iter().map(|&p| p.max(0.0) as f64).sum();
    let share = |p: f32| p.max(0.0) as f64 / total64;
    if power.iter().all(|&p| !(p > 0.0) || share(p) >= floor) {
        return power.iter().map(|p| p.max(0.0) / total).collect();
    }
    let q: Vec<f64> = power
        .iter()
        .map(|&p| if p > 0.0 { share(p).max(floor) } else { 0.0 })
        .collect();
    let sum: f64 = q.iter().sum();
    q.iter().map(|&x| (x / sum) as f32).collect()
}

/// pbrt-v4 spot fall-off: smoothstep between the cone and the fall-off start.
#[inline(always)]
fn smooth_falloff(cos: f32, cos_total: f32, cos_start: f32) -> f32 {
    if cos >= cos_start {
        return 1.0;
    }
    if cos <= cos_total || cos_start <= cos_total {
        return 0.0;
    }
    let t = ((cos - cos_total) / (cos_start - cos_total)).clamp(0.0, 1.0);
    t * t * (3.0 - 2.0 * t)
}

#[cfg(all(test, target_arch = "x86_64"))]
mod tests {
    // The lane loops index the table's per-lane arrays together.
    #![allow(clippy::needless_range_loop)]

    use super::*;
    use crate::render::BvhKind;
    use crate::render::ray_packet::{LANES, LaneMask};
    use crate::render::sampling::Rng;
    use crate::render::simd::RenderIsa;
    use crate::render::triangle_lights::Chosen;
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
