//! Fuzzing the experiment parser in-process: ≥ 100 000 random and mutated
//! inputs (mutations of the valid examples), each parsed and, when valid,
//! planned. Any panic fails the test (with the input); so does any single
//! input taking more than 1 s of its thread's CPU time, or 30 s of wall time
//! (a hang). CPU time, not wall time, is the work measure: it does not grow
//! when other processes load the machine. Deterministic (fixed seeds), two
//! threads. The KDL crate parses at roughly 0.5 µs per byte, so inputs are kept
//! small (comment lines and indentation stripped from the seeds).

use camsim::experiment::{self, Loader};
use std::path::Path;
use std::time::{Duration, Instant};

/// CPU time used so far by the calling thread (CLOCK_THREAD_CPUTIME_ID).
fn thread_cpu_time() -> Duration {
    let mut ts = libc::timespec {
        tv_sec: 0,
        tv_nsec: 0,
    };
    // SAFETY: clock_gettime writes one timespec into the valid pointer.
    let rc = unsafe { libc::clock_gettime(libc::CLOCK_THREAD_CPUTIME_ID, &mut ts) };
    assert_eq!(rc, 0, "clock_gettime(CLOCK_THREAD_CPUTIME_ID) failed");
    Duration::new(ts.tv_sec as u64, ts.tv_nsec as u32)
}

/// Work limits of one input: its thread's CPU time, and wall time as a
/// backstop for a hang that blocks without computing.
const CPU_LIMIT: Duration = Duration::from_secs(1);
const WALL_LIMIT: Duration = Duration::from_secs(30);

struct Rng(u64);
impl Rng {
    fn next(&mut self) -> u64 {
        // xorshift64*
        self.0 ^= self.0 >> 12;
        self.0 ^= self.0 << 25;
        self.0 ^= self.0 >> 27;
        self.0.wrapping_mul(0x2545_F491_4F6C_DD1D)
    }
    fn below(&mut self, n: usize) -> usize {
        if n == 0 {
            0
        } else {
            (self.next() % n as u64) as usize
        }
    }
}

const TOKENS: &[&str] = &[
    "{",
    "}",
    "(",
    ")",
    "\"",
    "=",
    ";",
    "\\",
    "/-",
    "//",
    "/*",
    "*/",
    "#",
    "#true",
    "#null",
    "#inf",
    "#-inf",
    "#nan",
    "r#\"",
    "\"\"\"",
    "\n",
    " ",
    "\t",
    "0",
    "-1",
    "1e999",
    "-0.0",
    "0x10",
    "1_000",
    "170141183460469231731687303715884105728",
    "0.30000000000000004",
    "(0 0 0)",
    "(1 2)",
    "(1 2 3 4)",
    "(400 700 10)",
    "(u8)",
    "experiment",
    "setup",
    "base",
    "scene",
    "add",
    "remove",
    "override",
    "camera",
    "lens",
    "sensor",
    "render",
    "sweep",
    "zip",
    "measure",
    "description",
    "spp=",
    "seed=",
    "max-bounces=",
    "wavelength-nm=",
    "position-m=",
    "look-at-m=",
    "up=",
    "target=",
    "file=",
    "scale=",
    "start=",
    "stop=",
    "step=",
    "exposure-s=",
    "exposure=",
    "name=",
    "of=",
    "spectrum=",
    "\"cie-d65\"",
    "\"smoke\"",
    "render.spp",
    "sensor.exposure-s",
    "lens.film-distance-mm",
    "tag.x",
    "object.e.position-m",
    "measure.colorimetry.spectrum",
    "\"slanted-edge\"",
    "\"mesh\"",
    "\"../scenes/bunny.obj\"",
    "\"cornell-box.kdl\"",
    "é",
    "\u{feff}",
    "\u{0}",
];

/// The valid examples, without comment lines (comments only cost parse time).
fn seeds() -> Vec<String> {
    let compact = |t: &str| {
        t.lines()
            .map(str::trim)
            .filter(|l| !l.starts_with("//") && !l.is_empty())
            .collect::<Vec<_>>()
            .join("\n")
    };
    let mut v: Vec<String> = experiment::embedded::EXPERIMENTS
        .iter()
        .filter(|(_, t)| !t.contains("base \""))
        .map(|(_, t)| compact(t))
        .collect();
    v.push(compact(
        &std::fs::read_to_string("tests/experiments/grid12.kdl").unwrap(),
    ));
    // Experiments with a base get a small base next to the fuzz file instead.
    for (_, t) in experiment::embedded::EXPERIMENTS
        .iter()
        .filter(|(_, t)| t.contains("base \""))
    {
        v.push(compact(t).replace("cornell-box.kdl", "small-setup.kdl"));
    }
    v.push(
        r#"experiment "e" {
    add "e" target="slanted-edge" position-m=(0 0.1 0) rotate-deg=(0 0 5) scale=2 tilt-deg=5
    camera position-m=(0 0 -1) look-at-m=(0 0 0)
    render spp=4 max-bounces=2 seed=3 wavelength-nm=(400 700 10)
    measure "colorimetry" spectrum="cie-a"
    sweep {
        object.e.position-m (0 0 0) (0 0 1)
        camera.position-m (0 0 -1) (0 0 -2)
        render.spp start=1 stop=4 step=1
        zip { tag.a 1 2; tag.b "x" "y" }
    }
}"#
        .to_string(),
    );
    v
}

fn mutate(rng: &mut Rng, src: &str) -> String {
    let mut b: Vec<u8> = src.as_bytes().to_vec();
    let n = 1 + rng.below(4);
    for _ in 0..n {
        let len = b.len();
        match rng.below(7) {
            0 if len > 0 => {
                let i = rng.below(len);
                let k = 1 + rng.below(8.min(len - i));
                b.drain(i..i + k);
            }
            1 => {
                let i = rng.below(len + 1);
                let t = TOKENS[rng.below(TOKENS.len())].as_bytes();
                b.splice(i..i, t.iter().copied());
            }
            2 if len > 0 => {
                let i = rng.below(len);
                b[i] = rng.next() as u8;
            }
            3 if len > 1 => {
                let i = rng.below(len);
                let k = 1 + rng.below(40.min(len - i));
                let seg: Vec<u8> = b[i..i + k].to_vec();
                let j = rng.below(len + 1);
                b.splice(j..j, seg);
            }
            4 if len > 0 => {
                let i = rng.below(len);
                let k = rng.below(30.min(len - i) + 1);
                let t = TOKENS[rng.below(TOKENS.len())].as_bytes();
                b.splice(i..i + k, t.iter().copied());
            }
            5 => {
                b.truncate(rng.below(len + 1));
            }
            _ => {
                let i = rng.below(len + 1);
                const CH: &[u8] = b"{}()\"=;#\\/ \n0123456789.-eabc";
                let c = CH[rng.below(CH.len())];
                b.insert(i, c);
            }
        }
    }
    String::from_utf8_lossy(&b).into_owned()
}

fn random_input(rng: &mut Rng) -> String {
    let n = rng.below(60);
    let mut s = String::new();
    for _ in 0..n {
        if rng.below(3) == 0 {
            s.push_str(TOKENS[rng.below(TOKENS.len())]);
        } else {
            const CH: &[u8] = b" \n{}()\"=abcdefghijklmnopqrstuvwxyz0123456789.-#;/\\";
            s.push(char::from(CH[rng.below(CH.len())]));
        }
    }
    s
}

fn fuzz(thread: u64, total: usize, seeds: &[String]) -> (usize, usize, Duration) {
    let path = Path::new("tests/experiments/fuzz.kdl");
    let mut rng = Rng(0x9E37_79B9_7F4A_7C15 ^ (thread.wrapping_mul(0xD1B5_4A32_D192_ED03)));
    let (mut ok, mut planned) = (0usize, 0usize);
    let mut slowest = Duration::ZERO;
    for i in 0..total {
        let input = if i % 10 == 0 {
            random_input(&mut rng)
        } else {
            let k = rng.below(seeds.len());
            mutate(&mut rng, &seeds[k])
        };
        let t = Instant::now();
        let c = thread_cpu_time();
        let r = std::panic::catch_unwind(|| {
            match experiment::parse_source(path, input.clone(), Loader::Disk) {
                Ok(p) => {
                    let planned =
                        p.kind == experiment::DocKind::Experiment && p.sweep.count() <= 200;
                    if planned {
                        let _ = experiment::plan(&p, None);
                    }
                    (true, planned)
                }
                Err(e) => {
                    assert!(e.line >= 1 && e.col >= 1);
                    let _ = e.to_string();
                    (false, false)
                }
            }
        });
        let dt = thread_cpu_time() - c;
        let wall = t.elapsed();
        slowest = slowest.max(dt);
        match r {
            Ok((o, p)) => {
                ok += o as usize;
                planned += p as usize;
            }
            Err(_) => panic!("input #{i} of thread {thread} panicked:\n{input}"),
        }
        assert!(
            dt < CPU_LIMIT && wall < WALL_LIMIT,
            "input #{i} took {dt:?} CPU, {wall:?} wall:\n{input}"
        );
    }
    (ok, planned, slowest)
}

#[test]
fn no_panic_or_hang_on_100k_random_and_mutated_inputs() {
    let mut seeds = seeds();
    for s in &seeds {
        experiment::parse_source(
            Path::new("tests/experiments/fuzz.kdl"),
            s.clone(),
            Loader::Disk,
        )
        .unwrap_or_else(|e| panic!("seed must be valid: {e}"));
    }
    // Small seeds: each line of the examples inside a minimal experiment (most
    // of the KDL parse time is proportional to the input length).
    let minis: Vec<String> = seeds
        .iter()
        .flat_map(|s| s.lines().map(str::to_string).collect::<Vec<_>>())
        .filter(|l| {
            l.contains('=')
                && !l.contains('{')
                && !l.starts_with("base")
                && !l.starts_with("measure")
        })
        .map(|l| {
            format!("experiment \"m\" {{\n{l}\nmeasure \"colorimetry\" spectrum=\"cie-a\"\n}}")
        })
        .collect();
    seeds.extend(minis.iter().cloned());
    seeds.extend(minis);
    let total: usize = std::env::var("CAMSIM_FUZZ_INPUTS")
        .ok()
        .and_then(|s| s.parse().ok())
        .unwrap_or(100_000);
    let threads = 2;
    let t0 = Instant::now();
    let results: Vec<(usize, usize, Duration)> = std::thread::scope(|sc| {
        let hs: Vec<_> = (0..threads)
            .map(|t| {
                let seeds = &seeds;
                sc.spawn(move || fuzz(t as u64, total / threads, seeds))
            })
            .collect();
        hs.into_iter().map(|h| h.join().unwrap()).collect()
    });
    let ok: usize = results.iter().map(|r| r.0).sum();
    let planned: usize = results.iter().map(|r| r.1).sum();
    let slowest = results.iter().map(|r| r.2).max().unwrap();
    eprintln!(
        "{total} inputs in {:?}: {ok} valid, {planned} planned, slowest {slowest:?} CPU",
        t0.elapsed()
    );
    assert!(ok > 100, "mutations should keep some inputs valid ({ok})");
}

/// Inputs built to exhaust the stack or time: each fails (or passes) cleanly and quickly.
#[test]
fn pathological_inputs_fail_cleanly() {
    let path = Path::new("tests/experiments/pathological.kdl");
    let exp = |body: &str| {
        format!("experiment \"p\" {{\n    measure \"colorimetry\" spectrum=\"cie-a\"\n{body}\n}}\n")
    };
    let cases: Vec<(String, Option<(usize, usize)>)> = vec![
        ("a {".repeat(50_000), Some((1, 195))),
        ("/*".repeat(50_000), Some((1, 129))),
        (
            exp(&format!(
                "    render wavelength-nm=({})",
                "1 ".repeat(100_000)
            )),
            Some((3, 26)),
        ),
        (
            exp(&format!("    description \"{}\"", "x".repeat(200_000))),
            None,
        ),
        (
            exp(&(0..5000)
                .map(|i| format!("    add \"o{i}\" target=\"mcc\"\n"))
                .collect::<String>()),
            None,
        ),
        (
            exp("    sweep {\n        tag.a start=0 stop=1e12 step=1\n    }"),
            Some((4, 9)),
        ),
        (
            exp(&format!(
                "    sweep {{\n{}    }}",
                (0..40)
                    .map(|i| format!("        tag.t{i} 1 2\n"))
                    .collect::<String>()
            )),
            Some((3, 5)),
        ),
        ("\u{feff}\u{0}\u{7f}".repeat(1000), Some((1, 2))),
    ];
    for (i, (text, want)) in cases.into_iter().enumerate() {
        let (t, c) = (Instant::now(), thread_cpu_time());
        let r = experiment::parse_source(path, text, Loader::Disk)
            .and_then(|p| experiment::plan(&p, None).map(|_| ()));
        let (dt, wall) = (thread_cpu_time() - c, t.elapsed());
        assert!(
            dt < 5 * CPU_LIMIT && wall < WALL_LIMIT,
            "case {i} took {dt:?} CPU, {wall:?} wall"
        );
        match (r, want) {
            (Ok(()), None) => {}
            (Err(e), Some((line, col))) => {
                assert_eq!(
                    (e.line, e.col),
                    (line, col),
                    "case {i}: {}",
                    e.message.chars().take(200).collect::<String>()
                )
            }
            (r, w) => panic!(
                "case {i}: got {:?}, wanted {:?}",
                r.err().map(|e| (
                    e.line,
                    e.col,
                    e.message.chars().take(200).collect::<String>()
                )),
                w
            ),
        }
    }
}
