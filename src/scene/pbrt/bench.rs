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
    /// Wall-clock parse time.
    pub parse_s: f64,
    /// CPU time of the process during the parse (user + system), when available:
    /// on a shared machine this is the fairer denominator.
    pub parse_cpu_s: Option<f64>,
    /// MB (10^6 bytes) per wall-clock second.
    pub throughput_mb_per_s: f64,
    /// MB per CPU second, when available.
    pub throughput_mb_per_cpu_s: Option<f64>,
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

/// CPU time (user + system) of this process in seconds, from /proc/self/stat
/// (clock ticks assumed 100 Hz, the Linux default).
pub fn process_cpu_s() -> Option<f64> {
    let s = std::fs::read_to_string("/proc/self/stat").ok()?;
    // fields after the parenthesised command name; utime and stime are fields 14 and 15
    let rest = &s[s.rfind(')')? + 2..];
    let f: Vec<&str> = rest.split_whitespace().collect();
    let ut: f64 = f.get(11)?.parse().ok()?;
    let st: f64 = f.get(12)?.parse().ok()?;
    Some((ut + st) / 100.0)
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
    let c0 = process_cpu_s();
    let t = Instant::now();
    let scene = super::load(&path, &super::LoadOptions::default())?;
    let dt = t.elapsed().as_secs_f64();
    let cpu = match (c0, process_cpu_s()) {
        (Some(a), Some(b)) if b > a => Some(b - a),
        _ => None,
    };
    Ok(ParseBenchReport {
        file_bytes: bytes,
        triangles: scene.triangle_count(),
        parse_s: dt,
        parse_cpu_s: cpu,
        throughput_mb_per_s: bytes as f64 / 1e6 / dt,
        throughput_mb_per_cpu_s: cpu.map(|c| bytes as f64 / 1e6 / c),
        peak_rss_mib: peak_rss_mib(),
        threads: 1,
    })
}
