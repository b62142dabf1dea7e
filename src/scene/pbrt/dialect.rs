//! Which pbrt version a scene file is written for, decided by its syntax.
//!
//! The two versions give an emitter's numbers different meanings: pbrt-v4
//! normalises every emission spectrum photometrically (divides by ∫ȳS, so a
//! light of `scale` 1 has luminance 1 nit), pbrt-v3 takes `L`/`I` literally
//! (radiance in its units; an `rgb` white has luminance 1). camsim reads a
//! file with the meaning of the version it is written in:
//!
//! - pbrt-v3 markers: `WorldEnd`, `TransformBegin`/`TransformEnd`, a `color`
//!   parameter, `Film "image"`, `Integrator "directlighting"`/`"whitted"`,
//!   the v3 materials `matte`, `uber`, `plastic`, `metal`, `glass`,
//!   `substrate`, `translucent`, `kdsubsurface`, `fourier`, `disney`.
//! - pbrt-v4 markers: `ColorSpace`, `Option`, `Attribute`, `Film "rgb"`/
//!   `"spectral"`/`"gbuffer"`, the v4 materials `diffuse`, `coateddiffuse`,
//!   `coatedconductor`, `conductor`, `dielectric`, `thindielectric`,
//!   `diffusetransmission`.
//!
//! Only v3 markers → pbrt-v3; anything else (v4 markers, both, or none) →
//! pbrt-v4, which camsim's parser implements. Only the top-level file is
//! scanned (included files usually hold geometry and materials, the Film
//! and Integrator that tell the version are in the main file). A caller can
//! override the decision (`--pbrt-version`).

use super::lexer::{Lexer, TokenKind};

/// A pbrt scene-language version.
#[derive(Clone, Copy, Debug, PartialEq, Eq, clap::ValueEnum, serde::Serialize)]
pub enum PbrtVersion {
    /// pbrt-v3: emission spectra are literal.
    V3,
    /// pbrt-v4: emission spectra are normalised to 1 nit per unit `scale`.
    V4,
}

/// The version used for a file and why.
#[derive(Clone, Debug, PartialEq, Eq)]
pub struct Dialect {
    pub version: PbrtVersion,
    /// One line: how it was decided, e.g. `pbrt-v3 (syntax: Film "image" at line 5)`.
    pub reason: String,
}

impl Default for Dialect {
    fn default() -> Self {
        Self {
            version: PbrtVersion::V4,
            reason: "pbrt-v4 (default)".into(),
        }
    }
}

const V3_MATERIALS: &[&str] = &[
    "matte",
    "uber",
    "plastic",
    "metal",
    "glass",
    "substrate",
    "translucent",
    "kdsubsurface",
    "fourier",
    "disney",
];
const V4_MATERIALS: &[&str] = &[
    "diffuse",
    "coateddiffuse",
    "coatedconductor",
    "conductor",
    "dielectric",
    "thindielectric",
    "diffusetransmission",
];

/// Decide the version of `text` (a scene file's contents), or take `forced`.
pub fn decide(text: &str, forced: Option<PbrtVersion>) -> Dialect {
    if let Some(v) = forced {
        return Dialect {
            version: v,
            reason: format!("{} (set by the caller)", name(v)),
        };
    }
    let (v3, v4) = scan(text);
    let line = |off: usize| text[..off.min(text.len())].matches('\n').count() + 1;
    match (v3, v4) {
        (Some((what, at)), None) => Dialect {
            version: PbrtVersion::V3,
            reason: format!("pbrt-v3 (syntax: {what} at line {})", line(at)),
        },
        (None, Some((what, at))) => Dialect {
            version: PbrtVersion::V4,
            reason: format!("pbrt-v4 (syntax: {what} at line {})", line(at)),
        },
        (Some((w3, a3)), Some((w4, a4))) => Dialect {
            version: PbrtVersion::V4,
            reason: format!(
                "pbrt-v4 (mixed syntax: {w3} at line {}, {w4} at line {}; read as pbrt-v4)",
                line(a3),
                line(a4)
            ),
        },
        (None, None) => Dialect {
            version: PbrtVersion::V4,
            reason: "pbrt-v4 (no version-specific syntax; default)".into(),
        },
    }
}

fn name(v: PbrtVersion) -> &'static str {
    match v {
        PbrtVersion::V3 => "pbrt-v3",
        PbrtVersion::V4 => "pbrt-v4",
    }
}

type Mark = Option<(String, usize)>;

/// First v3 and first v4 marker (description, byte offset).
fn scan(text: &str) -> (Mark, Mark) {
    let src = text.as_bytes();
    let mut lx = Lexer::new(0);
    let (mut v3, mut v4): (Mark, Mark) = (None, None);
    let mut directive = String::new();
    // The string right after a directive is its type; after "string type", a
    // MakeNamedMaterial's type.
    let (mut expect_type, mut expect_named_type) = (false, false);
    while let Ok(Some(t)) = lx.next_token(src) {
        let s = &text[t.span.start..t.span.end];
        match t.kind {
            TokenKind::Word if t.num.is_none() => {
                directive = s.to_string();
                expect_type = true;
                expect_named_type = false;
                let mark = match s {
                    "WorldEnd" | "TransformBegin" | "TransformEnd" => Some(3),
                    "ColorSpace" | "Option" | "Attribute" => Some(4),
                    _ => None,
                };
                match mark {
                    Some(3) if v3.is_none() => v3 = Some((s.to_string(), t.span.start)),
                    Some(4) if v4.is_none() => v4 = Some((s.to_string(), t.span.start)),
                    _ => {}
                }
            }
            TokenKind::Str { .. } => {
                let first = std::mem::take(&mut expect_type);
                let named = std::mem::take(&mut expect_named_type);
                let ty = if first || named { Some(s) } else { None };
                let what = |k: &str| format!("{} \"{k}\"", directive);
                if let Some(ty) = ty {
                    let is_material = directive == "Material" || named;
                    let v = match (directive.as_str(), ty) {
                        ("Film", "image") => Some(3),
                        ("Film", "rgb" | "spectral" | "gbuffer") => Some(4),
                        ("Integrator", "directlighting" | "whitted") => Some(3),
                        _ if is_material && V3_MATERIALS.contains(&ty) => Some(3),
                        _ if is_material && V4_MATERIALS.contains(&ty) => Some(4),
                        _ => None,
                    };
                    match v {
                        Some(3) if v3.is_none() => v3 = Some((what(ty), t.span.start)),
                        Some(4) if v4.is_none() => v4 = Some((what(ty), t.span.start)),
                        _ => {}
                    }
                    if !first || directive != "MakeNamedMaterial" {
                        continue;
                    }
                }
                // Parameter declaration "type name".
                let mut it = s.split_whitespace();
                if let (Some(pt), Some(_)) = (it.next(), it.next()) {
                    if pt == "color" && v3.is_none() {
                        v3 = Some(("a \"color\" parameter".into(), t.span.start));
                    }
                    if s == "string type" && directive == "MakeNamedMaterial" {
                        expect_named_type = true;
                    }
                }
            }
            TokenKind::LBracket => {}
            _ => {
                expect_type = false;
                expect_named_type = false;
            }
        }
    }
    (v3, v4)
}

#[cfg(test)]
mod tests {
    use super::*;

    #[test]
    fn versions_from_syntax() {
        let v3 = "Film \"image\" \"integer xresolution\" [4]\nWorldBegin\nWorldEnd\n";
        let d = decide(v3, None);
        assert_eq!(d.version, PbrtVersion::V3);
        assert!(
            d.reason.contains("Film \"image\" at line 1"),
            "{}",
            d.reason
        );
        let v4 = "Film \"rgb\"\nWorldBegin\nMaterial \"diffuse\"\n";
        assert_eq!(decide(v4, None).version, PbrtVersion::V4);
        let named = "WorldBegin\nMakeNamedMaterial \"a\" \"string type\" [ \"matte\" ] \"rgb Kd\" [1 1 1]\n";
        let d = decide(named, None);
        assert_eq!(d.version, PbrtVersion::V3);
        assert!(d.reason.contains("\"matte\" at line 2"), "{}", d.reason);
        let color = "WorldBegin\nMaterial \"mix\" \"color Kd\" [1 1 1]\n";
        assert_eq!(decide(color, None).version, PbrtVersion::V3);
        // An area light "diffuse" is not a material: no marker.
        let none = "WorldBegin\nAreaLightSource \"diffuse\" \"rgb L\" [1 1 1]\n";
        let d = decide(none, None);
        assert_eq!(d.version, PbrtVersion::V4);
        assert!(d.reason.contains("default"), "{}", d.reason);
        let mixed = "Film \"image\"\nColorSpace \"srgb\"\n";
        let d = decide(mixed, None);
        assert_eq!(d.version, PbrtVersion::V4);
        assert!(d.reason.contains("mixed"), "{}", d.reason);
        let d = decide(v4, Some(PbrtVersion::V3));
        assert_eq!(d.version, PbrtVersion::V3);
        assert!(d.reason.contains("set by the caller"));
    }
}
