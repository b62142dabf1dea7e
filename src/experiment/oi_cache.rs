//! The optical-image cache: a variant's optical image stored on disk under a
//! content hash of everything the render reads, so a sweep over sensor-only
//! settings (exposure, ISO, noise switches, gains, binning that keeps the
//! film) renders once.
//!
//! The key is a SHA-256 over: a format tag, camsim's version and a digest of
//! the running executable (a rebuilt camsim never reuses an older renderer's
//! images), the *built* scene (every object, mesh, material, light and the
//! camera pose after the experiment's add/remove/override edits — so the scene
//! file, its included files and meshes count through what they load to), the
//! camera model with the bytes of its lens file, the film (the sensor's rows,
//! cols and pixel pitch when it has them) and the render settings (spp,
//! bounces, seed, wavelength grid, batches, render window, and the sensor's
//! per-channel weights for the rendered standard error — those depend on the
//! sensor's QE and illuminance scale, so a QE sweep re-renders).
//!
//! Files: `<dir>/<hash>.bin` = magic, SHA-256 of the payload, payload length,
//! payload (the [`OpticalImage`] in postcard's encoding, which stores every
//! `f32`/`f64` as its raw bits: the round trip is bit-exact). Written
//! atomically; a file whose length, digest or decoding disagrees is reported
//! as a warning, removed and rendered again. After each store, the least
//! recently used files (modification time, touched on every hit) are removed
//! until the cache fits its size limit.

use crate::optical_image::OpticalImage;
use crate::render::RenderSettings;
use crate::scene::{CameraModel, FilmSpec, Scene};
use crate::{Error, Result};
use sha2::{Digest, Sha256};
use std::path::{Path, PathBuf};
use std::sync::OnceLock;

const MAGIC: &[u8; 12] = b"camsim-oi-1\n";
const HEADER: usize = MAGIC.len() + 32 + 8;

/// Default size limit of the cache (`camsim run --cache-max-gb`), in GB (10⁹ bytes).
pub const DEFAULT_MAX_GB: f64 = 4.0;

/// An optical-image cache directory with a size limit.
#[derive(Clone, Debug)]
pub struct OiCache {
    pub dir: PathBuf,
    pub max_bytes: u64,
}

/// Where a variant's optical image came from: `hit`, `miss` (rendered and
/// stored) or `off` (rendered, cache disabled).
#[derive(Clone, Debug, PartialEq)]
pub struct CacheUse {
    pub status: &'static str,
    pub hash: String,
}

/// A digest of the running executable (read once per process): images
/// rendered by another build of camsim are never reused.
fn build_digest() -> &'static [u8] {
    static D: OnceLock<Vec<u8>> = OnceLock::new();
    D.get_or_init(|| {
        std::env::current_exe()
            .and_then(std::fs::read)
            .map(|b| Sha256::digest(&b).to_vec())
            .unwrap_or_else(|_| b"<no executable>".to_vec())
    })
}

fn encode<T: serde::Serialize>(what: &str, v: &T) -> Result<Vec<u8>> {
    postcard::to_stdvec(v).map_err(|e| Error::invalid(format!("oi cache: encoding {what}: {e}")))
}

/// The cache key (hex SHA-256) of a render of `scene` through `model` on
/// `film` with `settings`.
pub fn key(
    scene: &Scene,
    model: &CameraModel,
    film: &FilmSpec,
    settings: &RenderSettings,
) -> Result<String> {
    let mut h = Sha256::new();
    let mut part = |name: &str, bytes: &[u8]| {
        h.update(name.as_bytes());
        h.update((bytes.len() as u64).to_le_bytes());
        h.update(bytes);
    };
    part("format", MAGIC);
    part("version", crate::version().as_bytes());
    part("build", build_digest());
    part("scene", &encode("the scene", scene)?);
    part("camera", &encode("the camera model", model)?);
    if let CameraModel::LensFile { path, .. } = model {
        let b = std::fs::read(path).map_err(|e| Error::io(path, e))?;
        part("lens-file", &Sha256::digest(&b));
    }
    part("film", &encode("the film", film)?);
    // Thread count never changes the image (bit-identical for any count).
    let s = RenderSettings {
        threads: 0,
        ..settings.clone()
    };
    part("settings", &encode("the render settings", &s)?);
    Ok(hex::encode(h.finalize()))
}

impl OiCache {
    pub fn new(dir: impl Into<PathBuf>, max_gb: f64) -> Self {
        Self {
            dir: dir.into(),
            max_bytes: (max_gb * 1e9) as u64,
        }
    }

    /// The cache of a run writing under `out`: `<out>/.cache/optical-images`.
    pub fn under(out: &Path, max_gb: f64) -> Self {
        Self::new(out.join(".cache").join("optical-images"), max_gb)
    }

    pub fn file(&self, key: &str) -> PathBuf {
        self.dir.join(format!("{key}.bin"))
    }

    /// The cached image of `key`, if a sound one exists. A damaged file is
    /// reported on stderr, removed, and treated as absent.
    pub fn load(&self, key: &str) -> Option<OpticalImage> {
        let p = self.file(key);
        let bytes = match std::fs::read(&p) {
            Ok(b) => b,
            Err(e) if e.kind() == std::io::ErrorKind::NotFound => return None,
            Err(e) => {
                eprintln!(
                    "warning: optical-image cache file {} unreadable ({e}); rendering again",
                    p.display()
                );
                return None;
            }
        };
        match decode(&bytes) {
            Ok(oi) => {
                // Mark as recently used for the size limit's eviction order.
                if let Ok(f) = std::fs::File::options().write(true).open(&p) {
                    let _ = f.set_modified(std::time::SystemTime::now());
                }
                Some(oi)
            }
            Err(why) => {
                eprintln!(
                    "warning: optical-image cache file {} is damaged ({why}); removed, rendering again",
                    p.display()
                );
                let _ = std::fs::remove_file(&p);
                None
            }
        }
    }

    /// Store `oi` under `key` (atomically), then evict to the size limit.
    /// An image larger than the whole limit is not written (returns false).
    pub fn store(&self, key: &str, oi: &OpticalImage) -> Result<bool> {
        let payload = encode("the optical image", oi)?;
        if (HEADER + payload.len()) as u64 > self.max_bytes {
            return Ok(false);
        }
        let mut bytes = Vec::with_capacity(HEADER + payload.len());
        bytes.extend_from_slice(MAGIC);
        bytes.extend_from_slice(&Sha256::digest(&payload));
        bytes.extend_from_slice(&(payload.len() as u64).to_le_bytes());
        bytes.extend_from_slice(&payload);
        crate::diag::write_atomic(&self.file(key), &bytes)?;
        self.evict();
        Ok(true)
    }

    /// Remove least recently used `.bin` files until the total fits `max_bytes`.
    pub fn evict(&self) {
        let Ok(rd) = std::fs::read_dir(&self.dir) else {
            return;
        };
        let mut files: Vec<(std::time::SystemTime, PathBuf, u64)> = rd
            .filter_map(|e| e.ok())
            .filter(|e| e.path().extension().is_some_and(|x| x == "bin"))
            .filter_map(|e| {
                let m = e.metadata().ok()?;
                Some((m.modified().ok()?, e.path(), m.len()))
            })
            .collect();
        let mut total: u64 = files.iter().map(|f| f.2).sum();
        files.sort();
        for (_, p, len) in files {
            if total <= self.max_bytes {
                break;
            }
            if std::fs::remove_file(&p).is_ok() {
                total -= len;
            }
        }
    }
}

/// Check and decode a cache file's bytes.
fn decode(bytes: &[u8]) -> std::result::Result<OpticalImage, String> {
    if bytes.len() < HEADER || &bytes[..MAGIC.len()] != MAGIC {
        return Err("not a camsim optical-image cache file".into());
    }
    let digest = &bytes[MAGIC.len()..MAGIC.len() + 32];
    let mut n = [0u8; 8];
    n.copy_from_slice(&bytes[MAGIC.len() + 32..HEADER]);
    let n = u64::from_le_bytes(n);
    let payload = &bytes[HEADER..];
    if payload.len() as u64 != n {
        return Err(format!(
            "{} payload bytes, header says {n} (truncated?)",
            payload.len()
        ));
    }
    if Sha256::digest(payload).as_slice() != digest {
        return Err("payload digest mismatch".into());
    }
    postcard::from_bytes(payload).map_err(|e| format!("undecodable payload: {e}"))
}

#[cfg(test)]
mod tests {
    use super::*;
    use crate::optical_image::Rect;
    use crate::spectrum::WavelengthGrid;

    fn image() -> OpticalImage {
        let grid = WavelengthGrid::new(400.0, 700.0, 100.0).unwrap();
        let mut oi = OpticalImage::new(4, 3, Rect::new(1, 0, 2, 3), 1.4e-6, grid);
        for (i, v) in oi.irradiance.iter_mut().enumerate() {
            *v = (i as f32 * 0.1).sin() * 1e-7 + f32::MIN_POSITIVE * i as f32;
        }
        oi.irradiance[1] = f32::NAN;
        oi.stderr = oi.irradiance.iter().map(|v| v * 0.01).collect();
        oi.weighted_stderr = vec![0.25, 1e-30, 3.0];
        oi.labels = vec![0, 1, crate::scene::NO_OBJECT, 0, 1, 1];
        oi.label_names = vec!["a".into(), "édge".into()];
        oi.depth_m[2] = 1.5;
        oi.spp = 17;
        oi.render_s = 0.123456789;
        oi.nan_count = 3;
        oi
    }

    fn same(a: &OpticalImage, b: &OpticalImage) -> bool {
        let bits = |v: &[f32]| v.iter().map(|x| x.to_bits()).collect::<Vec<_>>();
        a.full_width == b.full_width
            && a.full_height == b.full_height
            && a.window == b.window
            && a.pixel_pitch_m.to_bits() == b.pixel_pitch_m.to_bits()
            && a.grid == b.grid
            && bits(&a.irradiance) == bits(&b.irradiance)
            && bits(&a.stderr) == bits(&b.stderr)
            && bits(&a.weighted_stderr) == bits(&b.weighted_stderr)
            && a.labels == b.labels
            && a.label_names == b.label_names
            && bits(&a.depth_m) == bits(&b.depth_m)
            && a.spp == b.spp
            && a.render_s.to_bits() == b.render_s.to_bits()
            && a.nan_count == b.nan_count
    }

    #[test]
    fn round_trip_is_bit_exact_and_damage_is_detected() {
        let dir = tempfile::tempdir().unwrap();
        let c = OiCache::new(dir.path(), 1.0);
        let oi = image();
        assert!(c.store("k", &oi).unwrap());
        // Larger than the whole limit: not written.
        let tiny = OiCache {
            dir: dir.path().join("tiny"),
            max_bytes: 100,
        };
        assert!(!tiny.store("k", &oi).unwrap());
        assert!(!tiny.file("k").exists());
        let back = c.load("k").expect("stored image loads");
        assert!(same(&oi, &back));
        // Truncated: detected, removed, absent.
        let p = c.file("k");
        let b = std::fs::read(&p).unwrap();
        std::fs::write(&p, &b[..b.len() - 5]).unwrap();
        assert!(c.load("k").is_none());
        assert!(!p.exists());
        // One flipped payload bit: digest mismatch.
        let mut b2 = b.clone();
        let last = b2.len() - 1;
        b2[last] ^= 1;
        std::fs::write(&p, &b2).unwrap();
        assert!(decode(&b2).unwrap_err().contains("digest"));
        assert!(c.load("k").is_none());
    }

    #[test]
    fn eviction_keeps_the_most_recently_used() {
        let dir = tempfile::tempdir().unwrap();
        let oi = image();
        let size = {
            let c = OiCache::new(dir.path(), 1.0);
            c.store("probe", &oi).unwrap();
            let n = std::fs::metadata(c.file("probe")).unwrap().len();
            std::fs::remove_file(c.file("probe")).unwrap();
            n
        };
        // Room for two files, not three.
        let c = OiCache {
            dir: dir.path().into(),
            max_bytes: 2 * size + size / 2,
        };
        let t0 = std::time::SystemTime::now();
        for (k, age_s) in [("a", 30), ("b", 20)] {
            c.store(k, &oi).unwrap();
            let f = std::fs::File::options()
                .write(true)
                .open(c.file(k))
                .unwrap();
            f.set_modified(t0 - std::time::Duration::from_secs(age_s))
                .unwrap();
        }
        // A hit on "a" makes "b" the least recently used.
        assert!(c.load("a").is_some());
        c.store("c", &oi).unwrap();
        assert!(c.file("a").exists());
        assert!(!c.file("b").exists());
        assert!(c.file("c").exists());
    }
}
