//! Where camsim deliberately differs from pbrt when it renders a pbrt file,
//! one line each (`camsim scene info` prints them under
//! `differences_from_pbrt`).

use super::LoadedScene;
use super::dialect::PbrtVersion;

/// The deliberate differences that apply to this scene.
pub fn differences_from_pbrt(l: &LoadedScene) -> Vec<String> {
    let mut d = vec![
        "integrator: camsim's own spectral path tracer (next-event estimation with MIS, \
         Russian roulette, 6 bounces unless `render --max-bounces`); the file's Integrator, \
         Sampler and PixelFilter and their parameters (maxdepth, pixelsamples) are not read"
            .to_string(),
        "film quantity: physical irradiance at the sensor, W/(m²·nm), with the lens's \
         f-number and cos⁴θ fall-off (a perspective pinhole is f/0.886, so E = L on axis); \
         pbrt records radiance — `render --film radiance` gives pbrt's quantity in W/(sr·m²·nm)"
            .to_string(),
        "film scale: spectral values are radiometric (W/(sr·m²·nm) for pbrt-v4's normalised \
         numbers); pbrt-v4's spectral film stores them × ∫ȳ = 106.856895, so divide a pbrt-v4 \
         spectral EXR by 106.856895 to compare"
            .to_string(),
        "spectral grid: camsim's bands (400–700 nm every 10 nm) unless a spectral Film sets \
         nbuckets/lambdamin/lambdamax (pbrt-v4's own default is 16 buckets over 360–830 nm); \
         each bucket is the mean of sub-bands ≤ 2.5 nm wide sampled at their centres (`camsim \
         render`), where pbrt averages over it with random wavelengths"
            .to_string(),
    ];
    d.push(match l.dialect.version {
        PbrtVersion::V4 => format!(
            "lights: pbrt-v4 photometric normalisation (spectrum / ∫ȳS per unit scale); file read as {}",
            l.dialect.reason
        ),
        PbrtVersion::V3 => format!(
            "lights: pbrt-v3 meaning, spectra × scale taken literally (no photometric \
             normalisation); file read as {}",
            l.dialect.reason
        ),
    });
    d.push(
        "shapes: a ReverseOrientation sphere (facing inwards) and every cylinder are \
         triangle meshes (96 segments per turn); partial spheres and disks are full"
            .to_string(),
    );
    d
}
