//! Diagnostics shared by every parser and stage: errors that point at
//! `file:line:col`, show the offending source text, say what was expected and
//! suggest the nearest valid name.

use std::fmt;
use std::path::{Path, PathBuf};

/// An error located in a source file.
#[derive(Clone, Debug, PartialEq)]
pub struct Located {
    pub file: PathBuf,
    /// 1-based line.
    pub line: usize,
    /// 1-based column, in characters.
    pub col: usize,
    /// What is wrong, including what was expected.
    pub message: String,
    /// The source line that holds the error (may be empty).
    pub snippet: String,
    /// Length of the offending text on that line, in characters (≥ 1 for the caret).
    pub len: usize,
    /// Suggestion, e.g. "did you mean 'exposure-s'?".
    pub help: Option<String>,
}

impl Located {
    /// Build from a byte offset into `source` (clamped into range, never panics).
    pub fn at_offset(
        file: &Path,
        source: &str,
        offset: usize,
        len: usize,
        message: impl Into<String>,
    ) -> Self {
        let (line, col, snippet) = line_col(source, offset);
        let len_chars = source
            .get(offset.min(source.len())..(offset + len).min(source.len()))
            .map(|s| s.chars().take_while(|&c| c != '\n').count())
            .unwrap_or(1)
            .max(1);
        Self {
            file: file.to_path_buf(),
            line,
            col,
            message: message.into(),
            snippet,
            len: len_chars,
            help: None,
        }
    }
    pub fn with_help(mut self, help: impl Into<String>) -> Self {
        self.help = Some(help.into());
        self
    }
    pub fn with_help_opt(mut self, help: Option<String>) -> Self {
        self.help = help;
        self
    }
}

impl fmt::Display for Located {
    fn fmt(&self, f: &mut fmt::Formatter<'_>) -> fmt::Result {
        writeln!(
            f,
            "{}:{}:{}: error: {}",
            self.file.display(),
            self.line,
            self.col,
            self.message
        )?;
        if !self.snippet.is_empty() {
            let gutter = format!("{}", self.line);
            writeln!(f, "{} | {}", gutter, self.snippet)?;
            writeln!(
                f,
                "{} | {}{}",
                " ".repeat(gutter.len()),
                " ".repeat(self.col.saturating_sub(1)),
                "^".repeat(self.len.max(1))
            )?;
        }
        if let Some(h) = &self.help {
            writeln!(f, "  help: {h}")?;
        }
        Ok(())
    }
}

impl std::error::Error for Located {}

/// 1-based line and column (in chars) of byte `offset`, and the text of that line.
pub fn line_col(source: &str, offset: usize) -> (usize, usize, String) {
    let mut off = offset.min(source.len());
    while off > 0 && !source.is_char_boundary(off) {
        off -= 1;
    }
    let before = &source[..off];
    let line = before.matches('\n').count() + 1;
    let line_start = before.rfind('\n').map(|i| i + 1).unwrap_or(0);
    let col = source[line_start..off].chars().count() + 1;
    let line_end = source[line_start..]
        .find('\n')
        .map(|i| line_start + i)
        .unwrap_or(source.len());
    let snippet = source[line_start..line_end]
        .trim_end_matches('\r')
        .to_string();
    (line, col, snippet)
}

/// The closest candidate to `word` by Jaro–Winkler / Levenshtein, if close enough.
pub fn did_you_mean<'a>(
    word: &str,
    candidates: impl IntoIterator<Item = &'a str>,
) -> Option<String> {
    let mut best: Option<(f64, &str)> = None;
    for c in candidates {
        let d = strsim::levenshtein(word, c);
        let score = strsim::jaro_winkler(word, c);
        let close = d <= 2.max(word.len() / 3) || score > 0.85;
        if close && best.is_none_or(|(s, _)| score > s) {
            best = Some((score, c));
        }
    }
    best.map(|(_, c)| c.to_string())
}

/// The crate's error type.
#[derive(Debug, thiserror::Error)]
pub enum Error {
    /// An error in an input file, with its location.
    #[error("{0}")]
    Located(Box<Located>),
    /// A file could not be read or written.
    #[error("{path}: {message}")]
    Io { path: PathBuf, message: String },
    /// A stage that camsim does not implement yet (never replaced by invented numbers).
    #[error("not supported yet: {0}")]
    NotSupported(String),
    /// Invalid input or state, not tied to a source location.
    #[error("{0}")]
    Invalid(String),
}

impl From<Located> for Error {
    fn from(l: Located) -> Self {
        Error::Located(Box::new(l))
    }
}

impl Error {
    pub fn io(path: &Path, e: impl fmt::Display) -> Self {
        Error::Io {
            path: path.to_path_buf(),
            message: e.to_string(),
        }
    }
    pub fn invalid(msg: impl Into<String>) -> Self {
        Error::Invalid(msg.into())
    }
}

pub type Result<T, E = Error> = std::result::Result<T, E>;

/// A `serde_json` error in `source` (the text of `path`) as a located
/// diagnostic: `path:line:col: invalid JSON: …` with the source line and a
/// caret. serde_json reports a 1-based line and a 1-based byte column; both
/// are mapped through the text itself (LF or CRLF line ends), clamped, never
/// panicking. An I/O-level serde error (no position) gets line 1.
pub fn json_error(path: &Path, source: &str, e: &serde_json::Error) -> Error {
    let line = e.line().max(1);
    let offset = source
        .split_inclusive('\n')
        .take(line - 1)
        .map(str::len)
        .sum::<usize>()
        + e.column().saturating_sub(1);
    Error::from(Located::at_offset(
        path,
        source,
        offset.min(source.len()),
        1,
        format!("invalid JSON: {e}"),
    ))
}

/// Parse `source` (the text of `path`) as JSON; errors located by [`json_error`].
pub fn parse_json(path: &Path, source: &str) -> Result<serde_json::Value> {
    serde_json::from_str(source).map_err(|e| json_error(path, source, &e))
}

/// Find a relative file: in `base_dir`, then in each of its parents in turn
/// (`exists` says whether a path is there). A directory named relative to the
/// working directory (empty or relative) is also searched from its absolute
/// form, whose parents are listed. An absolute `written` is taken as is.
pub fn find_up(
    written: &str,
    base_dir: &Path,
    exists: impl Fn(&Path) -> bool,
) -> Option<std::path::PathBuf> {
    let w = Path::new(written);
    if w.is_absolute() {
        return exists(w).then(|| w.to_path_buf());
    }
    let found = base_dir.ancestors().map(|d| d.join(w)).find(|p| exists(p));
    found.or_else(|| {
        let dir = if base_dir.as_os_str().is_empty() {
            Path::new(".")
        } else {
            base_dir
        };
        let abs = std::path::absolute(dir).ok()?;
        abs.ancestors().map(|d| d.join(w)).find(|p| exists(p))
    })
}

/// Write a file atomically: write a sibling temp file, fsync, then rename over `path`.
/// A reader never sees a half-written file and an interrupted write loses nothing.
pub fn write_atomic(path: &Path, bytes: &[u8]) -> Result<()> {
    use std::io::Write;
    let dir = path
        .parent()
        .filter(|p| !p.as_os_str().is_empty())
        .unwrap_or(Path::new("."));
    std::fs::create_dir_all(dir).map_err(|e| Error::io(dir, e))?;
    // Created with mode 0666 less the umask, as a plain file would be (the
    // temp file's default 0600 would survive the rename and hide results
    // from collaborators on a shared file system).
    let mut b = tempfile::Builder::new();
    #[cfg(unix)]
    {
        use std::os::unix::fs::PermissionsExt;
        b.permissions(std::fs::Permissions::from_mode(0o666));
    }
    let mut tmp = b.tempfile_in(dir).map_err(|e| Error::io(dir, e))?;
    tmp.write_all(bytes).map_err(|e| Error::io(path, e))?;
    tmp.as_file().sync_all().map_err(|e| Error::io(path, e))?;
    tmp.persist(path).map_err(|e| Error::io(path, e.error))?;
    Ok(())
}

#[cfg(test)]
mod tests {
    /// Result files honour the umask like any file the user creates: compare
    /// with a file made by `File::create` in the same directory (mode 0666 less
    /// the process umask), for whatever umask the test runs under.
    #[cfg(unix)]
    #[test]
    fn atomic_writes_honour_the_umask() {
        use std::os::unix::fs::PermissionsExt;
        let dir = tempfile::tempdir().unwrap();
        let plain = dir.path().join("plain");
        std::fs::File::create(&plain).unwrap();
        let want = std::fs::metadata(&plain).unwrap().permissions().mode() & 0o777;
        let p = dir.path().join("results.csv");
        super::write_atomic(&p, b"x").unwrap();
        let got = std::fs::metadata(&p).unwrap().permissions().mode() & 0o777;
        assert_eq!(got, want, "written {got:o}, a plain file {want:o}");
    }

    #[test]
    fn json_errors_point_at_line_and_column() {
        let p = Path::new("lens.json");
        for src in [
            "{\n  \"a\": 1,\n  \"b\": x\n}\n",
            "{\r\n  \"a\": 1,\r\n  \"b\": x\r\n}\r\n",
        ] {
            let e = parse_json(p, src).unwrap_err();
            let Error::Located(l) = &e else { panic!("{e}") };
            assert_eq!((l.line, l.col), (3, 8), "{e}");
            assert!(e.to_string().contains("lens.json:3:8") && l.message.contains("invalid JSON"));
        }
        // Truncated input: located at the end, no panic.
        let e = parse_json(p, "{\"a\": [1, 2").unwrap_err().to_string();
        assert!(e.starts_with("lens.json:1:"), "{e}");
        assert!(parse_json(p, "{\"a\": [1, 2]}").is_ok());
    }

    use super::*;
    #[test]
    fn line_col_is_one_based_and_safe() {
        let s = "ab\ncdé\nf";
        assert_eq!(line_col(s, 0), (1, 1, "ab".into()));
        assert_eq!(line_col(s, 4), (2, 2, "cdé".into()));
        assert_eq!(line_col(s, 6), (2, 3, "cdé".into())); // inside 'é' → clamped back
        assert_eq!(line_col(s, 1000).0, 3);
    }
    #[test]
    fn suggestions() {
        assert_eq!(
            did_you_mean("exposure-ms", ["exposure-s", "spp"]),
            Some("exposure-s".into())
        );
        assert_eq!(did_you_mean("zzzz", ["exposure-s", "spp"]), None);
    }
    #[test]
    fn display_has_location_and_caret() {
        let l = Located::at_offset(Path::new("x.kdl"), "a\nspp 1\n", 2, 3, "bad").with_help("h");
        let s = l.to_string();
        assert!(s.starts_with("x.kdl:2:1: error: bad"), "{s}");
        assert!(s.contains("^^^"));
    }
}
