//! A minimal PLY reader for pbrt's `plymesh`: ASCII and binary (little / big
//! endian); vertex `x y z`, optional `nx ny nz` and `u v` (or `s t`,
//! `texture_u texture_v`); faces as `vertex_indices` (or `vertex_index`) lists of 3
//! or 4 vertices (quads split into two triangles). Other elements and properties
//! are skipped.

use super::to_scene::RawMesh;
use glam::{DVec3, Vec2};
use std::path::Path;

#[derive(Clone, Copy, Debug, PartialEq)]
enum Scalar {
    I8,
    U8,
    I16,
    U16,
    I32,
    U32,
    F32,
    F64,
}

fn scalar(s: &str) -> Option<Scalar> {
    Some(match s {
        "char" | "int8" => Scalar::I8,
        "uchar" | "uint8" => Scalar::U8,
        "short" | "int16" => Scalar::I16,
        "ushort" | "uint16" => Scalar::U16,
        "int" | "int32" => Scalar::I32,
        "uint" | "uint32" => Scalar::U32,
        "float" | "float32" => Scalar::F32,
        "double" | "float64" => Scalar::F64,
        _ => return None,
    })
}

#[derive(Debug)]
enum Prop {
    Scalar(Scalar, String),
    List(Scalar, Scalar, String),
}

struct Element {
    name: String,
    count: usize,
    props: Vec<Prop>,
}

#[derive(Clone, Copy, PartialEq)]
enum Format {
    Ascii,
    Le,
    Be,
}

struct Reader<'a> {
    data: &'a [u8],
    pos: usize,
    fmt: Format,
}

impl Reader<'_> {
    fn ascii_word(&mut self) -> Result<&str, String> {
        while self.pos < self.data.len() && self.data[self.pos].is_ascii_whitespace() {
            self.pos += 1;
        }
        let s = self.pos;
        while self.pos < self.data.len() && !self.data[self.pos].is_ascii_whitespace() {
            self.pos += 1;
        }
        if s == self.pos {
            return Err("unexpected end of data".into());
        }
        std::str::from_utf8(&self.data[s..self.pos]).map_err(|_| "invalid text in data".to_string())
    }
    fn read(&mut self, t: Scalar) -> Result<f64, String> {
        if self.fmt == Format::Ascii {
            let w = self.ascii_word()?;
            return w
                .parse::<f64>()
                .map_err(|_| format!("'{w}' is not a number"));
        }
        let n = match t {
            Scalar::I8 | Scalar::U8 => 1,
            Scalar::I16 | Scalar::U16 => 2,
            Scalar::I32 | Scalar::U32 | Scalar::F32 => 4,
            Scalar::F64 => 8,
        };
        if self.pos + n > self.data.len() {
            return Err("unexpected end of binary data".into());
        }
        let mut b = [0u8; 8];
        b[..n].copy_from_slice(&self.data[self.pos..self.pos + n]);
        self.pos += n;
        if self.fmt == Format::Be {
            b[..n].reverse();
        }
        Ok(match t {
            Scalar::I8 => b[0] as i8 as f64,
            Scalar::U8 => b[0] as f64,
            Scalar::I16 => i16::from_le_bytes([b[0], b[1]]) as f64,
            Scalar::U16 => u16::from_le_bytes([b[0], b[1]]) as f64,
            Scalar::I32 => i32::from_le_bytes([b[0], b[1], b[2], b[3]]) as f64,
            Scalar::U32 => u32::from_le_bytes([b[0], b[1], b[2], b[3]]) as f64,
            Scalar::F32 => f32::from_le_bytes([b[0], b[1], b[2], b[3]]) as f64,
            Scalar::F64 => f64::from_le_bytes(b),
        })
    }
}

/// Read a PLY file into an object-space mesh.
pub fn read(path: &Path) -> Result<RawMesh, String> {
    let data = std::fs::read(path)
        .map_err(|e| format!("cannot read PLY file '{}': {e}", path.display()))?;
    parse(&data).map_err(|m| format!("{}: {m}", path.display()))
}

pub fn parse(data: &[u8]) -> Result<RawMesh, String> {
    let end = data
        .windows(10)
        .position(|w| w == b"end_header")
        .ok_or("no 'end_header' in PLY header")?;
    let header = std::str::from_utf8(&data[..end]).map_err(|_| "PLY header is not text")?;
    let mut body = end + 10;
    while body < data.len() && data[body] != b'\n' {
        body += 1;
    }
    body += 1;
    let mut lines = header.lines();
    if lines.next().map(|l| l.trim()) != Some("ply") {
        return Err("not a PLY file (first line is not 'ply')".into());
    }
    let mut fmt = None;
    let mut elements: Vec<Element> = vec![];
    for line in lines {
        let w: Vec<&str> = line.split_whitespace().collect();
        match w.as_slice() {
            ["format", f, _] => {
                fmt = Some(match *f {
                    "ascii" => Format::Ascii,
                    "binary_little_endian" => Format::Le,
                    "binary_big_endian" => Format::Be,
                    _ => return Err(format!("unknown PLY format '{f}'")),
                })
            }
            ["element", name, count] => elements.push(Element {
                name: name.to_string(),
                count: count
                    .parse()
                    .map_err(|_| format!("bad element count '{count}'"))?,
                props: vec![],
            }),
            ["property", "list", ct, it, name] => {
                let e = elements.last_mut().ok_or("property before element")?;
                e.props.push(Prop::List(
                    scalar(ct).ok_or(format!("unknown type '{ct}'"))?,
                    scalar(it).ok_or(format!("unknown type '{it}'"))?,
                    name.to_string(),
                ));
            }
            ["property", t, name] => {
                let e = elements.last_mut().ok_or("property before element")?;
                e.props.push(Prop::Scalar(
                    scalar(t).ok_or(format!("unknown type '{t}'"))?,
                    name.to_string(),
                ));
            }
            ["comment", ..] | ["obj_info", ..] | [] => {}
            _ => return Err(format!("unrecognised PLY header line '{line}'")),
        }
    }
    let fmt = fmt.ok_or("PLY header has no 'format' line")?;
    let mut r = Reader {
        data,
        pos: body.min(data.len()),
        fmt,
    };
    let mut p = vec![];
    let mut n = vec![];
    let mut uv = vec![];
    let mut tri = vec![];
    for e in &elements {
        let cap = e.count.min(1 << 20);
        if e.name == "vertex" {
            p.reserve(cap);
        }
        for _ in 0..e.count {
            let mut v = [f64::NAN; 8]; // x y z nx ny nz u v
            for prop in &e.props {
                match prop {
                    Prop::Scalar(t, name) => {
                        let x = r.read(*t)?;
                        let slot = match name.as_str() {
                            "x" => 0,
                            "y" => 1,
                            "z" => 2,
                            "nx" => 3,
                            "ny" => 4,
                            "nz" => 5,
                            "u" | "s" | "texture_u" | "texture_s" => 6,
                            "v" | "t" | "texture_v" | "texture_t" => 7,
                            _ => continue,
                        };
                        v[slot] = x;
                    }
                    Prop::List(ct, it, name) => {
                        let k = r.read(*ct)?;
                        if !(0.0..=1e6).contains(&k) {
                            return Err(format!("bad list length {k}"));
                        }
                        let mut idx = Vec::with_capacity(k as usize);
                        for _ in 0..k as usize {
                            idx.push(r.read(*it)?);
                        }
                        if e.name == "face" && (name == "vertex_indices" || name == "vertex_index")
                        {
                            let ok = idx
                                .iter()
                                .all(|&i| i >= 0.0 && i.fract() == 0.0 && i < u32::MAX as f64);
                            if !ok {
                                return Err("negative or non-integer face index".into());
                            }
                            let u: Vec<u32> = idx.iter().map(|&i| i as u32).collect();
                            match u.len() {
                                3 => tri.push([u[0], u[1], u[2]]),
                                4 => {
                                    tri.push([u[0], u[1], u[2]]);
                                    tri.push([u[0], u[2], u[3]]);
                                }
                                k => {
                                    return Err(format!(
                                        "face with {k} vertices (3 or 4 supported)"
                                    ));
                                }
                            }
                        }
                    }
                }
            }
            if e.name == "vertex" {
                if v[..3].iter().any(|x| !x.is_finite()) {
                    return Err("vertex without finite x, y, z".into());
                }
                p.push(DVec3::new(v[0], v[1], v[2]));
                if v[3..6].iter().all(|x| x.is_finite()) {
                    n.push(DVec3::new(v[3], v[4], v[5]));
                }
                if v[6..8].iter().all(|x| x.is_finite()) {
                    uv.push(Vec2::new(v[6] as f32, v[7] as f32));
                }
            }
        }
    }
    if let Some(bad) = tri.iter().flatten().find(|&&i| i as usize >= p.len()) {
        return Err(format!(
            "face index {bad} out of range ({} vertices)",
            p.len()
        ));
    }
    let nv = p.len();
    Ok(RawMesh {
        p,
        n: (n.len() == nv && nv > 0).then_some(n),
        uv: (uv.len() == nv && nv > 0).then_some(uv),
        tri,
    })
}

#[cfg(test)]
mod tests {
    use super::*;
    #[test]
    fn ascii_and_binary_quads() {
        let a = b"ply\nformat ascii 1.0\nelement vertex 4\nproperty float x\nproperty float y\nproperty float z\nelement face 1\nproperty list uchar int vertex_indices\nend_header\n0 0 0\n1 0 0\n1 1 0\n0 1 0\n4 0 1 2 3\n";
        let m = parse(a).unwrap();
        assert_eq!(m.p.len(), 4);
        assert_eq!(m.tri, vec![[0, 1, 2], [0, 2, 3]]);
        let mut b = b"ply\nformat binary_little_endian 1.0\nelement vertex 3\nproperty double x\nproperty double y\nproperty double z\nelement face 1\nproperty list uchar uint vertex_indices\nend_header\n".to_vec();
        for v in [0.0f64, 0.0, 0.0, 2.0, 0.0, 0.0, 0.0, 3.0, 0.5] {
            b.extend_from_slice(&v.to_le_bytes());
        }
        b.push(3);
        for i in [0u32, 1, 2] {
            b.extend_from_slice(&i.to_le_bytes());
        }
        let m = parse(&b).unwrap();
        assert_eq!(m.p[2], DVec3::new(0.0, 3.0, 0.5));
        assert_eq!(m.tri, vec![[0, 1, 2]]);
        assert!(parse(&b[..b.len() - 2]).is_err());
    }
}
