//! What a measurement reads from a variant: the optical and sensor images
//! and the film rectangles the render stage chose per object, and the
//! conversions between full-frame and window pixels.

use crate::image::SensorImage;
use crate::optical_image::{OpticalImage, Rect};
use crate::sensor::SensorConfig;
use crate::spectrum::WavelengthGrid;
use crate::{Error, Result};
use std::collections::BTreeMap;

/// The images and choices of the render stage a measurement reads.
pub struct Inputs<'a> {
    pub oi: Option<&'a OpticalImage>,
    pub si: Option<&'a SensorImage>,
    /// The variant's sensor (file + inline properties), when it has one.
    pub sensor: Option<&'a SensorConfig>,
    /// Per measured object, the film rectangle (full-frame pixels) the render
    /// stage chose for it.
    pub object_rects: &'a BTreeMap<String, Rect>,
    /// The variant's render seed (noise regions are drawn with it unless
    /// `seed=` is given).
    pub seed: u64,
    /// The variant's wavelength grid (colorimetry's default).
    pub grid: &'a WavelengthGrid,
}

/// A full-frame rectangle in window pixels of an image whose window is `w`.
pub fn to_window(r: Rect, w: Rect, what: &str) -> Result<Rect> {
    let x0 = r.x.max(w.x);
    let y0 = r.y.max(w.y);
    let x1 = (r.x + r.w).min(w.x + w.w);
    let y1 = (r.y + r.h).min(w.y + w.h);
    if x1 <= x0 || y1 <= y0 {
        return Err(Error::invalid(format!(
            "{what} (x {} y {} w {} h {}) is outside the rendered window (x {} y {} w {} h {})",
            r.x, r.y, r.w, r.h, w.x, w.y, w.w, w.h
        )));
    }
    Ok(Rect::new(x0 - w.x, y0 - w.y, x1 - x0, y1 - y0))
}

/// Bounding box (window pixels) of the pixels labelled `name` or below it
/// (`name/…`); None when no pixel carries it.
pub fn label_box(labels: &[u32], names: &[String], w: u32, h: u32, name: &str) -> Option<Rect> {
    let ids: Vec<u32> = names
        .iter()
        .enumerate()
        .filter(|(_, n)| *n == name || n.strip_prefix(name).is_some_and(|r| r.starts_with('/')))
        .map(|(i, _)| i as u32)
        .collect();
    let (mut x0, mut y0, mut x1, mut y1) = (u32::MAX, u32::MAX, 0u32, 0u32);
    for y in 0..h {
        for x in 0..w {
            if ids.contains(&labels[(y * w + x) as usize]) {
                x0 = x0.min(x);
                y0 = y0.min(y);
                x1 = x1.max(x + 1);
                y1 = y1.max(y + 1);
            }
        }
    }
    (x0 != u32::MAX).then(|| Rect::new(x0, y0, x1 - x0, y1 - y0))
}
