//! Check time: every variant's stages are built from their parameters by the
//! same functions `run` uses (the sensor from its file and properties, the
//! camera model from the `lens` node, each measurement's options, the scene
//! edits' parameters), without rendering. A [`ParamError`] is located at the
//! property it names (its name, or its value), else at the node.

use super::apply::ApplyError;
use super::source::Span;
use super::spec::{PropSpans, ResolvedExperiment};
use crate::params::{ParamError, Params};
use std::path::Path;

/// Scenes already checked for intersecting objects, by their inputs (the
/// scene file and materials, additions, removals, overrides): a plan's
/// variants often share one scene (a sweep over the sensor, the camera or a
/// light's spectrum), which is then built and checked once.
#[derive(Default)]
pub struct CheckMemo {
    scenes: std::collections::HashMap<String, Result<(), (Span, ApplyError)>>,
}

/// Build (without rendering) every stage of `spec` from its parameters.
pub fn check_stages(spec: &ResolvedExperiment) -> Result<(), (Span, ApplyError)> {
    check_stages_with(spec, &mut CheckMemo::default())
}

/// [`check_stages`], remembering scene checks in `memo` (across a plan's variants).
pub fn check_stages_with(
    spec: &ResolvedExperiment,
    memo: &mut CheckMemo,
) -> Result<(), (Span, ApplyError)> {
    let located = |e: ParamError, ps: &PropSpans, whole: Span| {
        let spans = if e.on_value { &ps.values } else { &ps.names };
        let span = e
            .name
            .as_ref()
            .and_then(|n| spans.get(n))
            .copied()
            .unwrap_or(whole);
        (
            span,
            ApplyError {
                message: e.message,
                help: e.help,
                on_path: false,
            },
        )
    };
    if let Some(s) = &spec.sensor {
        crate::sensor::sensor_config(s.file.as_ref().map(|f| f.path.as_path()), &s.overrides)
            .map_err(|e| located(e, &s.spans, s.span))?;
    }
    if let Some(l) = &spec.lens {
        let model = crate::scene::camera_params::camera_model(
            l.file.as_ref().map(|f| f.path.as_path()),
            &l.overrides,
        )
        .map_err(|e| located(e, &l.spans, l.span))?;
        crate::optics::camera::check(&model)
            .map_err(|e| located(ParamError::section(e.to_string()), &l.spans, l.span))?;
    }
    let dir = spec.file.parent().unwrap_or(Path::new(""));
    for m in &spec.measures {
        check_measure(&m.kind, &m.params, dir).map_err(|e| located(e, &m.spans, m.span))?;
    }
    for a in &spec.additions {
        super::stages::target_spec(a, dir).map_err(|e| located(e, &a.spans, a.span))?;
    }
    if let Some(s) = &spec.sanity {
        crate::pov::check_params::pov_check(&s.params).map_err(|e| located(e, &s.spans, s.span))?;
    }
    for m in &spec.summaries {
        crate::summary::checked(&m.kind, &m.params, dir)
            .map_err(|e| located(e, &m.spans, m.span))?;
        if m.of.is_empty() {
            let e =
                ParamError::section(format!("summary \"{}\" needs of=\"<measurement>\"", m.kind))
                    .with_help("of= names the measurement whose rows it reads across the variants");
            return Err(located(e, &m.spans, m.span));
        }
    }
    for o in &spec.overrides {
        crate::scene::edits::check_override(&o.params, dir)
            .map_err(|e| located(e, &o.spans, o.span))?;
    }
    check_sampling(spec)?;
    // Each quality preset, applied as `camsim run --quality NAME` applies it.
    for q in &spec.qualities {
        let mut s = spec.clone();
        super::apply::apply_quality(&mut s, q, super::source::Loader::Disk)?;
        check_sampling(&s).map_err(|(sp, mut e)| {
            e.message = format!("quality \"{}\": {}", q.name, e.message);
            (sp, e)
        })?;
    }
    // The key holds everything `build_scene` reads but the camera pose (the
    // intersection check does not look through the camera).
    let key = serde_json::to_string(&(
        &spec.scene,
        &spec.scene_materials,
        &spec.additions,
        &spec.removals,
        &spec.overrides,
    ))
    .unwrap_or_default();
    if let Some(r) = memo.scenes.get(&key) {
        return r.clone();
    }
    let r = check_objects_stand_free(spec);
    memo.scenes.insert(key, r.clone());
    r
}

/// Error-driven sampling's settings: a budget, targets naming measurements
/// whose figures the render changes, a sample budget above the first round.
fn check_sampling(spec: &ResolvedExperiment) -> Result<(), (Span, ApplyError)> {
    let r = &spec.render;
    if !r.error_driven() {
        if r.max_s.is_some() || r.max_spp.is_some() {
            return Err((
                r.span,
                ApplyError::new("max-s and max-spp are budgets of error-driven sampling, which needs a target")
                    .help("add target-stderr=\"1%\" (or a `target \"MEASUREMENT\" stderr=…` child), or remove the budget"),
            ));
        }
        return Ok(());
    }
    if r.max_s.is_none() && r.max_spp.is_none() {
        return Err((
            r.span,
            ApplyError::new("a standard-error target needs a budget: max-s=… (seconds) or max-spp=… (samples per pixel)")
                .help("e.g. render spp=16 target-stderr=\"1%\" max-spp=1024 max-s=120"),
        ));
    }
    if let Some(m) = r.max_spp
        && m < r.spp
    {
        return Err((
            r.span,
            ApplyError::new(format!(
                "max-spp = {m} is below the first round's spp = {}",
                r.spp
            )),
        ));
    }
    for t in &r.targets {
        if !spec.measures.iter().any(|m| m.name == t.measurement) {
            let names: Vec<&str> = spec.measures.iter().map(|m| m.name.as_str()).collect();
            return Err((
                t.span,
                ApplyError::new(format!(
                    "target \"{}\": no measurement of that name; the experiment's: {}",
                    t.measurement,
                    names.join(", ")
                ))
                .help(
                    crate::diag::did_you_mean(&t.measurement, names.iter().copied())
                        .map(|s| format!("did you mean '{s}'?"))
                        .unwrap_or_else(|| "name a measurement of this experiment".into()),
                ),
            ));
        }
        if !super::sampling::depends_on_render(spec, &t.measurement) {
            return Err((
                t.span,
                ApplyError::new(format!(
                    "target \"{}\": its figures do not depend on the render (more samples cannot lower their standard error)",
                    t.measurement
                )),
            ));
        }
    }
    if !spec
        .measures
        .iter()
        .any(|m| super::sampling::depends_on_render(spec, &m.name))
    {
        return Err((
            r.span,
            ApplyError::new(
                "target-stderr: no measurement of this experiment depends on the render",
            ),
        ));
    }
    Ok(())
}

/// The scene with its edits, built as `run` builds it: no two objects may
/// intersect ([`crate::scene::intersections`]). The error points at the `add`
/// of an object involved, else at the `scene` node.
fn check_objects_stand_free(spec: &ResolvedExperiment) -> Result<(), (Span, ApplyError)> {
    let Some(f) = &spec.scene else {
        return Ok(());
    };
    let scene = super::stages::build_scene(spec)
        .map_err(|e| (f.span, ApplyError::new(format!("scene: {e}"))))?;
    let tol = crate::scene::intersections::DEFAULT_TOLERANCE_M;
    let Some(x) = crate::scene::intersections::intersecting_objects(&scene, tol)
        .into_iter()
        .next()
    else {
        return Ok(());
    };
    let added = spec
        .additions
        .iter()
        .find(|a| a.id == x.a || a.id == x.b || x.a.starts_with(&format!("{}/", a.id)))
        .or_else(|| {
            spec.additions
                .iter()
                .find(|a| x.b.starts_with(&format!("{}/", a.id)))
        });
    let span = added.map(|a| a.span).unwrap_or(f.span);
    Err((
        span,
        ApplyError::new(format!(
            "objects '{}' and '{}' intersect: one reaches {:.1} mm into the other (more than the {} mm of contact)",
            x.a,
            x.b,
            x.depth_m * 1e3,
            tol * 1e3
        ))
        .help("move or scale the added object so it stands free, or remove \"…\" a base-scene object"),
    ))
}

/// A measurement's options, built as `run` builds them.
fn check_measure(kind: &str, params: &Params, dir: &Path) -> Result<(), ParamError> {
    crate::measure::request::checked(kind, params, dir).map(|_| ())
}
