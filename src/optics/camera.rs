//! The one camera factory: a [`CameraModel`] (from a pbrt or KDL scene, or an
//! experiment's `lens` node through [`crate::scene::camera_params::camera_model`]) and
//! the film → the camera the renderer traces. Used by `camsim render`,
//! `camsim lens …` and the experiment runner.

use super::Camera;
use super::analysis::{DEFAULT_WAVELENGTH_NM, LensCamera, LensFile, lens_camera, load_lens};
use super::pinhole::Pinhole;
use super::thin_lens::ThinLens;
use crate::scene::{CameraModel, FilmSpec};
use crate::{Error, Result};

/// Build the camera of `model` for `film`: pinhole, thin lens, lens
/// prescription, RTF file, or a prescription through an RTF fitted on the fly.
pub fn build(model: &CameraModel, film: &FilmSpec) -> Result<Box<dyn Camera>> {
    match model {
        CameraModel::Pinhole {
            fov_deg,
            f_number,
            cos4,
        } => Ok(Box::new(
            Pinhole::new(*fov_deg, *f_number, film)?.with_cos4(*cos4),
        )),
        CameraModel::ThinLens {
            focal_length_m,
            f_number,
            focus_distance_m,
        } => Ok(Box::new(ThinLens::new(
            *focal_length_m,
            *f_number,
            *focus_distance_m,
        )?)),
        CameraModel::LensFile {
            path,
            aperture_diameter_m: Some(_),
            ..
        } => Err(Error::NotSupported(format!(
            "{}: changing the aperture of a lens file",
            path.display()
        ))),
        CameraModel::LensFile {
            path,
            film_distance_m,
            focus_distance_m,
            rtf_fit: Some(fit),
            ..
        } => super::analysis::fitted_rtf_camera(
            path,
            *film_distance_m,
            *focus_distance_m,
            fit.degree,
            fit.axis_weight,
        ),
        CameraModel::LensFile {
            path,
            film_distance_m,
            focus_distance_m,
            rtf_fit: None,
            ..
        } => {
            let cam = lens_camera(
                load_lens(path)?,
                film_distance_m.map(|d| d * 1e3),
                *focus_distance_m,
                DEFAULT_WAVELENGTH_NM,
            )?;
            Ok(match cam {
                LensCamera::Prescription(c) => Box::new(c),
                LensCamera::Rtf(c) => Box::new(c),
            })
        }
    }
}

/// What can be checked of `model` without building it (a fit takes seconds):
/// its lens file loads, and an RTF fit is asked of a prescription, not of an
/// RTF. `check` and `run` both call it.
pub fn check(model: &CameraModel) -> Result<()> {
    if let CameraModel::LensFile { path, rtf_fit, .. } = model {
        let lens = load_lens(path)?;
        if rtf_fit.is_some() && matches!(lens, LensFile::Rtf(_)) {
            return Err(Error::Invalid(format!(
                "{}: rtf-degree needs a lens prescription to fit, and this file is an RTF",
                path.display()
            )));
        }
    }
    Ok(())
}
