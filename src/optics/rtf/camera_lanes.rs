//! The RTF camera's rays for several samples side by side
//! (`Camera::sample_rays`; issue 17: the RTF polynomial evaluation
//! vectorises across rays).
//!
//! One RTF camera ray is a chain of dependent steps — the film point's
//! sampling box, square roots and divisions to reach the input plane, the
//! pass test, the power tables, six polynomials of 35 terms each summed in
//! order, the output ray — so a core working on one ray at a time mostly
//! waits for the result of the step before. Here many rays go through each
//! step together, with eight rays in the lanes of a vector, in a copy of this
//! code compiled for the widest instruction set the machine has:
//! - the steps up to the pass test (`front_lanes`: the arithmetic of
//!   `RtfCamera::film_ray` and `Rtf::rotate_in`, twelve divisions and three
//!   square roots a ray), with the table look-ups (sampling box, pass
//!   region at the input radius) lane by lane;
//! - the polynomials of the rays that pass (about half of a lens's pupil
//!   box), gathered into full lane groups (`FusedPolys::eval_lanes`);
//! - the output rays (`rotate_out`, `camera_ray`) sample after sample, as
//!   independent chains the core overlaps.
//!
//! Same bits as `RtfCamera::sample_ray`: every lane takes the scalar steps'
//! operations in their order (`front_lanes` restates `film_ray` and
//! `rotate_in` lane-wise; `tests` compare every ray's bits), and Rust never
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
    // The steps up to the input plane's rotated ray; the places of the
    // samples whose rays pass the pass test, in order.
    let mut fr: [Option<FilmRay>; CHUNK] = [None; CHUNK];
    let mut pass = [0usize; CHUNK];
    let mut rays: [Option<InputRay>; CHUNK] = [None; CHUNK];
    let mut l0 = 0;
    while l0 < m {
        let l1 = (l0 + LANES).min(m);
        front_lanes(
            cam,
            wi,
            &film_m[l0..l1],
            &u[l0..l1],
            &mut fr[l0..l1],
            &mut rays[l0..l1],
        );
        l0 = l1;
    }
    let mut np = 0;
    for l in 0..m {
        out[l] = None;
        if rays[l].is_some() {
            pass[np] = l;
            np += 1;
        }
    }
    // Their polynomials, `LANES` rays side by side, and their output rays.
    for group in pass[..np].chunks(LANES) {
        let (mut r, mut dx, mut dy) = ([0f64; LANES], [0f64; LANES], [0f64; LANES]);
        for (k, &l) in group.iter().enumerate() {
            if let Some(q) = &rays[l] {
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
        for (k, &l) in group.iter().enumerate() {
            if let (Some(f), Some(q)) = (&fr[l], &rays[l]) {
                let vals = [0, 1, 2, 3, 4, 5].map(|o| w.outputs[o].as_ref().map(|_| v[o][k]));
                out[l] = cam.camera_ray(f, cam.rtf.rotate_out(q, vals));
            }
        }
    }
}

/// `RtfCamera::film_ray` and then `Rtf::rotate_in` for at most `LANES`
/// samples of wavelength table `wi`, their arithmetic with the samples in
/// vector lanes (the divisions and square roots eight to an instruction).
/// Each lane takes the scalar steps' operations in their order, so `fr` and
/// `rays` are theirs bit for bit (`tests`); table look-ups (the sampling
/// box, the pass region at the input radius) stay lane by lane.
#[inline(always)]
fn front_lanes(
    cam: &RtfCamera,
    wi: usize,
    film_m: &[DVec2],
    u: &[DVec2],
    fr: &mut [Option<FilmRay>],
    rays: &mut [Option<InputRay>],
) {
    let m = fr.len();
    let w = &cam.rtf.waves[wi];
    let z_in = cam.input_plane_z_mm();
    let l_pass = w.pass.plane_distance_mm();
    let h = z_in + l_pass;
    fr.fill(None);
    rays.fill(None);
    if !(h > 0.0) {
        return;
    }
    type V = [f64; LANES];
    let (mut px, mut py, mut r) = ([0f64; LANES], [0f64; LANES], [0f64; LANES]);
    for l in 0..m {
        let p = -film_m[l] * 1e3;
        (px[l], py[l]) = (p.x, p.y);
    }
    for l in 0..LANES {
        r[l] = (px[l] * px[l] + py[l] * py[l]).sqrt();
    }
    // The sampling box, lane by lane (unit boxes in lanes without one).
    let mut b: [V; 4] = [[0.0; LANES], [1.0; LANES], [0.0; LANES], [1.0; LANES]];
    let mut boxed = [false; LANES];
    for l in 0..m {
        let bl = match cam.boxes[wi].as_ref().map(|t| t.at(r[l])) {
            Some(Ok(bl)) => bl,
            _ => cam.sampling_box(w, r[l]),
        };
        if let Some(bl) = bl {
            for (bk, v) in b.iter_mut().zip(bl) {
                bk[l] = v;
            }
            boxed[l] = true;
        }
    }
    // `film_ray`'s arithmetic.
    let (mut pin_x, mut pin_y, mut pin_z) = ([0f64; LANES], [0f64; LANES], [0f64; LANES]);
    let (mut dx, mut dy, mut dz, mut weight) =
        ([0f64; LANES], [0f64; LANES], [1f64; LANES], [0f64; LANES]);
    for l in 0..LANES {
        let pos = r[l] > 0.0;
        let (s, c) = (
            if pos { px[l] / r[l] } else { 0.0 },
            if pos { py[l] / r[l] } else { 1.0 },
        );
        let (ux, uy) = if l < m { (u[l].x, u[l].y) } else { (0.5, 0.5) };
        let qx = b[0][l] + ux * (b[1][l] - b[0][l]);
        let qy = b[2][l] + uy * (b[3][l] - b[2][l]);
        let (qrx, qry) = (qx * c + qy * s, -qx * s + qy * c);
        let (vx, vy, vz) = (qrx - px[l], qry - py[l], h - 0.0);
        let dist2 = vx * vx + vy * vy + vz * vz;
        weight[l] = (b[1][l] - b[0][l]) * (b[3][l] - b[2][l]) * h * h / (dist2 * dist2);
        let len = dist2.sqrt();
        (dx[l], dy[l], dz[l]) = (vx / len, vy / len, vz / len);
        let t = z_in / dz[l];
        (pin_x[l], pin_y[l], pin_z[l]) = (px[l] + dx[l] * t, py[l] + dy[l] * t, 0.0 + dz[l] * t);
    }
    // `rotate_in`'s arithmetic, up to the pass test.
    let (mut ri, mut si, mut ci, mut rdx, mut rdy) = (
        [0f64; LANES],
        [0f64; LANES],
        [1f64; LANES],
        [0f64; LANES],
        [0f64; LANES],
    );
    let (mut xp, mut yp) = ([0f64; LANES], [0f64; LANES]);
    for l in 0..LANES {
        let (x, y) = (pin_x[l], pin_y[l]);
        ri[l] = (x * x + y * y).sqrt();
        let pos = ri[l] > 0.0;
        (si[l], ci[l]) = (
            if pos { x / ri[l] } else { 0.0 },
            if pos { y / ri[l] } else { 1.0 },
        );
        rdx[l] = dx[l] * ci[l] - dy[l] * si[l];
        rdy[l] = dx[l] * si[l] + dy[l] * ci[l];
        xp[l] = rdx[l] / dz[l] * l_pass;
        yp[l] = ri[l] + rdy[l] / dz[l] * l_pass;
    }
    // The pass test: the region at each lane's input radius, then the test.
    let mut passed = [false; LANES];
    match &w.pass {
        super::PassNoPass::Ellipses(e) => {
            let mut ell: [V; 4] = [[0.0; LANES], [0.0; LANES], [1.0; LANES], [1.0; LANES]];
            let mut has = [false; LANES];
            for l in 0..m {
                if let Some(q) = e.at(ri[l]) {
                    for (ek, v) in ell.iter_mut().zip(q) {
                        ek[l] = v;
                    }
                    has[l] = true;
                }
            }
            for l in 0..LANES {
                let a = ((xp[l] - ell[0][l]) / ell[2][l]).powi(2);
                let c = ((yp[l] - ell[1][l]) / ell[3][l]).powi(2);
                passed[l] = has[l] && a + c <= 1.0;
            }
        }
        pass => {
            for l in 0..m {
                passed[l] = pass.passes(ri[l], xp[l], yp[l]);
            }
        }
    }
    for l in 0..m {
        if !boxed[l] {
            continue;
        }
        let d = glam::DVec3::new(dx[l], dy[l], dz[l]);
        fr[l] = Some(FilmRay {
            pin: glam::DVec3::new(pin_x[l], pin_y[l], pin_z[l]),
            d,
            weight: weight[l],
        });
        if d.z > 0.0 && passed[l] {
            rays[l] = Some(InputRay {
                r: ri[l],
                s: si[l],
                c: ci[l],
                dx: rdx[l],
                dy: rdy[l],
            });
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
