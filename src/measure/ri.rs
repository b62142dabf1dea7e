//! Relative illumination against field height from a flat-field image.
//!
//! Pixels of one channel (green by default on a mosaic) are binned by their
//! distance from the optical centre (pixel centres; centre defaults to the
//! image centre, or the full-frame centre for a window of a sensor image) into
//! equal-width annuli up to the farthest pixel. RI is each annulus' mean over
//! the innermost annulus' mean. Standard error: the standard error of the
//! annulus mean (std/√n) propagated through the ratio; the innermost
//! annulus is the reference and gets RI = 1 with its own relative error.

use super::plane::Plane;
use super::stats::{mean, std_dev};
use super::{Curve, Measured};
use crate::figure::Figure;
use crate::optical_image::Rect;
use crate::params::{Kind, ParamError, ParamSpec};
use crate::{Error, Result};

#[derive(Clone, Debug)]
pub struct RiOptions {
    /// Optical centre in plane coordinates (pixel i spans [i, i+1]); None = image centre.
    pub center_px: Option<(f64, f64)>,
    pub pixel_pitch_m: Option<f64>,
    pub bins: usize,
    /// CFA channel on a mosaic; ignored for a single-channel plane.
    pub channel: String,
}

impl Default for RiOptions {
    fn default() -> Self {
        Self {
            center_px: None,
            pixel_pitch_m: None,
            bins: 20,
            channel: "g".into(),
        }
    }
}

impl RiOptions {
    /// Defaults for a sensor image: centre at the full-frame centre, its pitch.
    pub fn for_sensor(img: &crate::image::SensorImage) -> Self {
        Self {
            center_px: Some((
                img.full_width as f64 / 2.0 - img.window.x as f64,
                img.full_height as f64 / 2.0 - img.window.y as f64,
            )),
            pixel_pitch_m: Some(img.pixel_pitch_m).filter(|p| *p > 0.0),
            ..Default::default()
        }
    }
}

/// `measure "ri"`: annuli, centre and (on a captured image) the channel.
#[derive(Clone, Debug)]
pub struct RiRequest {
    pub bins: usize,
    /// `channel`: None = "g" on a captured mosaic, the optical image on a
    /// rendered variant; given on a rendered variant, that channel of the
    /// simulated sensor image.
    pub channel: Option<String>,
    /// `center-px`: the optical centre in full-frame pixels (captured image:
    /// its pixels); None = the full-frame centre.
    pub center_px: Option<(f64, f64)>,
    pub input: Option<String>,
}

/// The properties of `measure "ri"`.
pub static SCHEMA: crate::params::Schema = crate::params::Schema {
    node: "measure \"ri\"",
    params: &[
        super::shared_params::name_param(),
        super::shared_params::input_param(),
        ParamSpec {
            name: "bin-count",
            kind: Kind::Integer,
            default: "20",
            doc: "equal-width annuli from the centre to the farthest pixel (1 … 10000)",
            example: "12",
        },
        ParamSpec {
            name: "center-px",
            kind: Kind::Numbers,
            default: "the full-frame centre",
            doc: "optical centre (x y), full-frame pixels (of a captured image: its pixels); pixel i spans [i, i+1]",
            example: "(30.5 20)",
        },
        ParamSpec {
            name: "channel",
            kind: Kind::Choice(&["r", "g", "b"]),
            default: "g",
            doc: "CFA channel read (black level subtracted): on a captured image (input=) default \"g\"; on a rendered variant it reads the simulated sensor image instead of the optical image's band-integrated irradiance",
            example: "\"r\"",
        },
    ],
};

/// Read `measure "ri"` (see [`SCHEMA`]).
pub fn from_params(d: &crate::params::ParamDict) -> std::result::Result<RiRequest, ParamError> {
    let center_px = match d.f64s("center-px")? {
        None => None,
        Some(v) if v.len() == 2 => Some((v[0], v[1])),
        Some(v) => {
            return Err(ParamError::value(
                "center-px",
                format!("'center-px': expected 2 numbers (x y), found {}", v.len()),
            ));
        }
    };
    Ok(RiRequest {
        bins: d.int("bin-count", 1, 10_000)?.map_or(20, |k| k as usize),
        channel: d.choice("channel")?.map(str::to_string),
        center_px,
        input: super::shared_params::nonempty(d, "input")?,
    })
}

/// RI curve (field height in mm when the pitch is known, else px) and figures
/// `ri@max` (outermost annulus) and `ri@half` (annulus holding half the maximum field height).
pub fn relative_illumination(
    plane: &Plane,
    opts: &RiOptions,
    measurement: &str,
) -> Result<Measured> {
    let (cx, cy) = opts
        .center_px
        .unwrap_or((plane.width as f64 / 2.0, plane.height as f64 / 2.0));
    let ch =
        if plane.is_mosaic() {
            Some(plane.channel_index(&opts.channel).ok_or_else(|| {
                Error::invalid(format!("channel '{}' not in the CFA", opts.channel))
            })?)
        } else {
            None
        };
    let nb = opts.bins.max(2);
    let r_of =
        |x: usize, y: usize| ((x as f64 + 0.5 - cx).powi(2) + (y as f64 + 0.5 - cy).powi(2)).sqrt();
    let corners = [
        (0, 0),
        (plane.width - 1, 0),
        (0, plane.height - 1),
        (plane.width - 1, plane.height - 1),
    ];
    let r_max = corners.iter().map(|&(x, y)| r_of(x, y)).fold(0.0, f64::max) * (1.0 + 1e-9);
    let mut bins: Vec<Vec<f64>> = vec![vec![]; nb];
    for y in 0..plane.height {
        for x in 0..plane.width {
            if ch.is_none() || plane.channel_at(x, y) == ch {
                let b = ((r_of(x, y) / r_max) * nb as f64) as usize;
                bins[b.min(nb - 1)].push(plane.get(x, y));
            }
        }
    }
    let m0 = mean(&bins[0]);
    if bins[0].len() < 2 || m0.is_nan() || m0 <= 0.0 {
        return Err(Error::invalid(
            "flat field: the central annulus is empty or not brighter than the black level",
        ));
    }
    let se0 = std_dev(&bins[0]) / (bins[0].len() as f64).sqrt() / m0;
    let scale = opts.pixel_pitch_m.map(|p| p * 1e3).unwrap_or(1.0);
    let unit = if opts.pixel_pitch_m.is_some() {
        "mm"
    } else {
        "px"
    };
    let (mut xs, mut ys, mut ses) = (vec![], vec![], vec![]);
    for (i, b) in bins.iter().enumerate() {
        if b.len() < 2 {
            continue;
        }
        let m = mean(b);
        let ri = m / m0;
        let rel = std_dev(b) / (b.len() as f64).sqrt() / m;
        xs.push((i as f64 + 0.5) / nb as f64 * r_max * scale);
        ys.push(ri);
        ses.push(if i == 0 {
            ri * se0
        } else {
            ri.abs() * (rel * rel + se0 * se0).sqrt()
        });
    }
    let last = ys.len() - 1;
    let half = xs
        .iter()
        .position(|&x| x >= 0.5 * r_max * scale)
        .unwrap_or(last);
    let figures = vec![
        Figure::new(measurement, "ri@max", "1", ys[last], ses[last]),
        Figure::new(measurement, "ri@half", "1", ys[half], ses[half]),
        Figure::new(measurement, "field_height_max", unit, r_max * scale, 0.0),
    ];
    Ok(Measured {
        figures,
        curves: vec![Curve::new(
            "ri",
            ("field height", unit),
            ("relative illumination", "1"),
            xs,
            ys,
            ses,
        )],
        pixels_read: vec![Rect::new(0, 0, plane.width as u32, plane.height as u32)],
    })
}

#[cfg(test)]
mod tests {
    use super::*;
    #[test]
    fn cos4_falloff_is_recovered() {
        // Flat field with cos⁴ falloff for a pinhole 100 px from the sensor: RI(r) = (1 + (r/100)²)⁻².
        let (w, h) = (121, 81);
        let mut d = vec![];
        for y in 0..h {
            for x in 0..w {
                let r2 = ((x as f64 + 0.5 - 60.5).powi(2) + (y as f64 + 0.5 - 40.5).powi(2)) / 1e4;
                d.push(1000.0 / (1.0 + r2).powi(2));
            }
        }
        let p = Plane::new(w, h, d).unwrap();
        let m = relative_illumination(
            &p,
            &RiOptions {
                bins: 30,
                ..Default::default()
            },
            "ri",
        )
        .unwrap();
        let c = &m.curves[0];
        for (x, y) in c.x.iter().zip(&c.y).skip(1) {
            let truth = 1.0 / (1.0 + x * x / 1e4).powi(2);
            // Annuli are 2.4 px wide: the mean over an annulus vs the value at its centre
            // differs by < 0.3 % here; the inner reference annulus is ~0.1 % below 1.
            assert!((y - truth).abs() < 0.005, "r={x}: {y} vs {truth}");
        }
    }
}
