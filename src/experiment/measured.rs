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
//!   text; default all) renders the region the named
//!   measurement reads once per sample count (each with its own seed,
//!   `render.seed + 1 + k`, so the runs are independent), runs the same
//!   stages and measurement, and reports per quantity the log–log slope of
//!   standard error against render time, the efficiency, and — with
//!   `reference-spp` (rendered with the variant's seed) — the error against
//!   that reference ([`crate::measure::convergence`]). Sensor measurements keep
//!   the sensor's noise, which puts a floor under their standard error; the
//!   optical-image measurement `ri` shows the pure Monte Carlo error. MCC
//!   patch means with clipped pixels in any run are not fitted (their
//!   standard error collapses with the noise, not as t^(−½)); they get a
//!   `<q>/clipped_fraction` figure instead.

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
/// Measurement kinds whose figures convergence can follow.
const CONVERGENCE_KINDS: &[&str] = &["sfr", "mcc", "profile", "noise", "ri"];

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
            MeasureOptions::Convergence(_) => {
                let of = single_of(m, "e.g. measure \"convergence\" of=\"sfr\" spp=(16 64 256)")?;
                let t = check_measurement_ref(spec, m, of).map_err(|e| (at("of"), e))?;
                if !CONVERGENCE_KINDS.contains(&t.kind.as_str()) || t.params.get("input").is_some()
                {
                    return Err((
                        at("of"),
                        ApplyError::new(format!(
                            "convergence follows a rendered measurement ({}); '{of}' is a '{}'{}",
                            CONVERGENCE_KINDS.join(", "),
                            t.kind,
                            if t.params.get("input").is_some() {
                                " of a captured image"
                            } else {
                                ""
                            }
                        )),
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

/// `convergence`: render the target measurement's region at each spp and
/// follow each of its figures' standard error against render time.
pub fn convergence(m: &Measure, spec: &ResolvedExperiment) -> Result<Measured> {
    let MeasureOptions::Convergence(opts) = options_of(m, spec)? else {
        return Err(Error::invalid(format!(
            "measurement '{}' is not a convergence",
            m.name
        )));
    };
    let of =
        m.of.first()
            .ok_or_else(|| Error::invalid("convergence needs of=\"<measurement>\""))?;
    let target = spec
        .measures
        .iter()
        .find(|x| &x.name == of)
        .ok_or_else(|| Error::invalid(format!("convergence: no measurement '{of}'")))?;
    let filter = opts.quantity.as_deref();
    let mut sub = spec.clone();
    sub.measures = vec![target.clone()];
    let scene = stages::build_scene(&sub)?;
    let camera = stages::build_camera(&sub, &scene)?;
    let need = stages::needs(&target.kind);
    let run_at = |spp: u64, seed: u64| -> Result<(Vec<Figure>, f64)> {
        let mut s = sub.clone();
        s.render.spp = spp;
        s.render.seed = seed;
        let t = Instant::now();
        let r = stages::render(&s, &scene, camera.as_ref())?;
        let dt = t.elapsed().as_secs_f64();
        let oi = r.oi;
        let si = if need.sensor_image {
            Some(stages::simulate_sensor(&s, &oi)?)
        } else {
            None
        };
        Ok((
            stages::measure(target, &s, Some(&oi), si.as_ref(), &r.object_rects)?.figures,
            dt,
        ))
    };
    let mut runs = vec![];
    for (k, &spp) in opts.spp.iter().enumerate() {
        runs.push((spp, run_at(spp, spec.render.seed + 1 + k as u64)?));
    }
    let reference = match opts.reference_spp {
        Some(r) => Some(run_at(r, spec.render.seed)?.0),
        None => None,
    };
    let mut out = Measured::default();
    for (spp, (_, dt)) in &runs {
        out.figures.push(Figure::new(
            &m.name,
            format!("spp{spp}/render_s"),
            "s",
            *dt,
            0.0,
        ));
    }
    let matches = |q: &str| filter.is_none_or(|f| q.contains(f));
    let (mut followed, mut clipped_out) = (0, 0);
    for f0 in runs[0].1.0.iter().filter(|f| matches(&f.quantity)) {
        let q = &f0.quantity;
        // A figure of clipped pixels (an MCC patch at the white level) does not
        // follow Monte Carlo noise: report how much clipped, fit nothing.
        let clipped = crate::measure::mcc::clipped_flag(q).map_or(0.0, |flag| {
            runs.iter()
                .flat_map(|(_, (figs, _))| figs.iter().filter(|f| f.quantity == flag))
                .map(|f| f.value)
                .fold(0.0, f64::max)
        });
        if clipped > 0.0 {
            out.figures.push(Figure::new(
                &m.name,
                format!("{q}/clipped_fraction"),
                "1",
                clipped,
                0.0,
            ));
            clipped_out += 1;
            continue;
        }
        let (spp_of, series): (Vec<u64>, Vec<crate::measure::convergence::Run>) = runs
            .iter()
            .filter_map(|(spp, (figs, dt))| {
                let f = figs
                    .iter()
                    .find(|f| &f.quantity == q && f.unit == f0.unit)?;
                Some((
                    *spp,
                    crate::measure::convergence::Run {
                        render_s: *dt,
                        value: f.value,
                        stderr: f.stderr,
                    },
                ))
            })
            .unzip();
        if series
            .iter()
            .filter(|r| r.stderr > 0.0 && r.render_s > 0.0)
            .count()
            < 2
        {
            continue; // an exact figure (no standard error) has nothing to converge
        }
        let rv = reference
            .as_ref()
            .and_then(|r| r.iter().find(|f| &f.quantity == q))
            .map(|f| f.value);
        let mut c = crate::measure::convergence::convergence(&series, rv, q, &f0.unit, &m.name)?;
        for (spp, r) in spp_of.iter().zip(&series) {
            c.figures.push(Figure::new(
                &m.name,
                format!("{q}/spp{spp}_stderr"),
                &f0.unit,
                r.stderr,
                0.0,
            ));
        }
        for cv in &mut c.curves {
            cv.name = format!("{q}/{}", cv.name);
        }
        out.figures.extend(c.figures);
        out.curves.extend(c.curves);
        followed += 1;
    }
    if followed == 0 {
        return Err(Error::invalid(format!(
            "convergence '{}': no figure of '{of}'{} has a standard error in ≥ 2 runs{}",
            m.name,
            filter
                .map(|q| format!(" matching quantity=\"{q}\""))
                .unwrap_or_default(),
            if clipped_out > 0 {
                format!(
                    " ({clipped_out} left out because their pixels clip at the sensor's white level or floor; shorten the exposure)"
                )
            } else {
                String::new()
            }
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
