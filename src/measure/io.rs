//! Image readers for measuring captures and renders: PNG (8/16-bit grey or
//! RGB(A)), OpenEXR (channels R, G, B and/or Y, optionally layer-prefixed
//! like `rgb.R`) and DNG / TIFF (uncompressed strips, 8 or 16 bits: a CFA
//! mosaic with `CFARepeatPatternDim`/`CFAPattern`, `BlackLevel`,
//! `WhiteLevel`; or a plain grey/RGB TIFF).
//!
//! Values are kept linear as stored (PNG code values are *not* de-gammaed:
//! a raw capture saved as 16-bit PNG is linear; an sRGB-encoded 8-bit PNG is
//! measured in code values, which the CLI notes). The DNG black level is
//! subtracted (per CFA cell when given per cell).

use super::plane::{ChannelView, Plane, channel_views, plane_views};
use crate::image::CfaPattern;
use crate::{Error, Result};
use std::path::{Path, PathBuf};

/// An image read from disk.
#[derive(Clone, Debug)]
pub struct LoadedImage {
    pub path: PathBuf,
    pub width: usize,
    pub height: usize,
    /// Full-resolution planes by name ("r", "g", "b" or "y").
    pub planes: Vec<(String, Plane)>,
    /// Raw CFA mosaic, black level subtracted (DNG with a CFA).
    pub mosaic: Option<Plane>,
    pub cfa: Option<CfaPattern>,
    pub black_level: f64,
    pub white_level: f64,
}

impl LoadedImage {
    /// The plane a measurement of `channel` reads: on a mosaic, the mosaic
    /// itself (the measurement selects its pixels); otherwise the named plane,
    /// or for `lum` the Rec. 709 luminance of R, G, B (or the single plane).
    pub fn plane_for(&self, channel: &str) -> Result<Plane> {
        if let Some(m) = &self.mosaic {
            return Ok(m.clone());
        }
        let ch = channel.to_ascii_lowercase();
        if let Some((_, p)) = self.planes.iter().find(|(n, _)| *n == ch) {
            return Ok(p.clone());
        }
        let get = |n: &str| self.planes.iter().find(|(m, _)| m == n).map(|(_, p)| p);
        match (ch.as_str(), get("r"), get("g"), get("b"), get("y")) {
            ("lum" | "y", Some(r), Some(g), Some(b), _) => Plane::new(
                self.width,
                self.height,
                (0..r.data.len())
                    .map(|i| 0.2126 * r.data[i] + 0.7152 * g.data[i] + 0.0722 * b.data[i])
                    .collect(),
            ),
            ("lum" | "y" | "g", _, _, _, Some(y)) => Ok(y.clone()),
            _ => Err(Error::invalid(format!(
                "{}: no channel '{channel}' (has {})",
                self.path.display(),
                self.planes
                    .iter()
                    .map(|p| p.0.as_str())
                    .collect::<Vec<_>>()
                    .join(", ")
            ))),
        }
    }

    /// Channel views for per-channel measurements (mosaic channels or planes).
    pub fn views(&self) -> Vec<ChannelView<'_>> {
        match &self.mosaic {
            Some(m) => channel_views(m, "y"),
            None => plane_views(&self.planes),
        }
    }
}

/// Read PNG, EXR, DNG or TIFF, chosen by the file's magic bytes.
pub fn read_image(path: &Path) -> Result<LoadedImage> {
    let bytes = std::fs::read(path).map_err(|e| Error::io(path, e))?;
    if bytes.starts_with(b"\x89PNG") {
        read_png(path, &bytes)
    } else if bytes.starts_with(&[0x76, 0x2f, 0x31, 0x01]) {
        read_exr(path)
    } else if bytes.starts_with(b"II*\0") || bytes.starts_with(b"MM\0*") {
        read_tiff(path, &bytes)
    } else {
        Err(Error::io(
            path,
            "not a PNG, OpenEXR, DNG or TIFF file (unknown magic bytes)",
        ))
    }
}

fn read_png(path: &Path, bytes: &[u8]) -> Result<LoadedImage> {
    let mut dec = png::Decoder::new(std::io::Cursor::new(bytes));
    dec.set_transformations(png::Transformations::EXPAND);
    let mut reader = dec.read_info().map_err(|e| Error::io(path, e))?;
    let size = reader
        .output_buffer_size()
        .ok_or_else(|| Error::io(path, "PNG too large"))?;
    let mut buf = vec![0u8; size];
    let info = reader
        .next_frame(&mut buf)
        .map_err(|e| Error::io(path, e))?;
    let (w, h) = (info.width as usize, info.height as usize);
    let nc = info.color_type.samples();
    let sixteen = info.bit_depth == png::BitDepth::Sixteen;
    let sample = |i: usize| -> f64 {
        if sixteen {
            u16::from_be_bytes([buf[2 * i], buf[2 * i + 1]]) as f64
        } else {
            buf[i] as f64
        }
    };
    let names: &[&str] = match nc {
        1 | 2 => &["y"],
        _ => &["r", "g", "b"],
    };
    let mut planes = vec![];
    for (c, n) in names.iter().enumerate() {
        let mut d = Vec::with_capacity(w * h);
        for y in 0..h {
            for x in 0..w {
                let bpp = if sixteen { 2 } else { 1 };
                let row = y * info.line_size / bpp;
                d.push(sample(row + x * nc + c));
            }
        }
        planes.push((n.to_string(), Plane::new(w, h, d)?));
    }
    let white = if sixteen { 65535.0 } else { 255.0 };
    Ok(LoadedImage {
        path: path.into(),
        width: w,
        height: h,
        planes,
        mosaic: None,
        cfa: None,
        black_level: 0.0,
        white_level: white,
    })
}

fn read_exr(path: &Path) -> Result<LoadedImage> {
    let img =
        exr::prelude::read_first_flat_layer_from_file(path).map_err(|e| Error::io(path, e))?;
    let size = img.layer_data.size;
    let (w, h) = (size.0, size.1);
    let mut planes = vec![];
    for ch in &img.layer_data.channel_data.list {
        let full = ch.name.to_string();
        let short = full
            .rsplit('.')
            .next()
            .unwrap_or(&full)
            .to_ascii_lowercase();
        if !matches!(short.as_str(), "r" | "g" | "b" | "y")
            || planes.iter().any(|(n, _): &(String, Plane)| *n == short)
        {
            continue;
        }
        if ch.sampling.0 != 1 || ch.sampling.1 != 1 {
            return Err(Error::NotSupported(format!(
                "{}: subsampled EXR channel '{full}'",
                path.display()
            )));
        }
        let d: Vec<f64> = ch.sample_data.values_as_f32().map(|v| v as f64).collect();
        planes.push((
            short,
            Plane::new(w, h, d).map_err(|e| Error::io(path, format!("channel {full}: {e}")))?,
        ));
    }
    if planes.is_empty() {
        return Err(Error::io(path, "EXR has none of the channels R, G, B, Y"));
    }
    planes.sort_by_key(|(n, _)| ["r", "g", "b", "y"].iter().position(|m| m == n));
    Ok(LoadedImage {
        path: path.into(),
        width: w,
        height: h,
        planes,
        mosaic: None,
        cfa: None,
        black_level: 0.0,
        white_level: f64::INFINITY,
    })
}

/// A TIFF IFD entry: tag, type, count, and the values read as f64.
struct Entry {
    tag: u16,
    values: Vec<f64>,
}

struct Tiff<'a> {
    b: &'a [u8],
    le: bool,
    path: &'a Path,
}

impl Tiff<'_> {
    fn err(&self, m: impl std::fmt::Display) -> Error {
        Error::io(self.path, format!("malformed TIFF/DNG: {m}"))
    }
    fn u16(&self, o: usize) -> Result<u16> {
        let s = self
            .b
            .get(o..o + 2)
            .ok_or_else(|| self.err(format!("offset {o} beyond the file")))?;
        Ok(if self.le {
            u16::from_le_bytes([s[0], s[1]])
        } else {
            u16::from_be_bytes([s[0], s[1]])
        })
    }
    fn u32(&self, o: usize) -> Result<u32> {
        let s = self
            .b
            .get(o..o + 4)
            .ok_or_else(|| self.err(format!("offset {o} beyond the file")))?;
        let a = [s[0], s[1], s[2], s[3]];
        Ok(if self.le {
            u32::from_le_bytes(a)
        } else {
            u32::from_be_bytes(a)
        })
    }
    fn ifd(&self, off: usize) -> Result<(Vec<Entry>, usize)> {
        let n = self.u16(off)? as usize;
        let mut out = vec![];
        for i in 0..n {
            let e = off + 2 + 12 * i;
            let tag = self.u16(e)?;
            let typ = self.u16(e + 2)?;
            let count = self.u32(e + 4)? as usize;
            let size = match typ {
                1 | 2 | 6 | 7 => 1,
                3 | 8 => 2,
                4 | 9 | 11 | 13 => 4,
                5 | 10 | 12 => 8,
                _ => continue,
            };
            if count > 1 << 24 {
                return Err(self.err(format!("tag {tag} claims {count} values")));
            }
            let base = if size * count <= 4 {
                e + 8
            } else {
                self.u32(e + 8)? as usize
            };
            let mut values = Vec::with_capacity(count);
            for k in 0..count {
                let o = base + k * size;
                values.push(match typ {
                    1 | 2 | 7 => *self
                        .b
                        .get(o)
                        .ok_or_else(|| self.err("value beyond the file"))?
                        as f64,
                    6 => *self
                        .b
                        .get(o)
                        .ok_or_else(|| self.err("value beyond the file"))?
                        as i8 as f64,
                    3 => self.u16(o)? as f64,
                    8 => self.u16(o)? as i16 as f64,
                    4 | 13 => self.u32(o)? as f64,
                    9 => self.u32(o)? as i32 as f64,
                    11 => f32::from_bits(self.u32(o)?) as f64,
                    5 => self.u32(o)? as f64 / self.u32(o + 4)?.max(1) as f64,
                    10 => self.u32(o)? as i32 as f64 / (self.u32(o + 4)? as i32).max(1) as f64,
                    _ => f64::NAN,
                });
            }
            out.push(Entry { tag, values });
        }
        let next = self.u32(off + 2 + 12 * n)? as usize;
        Ok((out, next))
    }
}

fn read_tiff(path: &Path, b: &[u8]) -> Result<LoadedImage> {
    let t = Tiff {
        b,
        le: b[0] == b'I',
        path,
    };
    // Gather IFD0 chain and SubIFDs (tag 330); pick the raw image: CFA
    // (photometric 32803) first, else the largest image.
    let mut ifds = vec![];
    let mut queue = vec![t.u32(4)? as usize];
    while let Some(off) = queue.pop() {
        if off == 0 || ifds.len() > 64 {
            continue;
        }
        let (entries, next) = t.ifd(off)?;
        if let Some(e) = entries.iter().find(|e| e.tag == 330) {
            queue.extend(e.values.iter().map(|v| *v as usize));
        }
        queue.push(next);
        ifds.push(entries);
    }
    let get = |es: &[Entry], tag: u16| es.iter().find(|e| e.tag == tag).map(|e| e.values.clone());
    let one = |es: &[Entry], tag: u16| get(es, tag).and_then(|v| v.first().copied());
    let is_cfa = |es: &[Entry]| one(es, 262) == Some(32803.0);
    let area = |es: &[Entry]| one(es, 256).unwrap_or(0.0) * one(es, 257).unwrap_or(0.0);
    let ifd = ifds
        .iter()
        .max_by(|a, b| {
            (is_cfa(a), area(a))
                .partial_cmp(&(is_cfa(b), area(b)))
                .unwrap_or(std::cmp::Ordering::Equal)
        })
        .ok_or_else(|| t.err("no image directory"))?;
    let w = one(ifd, 256).ok_or_else(|| t.err("no ImageWidth"))? as usize;
    let h = one(ifd, 257).ok_or_else(|| t.err("no ImageLength"))? as usize;
    let bits = one(ifd, 258).unwrap_or(1.0) as usize;
    let spp = one(ifd, 277).unwrap_or(1.0) as usize;
    let comp = one(ifd, 259).unwrap_or(1.0);
    if comp != 1.0 {
        return Err(Error::NotSupported(format!(
            "{}: compressed TIFF/DNG (compression {comp}); only uncompressed strips",
            path.display()
        )));
    }
    if get(ifd, 324).is_some() {
        return Err(Error::NotSupported(format!(
            "{}: tiled TIFF/DNG; only strips",
            path.display()
        )));
    }
    if bits != 8 && bits != 16 {
        return Err(Error::NotSupported(format!(
            "{}: {bits}-bit samples; only 8 and 16",
            path.display()
        )));
    }
    let offs = get(ifd, 273).ok_or_else(|| t.err("no StripOffsets"))?;
    let counts = get(ifd, 279).ok_or_else(|| t.err("no StripByteCounts"))?;
    let mut raw = Vec::with_capacity(w * h * spp * bits / 8);
    for (o, c) in offs.iter().zip(&counts) {
        let (o, c) = (*o as usize, *c as usize);
        raw.extend_from_slice(b.get(o..o + c).ok_or_else(|| {
            t.err(format!(
                "strip at {o}+{c} beyond the file ({} bytes)",
                b.len()
            ))
        })?);
    }
    let n = w * h * spp;
    if raw.len() < n * bits / 8 {
        return Err(t.err(format!(
            "strips hold {} bytes, {w}×{h}×{spp} samples need {}",
            raw.len(),
            n * bits / 8
        )));
    }
    let sample = |i: usize| -> f64 {
        if bits == 16 {
            let s = [raw[2 * i], raw[2 * i + 1]];
            (if t.le {
                u16::from_le_bytes(s)
            } else {
                u16::from_be_bytes(s)
            }) as f64
        } else {
            raw[i] as f64
        }
    };
    let white = one(ifd, 50717).unwrap_or(((1u64 << bits) - 1) as f64);
    if is_cfa(ifd) {
        if spp != 1 {
            return Err(t.err("CFA image with more than one sample per pixel"));
        }
        let dim = get(ifd, 33421).unwrap_or(vec![2.0, 2.0]);
        let (ph, pw) = (dim[0] as u32, dim.get(1).copied().unwrap_or(2.0) as u32);
        let pat = get(ifd, 33422).ok_or_else(|| t.err("CFA image without CFAPattern"))?;
        if pat.len() != (pw * ph) as usize || pat.iter().any(|&c| !(0.0..=2.0).contains(&c)) {
            return Err(Error::NotSupported(format!(
                "{}: CFA pattern {pat:?} (only R=0, G=1, B=2 cells)",
                path.display()
            )));
        }
        let cfa = CfaPattern {
            width: pw,
            height: ph,
            cells: pat.iter().map(|&c| c as u8).collect(),
            channels: vec!["r".into(), "g".into(), "b".into()],
        };
        let black = get(ifd, 50714).unwrap_or(vec![0.0]);
        let bdim = get(ifd, 50713).unwrap_or(vec![1.0, 1.0]);
        let (bh, bw) = (
            bdim[0].max(1.0) as usize,
            bdim.get(1).copied().unwrap_or(1.0).max(1.0) as usize,
        );
        let mut data = Vec::with_capacity(w * h);
        let mut chan = Vec::with_capacity(w * h);
        for y in 0..h {
            for x in 0..w {
                let bl = black
                    .get((y % bh) * bw + x % bw)
                    .or(black.first())
                    .copied()
                    .unwrap_or(0.0);
                data.push(sample(y * w + x) - bl);
                chan.push(cfa.channel_at(x as u32, y as u32) as u8);
            }
        }
        let mut m = Plane::new(w, h, data)?;
        m.channel = chan;
        m.channel_names = cfa.channels.clone();
        let bl = black.iter().sum::<f64>() / black.len().max(1) as f64;
        return Ok(LoadedImage {
            path: path.into(),
            width: w,
            height: h,
            planes: vec![],
            mosaic: Some(m),
            cfa: Some(cfa),
            black_level: bl,
            white_level: white,
        });
    }
    let names: &[&str] = if spp >= 3 { &["r", "g", "b"] } else { &["y"] };
    let mut planes = vec![];
    for (c, nm) in names.iter().enumerate() {
        planes.push((
            nm.to_string(),
            Plane::new(w, h, (0..w * h).map(|i| sample(i * spp + c)).collect())?,
        ));
    }
    Ok(LoadedImage {
        path: path.into(),
        width: w,
        height: h,
        planes,
        mosaic: None,
        cfa: None,
        black_level: 0.0,
        white_level: white,
    })
}

/// [`read_label_map`] for `image`: the map must have the image's size.
pub fn read_label_map_for(
    image: &LoadedImage,
    png_path: &Path,
    names_path: &Path,
) -> Result<(Vec<u32>, Vec<String>)> {
    let (w, h, labels, names) = read_label_map(png_path, names_path)?;
    if (w, h) != (image.width, image.height) {
        return Err(Error::io(
            png_path,
            format!(
                "label map is {w}×{h} but the captured image {} is {}×{}",
                image.path.display(),
                image.width,
                image.height
            ),
        ));
    }
    Ok((labels, names))
}

/// Object labels for a captured image: a grey PNG whose value k > 0 marks
/// object k and a text file whose k-th line (1-based) names it; value 0 is
/// "no object". Returns per-pixel label ids (k − 1, or `scene::NO_OBJECT`) and names.
pub fn read_label_map(
    png_path: &Path,
    names_path: &Path,
) -> Result<(usize, usize, Vec<u32>, Vec<String>)> {
    let im = read_image(png_path)?;
    let p = im
        .planes
        .iter()
        .find(|(n, _)| n == "y")
        .map(|(_, p)| p)
        .ok_or_else(|| Error::io(png_path, "label map must be a grey PNG"))?;
    let text = std::fs::read_to_string(names_path).map_err(|e| Error::io(names_path, e))?;
    let names: Vec<String> = text.lines().map(|l| l.trim().to_string()).collect();
    let mut labels = Vec::with_capacity(p.data.len());
    for (i, &v) in p.data.iter().enumerate() {
        let k = v as usize;
        labels.push(if k == 0 {
            crate::scene::NO_OBJECT
        } else if k <= names.len() {
            (k - 1) as u32
        } else {
            return Err(Error::io(
                png_path,
                format!(
                    "pixel ({}, {}) has label {k} but {} names only {}",
                    i % p.width,
                    i / p.width,
                    names_path.display(),
                    names.len()
                ),
            ));
        });
    }
    Ok((p.width, p.height, labels, names))
}

#[cfg(test)]
mod tests {
    use super::*;

    #[test]
    fn dng_roundtrip_subtracts_black_and_keeps_cfa() {
        let dir = tempfile::tempdir().unwrap();
        let p = dir.path().join("x.dng");
        let cfa = CfaPattern::bayer("grbg").unwrap();
        let dv: Vec<u16> = (0..6 * 4).map(|i| 64 + i as u16).collect();
        let img = crate::image::SensorImage::from_raw_dv(6, 4, &cfa, &dv, 64.0, 1023.0);
        crate::sensor::output::write_dng(&p, &img, &crate::sensor::SensorConfig::generic())
            .unwrap();
        let im = read_image(&p).unwrap();
        let m = im.mosaic.as_ref().unwrap();
        assert_eq!(
            (im.width, im.height, im.white_level, im.black_level),
            (6, 4, 1023.0, 64.0)
        );
        assert_eq!(m.get(5, 3), 23.0);
        assert_eq!(im.cfa.as_ref().unwrap(), &cfa);
        assert_eq!(m.channel_at(0, 0), Some(1));
        assert_eq!(m.channel_at(1, 0), Some(0));
    }

    #[test]
    fn png_16_and_8_bit_and_bad_files() {
        let dir = tempfile::tempdir().unwrap();
        for (depth, vals) in [
            (png::BitDepth::Sixteen, vec![0u16, 1000, 65535, 7]),
            (png::BitDepth::Eight, vec![0u16, 10, 255, 7]),
        ] {
            let p = dir.path().join("g.png");
            let f = std::fs::File::create(&p).unwrap();
            let mut e = png::Encoder::new(std::io::BufWriter::new(f), 2, 2);
            e.set_color(png::ColorType::Grayscale);
            e.set_depth(depth);
            let mut wr = e.write_header().unwrap();
            let bytes: Vec<u8> = if depth == png::BitDepth::Sixteen {
                vals.iter().flat_map(|v| v.to_be_bytes()).collect()
            } else {
                vals.iter().map(|&v| v as u8).collect()
            };
            wr.write_image_data(&bytes).unwrap();
            wr.finish().unwrap();
            let im = read_image(&p).unwrap();
            assert_eq!(
                im.plane_for("lum").unwrap().data,
                vals.iter().map(|&v| v as f64).collect::<Vec<_>>()
            );
        }
        let bad = dir.path().join("bad.png");
        std::fs::write(&bad, b"hello").unwrap();
        let e = read_image(&bad).unwrap_err().to_string();
        assert!(e.contains("bad.png") && e.contains("magic"), "{e}");
        let trunc = dir.path().join("t.dng");
        std::fs::write(&trunc, b"II*\0\x08\0\0\0\x05\0").unwrap();
        assert!(
            read_image(&trunc)
                .unwrap_err()
                .to_string()
                .contains("t.dng")
        );
    }

    #[test]
    fn exr_rgb_planes_and_luminance() {
        let dir = tempfile::tempdir().unwrap();
        let p = dir.path().join("x.exr");
        exr::prelude::write_rgb_file(&p, 3, 2, |x, y| (x as f32, y as f32, 1.0f32)).unwrap();
        let im = read_image(&p).unwrap();
        assert_eq!(
            im.planes.iter().map(|p| p.0.as_str()).collect::<Vec<_>>(),
            vec!["r", "g", "b"]
        );
        let l = im.plane_for("lum").unwrap();
        assert!((l.get(2, 1) - (0.2126 * 2.0 + 0.7152 + 0.0722)).abs() < 1e-6);
        assert_eq!(im.plane_for("r").unwrap().get(2, 0), 2.0);
    }
}
