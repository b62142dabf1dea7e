//! Colorimetry of a named spectrum: CIE 1931 chromaticity and luminance,
//! integrated on a wavelength grid with the shipped CMFs (trapezoid rule).

use crate::Result;
use crate::figure::Figure;
use crate::params::{Kind, ParamDict, ParamError, ParamSpec, Schema};
use crate::spectrum::{Spectrum, WavelengthGrid};
use std::path::Path;

/// `measure "colorimetry" spectrum="…" [wavelength-nm=(start stop step)]`.
#[derive(Clone, Debug, Default)]
pub struct ColorimetryOptions {
    /// The spectrum as written and as resolved (required).
    pub spectrum: Option<(String, Spectrum)>,
    /// The integration grid; None = the variant's render grid.
    pub grid: Option<WavelengthGrid>,
}

/// The properties of `measure "colorimetry"`.
pub static SCHEMA: Schema = Schema {
    node: "measure \"colorimetry\"",
    params: &[
        super::shared_params::name_param(),
        ParamSpec {
            name: "spectrum",
            kind: Kind::Spectrum,
            default: "",
            doc: "the spectrum measured (required): a shipped name or `file.csv#column`",
            example: "\"cie-a\"",
        },
        ParamSpec {
            name: "wavelength-nm",
            kind: Kind::Numbers,
            default: "the render grid",
            doc: "integration grid (start stop step), nm",
            example: "(400 700 5)",
        },
    ],
};

/// Read `measure "colorimetry"` (see [`SCHEMA`]); the spectrum is resolved
/// relative to `base_dir`.
pub fn from_params(
    d: &ParamDict,
    base_dir: &Path,
) -> std::result::Result<ColorimetryOptions, ParamError> {
    let spectrum = match d.str("spectrum")? {
        None => None,
        Some(s) => {
            let spd = crate::spectrum::library::resolve(s, base_dir).map_err(|e| {
                let mut err = ParamError::value("spectrum", e.clone());
                if let Some(i) = e.find("(did you mean") {
                    err.help = Some(e[i + 1..e.len() - 1].to_string());
                    err.message = e[..i].trim().to_string();
                }
                err
            })?;
            Some((s.to_string(), spd))
        }
    };
    let grid = match d.f64s("wavelength-nm")? {
        None => None,
        Some(v) if v.len() == 3 => Some(
            WavelengthGrid::new(v[0], v[1], v[2])
                .map_err(|e| ParamError::value("wavelength-nm", format!("'wavelength-nm': {e}")))?,
        ),
        Some(_) => {
            return Err(ParamError::value(
                "wavelength-nm",
                "'wavelength-nm': expected (start stop step) in nm",
            )
            .with_help("e.g. wavelength-nm=(400 700 10)"));
        }
    };
    Ok(ColorimetryOptions { spectrum, grid })
}

/// CIE 1931 chromaticity and luminance of the spectrum, on the options' grid
/// (else `default_grid`). Exact arithmetic on tabulated data: the standard
/// error is 0. For a radiance in W/(sr·m²·nm) the luminance is reported in
/// cd/m²; for any other unit the quantity is `Y` = ∫S·ȳ dλ in the spectrum's
/// unit × nm, labelled "relative".
pub fn colorimetry(
    measurement: &str,
    o: &ColorimetryOptions,
    default_grid: &WavelengthGrid,
) -> Result<Vec<Figure>> {
    let Some((_, spd)) = &o.spectrum else {
        return Err(crate::Error::invalid(
            "colorimetry needs spectrum=\"<name>\" (e.g. spectrum=\"cie-d65\")",
        ));
    };
    let grid = o.grid.as_ref().unwrap_or(default_grid);
    let (x, y) = crate::spectrum::chromaticity(spd, grid);
    let mut out = vec![
        Figure::new(measurement, "x", "1", x, 0.0),
        Figure::new(measurement, "y", "1", y, 0.0),
    ];
    if spd.unit == "W/(sr·m²·nm)" {
        out.push(Figure::new(
            measurement,
            "luminance",
            "cd/m2",
            crate::spectrum::units::luminance(spd, grid),
            0.0,
        ));
    } else {
        let y_rel = crate::spectrum::units::luminance(spd, grid)
            / crate::spectrum::units::LUMINOUS_EFFICACY_LM_PER_W;
        out.push(Figure::new(measurement, "Y", "relative", y_rel, 0.0));
    }
    Ok(out)
}
