//! The optical image: spectral irradiance at the sensor plane, W/(m²·nm),
//! for a rectangular window of the full film, with per-pixel object labels,
//! depth and Monte Carlo standard error.

use crate::spectrum::WavelengthGrid;
use serde::{Deserialize, Serialize};

/// A pixel rectangle of the full film.
#[derive(Clone, Copy, Debug, PartialEq, Eq, Hash, Serialize, Deserialize)]
pub struct Rect {
    pub x: u32,
    pub y: u32,
    pub w: u32,
    pub h: u32,
}

impl Rect {
    pub fn new(x: u32, y: u32, w: u32, h: u32) -> Self {
        Self { x, y, w, h }
    }
    pub fn contains(&self, x: u32, y: u32) -> bool {
        x >= self.x && y >= self.y && x < self.x + self.w && y < self.y + self.h
    }
    pub fn area(&self) -> u64 {
        self.w as u64 * self.h as u64
    }
    /// Smallest rectangle holding both.
    pub fn union(&self, o: &Rect) -> Rect {
        let x0 = self.x.min(o.x);
        let y0 = self.y.min(o.y);
        let x1 = (self.x + self.w).max(o.x + o.w);
        let y1 = (self.y + self.h).max(o.y + o.h);
        Rect::new(x0, y0, x1 - x0, y1 - y0)
    }
}

/// Spectral irradiance image (a window of the full film).
#[derive(Clone, Debug, Serialize, Deserialize)]
pub struct OpticalImage {
    /// Full film size in pixels.
    pub full_width: u32,
    pub full_height: u32,
    /// The window this image holds (the whole film unless ROI-rendered).
    pub window: Rect,
    /// Film pixel pitch, metres.
    pub pixel_pitch_m: f64,
    pub grid: WavelengthGrid,
    /// Irradiance, row-major over the window, band fastest: index (y·w + x)·n + band.
    pub irradiance: Vec<f32>,
    /// Standard error of each irradiance value (same layout), from independent
    /// sample batches; empty when not computed.
    pub stderr: Vec<f32>,
    /// Standard error of each weighted band sum the render was asked for
    /// (`RenderSettings::stderr_weights`), per pixel: index y·w·k + x·k + set
    /// for k sets; from the same batches. Empty when not computed.
    #[serde(default)]
    pub weighted_stderr: Vec<f32>,
    /// Object label per pixel (index into `label_names`, or `scene::NO_OBJECT`).
    pub labels: Vec<u32>,
    /// Object names indexed by label.
    pub label_names: Vec<String>,
    /// Distance along the primary ray to the first hit, metres (inf on escape).
    pub depth_m: Vec<f32>,
    /// Samples per pixel, render time and non-finite samples rejected.
    pub spp: u32,
    pub render_s: f64,
    pub nan_count: u64,
}

impl OpticalImage {
    /// A zero image of the given window.
    pub fn new(
        full_width: u32,
        full_height: u32,
        window: Rect,
        pixel_pitch_m: f64,
        grid: WavelengthGrid,
    ) -> Self {
        let n = window.area() as usize;
        let nb = grid.len();
        Self {
            full_width,
            full_height,
            window,
            pixel_pitch_m,
            irradiance: vec![0.0; n * nb],
            stderr: vec![],
            weighted_stderr: vec![],
            labels: vec![crate::scene::NO_OBJECT; n],
            label_names: vec![],
            depth_m: vec![f32::INFINITY; n],
            grid,
            spp: 0,
            render_s: 0.0,
            nan_count: 0,
        }
    }
    pub fn width(&self) -> u32 {
        self.window.w
    }
    pub fn height(&self) -> u32 {
        self.window.h
    }
    pub fn bands(&self) -> usize {
        self.grid.len()
    }
    /// Spectrum of window pixel (x, y).
    pub fn pixel(&self, x: u32, y: u32) -> &[f32] {
        let nb = self.bands();
        let i = (y as usize * self.window.w as usize + x as usize) * nb;
        &self.irradiance[i..i + nb]
    }
    pub fn pixel_mut(&mut self, x: u32, y: u32) -> &mut [f32] {
        let nb = self.bands();
        let i = (y as usize * self.window.w as usize + x as usize) * nb;
        &mut self.irradiance[i..i + nb]
    }
    /// Average each run of `k` consecutive bands into one band of `buckets`
    /// (made by `buckets.subdivided(k)`): the bucket means pbrt-v4's spectral
    /// film records. Standard errors become the mean of the `k` sub-band
    /// errors — an upper bound, since the sub-bands share their paths
    /// (sd(Σxᵢ/k) ≤ Σsd(xᵢ)/k). Per-weight-set errors are kept as they are
    /// (they were computed for whole pixels, not per band). Sums in f64.
    pub fn average_band_groups(&self, k: usize, buckets: WavelengthGrid) -> Result<Self, String> {
        let nb = self.bands();
        if k == 0 || buckets.len() * k != nb {
            return Err(format!(
                "cannot average {nb} bands in groups of {k} into {} buckets",
                buckets.len()
            ));
        }
        let avg = |v: &[f32]| -> Vec<f32> {
            v.chunks_exact(k)
                .map(|c| (c.iter().map(|&x| x as f64).sum::<f64>() / k as f64) as f32)
                .collect()
        };
        Ok(Self {
            irradiance: avg(&self.irradiance),
            stderr: avg(&self.stderr),
            grid: buckets,
            ..self.clone()
        })
    }
    /// Fold an independent render of the same window (another round of
    /// error-driven sampling, its own seed) into this one: each value becomes
    /// the spp-weighted mean (n₁m₁ + n₂m₂)/(n₁ + n₂), each standard error
    /// √((n₁s₁)² + (n₂s₂)²)/(n₁ + n₂) (the two means are independent);
    /// labels and depth stay this image's (round 0's primary hits). Sums in
    /// f64.
    pub fn combine(&mut self, other: &OpticalImage) -> Result<(), String> {
        if other.window != self.window
            || other.grid != self.grid
            || other.irradiance.len() != self.irradiance.len()
            || other.stderr.len() != self.stderr.len()
            || other.weighted_stderr.len() != self.weighted_stderr.len()
        {
            return Err(format!(
                "cannot combine optical images of different windows, grids or statistics ({:?} vs {:?})",
                self.window, other.window
            ));
        }
        let (n1, n2) = (self.spp as f64, other.spp as f64);
        let n = n1 + n2;
        if !(n1 > 0.0 && n2 > 0.0) {
            return Err("cannot combine an optical image of 0 samples".into());
        }
        let (w1, w2) = (n1 / n, n2 / n);
        for (a, b) in self.irradiance.iter_mut().zip(&other.irradiance) {
            *a = (w1 * *a as f64 + w2 * *b as f64) as f32;
        }
        let se = |a: &mut f32, b: f32| {
            *a = ((w1 * *a as f64).powi(2) + (w2 * b as f64).powi(2)).sqrt() as f32;
        };
        for (a, b) in self.stderr.iter_mut().zip(&other.stderr) {
            se(a, *b);
        }
        for (a, b) in self.weighted_stderr.iter_mut().zip(&other.weighted_stderr) {
            se(a, *b);
        }
        self.spp = self.spp.saturating_add(other.spp);
        self.render_s += other.render_s;
        self.nan_count += other.nan_count;
        Ok(())
    }

    /// Label id of a named object, if present.
    pub fn label_id(&self, name: &str) -> Option<u32> {
        self.label_names
            .iter()
            .position(|n| n == name)
            .map(|i| i as u32)
    }
}

#[cfg(test)]
mod combine_tests {
    use super::*;

    fn img(spp: u32, v: f32, se: f32) -> OpticalImage {
        let grid = WavelengthGrid::new(500.0, 510.0, 10.0).unwrap();
        let mut o = OpticalImage::new(2, 1, Rect::new(0, 0, 2, 1), 1e-6, grid);
        o.irradiance.iter_mut().for_each(|x| *x = v);
        o.stderr = vec![se; o.irradiance.len()];
        o.weighted_stderr = vec![se; 2];
        o.spp = spp;
        o
    }

    #[test]
    fn band_groups_average_into_their_buckets() {
        // Two buckets of width 10 nm centred at 400 and 410 nm, each split
        // into 4 sub-bands of 2.5 nm centred at 396.25 … 413.75 nm.
        let buckets = WavelengthGrid {
            start_nm: 400.0,
            step_nm: 10.0,
            count: 2,
        };
        let fine = buckets.subdivided(4);
        assert_eq!(fine.len(), 8);
        assert!((fine.wavelength(0) - 396.25).abs() < 1e-12);
        assert!((fine.wavelength(7) - 413.75).abs() < 1e-12);
        let mut o = OpticalImage::new(1, 1, Rect::new(0, 0, 1, 1), 1e-6, fine);
        o.irradiance = vec![1.0, 2.0, 3.0, 4.0, 10.0, 10.0, 20.0, 20.0];
        o.stderr = vec![0.1, 0.1, 0.3, 0.3, 1.0, 1.0, 1.0, 1.0];
        let b = o.average_band_groups(4, buckets.clone()).unwrap();
        assert_eq!(b.grid, buckets);
        assert_eq!(b.irradiance, vec![2.5, 15.0]);
        assert!((b.stderr[0] - 0.2).abs() < 1e-7 && (b.stderr[1] - 1.0).abs() < 1e-7);
        // A group size that does not tile the bands is refused.
        assert!(o.average_band_groups(3, buckets).is_err());
    }

    #[test]
    fn combined_rounds_are_the_spp_weighted_mean_with_independent_errors() {
        // 8 samples at mean 1 ± 0.4 and 24 at mean 3 ± 0.2: the 32-sample mean
        // is (8·1 + 24·3)/32 = 2.5, its stderr √((8·0.4)² + (24·0.2)²)/32 =
        // √(10.24 + 23.04)/32 = 0.18028.
        let mut a = img(8, 1.0, 0.4);
        a.combine(&img(24, 3.0, 0.2)).unwrap();
        assert_eq!(a.spp, 32);
        for x in &a.irradiance {
            assert!((x - 2.5).abs() < 1e-6);
        }
        for s in a.stderr.iter().chain(&a.weighted_stderr) {
            assert!((*s as f64 - (33.28f64).sqrt() / 32.0).abs() < 1e-6);
        }
        // Different windows are refused.
        let mut b = img(8, 1.0, 0.4);
        let mut c = img(8, 1.0, 0.4);
        c.window = Rect::new(1, 0, 2, 1);
        assert!(b.combine(&c).is_err());
    }
}
