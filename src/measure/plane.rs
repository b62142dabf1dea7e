//! A 2-D plane of values with an optional colour-filter channel per pixel:
//! the common input of the measurements. Built from a [`SensorImage`] (raw
//! mosaic, black level subtracted) or from any single-channel image.

use crate::image::SensorImage;
use crate::optical_image::Rect;
use crate::{Error, Result};

/// Row-major values; `channel[i]` is the CFA channel index of pixel `i`
/// (empty for a plane where every pixel carries the same quantity).
#[derive(Clone, Debug, PartialEq)]
pub struct Plane {
    pub width: usize,
    pub height: usize,
    pub data: Vec<f64>,
    pub channel: Vec<u8>,
    /// Channel names (e.g. ["r","g","b"]); empty for a single-channel plane.
    pub channel_names: Vec<String>,
}

impl Plane {
    /// A single-channel plane; errors on a size mismatch or non-finite values.
    pub fn new(width: usize, height: usize, data: Vec<f64>) -> Result<Self> {
        if data.len() != width * height {
            return Err(Error::invalid(format!(
                "plane of {width}×{height} needs {} values, got {}",
                width * height,
                data.len()
            )));
        }
        if let Some(i) = data.iter().position(|v| !v.is_finite()) {
            return Err(Error::invalid(format!(
                "non-finite value at pixel ({}, {})",
                i % width.max(1),
                i / width.max(1)
            )));
        }
        Ok(Self {
            width,
            height,
            data,
            channel: vec![],
            channel_names: vec![],
        })
    }

    /// The raw mosaic of a sensor image, black level subtracted (DV).
    pub fn from_sensor(img: &SensorImage) -> Result<Self> {
        let (w, h) = (img.width() as usize, img.height() as usize);
        let data: Vec<f64> = img
            .dv
            .iter()
            .map(|&v| v as f64 - img.black_level_dv)
            .collect();
        let mut p = Plane::new(w, h, data)?;
        if img.cfa.cells.len() > 1 {
            p.channel = (0..h)
                .flat_map(|y| (0..w).map(move |x| (x, y)))
                .map(|(x, y)| img.channel_at(x as u32, y as u32) as u8)
                .collect();
            p.channel_names = img.cfa.channels.clone();
        }
        Ok(p)
    }

    pub fn is_mosaic(&self) -> bool {
        !self.channel.is_empty()
    }
    pub fn get(&self, x: usize, y: usize) -> f64 {
        self.data[y * self.width + x]
    }
    pub fn channel_at(&self, x: usize, y: usize) -> Option<u8> {
        self.channel.get(y * self.width + x).copied()
    }
    /// Index of a channel name ("r", "g", "b", …).
    pub fn channel_index(&self, name: &str) -> Option<u8> {
        self.channel_names
            .iter()
            .position(|c| c == name)
            .map(|i| i as u8)
    }

    /// The sub-plane inside `r` (which must lie inside the plane).
    pub fn crop(&self, r: Rect) -> Result<Plane> {
        let (x0, y0, w, h) = (r.x as usize, r.y as usize, r.w as usize, r.h as usize);
        if w == 0 || h == 0 || x0 + w > self.width || y0 + h > self.height {
            return Err(Error::invalid(format!(
                "region {},{},{},{} (x,y,w,h) is empty or outside the {}×{} image",
                r.x, r.y, r.w, r.h, self.width, self.height
            )));
        }
        let mut data = Vec::with_capacity(w * h);
        let mut channel = Vec::new();
        for y in y0..y0 + h {
            data.extend_from_slice(&self.data[y * self.width + x0..y * self.width + x0 + w]);
            if self.is_mosaic() {
                channel
                    .extend_from_slice(&self.channel[y * self.width + x0..y * self.width + x0 + w]);
            }
        }
        Ok(Plane {
            width: w,
            height: h,
            data,
            channel,
            channel_names: self.channel_names.clone(),
        })
    }

    /// Swap rows and columns.
    pub fn transpose(&self) -> Plane {
        let (w, h) = (self.width, self.height);
        let mut data = vec![0.0; w * h];
        let mut channel = vec![0u8; if self.is_mosaic() { w * h } else { 0 }];
        for y in 0..h {
            for x in 0..w {
                data[x * h + y] = self.data[y * w + x];
                if self.is_mosaic() {
                    channel[x * h + y] = self.channel[y * w + x];
                }
            }
        }
        Plane {
            width: h,
            height: w,
            data,
            channel,
            channel_names: self.channel_names.clone(),
        }
    }
}

/// Parse "x,y,w,h" (pixels).
pub fn parse_rect(s: &str) -> Result<Rect> {
    let v: Vec<&str> = s.split(',').map(|t| t.trim()).collect();
    let bad = || {
        Error::invalid(format!(
            "bad region '{s}': expected x,y,w,h in whole pixels, e.g. 10,20,64,80"
        ))
    };
    if v.len() != 4 {
        return Err(bad());
    }
    let n: Vec<u32> = v
        .iter()
        .map(|t| t.parse::<u32>())
        .collect::<std::result::Result<_, _>>()
        .map_err(|_| bad())?;
    if n[2] == 0 || n[3] == 0 {
        return Err(bad());
    }
    Ok(Rect::new(n[0], n[1], n[2], n[3]))
}

#[cfg(test)]
mod tests {
    use super::*;
    #[test]
    fn crop_transpose_and_rect_parsing() {
        let p = Plane::new(3, 2, vec![0., 1., 2., 3., 4., 5.]).unwrap();
        let t = p.transpose();
        assert_eq!((t.width, t.height), (2, 3));
        assert_eq!(t.get(1, 2), 5.0);
        assert_eq!(p.crop(Rect::new(1, 1, 2, 1)).unwrap().data, vec![4., 5.]);
        assert!(p.crop(Rect::new(2, 0, 2, 1)).is_err());
        assert_eq!(parse_rect("1, 2,3,4").unwrap(), Rect::new(1, 2, 3, 4));
        assert!(parse_rect("1,2,3").is_err());
        assert!(Plane::new(1, 1, vec![f64::NAN]).is_err());
    }
}

/// One channel of an image: a whole plane (`index` None) or the pixels of one
/// CFA channel of a mosaic plane.
#[derive(Clone, Copy, Debug)]
pub struct ChannelView<'a> {
    pub name: &'a str,
    pub plane: &'a Plane,
    pub index: Option<u8>,
}

impl ChannelView<'_> {
    /// The value at (x, y) if that pixel belongs to this channel.
    pub fn value(&self, x: usize, y: usize) -> Option<f64> {
        match self.index {
            Some(c) if self.plane.channel_at(x, y) != Some(c) => None,
            _ => Some(self.plane.get(x, y)),
        }
    }
}

/// Channel views of a mosaic (one per CFA channel) or of a single-channel plane
/// (one view named `single_name`).
pub fn channel_views<'a>(plane: &'a Plane, single_name: &'a str) -> Vec<ChannelView<'a>> {
    if plane.is_mosaic() {
        plane
            .channel_names
            .iter()
            .enumerate()
            .map(|(i, n)| ChannelView {
                name: n,
                plane,
                index: Some(i as u8),
            })
            .collect()
    } else {
        vec![ChannelView {
            name: single_name,
            plane,
            index: None,
        }]
    }
}

/// Views of separate full planes, e.g. the R, G, B planes of an RGB image.
pub fn plane_views(planes: &[(String, Plane)]) -> Vec<ChannelView<'_>> {
    planes
        .iter()
        .map(|(n, p)| ChannelView {
            name: n,
            plane: p,
            index: None,
        })
        .collect()
}

/// Label ids of named objects; errors name the missing object and suggest the nearest.
pub fn label_ids(label_names: &[String], objects: &[String]) -> Result<Vec<u32>> {
    objects
        .iter()
        .map(|o| {
            label_names
                .iter()
                .position(|n| n == o)
                .map(|i| i as u32)
                .ok_or_else(|| {
                    let hint = crate::diag::did_you_mean(o, label_names.iter().map(|s| s.as_str()))
                        .map(|s| format!("; did you mean '{s}'?"))
                        .unwrap_or_default();
                    Error::invalid(format!("no object labelled '{o}' in the image{hint}"))
                })
        })
        .collect()
}
