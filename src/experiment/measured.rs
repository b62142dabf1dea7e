//! Measured inputs, comparisons and convergence inside an experiment run.
//!
//! - **Captured images**: `measured "capture-near" file="captures/edge.dng"
//!   [pixel-um=1.4] [labels="labels.png" names="names.txt"]` names a real
//!   capture (PNG 8/16 bit, OpenEXR, DNG/TIFF; read by
//!   [`crate::measure::io::read_image`]). A measurement with
//!   `input="capture-near"` reads it instead of the simulated sensor image,
//!   so its rows land in the same `results.csv` as the simulated ones.
//!   Captures carry no renderer labels: `sfr` needs `roi-px=(x y w h)` (or
//!   `of=` objects of the capture's label map), `mcc` and `profile` need the
//!   label map (a grey PNG, value k = the object named on line k of `names`,
//!   the format `camsim measure mcc --labels --names` reads), `noise` needs
//!   `conversion-gain-dv-e=`. Measurements on captures need no render: the
//!   runner skips every stage when an experiment measures captures only.
//! - **compare**: `measure "compare" of="mcc" reference="mcc-measured"`
//!   pairs the figures of two measurements of the same variant by quantity
//!   name (and unit) and reports RMSE, % errors and the slope through the
//!   origin with a scatter curve ([`crate::measure::compare`]). It runs after
//!   every other measurement of the variant. `quantity="_mean"` keeps only
//!   quantities containing that text; `normalize="mean"` divides each side by
//!   its mean over the pairs first (compares shapes, not exposure).
//! - **convergence**: `measure "convergence" of="sfr" spp=(16 64 256)
//!   [reference-spp=1024] [quantity="mtf50"]` (quantities containing that
//!   text; default all) runs the followed measurement once per count, each
//!   with its own seed (`render.seed + 1 + k`, so the runs are independent):
//!   a render of the region it reads, the same stages and measurement; for a
//!   `compare-curve`, the measurement it compares, then the comparison; for
//!   the sensor-only `conversion-gain`, that many flat frames. Per quantity it
//!   reports the log–log slopes of standard error against sample count and
//!   against wall time, a flag when the first is not −½, the efficiency, and
//!   — with `reference-spp` (the variant's seed, run first; the other runs
//!   take its exposure time) — the error against that reference
//!   ([`crate::measure::convergence`]). Sensor measurements keep the
//!   sensor's noise, which puts a floor under their standard error; the
//!   optical-image measurement `ri` shows the pure Monte Carlo error. MCC
//!   patch means with clipped pixels in any run are flagged (their standard
//!   error collapses with the noise, not as N^(−½)) with a
//!   `<q>/clipped_fraction` figure, and get no efficiency.

use super::apply::{ApplyError, check_input_name};
use super::source::Span;
use super::spec::{Measure, MeasuredInput, ResolvedExperiment};
use super::stages;
use crate::figure::Figure;
use crate::image::SensorImage;
use crate::measure::io::{LoadedImage, read_image, read_label_map_for};
use crate::measure::request::{self, MeasureOptions};
use crate::measure::{Measured, sfr::SfrChannel};
use crate::optical_image::{OpticalImage, Rect};
use crate::params::ParamError;
use crate::{Error, Result};
use std::collections::BTreeMap;
use std::path::Path;
use std::time::Instant;

/// Measurement kinds that can read a captured image (`input=`).
pub const INPUT_KINDS: &[&str] = &["sfr", "mcc", "profile", "noise", "ri"];
/// Measurement kinds whose figures convergence can follow: rendered ones,
/// a `compare-curve` of one of them (re-measured, then compared, per run) and
/// the sensor-only `conversion-gain` (its runs count frames, not samples).
const CONVERGENCE_KINDS: &[&str] = &[
    "sfr",
    "mcc",
    "profile",
    "noise",
    "ri",
    "compare-curve",
    "conversion-gain",
];
/// Kinds a followed `compare-curve` may compare (rendered measurements).
const RENDERED_KINDS: &[&str] = &["sfr", "mcc", "profile", "noise", "ri"];

/// The measurement convergence `m` follows (`of`) and the one its runs
/// measure: the same, or for a `compare-curve` the measurement it compares.
fn followed<'a>(
    spec: &'a ResolvedExperiment,
    m: &Measure,
    of: &str,
) -> Result<(&'a Measure, &'a Measure), ApplyError> {
    let t = spec
        .measures
        .iter()
        .find(|x| x.name == of && x.name != m.name && x.kind == "compare-curve");
    let (t, inner, kinds) = match t {
        Some(t) => {
            let inner = t.of.first().map(String::as_str).unwrap_or_default();
            (t, check_measurement_ref(spec, t, inner)?, RENDERED_KINDS)
        }
        None => {
            let t = check_measurement_ref(spec, m, of)?;
            (t, t, CONVERGENCE_KINDS)
        }
    };
    if !kinds.contains(&inner.kind.as_str()) || inner.params.get("input").is_some() {
        return Err(ApplyError::new(format!(
            "convergence follows a rendered measurement, a compare-curve of one, or conversion-gain ({}); '{}' is a '{}'{}",
            CONVERGENCE_KINDS.join(", "),
            inner.name,
            inner.kind,
            if inner.params.get("input").is_some() {
                " of a captured image"
            } else if t.name != inner.name {
                " (compared by a compare-curve)"
            } else {
                ""
            }
        )));
    }
    Ok((t, inner))
}

/// The directory a measurement's relative files are resolved against.
fn base_dir(spec: &ResolvedExperiment) -> &Path {
    spec.file.parent().unwrap_or(Path::new("."))
}

/// A [`ParamError`] of measurement `m`, at its property's name or value.
fn locate(m: &Measure, e: ParamError) -> (Span, ApplyError) {
    let span = match &e.name {
        Some(n) if e.on_value => m.spans.value_at(n, m.span),
        Some(n) => m.spans.name_at(n, m.span),
        None => m.span,
    };
    (
        span,
        ApplyError {
            message: e.message,
            help: e.help,
            on_path: false,
        },
    )
}

/// The options of measurement `m` ([`request::checked`], as `check` reads them).
pub fn options_of(m: &Measure, spec: &ResolvedExperiment) -> Result<MeasureOptions> {
    request::checked(&m.kind, &m.params, base_dir(spec))
        .map_err(|e| Error::invalid(format!("measurement '{}': {e}", m.name)))
}

/// Check-time checks of every measurement: its options
/// ([`request::checked`]: unknown, misspelt, wrong-typed or out-of-range
/// properties), then the references between nodes: `input=` names a
/// `measured` node (and what the kind needs of it), `compare` and
/// `convergence` name other measurements. Errors point at the property.
pub fn check_references(spec: &ResolvedExperiment) -> Result<(), (Span, ApplyError)> {
    for m in &spec.measures {
        let at = |k: &str| m.spans.value_at(k, m.span);
        if m.params.get("input").is_some() && !INPUT_KINDS.contains(&m.kind.as_str()) {
            return Err((
                at("input"),
                ApplyError::new(format!(
                    "measurement '{}' cannot read a captured image; kinds that can: {}",
                    m.kind,
                    INPUT_KINDS.join(", ")
                )),
            ));
        }
        let opts =
            request::checked(&m.kind, &m.params, base_dir(spec)).map_err(|e| locate(m, e))?;
        let n = request::needs(&m.kind);
        if n.sensor_config && !n.optical_image && spec.sensor.is_none() {
            return Err((
                m.span,
                ApplyError::new(format!(
                    "measure \"{}\" synthesises frames through the experiment's sensor, and there is none",
                    m.kind
                ))
                .help("add sensor \"sensors/imx363.kdl\" (or another sensor file)"),
            ));
        }
        let takes_of = request::schema(&m.kind).is_some_and(|s| s.get("of").is_some());
        if !m.of.is_empty() && !takes_of {
            return Err((
                at("of"),
                ApplyError::new(format!(
                    "measure \"{}\" takes no of= (it reads {})",
                    m.kind,
                    if m.kind == "colorimetry" {
                        "a spectrum"
                    } else {
                        "the whole image, or roi-px"
                    }
                )),
            ));
        }
        if let Some(name) = opts.input() {
            let c = check_input_name(spec, name).map_err(|e| (at("input"), e))?;
            let labelled = c.labels.is_some();
            let need =
                |msg: String, help: &str| Err((at("input"), ApplyError::new(msg).help(help)));
            match &opts {
                MeasureOptions::Sfr(r) if r.roi_px.is_none() && (m.of.is_empty() || !labelled) => {
                    return need(
                        format!(
                            "sfr on the captured image '{name}' needs roi-px=(x y w h) around the edge"
                        ),
                        "captures carry no object labels; or give the capture labels=… names=… and of=\"<object>\"",
                    );
                }
                MeasureOptions::Mcc(_) | MeasureOptions::Profile(_) if !labelled => {
                    return need(
                        format!(
                            "{} on the captured image '{name}' needs its label map",
                            m.kind
                        ),
                        "add labels=\"labels.png\" names=\"names.txt\" to the measured node",
                    );
                }
                MeasureOptions::Noise(r) if r.conversion_gain_dv_per_e.is_none() => {
                    return need(
                        format!(
                            "noise on the captured image '{name}' needs conversion-gain-dv-e=…"
                        ),
                        "the camera's conversion gain in DV per electron (Appendix IV's Poisson test)",
                    );
                }
                _ => {}
            }
        }
        match &opts {
            MeasureOptions::Compare(c) => {
                let of = single_of(
                    m,
                    "e.g. measure \"compare\" of=\"mcc\" reference=\"mcc-measured\"",
                )?;
                check_measurement_ref(spec, m, of).map_err(|e| (at("of"), e))?;
                let r = c.reference.as_deref().unwrap_or_default();
                check_measurement_ref(spec, m, r).map_err(|e| (at("reference"), e))?;
                if r == of {
                    return Err((
                        at("reference"),
                        ApplyError::new("compare: of and reference name the same measurement"),
                    ));
                }
            }
            MeasureOptions::CompareCurve(_) => {
                let of = single_of(
                    m,
                    "e.g. measure \"compare-curve\" of=\"ri\" curve=\"ri\" reference-file=\"….csv\"",
                )?;
                check_measurement_ref(spec, m, of).map_err(|e| (at("of"), e))?;
            }
            MeasureOptions::Convergence(c) => {
                let of = single_of(m, "e.g. measure \"convergence\" of=\"sfr\" spp=(16 64 256)")?;
                let (t, inner) = followed(spec, m, of).map_err(|e| (at("of"), e))?;
                if inner.kind == "conversion-gain"
                    && let Some(n) = c
                        .spp
                        .iter()
                        .chain(&c.reference_spp)
                        .find(|n| !(2..=10_000).contains(*n))
                {
                    return Err((
                        at(if c.spp.contains(n) {
                            "spp"
                        } else {
                            "reference-spp"
                        }),
                        ApplyError::new(format!(
                            "convergence of the sensor-only '{}' counts frames: {n} is outside 2 … 10000",
                            t.name
                        ))
                        .help("e.g. spp=(4 16 64) reference-spp=1024 (frame counts)"),
                    ));
                }
            }
            _ => {}
        }
    }
    Ok(())
}

/// Exactly one `of=` measurement (compare, convergence), which is returned.
fn single_of<'a>(m: &'a Measure, example: &str) -> Result<&'a str, (Span, ApplyError)> {
    match m.of.as_slice() {
        [one] => Ok(one.as_str()),
        _ => Err((
            m.spans.value_at("of", m.span),
            ApplyError::new(format!(
                "{} needs of=\"<measurement>\" (one simulated measurement)",
                m.kind
            ))
            .help(example),
        )),
    }
}

/// Another measurement of the experiment named `name` (not `m`, not a compare/convergence).
fn check_measurement_ref<'a>(
    spec: &'a ResolvedExperiment,
    m: &Measure,
    name: &str,
) -> Result<&'a Measure, ApplyError> {
    let others: Vec<&str> = spec
        .measures
        .iter()
        .filter(|x| x.name != m.name)
        .map(|x| x.name.as_str())
        .collect();
    match spec
        .measures
        .iter()
        .find(|x| x.name == name && x.name != m.name)
    {
        Some(t) if matches!(t.kind.as_str(), "compare" | "compare-curve" | "convergence") => {
            Err(ApplyError::new(format!(
                "'{name}' is a '{}' measurement; {} refers to a measurement of an image",
                t.kind, m.kind
            )))
        }
        Some(t) => Ok(t),
        None => {
            let mut e = ApplyError::new(format!(
                "no measurement named '{name}' in this experiment; names: {}",
                others.join(", ")
            ));
            e.help = crate::diag::did_you_mean(name, others.iter().copied())
                .map(|s| format!("did you mean '{s}'?"));
            Err(e)
        }
    }
}

/// Stages a measurement needs, given its properties: measurements of a
/// captured image (`input=`), `compare` and `convergence` (which renders on
/// its own) need none of the variant's stages.
pub fn needs_of(m: &Measure) -> stages::Needs {
    if m.params.get("input").is_some()
        || matches!(m.kind.as_str(), "compare" | "compare-curve" | "convergence")
    {
        return stages::Needs::default();
    }
    if m.kind == "ri" && m.params.get("channel").is_some() {
        // a channel of the simulated sensor image
        return stages::Needs {
            optical_image: true,
            sensor_image: true,
            sensor_config: true,
        };
    }
    stages::needs(&m.kind)
}

/// A captured image with its optional label map, read once per variant.
pub struct Capture {
    pub image: LoadedImage,
    pub labels: Option<(Vec<u32>, Vec<String>)>,
    pub pixel_pitch_m: Option<f64>,
}

/// Read a captured image and its label map (sizes must agree).
pub fn load_capture(c: &MeasuredInput) -> Result<Capture> {
    let image = read_image(&c.file.path)?;
    let labels = match (&c.labels, &c.names) {
        (Some(l), Some(n)) => Some(read_label_map_for(&image, &l.path, &n.path)?),
        _ => None,
    };
    Ok(Capture {
        image,
        labels,
        pixel_pitch_m: c.pixel_um.map(|p| p * 1e-6),
    })
}

/// Run measurement `m` on the captured image `cap` (called `input`).
pub fn measure_capture(
    m: &Measure,
    spec: &ResolvedExperiment,
    input: &str,
    cap: &Capture,
) -> Result<Measured> {
    let img = &cap.image;
    let err = |e: Error| Error::io(&img.path, e);
    let views_labels = || -> Result<&(Vec<u32>, Vec<String>)> {
        cap.labels.as_ref().ok_or_else(|| {
            Error::invalid(format!(
                "measurement '{}': the captured image '{input}' has no label map",
                m.name
            ))
        })
    };
    match options_of(m, spec)? {
        MeasureOptions::Sfr(r) => {
            let channel = match &r.options.channel {
                SfrChannel::Lum => "lum",
                SfrChannel::Named(c) => c.as_str(),
            };
            let plane = img.plane_for(channel)?;
            let opts = crate::measure::sfr::SfrOptions {
                pixel_pitch_m: cap.pixel_pitch_m,
                ..r.options.clone()
            };
            let mut regions = vec![];
            match r.roi_px {
                Some(roi) => regions.push((input.to_string(), roi)),
                None => {
                    let (labels, names) = views_labels()?;
                    for o in &m.of {
                        let roi = crate::measure::sfr::object_roi(
                            labels, names, img.width, img.height, o,
                        )
                        .map_err(err)?;
                        regions.push((o.clone(), roi));
                    }
                }
            }
            let mut out = Measured::default();
            for (p, roi) in regions {
                let (sfr, roi) =
                    crate::measure::sfr::sfr_of_region(&plane, roi, &opts).map_err(err)?;
                let x = sfr.measured(&m.name, roi).prefixed(&p);
                out.figures.extend(x.figures);
                out.curves.extend(x.curves);
                out.pixels_read.extend(x.pixels_read);
            }
            Ok(out)
        }
        MeasureOptions::Mcc(r) => {
            let (labels, names) = views_labels()?;
            let chart = m.of.first().map(String::as_str).unwrap_or("mcc");
            let patches = crate::measure::mcc::patch_means(
                &img.views(),
                labels,
                names,
                chart,
                r.inset_fraction,
            )
            .map_err(err)?;
            Ok(crate::measure::mcc::measured(&patches, &m.name))
        }
        MeasureOptions::Profile(r) => {
            let (labels, names) = views_labels()?;
            let opts = crate::measure::profile::ProfileOptions {
                step_px: if img.mosaic.is_some() { 2 } else { 1 },
                ..r.options.clone()
            };
            crate::measure::profile::profile(&img.views(), labels, names, &m.of, &opts, &m.name)
                .map_err(err)
        }
        MeasureOptions::Noise(r) => {
            let mut plane = img.plane_for(&r.options.channel)?;
            if let Some(roi) = r.roi_px {
                plane = plane.crop(roi).map_err(err)?;
            }
            let k = r
                .conversion_gain_dv_per_e
                .ok_or_else(|| Error::invalid("noise on a capture needs conversion-gain-dv-e"))?;
            let opts = crate::measure::noise::NoiseOptions {
                conversion_gain_dv_per_e: k,
                seed: r.seed.unwrap_or(spec.render.seed),
                ..r.options.clone()
            };
            Ok(crate::measure::noise::measure(&plane, &opts, &m.name)
                .map_err(err)?
                .0)
        }
        MeasureOptions::Ri(r) => {
            let channel = r.channel.clone().unwrap_or_else(|| "g".into());
            let plane = img.plane_for(&channel)?;
            let opts = crate::measure::ri::RiOptions {
                pixel_pitch_m: cap.pixel_pitch_m,
                center_px: r.center_px,
                bins: r.bins,
                channel,
            };
            crate::measure::ri::relative_illumination(&plane, &opts, &m.name).map_err(err)
        }
        o => Err(Error::invalid(format!(
            "measurement '{}' cannot read a captured image",
            o.kind()
        ))),
    }
}

/// The compare options of `m` (an error for another kind).
fn compare_options(m: &Measure) -> Result<crate::measure::compare::CompareOptions> {
    match request::checked(&m.kind, &m.params, Path::new("."))
        .map_err(|e| Error::invalid(format!("measurement '{}': {e}", m.name)))?
    {
        MeasureOptions::Compare(c) => Ok(c),
        o => Err(Error::invalid(format!(
            "measurement '{}' is a '{}', not a compare",
            m.name,
            o.kind()
        ))),
    }
}

/// `compare-curve`: the curve named by `curve=` of measurement `of` against
/// the reference curve of its CSV ([`crate::measure::compare_curve`]).
pub fn compare_curve(m: &Measure, spec: &ResolvedExperiment, of: &Measured) -> Result<Measured> {
    let MeasureOptions::CompareCurve(o) = options_of(m, spec)? else {
        return Err(Error::invalid(format!(
            "measurement '{}' is a '{}', not a compare-curve",
            m.name, m.kind
        )));
    };
    let want = o.curve.as_deref().unwrap_or_default();
    let c = of.curves.iter().find(|c| c.name == want).ok_or_else(|| {
        let names: Vec<&str> = of.curves.iter().map(|c| c.name.as_str()).collect();
        Error::invalid(format!(
            "compare-curve '{}': '{}' has no curve '{want}'; its curves: {}{}",
            m.name,
            m.of.first().map(String::as_str).unwrap_or(""),
            names.join(", "),
            crate::diag::did_you_mean(want, names.iter().copied())
                .map(|s| format!(" (did you mean '{s}'?)"))
                .unwrap_or_default()
        ))
    })?;
    crate::measure::compare_curve::compare_curve(c, &o, &m.name)
}

/// `compare`: pair the figures of measurement `of` (simulated) and
/// `reference` by quantity and unit, optionally filtered and normalised.
pub fn compare(m: &Measure, of: &Measured, reference: &Measured) -> Result<Measured> {
    let opts = compare_options(m)?;
    let filter = opts.quantity.as_deref();
    let keep = |f: &&Figure| filter.is_none_or(|q| f.quantity.contains(q));
    let refs: BTreeMap<&str, &Figure> = reference
        .figures
        .iter()
        .filter(keep)
        .map(|f| (f.quantity.as_str(), f))
        .collect();
    let mut pairs = vec![];
    let mut unit: Option<&str> = None;
    for f in of.figures.iter().filter(keep) {
        let Some(r) = refs.get(f.quantity.as_str()) else {
            continue;
        };
        if r.unit != f.unit {
            continue;
        }
        match unit {
            None => unit = Some(&f.unit),
            Some(u) if u != f.unit => {
                return Err(Error::invalid(format!(
                    "compare '{}': the paired figures mix units ({u} and {}); keep one kind with quantity=\"…\"",
                    m.name, f.unit
                )));
            }
            _ => {}
        }
        pairs.push(crate::measure::compare::Pair {
            name: f.quantity.clone(),
            simulated: f.value,
            reference: r.value,
        });
    }
    if pairs.len() < 2 {
        return Err(Error::invalid(format!(
            "compare '{}': '{}' and its reference share {} figure(s) with the same quantity and unit; at least 2 are needed",
            m.name,
            m.of.first().map(String::as_str).unwrap_or("?"),
            pairs.len()
        )));
    }
    let mut unit = unit.unwrap_or("1").to_string();
    if opts.normalize_mean {
        let n = pairs.len() as f64;
        let ms = pairs.iter().map(|p| p.simulated).sum::<f64>() / n;
        let mr = pairs.iter().map(|p| p.reference).sum::<f64>() / n;
        if ms == 0.0 || mr == 0.0 {
            return Err(Error::invalid(format!(
                "compare '{}': normalize=\"mean\" with a zero mean",
                m.name
            )));
        }
        for p in &mut pairs {
            p.simulated /= ms;
            p.reference /= mr;
        }
        unit = "1".into();
    }
    let mut out = crate::measure::compare::compare(&pairs, &unit, &m.name)?;
    out.figures
        .push(Figure::new(&m.name, "pairs", "1", pairs.len() as f64, 0.0));
    Ok(out)
}

/// One convergence run: its figures, wall time (s) and the sensor's exposure (s).
type Run = (Vec<Figure>, f64, Option<f64>);

/// `convergence`: run the followed measurement at each sample count (a
/// render of its region, or frames of a sensor-only one) and follow each of
/// its figures' standard error against the run's wall time.
pub fn convergence(m: &Measure, spec: &ResolvedExperiment) -> Result<Measured> {
    use crate::measure::convergence as conv;
    let MeasureOptions::Convergence(opts) = options_of(m, spec)? else {
        return Err(Error::invalid(format!(
            "measurement '{}' is not a convergence",
            m.name
        )));
    };
    let of =
        m.of.first()
            .ok_or_else(|| Error::invalid("convergence needs of=\"<measurement>\""))?;
    let (target, inner) = followed(spec, m, of)
        .map_err(|e| Error::invalid(format!("convergence '{}': {}", m.name, e.message)))?;
    let filter = opts.quantity.as_deref();
    let mut sub = spec.clone();
    sub.measures = vec![inner.clone()];
    let sensor_only = inner.kind == "conversion-gain";
    let label = if sensor_only { "frames" } else { "spp" };
    // Frames are independent; rendered figures follow the sampler's law.
    let law = if sensor_only || spec.render.sampler == crate::render::SamplerKind::Independent {
        conv::ErrorLaw::InverseSqrt
    } else {
        conv::ErrorLaw::AtLeastInverseSqrt
    };
    // The renderer's scene and camera are built once; a run's wall time is
    // what the run itself costs (label pass, render, sensor, measurement).
    let built = if sensor_only {
        None
    } else {
        let scene = stages::build_scene(&sub)?;
        let camera = stages::build_camera(&sub, &scene)?;
        Some((scene, camera))
    };
    let need = needs_of(inner);
    // One run: (figures, wall time, the sensor's exposure). `exposure`: a
    // fixed exposure time replacing the sensor's (auto exposure included).
    let run_at = |count: u64, seed: u64, exposure: Option<f64>| -> Result<Run> {
        let mut s = sub.clone();
        s.render.seed = seed;
        if let (Some(e), Some(sensor)) = (exposure, s.sensor.as_mut()) {
            sensor
                .overrides
                .set("exposure-s", crate::params::Value::Number(e));
        }
        let t = Instant::now();
        let mut exposure_s = None;
        let measured = match &built {
            None => {
                let MeasureOptions::ConversionGain(mut o) = options_of(inner, &s)? else {
                    return Err(Error::invalid("convergence: expected a conversion-gain"));
                };
                o.frames = count as usize;
                let cfg = stages::sensor_config(&s)?.ok_or_else(|| {
                    Error::invalid(format!("measurement '{}' needs a sensor", inner.name))
                })?;
                crate::measure::conversion_gain::measure(&cfg, &o, seed, &inner.name)?
            }
            Some((scene, camera)) => {
                s.render.spp = count;
                let r = stages::render(&s, scene, camera.as_ref())?;
                let si = if need.sensor_image {
                    Some(stages::simulate_sensor(&s, &r.oi)?)
                } else {
                    None
                };
                exposure_s = si.as_ref().map(|x| x.exposure_s);
                stages::measure(inner, &s, Some(&r.oi), si.as_ref(), &r.object_rects)?
            }
        };
        let measured = if target.kind == "compare-curve" {
            compare_curve(target, &s, &measured)?
        } else {
            measured
        };
        Ok((measured.figures, t.elapsed().as_secs_f64(), exposure_s))
    };
    // The reference (or, without one, the largest count) runs first; the
    // others take its exposure time. Auto exposure set from each run's own
    // noisy render would differ between runs — its bright percentile is
    // biased high at few samples — and bias every figure in DV.
    let last = opts.spp.len() - 1;
    let first = match opts.reference_spp {
        Some(r) => run_at(r, spec.render.seed, None)?,
        None => run_at(opts.spp[last], spec.render.seed + 1 + last as u64, None)?,
    };
    let exposure = first.2;
    let mut runs = vec![];
    for (k, &n) in opts.spp.iter().enumerate() {
        let r = if opts.reference_spp.is_none() && k == last {
            first.clone()
        } else {
            run_at(n, spec.render.seed + 1 + k as u64, exposure)?
        };
        runs.push((n, (r.0, r.1)));
    }
    let reference = opts.reference_spp.map(|_| first.0);
    let mut out = Measured::default();
    if let Some(e) = exposure {
        out.figures
            .push(Figure::new(&m.name, "exposure_s", "s", e, 0.0));
    }
    for (n, (_, dt)) in &runs {
        out.figures.push(Figure::new(
            &m.name,
            format!("{label}{n}/wall_s"),
            "s",
            *dt,
            0.0,
        ));
    }
    // Wall time = fixed cost + cost per sample: the fixed part is why the
    // slope against time is steeper than against samples at small counts.
    let counts: Vec<f64> = runs.iter().map(|r| r.0 as f64).collect();
    let times: Vec<f64> = runs.iter().map(|r| r.1.1).collect();
    if let Some((a, _, sa, _)) = crate::measure::stats::line_fit(&counts, &times) {
        out.figures
            .push(Figure::new(&m.name, "fixed_cost_s", "s", a, sa));
    }
    let matches = |q: &str| filter.is_none_or(|f| q.contains(f));
    let mut followed_n = 0;
    for f0 in runs[0].1.0.iter().filter(|f| matches(&f.quantity)) {
        let q = &f0.quantity;
        // A figure of clipped pixels (an MCC patch at the white level) does not
        // follow Monte Carlo noise: fitted and flagged, with how much clipped.
        let clipped = crate::measure::mcc::clipped_flag(q).map_or(0.0, |flag| {
            runs.iter()
                .flat_map(|(_, (figs, _))| figs.iter().filter(|f| f.quantity == flag))
                .map(|f| f.value)
                .fold(0.0, f64::max)
        });
        let (counts_of, series): (Vec<u64>, Vec<conv::Run>) = runs
            .iter()
            .filter_map(|(n, (figs, dt))| {
                let f = figs
                    .iter()
                    .find(|f| &f.quantity == q && f.unit == f0.unit)?;
                Some((
                    *n,
                    conv::Run {
                        wall_s: *dt,
                        samples: *n as f64,
                        value: f.value,
                        stderr: f.stderr,
                    },
                ))
            })
            .unzip();
        if series
            .iter()
            .filter(|r| r.stderr > 0.0 && r.wall_s > 0.0)
            .count()
            < 2
        {
            continue; // an exact figure (no standard error) has nothing to converge
        }
        let rv = reference
            .as_ref()
            .and_then(|r| r.iter().find(|f| &f.quantity == q && f.unit == f0.unit))
            .map(|f| (f.value, f.stderr));
        let mut c = conv::convergence(&series, rv, q, &f0.unit, &m.name, clipped, law)?;
        for (n, r) in counts_of.iter().zip(&series) {
            c.figures.push(Figure::new(
                &m.name,
                format!("{q}/{label}{n}_stderr"),
                &f0.unit,
                r.stderr,
                0.0,
            ));
        }
        out.figures.extend(c.figures);
        out.curves.extend(c.curves);
        followed_n += 1;
    }
    if followed_n == 0 {
        return Err(Error::invalid(format!(
            "convergence '{}': no figure of '{of}'{} has a standard error in ≥ 2 runs",
            m.name,
            filter
                .map(|q| format!(" matching quantity=\"{q}\""))
                .unwrap_or_default(),
        )));
    }
    Ok(out)
}

/// `measure "stability"`: one stiff or extreme case ([`crate::stability`]),
/// which renders and runs the variant's sensor on its own.
fn stability(m: &Measure, spec: &ResolvedExperiment) -> Result<Measured> {
    let MeasureOptions::Stability(o) = options_of(m, spec)? else {
        return Err(Error::invalid(format!(
            "'{}' is not a stability case",
            m.name
        )));
    };
    let sensor = stages::sensor_config(spec)?;
    crate::stability::measure(&m.name, &o, sensor.as_ref(), spec.render.seed)
}

/// Run every measurement of a variant, in dependency order (compare last),
/// and return their results in file order. Captured images are read once.
pub fn measure_all(
    spec: &ResolvedExperiment,
    oi: Option<&OpticalImage>,
    si: Option<&SensorImage>,
    object_rects: &BTreeMap<String, Rect>,
) -> Result<Vec<Measured>> {
    let mut caps: BTreeMap<String, Capture> = BTreeMap::new();
    let mut done: Vec<Option<Measured>> = vec![None; spec.measures.len()];
    for pass in 0..2 {
        for (i, m) in spec.measures.iter().enumerate() {
            let combines = matches!(m.kind.as_str(), "compare" | "compare-curve");
            if combines != (pass == 1) {
                continue;
            }
            let r = if combines {
                let get = |name: &str| -> Result<&Measured> {
                    spec.measures
                        .iter()
                        .position(|x| x.name == name)
                        .and_then(|k| done[k].as_ref())
                        .ok_or_else(|| {
                            Error::invalid(format!("compare '{}': no results of '{name}'", m.name))
                        })
                };
                let of = m.of.first().map(String::as_str).unwrap_or("");
                if m.kind == "compare-curve" {
                    compare_curve(m, spec, get(of)?)?
                } else {
                    let reference = compare_options(m)?.reference.unwrap_or_default();
                    compare(m, get(of)?, get(&reference)?)?
                }
            } else if m.kind == "convergence" {
                convergence(m, spec)?
            } else if m.kind == "stability" {
                stability(m, spec)?
            } else if let Some(input) = m.params.str("input").map_err(Error::invalid)? {
                let c = spec.measured_input(input).ok_or_else(|| {
                    Error::invalid(format!(
                        "measurement '{}': unknown measured input '{input}'",
                        m.name
                    ))
                })?;
                if !caps.contains_key(input) {
                    caps.insert(input.to_string(), load_capture(c)?);
                }
                measure_capture(m, spec, input, &caps[input])?
            } else {
                stages::measure(m, spec, oi, si, object_rects)?
            };
            done[i] = Some(r);
        }
    }
    Ok(done.into_iter().map(Option::unwrap_or_default).collect())
}
