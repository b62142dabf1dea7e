//! `camsim pov SCENE --out FILE.pov [--png FILE.png]`: the geometry sanity
//! export (see `camsim::pov`).

use camsim::{Error, Result};
use clap::Args;
use std::path::{Path, PathBuf};

#[derive(Args)]
pub struct PovArgs {
    /// Scene file (.kdl or .pbrt).
    pub scene: PathBuf,
    /// POV-Ray scene file to write.
    #[arg(long)]
    pub out: PathBuf,
    /// Also render it with `povray` to this PNG.
    #[arg(long)]
    pub png: Option<PathBuf>,
}

/// Load a KDL or pbrt scene with its own camera and film.
pub fn load_scene(path: &Path) -> Result<camsim::scene::Scene> {
    match path.extension().and_then(|e| e.to_str()).unwrap_or("") {
        "kdl" => Ok(camsim::scene::kdl_scene::load_kdl_scene(path)?.scene),
        "pbrt" | "gz" => {
            camsim::scene::pbrt::load(path, &camsim::scene::pbrt::LoadOptions::default())
        }
        _ => Err(Error::invalid(format!(
            "{}: unknown scene format (expected .kdl or .pbrt)",
            path.display()
        ))),
    }
}

pub fn pov(a: PovArgs) -> Result<i32> {
    let scene = load_scene(&a.scene)?;
    let film = scene.film.clone().unwrap_or_default();
    camsim::pov::export_and_render(&scene, &film, &a.out, a.png.as_deref())?;
    println!("{}", a.out.display());
    if let Some(p) = &a.png {
        println!("{}", p.display());
    }
    Ok(0)
}
