//! The RTF camera's rays for several samples side by side
//! (`Camera::sample_rays`; issue 17: the RTF polynomial evaluation
//! vectorises across rays).
//!
//! One RTF camera ray is a chain of dependent steps — the film point's
//! sampling box, square roots and divisions to reach the input plane, the
//! pass test, the power tables, six polynomials of 35 terms each summed in
//! order, the output ray — so a core working on one ray at a time mostly
//! waits for the result of the step before. Here many rays go
//! through each step together: the scalar steps run sample after sample in a
//! loop (independent chains the core overlaps), and the polynomials of the
//! rays that pass the pass test (about half of a lens's pupil box) are
//! evaluated with eight rays in vector lanes (`FusedPolys::eval_lanes`), in a
//! copy of this code compiled for the widest instruction set the machine has.
//!
//! Same bits as `RtfCamera::sample_ray`: every lane calls the same steps
//! (`film_ray`, `rotate_in`, `rotate_out`, `camera_ray`) and the polynomial
//! lanes take the scalar evaluation's operations in its order; Rust never
//! fuses a multiply and an add, so the instruction set does not change a
//! bit. Samples of different wavelength tables, tables whose outputs do not
//! share their exponents, or of degree above 7 go one at a time.

// Lane loops index several per-lane arrays at once.
#![allow(clippy::needless_range_loop)]

use super::{FilmRay, InputRay, RtfCamera, SHORT_POWERS};
use crate::optics::{Camera, CameraRay};
use glam::DVec2;

/// Rays whose polynomials are evaluated side by side: eight f64 lanes, one
/// AVX-512 register (two AVX2 ones).
const LANES: usize = 8;

/// `Camera::sample_rays` of `cam`.
pub(super) fn sample_rays(
    cam: &RtfCamera,
    film_m: &[DVec2],
    u: &[DVec2],
    lambda_nm: &[f64],
    out: &mut [Option<CameraRay>],
) {
    #[cfg(target_arch = "x86_64")]
    {
        static LEVEL: std::sync::OnceLock<u8> = std::sync::OnceLock::new();
        let level = *LEVEL.get_or_init(|| {
            if std::arch::is_x86_feature_detected!("avx512f") {
                2
            } else if std::arch::is_x86_feature_detected!("avx2") {
                1
            } else {
                0
            }
        });
        match level {
            // SAFETY: the CPU has the features the copy is compiled for.
            2 => return unsafe { sample_rays_avx512(cam, film_m, u, lambda_nm, out) },
            // SAFETY: as above.
            1 => return unsafe { sample_rays_avx2(cam, film_m, u, lambda_nm, out) },
            _ => {}
        }
    }
    sample_rays_here(cam, film_m, u, lambda_nm, out)
}

#[cfg(target_arch = "x86_64")]
#[target_feature(enable = "avx512f")]
unsafe fn sample_rays_avx512(
    cam: &RtfCamera,
    film_m: &[DVec2],
    u: &[DVec2],
    lambda_nm: &[f64],
    out: &mut [Option<CameraRay>],
) {
    sample_rays_here(cam, film_m, u, lambda_nm, out)
}

#[cfg(target_arch = "x86_64")]
#[target_feature(enable = "avx2")]
unsafe fn sample_rays_avx2(
    cam: &RtfCamera,
    film_m: &[DVec2],
    u: &[DVec2],
    lambda_nm: &[f64],
    out: &mut [Option<CameraRay>],
) {
    sample_rays_here(cam, film_m, u, lambda_nm, out)
}

/// Samples taken through the scalar steps before their polynomials are
/// evaluated: enough that the rays that pass fill whole lane groups.
const CHUNK: usize = 64;

/// `CHUNK` samples at a time.
#[inline(always)]
fn sample_rays_here(
    cam: &RtfCamera,
    film_m: &[DVec2],
    u: &[DVec2],
    lambda_nm: &[f64],
    out: &mut [Option<CameraRay>],
) {
    let n = out.len();
    assert!(film_m.len() == n && u.len() == n && lambda_nm.len() == n);
    let mut i = 0;
    while i < n {
        let m = (n - i).min(CHUNK);
        let span = i..i + m;
        chunk(
            cam,
            &film_m[span.clone()],
            &u[span.clone()],
            &lambda_nm[span.clone()],
            &mut out[span],
        );
        i += m;
    }
}

/// At most `CHUNK` samples: the scalar steps sample after sample, then the
/// polynomials of the rays that pass, `LANES` of them side by side.
#[inline(always)]
fn chunk(
    cam: &RtfCamera,
    film_m: &[DVec2],
    u: &[DVec2],
    lambda_nm: &[f64],
    out: &mut [Option<CameraRay>],
) {
    let m = out.len();
    let wi = cam.rtf.wave_index(lambda_nm[0]);
    let one_table =
        cam.rtf.waves.len() == 1 || lambda_nm.iter().all(|&l| cam.rtf.wave_index(l) == wi);
    let plan = &cam.plans[wi];
    let fused = match &plan.fused {
        Some(f) if one_table && plan.powers <= SHORT_POWERS => f,
        _ => {
            for l in 0..m {
                out[l] = cam.sample_ray(film_m[l], u[l], lambda_nm[l]);
            }
            return;
        }
    };
    let w = &cam.rtf.waves[wi];
    // The steps up to the input plane's rotated ray; the rays that pass the
    // pass test, in order, with their samples' places.
    let mut fr: [Option<FilmRay>; CHUNK] = [None; CHUNK];
    let mut pass: [(usize, Option<InputRay>); CHUNK] = [(0, None); CHUNK];
    let mut np = 0;
    for l in 0..m {
        out[l] = None;
        fr[l] = cam.film_ray(wi, film_m[l], u[l]);
        if let Some(f) = &fr[l]
            && let Some(q) = cam.rtf.rotate_in(w, f.pin.x, f.pin.y, f.d)
        {
            pass[np] = (l, Some(q));
            np += 1;
        }
    }
    // Their polynomials, `LANES` rays side by side, and their output rays.
    for group in pass[..np].chunks(LANES) {
        let (mut r, mut dx, mut dy) = ([0f64; LANES], [0f64; LANES], [0f64; LANES]);
        for (k, (_, q)) in group.iter().enumerate() {
            if let Some(q) = q {
                (r[k], dx[k], dy[k]) = (q.r, q.dx, q.dy);
            }
        }
        let mut pr = [[1f64; LANES]; SHORT_POWERS];
        let mut px = [[1f64; LANES]; SHORT_POWERS];
        let mut py = [[1f64; LANES]; SHORT_POWERS];
        for i in 1..plan.powers {
            for k in 0..LANES {
                pr[i][k] = pr[i - 1][k] * r[k];
                px[i][k] = px[i - 1][k] * dx[k];
                py[i][k] = py[i - 1][k] * dy[k];
            }
        }
        let v = fused.eval_lanes(&pr, &px, &py);
        for (k, &(l, q)) in group.iter().enumerate() {
            if let (Some(f), Some(q)) = (&fr[l], &q) {
                let vals = [0, 1, 2, 3, 4, 5].map(|o| w.outputs[o].as_ref().map(|_| v[o][k]));
                out[l] = cam.camera_ray(f, cam.rtf.rotate_out(q, vals));
            }
        }
    }
}

#[cfg(test)]
mod tests {
    use super::super::{Rtf, RtfCamera};
    use crate::optics::Camera;
    use glam::DVec2;
    use std::path::Path;

    /// `sample_rays` gives `sample_ray`'s bits, ray for ray, on the shipped
    /// Pixel 4a tables: film points over and beyond the lens's field (so
    /// some rays pass, some are blocked and some film points have no
    /// sampling box), in batches of 1, 3, 8, 17 and 100 samples (whole and
    /// partly filled lane groups).
    #[test]
    fn side_by_side_rays_are_one_at_a_times() {
        let rtf = Rtf::load(Path::new(
            "lenses/rtf/pixel4a-rearcamera-ellipse-raytransfer.json",
        ))
        .unwrap();
        let cam = RtfCamera::new(rtf, 0.546975).unwrap();
        let mut rng = crate::render::sampling::Rng::for_sample(5, 0, 0);
        let mut uni = || rng.uniform() as f64;
        let (mut some, mut none, mut total) = (0, 0, 0);
        for n in [1, 3, 8, 17, 100] {
            for _ in 0..40 {
                let film: Vec<DVec2> = (0..n)
                    .map(|_| DVec2::new(uni() - 0.5, uni() - 0.5) * 9e-3)
                    .collect();
                let u: Vec<DVec2> = (0..n).map(|_| DVec2::new(uni(), uni())).collect();
                let lambda = vec![550.0; n];
                let mut out = vec![None; n];
                cam.sample_rays(&film, &u, &lambda, &mut out);
                for i in 0..n {
                    let one = cam.sample_ray(film[i], u[i], lambda[i]);
                    let bits = |r: Option<crate::optics::CameraRay>| {
                        r.map(|r| {
                            [
                                r.origin.x,
                                r.origin.y,
                                r.origin.z,
                                r.direction.x,
                                r.direction.y,
                                r.direction.z,
                                r.weight,
                            ]
                            .map(f64::to_bits)
                        })
                    };
                    assert_eq!(bits(out[i]), bits(one), "batch of {n}, sample {i}");
                    if one.is_some() {
                        some += 1
                    } else {
                        none += 1
                    }
                    total += 1;
                }
            }
        }
        assert!(
            some > total / 10 && none > total / 10,
            "{some} passed, {none} blocked"
        );
    }
}
