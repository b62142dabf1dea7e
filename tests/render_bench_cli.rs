//! `camsim bench render` as a user runs it, without Mitsuba.

use std::process::Command;

fn camsim() -> Command {
    Command::new(env!("CARGO_BIN_EXE_camsim"))
}

/// `camsim bench render --spp 1 --bvh bvh4` plus the caller's options.
fn bench_1spp() -> Command {
    let mut c = camsim();
    c.args(["bench", "render", "--spp", "1", "--bvh", "bvh4"]);
    c
}

/// The standard output of `c`, which must succeed (else its output is shown).
fn stdout_of_success(c: &mut Command) -> String {
    let out = c.output().unwrap();
    let stdout = String::from_utf8_lossy(&out.stdout).into_owned();
    assert!(
        out.status.success(),
        "{stdout}{}",
        String::from_utf8_lossy(&out.stderr)
    );
    stdout
}

/// The bench's 256×256 CIE Y image written to `p`.
fn read_bench_y(p: &std::path::Path) -> Vec<f32> {
    let (w, h, d) = camsim::render::bench::read_pfm(p).unwrap();
    assert_eq!((w, h), (256, 256));
    d
}

fn read_pfm_mean(p: &std::path::Path) -> f64 {
    let d = read_bench_y(p);
    d.iter().map(|&x| x as f64).sum::<f64>() / d.len() as f64
}

#[test]
fn bench_scene_mean_luminance_matches_mitsuba() {
    // Mitsuba 3.9.1 llvm_ad_spectral, cornell_box() at 256², max_depth 7, box
    // filter, 1024 spp (bench/mitsuba_compare.sh): mean CIE Y = 0.15380, its
    // own noise < 0.05 %. camsim at 1 spp: per-pixel relative noise ≈ 110 %,
    // so the image mean has σ ≈ 110 %/√65536 ≈ 0.45 %; 2 % is > 4σ and still
    // catches a wrong spectrum, emitter scale, camera or bounce count.
    let dir = tempfile::tempdir().unwrap();
    let y = dir.path().join("y.pfm");
    let stdout = stdout_of_success(
        bench_1spp()
            .args(["--ref-spp", "0", "--threads", "2", "--y-out"])
            .arg(&y),
    );
    assert!(stdout.contains("camsim-bench spp=1 "), "{stdout}");
    // the machine beside the speed (issue 17): "cpu: MODEL (VECTOR WIDTH)"
    let cpu = format!("cpu: {}", camsim::machine::cpu());
    assert!(stdout.lines().any(|l| l == cpu), "{cpu} not in {stdout}");
    // and the render kernel's instruction set level (issue 17 item 2)
    let isa = camsim::render::simd::RenderIsa::detect().name();
    assert!(
        stdout.lines().any(|l| l == format!("render kernel: {isa}"))
            && stdout.contains(&format!(" render_isa={isa}")),
        "{isa} not in {stdout}"
    );
    let m = read_pfm_mean(&y);
    assert!((m / 0.15380 - 1.0).abs() < 0.02, "mean Y {m}");

    // The same image as a reference: RMSE 0, reported on the machine line.
    let out = bench_1spp().arg("--reference").arg(&y).output().unwrap();
    let stdout = String::from_utf8_lossy(&out.stdout);
    assert!(out.status.success(), "{stdout}");
    assert!(stdout.contains(" rmse_y=0.000000e0 "), "{stdout}");
}

/// `--max-bounces 0` reaches the renderer: only the emitter, seen directly,
/// is left. At 1 spp each pixel's one sample sees the uniform light (the same
/// Y in every such pixel) or nothing lit (Y = 0); the default 6 bounces light
/// every wall.
#[test]
fn bench_max_bounces_reaches_the_render() {
    let dir = tempfile::tempdir().unwrap();
    let y = dir.path().join("y.pfm");
    let stdout = stdout_of_success(
        bench_1spp()
            .args(["--ref-spp", "0", "--max-bounces", "0", "--y-out"])
            .arg(&y),
    );
    assert!(stdout.contains(" max_bounces=0"), "{stdout}");
    assert!(
        stdout.contains("max_bounces 0 (Mitsuba max_depth 1)"),
        "{stdout}"
    );
    let d = read_bench_y(&y);
    let lit: Vec<f32> = d.iter().copied().filter(|&v| v != 0.0).collect();
    // The light covers a few per cent of the image.
    assert!(
        !lit.is_empty() && lit.len() < d.len() / 20,
        "{} lit pixels",
        lit.len()
    );
    assert!(lit.iter().all(|&v| v == lit[0]), "more than one lit value");
}

#[test]
fn bench_render_rejects_bad_options_with_named_files() {
    let dir = tempfile::tempdir().unwrap();
    let small = dir.path().join("small.pfm");
    camsim::render::bench::write_pfm(&small, 2, 1, &[0.0, 1.0]).unwrap();
    let out = bench_1spp()
        .arg("--reference")
        .arg(&small)
        .output()
        .unwrap();
    assert!(!out.status.success());
    let err = String::from_utf8_lossy(&out.stderr);
    assert!(err.contains("small.pfm") && err.contains("2×1"), "{err}");

    let out = camsim()
        .args(["bench", "render", "--spp", "1", "--bvh", "octree"])
        .output()
        .unwrap();
    assert!(!out.status.success());
    assert!(String::from_utf8_lossy(&out.stderr).contains("--bvh 'octree'"));

    // No bands is an error, not one band.
    let out = bench_1spp().args(["--bands", "0"]).output().unwrap();
    assert!(!out.status.success());
    let err = String::from_utf8_lossy(&out.stderr);
    assert!(err.contains("--bands 0"), "{err}");
}

/// `CAMSIM_RENDER_ISA` lowers the render kernel's level (sse runs on every
/// x86-64) and an unknown value is ignored with a warning naming the choices.
#[test]
fn render_isa_environment_variable_lowers_the_kernel() {
    let out = bench_1spp()
        .args(["--ref-spp", "0", "--threads", "2"])
        .env("CAMSIM_RENDER_ISA", "sse")
        .output()
        .unwrap();
    let stdout = String::from_utf8_lossy(&out.stdout);
    assert!(out.status.success(), "{stdout}");
    assert!(stdout.contains("render kernel: sse\n"), "{stdout}");
    assert!(stdout.contains(" render_isa=sse"), "{stdout}");

    let out = bench_1spp()
        .args(["--ref-spp", "0", "--threads", "2"])
        .env("CAMSIM_RENDER_ISA", "avx1024")
        .output()
        .unwrap();
    assert!(out.status.success());
    let err = String::from_utf8_lossy(&out.stderr);
    assert!(
        err.contains("CAMSIM_RENDER_ISA=\"avx1024\" ignored (expected sse, avx2 or avx512)"),
        "{err}"
    );
    let isa = camsim::render::simd::RenderIsa::detect().name();
    assert!(String::from_utf8_lossy(&out.stdout).contains(&format!("render kernel: {isa}\n")));
}

/// `camsim bench sensor --threads N` runs on N threads and says so (the flag
/// was once ignored: the bench ran on every core while its report divided the
/// CPU time by that count). With one thread, CPU time cannot exceed wall time
/// by more than the clock's resolution (10 ms ticks) — two threads would
/// give about twice the wall time.
#[test]
fn bench_sensor_honours_threads() {
    let stdout = stdout_of_success(camsim().args(["bench", "sensor", "--threads", "1"]));
    let value = |q: &str| -> String {
        stdout
            .lines()
            .find_map(|l| l.strip_prefix(&format!("sensor,{q},")))
            .and_then(|rest| rest.split(',').nth(1))
            .unwrap_or_else(|| panic!("no {q} in:\n{stdout}"))
            .to_string()
    };
    assert_eq!(value("threads"), "1");
    let wall: f64 = value("simulate_time_best_of_5").parse().unwrap();
    if let Ok(cpu) = value("simulate_cpu_time").parse::<f64>() {
        assert!(
            cpu <= wall * 1.2 + 0.02,
            "cpu {cpu} s over wall {wall} s on one thread"
        );
    }
}
