//! Parser throughput benchmark: a generated `trianglemesh` file of a given size,
//! parsed on one core, reported in MB/s with the process's peak resident memory
//! (VmHWM from /proc/self/status, Linux only).

use crate::diag::{Error, Result};
use serde::Serialize;
use std::io::Write;
use std::time::Instant;

#[derive(Clone, Debug, Serialize)]
pub struct ParseBenchReport {
    pub file_bytes: u64,
    pub triangles: usize,
    pub parse_s: f64,
    pub throughput_mb_per_s: f64,
    /// Peak resident set size of the process (VmHWM), in MiB, if available.
    pub peak_rss_mib: Option<f64>,
    pub threads: usize,
}

/// Peak resident memory of this process in MiB (Linux `VmHWM`).
pub fn peak_rss_mib() -> Option<f64> {
    let s = std::fs::read_to_string("/proc/self/status").ok()?;
    let line = s.lines().find(|l| l.starts_with("VmHWM:"))?;
    let kb: f64 = line.split_whitespace().nth(1)?.parse().ok()?;
    Some(kb / 1024.0)
}

/// Write a pbrt file holding one grid `trianglemesh` of about `target_mb` megabytes.
pub fn write_mesh_file(path: &std::path::Path, target_mb: f64) -> Result<u64> {
    // ~ 3 numbers of ~9 chars per vertex + 6 indices of ~7 chars per quad ≈ 70 bytes per vertex.
    let verts = ((target_mb * 1e6) / 70.0).max(4.0);
    let n = verts.sqrt().ceil() as usize;
    let f = std::fs::File::create(path).map_err(|e| Error::io(path, e))?;
    let mut w = std::io::BufWriter::new(f);
    let io = |e| Error::io(path, e);
    writeln!(
        w,
        "LookAt 0 0 -3  0 0 0  0 1 0\nCamera \"perspective\" \"float fov\" [45]\nWorldBegin"
    )
    .map_err(io)?;
    write!(w, "Shape \"trianglemesh\" \"point3 P\" [").map_err(io)?;
    for j in 0..n {
        for i in 0..n {
            let (x, y) = (i as f64 / n as f64 - 0.5, j as f64 / n as f64 - 0.5);
            let z = 0.01 * ((i * 7 + j * 13) % 100) as f64;
            write!(w, " {x:.6} {y:.6} {z:.4}").map_err(io)?;
        }
        writeln!(w).map_err(io)?;
    }
    write!(w, "]\n\"integer indices\" [").map_err(io)?;
    for j in 0..n - 1 {
        for i in 0..n - 1 {
            let a = j * n + i;
            write!(
                w,
                " {} {} {} {} {} {}",
                a,
                a + 1,
                a + n + 1,
                a,
                a + n + 1,
                a + n
            )
            .map_err(io)?;
        }
        writeln!(w).map_err(io)?;
    }
    writeln!(w, "]").map_err(io)?;
    w.flush().map_err(io)?;
    drop(w);
    Ok(std::fs::metadata(path).map_err(io)?.len())
}

/// Generate a ~`target_mb` MB file in a temporary directory, parse it on the
/// calling thread and report throughput and peak memory.
pub fn run_parse_benchmark(target_mb: f64) -> Result<ParseBenchReport> {
    let dir = tempfile::tempdir().map_err(|e| Error::invalid(format!("temp dir: {e}")))?;
    let path = dir.path().join("bench-mesh.pbrt");
    let bytes = write_mesh_file(&path, target_mb)?;
    let t = Instant::now();
    let scene = super::load(&path, &super::LoadOptions::default())?;
    let dt = t.elapsed().as_secs_f64();
    Ok(ParseBenchReport {
        file_bytes: bytes,
        triangles: scene.triangle_count(),
        parse_s: dt,
        throughput_mb_per_s: bytes as f64 / 1e6 / dt,
        peak_rss_mib: peak_rss_mib(),
        threads: 1,
    })
}
