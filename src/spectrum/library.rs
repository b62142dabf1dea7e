//! Named spectra shipped with camsim (embedded in the binary from `data/`, so the
//! tool stands alone). Every entry records the file it came from; `data/README.md`
//! gives each file's provenance.
//!
//! Names (use them in KDL as `spectrum="cie-d65"`):
//! - illuminants: `cie-a`, `cie-d65`, `cie-f2` (relative, CIE tables), `iset-d65`, `iset-a`
//!   (ISETCam's copies), `gretag-a`, `gretag-cwf`, `gretag-day` (W/(sr·m²·nm)),
//!   `cbox-lamp` (the Cornell box area light, PR-670 `cbox-lights-1`, W/(sr·m²·nm)),
//!   `cbox-lamp-2020-11-03`;
//! - surfaces: `cbox-red-wall`, `cbox-green-wall`, `cbox-white-wall`, `mcc-mini-01`…`mcc-mini-24`
//!   (the paper's miniature chart, column-major, white = 04), `mcc-01`…`mcc-24`
//!   (standard chart, same layout), `mcc-iso-01`…`mcc-iso-24` (ISO 17321, row-major);
//! - sensor: `p4a-qe-r|g|b` (corrected QE, IR cut included), `imx363-qe-r|g|b` (nominal,
//!   no IR cut), `ircf-largan`;
//! - CIE: `cie1931-x`, `cie1931-y`, `cie1931-z`;
//! - constants: `zero`, `one`, `constant:<value>` (e.g. `constant:0.5`).
//!
//! Anything else is read as `PATH.csv#column` relative to the referring file.

use super::csv::SpectralTable;
use super::{Extrapolation, Spectrum};
use std::path::Path;
use std::sync::OnceLock;

struct Embedded {
    path: &'static str,
    text: &'static str,
}

macro_rules! embed {
    ($p:literal) => {
        Embedded {
            path: $p,
            text: include_str!(concat!(env!("CARGO_MANIFEST_DIR"), "/", $p)),
        }
    };
}

const FILES: &[Embedded] = &[
    embed!("data/cie/cie1931_2deg_cmf_380-780_5nm.csv"),
    embed!("data/lights/cie_illuminants_A_D65_F2_380-780_5nm.csv"),
    embed!("data/lights/D65.csv"),
    embed!("data/lights/illuminantA.csv"),
    embed!("data/lights/gretag_illA_20201023.csv"),
    embed!("data/lights/gretag_illCWF_20201023.csv"),
    embed!("data/lights/gretag_illDay_20201023.csv"),
    embed!("data/cornellbox/pr670_2020-12-11_radiance.csv"),
    embed!("data/cornellbox/cbox_lamp_spd_2020-11-03.csv"),
    embed!("data/cornellbox/cbox_surfaces_reflectance.csv"),
    embed!("data/surfaces/MiniatureMacbethChart_reflectance.csv"),
    embed!("data/surfaces/macbethChart_reflectance.csv"),
    embed!("data/surfaces/macbeth_colorchecker_ohta_iso17321_380-780_5nm.csv"),
    embed!("data/sensor/p4a_corrected_color_filters.csv"),
    embed!("data/sensor/imx363_qe_public.csv"),
    embed!("data/sensor/ircf_public_Largan_K098-BIR690UV.csv"),
];

/// (name, file, column index (0-based among value columns), extrapolation, unit)
type Entry = (String, &'static str, usize, Extrapolation, &'static str);

fn entries() -> &'static Vec<Entry> {
    static E: OnceLock<Vec<Entry>> = OnceLock::new();
    E.get_or_init(|| {
        use Extrapolation::*;
        let rad = "W/(sr·m²·nm)";
        let mut v: Vec<Entry> = vec![
            (
                "cie1931-x".into(),
                "data/cie/cie1931_2deg_cmf_380-780_5nm.csv",
                0,
                Zero,
                "1",
            ),
            (
                "cie1931-y".into(),
                "data/cie/cie1931_2deg_cmf_380-780_5nm.csv",
                1,
                Zero,
                "1",
            ),
            (
                "cie1931-z".into(),
                "data/cie/cie1931_2deg_cmf_380-780_5nm.csv",
                2,
                Zero,
                "1",
            ),
            (
                "cie-a".into(),
                "data/lights/cie_illuminants_A_D65_F2_380-780_5nm.csv",
                0,
                Zero,
                "relative",
            ),
            (
                "cie-d65".into(),
                "data/lights/cie_illuminants_A_D65_F2_380-780_5nm.csv",
                1,
                Zero,
                "relative",
            ),
            (
                "cie-f2".into(),
                "data/lights/cie_illuminants_A_D65_F2_380-780_5nm.csv",
                2,
                Zero,
                "relative",
            ),
            (
                "iset-d65".into(),
                "data/lights/D65.csv",
                0,
                Zero,
                "relative",
            ),
            (
                "iset-a".into(),
                "data/lights/illuminantA.csv",
                0,
                Zero,
                "relative",
            ),
            (
                "gretag-a".into(),
                "data/lights/gretag_illA_20201023.csv",
                0,
                Zero,
                rad,
            ),
            (
                "gretag-cwf".into(),
                "data/lights/gretag_illCWF_20201023.csv",
                0,
                Zero,
                rad,
            ),
            (
                "gretag-day".into(),
                "data/lights/gretag_illDay_20201023.csv",
                0,
                Zero,
                rad,
            ),
            (
                "cbox-lamp-2020-11-03".into(),
                "data/cornellbox/cbox_lamp_spd_2020-11-03.csv",
                0,
                Zero,
                rad,
            ),
            (
                "cbox-red-wall".into(),
                "data/cornellbox/cbox_surfaces_reflectance.csv",
                0,
                Clamp,
                "1",
            ),
            (
                "cbox-green-wall".into(),
                "data/cornellbox/cbox_surfaces_reflectance.csv",
                1,
                Clamp,
                "1",
            ),
            (
                "cbox-white-wall".into(),
                "data/cornellbox/cbox_surfaces_reflectance.csv",
                2,
                Clamp,
                "1",
            ),
            (
                "p4a-qe-r".into(),
                "data/sensor/p4a_corrected_color_filters.csv",
                0,
                Zero,
                "1",
            ),
            (
                "p4a-qe-g".into(),
                "data/sensor/p4a_corrected_color_filters.csv",
                1,
                Zero,
                "1",
            ),
            (
                "p4a-qe-b".into(),
                "data/sensor/p4a_corrected_color_filters.csv",
                2,
                Zero,
                "1",
            ),
            (
                "imx363-qe-r".into(),
                "data/sensor/imx363_qe_public.csv",
                0,
                Zero,
                "1",
            ),
            (
                "imx363-qe-g".into(),
                "data/sensor/imx363_qe_public.csv",
                1,
                Zero,
                "1",
            ),
            (
                "imx363-qe-b".into(),
                "data/sensor/imx363_qe_public.csv",
                2,
                Zero,
                "1",
            ),
            (
                "ircf-largan".into(),
                "data/sensor/ircf_public_Largan_K098-BIR690UV.csv",
                0,
                Zero,
                "1",
            ),
        ];
        // The Cornell box lamp: PR-670 column 'cbox-lights-1' (index found by name below).
        v.push((
            "cbox-lamp".into(),
            "data/cornellbox/pr670_2020-12-11_radiance.csv",
            usize::MAX,
            Zero,
            rad,
        ));
        for i in 1..=24 {
            v.push((
                format!("mcc-mini-{i:02}"),
                "data/surfaces/MiniatureMacbethChart_reflectance.csv",
                i - 1,
                Clamp,
                "1",
            ));
            v.push((
                format!("mcc-{i:02}"),
                "data/surfaces/macbethChart_reflectance.csv",
                i - 1,
                Clamp,
                "1",
            ));
            v.push((
                format!("mcc-iso-{i:02}"),
                "data/surfaces/macbeth_colorchecker_ohta_iso17321_380-780_5nm.csv",
                i - 1,
                Clamp,
                "1",
            ));
        }
        v
    })
}

fn table(path: &str) -> &'static SpectralTable {
    static T: OnceLock<Vec<SpectralTable>> = OnceLock::new();
    let all = T.get_or_init(|| {
        FILES
            .iter()
            .map(|f| {
                SpectralTable::parse(f.text, f.path).expect("embedded spectral data must parse")
            })
            .collect()
    });
    let i = FILES
        .iter()
        .position(|f| f.path == path)
        .expect("embedded file is listed");
    &all[i]
}

/// All shipped spectrum names.
pub fn names() -> Vec<String> {
    entries().iter().map(|e| e.0.clone()).collect()
}

/// A shipped spectrum by name (see module docs), or an error with a suggestion.
pub fn named(name: &str) -> Result<Spectrum, String> {
    if name == "zero" {
        return Ok(Spectrum::constant("zero", 0.0));
    }
    if name == "one" {
        return Ok(Spectrum::constant("one", 1.0));
    }
    if let Some(v) = name.strip_prefix("constant:") {
        let x: f64 = v
            .parse()
            .map_err(|_| format!("'{name}': expected constant:<number>"))?;
        if !x.is_finite() {
            return Err(format!("'{name}': constant must be finite"));
        }
        return Ok(Spectrum::constant(name, x));
    }
    let Some((n, file, col, ex, unit)) = entries().iter().find(|e| e.0 == name) else {
        let all = names();
        let hint = crate::diag::did_you_mean(name, all.iter().map(|s| s.as_str()))
            .map(|s| format!(" (did you mean '{s}'?)"))
            .unwrap_or_default();
        return Err(format!("unknown spectrum '{name}'{hint}"));
    };
    let t = table(file);
    let column = if *col == usize::MAX {
        "cbox-lights-1".to_string()
    } else {
        t.columns[*col].0.clone()
    };
    let mut s = t.spectrum(&column)?;
    s.name = n.clone();
    Ok(s.with_extrapolation(*ex).with_unit(*unit))
}

/// Resolve a spectrum reference: a shipped name, or `PATH.csv#column` relative to `base_dir`.
pub fn resolve(reference: &str, base_dir: &Path) -> Result<Spectrum, String> {
    if let Some((path, col)) = reference.split_once('#') {
        let p = base_dir.join(path);
        let t = SpectralTable::load(&p)?;
        let mut s = t.spectrum(col)?;
        if let Some(u) = t.units() {
            s.unit = u.to_string();
        }
        return Ok(s);
    }
    named(reference)
}

/// CIE 1931 2° colour-matching functions x̄, ȳ, z̄.
pub fn cie1931_cmfs() -> &'static [Spectrum; 3] {
    static C: OnceLock<[Spectrum; 3]> = OnceLock::new();
    C.get_or_init(|| {
        [
            named("cie1931-x").unwrap(),
            named("cie1931-y").unwrap(),
            named("cie1931-z").unwrap(),
        ]
    })
}

#[cfg(test)]
mod tests {
    use super::*;
    #[test]
    fn every_name_loads() {
        for n in names() {
            let s = named(&n).unwrap_or_else(|e| panic!("{n}: {e}"));
            assert!(s.values.iter().all(|v| v.is_finite()));
        }
        let lamp = named("cbox-lamp").unwrap();
        // README: peak ≈3.9e-3 W/(sr·m²·nm) at 615 nm
        let (i, peak) = lamp
            .values
            .iter()
            .enumerate()
            .fold((0, 0.0), |a, (i, &v)| if v > a.1 { (i, v) } else { a });
        assert!((peak - 3.9e-3).abs() < 0.2e-3, "{peak}");
        assert!((lamp.wavelengths_nm[i] - 615.0).abs() <= 10.0);
    }
    #[test]
    fn unknown_names_suggest() {
        let e = named("cie-d56").unwrap_err();
        assert!(e.contains("did you mean 'cie-d65'"), "{e}");
    }
}
