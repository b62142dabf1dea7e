//! Stiff and extreme cases (issue 16 item 5), each run against an analytic
//! or converged reference: `measure "stability" case="…"`.
//!
//! A case is a list of [`Check`]s. Every check is dimensionless (a ratio to
//! the analytic value, a relative deviation, a count or a fraction), so one
//! report column holds any case. A check passes when its value is finite and
//! `|value − reference| ≤ tolerance`; each tolerance is derived in the case's
//! code (Monte Carlo standard error, f32/f64 rounding, or an exact count).
//!
//! Decision: a case never fails its variant. It always returns figures —
//! `passed` (1/0), `checks`, `failed_checks`, and the worst check's `value`,
//! `reference`, `error` (value − reference) and `tolerance` (the check with
//! the largest |error|/tolerance) — so the report's table lists every case
//! with pass/fail. A failed check adds `failed/<check>` (|error|/tolerance,
//! or `failed/<check>/nonfinite` = 1 when its value, reference or
//! tolerance is not finite) and prints
//! what failed and where on the run log (stderr); a case whose own machinery
//! returns an error fails its `ran` check with that message. No figure is
//! ever NaN (the runner refuses those).
//!
//! Cases, one file per group:
//! - `render_cases`: `dynamic-range` (10⁸ between two emitters),
//!   `grazing` (light and view at grazing angles over a seam), `scale`
//!   (1 mm and 1 km against 1 m);
//! - `sensor_cases`: `sensor-saturated-dark`, `exposure-gain`;
//! - `rtf_cases`: `rtf-beyond-field`, `rtf-singular-fit`;
//! - `sfr_case`: `sfr-noisy`.

pub mod render_cases;
pub mod rtf_cases;
pub mod sensor_cases;
pub mod sfr_case;

use crate::figure::Figure;
use crate::measure::Measured;
use crate::measure::stability::{CASES, StabilityOptions};
use crate::sensor::config::SensorConfig;
use crate::{Error, Result};

/// One check of a case: a dimensionless value against its reference.
#[derive(Clone, Debug, PartialEq)]
pub struct Check {
    /// Short name, e.g. `dim/irradiance_ratio`.
    pub name: String,
    pub value: f64,
    pub reference: f64,
    /// Largest |value − reference| that passes (before `tolerance-scale`).
    pub tolerance: f64,
    /// The value's own standard error (0 when deterministic).
    pub stderr: f64,
    /// Where: what the check looked at, for the failure message.
    pub at: String,
}

impl Check {
    pub fn new(name: &str, value: f64, reference: f64, tolerance: f64, at: &str) -> Self {
        Self {
            name: name.into(),
            value,
            reference,
            tolerance,
            stderr: 0.0,
            at: at.into(),
        }
    }
    pub fn with_stderr(mut self, se: f64) -> Self {
        self.stderr = if se.is_finite() { se } else { 0.0 };
        self
    }
    /// A count that must be exactly `reference`.
    pub fn count(name: &str, value: usize, reference: usize, at: &str) -> Self {
        Self::new(name, value as f64, reference as f64, 0.0, at)
    }
    pub fn error(&self) -> f64 {
        self.value - self.reference
    }
    /// Value, reference and tolerance are all finite numbers.
    pub fn finite(&self) -> bool {
        self.value.is_finite() && self.reference.is_finite() && self.tolerance.is_finite()
    }
    pub fn passed(&self, scale: f64) -> bool {
        self.finite() && self.error().abs() <= self.tolerance * scale
    }
    /// |error| / tolerance (∞ when the tolerance is 0 and the error is not).
    fn ratio(&self, scale: f64) -> f64 {
        let e = self.error().abs();
        if e == 0.0 {
            0.0
        } else {
            e / (self.tolerance * scale)
        }
    }
    fn message(&self, case: &str, scale: f64) -> String {
        if !self.finite() {
            return format!(
                "stability case '{case}': check '{}' ({}) is not finite: value {}, reference {}, tolerance {}",
                self.name, self.at, self.value, self.reference, self.tolerance
            );
        }
        format!(
            "stability case '{case}': check '{}' ({}) failed: value {:e}, reference {:e}, |error| {:e} > tolerance {:e}",
            self.name,
            self.at,
            self.value,
            self.reference,
            self.error().abs(),
            self.tolerance * scale
        )
    }
}

/// The checks of `case` (see the case modules). `sensor` is the experiment's
/// sensor (the sensor cases need one); `seed` drives every random number.
pub fn run_case(case: &str, sensor: Option<&SensorConfig>, seed: u64) -> Result<Vec<Check>> {
    let need_sensor = || {
        sensor.ok_or_else(|| {
            Error::invalid(format!(
                "stability case '{case}' runs the experiment's sensor, and there is none (add sensor \"sensors/….kdl\")"
            ))
        })
    };
    match case {
        "dynamic-range" => render_cases::dynamic_range(seed),
        "grazing" => render_cases::grazing(seed),
        "scale" => render_cases::scale(seed),
        "sensor-saturated-dark" => sensor_cases::saturated_dark(need_sensor()?, seed),
        "exposure-gain" => sensor_cases::exposure_gain(need_sensor()?, seed),
        "rtf-beyond-field" => rtf_cases::beyond_field(),
        "rtf-singular-fit" => rtf_cases::singular_fit(),
        "sfr-noisy" => sfr_case::noisy_roi(seed),
        _ => Err(Error::invalid(format!(
            "unknown stability case '{case}'; expected one of: {}",
            CASES.join(", ")
        ))),
    }
}

/// The figures of a case's checks (see the module docs), and the messages
/// of the failed ones.
pub fn figures(
    measurement: &str,
    case: &str,
    checks: &[Check],
    scale: f64,
) -> (Vec<Figure>, Vec<String>) {
    let failed: Vec<&Check> = checks.iter().filter(|c| !c.passed(scale)).collect();
    let fig = |q: &str, v: f64, se: f64| Figure::new(measurement, q, "1", v, se);
    let mut out = vec![
        fig(
            "passed",
            (failed.is_empty() && !checks.is_empty()) as u8 as f64,
            0.0,
        ),
        fig("checks", checks.len() as f64, 0.0),
        fig("failed_checks", failed.len() as f64, 0.0),
    ];
    // The worst finite check: the largest |error|/tolerance.
    let worst = checks
        .iter()
        .filter(|c| c.finite())
        .max_by(|a, b| a.ratio(scale).total_cmp(&b.ratio(scale)));
    if let Some(w) = worst {
        out.push(fig("value", w.value, w.stderr));
        out.push(fig("reference", w.reference, 0.0));
        out.push(fig("error", w.error(), w.stderr));
        out.push(fig("tolerance", w.tolerance * scale, 0.0));
    }
    let mut messages = vec![];
    for c in &failed {
        if c.finite() {
            let r = c.ratio(scale);
            // a zero tolerance gives ∞: written as the |error| itself
            let v = if r.is_finite() { r } else { c.error().abs() };
            out.push(fig(&format!("failed/{}", c.name), v, 0.0));
        } else {
            out.push(fig(&format!("failed/{}/nonfinite", c.name), 1.0, 0.0));
        }
        messages.push(c.message(case, scale));
    }
    if checks.is_empty() {
        messages.push(format!("stability case '{case}': no checks were run"));
    }
    (out, messages)
}

/// Run `measure "stability"`: the case's checks as figures; a failed check
/// is printed (what and where) on stderr, the run log.
pub fn measure(
    measurement: &str,
    opts: &StabilityOptions,
    sensor: Option<&SensorConfig>,
    seed: u64,
) -> Result<Measured> {
    let case = opts.case.as_deref().ok_or_else(|| {
        Error::invalid(format!(
            "measurement '{measurement}': stability needs case=\"<case>\""
        ))
    })?;
    if !CASES.contains(&case) {
        return Err(Error::invalid(format!(
            "measurement '{measurement}': unknown stability case '{case}'"
        )));
    }
    // A configuration error (no sensor) is the experiment's error; anything
    // the case's own machinery refuses is a failed check of the case.
    if matches!(case, "sensor-saturated-dark" | "exposure-gain") && sensor.is_none() {
        return Err(Error::invalid(format!(
            "measurement '{measurement}': stability case '{case}' runs the experiment's sensor, and there is none (add sensor \"sensors/….kdl\")"
        )));
    }
    let checks = match run_case(case, sensor, seed) {
        Ok(c) => c,
        Err(e) => {
            let mut c = Check::new("ran", 0.0, 1.0, 0.0, &e.to_string());
            c.at = format!("the case stopped with an error: {e}");
            vec![c]
        }
    };
    let (figures, messages) = figures(measurement, case, &checks, opts.tolerance_scale);
    for m in &messages {
        eprintln!("camsim: measurement '{measurement}': {m}");
    }
    Ok(Measured {
        figures,
        ..Default::default()
    })
}

/// Count of non-finite values.
pub(crate) fn nonfinite(v: &[f32]) -> usize {
    v.iter().filter(|x| !x.is_finite()).count()
}

#[cfg(test)]
mod tests {
    use super::*;

    #[test]
    fn a_failed_check_is_named_and_no_figure_is_nan() {
        let checks = vec![
            Check::new("ok", 1.0, 1.0, 0.1, "here"),
            Check::new("off", 1.5, 1.0, 0.1, "there"),
            Check::new("nan", f64::NAN, 1.0, 0.1, "nowhere"),
            Check::new("nan-tol", 1.0, 1.0, f64::NAN, "nowhere"),
        ];
        let (f, msg) = figures("m", "c", &checks, 1.0);
        let get = |q: &str| f.iter().find(|x| x.quantity == q).map(|x| x.value);
        assert_eq!(get("passed"), Some(0.0));
        assert_eq!(get("failed_checks"), Some(3.0));
        assert_eq!(get("failed/nan-tol/nonfinite"), Some(1.0));
        assert!((get("failed/off").unwrap() - 5.0).abs() < 1e-12);
        assert_eq!(get("failed/nan/nonfinite"), Some(1.0));
        // the worst finite check is the headline
        assert_eq!(get("value"), Some(1.5));
        assert!(
            f.iter()
                .all(|x| x.value.is_finite() && x.stderr.is_finite())
        );
        assert_eq!(msg.len(), 3);
        assert!(
            msg[0].contains("'off'") && msg[0].contains("there"),
            "{}",
            msg[0]
        );
        assert!(msg[1].contains("not finite"), "{}", msg[1]);
        // all passing
        let (f, msg) = figures("m", "c", &checks[..1], 1.0);
        assert_eq!(f[0].value, 1.0);
        assert!(msg.is_empty());
        // a zero tolerance scale fails the inexact check only
        let exact = [
            Check::count("n", 0, 0, "x"),
            Check::new("r", 1.01, 1.0, 0.1, "y"),
        ];
        let (f, _) = figures("m", "c", &exact, 0.0);
        assert_eq!(f[2].value, 1.0);
    }
}
