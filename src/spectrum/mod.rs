//! Spectra: wavelength grids, sampled spectra with declared interpolation and
//! extrapolation, the CSV format of `data/`, named spectra and radiometric /
//! photometric conversions.
//!
//! Units: wavelength in nanometres; spectral quantities are per nanometre
//! (radiance W/(sr·m²·nm), irradiance W/(m²·nm)); reflectance and QE are 0–1.

pub mod color;
pub mod csv;
pub mod library;
pub mod units;

use serde::{Deserialize, Serialize};

/// A regular wavelength grid: `start_nm, start_nm + step_nm, …` with `count` samples.
/// Default: 400–700 nm at 10 nm (31 bands), as ISETCam and pbrt-v4's spectral film.
#[derive(Clone, Debug, PartialEq, Serialize, Deserialize)]
pub struct WavelengthGrid {
    pub start_nm: f64,
    pub step_nm: f64,
    pub count: usize,
}

impl Default for WavelengthGrid {
    fn default() -> Self {
        Self {
            start_nm: 400.0,
            step_nm: 10.0,
            count: 31,
        }
    }
}

impl WavelengthGrid {
    /// Grid from start to stop inclusive. The count is rounded, so 400..=700 step 10
    /// gives 31 bands even though 300/10 is not exact in floating point.
    pub fn new(start_nm: f64, stop_nm: f64, step_nm: f64) -> Result<Self, String> {
        if !(start_nm.is_finite() && stop_nm.is_finite() && step_nm.is_finite()) {
            return Err("wavelength grid values must be finite".into());
        }
        if start_nm <= 0.0 {
            return Err(format!("wavelength start must be > 0 nm, got {start_nm}"));
        }
        if step_nm <= 0.0 {
            return Err(format!("wavelength step must be > 0 nm, got {step_nm}"));
        }
        if stop_nm < start_nm {
            return Err(format!(
                "wavelength stop {stop_nm} nm is below start {start_nm} nm"
            ));
        }
        let n = ((stop_nm - start_nm) / step_nm + 1e-9).floor() as usize + 1;
        if n > 10_000 {
            return Err(format!(
                "wavelength grid has {n} samples; at most 10000 allowed"
            ));
        }
        Ok(Self {
            start_nm,
            step_nm,
            count: n,
        })
    }
    pub fn len(&self) -> usize {
        self.count
    }
    pub fn is_empty(&self) -> bool {
        self.count == 0
    }
    /// Wavelength of band `i` in nm (computed as start + i·step, never accumulated).
    pub fn wavelength(&self, i: usize) -> f64 {
        self.start_nm + i as f64 * self.step_nm
    }
    pub fn wavelengths(&self) -> Vec<f64> {
        (0..self.count).map(|i| self.wavelength(i)).collect()
    }
    pub fn stop_nm(&self) -> f64 {
        self.wavelength(self.count.saturating_sub(1))
    }
    /// The grid that splits each band of this one (taken as a bucket of
    /// width `step_nm` centred on its wavelength, as pbrt-v4's spectral film
    /// buckets) into `k` equal sub-bands, sampled at their centres: bucket
    /// `i` is the mean of fine bands `i·k … i·k + k − 1` (midpoint rule over
    /// the bucket).
    pub fn subdivided(&self, k: usize) -> Self {
        let k = k.max(1);
        let step = self.step_nm / k as f64;
        Self {
            start_nm: self.start_nm - 0.5 * self.step_nm + 0.5 * step,
            step_nm: step,
            count: self.count * k,
        }
    }
    /// Width of band `i` for integration (trapezoid weights: half at the ends).
    pub fn trapezoid_weight(&self, i: usize) -> f64 {
        if self.count == 1 {
            self.step_nm
        } else if i == 0 || i + 1 == self.count {
            0.5 * self.step_nm
        } else {
            self.step_nm
        }
    }
}

/// How a sampled spectrum is evaluated between its samples.
#[derive(Clone, Copy, Debug, PartialEq, Eq, Serialize, Deserialize, Default)]
pub enum Interpolation {
    #[default]
    Linear,
    /// Value of the nearest sample.
    Nearest,
}

/// How a sampled spectrum is evaluated outside its wavelength range.
#[derive(Clone, Copy, Debug, PartialEq, Eq, Serialize, Deserialize, Default)]
pub enum Extrapolation {
    /// Zero outside the sampled range (QE, illuminants: no data means no signal).
    #[default]
    Zero,
    /// Hold the end values constant (reflectances).
    Clamp,
    /// Refuse: evaluating outside the range is an error found when resampling.
    Error,
}

/// A spectrum sampled at increasing wavelengths.
#[derive(Clone, Debug, PartialEq, Serialize, Deserialize)]
pub struct Spectrum {
    pub name: String,
    pub wavelengths_nm: Vec<f64>,
    pub values: Vec<f64>,
    pub interpolation: Interpolation,
    pub extrapolation: Extrapolation,
    /// Unit of the values, e.g. "W/(sr·m²·nm)", "1" for reflectance.
    pub unit: String,
}

impl Spectrum {
    pub fn new(
        name: impl Into<String>,
        wavelengths_nm: Vec<f64>,
        values: Vec<f64>,
    ) -> Result<Self, String> {
        let name = name.into();
        if wavelengths_nm.len() != values.len() {
            return Err(format!(
                "spectrum '{name}': {} wavelengths but {} values",
                wavelengths_nm.len(),
                values.len()
            ));
        }
        if wavelengths_nm.is_empty() {
            return Err(format!("spectrum '{name}' has no samples"));
        }
        for (i, (&w, &v)) in wavelengths_nm.iter().zip(&values).enumerate() {
            if !w.is_finite() || !v.is_finite() {
                return Err(format!(
                    "spectrum '{name}': sample {i} is not finite ({w} nm, {v})"
                ));
            }
            if i > 0 && w <= wavelengths_nm[i - 1] {
                return Err(format!(
                    "spectrum '{name}': wavelengths must increase ({} then {w} nm)",
                    wavelengths_nm[i - 1]
                ));
            }
        }
        Ok(Self {
            name,
            wavelengths_nm,
            values,
            interpolation: Interpolation::Linear,
            extrapolation: Extrapolation::Zero,
            unit: "1".into(),
        })
    }
    pub fn constant(name: impl Into<String>, value: f64) -> Self {
        Self {
            name: name.into(),
            wavelengths_nm: vec![1.0, 100_000.0],
            values: vec![value, value],
            interpolation: Interpolation::Linear,
            extrapolation: Extrapolation::Clamp,
            unit: "1".into(),
        }
    }
    pub fn with_extrapolation(mut self, e: Extrapolation) -> Self {
        self.extrapolation = e;
        self
    }
    pub fn with_unit(mut self, unit: impl Into<String>) -> Self {
        self.unit = unit.into();
        self
    }
    pub fn scaled(mut self, k: f64) -> Self {
        for v in &mut self.values {
            *v *= k;
        }
        self
    }
    pub fn min_nm(&self) -> f64 {
        self.wavelengths_nm[0]
    }
    pub fn max_nm(&self) -> f64 {
        *self.wavelengths_nm.last().unwrap()
    }
    /// Evaluate at `lambda_nm` (Err only with `Extrapolation::Error` outside the range).
    pub fn try_eval(&self, lambda_nm: f64) -> Result<f64, String> {
        let w = &self.wavelengths_nm;
        let v = &self.values;
        let n = w.len();
        if lambda_nm < w[0] || lambda_nm > w[n - 1] {
            return match self.extrapolation {
                Extrapolation::Zero => Ok(0.0),
                Extrapolation::Clamp => Ok(if lambda_nm < w[0] { v[0] } else { v[n - 1] }),
                Extrapolation::Error => Err(format!(
                    "spectrum '{}' is defined on {}–{} nm, asked for {lambda_nm} nm",
                    self.name,
                    w[0],
                    w[n - 1]
                )),
            };
        }
        if n == 1 {
            return Ok(v[0]);
        }
        // first index with w[i] >= lambda
        let i = w.partition_point(|&x| x < lambda_nm);
        if i == 0 {
            return Ok(v[0]);
        }
        let (w0, w1, v0, v1) = (w[i - 1], w[i], v[i - 1], v[i]);
        Ok(match self.interpolation {
            Interpolation::Linear => {
                let t = (lambda_nm - w0) / (w1 - w0);
                v0 + t * (v1 - v0)
            }
            Interpolation::Nearest => {
                if lambda_nm - w0 <= w1 - lambda_nm {
                    v0
                } else {
                    v1
                }
            }
        })
    }
    /// Evaluate, treating `Extrapolation::Error` as zero (use `resample` to get the error).
    pub fn eval(&self, lambda_nm: f64) -> f64 {
        self.try_eval(lambda_nm).unwrap_or(0.0)
    }
    /// Point samples on a grid.
    pub fn resample(&self, grid: &WavelengthGrid) -> Result<Vec<f64>, String> {
        (0..grid.len())
            .map(|i| self.try_eval(grid.wavelength(i)))
            .collect()
    }
    /// Trapezoid integral of self(λ)·other(λ) over a grid, in value-units × nm.
    pub fn integrate_product(&self, other: &Spectrum, grid: &WavelengthGrid) -> f64 {
        (0..grid.len())
            .map(|i| {
                let l = grid.wavelength(i);
                self.eval(l) * other.eval(l) * grid.trapezoid_weight(i)
            })
            .sum()
    }
}

/// CIE 1931 XYZ of a spectral power distribution on `grid` (unnormalised; Y in
/// units of the SPD × nm). Uses the shipped CIE 1931 2° CMFs.
pub fn xyz(spd: &Spectrum, grid: &WavelengthGrid) -> [f64; 3] {
    let cmf = library::cie1931_cmfs();
    [
        spd.integrate_product(&cmf[0], grid),
        spd.integrate_product(&cmf[1], grid),
        spd.integrate_product(&cmf[2], grid),
    ]
}

/// CIE xy chromaticity of an SPD.
pub fn chromaticity(spd: &Spectrum, grid: &WavelengthGrid) -> (f64, f64) {
    let [x, y, z] = xyz(spd, grid);
    let s = x + y + z;
    if s <= 0.0 { (0.0, 0.0) } else { (x / s, y / s) }
}

#[cfg(test)]
mod tests {
    use super::*;

    #[test]
    fn grid_count_is_robust_to_float_steps() {
        assert_eq!(WavelengthGrid::new(400.0, 700.0, 10.0).unwrap().len(), 31);
        assert_eq!(WavelengthGrid::new(0.4, 0.7, 0.1).unwrap().len(), 4);
        assert_eq!(WavelengthGrid::new(380.0, 780.0, 5.0).unwrap().len(), 81);
        assert!(WavelengthGrid::new(400.0, 300.0, 10.0).is_err());
        assert!(WavelengthGrid::new(400.0, 700.0, 0.0).is_err());
        assert!(WavelengthGrid::new(400.0, 700.0, f64::NAN).is_err());
    }

    #[test]
    fn interpolation_and_extrapolation() {
        let s = Spectrum::new("t", vec![400.0, 500.0], vec![0.0, 1.0]).unwrap();
        assert!((s.eval(450.0) - 0.5).abs() < 1e-15);
        assert_eq!(s.eval(399.0), 0.0);
        let c = s.clone().with_extrapolation(Extrapolation::Clamp);
        assert_eq!(c.eval(600.0), 1.0);
        let e = s.with_extrapolation(Extrapolation::Error);
        assert!(e.try_eval(600.0).is_err());
        assert!(Spectrum::new("bad", vec![500.0, 400.0], vec![1.0, 1.0]).is_err());
        assert!(Spectrum::new("nan", vec![400.0], vec![f64::NAN]).is_err());
    }

    #[test]
    fn d65_chromaticity_from_shipped_cmfs() {
        // Acceptance (issue 2): D65 with the shipped CMFs gives (0.3127, 0.3290) within 1e-4.
        let d65 = library::named("cie-d65").unwrap();
        let grid = WavelengthGrid::new(380.0, 780.0, 5.0).unwrap();
        let (x, y) = chromaticity(&d65, &grid);
        assert!((x - 0.3127).abs() < 1e-4, "x = {x}");
        assert!((y - 0.3290).abs() < 1e-4, "y = {y}");
    }
}
