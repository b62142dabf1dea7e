//! Helpers shared by integration tests (`mod common;` in a test file).
#![allow(dead_code)]

use std::process::{Command, Output};

/// Run the camsim binary under test with `args` (its output captured).
pub fn camsim(args: &[&str]) -> Output {
    Command::new(env!("CARGO_BIN_EXE_camsim"))
        .args(args)
        .output()
        .unwrap()
}

/// The standard error text of a finished command.
pub fn stderr(o: &Output) -> String {
    String::from_utf8_lossy(&o.stderr).into_owned()
}

/// Numeric rows of a reference CSV table. Blank lines and `#` comment lines
/// are skipped, and so is one header line (the first that is not numbers);
/// any other non-numeric line is a broken reference file and panics.
pub fn numeric_rows(path: &str) -> Vec<Vec<f64>> {
    let text = std::fs::read_to_string(path).unwrap_or_else(|e| panic!("{path}: {e}"));
    let mut header_seen = false;
    let mut rows = Vec::new();
    for (i, l) in text.lines().enumerate() {
        let l = l.trim();
        if l.is_empty() || l.starts_with('#') {
            continue;
        }
        let parsed: Option<Vec<f64>> = l.split(',').map(|x| x.trim().parse().ok()).collect();
        match parsed {
            Some(v) => rows.push(v),
            None if !header_seen && rows.is_empty() => header_seen = true,
            None => panic!("{path}:{}: not a numeric row: {l}", i + 1),
        }
    }
    rows
}

/// Open `page` in headless Chromium and return its DOM after the scripts ran,
/// asserting that the page logged nothing to the console. Without Chromium:
/// panics when the env var CI is set, else prints a note and returns None.
pub fn chromium_dom(page: &std::path::Path) -> Option<String> {
    use std::process::Command;
    let chromium = ["/usr/bin/chromium", "/usr/bin/chromium-browser"]
        .into_iter()
        .map(std::path::PathBuf::from)
        .find(|p| p.exists());
    let Some(chromium) = chromium else {
        if std::env::var_os("CI").is_some() {
            panic!("chromium is required in CI (Debian package 'chromium')");
        }
        println!(
            "note: chromium not found; skipping the browser check (install Debian's 'chromium')"
        );
        return None;
    };
    let ud = tempfile::tempdir().unwrap();
    let mut child = Command::new(&chromium)
        .args([
            "--headless",
            "--no-sandbox",
            "--disable-gpu",
            "--disable-quic",
            "--no-first-run",
            "--disable-background-networking",
            "--disable-component-update",
            "--disable-sync",
            "--enable-logging=stderr",
            "--v=0",
        ])
        .arg(format!("--user-data-dir={}", ud.path().display()))
        .arg("--dump-dom")
        .arg(format!("file://{}", page.display()))
        .stdout(std::process::Stdio::piped())
        .stderr(std::process::Stdio::piped())
        .spawn()
        .unwrap();
    // Read both pipes on threads, kill our child if it hangs past 90 s.
    let mut so = child.stdout.take().unwrap();
    let mut se = child.stderr.take().unwrap();
    let t1 = std::thread::spawn(move || {
        let mut s = String::new();
        std::io::Read::read_to_string(&mut so, &mut s).ok();
        s
    });
    let t2 = std::thread::spawn(move || {
        let mut s = String::new();
        std::io::Read::read_to_string(&mut se, &mut s).ok();
        s
    });
    let start = std::time::Instant::now();
    loop {
        if child.try_wait().unwrap().is_some() {
            break;
        }
        if start.elapsed().as_secs() > 90 {
            child.kill().ok();
            panic!("chromium did not finish within 90 s");
        }
        std::thread::sleep(std::time::Duration::from_millis(100));
    }
    let (dom, log) = (t1.join().unwrap(), t2.join().unwrap());
    let console: Vec<&str> = log.lines().filter(|l| l.contains(":CONSOLE")).collect();
    assert!(
        console.is_empty(),
        "console messages in {}: {console:?}",
        page.display()
    );
    Some(dom)
}

/// dcraw (an independent raw reader) opens the DNG at `dng` with this size,
/// CFA pattern (as dcraw prints it, e.g. "GR/BG") and black/white level.
/// Without dcraw: panics when the env var CI is set, else prints a note and
/// returns false (nothing checked).
pub fn dcraw_reads(
    dng: &std::path::Path,
    size: (u32, u32),
    pattern: &str,
    black_white: (u32, u32),
) -> bool {
    use std::process::Command;
    if Command::new("dcraw").output().is_err() {
        assert!(
            std::env::var_os("CI").is_none(),
            "dcraw must be installed in CI (.ci/run installs the Debian package 'dcraw')"
        );
        eprintln!("note: dcraw not installed; skipping the external DNG check (CI would fail)");
        return false;
    }
    let id = Command::new("dcraw")
        .arg("-i")
        .arg("-v")
        .arg(dng)
        .output()
        .unwrap();
    let s = String::from_utf8_lossy(&id.stdout);
    assert!(id.status.success(), "dcraw -i {}: {s}", dng.display());
    let got = s
        .lines()
        .find(|l| l.starts_with("Image size:"))
        .map(|l| l.split_whitespace().collect::<Vec<_>>().join(" "));
    let want = format!("Image size: {} x {}", size.0, size.1);
    assert_eq!(got.as_deref(), Some(want.as_str()), "{s}");
    assert!(s.contains(&format!("Filter pattern: {pattern}")), "{s}");
    let dec = Command::new("dcraw")
        .args(["-v", "-d", "-c"])
        .arg(dng)
        .output()
        .unwrap();
    let log = String::from_utf8_lossy(&dec.stderr);
    assert!(dec.status.success(), "{log}");
    let levels = format!("darkness {}, saturation {}", black_white.0, black_white.1);
    assert!(log.contains(&levels), "{levels}: {log}");
    true
}

/// erfc with fractional error < 1.2e-7 (Chebyshev fit, Numerical Recipes
/// `erfcc`): the reference the edge tests build their images from,
/// independent of the crate's own functions.
pub fn erfc(x: f64) -> f64 {
    let z = x.abs();
    let t = 1.0 / (1.0 + 0.5 * z);
    let p = -z * z - 1.26551223
        + t * (1.00002368
            + t * (0.37409196
                + t * (0.09678418
                    + t * (-0.18628806
                        + t * (0.27886807
                            + t * (-1.13520398
                                + t * (1.48851587 + t * (-0.82215223 + t * 0.17087277))))))));
    let a = t * p.exp();
    if x >= 0.0 { a } else { 2.0 - a }
}
