//! Mesh loaders: OBJ (shipped bunny), glTF and PLY (ASCII / binary LE / BE)
//! written by the test, and the bad-input paths.

use camsim::scene::mesh_io::load_mesh;
use std::path::Path;

#[test]
fn bunny_obj_loads_with_all_triangles() {
    let m = load_mesh(Path::new("scenes/bunny.obj")).unwrap();
    assert_eq!(m.mesh.positions.len(), 1839);
    assert_eq!(m.mesh.indices.len(), 3674);
    assert!(m.warnings.is_empty(), "{:?}", m.warnings);
}

/// A unit square (2 triangles) plus one degenerate and one NaN triangle.
fn ply_bytes(format: &str) -> Vec<u8> {
    let verts: [[f32; 3]; 6] = [
        [0.0, 0.0, 0.0],
        [1.0, 0.0, 0.0],
        [1.0, 1.0, 0.0],
        [0.0, 1.0, 0.0],
        [2.0, 2.0, 2.0],
        [f32::NAN, 0.0, 0.0],
    ];
    // quad as one polygon (fan-triangulated), degenerate (0,0,1 repeated), NaN.
    let faces: [&[i32]; 3] = [&[0, 1, 2, 3], &[0, 0, 1], &[5, 1, 2]];
    let mut out = format!(
        "ply\nformat {format} 1.0\ncomment test\nelement vertex {}\nproperty float x\nproperty float y\nproperty float z\nelement face {}\nproperty list uchar int vertex_indices\nend_header\n",
        verts.len(),
        faces.len()
    )
    .into_bytes();
    match format {
        "ascii" => {
            for v in verts {
                out.extend(format!("{} {} {}\n", v[0], v[1], v[2]).bytes());
            }
            for f in faces {
                let s: Vec<String> = f.iter().map(|i| i.to_string()).collect();
                out.extend(format!("{} {}\n", f.len(), s.join(" ")).bytes());
            }
        }
        _ => {
            let le = format == "binary_little_endian";
            for v in verts {
                for c in v {
                    out.extend(if le { c.to_le_bytes() } else { c.to_be_bytes() });
                }
            }
            for f in faces {
                out.push(f.len() as u8);
                for &i in f {
                    out.extend(if le { i.to_le_bytes() } else { i.to_be_bytes() });
                }
            }
        }
    }
    out
}

#[test]
fn ply_ascii_and_binary_agree_and_drop_bad_triangles() {
    let dir = tempfile::tempdir().unwrap();
    let mut meshes = vec![];
    for fmt in ["ascii", "binary_little_endian", "binary_big_endian"] {
        let p = dir.path().join(format!("{fmt}.ply"));
        std::fs::write(&p, ply_bytes(fmt)).unwrap();
        let m = load_mesh(&p).unwrap();
        assert_eq!(m.mesh.indices, vec![[0, 1, 2], [0, 2, 3]], "{fmt}");
        assert_eq!(m.warnings.len(), 2, "{fmt}: {:?}", m.warnings);
        assert!(
            m.warnings.iter().all(|w| w.contains(&format!("{fmt}.ply"))),
            "{:?}",
            m.warnings
        );
        meshes.push(m.mesh);
    }
    assert_eq!(meshes[0].positions[..5], meshes[1].positions[..5]);
    assert_eq!(meshes[1].positions[..5], meshes[2].positions[..5]);
}

#[test]
fn empty_or_broken_meshes_are_errors_naming_the_file() {
    let dir = tempfile::tempdir().unwrap();
    let p = dir.path().join("empty.ply");
    std::fs::write(&p, "ply\nformat ascii 1.0\nelement vertex 0\nproperty float x\nproperty float y\nproperty float z\nend_header\n").unwrap();
    let e = load_mesh(&p).unwrap_err().to_string();
    assert!(
        e.contains("empty.ply") && e.contains("no valid triangles"),
        "{e}"
    );
    let p = dir.path().join("oob.obj");
    std::fs::write(&p, "v 0 0 0\nv 1 0 0\nv 0 1 0\nf 1 2 3\nf 1 2 9\n").unwrap();
    assert!(load_mesh(&p).is_err());
    let p = dir.path().join("flat.obj");
    std::fs::write(&p, "v 0 0 0\nv 1 0 0\nv 2 0 0\nf 1 2 3\n").unwrap();
    let e = load_mesh(&p).unwrap_err().to_string();
    assert!(e.contains("flat.obj"), "{e}");
    let e = load_mesh(&dir.path().join("missing.obj"))
        .unwrap_err()
        .to_string();
    assert!(e.contains("missing.obj"), "{e}");
    let e = load_mesh(&dir.path().join("x.stl"))
        .unwrap_err()
        .to_string();
    assert!(e.contains("x.stl"), "{e}");
}

#[test]
fn gltf_with_node_transform() {
    let dir = tempfile::tempdir().unwrap();
    // One triangle, positions f32×9, indices u16×3 (+2 padding bytes).
    let pos: [f32; 9] = [0.0, 0.0, 0.0, 1.0, 0.0, 0.0, 0.0, 1.0, 0.0];
    let mut bin: Vec<u8> = pos.iter().flat_map(|f| f.to_le_bytes()).collect();
    for i in [0u16, 1, 2] {
        bin.extend(i.to_le_bytes());
    }
    bin.extend([0, 0]);
    std::fs::write(dir.path().join("tri.bin"), &bin).unwrap();
    let json = r#"{
      "asset": {"version": "2.0"},
      "scene": 0,
      "scenes": [{"nodes": [0]}],
      "nodes": [{"mesh": 0, "translation": [0, 0, 5], "scale": [2, 2, 2]}],
      "meshes": [{"primitives": [{"attributes": {"POSITION": 0}, "indices": 1}]}],
      "buffers": [{"uri": "tri.bin", "byteLength": 44}],
      "bufferViews": [
        {"buffer": 0, "byteOffset": 0, "byteLength": 36},
        {"buffer": 0, "byteOffset": 36, "byteLength": 6}
      ],
      "accessors": [
        {"bufferView": 0, "componentType": 5126, "count": 3, "type": "VEC3", "min": [0,0,0], "max": [1,1,0]},
        {"bufferView": 1, "componentType": 5123, "count": 3, "type": "SCALAR"}
      ]
    }"#;
    let p = dir.path().join("tri.gltf");
    std::fs::write(&p, json).unwrap();
    let m = load_mesh(&p).unwrap();
    assert_eq!(m.mesh.indices, vec![[0, 1, 2]]);
    assert_eq!(m.mesh.positions[1], glam::Vec3::new(2.0, 0.0, 5.0));
    assert_eq!(m.mesh.positions[2], glam::Vec3::new(0.0, 2.0, 5.0));
}
