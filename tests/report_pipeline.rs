//! Measurements → results.csv/curves → HTML report, index and diff, on
//! synthetic captures whose noise seed and lamp power we control.

mod common;

use camsim::image::CfaPattern;
use camsim::measure::compare::{Pair, compare};
use camsim::measure::convergence::{ErrorLaw, Run, convergence};
use camsim::measure::noise::{NoiseOptions, measure as noise_measure};
use camsim::measure::plane::{Plane, channel_views};
use camsim::measure::ri::{RiOptions, relative_illumination};
use camsim::measure::sfr::{SfrOptions, sfr};
use camsim::measure::stats::SplitMix64;
use camsim::measure::{Measured, mcc};
use camsim::report::diff::{DiffOptions, diff_rows, read_dir_results};
use camsim::report::results::{ResultRow, write_curves, write_results};
use common::erfc;
use std::path::{Path, PathBuf};
use std::process::Command;

const CG: f64 = 0.17;

fn bayer(p: &mut Plane) {
    let cfa = CfaPattern::bayer("rggb").unwrap();
    let w = p.width;
    p.channel = (0..p.data.len())
        .map(|i| cfa.channel_at((i % w) as u32, (i / w) as u32) as u8)
        .collect();
    p.channel_names = cfa.channels;
}

/// Photon noise (Gaussian, variance = mean electrons), converted to DV.
fn dv(e: f64, rng: &mut SplitMix64) -> f64 {
    (e + e.max(0.0).sqrt() * rng.gauss()) * CG
}

fn rows_of(m: &Measured, variant: &str, focus: &str) -> Vec<ResultRow> {
    m.figures
        .iter()
        .map(|f| ResultRow {
            experiment: "fig-test".into(),
            variant: variant.into(),
            params: vec![("focus-m".into(), focus.into())],
            measurement: f.measurement.clone(),
            quantity: f.quantity.clone(),
            unit: f.unit.clone(),
            value: f.value,
            stderr: f.stderr,
            render_s: 1.25,
            total_s: 1.5,
        })
        .collect()
}

fn png_gray(path: &Path, w: usize, h: usize, v: &[f64]) {
    let max = v.iter().cloned().fold(1e-9, f64::max);
    std::fs::create_dir_all(path.parent().unwrap()).unwrap();
    let f = std::fs::File::create(path).unwrap();
    let mut e = png::Encoder::new(std::io::BufWriter::new(f), w as u32, h as u32);
    e.set_color(png::ColorType::Grayscale);
    e.set_depth(png::BitDepth::Eight);
    let mut wr = e.write_header().unwrap();
    wr.write_image_data(
        &v.iter()
            .map(|x| (x / max * 255.0).clamp(0.0, 255.0) as u8)
            .collect::<Vec<_>>(),
    )
    .unwrap();
    wr.finish().unwrap();
}

/// One simulated "run" of a two-variant experiment into `dir`.
fn run(dir: &Path, seed: u64, power: f64) {
    let mut rows = vec![];
    for (vi, (variant, focus, sigma)) in [("near", "0.3", 0.6), ("far", "0.5", 1.2)]
        .into_iter()
        .enumerate()
    {
        let mut rng = SplitMix64(seed * 100 + vi as u64);
        // Slanted edge, 5°, 8×8 sub-samples.
        let (w, h) = (80usize, 72usize);
        let th = 5f64.to_radians();
        let mut edge = vec![];
        for j in 0..h {
            for i in 0..w {
                let mut acc = 0.0;
                for a in 0..8 {
                    for b in 0..8 {
                        let x = i as f64 - 0.5 + (b as f64 + 0.5) / 8.0 - 40.0;
                        let y = j as f64 - 0.5 + (a as f64 + 0.5) / 8.0 - 36.0;
                        acc += 0.5
                            * erfc(
                                -(x * th.cos() - y * th.sin()) / sigma / std::f64::consts::SQRT_2,
                            );
                    }
                }
                edge.push(dv(power * (400.0 + 3000.0 * acc / 64.0), &mut rng));
            }
        }
        let s = sfr(
            &Plane::new(w, h, edge).unwrap(),
            &SfrOptions {
                pixel_pitch_m: Some(1.4e-6),
                ..Default::default()
            },
        )
        .unwrap();
        let m = s.measured(
            "sfr",
            camsim::optical_image::Rect::new(0, 0, w as u32, h as u32),
        );
        write_curves(dir, variant, "sfr", &m.curves).unwrap();
        rows.extend(rows_of(&m, variant, focus));

        // MCC chart: 6×4 patches of 20 px, labels mcc/patch01…24.
        let (cw, ch) = (160usize, 112usize);
        let mut names: Vec<String> = (1..=24).map(|k| format!("mcc/patch{k:02}")).collect();
        names.push("wall".into());
        let (mut labels, mut data) = (vec![24u32; cw * ch], vec![]);
        let cfa = CfaPattern::bayer("rggb").unwrap();
        for y in 0..ch {
            for x in 0..cw {
                let (px, py, ix, iy) = (
                    (x as i64 - 8) / 24,
                    (y as i64 - 8) / 24,
                    (x as i64 - 8) % 24,
                    (y as i64 - 8) % 24,
                );
                let e = if x >= 8 && y >= 8 && px < 6 && py < 4 && ix < 20 && iy < 20 {
                    let k = (py * 6 + px) as usize;
                    labels[y * cw + x] = k as u32;
                    let c = cfa.channel_at(x as u32, y as u32);
                    (3000.0 + 600.0 * k as f64) * [0.6, 1.0, 0.8][c]
                } else {
                    150.0
                };
                data.push(dv(power * e, &mut rng));
            }
        }
        let mut chart = Plane::new(cw, ch, data.clone()).unwrap();
        bayer(&mut chart);
        let patches =
            mcc::patch_means(&channel_views(&chart, "y"), &labels, &names, "mcc", 0.15).unwrap();
        let m = mcc::measured(&patches, "mcc");
        write_curves(dir, variant, "mcc", &m.curves).unwrap();
        rows.extend(rows_of(&m, variant, focus));
        png_gray(
            &dir.join("previews").join(variant).join("sensor.png"),
            cw,
            ch,
            &data,
        );
        let rois: Vec<String> = m
            .pixels_read
            .iter()
            .map(|r| {
                format!(
                    "{{\"label\":\"patch\",\"x\":{},\"y\":{},\"w\":{},\"h\":{}}}",
                    r.x, r.y, r.w, r.h
                )
            })
            .collect();
        std::fs::write(
            dir.join("previews").join(variant).join("sensor.rois.json"),
            format!("[{}]", rois.join(",")),
        )
        .unwrap();

        // Simulated vs "measured" patch means (measured = truth · 1.02).
        let pairs: Vec<Pair> = patches
            .iter()
            .flat_map(|p| {
                let k = (p.number - 1) as f64;
                p.means
                    .iter()
                    .enumerate()
                    .map(move |(c, (cn, mean, _))| Pair {
                        name: format!("{}/{cn}", p.number),
                        simulated: *mean,
                        reference: 1.02 * CG * (3000.0 + 600.0 * k) * [0.6, 1.0, 0.8][c],
                    })
            })
            .collect();
        let m = compare(&pairs, "DV", "mcc-vs-measured").unwrap();
        write_curves(dir, variant, "mcc-vs-measured", &m.curves).unwrap();
        rows.extend(rows_of(&m, variant, focus));

        // Uniform-region noise on a gently lit Bayer frame.
        let n = 120usize;
        let flat: Vec<f64> = (0..n * n)
            .map(|i| {
                dv(
                    power * 2000.0 * (1.0 + 0.5 * (i % n) as f64 / n as f64),
                    &mut rng,
                )
            })
            .collect();
        let mut fp = Plane::new(n, n, flat).unwrap();
        bayer(&mut fp);
        let (m, _) = noise_measure(
            &fp,
            &NoiseOptions {
                regions: 200,
                conversion_gain_dv_per_e: CG,
                seed: 3,
                ..Default::default()
            },
            "noise",
        )
        .unwrap();
        write_curves(dir, variant, "noise", &m.curves).unwrap();
        rows.extend(rows_of(&m, variant, focus));

        // Relative illumination: cos⁴ flat field.
        let ri_img: Vec<f64> = (0..n * n)
            .map(|i| {
                let (x, y) = ((i % n) as f64 - 60.0, (i / n) as f64 - 60.0);
                dv(
                    power * 3000.0 / (1.0 + (x * x + y * y) / 2e4).powi(2),
                    &mut rng,
                )
            })
            .collect();
        let mut rp = Plane::new(n, n, ri_img).unwrap();
        bayer(&mut rp);
        let m = relative_illumination(
            &rp,
            &RiOptions {
                pixel_pitch_m: Some(1.4e-6),
                ..Default::default()
            },
            "ri",
        )
        .unwrap();
        write_curves(dir, variant, "ri", &m.curves).unwrap();
        rows.extend(rows_of(&m, variant, focus));

        // Convergence of MTF50 with render time.
        let runs: Vec<Run> = [1.0, 2.0, 4.0, 8.0, 16.0]
            .iter()
            .map(|&t| {
                let se = 0.004 / f64::sqrt(t);
                Run {
                    wall_s: t,
                    samples: 64.0 * t,
                    value: s.mtf50_cy_per_px.unwrap() + se * rng.gauss(),
                    stderr: se,
                }
            })
            .collect();
        let m = convergence(
            &runs,
            s.mtf50_cy_per_px.map(|v| (v, 0.0)),
            "mtf50",
            "cy/px",
            "convergence",
            0.0,
            ErrorLaw::InverseSqrt,
        )
        .unwrap();
        write_curves(dir, variant, "convergence", &m.curves).unwrap();
        rows.extend(rows_of(&m, variant, focus));
    }
    write_results(&dir.join("results.csv"), &rows).unwrap();
    std::fs::write(
        dir.join("manifest.json"),
        r#"{"status":"ok","total_s":3.0,"git_commit":"0123abc","threads":2,"version":"0.1.0"}"#,
    )
    .unwrap();
}

fn experiment(root: &Path, name: &str, seed: u64, power: f64) -> PathBuf {
    let d = root.join(name).join("fig-test");
    std::fs::create_dir_all(&d).unwrap();
    run(&d, seed, power);
    d
}

#[test]
fn diff_ignores_seed_noise_and_flags_five_percent_lamp_power() {
    let tmp = tempfile::tempdir().unwrap();
    let a = read_dir_results(&experiment(tmp.path(), "a", 1, 1.0)).unwrap();
    let b = read_dir_results(&experiment(tmp.path(), "b", 2, 1.0)).unwrap();
    let c = read_dir_results(&experiment(tmp.path(), "c", 1, 1.05)).unwrap();
    let opts = DiffOptions::default();
    let ab = diff_rows(&a, &b, &opts);
    println!(
        "seed only: {} compared, {} changed, {} significant (z > {:.2})",
        ab.compared,
        ab.changes.len(),
        ab.significant(),
        ab.z_threshold
    );
    let max_z = ab
        .changes
        .iter()
        .map(|c| c.z)
        .filter(|z| z.is_finite())
        .fold(0.0, f64::max);
    println!("largest |Δ|/σ between seeds: {max_z:.2}");
    assert!(
        ab.compared > 150 && ab.changes.len() > 150,
        "the seeds must actually change the figures"
    );
    assert_eq!(
        ab.significant(),
        0,
        "{:?}",
        ab.changes
            .iter()
            .filter(|c| c.significant)
            .collect::<Vec<_>>()
    );
    let ac = diff_rows(&a, &c, &opts);
    let flagged: Vec<_> = ac.changes.iter().filter(|c| c.significant).collect();
    let flagged_means = flagged.iter().filter(|c| c.measurement == "mcc").count();
    println!(
        "lamp +5 %: {} significant, {flagged_means} of 144 MCC patch means",
        ac.significant()
    );
    // Patch means scale with lamp power. The darkest (r of patch 1: 1800 e⁻, 49 px
    // after erosion) has a relative se of 1/√(1800·49) = 0.34 %, so a 5 % change has
    // z ≥ 5/(0.34·√2) ≈ 10 ≫ 4.34: every patch mean must be flagged.
    assert_eq!(flagged_means, 144);
    // MTF does not depend on lamp power: not flagged.
    assert!(
        !flagged
            .iter()
            .any(|c| c.measurement == "sfr" && c.quantity == "mtf50")
    );
}

fn camsim(args: &[&str], cwd: &Path) -> (i32, String, String) {
    let o = Command::new(env!("CARGO_BIN_EXE_camsim"))
        .args(args)
        .current_dir(cwd)
        .output()
        .unwrap();
    (
        o.status.code().unwrap_or(-1),
        String::from_utf8_lossy(&o.stdout).into(),
        String::from_utf8_lossy(&o.stderr).into(),
    )
}

#[test]
fn diff_cli_reads_directories_and_git_revisions() {
    let tmp = tempfile::tempdir().unwrap();
    let repo = tmp.path().join("repo");
    let a = experiment(&repo, "results", 1, 1.0);
    let git = |args: &[&str]| {
        let o = Command::new("git")
            .args([
                "-c",
                "user.name=t",
                "-c",
                "user.email=t@t",
                "-c",
                "commit.gpgsign=false",
            ])
            .args(args)
            .current_dir(&repo)
            .output()
            .unwrap();
        assert!(
            o.status.success(),
            "git {args:?}: {}",
            String::from_utf8_lossy(&o.stderr)
        );
    };
    git(&["init", "-q"]);
    git(&["add", "results"]);
    git(&["commit", "-qm", "a"]);
    run(&a, 1, 1.05);
    git(&["commit", "-qam", "lamp +5%"]);
    let (code, out, err) = camsim(&["diff", "HEAD~1", "HEAD", "--html", "d.html"], &repo);
    assert_eq!(code, 1, "{out}\n{err}");
    assert!(
        out.contains("SIGNIFICANT fig-test/near mcc.patch01/r_mean"),
        "{out}"
    );
    assert!(repo.join("d.html").exists());
    let (code, out, _) = camsim(&["diff", "HEAD", "results"], &repo);
    assert_eq!(code, 0, "{out}");
    let (code, out, err) = camsim(&["report", "results"], &repo);
    assert_eq!(code, 0, "{out}\n{err}");
    assert!(
        repo.join("results/fig-test/report.html").exists()
            && repo.join("results/index.html").exists()
    );
    let (code, _, err) = camsim(&["diff", "no-such-rev", "HEAD"], &repo);
    assert_eq!(code, 3);
    assert!(
        err.contains("neither a results directory nor a git revision"),
        "{err}"
    );
}

/// A report must open offline: its Content-Security-Policy forbids every
/// fetch, and the only absolute URLs in it are XML namespace names
/// (`http://www.w3.org/…`, identifiers that are never fetched) — no
/// `src`/`href`/`url(…)` pointing at a server.
fn assert_no_network(html: &str) {
    assert!(
        html.contains("content=\"default-src 'none';"),
        "report lacks the CSP that blocks network access"
    );
    for scheme in ["http://", "https://", "//cdn", "ftp://"] {
        for (i, _) in html.match_indices(scheme) {
            let before = &html[i.saturating_sub(16)..i];
            let after = &html[i..(i + 40).min(html.len())];
            assert!(
                scheme == "http://"
                    && after.starts_with("http://www.w3.org/")
                    && (before.ends_with("xmlns=\"") || before.ends_with("xmlns:xlink=\"")),
                "network reference in the report: …{before}{after}…"
            );
        }
    }
    for bad in ["src=\"//", "href=\"//", "url(//", "@import"] {
        assert!(!html.contains(bad), "network reference {bad} in the report");
    }
}

#[test]
fn report_and_index_render_every_plot_and_open_in_chromium() {
    let tmp = tempfile::tempdir().unwrap();
    let root = tmp.path().join("results");
    let d = experiment(tmp.path(), "results", 1, 1.0);
    camsim::report::write_report(&d).unwrap();
    camsim::report::write_index(&root).unwrap();
    if let Some(keep) = std::env::var_os("CAMSIM_KEEP_REPORT") {
        // For looking at the report by eye: copy it out of the temp dir.
        std::fs::copy(d.join("report.html"), keep).unwrap();
    }
    let html = std::fs::read_to_string(d.join("report.html")).unwrap();
    let plots = html.matches("<figure class=\"plot\"").count();
    // sfr: esf, lsf, mtf + 7 figures vs focus; mcc: 3 channel curves → 1 chart + 72 vs focus;
    // at least the curve charts of every measurement must be there.
    for t in [
        "sfr: mtf",
        "sfr: lsf",
        "ri: ri",
        "noise: std_vs_mean",
        "mcc-vs-measured: scatter",
        "convergence: stderr_vs_time",
        "convergence: error_vs_time",
    ] {
        assert!(html.contains(t), "missing plot {t}");
    }
    assert!(plots >= 10, "{plots} plots");
    assert!(!html.contains("data-points=\"0\""));
    assert!(
        html.contains("data:image/png;base64,") && html.contains("<rect"),
        "preview with ROI overlay"
    );
    assert_no_network(&html);
    let index = std::fs::read_to_string(root.join("index.html")).unwrap();
    assert_no_network(&index);
    // (minijinja's HTML escaping writes '/' as &#x2f; inside the href.)
    assert!(
        index.contains("report.html\">fig-test</a>") && index.contains("sfr mtf50 = "),
        "{index}"
    );
    // per-experiment run times and their total (issue 16 item 3)
    assert!(index.contains("all experiments</td>"), "{index}");

    // Headless Chromium: no console errors, every plot drawn with data.
    for page in [d.join("report.html"), root.join("index.html")] {
        let Some(dom) = common::chromium_dom(&page) else {
            return;
        };
        if page.ends_with("report.html") {
            assert!(
                dom.contains("data-plots-ok=\"true\""),
                "a plot is empty or missing: {}",
                &dom[..dom.len().min(500)]
            );
            assert!(
                dom.contains(&format!("data-plots=\"{plots}\"")),
                "script saw a different number of plots"
            );
        } else {
            assert!(
                dom.contains("data-plots=\"0\""),
                "index page script did not run"
            );
        }
    }
}
