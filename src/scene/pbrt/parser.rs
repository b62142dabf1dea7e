//! Directive parser with pbrt's graphics state.
//!
//! The token stream is a stack of per-file lexers: `Include`/`Import` push a file,
//! its end pops it, so a parameter list may continue across the end of an included
//! file (pbrt-v4 includes at token level). `Import` is treated as `Include`
//! (pbrt-v4 only restricts what an imported file may contain, for parallel parsing).
//! Relative paths resolve against the top-level file's directory, as pbrt-v4 does.
//! Files ending in `.gz` are decompressed.

use super::lexer::{FileId, Lexer, Span, Token, TokenKind, unescape};
use super::params::{Ctx, PResult, Param, ParamList, ParamType, SpanError, TYPE_NAMES};
use super::to_scene::{self, AreaLightSpec, CameraParams, FilmParams, Textures};
use crate::scene::{Instance, MaterialId, Scene};
use glam::{DMat4, DVec3};
use std::collections::{HashMap, HashSet};
use std::path::{Path, PathBuf};

/// One source file.
pub struct SourceFile {
    pub path: PathBuf,
    pub text: String,
}

#[derive(Clone, Copy, Debug, PartialEq, Eq)]
enum Block {
    Attribute,
    Transform,
    Object,
}

#[derive(Clone, Debug)]
enum MatRef {
    Default,
    Id(MaterialId),
    Named(String, Span),
}

#[derive(Clone, Debug)]
struct GState {
    ctm: [DMat4; 2],
    active: [bool; 2],
    reverse_orientation: bool,
    material: MatRef,
    area_light: Option<AreaLightSpec>,
    /// `#ObjectName` path of the enclosing blocks.
    names: Vec<String>,
    /// Whether this block already set its own name (a second hint replaces it).
    name_here: bool,
    /// `Attribute "shape"|"light"|"material"|… ` defaults.
    attributes: Vec<(String, Vec<ParamDefault>)>,
}

#[derive(Clone, Debug)]
struct ParamDefault {
    ty: ParamType,
    name: String,
    nums: Vec<f64>,
    ints: Vec<i32>,
    strs: Vec<String>,
    bools: Vec<bool>,
    span: Span,
}

impl Default for GState {
    fn default() -> Self {
        Self {
            ctm: [DMat4::IDENTITY; 2],
            active: [true, true],
            reverse_orientation: false,
            material: MatRef::Default,
            area_light: None,
            names: vec![],
            name_here: false,
            attributes: vec![],
        }
    }
}

const DIRECTIVES: &[&str] = &[
    "Accelerator",
    "ActiveTransform",
    "AreaLightSource",
    "Attribute",
    "AttributeBegin",
    "AttributeEnd",
    "Camera",
    "ColorSpace",
    "ConcatTransform",
    "CoordinateSystem",
    "CoordSysTransform",
    "Film",
    "Identity",
    "Import",
    "Include",
    "Integrator",
    "LightSource",
    "LookAt",
    "MakeNamedMaterial",
    "MakeNamedMedium",
    "Material",
    "MediumInterface",
    "NamedMaterial",
    "ObjectBegin",
    "ObjectEnd",
    "ObjectInstance",
    "Option",
    "PixelFilter",
    "ReverseOrientation",
    "Rotate",
    "Sampler",
    "Scale",
    "Shape",
    "Texture",
    "Transform",
    "TransformBegin",
    "TransformEnd",
    "TransformTimes",
    "Translate",
    "WorldBegin",
    "WorldEnd",
];

const MAX_INCLUDE_DEPTH: usize = 64;

pub struct Parser {
    pub files: Vec<SourceFile>,
    stack: Vec<Lexer>,
    /// Canonical paths of the files on the include stack, for cycle detection.
    active_paths: Vec<PathBuf>,
    peeked: Option<Token>,
    pending_hints: Vec<String>,
    pub ctx: Ctx,
    pub scene: Scene,
    state: GState,
    state_stack: Vec<(GState, Block, Span)>,
    in_world: bool,
    named_coord: HashMap<String, [DMat4; 2]>,
    pending_materials: HashMap<String, Span>,
    defined_materials: HashSet<String>,
    textures: Textures,
    object_def: Option<(String, Vec<usize>, Span)>,
    objects: HashMap<String, Vec<usize>>,
    media: HashSet<String>,
    pub shape_count: usize,
    anon_materials: usize,
    pub camera: Option<(CameraParams, DMat4, Span)>,
    pub film: Option<FilmParams>,
    /// Mesh indices that are instance prototypes.
    pub prototypes: Vec<usize>,
}

impl Parser {
    pub fn new(strict: bool, base_dir: PathBuf) -> Self {
        Self {
            files: vec![],
            stack: vec![],
            active_paths: vec![],
            peeked: None,
            pending_hints: vec![],
            ctx: Ctx {
                strict,
                base_dir,
                warnings: vec![],
                dialect: Default::default(),
            },
            scene: Scene::default(),
            state: GState::default(),
            state_stack: vec![],
            in_world: false,
            named_coord: HashMap::new(),
            pending_materials: HashMap::new(),
            defined_materials: HashSet::new(),
            textures: Textures::default(),
            object_def: None,
            objects: HashMap::new(),
            media: HashSet::new(),
            shape_count: 0,
            anon_materials: 0,
            camera: None,
            film: None,
            prototypes: vec![],
        }
    }

    /// Push a source onto the token stream.
    pub fn push_source(&mut self, path: PathBuf, text: String) {
        let canon = std::fs::canonicalize(&path).unwrap_or_else(|_| path.clone());
        self.files.push(SourceFile { path, text });
        self.stack
            .push(Lexer::new((self.files.len() - 1) as FileId));
        self.active_paths.push(canon);
    }

    pub fn text(&self, span: Span) -> &str {
        let t = &self.files[span.file as usize].text;
        t.get(span.start..span.end).unwrap_or("")
    }

    fn string_of(&self, t: &Token) -> String {
        match t.kind {
            TokenKind::Str { escaped: true } => unescape(
                &self.files[t.span.file as usize].text.as_bytes()[t.span.start..t.span.end],
            ),
            _ => self.text(t.span).to_string(),
        }
    }

    fn raw_next(&mut self) -> PResult<Option<Token>> {
        loop {
            let Some(lx) = self.stack.last_mut() else {
                return Ok(None);
            };
            let src = self.files[lx.file as usize].text.as_bytes();
            match lx.next_token(src) {
                Ok(Some(t)) => return Ok(Some(t)),
                Ok(None) => {
                    self.stack.pop();
                    self.active_paths.pop();
                }
                Err(e) => {
                    return Err(SpanError::new(
                        Span {
                            file: lx.file,
                            start: e.offset,
                            end: e.offset + e.len.max(1),
                        },
                        e.message,
                    ));
                }
            }
        }
    }

    fn next(&mut self) -> PResult<Option<Token>> {
        if let Some(t) = self.peeked.take() {
            return Ok(Some(t));
        }
        loop {
            match self.raw_next()? {
                Some(t) if t.kind == TokenKind::NameHint => {
                    let s = self.text(t.span).to_string();
                    self.pending_hints.push(s);
                }
                other => return Ok(other),
            }
        }
    }

    fn peek(&mut self) -> PResult<Option<Token>> {
        if self.peeked.is_none() {
            self.peeked = self.next()?;
        }
        Ok(self.peeked)
    }

    /// Span just past the last token, for "unexpected end of file" errors.
    fn eof_span(&self, after: Span) -> Span {
        Span {
            file: after.file,
            start: after.end,
            end: after.end + 1,
        }
    }

    fn expect_string(&mut self, directive: &str, dspan: Span) -> PResult<(String, Span)> {
        match self.next()? {
            Some(t) if matches!(t.kind, TokenKind::Str { .. }) => Ok((self.string_of(&t), t.span)),
            Some(t) => Err(SpanError::new(
                t.span,
                format!(
                    "'{directive}' expects a quoted string, found '{}'",
                    self.text(t.span)
                ),
            )),
            None => Err(SpanError::new(
                self.eof_span(dspan),
                format!("'{directive}' expects a quoted string, found the end of the file"),
            )),
        }
    }

    /// `n` numbers, with or without brackets.
    fn numbers(&mut self, directive: &str, dspan: Span, n: usize) -> PResult<Vec<f64>> {
        let mut v = Vec::with_capacity(n);
        let bracket = match self.peek()? {
            Some(t) if t.kind == TokenKind::LBracket => {
                self.next()?;
                Some(t.span)
            }
            _ => None,
        };
        let mut last = dspan;
        loop {
            if bracket.is_none() && v.len() == n {
                break;
            }
            let t = self.next()?;
            let Some(t) = t else {
                let msg = match bracket {
                    Some(_) => format!(
                        "missing ']' in '{directive}': end of file before the closing bracket"
                    ),
                    None => format!(
                        "'{directive}' expects {n} numbers, found the end of the file after {}",
                        v.len()
                    ),
                };
                return Err(SpanError::new(bracket.unwrap_or(self.eof_span(last)), msg));
            };
            last = t.span;
            match (t.kind, t.num) {
                (TokenKind::RBracket, _) if bracket.is_some() => break,
                (TokenKind::Word, Some(x)) => v.push(x),
                _ => {
                    let mut e = SpanError::new(
                        t.span,
                        format!(
                            "'{directive}' expects {n} numbers, found '{}'",
                            self.text(t.span)
                        ),
                    );
                    if bracket.is_some() {
                        e.help = Some("missing ']'?".into());
                    }
                    return Err(e);
                }
            }
        }
        if v.len() != n {
            return Err(SpanError::new(
                dspan,
                format!("'{directive}' expects {n} numbers, got {}", v.len()),
            ));
        }
        Ok(v)
    }

    /// The parameter list following a directive.
    fn params(&mut self) -> PResult<ParamList> {
        let mut list = ParamList::default();
        while let Some(t) = self.peek()? {
            if !matches!(t.kind, TokenKind::Str { .. }) {
                break;
            }
            self.next()?;
            let decl = self.string_of(&t);
            let mut it = decl.split_whitespace();
            let (Some(ty_s), Some(name), None) = (it.next(), it.next(), it.next()) else {
                return Err(SpanError::new(
                    t.span,
                    format!("expected a parameter declaration \"type name\", found \"{decl}\""),
                ));
            };
            let Some((ty, v3_alias)) = ParamType::parse(ty_s) else {
                let mut e = SpanError::new(t.span, format!("unknown parameter type '{ty_s}'"));
                e.help = suggest(ty_s, TYPE_NAMES.iter().copied())
                    .map(|s| format!("did you mean '{s}'?"));
                return Err(e);
            };
            if v3_alias && ty_s == "color" {
                self.ctx.warn(
                    t.span,
                    format!("pbrt-v3 parameter type 'color' for '{name}' read as 'rgb'"),
                )?;
            }
            let mut p = Param {
                ty,
                name: name.to_string(),
                nums: vec![],
                ints: vec![],
                strs: vec![],
                bools: vec![],
                span: t.span,
                used: Default::default(),
                inherited: false,
            };
            let first = self.next()?;
            let Some(first) = first else {
                return Err(SpanError::new(
                    t.span,
                    format!("parameter '{name}' has no value (end of file)"),
                ));
            };
            match first.kind {
                TokenKind::LBracket => loop {
                    let Some(v) = self.next()? else {
                        let mut e = SpanError::new(
                            first.span,
                            format!(
                                "missing ']' for parameter '{name}': end of file before the closing bracket"
                            ),
                        );
                        e.help = Some("close the value list with ']'".into());
                        return Err(e);
                    };
                    if v.kind == TokenKind::RBracket {
                        break;
                    }
                    self.value(&mut p, &v, true)?;
                },
                _ => self.value(&mut p, &first, false)?,
            }
            if p.is_empty() && ty != ParamType::Spectrum {
                return Err(SpanError::new(
                    t.span,
                    format!("parameter '{name}' has an empty value list"),
                ));
            }
            if ty.numeric() && !p.nums.len().is_multiple_of(ty.arity()) {
                return Err(SpanError::new(
                    t.span,
                    format!(
                        "{} parameter '{name}' needs a multiple of {} values, got {}",
                        ty.name(),
                        ty.arity(),
                        p.nums.len()
                    ),
                ));
            }
            if ty == ParamType::Spectrum && !p.nums.is_empty() && !p.strs.is_empty() {
                return Err(SpanError::new(
                    t.span,
                    format!("spectrum '{name}' mixes numbers and strings"),
                ));
            }
            if let Some(old) = list.push(p) {
                self.ctx.warn(
                    old.span,
                    format!("parameter '{}' given twice; the last one is used", old.name),
                )?;
            }
        }
        Ok(list)
    }

    fn value(&mut self, p: &mut Param, t: &Token, in_brackets: bool) -> PResult<()> {
        // A bare word inside brackets that is not a value is most likely the next directive.
        let looks_like_directive = t.kind == TokenKind::Word
            && self
                .text(t.span)
                .starts_with(|c: char| c.is_ascii_uppercase());
        let help = (in_brackets && looks_like_directive).then(|| "missing ']'?".to_string());
        let bad = |s: &Self, what: &str| {
            let mut e = SpanError::new(
                t.span,
                format!(
                    "{} parameter '{}' expects {what}, found '{}'",
                    p.ty.name(),
                    p.name,
                    s.text(t.span)
                ),
            );
            e.help = help.clone();
            e
        };
        match p.ty {
            ParamType::String | ParamType::Texture => match t.kind {
                TokenKind::Str { .. } => p.strs.push(self.string_of(t)),
                _ => return Err(bad(self, "quoted strings")),
            },
            ParamType::Bool => {
                let s = match t.kind {
                    TokenKind::Str { .. } | TokenKind::Word => self.text(t.span),
                    _ => "",
                };
                match s {
                    "true" => p.bools.push(true),
                    "false" => p.bools.push(false),
                    _ => return Err(bad(self, "\"true\" or \"false\"")),
                }
            }
            ParamType::Spectrum => match (t.kind, t.num) {
                (TokenKind::Word, Some(x)) => p.nums.push(x),
                (TokenKind::Str { .. }, _) => p.strs.push(self.string_of(t)),
                _ => return Err(bad(self, "numbers or a spectrum name")),
            },
            ty => match (t.kind, t.num) {
                (TokenKind::Word, Some(x)) if ty == ParamType::Integer => {
                    if x.fract() != 0.0 || x.abs() > i32::MAX as f64 {
                        return Err(bad(self, "32-bit integers"));
                    }
                    p.ints.push(x as i32)
                }
                (TokenKind::Word, Some(x)) => p.nums.push(x),
                _ => return Err(bad(self, "numbers")),
            },
        }
        Ok(())
    }

    /// Apply `#ObjectName` hints read since the last directive to the current block.
    fn apply_hints(&mut self) {
        for h in std::mem::take(&mut self.pending_hints) {
            if self.state.name_here {
                self.state.names.pop();
            }
            if self.state.names.last() != Some(&h) {
                self.state.names.push(h);
                self.state.name_here = true;
            } else {
                self.state.name_here = false;
            }
        }
    }

    /// Parse everything on the token stream.
    pub fn run(&mut self) -> PResult<()> {
        while let Some(t) = self.next()? {
            if t.kind != TokenKind::Word {
                let what = match t.kind {
                    TokenKind::Str { .. } => format!("the string \"{}\"", self.text(t.span)),
                    TokenKind::LBracket => "'['".into(),
                    TokenKind::RBracket => "']' without a matching '['".into(),
                    _ => self.text(t.span).to_string(),
                };
                return Err(SpanError::new(
                    t.span,
                    format!("expected a directive, found {what}"),
                ));
            }
            self.apply_hints();
            let name = self.text(t.span).to_string();
            self.directive(&name, t.span)?;
        }
        self.finish()
    }

    fn check_unused(&mut self, params: &ParamList, directive: &str) -> PResult<()> {
        let unused: Vec<(Span, String)> =
            params.unused().map(|p| (p.span, p.name.clone())).collect();
        for (span, name) in unused {
            self.ctx.warn(
                span,
                format!("parameter '{name}' is not used by '{directive}'"),
            )?;
        }
        Ok(())
    }

    fn world_only(&self, d: &str, span: Span) -> PResult<()> {
        if !self.in_world {
            return Err(SpanError::new(
                span,
                format!("'{d}' is only allowed after WorldBegin"),
            ));
        }
        Ok(())
    }
    fn options_only(&self, d: &str, span: Span) -> PResult<()> {
        if self.in_world {
            return Err(SpanError::new(
                span,
                format!("'{d}' is not allowed after WorldBegin"),
            ));
        }
        Ok(())
    }

    fn concat(&mut self, m: DMat4) {
        for i in 0..2 {
            if self.state.active[i] {
                self.state.ctm[i] *= m;
            }
        }
    }
    fn set_ctm(&mut self, m: DMat4) {
        for i in 0..2 {
            if self.state.active[i] {
                self.state.ctm[i] = m;
            }
        }
    }

    fn push_block(&mut self, kind: Block, span: Span) {
        self.state_stack.push((self.state.clone(), kind, span));
        self.state.name_here = false;
    }

    fn pop_block(&mut self, kind: Block, span: Span, d: &str) -> PResult<()> {
        let Some((saved, k, _)) = self.state_stack.pop() else {
            return Err(SpanError::new(
                span,
                format!("'{d}' without a matching begin"),
            ));
        };
        if k != kind {
            self.ctx.warn(span, format!("'{d}' closes a {k:?} block"))?;
        }
        if kind == Block::Transform {
            // TransformEnd restores only the transform.
            self.state.ctm = saved.ctm;
            self.state.active = saved.active;
        } else {
            self.state = saved;
        }
        Ok(())
    }

    fn directive(&mut self, d: &str, span: Span) -> PResult<()> {
        match d {
            "Include" | "Import" => {
                let (file, fspan) = self.expect_string(d, span)?;
                self.include(&file, fspan)?;
            }
            "Identity" => self.set_ctm(DMat4::IDENTITY),
            "Translate" => {
                let v = self.numbers(d, span, 3)?;
                self.concat(DMat4::from_translation(DVec3::new(v[0], v[1], v[2])));
            }
            "Scale" => {
                let v = self.numbers(d, span, 3)?;
                self.concat(DMat4::from_scale(DVec3::new(v[0], v[1], v[2])));
            }
            "Rotate" => {
                let v = self.numbers(d, span, 4)?;
                let axis = DVec3::new(v[1], v[2], v[3]);
                if !(axis.length() > 0.0) {
                    return Err(SpanError::new(span, "Rotate axis has zero length"));
                }
                self.concat(DMat4::from_axis_angle(axis.normalize(), v[0].to_radians()));
            }
            "LookAt" => {
                let v = self.numbers(d, span, 9)?;
                let pose = crate::scene::CameraPose {
                    position: DVec3::new(v[0], v[1], v[2]),
                    look_at: DVec3::new(v[3], v[4], v[5]),
                    up: DVec3::new(v[6], v[7], v[8]),
                };
                let Some(w) = crate::scene::look_at_to_world(&pose) else {
                    return Err(SpanError::new(
                        span,
                        "degenerate LookAt: eye equals target or up is parallel to the view direction",
                    ));
                };
                self.concat(w.inverse());
            }
            "Transform" | "ConcatTransform" => {
                let v = self.numbers(d, span, 16)?;
                let mut a = [0.0; 16];
                a.copy_from_slice(&v);
                // The 16 numbers are the matrix in column-major order (translation in 12..15).
                let m = DMat4::from_cols_array(&a);
                if d == "Transform" {
                    self.set_ctm(m)
                } else {
                    self.concat(m)
                }
            }
            "CoordinateSystem" => {
                let (n, _) = self.expect_string(d, span)?;
                self.named_coord.insert(n, self.state.ctm);
            }
            "CoordSysTransform" => {
                let (n, nspan) = self.expect_string(d, span)?;
                match self.named_coord.get(&n) {
                    Some(m) => self.state.ctm = *m,
                    None => self.ctx.warn(
                        nspan,
                        format!("unknown coordinate system '{n}'; transform unchanged"),
                    )?,
                }
            }
            "ActiveTransform" => {
                let t = self.next()?;
                let w = t.map(|t| (self.text(t.span).to_string(), t.span));
                match w.as_ref().map(|(s, sp)| (s.as_str(), *sp)) {
                    Some(("StartTime", _)) => self.state.active = [true, false],
                    Some(("EndTime", _)) => self.state.active = [false, true],
                    Some(("All", _)) => self.state.active = [true, true],
                    Some((s, sp)) => {
                        return Err(SpanError::new(
                            sp,
                            format!(
                                "ActiveTransform expects StartTime, EndTime or All, found '{s}'"
                            ),
                        ));
                    }
                    None => {
                        return Err(SpanError::new(
                            self.eof_span(span),
                            "ActiveTransform expects StartTime, EndTime or All",
                        ));
                    }
                }
            }
            "TransformTimes" => {
                self.numbers(d, span, 2)?;
            }
            "ReverseOrientation" => {
                self.world_only(d, span)?;
                self.state.reverse_orientation = !self.state.reverse_orientation;
            }
            "AttributeBegin" => self.push_block(Block::Attribute, span),
            "AttributeEnd" => self.pop_block(Block::Attribute, span, d)?,
            "TransformBegin" => {
                self.ctx.warn(
                    span,
                    "pbrt-v3 'TransformBegin' read as a transform-only push",
                )?;
                self.push_block(Block::Transform, span);
            }
            "TransformEnd" => {
                self.ctx
                    .warn(span, "pbrt-v3 'TransformEnd' read as a transform-only pop")?;
                self.pop_block(Block::Transform, span, d)?;
            }
            "Attribute" => {
                let (target, tspan) = self.expect_string(d, span)?;
                if !["shape", "light", "material", "medium", "texture"].contains(&target.as_str()) {
                    return Err(SpanError::new(
                        tspan,
                        format!(
                            "Attribute target must be shape, light, material, medium or texture, found '{target}'"
                        ),
                    ));
                }
                let params = self.params()?;
                let defs: Vec<ParamDefault> = params
                    .params
                    .into_iter()
                    .map(|p| ParamDefault {
                        ty: p.ty,
                        name: p.name,
                        nums: p.nums,
                        ints: p.ints,
                        strs: p.strs,
                        bools: p.bools,
                        span: p.span,
                    })
                    .collect();
                self.state.attributes.push((target, defs));
            }
            "WorldBegin" => {
                if self.in_world {
                    return Err(SpanError::new(span, "WorldBegin given twice"));
                }
                self.in_world = true;
                self.state.ctm = [DMat4::IDENTITY; 2];
                self.named_coord
                    .insert("world".into(), [DMat4::IDENTITY; 2]);
            }
            "WorldEnd" => {
                self.ctx.warn(
                    span,
                    "pbrt-v3 'WorldEnd' ignored (pbrt-v4 ends the world at the end of the file)",
                )?;
            }
            "Camera" => {
                self.options_only(d, span)?;
                let (ty, tspan) = self.expect_string(d, span)?;
                let params = self.params()?;
                let cam = to_scene::camera_params(&ty, tspan, &params, &mut self.ctx)?;
                self.check_unused(&params, d)?;
                let world_from_camera = self.state.ctm[0].inverse();
                if !world_from_camera.is_finite() {
                    return Err(SpanError::new(span, "the camera transform is singular"));
                }
                self.named_coord.insert(
                    "camera".into(),
                    [self.state.ctm[0].inverse(), self.state.ctm[1].inverse()],
                );
                self.camera = Some((cam, world_from_camera, span));
            }
            "Film" => {
                self.options_only(d, span)?;
                let (ty, tspan) = self.expect_string(d, span)?;
                let params = self.params()?;
                self.film = Some(to_scene::film_params(&ty, tspan, &params, &mut self.ctx)?);
                self.check_unused(&params, d)?;
            }
            "Sampler" | "PixelFilter" | "Accelerator" | "Integrator" => {
                self.options_only(d, span)?;
                let (ty, tspan) = self.expect_string(d, span)?;
                let params = self.params()?;
                // camsim renders with its own sampler, filter and integrator settings.
                for p in &params.params {
                    p.used.set(true);
                }
                if d == "Integrator" && ty == "directlighting" {
                    self.ctx.warn(tspan, "pbrt-v3 integrator 'directlighting' read as pbrt-v4 'path' (camsim uses its own integrator settings)")?;
                }
            }
            "ColorSpace" => {
                let (cs, cspan) = self.expect_string(d, span)?;
                if cs != "srgb" {
                    self.ctx.warn(
                        cspan,
                        format!("colour space '{cs}' not supported; rgb values are read as sRGB"),
                    )?;
                }
            }
            "Option" => {
                let params = self.params()?;
                for p in &params.params {
                    p.used.set(true);
                }
            }
            "MakeNamedMedium" => {
                let (name, nspan) = self.expect_string(d, span)?;
                let params = self.params()?;
                for p in &params.params {
                    p.used.set(true);
                }
                self.ctx.warn(
                    nspan,
                    format!("participating media are not supported; medium '{name}' is ignored"),
                )?;
                self.media.insert(name);
            }
            "MediumInterface" => {
                let (a, aspan) = self.expect_string(d, span)?;
                let b = match self.peek()? {
                    Some(t) if matches!(t.kind, TokenKind::Str { .. }) => {
                        self.next()?;
                        self.string_of(&t)
                    }
                    _ => a.clone(),
                };
                if !a.is_empty() || !b.is_empty() {
                    self.ctx.warn(aspan, "MediumInterface ignored: participating media are not supported (vacuum is used)")?;
                }
            }
            "Texture" => {
                self.world_only(d, span)?;
                let (name, _) = self.expect_string(d, span)?;
                let (kind, kspan) = self.expect_string(d, span)?;
                let (class, cspan) = self.expect_string(d, span)?;
                let params = self.params()?;
                to_scene::texture(
                    &mut self.textures,
                    name,
                    &kind,
                    kspan,
                    &class,
                    cspan,
                    &params,
                    &mut self.ctx,
                )?;
                self.check_unused(&params, d)?;
            }
            "Material" => {
                self.world_only(d, span)?;
                let (ty, tspan) = self.expect_string(d, span)?;
                let params = self.params_with_attributes("material")?;
                let m = to_scene::material(&ty, tspan, &params, &mut self.ctx, &self.textures)?;
                self.check_unused(&params, d)?;
                self.anon_materials += 1;
                let id = self
                    .scene
                    .material(&format!("{ty}#{}", self.anon_materials), m);
                self.state.material = MatRef::Id(id);
            }
            "MakeNamedMaterial" => {
                self.world_only(d, span)?;
                let (name, nspan) = self.expect_string(d, span)?;
                let params = self.params_with_attributes("material")?;
                let Some(ty) = params.string("type")? else {
                    return Err(SpanError::new(
                        nspan,
                        format!("MakeNamedMaterial '{name}' needs a \"string type\" parameter"),
                    ));
                };
                let tspan = params.span_of("type").unwrap_or(nspan);
                let m = to_scene::material(&ty, tspan, &params, &mut self.ctx, &self.textures)?;
                self.check_unused(&params, d)?;
                if !self.defined_materials.insert(name.clone()) {
                    self.ctx.warn(
                        nspan,
                        format!("named material '{name}' redefined; the last definition is used"),
                    )?;
                }
                self.pending_materials.remove(&name);
                self.scene.material(&name, m);
            }
            "NamedMaterial" => {
                self.world_only(d, span)?;
                let (name, nspan) = self.expect_string(d, span)?;
                self.state.material = MatRef::Named(name, nspan);
            }
            "LightSource" => {
                self.world_only(d, span)?;
                let (ty, tspan) = self.expect_string(d, span)?;
                let params = self.params_with_attributes("light")?;
                let light =
                    to_scene::light(&ty, tspan, &params, &mut self.ctx, &self.state.ctm[0])?;
                self.check_unused(&params, d)?;
                if let Some(l) = light {
                    self.scene.lights.push(l);
                }
            }
            "AreaLightSource" => {
                self.world_only(d, span)?;
                let (ty, tspan) = self.expect_string(d, span)?;
                let params = self.params_with_attributes("light")?;
                self.state.area_light = to_scene::area_light(&ty, tspan, &params, &mut self.ctx)?;
                self.check_unused(&params, d)?;
            }
            "Shape" => {
                self.world_only(d, span)?;
                let (ty, tspan) = self.expect_string(d, span)?;
                let params = self.params_with_attributes("shape")?;
                self.shape(&ty, tspan, &params)?;
                self.check_unused(&params, d)?;
            }
            "ObjectBegin" => {
                self.world_only(d, span)?;
                let (name, nspan) = self.expect_string(d, span)?;
                if self.object_def.is_some() {
                    return Err(SpanError::new(
                        span,
                        "ObjectBegin inside another object definition",
                    ));
                }
                self.push_block(Block::Object, span);
                if self.objects.contains_key(&name) {
                    self.ctx.warn(
                        nspan,
                        format!("object '{name}' redefined; the last definition is used"),
                    )?;
                }
                self.object_def = Some((name, vec![], nspan));
            }
            "ObjectEnd" => {
                self.world_only(d, span)?;
                let Some((name, meshes, _)) = self.object_def.take() else {
                    return Err(SpanError::new(span, "ObjectEnd without ObjectBegin"));
                };
                self.pop_block(Block::Object, span, d)?;
                self.objects.insert(name, meshes);
            }
            "ObjectInstance" => {
                self.world_only(d, span)?;
                let (name, nspan) = self.expect_string(d, span)?;
                if self.object_def.is_some() {
                    return Err(SpanError::new(
                        span,
                        "ObjectInstance inside an object definition",
                    ));
                }
                let Some(meshes) = self.objects.get(&name) else {
                    let mut e = SpanError::new(nspan, format!("unknown object '{name}'"));
                    e.help = suggest(&name, self.objects.keys().map(|s| s.as_str()))
                        .map(|s| format!("did you mean '{s}'?"));
                    return Err(e);
                };
                if meshes.is_empty() {
                    self.ctx.warn(
                        nspan,
                        format!("object '{name}' has no shapes; instance skipped"),
                    )?;
                } else {
                    let prototype = meshes.clone();
                    // An instance inside `#ObjectName`-named blocks gets that label.
                    let object = (!self.state.names.is_empty())
                        .then(|| self.scene.object(&self.state.names.join("/")));
                    self.scene.instances.push(Instance {
                        prototype,
                        to_world: self.state.ctm[0],
                        object,
                    });
                }
            }
            _ => {
                let mut e = SpanError::new(span, format!("unknown directive '{d}'"));
                e.help =
                    suggest(d, DIRECTIVES.iter().copied()).map(|s| format!("did you mean '{s}'?"));
                return Err(e);
            }
        }
        Ok(())
    }

    /// Parameters of a directive with the enclosing `Attribute` defaults for `target` in front
    /// (the directive's own values come last and win).
    fn params_with_attributes(&mut self, target: &str) -> PResult<ParamList> {
        let own = self.params()?;
        let defaults: Vec<&ParamDefault> = self
            .state
            .attributes
            .iter()
            .filter(|(t, _)| t == target)
            .flat_map(|(_, v)| v.iter())
            .collect();
        if defaults.is_empty() {
            return Ok(own);
        }
        let mut list = ParamList::default();
        for d in defaults {
            list.push(Param {
                ty: d.ty,
                name: d.name.clone(),
                nums: d.nums.clone(),
                ints: d.ints.clone(),
                strs: d.strs.clone(),
                bools: d.bools.clone(),
                span: d.span,
                used: Default::default(),
                inherited: true,
            });
        }
        for p in own.params {
            list.push(p);
        }
        Ok(list)
    }

    fn include(&mut self, file: &str, fspan: Span) -> PResult<()> {
        let path = self.ctx.resolve_path(file);
        if self.stack.len() >= MAX_INCLUDE_DEPTH {
            return Err(SpanError::new(
                fspan,
                format!("includes nested deeper than {MAX_INCLUDE_DEPTH} levels"),
            ));
        }
        let canon = std::fs::canonicalize(&path).map_err(|e| {
            SpanError::new(fspan, format!("cannot include '{}': {e}", path.display()))
        })?;
        if self.active_paths.contains(&canon) {
            return Err(SpanError::new(
                fspan,
                format!("include cycle: '{}' is already being read", path.display()),
            ));
        }
        let text = read_source(&path).map_err(|m| SpanError::new(fspan, m))?;
        // A peeked token belongs to the including file; it was consumed by expect_string, so none is pending.
        debug_assert!(self.peeked.is_none());
        self.files.push(SourceFile { path, text });
        self.stack
            .push(Lexer::new((self.files.len() - 1) as FileId));
        self.active_paths.push(canon);
        Ok(())
    }

    fn material_id(&mut self) -> PResult<(MaterialId, Option<String>)> {
        Ok(match self.state.material.clone() {
            MatRef::Default => (
                self.scene.material(
                    "(default)",
                    crate::scene::Material::Diffuse {
                        reflectance: crate::spectrum::Spectrum::constant("default", 0.5),
                    },
                ),
                None,
            ),
            MatRef::Id(id) => (id, None),
            MatRef::Named(name, nspan) => {
                if !self.defined_materials.contains(&name) {
                    // pbrt-v4 resolves named materials at the end: allow a later definition.
                    self.pending_materials.entry(name.clone()).or_insert(nspan);
                    if let Some(i) = self.scene.materials.iter().position(|m| m.name == name) {
                        return Ok((i as MaterialId, Some(name)));
                    }
                    let id = self.scene.material(
                        &name,
                        crate::scene::Material::Diffuse {
                            reflectance: crate::spectrum::Spectrum::constant("placeholder", 0.5),
                        },
                    );
                    return Ok((id, Some(name)));
                }
                let i = self
                    .scene
                    .materials
                    .iter()
                    .position(|m| m.name == name)
                    .expect("defined");
                (i as MaterialId, Some(name))
            }
        })
    }

    /// The object label of the next shape (see the module docs of `pbrt`).
    fn label(&self, material_name: Option<&str>) -> String {
        if let Some((name, _, _)) = &self.object_def {
            return name.clone();
        }
        if !self.state.names.is_empty() {
            let mut s = self.state.names.join("/");
            if let Some(m) = material_name
                && self.state.names.last().map(|s| s.as_str()) != Some(m)
            {
                s.push('/');
                s.push_str(m);
            }
            return s;
        }
        if let Some(m) = material_name {
            return m.to_string();
        }
        format!("shape{}", self.shape_count)
    }

    fn shape(&mut self, ty: &str, tspan: Span, params: &ParamList) -> PResult<()> {
        let (material, mname) = self.material_id()?;
        let label = self.label(mname.as_deref());
        self.shape_count += 1;
        if self.state.ctm[0] != self.state.ctm[1] {
            self.ctx.warn(
                tspan,
                "animated transforms are not supported; the start transform is used",
            )?;
        }
        let in_object = self.object_def.is_some();
        let mut area = self.state.area_light.clone();
        if in_object && area.is_some() {
            self.ctx.warn(
                tspan,
                "area lights inside object instances are not supported; emission ignored",
            )?;
            area = None;
        }
        let object = self.scene.object(&label);
        let shape = to_scene::ShapeInput {
            kind: ty,
            span: tspan,
            params,
            to_world: self.state.ctm[0],
            reverse_orientation: self.state.reverse_orientation,
            material,
            object,
            area_light: area.as_ref(),
            force_mesh: in_object,
        };
        let geo = to_scene::shape(&shape, &mut self.ctx)?;
        match geo {
            None => {}
            Some(to_scene::Geometry::Mesh(m)) => {
                self.scene.meshes.push(m);
                let i = self.scene.meshes.len() - 1;
                if let Some((_, list, _)) = &mut self.object_def {
                    list.push(i);
                    self.prototypes.push(i);
                }
            }
            Some(to_scene::Geometry::Sphere(s)) => self.scene.spheres.push(s),
            Some(to_scene::Geometry::Disk(d)) => self.scene.disks.push(d),
        }
        Ok(())
    }

    fn finish(&mut self) -> PResult<()> {
        if let Some((_, _, span)) = &self.object_def {
            return Err(SpanError::new(*span, "ObjectBegin without ObjectEnd"));
        }
        if let Some((_, k, span)) = self.state_stack.last() {
            let span = *span;
            self.ctx.warn(
                span,
                format!("{k:?}Begin without a matching End at the end of the file"),
            )?;
        }
        if let Some((name, span)) = self.pending_materials.iter().next() {
            let mut e = SpanError::new(
                *span,
                format!("named material '{name}' is used but never defined"),
            );
            e.help = suggest(name, self.defined_materials.iter().map(|s| s.as_str()))
                .map(|s| format!("did you mean '{s}'?"));
            return Err(e);
        }
        if !self.in_world && (self.camera.is_some() || self.film.is_some()) {
            self.ctx
                .warn(Span::default(), "the file has no WorldBegin")?;
        }
        let film = self.film.clone().unwrap_or_default();
        self.scene.film = Some(film.spec.clone());
        if let Some((cam, to_world, span)) = self.camera.clone() {
            self.scene.camera = Some(to_scene::camera(
                &cam,
                to_world,
                &film,
                span,
                &mut self.ctx,
            )?);
        }
        Ok(())
    }
}

/// Read a scene file (UTF-8; `.gz` decompressed).
pub fn read_source(path: &Path) -> Result<String, String> {
    let bytes =
        std::fs::read(path).map_err(|e| format!("cannot read '{}': {e}", path.display()))?;
    let bytes = if path.extension().is_some_and(|e| e == "gz") {
        use std::io::Read;
        let mut out = vec![];
        flate2::read::MultiGzDecoder::new(&bytes[..])
            .read_to_end(&mut out)
            .map_err(|e| format!("cannot decompress '{}': {e}", path.display()))?;
        out
    } else {
        bytes
    };
    Ok(match String::from_utf8(bytes) {
        Ok(s) => s,
        Err(e) => String::from_utf8_lossy(e.as_bytes()).into_owned(),
    })
}

/// `diag::did_you_mean`, skipped for long words (no useful suggestion, and the
/// string metrics are quadratic in the length).
fn suggest<'a>(word: &str, candidates: impl IntoIterator<Item = &'a str>) -> Option<String> {
    if word.len() > 40 {
        return None;
    }
    crate::diag::did_you_mean(word, candidates)
}
