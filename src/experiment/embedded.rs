//! The default experiments compiled into the binary (`camsim run` without
//! arguments). Their paths are `CARGO_MANIFEST_DIR/experiments/<file>`, so the
//! scenes, lenses and sensors they reference are read from the source tree the
//! binary was built from; when that tree is gone, `camsim run` falls back to
//! `./experiments/` relative to the working directory (see
//! [`default_root`]). A test checks this list against the `experiments/`
//! directory, so a new experiment file cannot be forgotten here.

use std::path::{Path, PathBuf};

macro_rules! embed {
    ($p:literal) => {
        (
            $p,
            include_str!(concat!(env!("CARGO_MANIFEST_DIR"), "/experiments/", $p)),
        )
    };
}

/// (file name inside `experiments/`, contents)
pub const EXPERIMENTS: &[(&str, &str)] = &[
    embed!("convergence-ri.kdl"),
    embed!("convergence.kdl"),
    embed!("cornell-box.kdl"),
    embed!("e2e-quick.kdl"),
    embed!("fig03-qe-correction.kdl"),
    embed!("fig04-qualitative.kdl"),
    embed!("fig05-relative-illumination.kdl"),
    embed!("fig07-lsf-mtf.kdl"),
    embed!("fig08-sensor-noise.kdl"),
    embed!("fig09-interreflection.kdl"),
    embed!("fig10-chromatic.kdl"),
    embed!("fig11-conversion-gain.kdl"),
    embed!("rtf-vs-prescription.kdl"),
    embed!("smoke.kdl"),
    embed!("stability.kdl"),
    embed!("table1-sensor.kdl"),
];

/// The directory the embedded experiments pretend to live in.
pub fn default_root() -> PathBuf {
    let built = Path::new(env!("CARGO_MANIFEST_DIR"));
    if built.join("experiments").is_dir() || !Path::new("experiments").is_dir() {
        built.to_path_buf()
    } else {
        PathBuf::from(".")
    }
}

/// Paths of the embedded experiment files, under [`default_root`].
pub fn paths() -> Vec<PathBuf> {
    let root = default_root().join("experiments");
    EXPERIMENTS.iter().map(|(n, _)| root.join(n)).collect()
}

/// Contents of an embedded file addressed by its path (any root).
pub fn lookup(path: &Path) -> Option<&'static str> {
    let name = path.file_name()?.to_str()?;
    let parent = path.parent()?.file_name()?.to_str()?;
    if parent != "experiments" {
        return None;
    }
    EXPERIMENTS
        .iter()
        .find(|(n, _)| *n == name)
        .map(|(_, t)| *t)
}
