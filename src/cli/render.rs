use camsim::{Error, Result};
use clap::Args;
use std::path::PathBuf;

#[derive(Args)]
pub struct RenderArgs {
    /// Scene file (pbrt or KDL).
    pub scene: PathBuf,
    #[arg(long)]
    pub spp: Option<u32>,
    #[arg(long)]
    pub threads: Option<usize>,
    /// Render only this pixel rectangle: x,y,w,h.
    #[arg(long)]
    pub roi: Option<String>,
    #[arg(long, default_value = "render.exr")]
    pub out: PathBuf,
    #[arg(long)]
    pub seed: Option<u64>,
}

#[derive(Args)]
pub struct BenchArgs {
    /// Which benchmark: render, parse, sensor.
    pub which: String,
}

pub fn render(_a: RenderArgs) -> Result<i32> {
    Err(Error::NotSupported("render".into()))
}
pub fn bench(a: BenchArgs) -> Result<i32> {
    if a.which == "parse" {
        return super::scene::bench_parse();
    }
    Err(Error::NotSupported("bench".into()))
}
