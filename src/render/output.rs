//! Writing an optical image: multichannel spectral EXR, sRGB PNG preview and
//! a JSON sidecar. All files are written atomically.
//!
//! EXR channels: `R`, `G`, `B` (linear sRGB, D65 white, from the CIE 1931 2°
//! CMFs: X = Σ E(λ)·x̄(λ)·Δλ with trapezoid weights, so RGB carries W/m²
//! weighted by the CMFs — no photometric 683 lm/W factor), one channel per
//! wavelength named as pbrt-v4's spectral film does (`S0.` + `%.3f` nm with the
//! decimal point written as a comma, e.g. `S0.400,000nm`; OpenEXR spectral
//! layout), values in W/(m²·nm), and `Z` (depth along the primary ray, m).

use crate::diag::write_atomic;
use crate::optical_image::OpticalImage;
use crate::spectrum::library;
use crate::{Error, Result};
use std::path::Path;

/// pbrt-v4 channel name for a wavelength.
pub fn spectral_channel_name(lambda_nm: f64) -> String {
    format!("S0.{:.3}nm", lambda_nm)
        .replace('.', ",")
        .replacen("S0,", "S0.", 1)
}

/// Linear sRGB (D65) of every pixel, row-major.
pub fn linear_srgb(img: &OpticalImage) -> Vec<[f32; 3]> {
    let cmf = library::cie1931_cmfs();
    let g = &img.grid;
    let nb = g.len();
    let w: Vec<[f64; 3]> = (0..nb)
        .map(|i| {
            let l = g.wavelength(i);
            let t = g.trapezoid_weight(i);
            [cmf[0].eval(l) * t, cmf[1].eval(l) * t, cmf[2].eval(l) * t]
        })
        .collect();
    const M: [[f64; 3]; 3] = [
        [3.2404542, -1.5371385, -0.4985314],
        [-0.9692660, 1.8760108, 0.0415560],
        [0.0556434, -0.2040259, 1.0572252],
    ];
    img.irradiance
        .chunks_exact(nb)
        .map(|px| {
            let mut xyz = [0.0f64; 3];
            for (e, wi) in px.iter().zip(&w) {
                for k in 0..3 {
                    xyz[k] += *e as f64 * wi[k];
                }
            }
            let mut rgb = [0.0f32; 3];
            for k in 0..3 {
                rgb[k] = (M[k][0] * xyz[0] + M[k][1] * xyz[1] + M[k][2] * xyz[2]) as f32;
            }
            rgb
        })
        .collect()
}

/// Write the spectral EXR.
pub fn write_exr(path: &Path, img: &OpticalImage) -> Result<()> {
    use exr::prelude::*;
    let (w, h) = (img.width() as usize, img.height() as usize);
    let nb = img.bands();
    let rgb = linear_srgb(img);
    let mut list: SmallVec<[AnyChannel<FlatSamples>; 4]> = SmallVec::new();
    for (k, name) in ["R", "G", "B"].iter().enumerate() {
        list.push(AnyChannel::new(
            *name,
            FlatSamples::F32(rgb.iter().map(|p| p[k]).collect()),
        ));
    }
    for b in 0..nb {
        let name = spectral_channel_name(img.grid.wavelength(b));
        list.push(AnyChannel::new(
            name.as_str(),
            FlatSamples::F32(img.irradiance.iter().skip(b).step_by(nb).copied().collect()),
        ));
    }
    list.push(AnyChannel::new("Z", FlatSamples::F32(img.depth_m.clone())));
    let layer = Layer::new(
        (w, h),
        LayerAttributes::default(),
        Encoding::FAST_LOSSLESS,
        AnyChannels::sort(list),
    );
    let image = Image::from_layer(layer);
    let mut buf = std::io::Cursor::new(Vec::new());
    image
        .write()
        .to_buffered(&mut buf)
        .map_err(|e| crate::Error::io(path, e))?;
    write_atomic(path, buf.get_ref())
}

fn srgb_encode(x: f32) -> u8 {
    let x = x.clamp(0.0, 1.0);
    let v = if x <= 0.0031308 {
        12.92 * x
    } else {
        1.055 * x.powf(1.0 / 2.4) - 0.055
    };
    (v * 255.0 + 0.5) as u8
}

/// Write an 8-bit sRGB PNG preview, auto-exposed so that the 99th percentile
/// of luminance maps to 1.
pub fn write_png_preview(path: &Path, img: &OpticalImage) -> Result<()> {
    let rgb = linear_srgb(img);
    let mut lum: Vec<f32> = rgb
        .iter()
        .map(|p| 0.2126 * p[0] + 0.7152 * p[1] + 0.0722 * p[2])
        .filter(|y| y.is_finite())
        .collect();
    lum.sort_by(|a, b| a.total_cmp(b));
    let p99 = lum
        .get(((lum.len() as f64 * 0.99) as usize).min(lum.len().saturating_sub(1)))
        .copied()
        .unwrap_or(0.0);
    let k = if p99 > 0.0 { 1.0 / p99 } else { 1.0 };
    let data: Vec<u8> = rgb
        .iter()
        .flat_map(|p| {
            [
                srgb_encode(p[0] * k),
                srgb_encode(p[1] * k),
                srgb_encode(p[2] * k),
            ]
        })
        .collect();
    let mut out = Vec::new();
    {
        let mut enc = png::Encoder::new(&mut out, img.width(), img.height());
        enc.set_color(png::ColorType::Rgb);
        enc.set_depth(png::BitDepth::Eight);
        let mut wr = enc.write_header().map_err(|e| Error::io(path, e))?;
        wr.write_image_data(&data).map_err(|e| Error::io(path, e))?;
    }
    write_atomic(path, &out)
}

/// Write the JSON sidecar.
pub fn write_sidecar(path: &Path, value: &serde_json::Value) -> Result<()> {
    let s = serde_json::to_string_pretty(value).map_err(|e| Error::io(path, e))?;
    write_atomic(path, s.as_bytes())
}

#[cfg(test)]
mod tests {
    #[test]
    fn pbrt_v4_channel_names() {
        assert_eq!(super::spectral_channel_name(400.0), "S0.400,000nm");
        assert_eq!(super::spectral_channel_name(555.5), "S0.555,500nm");
    }
}
