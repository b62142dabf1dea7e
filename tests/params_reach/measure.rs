//! Parameter-reach probes of the measurements: the value each `measure
//! "<kind>"` property holds in the BUILT options, written back in the KDL
//! unit by this file's own arithmetic (not by the code under test).
//! `name`, `of` and `input` are probed by the experiment layer's test.

use camsim::measure::MeasureOptions;
use camsim::measure::sfr::SfrChannel;
use camsim::params::Value;

fn num(x: f64) -> Option<Value> {
    Some(Value::Number(x))
}
fn text(s: &str) -> Option<Value> {
    Some(Value::String(s.to_string()))
}
fn list(v: &[f64]) -> Option<Value> {
    Some(Value::List(v.iter().map(|x| Value::Number(*x)).collect()))
}
fn rect(r: Option<camsim::optical_image::Rect>) -> Option<Value> {
    r.and_then(|r| list(&[r.x as f64, r.y as f64, r.w as f64, r.h as f64]))
}

/// The value the built options hold for property `name` of `measure "<kind>"`
/// (None: a name this probe does not know, or an absent optional value).
pub fn probe(kind: &str, name: &str, opts: &MeasureOptions) -> Option<Value> {
    match (kind, opts) {
        ("colorimetry", MeasureOptions::Colorimetry(c)) => match name {
            "spectrum" => c.spectrum.as_ref().and_then(|(s, _)| text(s)),
            "wavelength-nm" => c.grid.as_ref().and_then(|g| {
                let stop = g.start_nm + g.step_nm * (g.count as f64 - 1.0);
                list(&[g.start_nm, stop, g.step_nm])
            }),
            _ => None,
        },
        ("sfr", MeasureOptions::Sfr(r)) => match name {
            "channel" => match &r.options.channel {
                SfrChannel::Lum => text("lum"),
                SfrChannel::Named(c) => text(c),
            },
            "roi-px" => rect(r.roi_px),
            "fit-degree" => num(r.options.fit_degree as f64),
            "jackknife-count" => num(r.options.jackknife_groups as f64),
            "max-freq-cy-px" => num(r.options.max_freq_cy_per_px),
            "max-noise-fraction" => num(r.options.max_noise_floor),
            _ => None,
        },
        ("ri", MeasureOptions::Ri(r)) => match name {
            "bin-count" => num(r.bins as f64),
            "center-px" => r.center_px.and_then(|(x, y)| list(&[x, y])),
            "channel" => r.channel.as_deref().and_then(text),
            _ => None,
        },
        ("noise", MeasureOptions::Noise(r)) => match name {
            "channel" => text(&r.options.channel),
            "roi-px" => rect(r.roi_px),
            "region-px" => num(r.options.region_px as f64),
            "region-count" => num(r.options.regions as f64),
            "seed" => r.seed.and_then(|s| num(s as f64)),
            "conversion-gain-dv-e" => r.conversion_gain_dv_per_e.and_then(num),
            "read-noise-e" => num(r.options.read_noise_e),
            "outlier-sigma" => num(r.options.outlier_sigma),
            "nonuniform-ratio" => num(r.options.nonuniform_ratio),
            "fold-count" => num(r.options.folds as f64),
            "band-percent" => num(r.band * 100.0),
            _ => None,
        },
        ("profile", MeasureOptions::Profile(r)) => match name {
            "band-px" => num(r.options.band_px as f64),
            "vertical" => Some(Value::Bool(r.options.vertical)),
            "channels" => text(&r.options.channels.join(" ")),
            "ratios" => text(
                &r.options
                    .ratios
                    .iter()
                    .map(|(a, b)| format!("{a}/{b}"))
                    .collect::<Vec<_>>()
                    .join(" "),
            ),
            _ => None,
        },
        ("mcc", MeasureOptions::Mcc(r)) => match name {
            "inset-fraction" => num(r.inset_fraction),
            _ => None,
        },
        ("compare", MeasureOptions::Compare(c)) => match name {
            "reference" => c.reference.as_deref().and_then(text),
            "quantity" => c.quantity.as_deref().and_then(text),
            "normalize" => text(if c.normalize_mean { "mean" } else { "none" }),
            _ => None,
        },
        ("compare-curve", MeasureOptions::CompareCurve(c)) => match name {
            "curve" => c.curve.as_deref().and_then(text),
            "reference-file" => c.reference.as_ref().and_then(|r| {
                // the path as written, relative to the project root it was found in
                let p = r.file.to_string_lossy();
                text(&p[p.find("lenses/").unwrap_or(0)..])
            }),
            "x-column" => c.x_column.as_deref().and_then(text),
            "y-column" => c.y_column.as_deref().and_then(text),
            "reference-filter" => c
                .reference_filter
                .as_ref()
                .and_then(|(k, v)| text(&format!("{k}={v}"))),
            "reference-y-scale-factor" => num(c.reference_y_scale),
            "x-unit" => c.x_unit.as_deref().and_then(text),
            "normalize" => text(match c.normalize {
                camsim::measure::compare_curve::Normalize::Max => "max",
                camsim::measure::compare_curve::Normalize::None => "none",
            }),
            "x-range-curve-unit" => c.x_range.and_then(|(a, b)| list(&[a, b])),
            "crossing-level" => c.crossing_level.and_then(num),
            _ => None,
        },
        ("convergence", MeasureOptions::Convergence(c)) => match name {
            "spp" => list(&c.spp.iter().map(|s| *s as f64).collect::<Vec<_>>()),
            "reference-spp" => c.reference_spp.and_then(|s| num(s as f64)),
            "quantity" => c.quantity.as_deref().and_then(text),
            _ => None,
        },
        ("conversion-gain", MeasureOptions::ConversionGain(c)) => match name {
            "mean-dv" => num(c.mean_dv),
            "frame-count" => num(c.frames as f64),
            "exposure-s" => num(c.exposure_s),
            "roi-px" => rect(c.roi_px),
            "channel" => text(&c.channel),
            "prnu-percent" => c.prnu.and_then(|p| num(p * 100.0)),
            "reference-mean-dv" => c
                .reference
                .map(|r| r.0)
                .filter(|x| !x.is_nan())
                .and_then(num),
            "reference-variance-dv2" => c
                .reference
                .map(|r| r.1)
                .filter(|x| !x.is_nan())
                .and_then(num),
            _ => None,
        },
        ("sensor-calibration", MeasureOptions::SensorCalibration(c)) => match name {
            "level-count" => num(c.levels as f64),
            "frame-count" => num(c.frames as f64),
            "exposure-s" => num(c.exposure_s),
            "max-level-fraction" => num(c.max_level_fraction),
            "dark-exposure-s" => list(&c.dark_exposures_s),
            "roi-px" => rect(c.roi_px),
            "channel" => text(&c.channel),
            "tolerance-percent" => num(c.tolerance_percent),
            _ => None,
        },
        ("stability", MeasureOptions::Stability(c)) => match name {
            "case" => c.case.as_deref().and_then(text),
            "tolerance-scale" => num(c.tolerance_scale),
            _ => None,
        },
        _ => None,
    }
}
