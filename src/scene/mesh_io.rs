//! Triangle-mesh loaders: Wavefront OBJ (`tobj`), glTF 2.0 (`gltf`, all mesh
//! primitives of the default scene with their node transforms), and PLY
//! (ASCII, binary little- and big-endian; a small reader of our own).
//!
//! Every loader returns one `Mesh` (material and object ids 0, for the caller
//! to set) plus warnings. Triangles with a non-finite vertex or zero area are
//! dropped with a warning naming the file; an out-of-range index is an error;
//! a mesh with no triangle left is an error naming the file. Vertex
//! normals are kept only when every vertex has a finite, non-zero one.

use super::model::Mesh;
use crate::{Error, Result};
use glam::{Mat4, Vec3};
use std::path::Path;

/// A loaded mesh and the notes made while loading it.
#[derive(Clone, Debug)]
pub struct LoadedMesh {
    pub mesh: Mesh,
    pub warnings: Vec<String>,
}

/// Load a mesh by file extension (`.obj`, `.gltf`, `.glb`, `.ply`).
pub fn load_mesh(path: &Path) -> Result<LoadedMesh> {
    let ext = path
        .extension()
        .and_then(|e| e.to_str())
        .unwrap_or("")
        .to_ascii_lowercase();
    let (positions, normals, tris) = match ext.as_str() {
        "obj" => load_obj(path)?,
        "gltf" | "glb" => load_gltf(path)?,
        "ply" => load_ply(path)?,
        _ => {
            return Err(Error::invalid(format!(
                "{}: unknown mesh format '.{ext}' (expected .obj, .gltf, .glb or .ply)",
                path.display()
            )));
        }
    };
    finish(path, positions, normals, tris)
}

type Raw = (Vec<Vec3>, Option<Vec<Vec3>>, Vec<[u32; 3]>);

/// Validate and clean: drop non-finite and degenerate triangles (with a warning).
fn finish(
    path: &Path,
    positions: Vec<Vec3>,
    normals: Option<Vec<Vec3>>,
    tris: Vec<[u32; 3]>,
) -> Result<LoadedMesh> {
    let n = positions.len();
    let mut warnings = Vec::new();
    let (mut nan, mut degenerate) = (0usize, 0usize);
    let mut kept = Vec::with_capacity(tris.len());
    for (i, t) in tris.iter().enumerate() {
        if let Some(&bad) = t.iter().find(|&&k| k as usize >= n) {
            return Err(Error::invalid(format!(
                "{}: triangle {i} uses vertex {bad}, but the mesh has {n} vertices",
                path.display()
            )));
        }
        let p = [
            positions[t[0] as usize],
            positions[t[1] as usize],
            positions[t[2] as usize],
        ];
        if p.iter().any(|v| !v.is_finite()) {
            nan += 1;
            continue;
        }
        let area2 = (p[1] - p[0]).cross(p[2] - p[0]).length();
        if area2.is_nan() || area2 <= 0.0 || !area2.is_finite() {
            degenerate += 1;
            continue;
        }
        kept.push(*t);
    }
    if nan > 0 {
        warnings.push(format!(
            "{}: dropped {nan} triangle(s) with non-finite vertices",
            path.display()
        ));
    }
    if degenerate > 0 {
        warnings.push(format!(
            "{}: dropped {degenerate} degenerate (zero-area) triangle(s)",
            path.display()
        ));
    }
    if kept.is_empty() {
        return Err(Error::invalid(format!(
            "{}: mesh has no valid triangles",
            path.display()
        )));
    }
    let normals = normals
        .filter(|ns| ns.len() == n && ns.iter().all(|v| v.is_finite() && v.length_squared() > 0.0));
    Ok(LoadedMesh {
        mesh: Mesh {
            positions,
            normals,
            uvs: None,
            indices: kept,
            material: 0,
            object: 0,
            emission: None,
        },
        warnings,
    })
}

fn load_obj(path: &Path) -> Result<Raw> {
    let f = std::fs::File::open(path).map_err(|e| Error::io(path, e))?;
    let mut r = std::io::BufReader::new(f);
    let opts = tobj::LoadOptions {
        triangulate: true,
        single_index: true,
        ..Default::default()
    };
    let (models, _materials) =
        tobj::load_obj_buf(&mut r, &opts, |_| Err(tobj::LoadError::OpenFileFailed))
            .map_err(|e| Error::invalid(format!("{}: OBJ: {e}", path.display())))?;
    let (mut positions, mut normals, mut tris) = (Vec::new(), Vec::new(), Vec::new());
    let mut all_normals = true;
    for m in &models {
        let base = positions.len() as u32;
        let mesh = &m.mesh;
        positions.extend(
            mesh.positions
                .chunks_exact(3)
                .map(|c| Vec3::new(c[0], c[1], c[2])),
        );
        if mesh.normals.len() == mesh.positions.len() {
            normals.extend(
                mesh.normals
                    .chunks_exact(3)
                    .map(|c| Vec3::new(c[0], c[1], c[2])),
            );
        } else {
            all_normals = false;
        }
        tris.extend(
            mesh.indices
                .chunks_exact(3)
                .map(|c| [base + c[0], base + c[1], base + c[2]]),
        );
    }
    Ok((positions, all_normals.then_some(normals), tris))
}

fn load_gltf(path: &Path) -> Result<Raw> {
    let g = gltf::Gltf::open(path)
        .map_err(|e| Error::invalid(format!("{}: glTF: {e}", path.display())))?;
    let base = path.parent();
    let buffers = gltf::import_buffers(&g.document, base, g.blob.clone())
        .map_err(|e| Error::invalid(format!("{}: glTF buffers: {e}", path.display())))?;
    let (mut positions, mut normals, mut tris) = (Vec::new(), Vec::new(), Vec::new());
    let mut all_normals = true;
    let scene = g
        .document
        .default_scene()
        .or_else(|| g.document.scenes().next());
    let Some(scene) = scene else {
        return Err(Error::invalid(format!(
            "{}: glTF has no scene",
            path.display()
        )));
    };
    let mut stack: Vec<(gltf::Node, Mat4)> = scene.nodes().map(|n| (n, Mat4::IDENTITY)).collect();
    while let Some((node, parent)) = stack.pop() {
        let xf = parent * Mat4::from_cols_array_2d(&node.transform().matrix());
        for c in node.children() {
            stack.push((c, xf));
        }
        let Some(mesh) = node.mesh() else { continue };
        let nxf = xf.inverse().transpose();
        for prim in mesh.primitives() {
            if prim.mode() != gltf::mesh::Mode::Triangles {
                return Err(Error::NotSupported(format!(
                    "{}: glTF primitive mode {:?} (only triangles)",
                    path.display(),
                    prim.mode()
                )));
            }
            let reader = prim.reader(|b| buffers.get(b.index()).map(|d| &d.0[..]));
            let Some(pos) = reader.read_positions() else {
                continue;
            };
            let b = positions.len() as u32;
            let start = positions.len();
            positions.extend(pos.map(|p| xf.transform_point3(Vec3::from(p))));
            let count = (positions.len() - start) as u32;
            match reader.read_normals() {
                Some(ns) => normals
                    .extend(ns.map(|n| nxf.transform_vector3(Vec3::from(n)).normalize_or_zero())),
                None => all_normals = false,
            }
            match reader.read_indices() {
                Some(ix) => {
                    let ix: Vec<u32> = ix.into_u32().collect();
                    tris.extend(ix.chunks_exact(3).map(|c| [b + c[0], b + c[1], b + c[2]]));
                }
                None => {
                    tris.extend((0..count / 3).map(|i| [b + 3 * i, b + 3 * i + 1, b + 3 * i + 2]))
                }
            }
        }
    }
    Ok((positions, all_normals.then_some(normals), tris))
}

// ---------------------------------------------------------------- PLY
//
// The one PLY reader of camsim (mesh files and pbrt's `plymesh`): ASCII and
// binary (little / big endian); vertex `x y z`, optional `nx ny nz` and
// `u v` (or `s t`, `texture_u texture_v`, `texture_s texture_t`); faces as
// `vertex_indices` (or `vertex_index`) lists, split into a triangle fan.
// Other elements and properties are read past and ignored.

/// A PLY mesh as stored in the file (object space, f64 positions).
#[derive(Clone, Debug, Default, PartialEq)]
pub struct PlyMesh {
    pub positions: Vec<glam::DVec3>,
    /// Present when every vertex has `nx ny nz`.
    pub normals: Option<Vec<glam::DVec3>>,
    /// Present when every vertex has texture coordinates.
    pub uvs: Option<Vec<glam::Vec2>>,
    pub triangles: Vec<[u32; 3]>,
}

/// A PLY problem: the 1-based header line when it is in the header.
#[derive(Clone, Debug, PartialEq)]
pub struct PlyError {
    pub line: Option<usize>,
    pub message: String,
}

impl PlyError {
    fn header(line: usize, message: impl Into<String>) -> Self {
        Self {
            line: Some(line),
            message: message.into(),
        }
    }
    fn data(message: impl Into<String>) -> Self {
        Self {
            line: None,
            message: message.into(),
        }
    }
    /// `path:line: PLY: …` (header) or `path: PLY data: …`.
    pub fn located(&self, path: &Path) -> String {
        match self.line {
            Some(l) => format!("{}:{l}: PLY: {}", path.display(), self.message),
            None => format!("{}: PLY data: {}", path.display(), self.message),
        }
    }
}

/// Read a PLY file; errors name the file (and the header line).
pub fn read_ply(path: &Path) -> Result<PlyMesh> {
    let data = std::fs::read(path).map_err(|e| Error::io(path, e))?;
    parse_ply(&data).map_err(|e| Error::invalid(e.located(path)))
}

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

impl Scalar {
    fn parse(s: &str) -> Option<Scalar> {
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
    fn size(self) -> usize {
        match self {
            Scalar::I8 | Scalar::U8 => 1,
            Scalar::I16 | Scalar::U16 => 2,
            Scalar::I32 | Scalar::U32 | Scalar::F32 => 4,
            Scalar::F64 => 8,
        }
    }
}

#[derive(Clone, Debug)]
enum Prop {
    Scalar(String, Scalar),
    List(String, Scalar, Scalar),
}

#[derive(Clone, Debug)]
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

/// Reads PLY values from the body, as ASCII words or binary scalars.
struct Body<'a> {
    data: &'a [u8],
    pos: usize,
    format: Format,
}

impl Body<'_> {
    fn value(&mut self, t: Scalar) -> std::result::Result<f64, String> {
        if self.format == Format::Ascii {
            let d = self.data;
            while self.pos < d.len() && d[self.pos].is_ascii_whitespace() {
                self.pos += 1;
            }
            let s = self.pos;
            while self.pos < d.len() && !d[self.pos].is_ascii_whitespace() {
                self.pos += 1;
            }
            if s == self.pos {
                return Err("unexpected end of file".into());
            }
            let w = String::from_utf8_lossy(&d[s..self.pos]);
            return w.parse::<f64>().map_err(|_| format!("bad number '{w}'"));
        }
        let n = t.size();
        if self.pos + n > self.data.len() {
            return Err("unexpected end of file".into());
        }
        let mut b = [0u8; 8];
        b[..n].copy_from_slice(&self.data[self.pos..self.pos + n]);
        self.pos += n;
        if self.format == Format::Be {
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

/// Parse the header: (format, elements, byte offset of the body).
fn ply_header(data: &[u8]) -> std::result::Result<(Format, Vec<Element>, usize), PlyError> {
    let mut pos = 0usize;
    let mut read = 0usize;
    let mut next_line = || -> std::result::Result<String, PlyError> {
        if pos >= data.len() {
            return Err(PlyError::header(
                read + 1,
                "header ends before 'end_header'",
            ));
        }
        let end = data[pos..]
            .iter()
            .position(|&c| c == b'\n')
            .map_or(data.len(), |k| pos + k);
        let l = String::from_utf8_lossy(&data[pos..end])
            .trim_end_matches('\r')
            .to_string();
        pos = end + 1;
        read += 1;
        Ok(l)
    };
    if next_line()?.trim() != "ply" {
        return Err(PlyError::header(1, "file does not start with 'ply'"));
    }
    let mut format = None;
    let mut elements: Vec<Element> = Vec::new();
    let mut ln = 1;
    loop {
        let l = next_line()?;
        ln += 1;
        let w: Vec<&str> = l.split_whitespace().collect();
        let err = |m: String| Err(PlyError::header(ln, m));
        match w.first().copied() {
            Some("format") => {
                format = Some(match w.get(1).copied() {
                    Some("ascii") => Format::Ascii,
                    Some("binary_little_endian") => Format::Le,
                    Some("binary_big_endian") => Format::Be,
                    other => return err(format!("unknown format {other:?}")),
                })
            }
            Some("element") => {
                let (Some(name), Some(count)) = (w.get(1), w.get(2).and_then(|c| c.parse().ok()))
                else {
                    return err(format!("bad element line '{l}'"));
                };
                elements.push(Element {
                    name: name.to_string(),
                    count,
                    props: vec![],
                });
            }
            Some("property") => {
                let Some(el) = elements.last_mut() else {
                    return err("property before any element".into());
                };
                let p = if w.get(1) == Some(&"list") {
                    match (
                        w.get(2).and_then(|s| Scalar::parse(s)),
                        w.get(3).and_then(|s| Scalar::parse(s)),
                        w.get(4),
                    ) {
                        (Some(c), Some(i), Some(n)) => Prop::List(n.to_string(), c, i),
                        _ => return err(format!("bad list property '{l}'")),
                    }
                } else {
                    match (w.get(1).and_then(|s| Scalar::parse(s)), w.get(2)) {
                        (Some(t), Some(n)) => Prop::Scalar(n.to_string(), t),
                        _ => return err(format!("bad property '{l}'")),
                    }
                };
                el.props.push(p);
            }
            Some("end_header") => break,
            Some("comment") | Some("obj_info") | None => {}
            Some(other) => return err(format!("unknown header keyword '{other}'")),
        }
    }
    let Some(format) = format else {
        return Err(PlyError::header(ln, "missing 'format' line"));
    };
    Ok((format, elements, pos.min(data.len())))
}

/// Parse PLY bytes (see the section comment for what is read).
pub fn parse_ply(data: &[u8]) -> std::result::Result<PlyMesh, PlyError> {
    let (format, elements, body) = ply_header(data)?;
    let mut rd = Body {
        data,
        pos: body,
        format,
    };
    let bad = |m: String| PlyError::data(m);
    let mut out = PlyMesh::default();
    let (mut normals, mut uvs) = (Vec::new(), Vec::new());
    for el in &elements {
        let slot_of = |n: &str| -> Option<usize> {
            Some(match n {
                "x" => 0,
                "y" => 1,
                "z" => 2,
                "nx" => 3,
                "ny" => 4,
                "nz" => 5,
                "u" | "s" | "texture_u" | "texture_s" => 6,
                "v" | "t" | "texture_v" | "texture_t" => 7,
                _ => return None,
            })
        };
        let is_vertex = el.name == "vertex";
        if is_vertex {
            let has = |n: &str| {
                el.props
                    .iter()
                    .any(|p| matches!(p, Prop::Scalar(x, _) if x == n))
            };
            if !(has("x") && has("y") && has("z")) {
                return Err(bad("vertex element lacks x, y, z".into()));
            }
            out.positions.reserve(el.count.min(1 << 20));
        }
        let mut face: Vec<u32> = Vec::new();
        for _ in 0..el.count {
            let mut v = [f64::NAN; 8]; // x y z nx ny nz u v
            face.clear();
            for p in &el.props {
                match p {
                    Prop::Scalar(name, t) => {
                        let x = rd.value(*t).map_err(bad)?;
                        if is_vertex && let Some(k) = slot_of(name) {
                            v[k] = x;
                        }
                    }
                    Prop::List(name, ct, it) => {
                        let c = rd.value(*ct).map_err(bad)?;
                        if !(0.0..=1e6).contains(&c) || c.fract() != 0.0 {
                            return Err(bad(format!("bad list length {c}")));
                        }
                        let is_face = el.name == "face"
                            && (name == "vertex_indices" || name == "vertex_index");
                        for _ in 0..c as usize {
                            let i = rd.value(*it).map_err(bad)?;
                            if is_face {
                                if !(i >= 0.0 && i.fract() == 0.0 && i < u32::MAX as f64) {
                                    return Err(bad(format!(
                                        "negative or non-integer vertex index {i}"
                                    )));
                                }
                                face.push(i as u32);
                            }
                        }
                    }
                }
            }
            if is_vertex {
                out.positions.push(glam::DVec3::new(v[0], v[1], v[2]));
                if v[3..6].iter().all(|x| !x.is_nan()) {
                    normals.push(glam::DVec3::new(v[3], v[4], v[5]));
                }
                if v[6..8].iter().all(|x| !x.is_nan()) {
                    uvs.push(glam::Vec2::new(v[6] as f32, v[7] as f32));
                }
            } else if face.len() >= 3 {
                for k in 1..face.len() - 1 {
                    out.triangles.push([face[0], face[k], face[k + 1]]);
                }
            }
        }
    }
    let nv = out.positions.len();
    if let Some(i) = out.triangles.iter().flatten().find(|&&i| i as usize >= nv) {
        return Err(bad(format!("face index {i} out of range ({nv} vertices)")));
    }
    out.normals = (nv > 0 && normals.len() == nv).then_some(normals);
    out.uvs = (nv > 0 && uvs.len() == nv).then_some(uvs);
    Ok(out)
}

fn load_ply(path: &Path) -> Result<Raw> {
    let m = read_ply(path)?;
    let v = |p: &glam::DVec3| p.as_vec3();
    Ok((
        m.positions.iter().map(v).collect(),
        m.normals.map(|n| n.iter().map(v).collect()),
        m.triangles,
    ))
}

#[cfg(test)]
mod tests {
    use super::*;
    #[test]
    fn ply_header_errors_name_the_file() {
        let dir = tempfile::tempdir().unwrap();
        let p = dir.path().join("bad.ply");
        std::fs::write(
            &p,
            "ply\nformat ascii 1.0\nelement vertex 1\nproperty float x\nwhat\n",
        )
        .unwrap();
        let e = load_mesh(&p).unwrap_err().to_string();
        assert!(e.contains("bad.ply:5"), "{e}");
    }

    #[test]
    fn ascii_and_binary_quads_with_uvs() {
        let a = b"ply\nformat ascii 1.0\nelement vertex 4\nproperty float x\nproperty float y\nproperty float z\nproperty float u\nproperty float v\nelement face 1\nproperty list uchar int vertex_indices\nend_header\n0 0 0 0 0\n1 0 0 1 0\n1 1 0 1 1\n0 1 0 0 1\n4 0 1 2 3\n";
        let m = parse_ply(a).unwrap();
        assert_eq!(m.positions.len(), 4);
        assert_eq!(m.triangles, vec![[0, 1, 2], [0, 2, 3]]);
        assert_eq!(m.uvs.as_ref().unwrap()[2], glam::Vec2::new(1.0, 1.0));
        assert!(m.normals.is_none());
        for be in [false, true] {
            let mut b = format!(
                "ply\nformat binary_{}_endian 1.0\nelement vertex 3\nproperty double x\nproperty double y\nproperty double z\nelement face 1\nproperty list uchar uint vertex_indices\nend_header\n",
                if be { "big" } else { "little" }
            )
            .into_bytes();
            for v in [0.0f64, 0.0, 0.0, 2.0, 0.0, 0.0, 0.0, 3.0, 0.5] {
                b.extend_from_slice(&if be { v.to_be_bytes() } else { v.to_le_bytes() });
            }
            b.push(3);
            for i in [0u32, 1, 2] {
                b.extend_from_slice(&if be { i.to_be_bytes() } else { i.to_le_bytes() });
            }
            let m = parse_ply(&b).unwrap();
            assert_eq!(m.positions[2], glam::DVec3::new(0.0, 3.0, 0.5));
            assert_eq!(m.triangles, vec![[0, 1, 2]]);
            let e = parse_ply(&b[..b.len() - 2]).unwrap_err();
            assert_eq!(e.line, None);
            assert!(e.message.contains("end of file"), "{e:?}");
        }
    }

    #[test]
    fn out_of_range_and_negative_indices_are_errors() {
        let h = "ply\nformat ascii 1.0\nelement vertex 3\nproperty float x\nproperty float y\nproperty float z\nelement face 1\nproperty list uchar int vertex_indices\nend_header\n0 0 0\n1 0 0\n0 1 0\n";
        let e = parse_ply(format!("{h}3 0 1 7\n").as_bytes()).unwrap_err();
        assert!(e.message.contains("face index 7 out of range"), "{e:?}");
        let e = parse_ply(format!("{h}3 0 -1 2\n").as_bytes()).unwrap_err();
        assert!(e.message.contains("negative"), "{e:?}");
        let e = parse_ply(b"ply\nformat ascii 1.0\nelement vertex 1\n").unwrap_err();
        assert_eq!(e.line, Some(4)); // the missing line
        assert!(e.message.contains("end_header"), "{e:?}");
    }
}
