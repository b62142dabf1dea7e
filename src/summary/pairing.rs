//! Pairing one measurement's rows across variants: the rows are split by the
//! value of one swept axis (e.g. `tag.qe` = "nominal" / "corrected"), and
//! within each value keyed by the values of every *other* axis plus the
//! quantity, so rows of two axis values pair when they differ only in that
//! axis. Axes zipped with it (whose value follows from the axis value, e.g.
//! `sensor.file` beside `tag.qe`) are left out of that key. Quantities of the form `…patchNN/<channel>_mean` (what `measure
//! "mcc"` writes) also give the patch number and the channel.

use crate::report::results::ResultRow;
use crate::{Error, Result};
use std::collections::BTreeMap;

/// The points of one axis value, keyed by (group, quantity).
pub type Points = BTreeMap<(String, String), Point>;

/// Each axis value with its points, in order of first appearance.
pub type Split = Vec<(String, Points)>;

/// One value of the measurement in one variant.
#[derive(Clone, Debug, PartialEq)]
pub struct Point {
    /// The other axes' values, `name=value` joined by `,` (the pairing group).
    pub group: String,
    pub quantity: String,
    pub unit: String,
    pub value: f64,
    pub stderr: f64,
}

/// The rows of each value of `axis`, in order of first appearance; within a
/// value, keyed by (group, quantity). Errors: `axis` is not a swept column,
/// or a key repeats within one axis value (the axis does not separate them).
pub fn split_by_axis(
    summary: &str,
    axis: &str,
    axes: &[String],
    rows: &[&ResultRow],
) -> Result<Split> {
    if !axes.iter().any(|a| a == axis) {
        return Err(Error::invalid(format!(
            "summary '{summary}': axis '{axis}' is not swept in this experiment; swept: {}",
            if axes.is_empty() {
                "none".to_string()
            } else {
                axes.join(", ")
            }
        )));
    }
    let tied = tied_axes(axis, rows);
    let mut out: Split = vec![];
    for r in rows {
        let Some(av) = r.params.iter().find(|p| p.0 == axis).map(|p| p.1.clone()) else {
            continue;
        };
        let group = r
            .params
            .iter()
            .filter(|p| p.0 != axis && !tied.contains(&p.0))
            .map(|p| format!("{}={}", p.0, p.1))
            .collect::<Vec<_>>()
            .join(",");
        let i = match out.iter().position(|(v, _)| *v == av) {
            Some(i) => i,
            None => {
                out.push((av.clone(), BTreeMap::new()));
                out.len() - 1
            }
        };
        let key = (group.clone(), r.quantity.clone());
        if out[i].1.contains_key(&key) {
            return Err(Error::invalid(format!(
                "summary '{summary}': two rows of '{}' with {axis}={av} and {group}; the other axes must tell variants apart",
                r.quantity
            )));
        }
        out[i].1.insert(
            key,
            Point {
                group,
                quantity: r.quantity.clone(),
                unit: r.unit.clone(),
                value: r.value,
                stderr: r.stderr,
            },
        );
    }
    Ok(out)
}

/// Axes whose value follows from `axis`'s (one value per value of `axis`,
/// e.g. `sensor.file` zipped with `tag.qe`): they do not tell variants apart
/// for pairing, so they are left out of the group.
pub fn tied_axes(axis: &str, rows: &[&ResultRow]) -> Vec<String> {
    let mut seen: BTreeMap<(String, String), String> = BTreeMap::new();
    let mut untied: std::collections::BTreeSet<String> = Default::default();
    let mut names: Vec<String> = vec![];
    for r in rows {
        let Some(av) = r.params.iter().find(|p| p.0 == axis).map(|p| &p.1) else {
            continue;
        };
        for (k, v) in r.params.iter().filter(|p| p.0 != axis) {
            if !names.contains(k) {
                names.push(k.clone());
            }
            match seen.get(&(k.clone(), av.clone())) {
                Some(prev) if prev != v => {
                    untied.insert(k.clone());
                }
                Some(_) => {}
                None => {
                    seen.insert((k.clone(), av.clone()), v.clone());
                }
            }
        }
    }
    names.retain(|n| !untied.contains(n));
    names
}

/// The points of axis value `v` (an error naming the values present when absent).
pub fn points_of<'a>(
    summary: &str,
    axis: &str,
    split: &'a [(String, Points)],
    v: &str,
) -> Result<&'a Points> {
    split
        .iter()
        .find(|(a, _)| a == v)
        .map(|(_, m)| m)
        .ok_or_else(|| {
            Error::invalid(format!(
                "summary '{summary}': no variant has {axis}={v}; values present: {}",
                split
                    .iter()
                    .map(|(a, _)| a.as_str())
                    .collect::<Vec<_>>()
                    .join(", ")
            ))
        })
}

/// `(patch number, channel)` of a quantity `…patchNN/<channel>_mean`.
pub fn patch_channel(quantity: &str) -> Option<(usize, String)> {
    let (head, ch) = quantity.rsplit_once('/')?;
    let ch = ch.strip_suffix("_mean")?;
    let digits = head.rsplit_once("patch").map(|p| p.1)?;
    let n = digits.parse::<usize>().ok()?;
    Some((n, ch.to_string()))
}

/// The channel of a quantity for grouping plot series: `<channel>` of
/// `…/<channel>_mean`, else "all".
pub fn series_of(quantity: &str) -> String {
    quantity
        .rsplit_once('/')
        .map(|p| p.1)
        .unwrap_or(quantity)
        .strip_suffix("_mean")
        .map(str::to_string)
        .unwrap_or_else(|| "all".into())
}

#[cfg(test)]
mod tests {
    use super::*;

    #[test]
    fn patch_channel_reads_mcc_quantities() {
        assert_eq!(patch_channel("patch07/g_mean"), Some((7, "g".into())));
        assert_eq!(
            patch_channel("chart/patch24/b_mean"),
            Some((24, "b".into()))
        );
        assert_eq!(patch_channel("patch07/g_clipped_fraction"), None);
        assert_eq!(series_of("patch07/r_mean"), "r");
        assert_eq!(series_of("mtf50"), "all");
    }
}
