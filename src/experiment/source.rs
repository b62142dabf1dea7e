//! Source files of an experiment: loading (from disk or the embedded default
//! experiments), the tuple pre-pass, KDL parsing with errors mapped to
//! `file:line:col`, and span helpers.
//!
//! **Tuples.** KDL has no list value, so camsim accepts `(x y z)` in value
//! position (`position-m=(0 0.1 -0.4)`, or an argument `(0 0.1 -0.4)`) and
//! rewrites it, before KDL parsing, into the string `"0 0.1 -0.4"` of the
//! *same byte length* (`(`→`"`, `)`→`"`), so every offset stays valid. The
//! rewritten offsets are remembered, and the experiment parser turns those
//! strings back into lists of numbers. A parenthesis is a tuple only when its
//! contents hold numbers, spaces and tabs alone and the `)` is not glued to a
//! following value (that would be a KDL type annotation such as `(u8)5`).

use crate::diag::Located;
use std::collections::BTreeSet;
use std::path::{Path, PathBuf};
use std::sync::Arc;

/// Longest caret drawn under an error (long values are cut).
const MAX_CARET: usize = 120;

/// Deepest `{ … }` or `/* … */` nesting accepted; deeper input would exhaust the
/// KDL parser's stack (the language needs 4 levels).
pub const MAX_NESTING: usize = 64;

/// A location in one of the files of a [`SourceMap`]: byte offset and length.
#[derive(Clone, Copy, Debug, Default, PartialEq, Eq, Hash)]
pub struct Span {
    pub file: usize,
    pub offset: usize,
    pub len: usize,
}

/// One loaded source file.
#[derive(Debug)]
pub struct SourceFile {
    pub path: PathBuf,
    pub text: String,
    /// Byte offsets of `(` that the tuple pre-pass rewrote.
    pub tuples: BTreeSet<usize>,
}

/// Every file read while parsing one experiment (the experiment and its bases).
#[derive(Debug, Default, Clone)]
pub struct SourceMap {
    pub files: Vec<Arc<SourceFile>>,
}

impl SourceMap {
    pub fn add(&mut self, path: PathBuf, text: String) -> usize {
        let tuples = find_tuples(&text);
        self.files.push(Arc::new(SourceFile { path, text, tuples }));
        self.files.len() - 1
    }
    pub fn file(&self, i: usize) -> &SourceFile {
        &self.files[i]
    }
    /// A located error at `span`.
    pub fn error(&self, span: Span, message: impl Into<String>) -> Located {
        match self.files.get(span.file) {
            Some(f) => Located::at_offset(
                &f.path,
                &f.text,
                span.offset,
                span.len.min(MAX_CARET),
                message,
            ),
            None => Located {
                file: PathBuf::from("<unknown>"),
                line: 1,
                col: 1,
                message: message.into(),
                snippet: String::new(),
                len: 1,
                help: None,
            },
        }
    }
}

/// Where experiment files come from. `Disk` reads the file system; `Embedded`
/// first looks the (normalised) path up in the experiments compiled into the
/// binary, then falls back to the disk.
#[derive(Clone, Copy, Debug, PartialEq, Eq)]
pub enum Loader {
    Disk,
    Embedded,
}

impl Loader {
    pub fn read(&self, path: &Path) -> Result<String, String> {
        if *self == Loader::Embedded
            && let Some(t) = super::embedded::lookup(path)
        {
            return Ok(t.to_string());
        }
        std::fs::read_to_string(path).map_err(|e| e.to_string())
    }
    pub fn exists(&self, path: &Path) -> bool {
        (*self == Loader::Embedded && super::embedded::lookup(path).is_some()) || path.is_file()
    }
}

/// Byte offsets of the `(` of every tuple in `text` (see module docs). Never panics.
pub fn find_tuples(text: &str) -> BTreeSet<usize> {
    let b = text.as_bytes();
    let mut out = BTreeSet::new();
    let mut i = 0;
    while i < b.len() {
        match b[i] {
            b'/' if b.get(i + 1) == Some(&b'/') => {
                while i < b.len() && b[i] != b'\n' {
                    i += 1;
                }
            }
            b'/' if b.get(i + 1) == Some(&b'*') => {
                let mut depth = 1usize;
                i += 2;
                while i < b.len() && depth > 0 {
                    if b[i] == b'/' && b.get(i + 1) == Some(&b'*') {
                        depth += 1;
                        i += 2;
                    } else if b[i] == b'*' && b.get(i + 1) == Some(&b'/') {
                        depth -= 1;
                        i += 2;
                    } else {
                        i += 1;
                    }
                }
            }
            b'#' if matches!(b.get(i + 1), Some(b'#') | Some(b'"')) => {
                // raw string #"…"#, ##"…"##, also multi-line #"""…"""#
                let mut h = 0;
                while i < b.len() && b[i] == b'#' {
                    h += 1;
                    i += 1;
                }
                if i < b.len() && b[i] == b'"' {
                    i += 1;
                    loop {
                        if i >= b.len() {
                            break;
                        }
                        if b[i] == b'"'
                            && b[i + 1..].iter().take(h).filter(|&&c| c == b'#').count() == h
                        {
                            i += 1 + h;
                            break;
                        }
                        i += 1;
                    }
                }
            }
            b'"' => {
                let triple = b.get(i + 1) == Some(&b'"') && b.get(i + 2) == Some(&b'"');
                i += if triple { 3 } else { 1 };
                while i < b.len() {
                    if b[i] == b'\\' {
                        i += 2;
                        continue;
                    }
                    if b[i] == b'"' {
                        if !triple {
                            i += 1;
                            break;
                        }
                        if b.get(i + 1) == Some(&b'"') && b.get(i + 2) == Some(&b'"') {
                            i += 3;
                            break;
                        }
                    }
                    i += 1;
                }
            }
            b'(' => {
                if let Some(end) = tuple_end(b, i) {
                    out.insert(i);
                    i = end + 1;
                } else {
                    i += 1;
                }
            }
            _ => i += 1,
        }
    }
    out
}

/// Index of the `)` closing a tuple opened at `open`, if it is one.
fn tuple_end(b: &[u8], open: usize) -> Option<usize> {
    let mut j = open + 1;
    let mut has_digit = false;
    while j < b.len() && b[j] != b')' {
        let c = b[j];
        if c.is_ascii_digit() {
            has_digit = true;
        } else if !(c == b' '
            || c == b'\t'
            || c == b'.'
            || c == b'-'
            || c == b'+'
            || c == b'e'
            || c == b'E'
            || c == b'_')
        {
            return None;
        }
        j += 1;
    }
    if j >= b.len() || !has_digit {
        return None;
    }
    // `(…)` glued to a value is a type annotation, not a tuple.
    match b.get(j + 1) {
        None => Some(j),
        Some(c)
            if c.is_ascii_whitespace() || *c == b';' || *c == b'}' || *c == b'/' || *c == b'\\' =>
        {
            Some(j)
        }
        _ => None,
    }
}

/// The text with every tuple rewritten into a same-length string.
pub fn rewrite_tuples(text: &str, tuples: &BTreeSet<usize>) -> String {
    let mut bytes = text.as_bytes().to_vec();
    for &o in tuples {
        bytes[o] = b'"';
        if let Some(close) = bytes[o + 1..].iter().position(|&c| c == b')') {
            bytes[o + 1 + close] = b'"';
        }
    }
    // Only ASCII bytes were swapped for ASCII bytes: still valid UTF-8.
    String::from_utf8(bytes).unwrap_or_else(|_| text.to_string())
}

/// Offset of the first `{` or `/*` nested deeper than [`MAX_NESTING`], if any.
/// Strings and line comments are skipped as in [`find_tuples`]. Never panics.
pub fn too_deep(text: &str) -> Option<usize> {
    let b = text.as_bytes();
    let (mut depth, mut i) = (0usize, 0usize);
    while i < b.len() {
        match b[i] {
            b'/' if b.get(i + 1) == Some(&b'/') => {
                while i < b.len() && b[i] != b'\n' {
                    i += 1;
                }
            }
            b'/' if b.get(i + 1) == Some(&b'*') => {
                let mut c = 0usize;
                while i < b.len() {
                    if b[i] == b'/' && b.get(i + 1) == Some(&b'*') {
                        c += 1;
                        if c > MAX_NESTING {
                            return Some(i);
                        }
                        i += 2;
                    } else if b[i] == b'*' && b.get(i + 1) == Some(&b'/') {
                        c -= 1;
                        i += 2;
                        if c == 0 {
                            break;
                        }
                    } else {
                        i += 1;
                    }
                }
            }
            b'"' => {
                let triple = b.get(i + 1) == Some(&b'"') && b.get(i + 2) == Some(&b'"');
                i += if triple { 3 } else { 1 };
                while i < b.len() {
                    if b[i] == b'\\' {
                        i += 2;
                        continue;
                    }
                    if b[i] == b'"'
                        && (!triple || (b.get(i + 1) == Some(&b'"') && b.get(i + 2) == Some(&b'"')))
                    {
                        i += if triple { 3 } else { 1 };
                        break;
                    }
                    i += 1;
                }
            }
            b'{' => {
                depth += 1;
                if depth > MAX_NESTING {
                    return Some(i);
                }
                i += 1;
            }
            b'}' => {
                depth = depth.saturating_sub(1);
                i += 1;
            }
            _ => i += 1,
        }
    }
    None
}

/// Parse one file of the map as KDL v2. Parser errors become `file:line:col`
/// diagnostics; a panic inside the KDL crate (defence in depth) becomes an error too.
pub fn parse_kdl(map: &SourceMap, file: usize) -> Result<kdl::KdlDocument, Located> {
    let f = map.file(file);
    if let Some(at) = too_deep(&f.text) {
        return Err(map
            .error(
                Span {
                    file,
                    offset: at,
                    len: 2,
                },
                format!("nesting deeper than {MAX_NESTING} levels"),
            )
            .with_help("experiments nest at most experiment { sweep { zip { … } } }"));
    }
    let text = rewrite_tuples(&f.text, &f.tuples);
    let res = std::panic::catch_unwind(|| kdl::KdlDocument::parse_v2(&text));
    match res {
        Ok(Ok(doc)) => Ok(doc),
        Ok(Err(e)) => {
            let d = e.diagnostics.first();
            let (off, len) = d.map(|d| (d.span.offset(), d.span.len())).unwrap_or((0, 1));
            let mut msg = d
                .and_then(|d| d.message.clone())
                .unwrap_or_else(|| "invalid KDL".into());
            if let Some(label) = d.and_then(|d| d.label.clone())
                && label != "here"
            {
                msg = format!("{msg} ({label})");
            }
            let mut help = d.and_then(|d| d.help.clone());
            let near_paren = f
                .text
                .as_bytes()
                .get(off.saturating_sub(1)..(off + 1).min(f.text.len()))
                .is_some_and(|w| w.contains(&b'('));
            if near_paren {
                help = Some("a list of numbers is written (x y z), numbers separated by spaces; a '(name)' glued to a value is a KDL type annotation, which camsim does not use".into());
            }
            if help.is_none() {
                help = Some(
                    "see docs/experiment-language.md for the KDL v2 syntax camsim reads".into(),
                );
            }
            Err(map
                .error(
                    Span {
                        file,
                        offset: off,
                        len: len.max(1),
                    },
                    format!("KDL syntax: {msg}"),
                )
                .with_help_opt(help))
        }
        Err(_) => Err(map.error(
            Span {
                file,
                offset: 0,
                len: 1,
            },
            "the KDL parser failed on this file",
        )),
    }
}

/// Skip whitespace, comments and line continuations from `offset`.
pub fn skip_trivia(text: &str, mut offset: usize) -> usize {
    let b = text.as_bytes();
    loop {
        let start = offset;
        while offset < b.len()
            && (b[offset] == b' ' || b[offset] == b'\t' || b[offset] == b'\n' || b[offset] == b'\r')
        {
            offset += 1;
        }
        if offset + 1 < b.len() && b[offset] == b'/' && b[offset + 1] == b'*' {
            if let Some(e) = text[offset..].find("*/") {
                offset += e + 2;
            } else {
                return offset;
            }
        } else if offset + 1 < b.len() && b[offset] == b'/' && b[offset + 1] == b'/' {
            while offset < b.len() && b[offset] != b'\n' {
                offset += 1;
            }
        } else if offset < b.len() && b[offset] == b'\\' {
            offset += 1;
        }
        if offset == start {
            return offset;
        }
    }
}

#[cfg(test)]
mod tests {
    use super::*;

    fn tuples(s: &str) -> Vec<usize> {
        find_tuples(s).into_iter().collect()
    }

    #[test]
    fn tuples_are_found_only_in_value_position_outside_strings_and_comments() {
        assert_eq!(tuples("a p=(0 1 -2.5e3)"), vec![4]);
        assert_eq!(tuples("a (1 2) (3 4)\n"), vec![2, 8]);
        assert_eq!(
            tuples("a \"(1 2)\" // (3 4)\n/* (5 6) */"),
            Vec::<usize>::new()
        );
        assert_eq!(tuples("a #\"(1 2)\"# (3)"), vec![12]);
        assert_eq!(tuples("a \"\"\"\n(1 2)\n\"\"\" (7)"), vec![16]);
        // type annotations and words are left to KDL
        assert_eq!(tuples("a (u8)5 (1)2 (x y)"), Vec::<usize>::new());
        assert_eq!(tuples("a (1 2"), Vec::<usize>::new());
    }

    #[test]
    fn rewriting_keeps_every_offset() {
        let s = "node p=(0 1 2) q=\"x\"";
        let t = rewrite_tuples(s, &find_tuples(s));
        assert_eq!(t, "node p=\"0 1 2\" q=\"x\"");
        assert_eq!(t.len(), s.len());
    }

    #[test]
    fn deep_nesting_is_refused_before_kdl_parsing() {
        assert_eq!(too_deep("a { b { c } }"), None);
        let deep = "a {".repeat(20_000);
        assert_eq!(too_deep(&deep), Some(3 * MAX_NESTING + 2));
        assert!(too_deep(&"/*".repeat(20_000)).is_some());
        assert_eq!(too_deep(&format!("a \"{}\"", "{".repeat(100))), None);
        assert_eq!(too_deep(&format!("// {}\n", "{".repeat(100))), None);
    }

    #[test]
    fn trivia_is_skipped() {
        let s = "  /* c */ // x\n \\\n v";
        assert_eq!(&s[skip_trivia(s, 0)..], "v");
    }
}
