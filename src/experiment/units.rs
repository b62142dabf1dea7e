//! The unit rule of the experiment language: a property holding a number must
//! say its unit in its name (`exposure-s`, `film-distance-mm`, `position-m`).
//! Dimensionless quantities are either listed here by name (`spp`, `seed`,
//! `scale`, `f-number`, …) or end in a word that says they are pure numbers
//! (`-count`, `-ratio`, `-factor`, `-gain`, `-bits`, `-percent`, …).

/// Unit suffixes (after the last `-`, or the last two words for compound units).
pub const UNIT_SUFFIXES: &[&str] = &[
    "m",
    "mm",
    "um",
    "nm",
    "km",
    "s",
    "ms",
    "us",
    "ns",
    "deg",
    "rad",
    "sr",
    "dv",
    "dv2",
    "e",
    "v",
    "mv",
    "uv",
    "w",
    "k",
    "hz",
    "lux",
    "cd-m2",
    "w-m2",
    "w-m2-nm",
    "w-sr-m2-nm",
    "photons-s-m2-nm",
    "e-s",
    "v-s",
    "dv-e",
    "e-dv",
    "v-e",
    "uv-e",
    "cy-px",
    "cy-mm",
    "px",
    "lm",
    "db",
    // the unit of the curve a property applies to (compare-curve's x-range)
    "curve-unit",
];

/// Dimensionless property names.
pub const DIMENSIONLESS: &[&str] = &[
    "spp",
    "seed",
    "max-bounces",
    "scale",
    "f-number",
    "bit-depth",
    "iso",
    "threads",
    "degree",
    "rows",
    "cols",
    "width-px",
    "height-px",
    "gain",
    "analog-gain",
    "fill-factor",
    "count",
    "frames",
    "channel",
    "reflectance",
    "albedo",
    "index",
    "order",
    "ior",
    "up",
    "tilt",
    "weight",
    "batches",
    "samples",
    "exponent",
    "fraction",
    "quantile",
];

/// Words that mark a name as dimensionless when it ends with `-<word>`.
pub const DIMENSIONLESS_WORDS: &[&str] = &[
    "count",
    "percentile",
    "iou",
    "ratio",
    "factor",
    "gain",
    "bits",
    "percent",
    "fraction",
    "number",
    "index",
    "px",
    "spp",
    "level",
    "sigma",
    "scale",
    "order",
    "degree",
    "samples",
    "frames",
    "rows",
    "cols",
    "ior",
    "albedo",
    "reflectance",
    "weight",
    "seed",
    // a standard-error target is in each figure's own unit (or "N%")
    "stderr",
];

/// Does `name` carry a unit (or is it dimensionless by name)?
pub fn has_unit(name: &str) -> bool {
    let n = name.to_ascii_lowercase();
    if DIMENSIONLESS.contains(&n.as_str()) {
        return true;
    }
    for w in DIMENSIONLESS_WORDS {
        if n.ends_with(&format!("-{w}")) || n == *w {
            return true;
        }
    }
    UNIT_SUFFIXES.iter().any(|u| n.ends_with(&format!("-{u}")))
}

/// A suggested name with a unit for a bare name, e.g. `exposure` → `exposure-s`.
pub fn suggest_unit(name: &str) -> String {
    let n = name.to_ascii_lowercase();
    let unit = if n.contains("exposure") || n.contains("time") || n.contains("duration") {
        "s"
    } else if n.contains("wavelength") {
        "nm"
    } else if n.contains("film")
        || n.contains("focal")
        || n.contains("pitch")
        || n.contains("pixel")
    {
        "mm"
    } else if n.contains("angle") || n.contains("rotate") || n.contains("tilt") || n.contains("fov")
    {
        "deg"
    } else if n.contains("voltage") || n.contains("swing") {
        "v"
    } else if n.contains("well") || n.contains("noise") {
        "e"
    } else {
        "m"
    };
    format!("{n}-{unit}")
}

/// The help text for a number under a unit-less name.
pub fn unit_help(name: &str) -> String {
    format!(
        "write {}=…; units are part of every numeric name (-m, -mm, -um, -nm, -s, -deg, -e, -v, -dv, -w-sr-m2-nm, …)",
        suggest_unit(name)
    )
}

#[cfg(test)]
mod tests {
    use super::*;
    #[test]
    fn units_are_recognised() {
        assert!(has_unit("exposure-s"));
        assert!(has_unit("film-distance-mm"));
        assert!(has_unit("spp"));
        assert!(has_unit("prnu-percent"));
        assert!(!has_unit("exposure"));
        assert!(!has_unit("distance"));
        assert_eq!(suggest_unit("exposure"), "exposure-s");
    }
}
