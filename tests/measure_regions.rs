//! MCC patch means and line profiles find their regions from object labels.

use camsim::image::CfaPattern;
use camsim::measure::mcc::{measured, patch_means};
use camsim::measure::plane::{Plane, channel_views};
use camsim::measure::profile::{ProfileOptions, profile};

/// A 6×4 chart of 20-px patches with 4-px gaps on a 160×112 Bayer mosaic.
/// Patch k has r = 10k, g = 20k, b = 5k + 3; a 1-px ring at each patch border
/// (inside the label) carries a blurred value 999 that erosion must exclude.
fn chart() -> (Plane, Vec<u32>, Vec<String>) {
    let (w, h) = (160usize, 112usize);
    let cfa = CfaPattern::bayer("rggb").unwrap();
    let mut names: Vec<String> = (1..=24).map(|k| format!("mcc/patch{k:02}")).collect();
    names.push("wall".into());
    let mut labels = vec![24u32; w * h];
    let mut data = vec![1.0; w * h];
    let mut chan = vec![0u8; w * h];
    for y in 0..h {
        for x in 0..w {
            let c = cfa.channel_at(x as u32, y as u32);
            chan[y * w + x] = c as u8;
            let (px, py) = ((x as i64 - 8) / 24, (y as i64 - 8) / 24);
            let (ix, iy) = ((x as i64 - 8) % 24, (y as i64 - 8) % 24);
            if x >= 8 && y >= 8 && px < 6 && py < 4 && ix < 20 && iy < 20 {
                let k = (py * 6 + px + 1) as f64;
                labels[y * w + x] = (py * 6 + px) as u32;
                let border = ix == 0 || iy == 0 || ix == 19 || iy == 19;
                data[y * w + x] = if border {
                    999.0
                } else {
                    [10.0 * k, 20.0 * k, 5.0 * k + 3.0][c]
                };
            }
        }
    }
    let mut p = Plane::new(w, h, data).unwrap();
    p.channel = chan;
    p.channel_names = cfa.channels;
    (p, labels, names)
}

#[test]
fn mcc_patch_means_from_labels_exclude_edges() {
    let (p, labels, names) = chart();
    let views = channel_views(&p, "y");
    let patches = patch_means(&views, &labels, &names, "mcc", 0.1).unwrap();
    assert_eq!(patches.len(), 24);
    for pa in &patches {
        let k = pa.number as f64;
        let want = [10.0 * k, 20.0 * k, 5.0 * k + 3.0];
        for (i, (c, m, se)) in pa.means.iter().enumerate() {
            assert_eq!(*m, want[i], "patch {} {c}", pa.number);
            assert_eq!(*se, 0.0);
        }
        // Erosion by round(0.1·20) = 2 px: a 16×16 core.
        assert_eq!((pa.rect.w, pa.rect.h), (16, 16));
    }
    let m = measured(&patches, "mcc");
    assert_eq!(m.figures.len(), 72);
    assert_eq!(m.figures[4].quantity, "patch02/g_mean");
    let e = patch_means(&views, &labels, &names, "mac", 0.1)
        .unwrap_err()
        .to_string();
    assert!(e.contains("did you mean 'mcc'"), "{e}");
}

#[test]
fn profile_through_achromatic_row_gives_channel_ratios() {
    let (p, labels, names) = chart();
    let views = channel_views(&p, "y");
    let objects: Vec<String> = (19..=24).map(|k| format!("mcc/patch{k:02}")).collect();
    let m = profile(
        &views,
        &labels,
        &names,
        &objects,
        &ProfileOptions::default(),
        "profile",
    )
    .unwrap();
    // Band: 4 rows through the row centre (y = 88…91), clear of the top and bottom borders.
    // The profile reads every labelled pixel in the band (no erosion), so in each band
    // row the 10 r (or g) pixels of a patch include exactly one border pixel (999).
    for o in &objects {
        let f = m
            .figures
            .iter()
            .find(|f| f.quantity == format!("{o}/g/r"))
            .unwrap();
        let k: f64 = o[9..].parse().unwrap();
        let (r_in, g_in) = (10.0 * k, 20.0 * k);
        let r_mean = (9.0 * r_in + 999.0) / 10.0;
        let g_mean = (9.0 * g_in + 999.0) / 10.0;
        assert!(
            (f.value - g_mean / r_mean).abs() < 1e-9,
            "{o}: {} vs {}",
            f.value,
            g_mean / r_mean
        );
    }
    assert!(m.curves.iter().any(|c| c.name == "ratio/g/r"));
    assert!(
        profile(
            &views,
            &labels,
            &names,
            &["mcc/patch99".into()],
            &ProfileOptions::default(),
            "p"
        )
        .is_err()
    );
}
