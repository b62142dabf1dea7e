//! The geometry sanity check: camsim's label buffer against POV-Ray's flat
//! label render of the same scene and pinhole-equivalent camera, compared
//! object by object with the intersection over union (IoU).
//!
//! - camsim side: `render::render` at 1 spp with `max_bounces` 0 (the label
//!   pass the experiment runner uses to find objects): each pixel's label is
//!   the object hit by the chief ray through the pixel centre.
//! - POV-Ray side: `export::labels_to_pov` rendered without antialiasing (one
//!   ray through each pixel centre), each pixel decoded back to a label.
//! - Per object: pixels_camsim = |A|, pixels_povray = |B|, IoU = |A∩B| / |A∪B|.
//!   An object *counts* when it covers more than `MIN_PIXELS` pixels in
//!   either image; the check fails when a counting object's IoU is below the
//!   threshold (default `DEFAULT_MIN_IOU`).
//!
//! Both renderers sample the same pixel centres through the same rays, so
//! they differ only where a pixel centre falls within float rounding of a
//! silhouette (camsim intersects in f32): an object of n pixels with a
//! perimeter of p pixels agrees to IoU ≳ 1 − (a few ·10⁻³)·p/n, well above
//! 0.98 for anything over 100 pixels. A misplaced, mirrored or mis-scaled
//! object, or a camera with the wrong field of view or handedness, moves
//! whole silhouettes and drops the IoU far below.
//!
//! Entry points: `check(scene, camera, film, width, height)` (camsim's labels
//! through `camera` itself) and `check_as_pinhole` (through camsim's pinhole
//! with `camera`'s field of view: for real lenses, whose distortion is not a
//! geometry error).

use super::camera::PinholeEquivalent;
use super::export::{label_colour, label_of_colour, labels_to_pov};
use crate::optics::Camera;
use crate::render::RenderSettings;
use crate::scene::{FilmSpec, NO_OBJECT, Scene};
use crate::spectrum::WavelengthGrid;
use crate::{Error, Result};
use std::path::Path;

/// Objects covering at most this many pixels (in both images) do not count.
pub const MIN_PIXELS: u64 = 100;
/// Default IoU threshold.
pub const DEFAULT_MIN_IOU: f64 = 0.98;
/// Label of a POV-Ray pixel whose colour is no object's label colour.
pub const UNKNOWN: u32 = u32::MAX - 1;

/// A per-pixel object label image, row 0 at the top; `NO_OBJECT` where
/// nothing was hit.
#[derive(Clone, Debug, PartialEq)]
pub struct LabelImage {
    pub width: u32,
    pub height: u32,
    pub labels: Vec<u32>,
}

/// One line of `iou.csv`.
#[derive(Clone, Debug, PartialEq)]
pub struct IouRow {
    pub object: String,
    pub pixels_camsim: u64,
    pub pixels_povray: u64,
    pub iou: f64,
}

impl IouRow {
    /// Larger than `MIN_PIXELS` in either renderer.
    pub fn counts(&self) -> bool {
        self.pixels_camsim.max(self.pixels_povray) > MIN_PIXELS
    }
}

/// The result of one check.
#[derive(Clone, Debug)]
pub struct Sanity {
    /// Objects seen by either renderer, in scene order.
    pub rows: Vec<IouRow>,
    pub camsim: LabelImage,
    pub povray: LabelImage,
    /// The camera POV-Ray was given.
    pub camera: PinholeEquivalent,
    /// The POV-Ray scene text that was rendered.
    pub pov_text: String,
}

/// The film of a `width` × `height` check image covering the physical width
/// of `film` (pitch scaled; the height follows `height`).
pub fn check_film(film: &FilmSpec, width: u32, height: u32) -> Result<FilmSpec> {
    if width == 0 || height == 0 {
        return Err(Error::invalid(format!(
            "sanity image size {width}×{height} is empty"
        )));
    }
    let pitch = film.width_px as f64 * film.pixel_pitch_m / width as f64;
    if !(pitch > 0.0 && pitch.is_finite()) {
        return Err(Error::invalid(format!(
            "film {}×{} px with pitch {} m has no area",
            film.width_px, film.height_px, film.pixel_pitch_m
        )));
    }
    Ok(FilmSpec {
        width_px: width,
        height_px: height,
        pixel_pitch_m: pitch,
        crop_window: None,
    })
}

/// camsim's label buffer of `scene` through `camera` on `film` (the label
/// pass: 1 spp, no bounces, one wavelength).
pub fn camsim_labels(scene: &Scene, camera: &dyn Camera, film: &FilmSpec) -> Result<LabelImage> {
    let settings = RenderSettings {
        spp: 1,
        max_bounces: 0,
        batches: 1,
        grid: WavelengthGrid::new(550.0, 550.0, 10.0).map_err(Error::invalid)?,
        ..Default::default()
    };
    let img = crate::render::render(scene, camera, film, &settings)?;
    Ok(LabelImage {
        width: film.width_px,
        height: film.height_px,
        labels: img.labels,
    })
}

/// POV-Ray's label image of `scene` through `camera`, and the scene text.
pub fn povray_labels(
    scene: &Scene,
    camera: &PinholeEquivalent,
    width: u32,
    height: u32,
) -> Result<(LabelImage, String)> {
    let text = labels_to_pov(scene, camera)?;
    let png = super::povray::render_png(&text, width, height, super::povray::Mode::Labels)?;
    let (w, h, px) = super::povray::decode_rgb8(&png, Path::new("povray output"))?;
    if (w, h) != (width, height) {
        return Err(Error::invalid(format!(
            "povray wrote a {w}×{h} image, {width}×{height} was asked for"
        )));
    }
    let n = scene.objects.len();
    let labels = px
        .iter()
        .map(|&c| {
            if c == [0, 0, 0] {
                NO_OBJECT
            } else {
                label_of_colour(c, n).unwrap_or(UNKNOWN)
            }
        })
        .collect();
    Ok((
        LabelImage {
            width,
            height,
            labels,
        },
        text,
    ))
}

/// Per-object IoU of two label images of the same size, objects named by
/// `names` (label id = index), in name order; objects in neither image are
/// left out.
pub fn compare(names: &[String], camsim: &LabelImage, povray: &LabelImage) -> Result<Vec<IouRow>> {
    if (camsim.width, camsim.height) != (povray.width, povray.height)
        || camsim.labels.len() != povray.labels.len()
    {
        return Err(Error::invalid(format!(
            "label images differ in size: {}×{} and {}×{}",
            camsim.width, camsim.height, povray.width, povray.height
        )));
    }
    let n = names.len();
    let (mut a, mut b, mut both) = (vec![0u64; n], vec![0u64; n], vec![0u64; n]);
    for (&x, &y) in camsim.labels.iter().zip(&povray.labels) {
        if (x as usize) < n {
            a[x as usize] += 1;
        }
        if (y as usize) < n {
            b[y as usize] += 1;
        }
        if x == y && (x as usize) < n {
            both[x as usize] += 1;
        }
    }
    Ok((0..n)
        .filter(|&i| a[i] + b[i] > 0)
        .map(|i| IouRow {
            object: names[i].clone(),
            pixels_camsim: a[i],
            pixels_povray: b[i],
            iou: both[i] as f64 / (a[i] + b[i] - both[i]) as f64,
        })
        .collect())
}

/// The check image's film (`width` × `height` over `film`'s width) and the
/// pinhole equivalent of `camera` posed by the scene's camera on it.
fn equivalent(
    scene: &Scene,
    camera: &dyn Camera,
    film: &FilmSpec,
    width: u32,
    height: u32,
) -> Result<(FilmSpec, PinholeEquivalent)> {
    let spec = scene
        .camera
        .as_ref()
        .ok_or_else(|| Error::invalid("the scene has no camera; the POV-Ray check needs one"))?;
    let small = check_film(film, width, height)?;
    let eq = PinholeEquivalent::of_camera(spec.to_world, camera, &small)?;
    Ok((small, eq))
}

/// Run the check: camsim's labels of `scene` through `camera` (posed by the
/// scene's camera, on a `width` × `height` image covering `film`'s physical
/// width) against POV-Ray's render of the same scene through the camera's
/// pinhole equivalent. Needs `povray` (an error naming the package otherwise).
pub fn check(
    scene: &Scene,
    camera: &dyn Camera,
    film: &FilmSpec,
    width: u32,
    height: u32,
) -> Result<Sanity> {
    let (small, pinhole) = equivalent(scene, camera, film, width, height)?;
    check_with(scene, scene, camera, &pinhole, &small)
}

/// `check` for a camera that is not a pinhole: a real lens distorts (the
/// Pixel 4a RTF by ~1.8 % from centre to corner) and vignettes, which moves
/// silhouettes by pixels and fails the IoU for reasons that are not geometry.
/// Here camsim renders its labels through its own `Pinhole` with the field of
/// view of `camera`'s pinhole equivalent (centre of projection at the camera
/// origin), so the check covers the scene, the pose and camsim's renderer and
/// pinhole, not the lens.
pub fn check_as_pinhole(
    scene: &Scene,
    camera: &dyn Camera,
    film: &FilmSpec,
    width: u32,
    height: u32,
) -> Result<Sanity> {
    let (small, eq) = equivalent(scene, camera, film, width, height)?;
    let pinhole = crate::optics::pinhole::Pinhole::new(eq.fov_short_deg(), 2.0, &small)?;
    let pov = PinholeEquivalent::of_camera(eq.to_world, &pinhole, &small)?;
    check_with(scene, scene, &pinhole, &pov, &small)
}

/// `check` with the POV-Ray side given separately: `pov_scene` through
/// `pinhole` against camsim's `scene` through `camera` on `film` (the check
/// film). Tests use it to feed POV-Ray a deliberately wrong scene or camera;
/// both scenes must share their object list.
pub fn check_with(
    scene: &Scene,
    pov_scene: &Scene,
    camera: &dyn Camera,
    pinhole: &PinholeEquivalent,
    film: &FilmSpec,
) -> Result<Sanity> {
    if scene.objects != pov_scene.objects {
        return Err(Error::invalid(
            "the two scenes of a sanity check must share their object labels",
        ));
    }
    // camsim first: its scene validation gives the clearer errors.
    let camsim = camsim_labels(scene, camera, film)?;
    let (povray, pov_text) = povray_labels(pov_scene, pinhole, film.width_px, film.height_px)?;
    let names: Vec<String> = scene.objects.iter().map(|o| o.name.clone()).collect();
    let rows = compare(&names, &camsim, &povray)?;
    Ok(Sanity {
        rows,
        camsim,
        povray,
        camera: pinhole.clone(),
        pov_text,
    })
}

impl Sanity {
    /// The counting object (> `MIN_PIXELS`) with the lowest IoU.
    pub fn min_iou(&self) -> Option<&IouRow> {
        self.rows
            .iter()
            .filter(|r| r.counts())
            .min_by(|a, b| a.iou.total_cmp(&b.iou))
    }

    /// Counting objects with IoU below `min_iou`.
    pub fn failures(&self, min_iou: f64) -> Vec<&IouRow> {
        self.rows
            .iter()
            .filter(|r| r.counts() && r.iou < min_iou)
            .collect()
    }

    /// `iou.csv`: `object,pixels_camsim,pixels_povray,iou`.
    pub fn csv(&self) -> Result<String> {
        let mut w = csv::Writer::from_writer(Vec::new());
        let e = |e: csv::Error| Error::invalid(format!("iou.csv: {e}"));
        w.write_record(["object", "pixels_camsim", "pixels_povray", "iou"])
            .map_err(e)?;
        for r in &self.rows {
            w.write_record([
                r.object.clone(),
                r.pixels_camsim.to_string(),
                r.pixels_povray.to_string(),
                format!("{:.6}", r.iou),
            ])
            .map_err(e)?;
        }
        let bytes = w
            .into_inner()
            .map_err(|e| Error::invalid(format!("iou.csv: {e}")))?;
        String::from_utf8(bytes).map_err(|e| Error::invalid(format!("iou.csv: {e}")))
    }

    /// The side-by-side PNG: camsim labels | POV-Ray labels | disagreement
    /// (agreeing pixels dimmed to a quarter, disagreeing pixels white), 4 grey
    /// pixels between panels. Each label has the same colour in both panels.
    pub fn side_by_side_png(&self) -> Result<Vec<u8>> {
        let (w, h) = (self.camsim.width as usize, self.camsim.height as usize);
        let gap = 4usize;
        let tw = 3 * w + 2 * gap;
        let mut rgb = vec![128u8; tw * h * 3];
        for y in 0..h {
            for x in 0..w {
                let i = y * w + x;
                let (a, b) = (self.camsim.labels[i], self.povray.labels[i]);
                let d = if a == b {
                    palette(a).map(|c| c / 4)
                } else {
                    [255, 255, 255]
                };
                for (panel, c) in [palette(a), palette(b), d].into_iter().enumerate() {
                    let o = (y * tw + panel * (w + gap) + x) * 3;
                    rgb[o..o + 3].copy_from_slice(&c);
                }
            }
        }
        let mut out = Vec::new();
        {
            let mut enc = png::Encoder::new(&mut out, tw as u32, h as u32);
            enc.set_color(png::ColorType::Rgb);
            enc.set_depth(png::BitDepth::Eight);
            let e = |e: png::EncodingError| Error::invalid(format!("side-by-side.png: {e}"));
            let mut wr = enc.write_header().map_err(e)?;
            wr.write_image_data(&rgb).map_err(e)?;
            wr.finish().map_err(e)?;
        }
        Ok(out)
    }
}

/// Display colour of a label: black for no object, magenta for an unknown
/// POV-Ray colour, otherwise a hue stepped by the golden ratio per label.
fn palette(label: u32) -> [u8; 3] {
    if label == NO_OBJECT {
        return [0, 0, 0];
    }
    if label == UNKNOWN || label_colour(label).is_none() {
        return [255, 0, 255];
    }
    let hue = (label as f64 * 0.618_033_988_749_895).fract() * 6.0;
    let (s, v) = (0.6, 0.9 - 0.25 * ((label / 7) % 2) as f64);
    let f = hue.fract();
    let (p, q, t) = (v * (1.0 - s), v * (1.0 - s * f), v * (1.0 - s * (1.0 - f)));
    let c = match hue as u32 {
        0 => [v, t, p],
        1 => [q, v, p],
        2 => [p, v, t],
        3 => [p, q, v],
        4 => [t, p, v],
        _ => [v, p, q],
    };
    c.map(|x| (x * 255.0).round() as u8)
}

#[cfg(test)]
mod tests {
    use super::*;

    fn img(labels: Vec<u32>) -> LabelImage {
        LabelImage {
            width: labels.len() as u32,
            height: 1,
            labels,
        }
    }

    #[test]
    fn iou_counts_intersection_over_union() {
        let names = vec!["a".to_string(), "b".into(), "c".into()];
        let x = img(vec![0, 0, 0, 1, NO_OBJECT, NO_OBJECT]);
        let y = img(vec![0, 0, 1, 1, 1, UNKNOWN]);
        let rows = compare(&names, &x, &y).unwrap();
        // a: |A| = 3, |B| = 2, |A∩B| = 2 → 2/3; b: |A| = 1, |B| = 3, ∩ = 1 → 1/3; c absent.
        assert_eq!(rows.len(), 2);
        assert_eq!(
            (rows[0].pixels_camsim, rows[0].pixels_povray),
            (3, 2),
            "{rows:?}"
        );
        assert!((rows[0].iou - 2.0 / 3.0).abs() < 1e-15);
        assert!((rows[1].iou - 1.0 / 3.0).abs() < 1e-15);
        assert!(compare(&names, &x, &img(vec![0])).is_err());
    }

    #[test]
    fn label_colours_round_trip_and_black_is_background() {
        for id in [0u32, 1, 254, 255, 256, 65535, 70000] {
            let c = label_colour(id).unwrap();
            assert_ne!(c, [0, 0, 0]);
            assert_eq!(label_of_colour(c, 70001), Some(id));
        }
        assert_eq!(label_of_colour([0, 0, 0], 10), None);
        assert_eq!(label_of_colour([0, 0, 11], 10), None);
        assert!(label_colour((1 << 24) - 1).is_none());
    }
}
