//! The stages a variant runs through: scene → camera → render → sensor →
//! measure. Each is one function here; the runner knows nothing else. Stages
//! that other modules are still building return `Error::NotSupported`, so a
//! variant that needs them fails with "not supported yet: …" and no number is
//! ever invented. The lead replaces the bodies as the modules land.

use super::spec::{Measure, ResolvedExperiment};
use crate::figure::Figure;
use crate::image::SensorImage;
use crate::optical_image::OpticalImage;
use crate::optics::Camera;
use crate::scene::Scene;
use crate::{Error, Result};

/// Which stages a measurement needs.
#[derive(Clone, Copy, Debug, Default, PartialEq, Eq)]
pub struct Needs {
    /// Scene, camera and render (the optical image).
    pub optical_image: bool,
    /// The sensor image (implies the optical image).
    pub sensor_image: bool,
}

/// Stage requirements per measurement kind. `colorimetry` reads a spectrum
/// only; `ri` and `convergence` can work on the optical image; every other
/// kind measures sensor digital values.
pub fn needs(kind: &str) -> Needs {
    match kind {
        "colorimetry" => Needs::default(),
        "ri" | "convergence" => Needs {
            optical_image: true,
            sensor_image: false,
        },
        _ => Needs {
            optical_image: true,
            sensor_image: true,
        },
    }
}

/// Load the scene file (pbrt or KDL) and apply additions, removals and overrides.
pub fn build_scene(spec: &ResolvedExperiment) -> Result<Scene> {
    let Some(scene) = &spec.scene else {
        return Err(Error::invalid(format!(
            "experiment '{}' has no scene; add scene \"….pbrt\"",
            spec.name
        )));
    };
    Err(Error::NotSupported(format!(
        "scene loading ('{}' and its additions): the pbrt/KDL scene loader is not wired into the runner",
        scene.written
    )))
}

/// Build the camera (lens model + pose) of a variant.
pub fn build_camera(spec: &ResolvedExperiment, _scene: &Scene) -> Result<Box<dyn Camera>> {
    if spec.camera.is_none() {
        return Err(Error::invalid(format!(
            "experiment '{}' has no camera pose",
            spec.name
        )));
    }
    Err(Error::NotSupported(
        "camera models (pinhole, thin lens, prescription, RTF) are not wired into the runner"
            .into(),
    ))
}

/// Render the optical image (only the regions the measurements read).
pub fn render(
    _spec: &ResolvedExperiment,
    _scene: &Scene,
    _camera: &dyn Camera,
) -> Result<OpticalImage> {
    Err(Error::NotSupported(
        "rendering: the spectral path tracer is not wired into the runner".into(),
    ))
}

/// Turn the optical image into sensor digital values.
pub fn simulate_sensor(spec: &ResolvedExperiment, _oi: &OpticalImage) -> Result<SensorImage> {
    if spec.sensor.is_none() {
        return Err(Error::invalid(format!(
            "experiment '{}' has no sensor",
            spec.name
        )));
    }
    Err(Error::NotSupported(
        "sensor simulation is not wired into the runner".into(),
    ))
}

/// Run one measurement.
pub fn measure(
    m: &Measure,
    spec: &ResolvedExperiment,
    _oi: Option<&OpticalImage>,
    _si: Option<&SensorImage>,
) -> Result<Vec<Figure>> {
    match m.kind.as_str() {
        "colorimetry" => colorimetry(m, spec),
        k => Err(Error::NotSupported(format!(
            "measurement '{k}' is not wired into the runner"
        ))),
    }
}

/// CIE 1931 chromaticity and luminance of a named spectrum, integrated on the
/// measurement's grid (`wavelength-nm=`, default the render grid) with the
/// shipped CMFs (trapezoid rule). Exact arithmetic on tabulated data: the
/// standard error is 0. For a radiance in W/(sr·m²·nm) the luminance is
/// reported in cd/m²; for any other unit the quantity is `Y` = ∫S·ȳ dλ in the
/// spectrum's unit × nm, labelled "relative".
pub fn colorimetry(m: &Measure, spec: &ResolvedExperiment) -> Result<Vec<Figure>> {
    let reference = m
        .params
        .str("spectrum")
        .map_err(Error::invalid)?
        .ok_or_else(|| Error::invalid("colorimetry needs spectrum=\"…\""))?;
    let dir = spec.file.parent().unwrap_or(std::path::Path::new("."));
    let spd = crate::spectrum::library::resolve(reference, dir).map_err(Error::invalid)?;
    let grid = match m.params.get("wavelength-nm") {
        Some(v) => {
            super::apply::as_grid(v, "wavelength-nm").map_err(|e| Error::invalid(e.message))?
        }
        None => spec.render.wavelength.clone(),
    };
    let (x, y) = crate::spectrum::chromaticity(&spd, &grid);
    let mut out = vec![
        Figure::new(&m.name, "x", "1", x, 0.0),
        Figure::new(&m.name, "y", "1", y, 0.0),
    ];
    if spd.unit == "W/(sr·m²·nm)" {
        out.push(Figure::new(
            &m.name,
            "luminance",
            "cd/m2",
            crate::spectrum::units::luminance(&spd, &grid),
            0.0,
        ));
    } else {
        let y_rel = crate::spectrum::units::luminance(&spd, &grid)
            / crate::spectrum::units::LUMINOUS_EFFICACY_LM_PER_W;
        out.push(Figure::new(&m.name, "Y", "relative", y_rel, 0.0));
    }
    Ok(out)
}
