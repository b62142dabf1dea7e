//! Sensor outputs: the raw mosaic as a 16-bit greyscale PNG and as a DNG
//! (uncompressed little-endian TIFF with the DNG CFA, black/white level and colour
//! tags, so raw converters open it), and a bilinear-demosaiced 8-bit preview PNG.
//!
//! DNG decisions: one IFD holding the raw CFA image (DNG 1.4, backward 1.1), one
//! strip, 16 bits per sample. `ColorMatrix1` (XYZ → camera) is fitted by least
//! squares from the sensor's own effective QE: camera RGB and CIE XYZ of the 24
//! ColorChecker patches (ISO 17321 reflectances) under D65, normalised so that D65
//! white maps to a camera neutral whose largest component is 1; `AsShotNeutral` is
//! that neutral (white balance for D65).

use super::config::SensorConfig;
use crate::diag::{Error, Result, write_atomic};
use crate::image::SensorImage;
use crate::spectrum::{WavelengthGrid, library};
use std::path::Path;

/// DV rounded and clamped to u16.
pub fn dv_u16(image: &SensorImage) -> Vec<u16> {
    image
        .dv
        .iter()
        .map(|&v| {
            if v.is_finite() {
                v.round().clamp(0.0, 65535.0) as u16
            } else {
                0
            }
        })
        .collect()
}

/// Encode 16-bit greyscale samples as PNG bytes.
pub fn png16_bytes(width: u32, height: u32, samples: &[u16]) -> Result<Vec<u8>> {
    if samples.len() != width as usize * height as usize {
        return Err(Error::invalid(
            "png16: sample count does not match width × height",
        ));
    }
    let mut out = vec![];
    {
        let mut enc = png::Encoder::new(&mut out, width, height);
        enc.set_color(png::ColorType::Grayscale);
        enc.set_depth(png::BitDepth::Sixteen);
        enc.set_compression(png::Compression::Fast);
        let mut w = enc
            .write_header()
            .map_err(|e| Error::invalid(format!("png: {e}")))?;
        let be: Vec<u8> = samples.iter().flat_map(|v| v.to_be_bytes()).collect();
        w.write_image_data(&be)
            .map_err(|e| Error::invalid(format!("png: {e}")))?;
    }
    Ok(out)
}

/// The raw mosaic as an 8-bit grey picture for a report: DV above black over
/// the white level above black, gamma 1/2.2 (the CFA pattern stays visible).
pub fn mosaic_png_bytes(image: &SensorImage) -> Result<Vec<u8>> {
    let (w, h) = (image.width() as usize, image.height() as usize);
    let range = (image.white_level_dv - image.black_level_dv).max(1.0);
    let px: Vec<u8> = image
        .dv
        .iter()
        .map(|&v| {
            let t = ((v as f64 - image.black_level_dv) / range).clamp(0.0, 1.0);
            (t.powf(1.0 / 2.2) * 255.0).round() as u8
        })
        .collect();
    if px.len() != w * h {
        return Err(Error::invalid(
            "mosaic picture: pixel count does not match the image",
        ));
    }
    let mut out = vec![];
    {
        let mut enc = png::Encoder::new(&mut out, w as u32, h as u32);
        enc.set_color(png::ColorType::Grayscale);
        enc.set_depth(png::BitDepth::Eight);
        let mut wr = enc
            .write_header()
            .map_err(|e| Error::invalid(format!("png: {e}")))?;
        wr.write_image_data(&px)
            .map_err(|e| Error::invalid(format!("png: {e}")))?;
    }
    Ok(out)
}

/// Write the raw mosaic DV as a 16-bit PNG (atomically).
pub fn write_raw_png(path: &Path, image: &SensorImage) -> Result<()> {
    write_atomic(
        path,
        &png16_bytes(image.width(), image.height(), &dv_u16(image))?,
    )
}

/// Read a 16-bit (or 8-bit) greyscale PNG: (width, height, samples).
pub fn read_png16(path: &Path) -> Result<(u32, u32, Vec<u16>)> {
    let f = std::fs::File::open(path).map_err(|e| Error::io(path, e))?;
    let dec = png::Decoder::new(std::io::BufReader::new(f));
    let mut r = dec.read_info().map_err(|e| Error::io(path, e))?;
    let size = r
        .output_buffer_size()
        .ok_or_else(|| Error::io(path, "image too large"))?;
    let mut buf = vec![0u8; size];
    let info = r.next_frame(&mut buf).map_err(|e| Error::io(path, e))?;
    if info.color_type != png::ColorType::Grayscale {
        return Err(Error::io(
            path,
            format!("expected a greyscale raw PNG, found {:?}", info.color_type),
        ));
    }
    let (w, h) = (info.width, info.height);
    let v: Vec<u16> = match info.bit_depth {
        png::BitDepth::Sixteen => buf[..info.buffer_size()]
            .chunks_exact(2)
            .map(|c| u16::from_be_bytes([c[0], c[1]]))
            .collect(),
        png::BitDepth::Eight => buf[..info.buffer_size()]
            .iter()
            .map(|&b| b as u16)
            .collect(),
        d => return Err(Error::io(path, format!("unsupported PNG bit depth {d:?}"))),
    };
    if v.len() != w as usize * h as usize {
        return Err(Error::io(path, "PNG rows are padded or truncated"));
    }
    Ok((w, h, v))
}

/// XYZ → camera matrix (row-major 3×3) and the D65 camera neutral, from the
/// sensor's effective QE (see module docs). `None` for non-RGB sensors.
pub fn dng_color(cfg: &SensorConfig) -> Option<([f64; 9], [f64; 3])> {
    if cfg.cfa.channels.len() != 3 {
        return None;
    }
    let grid = WavelengthGrid::new(400.0, 700.0, 5.0).ok()?;
    let d65 = library::named("cie-d65").ok()?;
    let cmf = library::cie1931_cmfs();
    let resp = |refl: &dyn Fn(f64) -> f64| -> ([f64; 3], [f64; 3]) {
        let (mut cam, mut xyz) = ([0.0; 3], [0.0; 3]);
        for i in 0..grid.len() {
            let l = grid.wavelength(i);
            let e = d65.eval(l) * refl(l);
            let q = cfg.effective_qe(l);
            for c in 0..3 {
                cam[c] += e * q[c] * l; // photon counting
                xyz[c] += e * cmf[c].eval(l);
            }
        }
        (cam, xyz)
    };
    // Normal equations for cam = M · xyz over the 24 patches.
    let (mut xtx, mut xty) = ([[0.0f64; 3]; 3], [[0.0f64; 3]; 3]);
    for p in 1..=24 {
        let s = library::named(&format!("mcc-iso-{p:02}")).ok()?;
        let (cam, xyz) = resp(&|l| s.eval(l));
        for a in 0..3 {
            for b in 0..3 {
                xtx[a][b] += xyz[a] * xyz[b];
                xty[a][b] += xyz[a] * cam[b];
            }
        }
    }
    let inv = invert3(&xtx)?;
    // M^T = inv(XᵀX)·XᵀY  → M[r][c] = Σ_k inv[c][k]·xty[k][r]
    let mut m = [0.0f64; 9];
    for r in 0..3 {
        for c in 0..3 {
            m[r * 3 + c] = (0..3).map(|k| inv[c][k] * xty[k][r]).sum();
        }
    }
    let (white_cam, white_xyz) = resp(&|_| 1.0);
    // Scale so that XYZ of D65 with Y = 1 maps to a neutral with max component 1.
    let xyz1 = [
        white_xyz[0] / white_xyz[1],
        1.0,
        white_xyz[2] / white_xyz[1],
    ];
    let n: Vec<f64> = (0..3)
        .map(|r| (0..3).map(|c| m[r * 3 + c] * xyz1[c]).sum())
        .collect();
    let mx = n.iter().cloned().fold(0.0, f64::max);
    if !mx.is_finite() || mx <= 0.0 {
        return None;
    }
    for v in &mut m {
        *v /= mx;
    }
    let wmax = white_cam.iter().cloned().fold(0.0, f64::max);
    let neutral = [
        white_cam[0] / wmax,
        white_cam[1] / wmax,
        white_cam[2] / wmax,
    ];
    if m.iter().chain(&neutral).any(|v| !v.is_finite()) || neutral.iter().any(|&v| v <= 0.0) {
        return None;
    }
    Some((m, neutral))
}

#[allow(clippy::needless_range_loop)]
fn invert3(a: &[[f64; 3]; 3]) -> Option<[[f64; 3]; 3]> {
    let det = a[0][0] * (a[1][1] * a[2][2] - a[1][2] * a[2][1])
        - a[0][1] * (a[1][0] * a[2][2] - a[1][2] * a[2][0])
        + a[0][2] * (a[1][0] * a[2][1] - a[1][1] * a[2][0]);
    if !det.is_finite() || det.abs() < 1e-300 {
        return None;
    }
    let mut r = [[0.0; 3]; 3];
    for i in 0..3 {
        for j in 0..3 {
            let (i1, i2) = ((j + 1) % 3, (j + 2) % 3);
            let (j1, j2) = ((i + 1) % 3, (i + 2) % 3);
            r[i][j] = (a[i1][j1] * a[i2][j2] - a[i1][j2] * a[i2][j1]) / det;
        }
    }
    Some(r)
}

enum Val {
    Byte(Vec<u8>),
    Ascii(String),
    Short(Vec<u16>),
    Long(Vec<u32>),
    Rational(Vec<(u32, u32)>),
    SRational(Vec<(i32, i32)>),
}

impl Val {
    fn type_count(&self) -> (u16, u32) {
        match self {
            Val::Byte(v) => (1, v.len() as u32),
            Val::Ascii(s) => (2, s.len() as u32 + 1),
            Val::Short(v) => (3, v.len() as u32),
            Val::Long(v) => (4, v.len() as u32),
            Val::Rational(v) => (5, v.len() as u32),
            Val::SRational(v) => (10, v.len() as u32),
        }
    }
    fn bytes(&self) -> Vec<u8> {
        match self {
            Val::Byte(v) => v.clone(),
            Val::Ascii(s) => {
                let mut b = s.as_bytes().to_vec();
                b.push(0);
                b
            }
            Val::Short(v) => v.iter().flat_map(|x| x.to_le_bytes()).collect(),
            Val::Long(v) => v.iter().flat_map(|x| x.to_le_bytes()).collect(),
            Val::Rational(v) => v
                .iter()
                .flat_map(|(a, b)| [a.to_le_bytes(), b.to_le_bytes()].concat())
                .collect(),
            Val::SRational(v) => v
                .iter()
                .flat_map(|(a, b)| [a.to_le_bytes(), b.to_le_bytes()].concat())
                .collect(),
        }
    }
}

fn srational(x: f64) -> (i32, i32) {
    (
        (x * 10000.0)
            .round()
            .clamp(i32::MIN as f64, i32::MAX as f64) as i32,
        10000,
    )
}
fn rational(x: f64) -> (u32, u32) {
    (
        (x * 10000.0).round().clamp(0.0, u32::MAX as f64) as u32,
        10000,
    )
}

/// Encode a raw sensor image as DNG bytes.
pub fn dng_bytes(image: &SensorImage, cfg: &SensorConfig) -> Result<Vec<u8>> {
    let (w, h) = (image.width(), image.height());
    if w == 0 || h == 0 {
        return Err(Error::invalid("DNG: empty image"));
    }
    let samples = dv_u16(image);
    let model = if cfg.name.is_empty() {
        "camsim sensor".to_string()
    } else {
        format!("camsim {}", cfg.name)
    };
    let mut tags: Vec<(u16, Val)> = vec![
        (254, Val::Long(vec![0])),
        (256, Val::Long(vec![w])),
        (257, Val::Long(vec![h])),
        (258, Val::Short(vec![16])),
        (259, Val::Short(vec![1])),
        (271, Val::Ascii("camsim".into())),
        (272, Val::Ascii(model.clone())),
        (273, Val::Long(vec![0])), // patched below
        (274, Val::Short(vec![1])),
        (277, Val::Short(vec![1])),
        (278, Val::Long(vec![h])),
        (279, Val::Long(vec![w * h * 2])),
        (284, Val::Short(vec![1])),
        (305, Val::Ascii(format!("camsim {}", crate::version()))),
        (50706, Val::Byte(vec![1, 4, 0, 0])),
        (50707, Val::Byte(vec![1, 1, 0, 0])),
        (50708, Val::Ascii(model)),
        (50713, Val::Short(vec![1, 1])),
        (50714, Val::Rational(vec![rational(image.black_level_dv)])),
        (
            50717,
            Val::Long(vec![image.white_level_dv.round().clamp(1.0, 65535.0) as u32]),
        ),
    ];
    let rgb = image.cfa.channels.len() == 3;
    if rgb {
        let (cw, ch) = (image.cfa.width, image.cfa.height);
        let mut pat = vec![];
        for dy in 0..ch {
            for dx in 0..cw {
                pat.push(
                    image
                        .cfa
                        .channel_at(image.window.x + dx, image.window.y + dy)
                        as u8,
                );
            }
        }
        tags.push((262, Val::Short(vec![32803])));
        tags.push((33421, Val::Short(vec![ch as u16, cw as u16])));
        tags.push((33422, Val::Byte(pat)));
        tags.push((50710, Val::Byte(vec![0, 1, 2])));
        tags.push((50711, Val::Short(vec![1])));
        let (m, neutral) = dng_color(cfg).ok_or_else(|| {
            Error::invalid("DNG: cannot derive a colour matrix from the sensor QE")
        })?;
        tags.push((
            50721,
            Val::SRational(m.iter().map(|&x| srational(x)).collect()),
        ));
        tags.push((
            50728,
            Val::Rational(neutral.iter().map(|&x| rational(x)).collect()),
        ));
        tags.push((50778, Val::Short(vec![21])));
    } else {
        tags.push((262, Val::Short(vec![34892])));
    }
    tags.sort_by_key(|t| t.0);
    // Layout: header (8) | IFD | out-of-line values | strip.
    let ifd_len = 2 + 12 * tags.len() + 4;
    let mut extra: Vec<u8> = vec![];
    let extra_start = 8 + ifd_len;
    // (tag, type, count, inline value or offset)
    let mut entries: Vec<(u16, u16, u32, [u8; 4])> = vec![];
    for (tag, v) in &tags {
        let (ty, count) = v.type_count();
        let b = v.bytes();
        if b.len() <= 4 {
            let mut inl = [0u8; 4];
            inl[..b.len()].copy_from_slice(&b);
            entries.push((*tag, ty, count, inl));
        } else {
            if extra.len() % 2 == 1 {
                extra.push(0);
            }
            let off = extra_start + extra.len();
            extra.extend_from_slice(&b);
            entries.push((*tag, ty, count, (off as u32).to_le_bytes()));
        }
    }
    if extra.len() % 2 == 1 {
        extra.push(0);
    }
    let strip_off = (extra_start + extra.len()) as u32;
    let mut out = Vec::with_capacity(strip_off as usize + samples.len() * 2);
    out.extend_from_slice(b"II*\0");
    out.extend_from_slice(&8u32.to_le_bytes());
    out.extend_from_slice(&(tags.len() as u16).to_le_bytes());
    for (tag, ty, count, mut inl) in entries {
        if tag == 273 {
            inl = strip_off.to_le_bytes();
        }
        out.extend_from_slice(&tag.to_le_bytes());
        out.extend_from_slice(&ty.to_le_bytes());
        out.extend_from_slice(&count.to_le_bytes());
        out.extend_from_slice(&inl);
    }
    out.extend_from_slice(&0u32.to_le_bytes());
    out.extend_from_slice(&extra);
    for s in samples {
        out.extend_from_slice(&s.to_le_bytes());
    }
    Ok(out)
}

/// Write a DNG (atomically).
pub fn write_dng(path: &Path, image: &SensorImage, cfg: &SensorConfig) -> Result<()> {
    write_atomic(path, &dng_bytes(image, cfg)?)
}

/// Bilinear demosaic: every channel at every pixel, from the average of the pixels of
/// that channel in the 3×3 neighbourhood (the pixel itself when it has the channel).
/// Black level subtracted; values in DV above black. Returns channel-interleaved data.
pub fn demosaic_bilinear(image: &SensorImage) -> Vec<f32> {
    let (w, h) = (image.width() as i64, image.height() as i64);
    let nch = image.cfa.channels.len();
    let b = image.black_level_dv as f32;
    let mut out = vec![0f32; (w * h) as usize * nch];
    for y in 0..h {
        for x in 0..w {
            let own = image.channel_at(x as u32, y as u32);
            let o = ((y * w + x) as usize) * nch;
            let mut sum = vec![0f32; nch];
            let mut cnt = vec![0u32; nch];
            for dy in -1..=1 {
                for dx in -1..=1 {
                    let (xx, yy) = (x + dx, y + dy);
                    if xx < 0 || yy < 0 || xx >= w || yy >= h {
                        continue;
                    }
                    let c = image.channel_at(xx as u32, yy as u32);
                    sum[c] += image.dv[(yy * w + xx) as usize] - b;
                    cnt[c] += 1;
                }
            }
            for c in 0..nch {
                out[o + c] = if c == own {
                    image.dv[(y * w + x) as usize] - b
                } else if cnt[c] > 0 {
                    sum[c] / cnt[c] as f32
                } else {
                    0.0
                };
            }
        }
    }
    out
}

/// An 8-bit sRGB-gamma preview: bilinear demosaic, white balance by `neutral` (camera
/// response to white; all ones = none), scaled so the 99.5th percentile is white.
pub fn preview_png_bytes(image: &SensorImage, neutral: &[f64]) -> Result<Vec<u8>> {
    let nch = image.cfa.channels.len();
    let d = demosaic_bilinear(image);
    let n = (image.width() * image.height()) as usize;
    if n == 0 {
        return Err(Error::invalid("preview: empty image"));
    }
    let gains: Vec<f32> = (0..nch)
        .map(|c| 1.0 / neutral.get(c).copied().unwrap_or(1.0).max(1e-6) as f32)
        .collect();
    let mut lum: Vec<f32> = (0..n)
        .map(|i| {
            (0..nch)
                .map(|c| d[i * nch + c] * gains[c])
                .fold(0.0, f32::max)
        })
        .collect();
    lum.sort_by(|a, b| a.total_cmp(b));
    let top = lum[((n as f64 * 0.995) as usize).min(n - 1)].max(1e-6);
    let enc = |v: f32| -> u8 {
        let x = (v / top).clamp(0.0, 1.0);
        let s = if x <= 0.0031308 {
            12.92 * x
        } else {
            1.055 * x.powf(1.0 / 2.4) - 0.055
        };
        (s * 255.0).round() as u8
    };
    let mut rgb = Vec::with_capacity(n * 3);
    for i in 0..n {
        if nch == 3 {
            for c in 0..3 {
                rgb.push(enc(d[i * 3 + c] * gains[c]));
            }
        } else {
            let v = enc(d[i * nch] * gains[0]);
            rgb.extend_from_slice(&[v, v, v]);
        }
    }
    let mut out = vec![];
    {
        let mut e = png::Encoder::new(&mut out, image.width(), image.height());
        e.set_color(png::ColorType::Rgb);
        e.set_depth(png::BitDepth::Eight);
        let mut w = e
            .write_header()
            .map_err(|e| Error::invalid(format!("png: {e}")))?;
        w.write_image_data(&rgb)
            .map_err(|e| Error::invalid(format!("png: {e}")))?;
    }
    Ok(out)
}

/// Write the demosaiced preview PNG, white-balanced for D65 when the sensor is RGB.
pub fn write_preview_png(path: &Path, image: &SensorImage, cfg: &SensorConfig) -> Result<()> {
    let neutral = dng_color(cfg)
        .map(|(_, n)| n.to_vec())
        .unwrap_or_else(|| vec![1.0; image.cfa.channels.len()]);
    write_atomic(path, &preview_png_bytes(image, &neutral)?)
}
