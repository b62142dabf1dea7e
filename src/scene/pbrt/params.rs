//! Typed parameter lists (`"float fov" [45]`) and their conversion to numbers,
//! strings and spectra.
//!
//! Decisions where pbrt leaves room:
//! - A duplicated parameter name: the last one wins (the earlier is dropped with a warning).
//! - A parameter that the directive never reads: a warning, an error with `--strict`.
//! - A lookup with the wrong type (`"string fov"` where a float is read) is an error.
//! - `rgb` → spectrum: pbrt-v4 fits a sigmoid-polynomial per colour from a table.
//!   camsim uses a smooth three-band partition of unity instead:
//!   `S(λ) = r·R(λ) + g·G(λ) + b·B(λ)` with `B = 1 − σ((λ−490)/w)`,
//!   `R = σ((λ−590)/w)`, `G = 1 − R − B`, `σ` the logistic function, `w = 12 nm`.
//!   The bands are non-negative and sum to one, so a reflectance rgb in [0, 1] gives a
//!   spectrum in [0, 1], a grey `(g, g, g)` gives exactly the flat spectrum `g`, and
//!   the map is linear, so pbrt's "unbounded" variant (scale·S(rgb/scale)) is the same
//!   function. The illuminant variant multiplies by the colour space's white
//!   (sRGB: CIE D65, normalised to luminance Y = 1 as pbrt's named illuminants are).
//! - `blackbody` is Planck's law normalised to a peak of 1 (pbrt-v4); the pbrt-v3
//!   form `[T scale]` is accepted with a warning.
//! - Named spectra: `stdillum-D65`, `stdillum-A`, `stdillum-F2` map to the shipped CIE
//!   tables (normalised to Y = 1); `glass-BK7`, `glass-BAF10`, `glass-F11`… are
//!   computed from their Sellmeier coefficients (Schott catalogue; only BK7 and
//!   fused silica are built in); any other pbrt name (metals, other illuminants)
//!   gives a warning and the caller's fallback. Shipped camsim names (`cbox-lamp`,
//!   `mcc-mini-04`, …) are accepted too.
//! - A spectrum file (`"spectrum Kd" "file.spd"`) holds `λ value` pairs, `#` comments
//!   allowed, and is resolved against the top-level scene directory.

use super::lexer::Span;
use crate::spectrum::{Extrapolation, Spectrum, WavelengthGrid};
use std::cell::Cell;
use std::path::{Path, PathBuf};

/// An error or warning at a source span (converted to `diag::Located` by the parser).
#[derive(Clone, Debug, PartialEq)]
pub struct SpanError {
    pub span: Span,
    pub message: String,
    pub help: Option<String>,
}

impl SpanError {
    pub fn new(span: Span, message: impl Into<String>) -> Self {
        Self {
            span,
            message: message.into(),
            help: None,
        }
    }
}

pub type PResult<T> = Result<T, SpanError>;

/// Warnings collected while loading; with `strict`, the first warning is an error.
#[derive(Debug, Default)]
pub struct Ctx {
    pub strict: bool,
    /// Directory of the top-level scene file (pbrt-v4 resolves relative paths against it).
    pub base_dir: PathBuf,
    pub warnings: Vec<SpanError>,
    /// The pbrt version the file is read as (light normalisation).
    pub dialect: super::dialect::Dialect,
}

impl Ctx {
    /// Record a warning (an error with `--strict`).
    pub fn warn(&mut self, span: Span, message: impl Into<String>) -> PResult<()> {
        let e = SpanError::new(span, message);
        if self.strict {
            return Err(SpanError {
                message: format!("{} (an error with --strict)", e.message),
                ..e
            });
        }
        self.warnings.push(e);
        Ok(())
    }
    pub fn resolve_path(&self, p: &str) -> PathBuf {
        let path = Path::new(p);
        if path.is_absolute() {
            path.to_path_buf()
        } else {
            self.base_dir.join(path)
        }
    }
}

/// Parameter types. pbrt-v3 aliases (`point`, `vector`, `normal`, `color`) map to
/// the v4 types.
#[derive(Clone, Copy, Debug, PartialEq, Eq)]
pub enum ParamType {
    Integer,
    Float,
    Bool,
    String,
    Point2,
    Vector2,
    Point3,
    Vector3,
    Normal,
    Rgb,
    Blackbody,
    Spectrum,
    Texture,
}

pub const TYPE_NAMES: &[&str] = &[
    "integer",
    "float",
    "bool",
    "string",
    "point2",
    "vector2",
    "point3",
    "vector3",
    "normal",
    "normal3",
    "rgb",
    "blackbody",
    "spectrum",
    "texture",
    "point",
    "vector",
    "color",
];

impl ParamType {
    pub fn parse(s: &str) -> Option<(Self, bool)> {
        use ParamType::*;
        // (type, is a pbrt-v3 alias)
        Some(match s {
            "integer" => (Integer, false),
            "float" => (Float, false),
            "bool" => (Bool, false),
            "string" => (String, false),
            "point2" => (Point2, false),
            "vector2" => (Vector2, false),
            "point3" => (Point3, false),
            "vector3" => (Vector3, false),
            "normal" | "normal3" => (Normal, false),
            "rgb" => (Rgb, false),
            "blackbody" => (Blackbody, false),
            "spectrum" => (Spectrum, false),
            "texture" => (Texture, false),
            "point" => (Point3, true),
            "vector" => (Vector3, true),
            "color" => (Rgb, true),
            _ => return None,
        })
    }
    pub fn name(self) -> &'static str {
        use ParamType::*;
        match self {
            Integer => "integer",
            Float => "float",
            Bool => "bool",
            String => "string",
            Point2 => "point2",
            Vector2 => "vector2",
            Point3 => "point3",
            Vector3 => "vector3",
            Normal => "normal",
            Rgb => "rgb",
            Blackbody => "blackbody",
            Spectrum => "spectrum",
            Texture => "texture",
        }
    }
    /// Whether values are numbers (else strings, or bools).
    pub fn numeric(self) -> bool {
        !matches!(
            self,
            ParamType::Bool | ParamType::String | ParamType::Texture
        )
    }
    /// Values per element (3 for point3), 0 when any count is fine.
    pub fn arity(self) -> usize {
        use ParamType::*;
        match self {
            Point2 | Vector2 => 2,
            Point3 | Vector3 | Normal | Rgb => 3,
            _ => 1,
        }
    }
}

/// One parameter.
#[derive(Debug)]
pub struct Param {
    pub ty: ParamType,
    pub name: String,
    pub nums: Vec<f64>,
    /// Values of an `integer` parameter (32-bit, as pbrt).
    pub ints: Vec<i32>,
    pub strs: Vec<String>,
    pub bools: Vec<bool>,
    /// Span of the `"type name"` declaration.
    pub span: Span,
    pub used: Cell<bool>,
    /// Came from an `Attribute` default: never reported as unused.
    pub inherited: bool,
}

impl Param {
    pub fn len(&self) -> usize {
        match self.ty {
            ParamType::Bool => self.bools.len(),
            ParamType::String | ParamType::Texture => self.strs.len(),
            ParamType::Integer => self.ints.len(),
            _ => self.nums.len(),
        }
    }
    pub fn is_empty(&self) -> bool {
        self.len() == 0
    }
}

/// The spectrum flavours of pbrt-v4 (how an `rgb` value is turned into a spectrum).
#[derive(Clone, Copy, Debug, PartialEq, Eq)]
pub enum SpectrumKind {
    /// Reflectance: bounded to [0, 1].
    Albedo,
    /// Any non-negative value (e.g. an index of refraction).
    Unbounded,
    /// Emission: rgb × the colour space's white.
    Illuminant,
}

/// A directive's parameters.
#[derive(Debug, Default)]
pub struct ParamList {
    pub params: Vec<Param>,
}

impl ParamList {
    /// Add a parameter; a same-named earlier one is removed (last wins) and returned.
    pub fn push(&mut self, p: Param) -> Option<Param> {
        let old = self
            .params
            .iter()
            .position(|q| q.name == p.name)
            .map(|i| self.params.remove(i));
        self.params.push(p);
        old
    }

    pub fn find(&self, name: &str) -> Option<&Param> {
        let p = self.params.iter().find(|p| p.name == name)?;
        p.used.set(true);
        Some(p)
    }
    pub fn has(&self, name: &str) -> bool {
        self.params.iter().any(|p| p.name == name)
    }

    fn typed(&self, name: &str, tys: &[ParamType]) -> PResult<Option<&Param>> {
        let Some(p) = self.find(name) else {
            return Ok(None);
        };
        if !tys.contains(&p.ty) {
            let want: Vec<&str> = tys.iter().map(|t| t.name()).collect();
            return Err(SpanError::new(
                p.span,
                format!(
                    "parameter '{name}' has type '{}', expected {}",
                    p.ty.name(),
                    want.join(" or ")
                ),
            ));
        }
        Ok(Some(p))
    }

    fn one_num(&self, name: &str, ty: ParamType) -> PResult<Option<f64>> {
        let Some(p) = self.typed(name, &[ty])? else {
            return Ok(None);
        };
        if p.nums.len() != 1 {
            return Err(SpanError::new(
                p.span,
                format!(
                    "parameter '{name}' needs exactly 1 value, got {}",
                    p.nums.len()
                ),
            ));
        }
        Ok(Some(p.nums[0]))
    }

    pub fn float(&self, name: &str, default: f64) -> PResult<f64> {
        Ok(self.one_num(name, ParamType::Float)?.unwrap_or(default))
    }
    pub fn float_opt(&self, name: &str) -> PResult<Option<f64>> {
        self.one_num(name, ParamType::Float)
    }
    pub fn int(&self, name: &str, default: i64) -> PResult<i64> {
        let Some(p) = self.typed(name, &[ParamType::Integer])? else {
            return Ok(default);
        };
        if p.ints.len() != 1 {
            return Err(SpanError::new(
                p.span,
                format!(
                    "parameter '{name}' needs exactly 1 value, got {}",
                    p.ints.len()
                ),
            ));
        }
        Ok(p.ints[0] as i64)
    }
    pub fn bool(&self, name: &str, default: bool) -> PResult<bool> {
        let Some(p) = self.typed(name, &[ParamType::Bool])? else {
            return Ok(default);
        };
        if p.bools.len() != 1 {
            return Err(SpanError::new(
                p.span,
                format!("parameter '{name}' needs exactly 1 value"),
            ));
        }
        Ok(p.bools[0])
    }
    pub fn string(&self, name: &str) -> PResult<Option<String>> {
        let Some(p) = self.typed(name, &[ParamType::String])? else {
            return Ok(None);
        };
        if p.strs.len() != 1 {
            return Err(SpanError::new(
                p.span,
                format!("parameter '{name}' needs exactly 1 value"),
            ));
        }
        Ok(Some(p.strs[0].clone()))
    }
    pub fn floats(&self, name: &str) -> PResult<Option<&[f64]>> {
        Ok(self
            .typed(name, &[ParamType::Float])?
            .map(|p| p.nums.as_slice()))
    }
    /// Integer array.
    pub fn ints(&self, name: &str) -> PResult<Option<&[i32]>> {
        Ok(self
            .typed(name, &[ParamType::Integer])?
            .map(|p| p.ints.as_slice()))
    }
    /// point3 / vector3 / normal array (flat, multiple of 3).
    pub fn vec3s(&self, name: &str, tys: &[ParamType]) -> PResult<Option<&[f64]>> {
        Ok(self.typed(name, tys)?.map(|p| p.nums.as_slice()))
    }
    pub fn point3(&self, name: &str, default: [f64; 3]) -> PResult<[f64; 3]> {
        let Some(p) = self.typed(name, &[ParamType::Point3])? else {
            return Ok(default);
        };
        if p.nums.len() != 3 {
            return Err(SpanError::new(
                p.span,
                format!("parameter '{name}' needs one point (3 values)"),
            ));
        }
        Ok([p.nums[0], p.nums[1], p.nums[2]])
    }
    pub fn span_of(&self, name: &str) -> Option<Span> {
        self.params.iter().find(|p| p.name == name).map(|p| p.span)
    }

    /// A texture reference (`"texture reflectance" "name"`), if the parameter has that type.
    pub fn texture_name(&self, name: &str) -> Option<(String, Span)> {
        let p = self
            .params
            .iter()
            .find(|p| p.name == name && p.ty == ParamType::Texture)?;
        p.used.set(true);
        p.strs.first().map(|s| (s.clone(), p.span))
    }

    /// A spectrum from `rgb`, `blackbody`, `spectrum` (λ/value pairs, named, file) or a
    /// single `float` (a constant spectrum). None when absent; an unknown named
    /// spectrum gives a warning and None (the caller's default applies).
    pub fn spectrum(
        &self,
        name: &str,
        kind: SpectrumKind,
        ctx: &mut Ctx,
    ) -> PResult<Option<Spectrum>> {
        use ParamType::*;
        let Some(p) = self.typed(name, &[Rgb, Blackbody, Spectrum, Float])? else {
            return Ok(None);
        };
        to_spectrum(p, kind, ctx)
    }

    /// Parameters never read, for the unused-parameter warning.
    pub fn unused(&self) -> impl Iterator<Item = &Param> {
        self.params.iter().filter(|p| !p.used.get() && !p.inherited)
    }
}

fn to_spectrum(p: &Param, kind: SpectrumKind, ctx: &mut Ctx) -> PResult<Option<Spectrum>> {
    let name = &p.name;
    match p.ty {
        ParamType::Float => {
            if p.nums.len() != 1 {
                return Err(SpanError::new(
                    p.span,
                    format!("parameter '{name}' needs exactly 1 value"),
                ));
            }
            Ok(Some(Spectrum::constant(name.clone(), p.nums[0])))
        }
        ParamType::Rgb => {
            if p.nums.len() != 3 {
                return Err(SpanError::new(
                    p.span,
                    format!(
                        "rgb parameter '{name}' needs 3 values, got {}",
                        p.nums.len()
                    ),
                ));
            }
            let rgb = [p.nums[0], p.nums[1], p.nums[2]];
            if rgb.iter().any(|&v| v < 0.0) {
                return Err(SpanError::new(
                    p.span,
                    format!("rgb parameter '{name}' has a negative value"),
                ));
            }
            if kind == SpectrumKind::Albedo && rgb.iter().any(|&v| v > 1.0) {
                return Err(SpanError::new(
                    p.span,
                    format!(
                        "rgb reflectance '{name}' has a value above 1 ({rgb:?}); reflectances must be in [0, 1]"
                    ),
                ));
            }
            rgb_to_spectrum(rgb, kind, name)
                .map(Some)
                .map_err(|m| SpanError::new(p.span, m))
        }
        ParamType::Blackbody => {
            let (t, scale) = match p.nums.len() {
                1 => (p.nums[0], 1.0),
                2 => {
                    ctx.warn(p.span, format!("pbrt-v3 blackbody form [T scale] for '{name}'; read as v4 T with a scale"))?;
                    (p.nums[0], p.nums[1])
                }
                n => {
                    return Err(SpanError::new(
                        p.span,
                        format!("blackbody '{name}' needs 1 value (K), got {n}"),
                    ));
                }
            };
            if t <= 0.0 {
                return Err(SpanError::new(
                    p.span,
                    format!("blackbody temperature must be > 0 K, got {t}"),
                ));
            }
            Ok(Some(blackbody_normalized(t).scaled(scale)))
        }
        ParamType::Spectrum => {
            if !p.strs.is_empty() {
                if p.strs.len() != 1 {
                    return Err(SpanError::new(
                        p.span,
                        format!("spectrum '{name}' needs one name or file"),
                    ));
                }
                let s = &p.strs[0];
                if let Some(sp) = named_spectrum(s) {
                    return Ok(Some(sp));
                }
                if let Ok(sp) = crate::spectrum::library::named(s) {
                    return Ok(Some(sp));
                }
                if s.starts_with("metal-")
                    || s.starts_with("glass-")
                    || s.starts_with("stdillum-")
                    || s.starts_with("canon")
                    || s.starts_with("nikon")
                    || s.starts_with("sony")
                {
                    ctx.warn(p.span, format!("named spectrum '{s}' is not built into camsim; using the default for '{name}'"))?;
                    return Ok(None);
                }
                let path = ctx.resolve_path(s);
                return read_spectrum_file(&path)
                    .map(Some)
                    .map_err(|m| SpanError::new(p.span, m));
            }
            let v = &p.nums;
            if v.len() < 2 || !v.len().is_multiple_of(2) {
                return Err(SpanError::new(
                    p.span,
                    format!(
                        "spectrum '{name}' needs λ/value pairs (an even count ≥ 2), got {} values",
                        v.len()
                    ),
                ));
            }
            let (w, val): (Vec<f64>, Vec<f64>) = v.chunks(2).map(|c| (c[0], c[1])).unzip();
            let sp = Spectrum::new(name.clone(), w, val).map_err(|m| SpanError::new(p.span, m))?;
            Ok(Some(sp.with_extrapolation(Extrapolation::Clamp)))
        }
        _ => unreachable!("checked by typed()"),
    }
}

fn logistic(x: f64) -> f64 {
    1.0 / (1.0 + (-x).exp())
}

/// The smooth, grey-preserving rgb → spectrum basis (see module docs), 360–830 nm at 5 nm.
pub fn rgb_to_spectrum(rgb: [f64; 3], kind: SpectrumKind, name: &str) -> Result<Spectrum, String> {
    const W: f64 = 12.0;
    let wl: Vec<f64> = (0..=94).map(|i| 360.0 + 5.0 * i as f64).collect();
    let white = if kind == SpectrumKind::Illuminant {
        Some(d65_normalized())
    } else {
        None
    };
    let vals = wl
        .iter()
        .map(|&l| {
            let b = 1.0 - logistic((l - 490.0) / W);
            let r = logistic((l - 590.0) / W);
            let g = (1.0 - r - b).max(0.0);
            let s = rgb[0] * r + rgb[1] * g + rgb[2] * b;
            match &white {
                Some(d) => s * d.eval(l),
                None => s,
            }
        })
        .collect();
    // Err only when huge rgb values overflow to infinity.
    let sp = Spectrum::new(name.to_string(), wl, vals)?;
    Ok(sp.with_extrapolation(if kind == SpectrumKind::Illuminant {
        Extrapolation::Zero
    } else {
        Extrapolation::Clamp
    }))
}

/// CIE Y of a spectrum relative to the equal-energy white's (∫ȳ·s / ∫ȳ), 360–830 nm.
pub fn luminance_y(s: &Spectrum) -> f64 {
    let grid = WavelengthGrid {
        start_nm: 360.0,
        step_nm: 1.0,
        count: 471,
    };
    let y = &crate::spectrum::library::cie1931_cmfs()[1];
    static ONE: std::sync::OnceLock<f64> = std::sync::OnceLock::new();
    let one = *ONE.get_or_init(|| Spectrum::constant("one", 1.0).integrate_product(y, &grid));
    s.integrate_product(y, &grid) / one
}

fn normalized_illuminant(lib: &str, name: &str) -> Spectrum {
    let s = crate::spectrum::library::named(lib).expect("shipped illuminant");
    let y = luminance_y(&s);
    let mut s = s.scaled(1.0 / y);
    s.name = name.to_string();
    s
}

fn d65_normalized() -> &'static Spectrum {
    static D: std::sync::OnceLock<Spectrum> = std::sync::OnceLock::new();
    D.get_or_init(|| normalized_illuminant("cie-d65", "stdillum-D65"))
}

/// Planck's law normalised to a peak of 1 (pbrt-v4's `blackbody`), 300–1000 nm at 5 nm.
pub fn blackbody_normalized(t_k: f64) -> Spectrum {
    const H: f64 = 6.626_070_15e-34;
    const C: f64 = 299_792_458.0;
    const KB: f64 = 1.380_649e-23;
    let planck = |l_nm: f64| {
        let l = l_nm * 1e-9;
        2.0 * H * C * C / (l.powi(5) * ((H * C / (l * KB * t_k)).exp() - 1.0))
    };
    // Wien's displacement law gives the peak.
    let peak_nm = 2.897_771_955e-3 / t_k * 1e9;
    let peak = planck(peak_nm);
    let wl: Vec<f64> = (0..=140).map(|i| 300.0 + 5.0 * i as f64).collect();
    let vals: Vec<f64> = wl
        .iter()
        .map(|&l| {
            let v = planck(l) / peak;
            if v.is_finite() { v } else { 0.0 }
        })
        .collect();
    Spectrum::new(format!("blackbody-{t_k}K"), wl, vals).expect("finite")
}

/// Sellmeier index of refraction, coefficients B1..3 and C1..3 in µm².
fn sellmeier(name: &str, b: [f64; 3], c: [f64; 3]) -> Spectrum {
    let wl: Vec<f64> = (0..=94).map(|i| 360.0 + 5.0 * i as f64).collect();
    let vals = wl
        .iter()
        .map(|&l| {
            let l2 = (l * 1e-3).powi(2);
            (1.0 + (0..3).map(|i| b[i] * l2 / (l2 - c[i])).sum::<f64>()).sqrt()
        })
        .collect();
    Spectrum::new(name, wl, vals)
        .expect("finite")
        .with_extrapolation(Extrapolation::Clamp)
}

/// pbrt's named spectra that camsim builds in (see module docs).
pub fn named_spectrum(name: &str) -> Option<Spectrum> {
    Some(match name {
        "stdillum-D65" => d65_normalized().clone(),
        "stdillum-A" => normalized_illuminant("cie-a", name),
        "stdillum-F2" => normalized_illuminant("cie-f2", name),
        // Schott N-BK7 catalogue Sellmeier coefficients.
        "glass-BK7" => sellmeier(
            name,
            [1.039_612_12, 0.231_792_344, 1.010_469_45],
            [0.006_000_698_67, 0.020_017_914_4, 103.560_653],
        ),
        // Fused silica (Malitson 1965).
        "fused-silica" | "glass-fused-silica" => sellmeier(
            name,
            [0.696_166_3, 0.407_942_6, 0.897_479_4],
            [
                0.068_404_3f64.powi(2),
                0.116_241_4f64.powi(2),
                9.896_161f64.powi(2),
            ],
        ),
        _ => return None,
    })
}

/// Read a pbrt spectrum file: whitespace-separated `λ value` pairs, `#` comments.
pub fn read_spectrum_file(path: &Path) -> Result<Spectrum, String> {
    let text = std::fs::read_to_string(path)
        .map_err(|e| format!("cannot read spectrum file {}: {e}", path.display()))?;
    let mut nums = vec![];
    for (ln, line) in text.lines().enumerate() {
        let line = line.split('#').next().unwrap_or("");
        for w in line.split(|c: char| c.is_whitespace() || c == ',') {
            if w.is_empty() {
                continue;
            }
            nums.push(
                super::lexer::parse_number(w).ok_or_else(|| {
                    format!("{}:{}: '{w}' is not a number", path.display(), ln + 1)
                })?,
            );
        }
    }
    if nums.len() < 2 || !nums.len().is_multiple_of(2) {
        return Err(format!(
            "{}: expected λ/value pairs, got {} numbers",
            path.display(),
            nums.len()
        ));
    }
    let (w, v): (Vec<f64>, Vec<f64>) = nums.chunks(2).map(|c| (c[0], c[1])).unzip();
    let name = path
        .file_stem()
        .map(|s| s.to_string_lossy().into_owned())
        .unwrap_or_default();
    Spectrum::new(name, w, v)
        .map(|s| s.with_extrapolation(Extrapolation::Clamp))
        .map_err(|e| format!("{}: {e}", path.display()))
}

#[cfg(test)]
mod tests {
    use super::*;

    #[test]
    fn rgb_basis_is_bounded_and_grey_preserving() {
        let g = rgb_to_spectrum([0.3, 0.3, 0.3], SpectrumKind::Albedo, "g").unwrap();
        assert!(g.values.iter().all(|v| (v - 0.3).abs() < 1e-12));
        let red = rgb_to_spectrum([1.0, 0.0, 0.0], SpectrumKind::Albedo, "r").unwrap();
        assert!(red.eval(700.0) > 0.99 && red.eval(420.0) < 1e-3);
        let blue = rgb_to_spectrum([0.0, 0.0, 1.0], SpectrumKind::Albedo, "b").unwrap();
        assert!(blue.eval(420.0) > 0.99 && blue.eval(650.0) < 1e-3);
        for rgb in [
            [1.0, 1.0, 0.0],
            [0.0, 1.0, 1.0],
            [1.0, 0.0, 1.0],
            [1.0, 1.0, 1.0],
        ] {
            let s = rgb_to_spectrum(rgb, SpectrumKind::Albedo, "x").unwrap();
            assert!(s.values.iter().all(|&v| (0.0..=1.0 + 1e-12).contains(&v)));
        }
    }

    #[test]
    fn illuminant_white_has_unit_luminance() {
        let w = rgb_to_spectrum([1.0, 1.0, 1.0], SpectrumKind::Illuminant, "w").unwrap();
        // ∫ȳ·D65/Y(D65) = 1 by construction; 1 nm vs 5 nm sampling limits agreement to ~1e-3.
        assert!((luminance_y(&w) - 1.0).abs() < 2e-3, "{}", luminance_y(&w));
    }

    #[test]
    fn bk7_index_at_d_line() {
        // Schott N-BK7: n_d = 1.5168 at 587.6 nm.
        let s = named_spectrum("glass-BK7").unwrap();
        let l2: f64 = 0.5876f64.powi(2);
        let n = (1.0
            + 1.039_612_12 * l2 / (l2 - 0.006_000_698_67)
            + 0.231_792_344 * l2 / (l2 - 0.020_017_914_4)
            + 1.010_469_45 * l2 / (l2 - 103.560_653))
            .sqrt();
        assert!((n - 1.5168).abs() < 2e-4);
        assert!((s.eval(587.6) - 1.5168).abs() < 5e-4);
    }

    #[test]
    fn blackbody_peaks_at_one_where_wien_says() {
        let b = blackbody_normalized(6500.0);
        let (i, m) = b
            .values
            .iter()
            .enumerate()
            .fold((0, 0.0), |a, (i, &v)| if v > a.1 { (i, v) } else { a });
        assert!(m <= 1.0 + 1e-12 && m > 0.999);
        assert!((b.wavelengths_nm[i] - 445.8).abs() < 5.0);
    }
}
