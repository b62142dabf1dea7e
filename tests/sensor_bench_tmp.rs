use camsim::optical_image::{OpticalImage, Rect};
use camsim::sensor::*;
use camsim::spectrum::WavelengthGrid;
#[test]
#[ignore]
fn parts() {
    let mut cfg = SensorConfig::load(std::path::Path::new("sensors/imx363.kdl")).unwrap();
    cfg.exposure = Exposure::Seconds(0.01);
    let (w, h) = (4032u32, 3024u32);
    let mut oi = OpticalImage::new(
        w,
        h,
        Rect::new(0, 0, w, h),
        1.4e-6,
        WavelengthGrid::default(),
    );
    for (i, v) in oi.irradiance.iter_mut().enumerate() {
        *v = 0.05 * ((i % 997) as f32 / 997.0);
    }
    for (name, s) in [
        ("none", Sources::none()),
        ("photon", {
            let mut s = Sources::none();
            s.photon_noise = true;
            s
        }),
        ("fpn", {
            let mut s = Sources::none();
            s.prnu = true;
            s
        }),
        ("read", {
            let mut s = Sources::none();
            s.read_noise = true;
            s
        }),
        ("all", Sources::all()),
    ] {
        cfg.sources = s;
        let t0 = std::time::Instant::now();
        let im = simulate(&cfg, &oi, 1).unwrap();
        println!("{name}: {:.3}s", t0.elapsed().as_secs_f64());
        std::hint::black_box(im);
    }
}
#[test]
#[ignore]
fn micro() {
    use camsim::sensor::rng::PixelRng;
    let n = 4_000_000u64;
    for &mu in &[5.0, 50.0, 1000.0] {
        let t0 = std::time::Instant::now();
        let mut s = 0.0;
        for i in 0..n {
            s += PixelRng::new(1, 1, i).poisson(mu);
        }
        println!(
            "poisson({mu}): {:.1} ns  {s}",
            t0.elapsed().as_secs_f64() * 1e9 / n as f64
        );
    }
    let t0 = std::time::Instant::now();
    let mut s = 0.0;
    for i in 0..n {
        let mut r = PixelRng::new(1, 1, i);
        s += r.normal() + r.normal();
    }
    println!(
        "2 normals: {:.1} ns {s}",
        t0.elapsed().as_secs_f64() * 1e9 / n as f64
    );
    let t0 = std::time::Instant::now();
    let mut s = 0u64;
    for i in 0..n {
        s ^= PixelRng::new(1, 1, i).next_u64();
    }
    println!(
        "new+u64: {:.1} ns {s}",
        t0.elapsed().as_secs_f64() * 1e9 / n as f64
    );
}
#[test]
#[ignore]
fn cpu_parts() {
    use camsim::sensor::bench::process_cpu_s;
    let mut cfg = SensorConfig::load(std::path::Path::new("sensors/imx363.kdl")).unwrap();
    cfg.exposure = Exposure::Seconds(0.01);
    let (w, h) = (4032u32, 3024u32);
    let mut oi = OpticalImage::new(
        w,
        h,
        Rect::new(0, 0, w, h),
        1.4e-6,
        WavelengthGrid::default(),
    );
    for (i, v) in oi.irradiance.iter_mut().enumerate() {
        *v = 0.0005 * ((i % 997) as f32 / 997.0);
    }
    for (name, s) in [
        ("none", Sources::none()),
        ("photon", {
            let mut s = Sources::none();
            s.photon_noise = true;
            s
        }),
        ("fpn", {
            let mut s = Sources::none();
            s.prnu = true;
            s
        }),
        ("read", {
            let mut s = Sources::none();
            s.read_noise = true;
            s
        }),
        ("all", Sources::all()),
    ] {
        cfg.sources = s;
        let c0 = process_cpu_s().unwrap();
        let t0 = std::time::Instant::now();
        let im = simulate(&cfg, &oi, 1).unwrap();
        println!(
            "{name}: wall {:.3}s cpu {:.3}s",
            t0.elapsed().as_secs_f64(),
            process_cpu_s().unwrap() - c0
        );
        std::hint::black_box(im);
    }
}
#[test]
#[ignore]
fn dark_mean_seeds() {
    let cfg = SensorConfig::load(std::path::Path::new("sensors/imx363.kdl")).unwrap();
    let g = WavelengthGrid::new(400.0, 700.0, 10.0).unwrap();
    let mut c = cfg.clone();
    c.exposure = Exposure::Seconds(0.0);
    let mut all = vec![];
    for s in 0..20 {
        let f = simulate_flat(
            &c,
            &camsim::spectrum::Spectrum::constant("z", 0.0),
            &g,
            Rect::new(1888, 1384, 256, 256),
            7000 + s,
        )
        .unwrap();
        let m = f.image.dv.iter().map(|&v| v as f64).sum::<f64>() / f.image.dv.len() as f64;
        all.push(m);
    }
    let mm = all.iter().sum::<f64>() / all.len() as f64;
    println!("dark means {:?} overall {mm}", &all[..5]);
}
