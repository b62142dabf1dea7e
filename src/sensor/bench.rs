//! `camsim bench sensor`: one 4032×3024 IMX363 frame from a cached optical image
//! (31 bands, 400–700 nm, built in memory once; the timing excludes building it).
//! Target (issue 17): ≤ 0.3 s on 2 threads. The optical image is 1.5 GB, so the
//! floor is memory bandwidth: each run also times one stream-read of the same
//! optical image over the same threads ([`stream_read_sum`]), and the report gives
//! both times and their ratio, with the CPU model, its vector width, the load
//! average around the runs and the peak resident memory (VmHWM).

use super::config::{Exposure, SensorConfig};
use super::pipeline::simulate;
use crate::diag::Result;
use crate::optical_image::{OpticalImage, Rect};
use crate::spectrum::WavelengthGrid;

/// Peak resident set size of this process in bytes (Linux `VmHWM`), if available.
pub fn peak_memory_bytes() -> Option<u64> {
    let s = std::fs::read_to_string("/proc/self/status").ok()?;
    let line = s.lines().find(|l| l.starts_with("VmHWM:"))?;
    let kb: u64 = line.split_whitespace().nth(1)?.parse().ok()?;
    Some(kb * 1024)
}

/// CPU time (user + system) of this process so far, seconds (Linux `/proc/self/stat`,
/// clock ticks assumed 100 Hz, the Linux default).
pub fn process_cpu_s() -> Option<f64> {
    let s = std::fs::read_to_string("/proc/self/stat").ok()?;
    let rest = &s[s.rfind(')')? + 2..];
    let f: Vec<&str> = rest.split_whitespace().collect();
    // fields after the command: state is index 0, utime index 11, stime index 12
    let ut: f64 = f.get(11)?.parse().ok()?;
    let st: f64 = f.get(12)?.parse().ok()?;
    Some((ut + st) / 100.0)
}

/// The 1-, 5- and 15-minute load averages (Linux `/proc/loadavg`), if available.
pub fn load_average() -> Option<[f64; 3]> {
    let s = std::fs::read_to_string("/proc/loadavg").ok()?;
    let mut it = s.split_whitespace().map(|x| x.parse::<f64>().ok());
    Some([it.next()??, it.next()??, it.next()??])
}

/// Read every float of `data` once on the current rayon pool, in chunks of `chunk`
/// floats (the sensor's rows), and return their sum: the memory-bandwidth floor of
/// any pass that reads the same data with the same threads. Sixteen independent
/// accumulators per chunk keep the adds off the critical path, so the time is the
/// time to bring the bytes in.
pub fn stream_read_sum(data: &[f32], chunk: usize) -> f32 {
    use rayon::prelude::*;
    data.par_chunks(chunk.max(1))
        .map(|c| {
            let mut acc = [0f32; 16];
            let it = c.chunks_exact(16);
            let rest: f32 = it.remainder().iter().sum();
            for v in it {
                for i in 0..16 {
                    acc[i] += v[i];
                }
            }
            acc.iter().sum::<f32>() + rest
        })
        .sum()
}

/// Benchmark result.
#[derive(Clone, Debug)]
pub struct SensorBench {
    pub width: u32,
    pub height: u32,
    pub bands: usize,
    pub threads: usize,
    /// The machine: CPU model and vector width.
    pub cpu: crate::machine::Cpu,
    /// The instruction set the sensor's row kernels ran with (`CAMSIM_SENSOR_ISA`
    /// lowers it).
    pub kernel_isa: &'static str,
    /// Wall time of `simulate` (best of `runs`), seconds.
    pub simulate_s: f64,
    /// CPU time (all threads) of the same run, seconds: on a busy machine wall time
    /// overstates the cost, CPU time / threads estimates the unloaded wall time.
    pub simulate_cpu_s: Option<f64>,
    /// Bytes of spectral irradiance in the optical image (what `simulate` must read).
    pub optical_image_bytes: u64,
    /// Wall time to stream-read the optical image once ([`stream_read_sum`], same
    /// threads, best of `runs`, interleaved with the simulate runs), seconds.
    pub stream_read_s: f64,
    pub runs: usize,
    /// Load averages (1, 5, 15 min) before the first and after the last run.
    pub load_before: Option<[f64; 3]>,
    pub load_after: Option<[f64; 3]>,
    pub peak_memory_bytes: Option<u64>,
}

impl std::fmt::Display for SensorBench {
    fn fmt(&self, f: &mut std::fmt::Formatter<'_>) -> std::fmt::Result {
        writeln!(f, "benchmark,quantity,unit,value")?;
        writeln!(
            f,
            "sensor,cpu_model,text,{}",
            self.cpu.model.replace(',', ";")
        )?;
        writeln!(f, "sensor,vector_width,text,{}", self.cpu.vector)?;
        writeln!(f, "sensor,kernel_isa,text,{}", self.kernel_isa)?;
        for (when, l) in [("before", self.load_before), ("after", self.load_after)] {
            match l {
                Some(l) => writeln!(f, "sensor,load_average_1min_{when},1,{:.2}", l[0])?,
                None => writeln!(f, "sensor,load_average_1min_{when},1,unavailable")?,
            }
        }
        writeln!(f, "sensor,frame_width,px,{}", self.width)?;
        writeln!(f, "sensor,frame_height,px,{}", self.height)?;
        writeln!(f, "sensor,bands,1,{}", self.bands)?;
        writeln!(f, "sensor,threads,1,{}", self.threads)?;
        writeln!(
            f,
            "sensor,optical_image_size,GB,{:.3}",
            self.optical_image_bytes as f64 / 1e9
        )?;
        writeln!(
            f,
            "sensor,simulate_time_best_of_{},s,{:.4}",
            self.runs, self.simulate_s
        )?;
        if let Some(c) = self.simulate_cpu_s {
            writeln!(f, "sensor,simulate_cpu_time,s,{c:.3}")?;
            writeln!(
                f,
                "sensor,unloaded_wall_estimate_cpu_over_threads,s,{:.3}",
                c / self.threads.max(1) as f64
            )?;
        }
        writeln!(
            f,
            "sensor,stream_read_time_best_of_{},s,{:.4}",
            self.runs, self.stream_read_s
        )?;
        writeln!(
            f,
            "sensor,stream_read_bandwidth,GB/s,{:.2}",
            self.optical_image_bytes as f64 / self.stream_read_s / 1e9
        )?;
        writeln!(
            f,
            "sensor,simulate_over_stream_read,1,{:.2}",
            self.simulate_s / self.stream_read_s
        )?;
        match self.peak_memory_bytes {
            Some(b) => writeln!(
                f,
                "sensor,peak_memory,MiB,{:.1}",
                b as f64 / (1024.0 * 1024.0)
            ),
            None => writeln!(f, "sensor,peak_memory,MiB,unavailable"),
        }
    }
}

/// Run the benchmark: IMX363 (`sensors/imx363.kdl`, embedded) on a smooth synthetic
/// optical image of 4032×3024 × 31 bands, all noise sources on, fixed exposure;
/// 5 rounds of (stream-read the optical image, simulate one frame), best of each.
pub fn bench_sensor() -> Result<SensorBench> {
    bench_sensor_runs(5)
}

/// [`bench_sensor`] with `runs` rounds.
pub fn bench_sensor_runs(runs: usize) -> Result<SensorBench> {
    let runs = runs.max(1);
    let cfg = SensorConfig::parse(
        include_str!(concat!(env!("CARGO_MANIFEST_DIR"), "/sensors/imx363.kdl")),
        std::path::Path::new("sensors/imx363.kdl"),
    )?;
    let mut cfg = cfg;
    cfg.exposure = Exposure::Seconds(0.01);
    let (w, h) = (4032u32, 3024u32);
    let grid = WavelengthGrid::default();
    let mut oi = OpticalImage::new(w, h, Rect::new(0, 0, w, h), 1.4e-6, grid);
    let nb = oi.bands();
    {
        use rayon::prelude::*;
        oi.irradiance
            .par_chunks_mut(w as usize * nb)
            .enumerate()
            .for_each(|(y, row)| {
                for x in 0..w as usize {
                    for b in 0..nb {
                        // a smooth gradient up to ~0.05 W/(m²·nm)
                        row[x * nb + b] = 0.05
                            * ((x + y) as f32 / (w + h) as f32)
                            * (0.5 + 0.5 * b as f32 / nb as f32);
                    }
                }
            });
    }
    let load_before = load_average();
    let mut best = f64::INFINITY;
    let mut best_cpu = None;
    let mut best_read = f64::INFINITY;
    for r in 0..runs {
        let t0 = std::time::Instant::now();
        std::hint::black_box(stream_read_sum(
            std::hint::black_box(&oi.irradiance),
            w as usize * nb,
        ));
        best_read = best_read.min(t0.elapsed().as_secs_f64());
        let c0 = process_cpu_s();
        let t0 = std::time::Instant::now();
        let im = simulate(&cfg, &oi, r as u64)?;
        let dt = t0.elapsed().as_secs_f64();
        let dc = process_cpu_s().zip(c0).map(|(a, b)| a - b);
        if dt < best {
            best = dt;
            best_cpu = dc;
        }
        // as a sequence of frames does: the next frame writes to these pages
        im.recycle();
    }
    Ok(SensorBench {
        width: w,
        height: h,
        bands: nb,
        threads: rayon::current_num_threads(),
        cpu: crate::machine::cpu(),
        kernel_isa: super::readout::Isa::detect().name(),
        simulate_s: best,
        simulate_cpu_s: best_cpu,
        optical_image_bytes: (oi.irradiance.len() * std::mem::size_of::<f32>()) as u64,
        stream_read_s: best_read,
        runs,
        load_before,
        load_after: load_average(),
        peak_memory_bytes: peak_memory_bytes(),
    })
}

#[cfg(test)]
mod tests {
    use super::*;

    /// The stream-read sum is the sum of every float, for chunk sizes that do and
    /// do not divide the data and on 1 and 2 threads: integers 1..=n sum exactly in
    /// f32 (every partial sum stays below 2^24 for n = 4000).
    #[test]
    fn stream_read_sum_reads_every_float_once() {
        let n = 4000usize;
        let data: Vec<f32> = (1..=n).map(|i| i as f32).collect();
        let exact = (n * (n + 1) / 2) as f32;
        for threads in [1, 2] {
            let pool = rayon::ThreadPoolBuilder::new()
                .num_threads(threads)
                .build()
                .unwrap();
            for chunk in [1, 7, 16, 33, 1000, 5000] {
                assert_eq!(pool.install(|| stream_read_sum(&data, chunk)), exact);
            }
        }
    }
}
