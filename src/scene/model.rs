//! The scene model shared by the pbrt parser, the mesh loaders, the KDL scene
//! builder and the renderer. Geometry is in metres, world space, y up (the
//! paper's Cornell box convention: origin at the centre of the box floor).
//! Spectra are kept continuous (`Spectrum`) and resampled onto the render
//! wavelength grid by the renderer.

use crate::spectrum::Spectrum;
use glam::{DMat4, DVec3, Vec2, Vec3};
use serde::{Deserialize, Serialize};

/// Index into `Scene::objects` (the label carried into the optical image).
pub type ObjectId = u32;
/// Index into `Scene::materials`.
pub type MaterialId = u32;

/// Label value for "no object" (background / escaped rays) in label images.
pub const NO_OBJECT: u32 = u32::MAX;

/// A named object: what measurements find their regions by (e.g. `mcc/patch04`,
/// `edge-near`, `wall-left`). Hierarchical names use `/`.
#[derive(Clone, Debug, PartialEq, Serialize, Deserialize)]
pub struct Object {
    pub name: String,
}

/// A named material.
#[derive(Clone, Debug, PartialEq, Serialize, Deserialize)]
pub struct NamedMaterial {
    pub name: String,
    pub material: Material,
}

/// Surface scattering models (all energy conserving for reflectances ≤ 1).
#[derive(Clone, Debug, PartialEq, Serialize, Deserialize)]
pub enum Material {
    /// Lambertian reflector.
    Diffuse { reflectance: Spectrum },
    /// Lambertian base plus a small glossy specular lobe — the paper's walls and
    /// cubes ("primarily Lambertian, with a small specular term"; pbrt-v3 `uber`
    /// Kd/Ks). `roughness` is the microfacet alpha (0 = mirror-like highlight).
    DiffuseSpecular {
        diffuse: Spectrum,
        specular: Spectrum,
        roughness: f64,
    },
    /// Perfect mirror with spectral reflectance.
    Mirror { reflectance: Spectrum },
    /// Smooth dielectric interface; a non-constant `ior` is dispersive.
    Dielectric { ior: Spectrum },
    /// Smooth or rough conductor (Fresnel from eta, k).
    Conductor {
        eta: Spectrum,
        k: Spectrum,
        roughness: f64,
    },
    /// Absorbs everything.
    Black,
}

/// Emission attached to a shape: one-sided (front = geometric normal side)
/// unless `two_sided`. Radiance in W/(sr·m²·nm).
#[derive(Clone, Debug, PartialEq, Serialize, Deserialize)]
pub struct Emission {
    pub radiance: Spectrum,
    pub two_sided: bool,
}

/// Triangle mesh in world space.
#[derive(Clone, Debug, Default, PartialEq, Serialize, Deserialize)]
pub struct Mesh {
    pub positions: Vec<Vec3>,
    /// Per-vertex shading normals (optional).
    pub normals: Option<Vec<Vec3>>,
    /// Per-vertex texture coordinates (optional).
    pub uvs: Option<Vec<Vec2>>,
    pub indices: Vec<[u32; 3]>,
    pub material: MaterialId,
    pub object: ObjectId,
    pub emission: Option<Emission>,
}

/// Sphere in world space.
#[derive(Clone, Debug, PartialEq, Serialize, Deserialize)]
pub struct Sphere {
    pub center: DVec3,
    pub radius: f64,
    pub material: MaterialId,
    pub object: ObjectId,
    pub emission: Option<Emission>,
}

/// Disk (one-sided emitter when emissive), normal pointing to its front.
#[derive(Clone, Debug, PartialEq, Serialize, Deserialize)]
pub struct Disk {
    pub center: DVec3,
    pub normal: DVec3,
    pub radius: f64,
    pub material: MaterialId,
    pub object: ObjectId,
    pub emission: Option<Emission>,
}

/// An instance of a mesh (index into `Scene::meshes` of a prototype that is not
/// itself rendered unless also listed as a plain mesh) with a world transform.
#[derive(Clone, Debug, PartialEq, Serialize, Deserialize)]
pub struct Instance {
    pub prototype: Vec<usize>,
    pub to_world: DMat4,
    /// Object label override for this instance (None keeps the prototype's).
    pub object: Option<ObjectId>,
}

/// Lights other than emissive shapes.
#[derive(Clone, Debug, PartialEq, Serialize, Deserialize)]
pub enum Light {
    /// Isotropic point light; intensity in W/(sr·nm).
    Point {
        position: DVec3,
        intensity: Spectrum,
    },
    /// Spot light: intensity W/(sr·nm) on axis, smooth fall-off between the angles.
    Spot {
        position: DVec3,
        direction: DVec3,
        cone_angle_deg: f64,
        falloff_start_deg: f64,
        intensity: Spectrum,
    },
    /// Directional light; `direction` is where the light travels; irradiance on a
    /// surface perpendicular to it in W/(m²·nm).
    Distant {
        direction: DVec3,
        irradiance: Spectrum,
    },
    /// Uniform environment of constant radiance W/(sr·m²·nm) (flat-field light).
    Infinite { radiance: Spectrum },
}

/// Camera pose: position, look-at point and up vector, metres, world space.
#[derive(Clone, Debug, PartialEq, Serialize, Deserialize)]
pub struct CameraPose {
    pub position: DVec3,
    pub look_at: DVec3,
    pub up: DVec3,
}

impl Default for CameraPose {
    fn default() -> Self {
        Self {
            position: DVec3::new(0.0, 0.0, -1.0),
            look_at: DVec3::ZERO,
            up: DVec3::Y,
        }
    }
}

/// Which camera model the scene asks for. Lenses are resolved by `optics`.
#[derive(Clone, Debug, PartialEq, Serialize, Deserialize)]
pub enum CameraModel {
    /// Pinhole with a nominal f-number used only for the irradiance scale
    /// (E = πL/(4N²)·cos⁴θ, or πL/(4N²) without `cos4`: an ideal lens with no
    /// natural vignetting, whose fall-off the sensor's relative illumination
    /// supplies). `fov_deg` is the full field of view across the shorter film
    /// side (pbrt's convention).
    Pinhole {
        fov_deg: f64,
        f_number: f64,
        cos4: bool,
    },
    /// Ideal thin lens.
    ThinLens {
        focal_length_m: f64,
        f_number: f64,
        focus_distance_m: f64,
    },
    /// A lens file (prescription or RTF JSON) with a film distance or focus distance.
    LensFile {
        path: std::path::PathBuf,
        film_distance_m: Option<f64>,
        focus_distance_m: Option<f64>,
        aperture_diameter_m: Option<f64>,
        /// Render a prescription through an RTF fitted to it on the fly.
        rtf_fit: Option<RtfFitRequest>,
    },
}

/// KDL `lens "PRESCRIPTION" rtf-degree=N [rtf-axis-weight=W]`: fit an RTF of
/// this degree to the prescription and render through it.
#[derive(Clone, Copy, Debug, PartialEq, Serialize, Deserialize)]
pub struct RtfFitRequest {
    pub degree: usize,
    /// Extra weight of the on-axis film bundles in the fit (1 = whole field).
    pub axis_weight: f64,
}

/// The scene's own camera (pbrt `Camera`, or KDL `camera`).
#[derive(Clone, Debug, PartialEq, Serialize, Deserialize)]
pub struct CameraSpec {
    /// World-from-camera transform (camera looks down +z, +y up, +x to the image's right).
    pub to_world: DMat4,
    pub model: CameraModel,
}

/// The scene's film: resolution, physical pixel pitch and an optional crop window
/// (pbrt's `cropwindow`, fractions [x0, x1, y0, y1]).
#[derive(Clone, Debug, PartialEq, Serialize, Deserialize)]
pub struct FilmSpec {
    pub width_px: u32,
    pub height_px: u32,
    pub pixel_pitch_m: f64,
    pub crop_window: Option<[f64; 4]>,
}

impl Default for FilmSpec {
    fn default() -> Self {
        Self {
            width_px: 256,
            height_px: 256,
            pixel_pitch_m: 1.4e-6,
            crop_window: None,
        }
    }
}

/// A whole scene.
#[derive(Clone, Debug, Default, PartialEq, Serialize, Deserialize)]
pub struct Scene {
    pub objects: Vec<Object>,
    pub materials: Vec<NamedMaterial>,
    pub meshes: Vec<Mesh>,
    pub spheres: Vec<Sphere>,
    pub disks: Vec<Disk>,
    pub instances: Vec<Instance>,
    pub lights: Vec<Light>,
    pub camera: Option<CameraSpec>,
    pub film: Option<FilmSpec>,
    /// Non-fatal notes gathered while loading (unsupported features, fallbacks).
    pub warnings: Vec<String>,
}

impl Scene {
    /// Add (or find) an object label and return its id.
    pub fn object(&mut self, name: &str) -> ObjectId {
        if let Some(i) = self.objects.iter().position(|o| o.name == name) {
            return i as ObjectId;
        }
        self.objects.push(Object {
            name: name.to_string(),
        });
        (self.objects.len() - 1) as ObjectId
    }
    /// Add a material and return its id (a same-named material is replaced).
    pub fn material(&mut self, name: &str, material: Material) -> MaterialId {
        if let Some(i) = self.materials.iter().position(|m| m.name == name) {
            self.materials[i].material = material;
            return i as MaterialId;
        }
        self.materials.push(NamedMaterial {
            name: name.to_string(),
            material,
        });
        (self.materials.len() - 1) as MaterialId
    }
    pub fn triangle_count(&self) -> usize {
        self.meshes.iter().map(|m| m.indices.len()).sum()
    }
}

/// World-from-camera matrix for a look-at pose: camera +z towards the target,
/// +y along the projected up vector, +x to the image's right (left-handed camera
/// frame, as pbrt). Returns None for a degenerate pose (target at the eye, or up
/// parallel to the view direction).
pub fn look_at_to_world(pose: &CameraPose) -> Option<DMat4> {
    let f = pose.look_at - pose.position;
    if !f.is_finite() || f.length() <= 0.0 {
        return None;
    }
    let f = f.normalize();
    let upn = pose.up.normalize_or_zero();
    let right = upn.cross(f);
    if right.length() < 1e-9 {
        return None;
    }
    let right = right.normalize();
    let up = f.cross(right);
    Some(DMat4::from_cols(
        right.extend(0.0),
        up.extend(0.0),
        f.extend(0.0),
        pose.position.extend(1.0),
    ))
}
