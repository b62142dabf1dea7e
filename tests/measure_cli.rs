//! `camsim measure …` on image files.

use camsim::image::CfaPattern;
use std::process::Command;

mod common;
use common::erfc;

/// 5° edge, Gaussian σ, pixels = mean of 16×16 sub-samples, values 0.1…0.9.
fn edge(w: usize, h: usize, sigma: f64) -> Vec<f64> {
    let th = 5f64.to_radians();
    let mut v = vec![];
    for j in 0..h {
        for i in 0..w {
            let mut acc = 0.0;
            for a in 0..16 {
                for b in 0..16 {
                    let x = i as f64 - 0.5 + (b as f64 + 0.5) / 16.0 - w as f64 / 2.0;
                    let y = j as f64 - 0.5 + (a as f64 + 0.5) / 16.0 - h as f64 / 2.0;
                    acc += 0.5
                        * erfc(-(x * th.cos() - y * th.sin()) / sigma / std::f64::consts::SQRT_2);
                }
            }
            v.push(0.1 + 0.8 * acc / 256.0);
        }
    }
    v
}

fn reference_mtf50(sigma: f64) -> f64 {
    let th = 5f64.to_radians();
    let sinc = |x: f64| {
        if x == 0.0 {
            1.0
        } else {
            (std::f64::consts::PI * x).sin() / (std::f64::consts::PI * x)
        }
    };
    let r = |f: f64| {
        (-2.0 * std::f64::consts::PI.powi(2) * sigma * sigma * f * f).exp()
            * sinc(f * th.cos())
            * sinc(f * th.sin())
            * sinc(f / 4.0)
    };
    let (mut a, mut b) = (0.0, 1.0);
    for _ in 0..60 {
        let m = 0.5 * (a + b);
        if r(m) > 0.5 { a = m } else { b = m }
    }
    a
}

fn camsim(args: &[&str]) -> (i32, String, String) {
    let o = Command::new(env!("CARGO_BIN_EXE_camsim"))
        .args(args)
        .output()
        .unwrap();
    (
        o.status.code().unwrap_or(-1),
        String::from_utf8_lossy(&o.stdout).into(),
        String::from_utf8_lossy(&o.stderr).into(),
    )
}

fn mtf50_of(out: &str) -> f64 {
    out.lines()
        .find_map(|l| l.strip_prefix("# mtf50_cy_per_px="))
        .unwrap()
        .parse()
        .unwrap()
}

#[test]
fn measure_sfr_on_png_and_dng() {
    let dir = tempfile::tempdir().unwrap();
    let (w, h) = (80, 72);
    let v = edge(w, h, 0.8);
    // 16-bit PNG, embedded in a larger frame to exercise --roi.
    let (fw, fh) = (w + 20, h + 10);
    let mut frame = vec![0u16; fw * fh];
    for y in 0..h {
        for x in 0..w {
            frame[(y + 4) * fw + x + 12] = (v[y * w + x] * 65535.0).round() as u16;
        }
    }
    let png_path = dir.path().join("edge.png");
    let f = std::fs::File::create(&png_path).unwrap();
    let mut e = png::Encoder::new(std::io::BufWriter::new(f), fw as u32, fh as u32);
    e.set_color(png::ColorType::Grayscale);
    e.set_depth(png::BitDepth::Sixteen);
    let mut wr = e.write_header().unwrap();
    wr.write_image_data(
        &frame
            .iter()
            .flat_map(|x| x.to_be_bytes())
            .collect::<Vec<u8>>(),
    )
    .unwrap();
    wr.finish().unwrap();
    let (code, out, err) = camsim(&[
        "measure",
        "sfr",
        png_path.to_str().unwrap(),
        "--roi",
        "12,4,80,72",
        "--pixel-um",
        "1.4",
    ]);
    assert_eq!(code, 0, "{err}");
    assert!(out.starts_with("freq_cy_per_px,freq_cy_per_mm,mtf\n"));
    let second: Vec<f64> = out
        .lines()
        .nth(2)
        .unwrap()
        .split(',')
        .map(|s| s.parse().unwrap())
        .collect();
    assert!((second[1] - second[0] / 1.4e-3).abs() < 1e-3, "{second:?}");
    let t50 = reference_mtf50(0.8);
    let m50 = mtf50_of(&out);
    // Same 1 % acceptance as the library test (16×16 sub-samples, 16-bit quantisation: negligible).
    assert!((m50 - t50).abs() / t50 < 0.01, "png: {m50} vs {t50}");

    // DNG Bayer mosaic, green channel, black level 64.
    let cfa = CfaPattern::bayer("rggb").unwrap();
    let dv: Vec<u16> = v
        .iter()
        .map(|x| (64.0 + x * 1000.0).round() as u16)
        .collect();
    let dng = dir.path().join("edge.dng");
    write_raw_dng(&dng, w as u32, h as u32, &dv, &cfa, 1023.0);
    let (code, out, err) = camsim(&["measure", "sfr", dng.to_str().unwrap(), "--channel", "g"]);
    assert_eq!(code, 0, "{err}");
    let m50 = mtf50_of(&out);
    // 10-bit quantisation (step 1/800 of the edge contrast) adds ~0.1 % noise to MTF50.
    assert!((m50 - t50).abs() / t50 < 0.015, "dng: {m50} vs {t50}");

    // Errors name the file and exit 3.
    let bad = dir.path().join("bad.exr");
    std::fs::write(&bad, b"nonsense").unwrap();
    let (code, _, err) = camsim(&["measure", "sfr", bad.to_str().unwrap()]);
    assert_eq!(code, 3);
    assert!(err.contains("bad.exr"), "{err}");
    let (code, _, err) = camsim(&[
        "measure",
        "sfr",
        png_path.to_str().unwrap(),
        "--roi",
        "90,4,80,72",
    ]);
    assert_eq!(code, 3);
    assert!(err.contains("outside"), "{err}");
}

fn write_png16_gray(path: &std::path::Path, w: usize, h: usize, v: &[u16]) {
    let f = std::fs::File::create(path).unwrap();
    let mut e = png::Encoder::new(std::io::BufWriter::new(f), w as u32, h as u32);
    e.set_color(png::ColorType::Grayscale);
    e.set_depth(png::BitDepth::Sixteen);
    let mut wr = e.write_header().unwrap();
    wr.write_image_data(&v.iter().flat_map(|x| x.to_be_bytes()).collect::<Vec<u8>>())
        .unwrap();
    wr.finish().unwrap();
}

#[test]
fn measure_mcc_profile_noise_ri_on_a_dng_with_a_label_map() {
    let dir = tempfile::tempdir().unwrap();
    // 6×4 chart of 20-px patches (gaps 4 px) on a 160×112 RGGB mosaic, black level 64:
    // patch k has r = 10k, g = 20k, b = 5k + 3 DV above black; background 2 DV.
    let (w, h) = (160usize, 112usize);
    let cfa = CfaPattern::bayer("rggb").unwrap();
    let (mut dv, mut lab) = (vec![0u16; w * h], vec![0u16; w * h]);
    for y in 0..h {
        for x in 0..w {
            let (px, py, ix, iy) = (
                (x as i64 - 8) / 24,
                (y as i64 - 8) / 24,
                (x as i64 - 8) % 24,
                (y as i64 - 8) % 24,
            );
            let inside = x >= 8 && y >= 8 && px < 6 && py < 4 && ix < 20 && iy < 20;
            let k = (py * 6 + px + 1) as u16;
            let c = cfa.channel_at(x as u32, y as u32);
            dv[y * w + x] = 64
                + if inside {
                    [10 * k, 20 * k, 5 * k + 3][c]
                } else {
                    2
                };
            lab[y * w + x] = if inside { k } else { 25 };
        }
    }
    let dng = dir.path().join("chart.dng");
    write_raw_dng(&dng, w as u32, h as u32, &dv, &cfa, 1023.0);
    let labels = dir.path().join("labels.png");
    write_png16_gray(&labels, w, h, &lab);
    let names = dir.path().join("names.txt");
    let mut nm: Vec<String> = (1..=24).map(|k| format!("mcc/patch{k:02}")).collect();
    nm.push("wall".into());
    std::fs::write(&names, nm.join("\n")).unwrap();
    let (l, n) = (labels.to_str().unwrap(), names.to_str().unwrap());
    let img = dng.to_str().unwrap();

    let (code, out, err) = camsim(&["measure", "mcc", img, "--labels", l, "--names", n]);
    assert_eq!(code, 0, "{err}");
    assert!(out.starts_with("patch,channel,mean_dv,stderr_dv,pixels\n"));
    assert!(out.contains("\n7,g,140.000000,0.000000,"), "{out}");
    assert_eq!(out.lines().count(), 1 + 72);

    let objs = (19..=24)
        .map(|k| format!("mcc/patch{k:02}"))
        .collect::<Vec<_>>()
        .join(",");
    let (code, out, err) = camsim(&[
        "measure",
        "profile",
        img,
        "--labels",
        l,
        "--names",
        n,
        "--objects",
        &objs,
    ]);
    assert_eq!(code, 0, "{err}");
    assert!(
        out.starts_with("position_px,profile_r,profile_g,profile_b,ratio_g_r\n"),
        "{out}"
    );
    // Inside every patch G/R = 2 exactly (no blur in this chart).
    assert!(out.contains("# mcc/patch21/g/r=2 ± 0 1"), "{out}");

    let (code, out, err) = camsim(&[
        "measure",
        "noise",
        img,
        "--conversion-gain",
        "0.17",
        "--regions",
        "50",
    ]);
    assert_eq!(code, 0, "{err}");
    assert_eq!(out.lines().filter(|l| !l.starts_with('#')).count(), 51);
    assert!(out.starts_with("x,y,w,h,verdict,mean_dv,std_dv\n"), "{out}");
    // The chart is noise-free: a region whose green pixels all hold one value
    // must be accepted with that mean (above black) and std 0 exactly; a region
    // straddling a patch edge mixes values ≥ 18 DV apart, beyond 3 Poisson σ
    // (≤ 1.9 DV at these levels, K = 0.17), and must be rejected.
    let mut accepted = 0;
    for l in out.lines().skip(1).filter(|l| !l.starts_with('#')) {
        let f: Vec<&str> = l.split(',').collect();
        let [x, y, rw, rh]: [usize; 4] = std::array::from_fn(|i| f[i].parse().unwrap());
        let mut vals = vec![];
        for yy in y..y + rh {
            for xx in x..x + rw {
                if cfa.channel_at(xx as u32, yy as u32) == 1 {
                    vals.push(dv[yy * w + xx] as f64 - 64.0);
                }
            }
        }
        let uniform = vals.iter().all(|&v| v == vals[0]);
        let (mean, std): (f64, f64) = (f[5].parse().unwrap(), f[6].parse().unwrap());
        if uniform {
            accepted += 1;
            assert_eq!(f[4], "Accepted", "{l}");
            assert!(
                (mean - vals[0]).abs() < 1e-4 && std == 0.0,
                "{l}: want {}",
                vals[0]
            );
        } else {
            assert_ne!(f[4], "Accepted", "{l}: mixes {vals:?}");
        }
    }
    assert!(accepted >= 5, "only {accepted} uniform regions drawn");
    assert!(
        out.contains(&format!("# noise/regions_accepted={accepted} ± "))
            || out.contains(&format!("# regions_accepted={accepted} ± ")),
        "{out}"
    );

    let (code, out, err) = camsim(&["measure", "ri", img, "--pixel-um", "1.4", "--bins", "5"]);
    assert_eq!(code, 0, "{err}");
    assert!(out.starts_with("field_height_mm,ri,stderr\n"), "{out}");
    // RI as documented (measure/ri.rs): green pixels binned by the distance of
    // their centres from the image centre into 5 equal annuli up to the corner
    // pixel; RI = annulus mean / centre-annulus mean; stderr = the annulus
    // means' standard errors (std/√n) propagated through the ratio. Computed
    // here from the chart's known values.
    let (cx, cy) = (w as f64 / 2.0, h as f64 / 2.0);
    let r_of = |x: usize, y: usize| (x as f64 + 0.5 - cx).hypot(y as f64 + 0.5 - cy);
    let r_max = r_of(0, 0) * (1.0 + 1e-9);
    let mut bins = vec![vec![]; 5];
    for y in 0..h {
        for x in 0..w {
            if cfa.channel_at(x as u32, y as u32) == 1 {
                let b = ((r_of(x, y) / r_max * 5.0) as usize).min(4);
                bins[b].push(dv[y * w + x] as f64 - 64.0);
            }
        }
    }
    let ms = |v: &Vec<f64>| {
        let m = v.iter().sum::<f64>() / v.len() as f64;
        let var = v.iter().map(|x| (x - m).powi(2)).sum::<f64>() / (v.len() - 1) as f64;
        (m, var.sqrt() / (v.len() as f64).sqrt() / m)
    };
    let (m0, se0) = ms(&bins[0]);
    let rows: Vec<Vec<f64>> = out
        .lines()
        .skip(1)
        .filter(|l| !l.starts_with('#'))
        .map(|l| l.split(',').map(|v| v.parse().unwrap()).collect())
        .collect();
    assert_eq!(rows.len(), 5, "{out}");
    for (i, row) in rows.iter().enumerate() {
        let (m, rel) = ms(&bins[i]);
        let ri = m / m0;
        let se = if i == 0 {
            ri * se0
        } else {
            ri * (rel * rel + se0 * se0).sqrt()
        };
        let fh = (i as f64 + 0.5) / 5.0 * r_max * 1.4e-3;
        // Printed with 6 decimals: 1e-6 absolute; the stderr within 1 %
        // (n vs n − 1 in the standard deviation: < 0.2 % with ≥ 300 pixels).
        assert!(
            (row[0] - fh).abs() < 1e-6,
            "bin {i}: field height {} vs {fh}",
            row[0]
        );
        assert!((row[1] - ri).abs() < 1e-6, "bin {i}: RI {} vs {ri}", row[1]);
        assert!(
            (row[2] - se).abs() < 0.01 * se + 1e-6,
            "bin {i}: stderr {} vs {se}",
            row[2]
        );
    }

    // A label map of the wrong size is an error naming it.
    let small = dir.path().join("small.png");
    write_png16_gray(&small, 4, 4, &[0; 16]);
    let (code, _, err) = camsim(&[
        "measure",
        "mcc",
        img,
        "--labels",
        small.to_str().unwrap(),
        "--names",
        n,
    ]);
    assert_eq!(code, 3);
    assert!(err.contains("small.png") && err.contains("4×4"), "{err}");
}

/// A raw capture written by the sensor's own DNG writer (black level 64 DV).
fn write_raw_dng(
    path: &std::path::Path,
    w: u32,
    h: u32,
    dv: &[u16],
    cfa: &camsim::image::CfaPattern,
    white_dv: f64,
) {
    let img = camsim::image::SensorImage::from_raw_dv(w, h, cfa, dv, 64.0, white_dv);
    camsim::sensor::output::write_dng(path, &img, &camsim::sensor::SensorConfig::generic())
        .unwrap();
}
