//! EMVA 1288-style calibration of the variant's sensor from simulated flat and
//! dark frames: `measure "sensor-calibration"` needs no scene.
//!
//! Light levels: `level-count` exposures under one flat irradiance, set so
//! the longest, `exposure-s`, gives `max-level-fraction` of the signal at
//! which the ADC clips, (white − black)/K electrons. Half the levels are
//! evenly spaced in signal up to 0.85 of the clip (the K fit uses those below
//! 70 % of saturation), the other half evenly from there to the brightest, so
//! the variance maximum that defines saturation is located finely. A dark sequence at
//! each light exposure, plus dark sequences at `dark-exposure-s` (long ones:
//! the dark signal grows by only the dark voltage × time). Every sequence has
//! `frame-count` frames of the crop `roi-px`, channel `channel`, simulated
//! through the full sensor pipeline ([`crate::sensor::flatfield::flat_sequence`])
//! and analysed by [`crate::sensor::calibrate::photon_transfer`] (system gain
//! K, temporal dark noise, DSNU, PRNU, saturation, dark signal, each with its
//! standard error).
//!
//! Figures, in the units of the paper's Table I, each beside the value the
//! sensor was given (`<q>/sensor`), the relative error (`<q>/error`, %) and
//! the deviation in standard errors (`<q>/z`): `conversion_gain` (DV/e⁻),
//! `read_noise` (mV; `read_noise_electrons`, e⁻), `dsnu` (mV), `prnu` (%),
//! `dark_voltage` (mV/s), `saturation` (e⁻). Volts are DV × the ADC step
//! (voltage swing / 2^bits) / analog gain. The expected saturation is
//! min(full well, (white − black)/K): a 10-bit ADC with a black level of 64
//! clips before a 6000 e⁻ well fills. `within_tolerance` counts the
//! parameters within 3 standard errors or `tolerance-percent` of the sensor's
//! value, whichever is larger.
//!
//! Curves: `photon_transfer#levels` (temporal variance against mean above
//! dark, DV) with `photon_transfer#fit` (the K line), and
//! `dark_signal#levels` (dark mean against exposure) with `dark_signal#fit`.

use super::conversion_gain::{channel_index, window};
use super::{Curve, Measured};
use crate::figure::Figure;
use crate::optical_image::Rect;
use crate::params::{Kind, ParamDict, ParamError, ParamSpec, Schema};
use crate::sensor::SensorConfig;
use crate::sensor::calibrate::{Estimate, photon_transfer};
use crate::sensor::flatfield::{flat_for_signal, flat_sequence};
use crate::{Error, Result};

/// `measure "sensor-calibration"` options.
#[derive(Clone, Debug, PartialEq)]
pub struct CalibrationOptions {
    pub levels: usize,
    pub frames: usize,
    pub exposure_s: f64,
    pub max_level_fraction: f64,
    pub dark_exposures_s: Vec<f64>,
    pub roi_px: Option<Rect>,
    pub channel: String,
    pub tolerance_percent: f64,
}

impl Default for CalibrationOptions {
    fn default() -> Self {
        Self {
            levels: 32,
            frames: 16,
            exposure_s: 0.1,
            max_level_fraction: 1.15,
            dark_exposures_s: vec![1.0, 5.0, 10.0],
            roi_px: None,
            channel: "g".into(),
            tolerance_percent: 5.0,
        }
    }
}

/// The properties of `measure "sensor-calibration"`.
pub static SCHEMA: Schema = Schema {
    node: "measure \"sensor-calibration\"",
    params: &[
        super::shared_params::name_param(),
        ParamSpec::new(
            "level-count",
            Kind::Integer,
            "32",
            "light levels: half evenly spaced in signal up to 0.85 of the ADC clip, half from there to max-level-fraction (4 … 1000)",
            "20",
        ),
        ParamSpec::new(
            "frame-count",
            Kind::Integer,
            "16",
            "frames per light or dark sequence (2 … 10000)",
            "8",
        ),
        ParamSpec::new(
            "exposure-s",
            Kind::Number,
            "0.1",
            "longest light exposure, s (> 0); each level is exposed its share of the brightest signal",
            "0.02",
        ),
        ParamSpec::new(
            "max-level-fraction",
            Kind::Number,
            "1.15",
            "signal of the brightest level as a fraction of the ADC clip, (white − black)/K electrons (0.85 < x ≤ 10; > 1 to find saturation); half the levels lie above 0.85",
            "1.6",
        ),
        ParamSpec::new(
            "dark-exposure-s",
            Kind::Numbers,
            "(1 5 10)",
            "extra dark exposures, s (≥ 0), for the dark signal's growth (darks at every light exposure are always taken)",
            "(2 4)",
        ),
        ParamSpec::new(
            "roi-px",
            Kind::Numbers,
            "128×128 at the sensor centre",
            "window (x y w h) simulated and analysed, full-frame sensor pixels",
            "(64 32 48 40)",
        ),
        ParamSpec::new(
            "channel",
            Kind::Choice(&["r", "g", "b"]),
            "g",
            "CFA channel analysed",
            "\"r\"",
        ),
        ParamSpec::new(
            "tolerance-percent",
            Kind::Number,
            "5",
            "a parameter agrees with the sensor's when within 3 standard errors or this percentage, whichever is larger (> 0)",
            "7.5",
        ),
    ],
};

/// Read `measure "sensor-calibration"` (see [`SCHEMA`]).
pub fn from_params(d: &ParamDict) -> std::result::Result<CalibrationOptions, ParamError> {
    let mut o = CalibrationOptions::default();
    if let Some(k) = d.int("level-count", 4, 1000)? {
        o.levels = k as usize;
    }
    if let Some(k) = d.int("frame-count", 2, 10_000)? {
        o.frames = k as usize;
    }
    if let Some(x) = d.positive("exposure-s")? {
        o.exposure_s = x;
    }
    if let Some(x) = d.positive("max-level-fraction")? {
        if !(x > KNEE && x <= 10.0) {
            return Err(ParamError::value(
                "max-level-fraction",
                format!("'max-level-fraction' = {x} is out of range; expected {KNEE} < x ≤ 10"),
            ));
        }
        o.max_level_fraction = x;
    }
    if let Some(v) = d.f64s("dark-exposure-s")? {
        if v.iter().any(|t| !(t.is_finite() && *t >= 0.0)) {
            return Err(ParamError::value(
                "dark-exposure-s",
                "'dark-exposure-s': every exposure must be ≥ 0 s",
            ));
        }
        o.dark_exposures_s = v;
    }
    o.roi_px = super::shared_params::roi_px(d, "roi-px")?;
    if let Some(c) = d.choice("channel")? {
        o.channel = c.to_string();
    }
    if let Some(x) = d.positive("tolerance-percent")? {
        o.tolerance_percent = x;
    }
    Ok(o)
}

/// Signal fraction of the ADC clip up to which half the levels are spread.
const KNEE: f64 = 0.85;

/// Signal of each light level as a fraction of the ADC clip (increasing).
pub fn level_fractions(levels: usize, max: f64) -> Vec<f64> {
    let lo = levels / 2;
    let hi = levels - lo;
    let mut f: Vec<f64> = (1..=lo).map(|k| KNEE * k as f64 / lo as f64).collect();
    f.extend((1..=hi).map(|k| KNEE + (max - KNEE) * k as f64 / hi as f64));
    f
}

/// One calibrated parameter: estimate and the sensor's value, same unit.
struct Row {
    quantity: &'static str,
    unit: &'static str,
    est: Estimate,
    sensor: f64,
}

/// Run `measure "sensor-calibration"` on the sensor `cfg`; frames seeded by `seed`.
pub fn measure(
    cfg: &SensorConfig,
    o: &CalibrationOptions,
    seed: u64,
    name: &str,
) -> Result<Measured> {
    let what = format!("measurement '{name}'");
    let win = window(o.roi_px, cfg, 128, 128, &what)?;
    let ch = channel_index(cfg, &o.channel, &what)?;
    let k_sensor = cfg.conversion_gain_dv_per_e();
    let clip_e = (cfg.white_level_dv() - cfg.black_level_dv) / k_sensor;
    let flat = flat_for_signal(cfg, ch, o.max_level_fraction * clip_e, o.exposure_s)?;
    // Sequence j gets its own seed base, so no two sequences share noise.
    let seq_seed = |j: usize| seed.wrapping_add((j as u64 + 1).wrapping_mul(0x1000_0001));
    let mut seqs = vec![];
    for (k, f) in level_fractions(o.levels, o.max_level_fraction)
        .into_iter()
        .enumerate()
    {
        let k = k + 1;
        let t = o.exposure_s * f / o.max_level_fraction;
        seqs.push(flat_sequence(
            cfg,
            Some(&flat),
            t,
            win,
            o.frames,
            seq_seed(2 * k),
            ch,
        )?);
        seqs.push(flat_sequence(
            cfg,
            None,
            t,
            win,
            o.frames,
            seq_seed(2 * k + 1),
            ch,
        )?);
    }
    for (i, &t) in o.dark_exposures_s.iter().enumerate() {
        seqs.push(flat_sequence(
            cfg,
            None,
            t,
            win,
            o.frames,
            seq_seed(2 * o.levels + 2 + i),
            ch,
        )?);
    }
    let pt = photon_transfer(&seqs).map_err(|e| Error::invalid(format!("{what}: {e}")))?;
    let mv_per_dv = cfg.quantization_step_v() / cfg.analog_gain * 1e3;
    let mv = |e: &Estimate| Estimate {
        value: e.value * mv_per_dv,
        stderr: e.stderr * mv_per_dv,
    };
    let cg = cfg.conversion_gain_v_per_e();
    let mut rows = vec![
        Row {
            quantity: "conversion_gain",
            unit: "DV/e-",
            est: pt.k_dv_per_e,
            sensor: k_sensor,
        },
        Row {
            quantity: "read_noise",
            unit: "mV",
            est: mv(&pt.dark_noise_dv),
            sensor: cfg.read_noise_v.hypot(cfg.reset_noise_v) * 1e3,
        },
        Row {
            quantity: "read_noise_electrons",
            unit: "e-",
            est: pt.dark_noise_e,
            sensor: cfg.read_noise_v.hypot(cfg.reset_noise_v) / cg,
        },
        Row {
            quantity: "dsnu",
            unit: "mV",
            est: mv(&pt.dsnu_dv),
            sensor: cfg.dsnu_v.hypot(cfg.column_fpn_offset_v) * 1e3,
        },
        Row {
            quantity: "prnu",
            unit: "%",
            est: Estimate {
                value: pt.prnu.value * 100.0,
                stderr: pt.prnu.stderr * 100.0,
            },
            sensor: cfg.prnu.hypot(cfg.column_fpn_gain) * 100.0,
        },
    ];
    match &pt.dark_signal_dv_per_s {
        Some(d) => rows.push(Row {
            quantity: "dark_voltage",
            unit: "mV/s",
            est: mv(d),
            sensor: cfg.dark_voltage_v_per_s * 1e3,
        }),
        None => {
            return Err(Error::invalid(format!(
                "{what}: the dark signal's growth needs dark frames at two or more exposures"
            )));
        }
    }
    match &pt.saturation_e {
        Some(s) => rows.push(Row {
            quantity: "saturation",
            unit: "e-",
            est: *s,
            sensor: cfg.full_well_e().min(clip_e),
        }),
        None => {
            return Err(Error::invalid(format!(
                "{what}: no light level passed the variance maximum; raise max-level-fraction above 1 (now {})",
                o.max_level_fraction
            )));
        }
    }
    let mut figures = vec![];
    let mut within = 0;
    for r in &rows {
        let q = r.quantity;
        let err = r.est.value / r.sensor - 1.0;
        let z = if r.est.stderr > 0.0 {
            (r.est.value - r.sensor) / r.est.stderr
        } else {
            0.0
        };
        let ok = (r.est.value - r.sensor).abs()
            <= (3.0 * r.est.stderr).max(o.tolerance_percent / 100.0 * r.sensor.abs());
        within += ok as usize;
        figures.push(Figure::new(name, q, r.unit, r.est.value, r.est.stderr));
        figures.push(Figure::new(
            name,
            format!("{q}/sensor"),
            r.unit,
            r.sensor,
            0.0,
        ));
        figures.push(Figure::new(
            name,
            format!("{q}/error"),
            "%",
            err * 100.0,
            r.est.stderr / r.sensor.abs() * 100.0,
        ));
        figures.push(Figure::new(name, format!("{q}/z"), "1", z, 0.0));
    }
    figures.push(Figure::new(
        name,
        "well_capacity/sensor",
        "e-",
        cfg.well_capacity_e,
        0.0,
    ));
    figures.push(Figure::new(
        name,
        "within_tolerance",
        "1",
        within as f64,
        0.0,
    ));
    figures.push(Figure::new(name, "parameters", "1", rows.len() as f64, 0.0));
    // Curves: photon transfer (light levels above the shortest dark) and dark signal.
    let d0 = pt
        .levels
        .iter()
        .filter(|l| l.dark)
        .min_by(|a, b| a.exposure_s.total_cmp(&b.exposure_s))
        .expect("photon_transfer had dark levels");
    let lights: Vec<_> = pt.levels.iter().filter(|l| !l.dark).collect();
    let px: Vec<f64> = lights.iter().map(|l| l.mean - d0.mean).collect();
    let py: Vec<f64> = lights.iter().map(|l| l.temporal_var).collect();
    let pse: Vec<f64> = lights.iter().map(|l| l.temporal_var_se).collect();
    let xmax = px.iter().cloned().fold(0.0, f64::max);
    let k = pt.k_dv_per_e.value;
    let mut darks: Vec<_> = pt.levels.iter().filter(|l| l.dark).collect();
    darks.sort_by(|a, b| a.exposure_s.total_cmp(&b.exposure_s));
    let dt: Vec<f64> = darks.iter().map(|l| l.exposure_s).collect();
    let dm: Vec<f64> = darks.iter().map(|l| l.mean).collect();
    let slope = pt.dark_signal_dv_per_s.map(|d| d.value).unwrap_or(0.0);
    let (tm, mm) = (
        dt.iter().sum::<f64>() / dt.len() as f64,
        dm.iter().sum::<f64>() / dm.len() as f64,
    );
    let t_last = dt.last().copied().unwrap_or(0.0);
    let curves = vec![
        Curve::new(
            "photon_transfer#levels",
            ("mean above dark", "DV"),
            ("temporal variance", "DV^2"),
            px,
            py,
            pse,
        ),
        Curve::new(
            "photon_transfer#fit",
            ("mean above dark", "DV"),
            ("temporal variance", "DV^2"),
            vec![0.0, xmax],
            vec![d0.temporal_var, d0.temporal_var + k * xmax],
            vec![],
        ),
        Curve::new(
            "dark_signal#levels",
            ("exposure", "s"),
            ("dark mean", "DV"),
            dt.clone(),
            dm,
            vec![],
        ),
        Curve::new(
            "dark_signal#fit",
            ("exposure", "s"),
            ("dark mean", "DV"),
            vec![dt[0], t_last],
            vec![mm + slope * (dt[0] - tm), mm + slope * (t_last - tm)],
            vec![],
        ),
    ];
    Ok(Measured {
        figures,
        curves,
        pixels_read: vec![],
    })
}
