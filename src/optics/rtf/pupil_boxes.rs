//! The RTF camera's pupil sampling boxes, tabulated over film radius.
//!
//! `RtfCamera::sampling_box` bounds, for one film point, where on the pass
//! plane a ray can pass: the union of the pass regions' boxes at nine input
//! radii around the film radius, grown by margins. It costs nine
//! interpolations of the ellipse table per camera ray, which was over a third
//! of `fig07-lsf-mtf`'s run time. It depends on the film radius alone, so a
//! camera with elliptical pass regions tabulates it once: the film radii
//! `[0, R]` are cut into cells, and a cell's box covers the box of every film
//! radius in it (below). A film radius beyond the table gets the exact box.
//!
//! Why a cell's box covers the exact box of every radius ρ in the cell
//! `[a, b]`: the exact box probes input radii within `[ρ − δ(ρ), ρ + δ(ρ)]`
//! (clamped at 0), δ growing with ρ, so all its probes lie in
//! `[a − δ(b), b + δ(b)]`. The ellipse table is linear in the input radius
//! between its positions, so the union of the pass boxes over that whole
//! interval is found exactly from its ends and the positions inside it, and
//! contains the union over the probes. Its margins (2 % of its size plus
//! δ(b)) are at least the exact box's (2 % of a smaller size plus δ(ρ)).
//!
//! What it changes: a camera ray samples a box at most a cell's width of
//! slope larger than before, so the estimate stays unbiased (the box only
//! has to cover the pass region; the weight is its area) with a fraction of a
//! per cent more rays blocked; the rays drawn are not those of the exact box.

use super::Ellipses;

/// Cells of a table: the film radius step is the table's reach over this.
const CELLS: usize = 2048;

/// Sampling boxes `[x0, x1, y0, y1]` (mm, rotated frame) per film-radius cell.
#[derive(Clone, Debug)]
pub(super) struct PupilBoxes {
    /// Film radius step, mm.
    step: f64,
    /// Per cell: its box, or None when no input radius near it passes.
    boxes: Vec<Option<[f64; 4]>>,
}

impl PupilBoxes {
    /// The table for elliptical pass regions `e`, for a camera whose exact
    /// box at film radius ρ probes input radii ρ ± `delta(ρ)` (`delta`
    /// non-decreasing, ≥ 0). None when the table has no extent (no positions,
    /// a last position ≤ 0, or a non-finite margin), and the camera keeps
    /// the exact box.
    pub(super) fn new(e: &Ellipses, delta: impl Fn(f64) -> f64) -> Option<Self> {
        let last = *e.positions_mm.last()?;
        // Film radii up to the last input radius and a margin past it: beyond
        // it nearly every ray is blocked, and the exact box takes over.
        let reach = last + 2.0 * delta(last);
        if !(last > 0.0 && reach.is_finite()) {
            return None;
        }
        let step = reach / CELLS as f64;
        let boxes = (0..CELLS)
            .map(|k| {
                let (a, b) = (k as f64 * step, (k + 1) as f64 * step);
                let d = delta(b);
                let hull = union_over(e, (a - d).max(0.0), b + d)?;
                // The exact box's margins, and a part in 10⁹ more for the
                // rounding of sums taken in another order.
                let mx = 0.020_000_001 * (hull[1] - hull[0]) + d * (1.0 + 1e-9);
                let my = 0.020_000_001 * (hull[3] - hull[2]) + d * (1.0 + 1e-9);
                Some([hull[0] - mx, hull[1] + mx, hull[2] - my, hull[3] + my])
            })
            .collect();
        Some(PupilBoxes { step, boxes })
    }

    /// The box of film radius `r` (mm, ≥ 0); `Err(())` beyond the table.
    #[inline]
    pub(super) fn at(&self, r: f64) -> Result<Option<[f64; 4]>, ()> {
        // `as usize` saturates; a NaN radius lands in cell 0, and the camera
        // rejects its ray (its origin is not finite).
        let k = (r / self.step) as usize;
        self.boxes.get(k).copied().ok_or(())
    }
}

/// Union of the pass regions' boxes over input radii `[lo, hi]` (0 ≤ lo ≤ hi):
/// the table is linear between its positions (constant below the first), so
/// the extremes are at the interval's ends or at positions inside it.
fn union_over(e: &Ellipses, lo: f64, hi: f64) -> Option<[f64; 4]> {
    let mut b = [
        f64::INFINITY,
        f64::NEG_INFINITY,
        f64::INFINITY,
        f64::NEG_INFINITY,
    ];
    let inner = e.positions_mm.iter().copied().filter(|&p| p > lo && p < hi);
    for r in [lo, hi].into_iter().chain(inner) {
        if let Some([cx, cy, rx, ry]) = e.at(r) {
            b[0] = b[0].min(cx - rx);
            b[1] = b[1].max(cx + rx);
            b[2] = b[2].min(cy - ry);
            b[3] = b[3].max(cy + ry);
        }
    }
    b[0].is_finite().then_some(b)
}

#[cfg(test)]
mod tests {
    use super::super::{Ellipses, PassNoPass, Rtf, RtfCamera};
    use std::path::Path;

    /// `a` holds `b` (both `[x0, x1, y0, y1]`).
    fn holds(a: [f64; 4], b: [f64; 4]) -> bool {
        a[0] <= b[0] && a[1] >= b[1] && a[2] <= b[2] && a[3] >= b[3]
    }

    /// Every film radius's tabulated box holds its exact box (`sampling_box`),
    /// and has a box wherever the exact one does: on the shipped Pixel 4a
    /// tables at its four fig07 film distances, and on a table whose region
    /// moves fast and unevenly with the input radius; radii are drawn at
    /// random and on cell boundaries, where the two boxes come closest.
    #[test]
    fn a_cells_box_holds_the_exact_box_of_every_radius_in_it() {
        let shipped = Rtf::load(Path::new(
            "lenses/rtf/pixel4a-rearcamera-ellipse-raytransfer.json",
        ))
        .unwrap();
        let mut fast = shipped.clone();
        fast.waves[0].pass = PassNoPass::Ellipses(Ellipses {
            positions_mm: vec![0.0, 0.2, 0.25, 1.0, 3.0],
            radii_x_mm: vec![1.0, 0.3, 1.5, 0.2, 2.5],
            radii_y_mm: vec![0.5, 1.7, 0.2, 0.9, 1.1],
            centers_x_mm: vec![0.0, -0.5, 0.4, 0.6, -0.3],
            centers_y_mm: vec![1.0, -2.0, 2.0, 0.1, 4.0],
            plane_distance_mm: 2.0,
        });
        let mut rng = crate::render::sampling::Rng::for_sample(11, 0, 0);
        for (rtf, film_mm) in [
            (&shipped, 0.57624),
            (&shipped, 0.49234),
            (&shipped, 0.546975),
            (&shipped, 0.519816),
            (&fast, 0.6),
        ] {
            let cam = RtfCamera::new(rtf.clone(), film_mm).unwrap();
            let w = &cam.rtf.waves[0];
            let t = cam.boxes[0]
                .as_ref()
                .expect("elliptical regions are tabulated");
            let top = t.step * t.boxes.len() as f64;
            let (mut n, mut some) = (0, 0);
            for k in 0..20_000 {
                let r = if k % 2 == 0 {
                    rng.uniform() as f64 * top
                } else {
                    (k / 2 % t.boxes.len()) as f64 * t.step
                };
                let Ok(tab) = t.at(r) else {
                    panic!("r {r} < {top} is in the table")
                };
                if let Some(exact) = cam.sampling_box(w, r) {
                    let tab = tab.unwrap_or_else(|| panic!("r {r}: no tabulated box"));
                    assert!(holds(tab, exact), "r {r}: {tab:?} does not hold {exact:?}");
                    some += 1;
                }
                n += 1;
            }
            // The table reaches past the last pass region, so some radii
            // have no box at all.
            assert!(some > n / 4 && some < n, "{some} of {n} radii with a box");
            assert!(t.at(top * 1.01).is_err(), "beyond the table");
        }
    }

    /// A tabulated box is larger than the exact one by little: on the shipped
    /// tables its area is within 1 % of the exact box's (the sampling
    /// efficiency it costs), averaged over film radii with a box.
    #[test]
    fn tabulated_boxes_are_barely_larger() {
        let rtf = Rtf::load(Path::new(
            "lenses/rtf/pixel4a-rearcamera-ellipse-raytransfer.json",
        ))
        .unwrap();
        let cam = RtfCamera::new(rtf, 0.546975).unwrap();
        let w = &cam.rtf.waves[0];
        let t = cam.boxes[0].as_ref().unwrap();
        let area = |b: [f64; 4]| (b[1] - b[0]) * (b[3] - b[2]);
        let (mut sum, mut n) = (0.0, 0);
        for k in 0..4000 {
            let r = (k as f64 + 0.5) / 4000.0 * t.step * t.boxes.len() as f64;
            if let (Ok(Some(tab)), Some(exact)) = (t.at(r), cam.sampling_box(w, r)) {
                sum += area(tab) / area(exact);
                n += 1;
            }
        }
        let mean = sum / n as f64;
        assert!((1.0..1.01).contains(&mean), "mean area ratio {mean}");
    }
}
