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
use std::io::BufRead;
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

/// Reads PLY values either from ASCII tokens or binary bytes.
struct PlyReader<R: BufRead> {
    r: R,
    format: Format,
    tokens: std::vec::IntoIter<String>,
}

impl<R: BufRead> PlyReader<R> {
    fn value(&mut self, t: Scalar) -> std::result::Result<f64, String> {
        match self.format {
            Format::Ascii => loop {
                if let Some(tok) = self.tokens.next() {
                    return tok
                        .parse::<f64>()
                        .map_err(|_| format!("bad number '{tok}'"));
                }
                let mut line = String::new();
                if self.r.read_line(&mut line).map_err(|e| e.to_string())? == 0 {
                    return Err("unexpected end of file".into());
                }
                self.tokens = line
                    .split_whitespace()
                    .map(str::to_string)
                    .collect::<Vec<_>>()
                    .into_iter();
            },
            _ => {
                let mut b = [0u8; 8];
                let n = t.size();
                self.r
                    .read_exact(&mut b[..n])
                    .map_err(|_| "unexpected end of file".to_string())?;
                let le = self.format == Format::Le;
                macro_rules! rd {
                    ($ty:ty, $n:expr) => {{
                        let a: [u8; $n] = b[..$n].try_into().unwrap();
                        (if le {
                            <$ty>::from_le_bytes(a)
                        } else {
                            <$ty>::from_be_bytes(a)
                        }) as f64
                    }};
                }
                Ok(match t {
                    Scalar::I8 => b[0] as i8 as f64,
                    Scalar::U8 => b[0] as f64,
                    Scalar::I16 => rd!(i16, 2),
                    Scalar::U16 => rd!(u16, 2),
                    Scalar::I32 => rd!(i32, 4),
                    Scalar::U32 => rd!(u32, 4),
                    Scalar::F32 => rd!(f32, 4),
                    Scalar::F64 => rd!(f64, 8),
                })
            }
        }
    }
}

fn load_ply(path: &Path) -> Result<Raw> {
    let f = std::fs::File::open(path).map_err(|e| Error::io(path, e))?;
    let mut r = std::io::BufReader::new(f);
    let err =
        |line: usize, m: String| Error::invalid(format!("{}:{line}: PLY: {m}", path.display()));
    let mut line_no = 0usize;
    let mut next_line = |r: &mut std::io::BufReader<std::fs::File>| -> Result<String> {
        let mut s = String::new();
        let n = r.read_line(&mut s).map_err(|e| Error::io(path, e))?;
        line_no += 1;
        if n == 0 {
            return Err(Error::invalid(format!(
                "{}: PLY header ends before 'end_header'",
                path.display()
            )));
        }
        Ok(s.trim_end_matches(['\n', '\r']).to_string())
    };
    if next_line(&mut r)?.trim() != "ply" {
        return Err(err(1, "file does not start with 'ply'".into()));
    }
    let mut format = None;
    let mut elements: Vec<Element> = Vec::new();
    let mut ln = 1;
    loop {
        let l = next_line(&mut r)?;
        ln += 1;
        let w: Vec<&str> = l.split_whitespace().collect();
        match w.first().copied() {
            Some("format") => {
                format = Some(match w.get(1).copied() {
                    Some("ascii") => Format::Ascii,
                    Some("binary_little_endian") => Format::Le,
                    Some("binary_big_endian") => Format::Be,
                    other => return Err(err(ln, format!("unknown format {other:?}"))),
                })
            }
            Some("element") => {
                let (Some(name), Some(count)) = (w.get(1), w.get(2).and_then(|c| c.parse().ok()))
                else {
                    return Err(err(ln, format!("bad element line '{l}'")));
                };
                elements.push(Element {
                    name: name.to_string(),
                    count,
                    props: vec![],
                });
            }
            Some("property") => {
                let Some(el) = elements.last_mut() else {
                    return Err(err(ln, "property before any element".into()));
                };
                let p = if w.get(1) == Some(&"list") {
                    match (
                        w.get(2).and_then(|s| Scalar::parse(s)),
                        w.get(3).and_then(|s| Scalar::parse(s)),
                        w.get(4),
                    ) {
                        (Some(c), Some(i), Some(n)) => Prop::List(n.to_string(), c, i),
                        _ => return Err(err(ln, format!("bad list property '{l}'"))),
                    }
                } else {
                    match (w.get(1).and_then(|s| Scalar::parse(s)), w.get(2)) {
                        (Some(t), Some(n)) => Prop::Scalar(n.to_string(), t),
                        _ => return Err(err(ln, format!("bad property '{l}'"))),
                    }
                };
                el.props.push(p);
            }
            Some("end_header") => break,
            Some("comment") | Some("obj_info") | None => {}
            Some(other) => return Err(err(ln, format!("unknown header keyword '{other}'"))),
        }
    }
    let Some(format) = format else {
        return Err(err(ln, "missing 'format' line".into()));
    };
    let mut rd = PlyReader {
        r,
        format,
        tokens: Vec::new().into_iter(),
    };
    let (mut positions, mut normals, mut tris) = (Vec::new(), Vec::new(), Vec::new());
    let mut has_normals = false;
    let bad = |m: String| Error::invalid(format!("{}: PLY data: {m}", path.display()));
    for el in &elements {
        let idx = |n: &str| {
            el.props
                .iter()
                .position(|p| matches!(p, Prop::Scalar(x, _) if x == n))
        };
        let (ix, iy, iz) = (idx("x"), idx("y"), idx("z"));
        let (inx, iny, inz) = (idx("nx"), idx("ny"), idx("nz"));
        if el.name == "vertex" {
            if ix.is_none() || iy.is_none() || iz.is_none() {
                return Err(bad("vertex element lacks x, y, z".into()));
            }
            has_normals = inx.is_some() && iny.is_some() && inz.is_some();
        }
        let mut vals = vec![0.0f64; el.props.len()];
        for _ in 0..el.count {
            let mut face: Vec<u32> = Vec::new();
            for (k, p) in el.props.iter().enumerate() {
                match p {
                    Prop::Scalar(_, t) => vals[k] = rd.value(*t).map_err(&bad)?,
                    Prop::List(name, ct, it) => {
                        let c = rd.value(*ct).map_err(&bad)?;
                        if !(0.0..=1e6).contains(&c) {
                            return Err(bad(format!("list length {c}")));
                        }
                        let is_face = el.name == "face"
                            && (name == "vertex_indices" || name == "vertex_index");
                        for _ in 0..c as usize {
                            let v = rd.value(*it).map_err(&bad)?;
                            if is_face {
                                if v < 0.0 {
                                    return Err(bad(format!("negative vertex index {v}")));
                                }
                                face.push(v as u32);
                            }
                        }
                    }
                }
            }
            if el.name == "vertex" {
                let g = |i: Option<usize>| vals[i.unwrap()] as f32;
                positions.push(Vec3::new(g(ix), g(iy), g(iz)));
                if has_normals {
                    normals.push(Vec3::new(g(inx), g(iny), g(inz)));
                }
            } else if el.name == "face" && face.len() >= 3 {
                for k in 1..face.len() - 1 {
                    tris.push([face[0], face[k], face[k + 1]]);
                }
            }
        }
    }
    Ok((positions, has_normals.then_some(normals), tris))
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
}
