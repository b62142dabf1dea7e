//! Running the `povray` binary (Debian package `povray`, POV-Ray 3.7)
//! headless.
//!
//! POV-Ray's I/O security (Debian's `/etc/povray/3.7/povray.conf`) only lets
//! it read and write below the working directory and /tmp, so every render
//! happens in a fresh temporary directory with relative file names, and the
//! PNG is read back from there.

use crate::{Error, Result};
use std::path::Path;

/// The one line a user without POV-Ray sees.
pub const NOT_INSTALLED: &str =
    "povray is not installed: install it with `apt-get install povray` (needed by `camsim pov`)";

/// True when a `povray` binary runs.
pub fn available() -> bool {
    std::process::Command::new("povray")
        .arg("--version")
        .stdout(std::process::Stdio::null())
        .stderr(std::process::Stdio::null())
        .status()
        .is_ok()
}

/// How to render.
#[derive(Clone, Copy, Debug, PartialEq, Eq)]
pub enum Mode {
    /// Exactly one ray through each pixel centre (no antialiasing) and
    /// `File_Gamma=1.0` (no transfer curve), so flat label colours come back
    /// byte for byte.
    Labels,
    /// Antialiased, sRGB-encoded: a picture to look at.
    Preview,
}

/// Render POV-Ray scene text to an 8-bit RGB PNG of `width` × `height` and
/// return the PNG bytes.
pub fn render_png(pov_text: &str, width: u32, height: u32, mode: Mode) -> Result<Vec<u8>> {
    if width == 0 || height == 0 {
        return Err(Error::invalid(format!(
            "POV-Ray image size {width}×{height} is empty"
        )));
    }
    let dir = tempfile::Builder::new()
        .prefix("camsim-pov")
        .tempdir()
        .map_err(|e| Error::io(&std::env::temp_dir(), e))?;
    let pov = dir.path().join("scene.pov");
    std::fs::write(&pov, pov_text).map_err(|e| Error::io(&pov, e))?;
    let mut cmd = std::process::Command::new("povray");
    cmd.current_dir(dir.path())
        .arg("+Iscene.pov")
        .arg("+Oscene.png")
        .arg(format!("+W{width}"))
        .arg(format!("+H{height}"))
        .args(["+FN8", "-UA", "-D", "-V", "-P"]);
    match mode {
        Mode::Labels => cmd.args(["-A", "File_Gamma=1.0"]),
        Mode::Preview => cmd.arg("+A0.1"),
    };
    let out = match cmd.output() {
        Ok(o) => o,
        Err(e) if e.kind() == std::io::ErrorKind::NotFound => {
            return Err(Error::invalid(NOT_INSTALLED));
        }
        Err(e) => return Err(Error::invalid(format!("cannot run povray: {e}"))),
    };
    let png = dir.path().join("scene.png");
    if !out.status.success() || !png.exists() {
        let err = String::from_utf8_lossy(&out.stderr);
        let tail: Vec<&str> = err
            .lines()
            .filter(|l| !l.trim().is_empty())
            .rev()
            .take(6)
            .collect();
        return Err(Error::invalid(format!(
            "povray failed ({}): {}",
            out.status,
            tail.into_iter().rev().collect::<Vec<_>>().join(" | ")
        )));
    }
    std::fs::read(&png).map_err(|e| Error::io(&png, e))
}

/// Decode an 8-bit (or 16-bit) RGB/RGBA PNG into width, height and RGB bytes
/// (16-bit samples keep their high byte).
pub fn decode_rgb8(bytes: &[u8], what: &Path) -> Result<(u32, u32, Vec<[u8; 3]>)> {
    let bad = |e: &dyn std::fmt::Display| Error::io(what, format!("not a readable PNG: {e}"));
    let dec = png::Decoder::new(std::io::Cursor::new(bytes));
    let mut r = dec.read_info().map_err(|e| bad(&e))?;
    let size = r
        .output_buffer_size()
        .ok_or_else(|| bad(&"image too large"))?;
    let mut buf = vec![0; size];
    let info = r.next_frame(&mut buf).map_err(|e| bad(&e))?;
    let ch = info.color_type.samples();
    let bpc = if info.bit_depth == png::BitDepth::Sixteen {
        2
    } else {
        1
    };
    if ch < 3
        || !matches!(
            info.bit_depth,
            png::BitDepth::Eight | png::BitDepth::Sixteen
        )
    {
        return Err(bad(&format!(
            "expected 8- or 16-bit RGB, found {:?} {:?}",
            info.color_type, info.bit_depth
        )));
    }
    let (w, h) = (info.width, info.height);
    let stride = info.line_size;
    let mut px = Vec::with_capacity(w as usize * h as usize);
    for y in 0..h as usize {
        let row = &buf[y * stride..];
        for x in 0..w as usize {
            let i = x * ch * bpc;
            px.push([row[i], row[i + bpc], row[i + 2 * bpc]]);
        }
    }
    Ok((w, h, px))
}
