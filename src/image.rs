//! Sensor-side images: colour filter array layout and the raw mosaic produced by
//! the sensor model, which measurements read.

use serde::{Deserialize, Serialize};

/// A colour filter array: a `width`×`height` tile of channel indices, anchored at
/// full-frame pixel (0,0), so windows of the frame keep the mosaic phase.
#[derive(Clone, Debug, PartialEq, Eq, Serialize, Deserialize)]
pub struct CfaPattern {
    pub width: u32,
    pub height: u32,
    /// Channel index per tile cell, row-major.
    pub cells: Vec<u8>,
    /// Channel names, e.g. ["r", "g", "b"].
    pub channels: Vec<String>,
}

impl CfaPattern {
    /// Parse a Bayer-style name like "rggb", "bggr", "grbg", "gbrg", or "mono".
    pub fn bayer(name: &str) -> Result<Self, String> {
        let name = name.to_ascii_lowercase();
        if name == "mono" {
            return Ok(Self {
                width: 1,
                height: 1,
                cells: vec![0],
                channels: vec!["w".into()],
            });
        }
        if name.len() != 4 || !name.chars().all(|c| matches!(c, 'r' | 'g' | 'b')) {
            return Err(format!(
                "unknown CFA pattern '{name}': expected rggb, bggr, grbg, gbrg or mono"
            ));
        }
        let cells = name.chars().map(|c| match c {
            'r' => 0,
            'g' => 1,
            _ => 2,
        });
        Ok(Self {
            width: 2,
            height: 2,
            cells: cells.collect(),
            channels: vec!["r".into(), "g".into(), "b".into()],
        })
    }
    /// Channel index at full-frame pixel (x, y).
    pub fn channel_at(&self, x: u32, y: u32) -> usize {
        self.cells[((y % self.height) * self.width + (x % self.width)) as usize] as usize
    }
    pub fn channel_index(&self, name: &str) -> Option<usize> {
        self.channels.iter().position(|c| c == name)
    }
}

/// Raw sensor output for a window of the full frame.
#[derive(Clone, Debug, Serialize, Deserialize)]
pub struct SensorImage {
    pub full_width: u32,
    pub full_height: u32,
    pub window: crate::optical_image::Rect,
    pub pixel_pitch_m: f64,
    pub cfa: CfaPattern,
    /// Digital values including the black level, row-major over the window.
    pub dv: Vec<f32>,
    /// Electrons per pixel before conversion (for analysis; empty if not kept).
    pub electrons: Vec<f32>,
    pub black_level_dv: f64,
    pub white_level_dv: f64,
    /// Conversion gain, DV per electron.
    pub conversion_gain_dv_per_e: f64,
    /// Object label per pixel, carried from the optical image (empty if none).
    pub labels: Vec<u32>,
    pub label_names: Vec<String>,
    pub exposure_s: f64,
}

impl SensorImage {
    /// Hand the DV and electron buffers back for the next frame of a sequence
    /// ([`crate::frame_buffer::for_overwrite`]).
    pub fn recycle(self) {
        crate::frame_buffer::recycle(self.dv);
        crate::frame_buffer::recycle(self.electrons);
    }

    pub fn width(&self) -> u32 {
        self.window.w
    }
    pub fn height(&self) -> u32 {
        self.window.h
    }
    pub fn dv_at(&self, x: u32, y: u32) -> f32 {
        self.dv[(y * self.window.w + x) as usize]
    }
    /// Channel at window pixel (x, y).
    pub fn channel_at(&self, x: u32, y: u32) -> usize {
        self.cfa.channel_at(self.window.x + x, self.window.y + y)
    }
    /// A full-frame raw image from stored digital values (e.g. to write a
    /// synthetic capture with `sensor::output::write_dng`); no labels, no
    /// electrons, conversion gain 1 DV/e⁻, pixel pitch 1 µm, exposure 0 s.
    pub fn from_raw_dv(
        width: u32,
        height: u32,
        cfa: &CfaPattern,
        dv: &[u16],
        black_level_dv: f64,
        white_level_dv: f64,
    ) -> Self {
        Self {
            full_width: width,
            full_height: height,
            window: crate::optical_image::Rect::new(0, 0, width, height),
            pixel_pitch_m: 1e-6,
            cfa: cfa.clone(),
            dv: dv.iter().map(|&v| v as f32).collect(),
            electrons: vec![],
            black_level_dv,
            white_level_dv,
            conversion_gain_dv_per_e: 1.0,
            labels: vec![],
            label_names: vec![],
            exposure_s: 0.0,
        }
    }
}
