//! The paper's spectra for the ISET Cornell box and MCC scenes.
//!
//! The exported pbrt-v3 scenes carry RGB placeholder materials. The paper's scripts
//! (`cbAssignMaterial`, `cbBoxCreate`; numbers in `data/cornellbox/cornellbox_setup.json`)
//! replace them by measured spectra:
//!
//! | material (pbrt name)               | camsim material                                      |
//! |------------------------------------|------------------------------------------------------|
//! | `LeftWall`                         | DiffuseSpecular(Kd = `cbox-red-wall`, Ks = 0.1·Kd)   |
//! | `RightWall`                        | DiffuseSpecular(Kd = `cbox-green-wall`, Ks = 0.1·Kd) |
//! | `BackWall`, `TopWall`, `BottomWall`| Diffuse(`cbox-white-wall`) (matte)                   |
//! | `CubeSmall`, `CubeLarge`           | DiffuseSpecular(Kd = `cbox-white-wall`, Ks = 0.5·Kd) |
//! | `Patch01`…`Patch24`                | Diffuse(`mcc-mini-01`…`24`) (column-major, 04 white) |
//! | `ShieldMat`, `Substrate`           | unchanged                                            |
//!
//! The specular roughness is the exported uber's (pbrt-v3 roughness 0.1 remapped).
//! The area light (object `AreaLight…`, the exported 4×4 cm emitter) gets the lamp
//! spectrum `cbox-lamp` (PR-670 `cbox-lights-1`, W/(sr·m²·nm)) as one-sided emission
//! and is moved by −0.005 m in y (exported at y = 0.305, placed at 0.300 by
//! `cbBoxCreate`). The exporter's placeholder `distant` light is removed: the paper's
//! box is lit by its lamp alone.
//!
//! A scene without the lamp (the MCC) keeps the exporter's `distant` light,
//! `rgb L [1 1 1]`. These pbrt-v3 files are now read with pbrt-v3's literal light
//! meaning (see [`super::dialect`]), which would make that light ∫ȳ = 106.857×
//! brighter than the pbrt-v4 reading the paper's scenes were always rendered with;
//! so a kept light that is exactly the pbrt-v3 reading of `rgb L [1 1 1]` gets the
//! pbrt-v4 value back (the same product, v3 value × 1/∫ȳ, bit for bit), and the
//! paper's scenes render as before whichever version they are read as.

use crate::diag::{Error, Result};
use crate::scene::{Emission, Light, Material, Scene};
use crate::spectrum::{Spectrum, library};

/// What `apply_paper_spectra` changed.
#[derive(Clone, Debug, Default, PartialEq)]
pub struct PaperSpectraReport {
    pub materials_replaced: Vec<String>,
    pub lamp_meshes: usize,
    pub lights_removed: usize,
    /// Placeholder distant lights put back to their pbrt-v4 value (see module docs).
    pub lights_renormalised: usize,
}

fn lib(name: &str) -> Result<Spectrum> {
    library::named(name).map_err(Error::invalid)
}

/// The pbrt-v3 uber roughness 0.1 of the exports, as a microfacet α.
fn exported_alpha(m: &Material) -> f64 {
    match m {
        Material::DiffuseSpecular { roughness, .. } => *roughness,
        _ => {
            let x = 0.1f64.ln();
            1.62142
                + 0.819955 * x
                + 0.1734 * x * x
                + 0.0171201 * x.powi(3)
                + 0.000640711 * x.powi(4)
        }
    }
}

/// Replace the ISET scenes' RGB placeholders by the paper's spectra (see module docs).
/// Errors when the scene has none of the expected material names.
pub fn apply_paper_spectra(scene: &mut Scene) -> Result<PaperSpectraReport> {
    let mut rep = PaperSpectraReport::default();
    let red = lib("cbox-red-wall")?;
    let green = lib("cbox-green-wall")?;
    let white = lib("cbox-white-wall")?;
    for nm in &mut scene.materials {
        let alpha = exported_alpha(&nm.material);
        let new = match nm.name.as_str() {
            "LeftWall" => Some(Material::DiffuseSpecular {
                diffuse: red.clone(),
                specular: red.clone().scaled(0.1),
                roughness: alpha,
            }),
            "RightWall" => Some(Material::DiffuseSpecular {
                diffuse: green.clone(),
                specular: green.clone().scaled(0.1),
                roughness: alpha,
            }),
            "BackWall" | "TopWall" | "BottomWall" => Some(Material::Diffuse {
                reflectance: white.clone(),
            }),
            "CubeSmall" | "CubeLarge" => Some(Material::DiffuseSpecular {
                diffuse: white.clone(),
                specular: white.clone().scaled(0.5),
                roughness: alpha,
            }),
            n => match n.strip_prefix("Patch").and_then(|d| d.parse::<u32>().ok()) {
                Some(k) if (1..=24).contains(&k) => Some(Material::Diffuse {
                    reflectance: lib(&format!("mcc-mini-{k:02}"))?,
                }),
                _ => None,
            },
        };
        if let Some(m) = new {
            nm.material = m;
            rep.materials_replaced.push(nm.name.clone());
        }
    }
    let lamp = lib("cbox-lamp")?;
    let lamp_objects: Vec<u32> = scene
        .objects
        .iter()
        .enumerate()
        .filter(|(_, o)| o.name == "AreaLight" || o.name.starts_with("AreaLight/"))
        .map(|(i, _)| i as u32)
        .collect();
    for m in &mut scene.meshes {
        if lamp_objects.contains(&m.object) {
            m.emission = Some(Emission {
                radiance: lamp.clone(),
                two_sided: false,
            });
            for p in &mut m.positions {
                p.y -= 0.005;
            }
            rep.lamp_meshes += 1;
        }
    }
    if rep.lamp_meshes > 0 {
        let before = scene.lights.len();
        scene.lights.retain(|l| !matches!(l, Light::Distant { .. }));
        rep.lights_removed = before - scene.lights.len();
    }
    for l in &mut scene.lights {
        if let Light::Distant { irradiance, .. } = l {
            let v3 = super::params::rgb_to_spectrum(
                [1.0; 3],
                super::params::SpectrumKind::Illuminant,
                &irradiance.name,
            )
            .map_err(Error::invalid)?;
            if irradiance.values == v3.values && irradiance.wavelengths_nm == v3.wavelengths_nm {
                *irradiance = irradiance
                    .clone()
                    .scaled(1.0 / super::to_scene::luminance_y_of_one());
                rep.lights_renormalised += 1;
            }
        }
    }
    if rep.materials_replaced.is_empty() && rep.lamp_meshes == 0 {
        return Err(Error::invalid(
            "apply_paper_spectra: the scene has none of the ISET Cornell box / MCC names (LeftWall, Patch01, AreaLight, …)",
        ));
    }
    Ok(rep)
}
