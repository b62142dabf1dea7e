//! Mutation fuzzing of the pbrt parser: 100 000 byte-level mutations of the test
//! corpus (deterministic xorshift seed) must never panic and never take a second.

use camsim::scene::pbrt::{LoadOptions, parse_text};
use std::path::PathBuf;
use std::time::{Duration, Instant};

struct XorShift(u64);
impl XorShift {
    fn next(&mut self) -> u64 {
        let mut x = self.0;
        x ^= x << 13;
        x ^= x >> 7;
        x ^= x << 17;
        self.0 = x;
        x
    }
    fn below(&mut self, n: usize) -> usize {
        (self.next() % n.max(1) as u64) as usize
    }
}

const BYTES: &[u8] = b"\"[]#\\\n 0123456789.-+eEabcxyzPN";
const WORDS: &[&str] = &[
    "Shape",
    "AttributeBegin",
    "AttributeEnd",
    "ObjectBegin \"o\"",
    "ObjectEnd",
    "ObjectInstance \"o\"",
    "WorldBegin",
    "Include",
    "Translate 1 2 3",
    "Scale 0 0 0",
    "Rotate 90 0 0 0",
    "LookAt 0 0 0 0 0 0 0 1 0",
    "ReverseOrientation",
    "TransformBegin",
    "TransformEnd",
    "Camera \"perspective\"",
    "[",
    "]",
    "\"",
    "1e308",
    "-1e308",
    "1e-320",
    "9e15",
    "-0",
    "\"float radius\"",
    "\"integer indices\"",
    "\"point3 P\"",
    "\"rgb L\"",
    "\"spectrum eta\"",
    "\"blackbody L\"",
    "\"string type\"",
    "#ObjectName X:",
    "NamedMaterial \"a\"",
    "MakeNamedMaterial \"a\"",
    "\"loopsubdiv\"",
    "\"integer levels\" 40",
    "CoordSysTransform \"camera\"",
    "ActiveTransform EndTime",
    "Texture \"t\" \"spectrum\" \"constant\"",
    "\"texture reflectance\" \"t\"",
    "AreaLightSource \"diffuse\"",
    "\"float power\" 1e300",
    "\"bool twosided\" true",
];

fn corpus() -> Vec<(PathBuf, Vec<u8>)> {
    let dir = PathBuf::from(env!("CARGO_MANIFEST_DIR")).join("tests/pbrt");
    let mut files = vec![];
    for sub in ["", "bad", "inc"] {
        let d = dir.join(sub);
        let mut names: Vec<_> = std::fs::read_dir(&d)
            .unwrap()
            .filter_map(|e| e.ok())
            .map(|e| e.path())
            .collect();
        names.sort();
        for p in names {
            if p.extension().is_some_and(|e| e == "pbrt") {
                files.push((p.clone(), std::fs::read(&p).unwrap()));
            }
        }
    }
    assert!(files.len() >= 40);
    files
}

fn mutate(rng: &mut XorShift, src: &[u8]) -> Vec<u8> {
    let mut v = src.to_vec();
    for _ in 0..1 + rng.below(4) {
        let n = v.len();
        match rng.below(6) {
            0 if n > 0 => {
                let i = rng.below(n);
                v[i] = BYTES[rng.below(BYTES.len())];
            }
            1 if n > 0 => {
                let i = rng.below(n);
                let len = 1 + rng.below(8.min(n - i));
                v.drain(i..i + len.min(n - i));
            }
            2 if n > 0 => {
                let i = rng.below(n);
                let j = (i + 1 + rng.below(16)).min(n);
                let chunk = v[i..j].to_vec();
                let at = rng.below(v.len() + 1);
                v.splice(at..at, chunk);
            }
            3 => {
                let w = WORDS[rng.below(WORDS.len())];
                let at = rng.below(v.len() + 1);
                let mut s = format!(" {w} ").into_bytes();
                v.splice(at..at, s.drain(..));
            }
            4 if n > 0 => {
                let i = rng.below(n);
                v[i] = (rng.next() & 0xff) as u8;
            }
            _ => {
                let at = rng.below(n + 1);
                v.truncate(at);
            }
        }
    }
    v
}

#[test]
fn one_hundred_thousand_mutations_no_panic_none_slow() {
    let files = corpus();
    let mut rng = XorShift(0x9E37_79B9_7F4A_7C15);
    let opts = [
        LoadOptions {
            strict: false,
            ..Default::default()
        },
        LoadOptions {
            strict: true,
            ..Default::default()
        },
    ];
    let mut worst = (Duration::ZERO, String::new());
    let (mut ok, mut err) = (0usize, 0usize);
    let t0 = Instant::now();
    for k in 0..100_000usize {
        let (path, src) = &files[rng.below(files.len())];
        let m = mutate(&mut rng, src);
        let text = String::from_utf8_lossy(&m).into_owned();
        let t = Instant::now();
        let r = std::panic::catch_unwind(|| parse_text(&text, path, &opts[k % 2]).is_ok());
        let dt = t.elapsed();
        match r {
            Ok(true) => ok += 1,
            Ok(false) => err += 1,
            Err(_) => panic!(
                "parser panicked on mutation {k} of {}:\n{text}",
                path.display()
            ),
        }
        if dt > worst.0 {
            worst = (dt, text);
        }
    }
    eprintln!(
        "fuzz: 100000 inputs in {:.2} s ({ok} parsed, {err} rejected); slowest {:.1} ms",
        t0.elapsed().as_secs_f64(),
        worst.0.as_secs_f64() * 1e3
    );
    assert!(
        worst.0 < Duration::from_secs(1),
        "slowest input took {:?}:\n{}",
        worst.0,
        worst.1
    );
    assert!(
        ok > 1000 && err > 1000,
        "mutations should both keep and break files ({ok} ok, {err} errors)"
    );
}
